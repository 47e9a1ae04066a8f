//! The one sequence of a pass, owned by the engine; the caller supplies the I/O ([`PassIo`]).
//!
//! The shell (`crate::service`) runs it on iceoryx2 ports, bus descriptors and the monotonic
//! clock; the scenario rig (`engine::rig`) on a simulated wire, scripted clients and simulated
//! time. Both call [`Engine::run_pass`], so the order the scenarios test is the order the service
//! runs. The engine stays sans-IO: it reads no clock (it asks [`PassIo::now`]), opens nothing,
//! and the trait is used generically (no dynamic dispatch; the sequence itself allocates
//! nothing: the items between the bus and the engine live in buffers the engine keeps).

use std::fmt::Display;
use std::time::Duration;

use chassis_interfaces::{ControlRequest, VelocityRequest};
use chassis_protocols::{Timestamp, WireItem};
use tracing::{debug, error};

use super::{BusItem, Device, Engine, HeldLock, Link, Ticket, ToPublish, Wake};

/// How a write to the bus went.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Written {
    /// The item, and every item the backend held before it, is on the bus; the write returned
    /// at this instant.
    Out(Timestamp),
    /// The backend holds the item until a later write or the flush carries it (the peer is
    /// slow); the write returned at this instant.
    Held(Timestamp),
}

/// Why a write to the bus failed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum WriteError<E> {
    /// This item was not sent (the transmit queue is full); the bus is still there.
    Dropped(E),
    /// The bus is gone: it is closed and reopened after a backoff.
    Lost(E),
}

/// Whose readers a pass wakes: one notification per kind and pass, after everything of the
/// pass is in shared memory.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Readers {
    State,
    Frames,
    Mux,
    /// Readers of the robot's description (`chassis/<name>/robot`).
    Description,
    /// The clients of `control` that wait for an answer.
    Control,
}

impl Readers {
    const ALL: [Readers; 5] = [
        Readers::State,
        Readers::Frames,
        Readers::Mux,
        Readers::Description,
        Readers::Control,
    ];

    fn bit(self) -> u8 {
        1 << self as u8
    }

    /// Whose readers `publication` is for.
    pub fn of(publication: &ToPublish) -> Self {
        match publication {
            ToPublish::State(_) => Readers::State,
            ToPublish::Frame(_) => Readers::Frames,
            ToPublish::Mux(_) => Readers::Mux,
            ToPublish::Description(_) => Readers::Description,
            ToPublish::Response { .. } => Readers::Control,
        }
    }

    fn what(self) -> (&'static str, &'static str) {
        match self {
            Readers::State => ("state", "state readers"),
            Readers::Frames => ("frame", "frame readers"),
            Readers::Mux => ("mux status", "mux readers"),
            Readers::Description => ("robot description", "description readers"),
            Readers::Control => ("control response", "control clients"),
        }
    }
}

/// What a pass needs from the world around the engine. [`Engine::run_pass`] calls these in the
/// one order of a pass; each method moves bytes, stamps what it reads with the caller's clock,
/// and decides nothing.
pub trait PassIo {
    /// Why an operation failed: the engine logs it (at most once a second per kind) and counts
    /// what could not be published.
    type Error: Display;

    /// The caller's clock (`CLOCK_MONOTONIC`; simulated time in the rig).
    fn now(&mut self) -> Timestamp;

    // ---- the command path -----------------------------------------------------------------

    /// Hands `take` every pending request of the sources in `sources` (one bit per source,
    /// by its index in the configuration), without consuming their notifications.
    fn read_requests(&mut self, sources: u32, take: impl FnMut(usize, &VelocityRequest));

    /// Hands `take` every pending control request with the ticket its answer will carry
    /// ([`ToPublish::Response`]).
    fn read_control(&mut self, take: impl FnMut(Ticket, &ControlRequest));

    /// Serves the simulated chassis' fault injections: the simulator's business, not the
    /// engine's (a caller without a simulator has nothing to do).
    fn serve_simulator(&mut self, now: Timestamp);

    /// Consumes the notifications of the listeners of `sources` (one bit each) that woke the
    /// loop; the engine then reads those sources once more.
    fn acknowledge(&mut self, sources: u32);

    // ---- the devices ----------------------------------------------------------------------

    /// Writes one item to the bus.
    fn write(&mut self, item: &WireItem) -> Result<Written, WriteError<Self::Error>>;

    /// Writes what the backend holds; `Ok` with the instant the flush returned.
    fn flush(&mut self) -> Result<Timestamp, WriteError<Self::Error>>;

    /// Reads what the bus has pending, at most one batch, into `into`, each item stamped when
    /// it was read, the CAN controller's reports among the frames in the order read.
    /// `Ok(true)`: the batch limit stopped the read with more pending. An error is a lost bus
    /// (the items read before it are in `into`).
    fn read_bus(&mut self, into: &mut Vec<(Timestamp, BusItem)>) -> Result<bool, Self::Error>;

    /// Hands `take` what the GPS receiver has pending. An error is a lost receiver.
    fn read_gps(&mut self, take: impl FnMut(&[u8])) -> Result<(), Self::Error>;

    /// Opens `device` at `now`; `Ok` with its name (for the log).
    fn open(&mut self, now: Timestamp, device: Device) -> Result<&str, Self::Error>;

    /// `device` failed: close it (its descriptor may stay open until the caller stops watching
    /// it).
    fn close(&mut self, device: Device);

    // ---- what the pass tells ----------------------------------------------------------------

    /// Keeps the held locks where they outlive the process (atomically: write, fsync, rename).
    fn keep_locks(&mut self, held: &[HeldLock]) -> Result<(), Self::Error>;

    /// Puts one publication in shared memory (a control answer: to the client waiting for it)
    /// without waking its readers.
    fn publish(&mut self, publication: ToPublish) -> Result<(), Self::Error>;

    /// Wakes the readers of `readers`.
    fn wake(&mut self, readers: Readers) -> Result<(), Self::Error>;
}

/// How long a failed write of the held locks waits before it is tried again.
const KEEP_RETRY: Duration = Duration::from_secs(1);

impl Engine {
    /// One pass after a wake-up, in the one order (the command path first):
    ///
    /// 1. [`Engine::begin_pass`] serves the tick and names what to read.
    /// 2. The requests of the sources to read, the control requests and the simulator's are
    ///    handed over; transmit: the mux decides and a changed command is on the bus before
    ///    anything else is read (each item stamped when its write returned).
    /// 3. The listeners that fired are acknowledged and their sources read again: a request
    ///    that came meanwhile (its notification just consumed) is decided and sent at once.
    /// 4. A changed held set is kept ([`PassIo::keep_locks`]) before anything of the pass is
    ///    published: an answered engage survives a crash.
    /// 5. The bus is drained: each item stamped when read, handed to the driver, and what it
    ///    produced (the tap, the state) put in shared memory at once; receive moderation
    ///    weighs the read. Then the GPS receiver.
    /// 6. [`Engine::handle_timeout`]: the driver's deadlines; transmit.
    /// 7. [`Engine::end_pass`] (mux status, the tick's state refresh); the devices due are
    ///    opened; everything left is published; the readers are woken, once per kind.
    pub fn run_pass(&mut self, io: &mut impl PassIo, wake: Wake) {
        let woke = io.now();
        let reads = self.begin_pass(woke, wake);
        io.read_requests(reads.sources, |source, request| {
            // A rejected request is counted and logged by `handle_request`.
            self.handle_request(woke, source, request).ok();
        });
        if reads.control {
            io.read_control(|ticket, request| self.handle_control(woke, ticket, request));
        }
        if reads.sim {
            io.serve_simulator(woke);
        }
        self.transmit(io, woke);
        if wake.sources != 0 {
            io.acknowledge(wake.sources);
            let now = io.now();
            let mut meanwhile = false;
            io.read_requests(wake.sources, |source, request| {
                meanwhile = true;
                self.handle_request(now, source, request).ok();
            });
            if meanwhile {
                let now = io.now();
                self.transmit(io, now);
            }
        }
        self.keep_locks(io, woke);
        if reads.bus {
            self.drain_bus(io);
        }
        let now = io.now();
        if reads.gps {
            self.read_gps(io, now);
        }
        self.handle_timeout(now);
        self.transmit(io, now);
        self.end_pass(now);
        self.open_due(io, now);
        self.tell(io, now);
    }

    /// The service's first publications, at `now`, after [`Engine::restore_locks`] (or
    /// [`Engine::restore_failed`]): the devices due are opened, a held set that must be kept is
    /// kept, the state and the mux status are published.
    pub fn start(&mut self, io: &mut impl PassIo, now: Timestamp) {
        self.open_due(io, now);
        self.publish_all(now);
        self.keep_locks(io, now);
        self.tell(io, now);
    }

    /// The orderly stop at `now`: zero (and the brake where there is one) on the bus, the
    /// control requests still waiting refused, the last state and mux status published.
    pub fn stop(&mut self, io: &mut impl PassIo, now: Timestamp) {
        self.shutdown(now);
        self.transmit(io, now);
        self.publish_all(now);
        self.keep_locks(io, now);
        self.tell(io, now);
    }

    /// Writes what the engine polls. Each item is stamped when its write returned (an item the
    /// backend held, when the write or the flush that carried it returned) and tapped once its
    /// stamp is known; a lost bus is closed.
    fn transmit(&mut self, io: &mut impl PassIo, now: Timestamp) {
        let mut lost = None;
        while let Some(item) = self.poll_transmit(now) {
            match io.write(&item) {
                Ok(Written::Out(at)) => {
                    self.tap_held(Some(at));
                    self.handle_sent(at, &item);
                }
                Ok(Written::Held(at)) => self.tx_held.push((at, item)),
                Err(WriteError::Dropped(err)) => self.handle_tx_dropped(now, &err),
                Err(WriteError::Lost(err)) => {
                    lost = Some(err);
                    break;
                }
            }
        }
        if lost.is_none() && self.bus == Link::Up {
            match io.flush() {
                Ok(at) => self.tap_held(Some(at)),
                Err(WriteError::Dropped(err)) => self.handle_tx_dropped(now, &err),
                Err(WriteError::Lost(err)) => lost = Some(err),
            }
        }
        // Written, but not known to have left the backend: stamped when their write returned.
        self.tap_held(None);
        if let Some(err) = lost {
            io.close(Device::Bus);
            self.handle_bus_lost(now, &err);
        }
    }

    /// Taps the items the backend held, stamped `out` (when the write or flush that carried
    /// them returned) or, without it, when their own write returned.
    fn tap_held(&mut self, out: Option<Timestamp>) {
        if self.tx_held.is_empty() {
            return;
        }
        let mut held = std::mem::take(&mut self.tx_held);
        for (stamp, item) in held.drain(..) {
            self.handle_sent(out.unwrap_or(stamp), &item);
        }
        self.tx_held = held;
    }

    /// Reads one batch from the bus. Each item goes to the driver in the order read, and what
    /// it produced goes to shared memory before the next (a reader that polls has the first
    /// sample of a burst without waiting for the last).
    fn drain_bus(&mut self, io: &mut impl PassIo) {
        // The bus may have been lost while transmitting.
        if self.bus != Link::Up {
            return;
        }
        let mut received = std::mem::take(&mut self.rx_items);
        received.clear();
        let result = io.read_bus(&mut received);
        let mut weight = 0;
        for (stamp, item) in &received {
            match item {
                BusItem::Rx(item) => {
                    weight += crate::rx_moderation::weight(item.as_rx());
                    self.handle_rx(*stamp, item.as_rx());
                }
                BusItem::Controller(report) => {
                    weight += 1;
                    self.handle_controller(*stamp, report);
                }
            }
            self.publish(io, *stamp);
        }
        self.rx_items = received;
        let now = io.now();
        match result {
            Ok(backlog) => self.handle_bus_read(now, weight, backlog),
            Err(err) => {
                io.close(Device::Bus);
                self.handle_bus_lost(now, &err);
            }
        }
    }

    fn read_gps(&mut self, io: &mut impl PassIo, now: Timestamp) {
        if self.gps != Some(Link::Up) {
            return;
        }
        if let Err(err) = io.read_gps(|bytes| self.handle_gps(now, bytes)) {
            io.close(Device::Gps);
            self.handle_gps_lost(now, &err);
        }
    }

    /// Opens the devices due at `now`.
    fn open_due(&mut self, io: &mut impl PassIo, now: Timestamp) {
        while let Some(device) = self.poll_open(now) {
            match io.open(now, device) {
                Ok(name) => self.handle_opened(now, device, name),
                Err(err) => self.handle_open_failed(now, device, &err),
            }
        }
    }

    /// Keeps the held set when it changed (or a failed write is due to be tried again).
    fn keep_locks(&mut self, io: &mut impl PassIo, now: Timestamp) {
        if let Some(held) = self.poll_held_locks() {
            self.unkept = Some(held);
        }
        let Some(held) = &self.unkept else {
            return;
        };
        if now < self.keep_retry_at {
            return;
        }
        match io.keep_locks(held) {
            Ok(()) => {
                debug!(held = held.len(), "held locks kept");
                self.unkept = None;
            }
            Err(err) => {
                error!("{err}; the held locks would not survive a restart: retrying every second");
                self.keep_retry_at = now + KEEP_RETRY;
            }
        }
    }

    /// Puts every pending publication in shared memory. The held set only changes with the
    /// requests and control requests of the command path, and is kept right after it.
    fn publish(&mut self, io: &mut impl PassIo, now: Timestamp) {
        while let Some(publication) = self.publications.pop_front() {
            let readers = Readers::of(&publication);
            match io.publish(publication) {
                Ok(()) => self.to_wake |= readers.bit(),
                Err(err) => self.handle_publish_failed(now, readers.what().0, &err),
            }
        }
    }

    /// Publishes what is left and wakes the readers of everything the pass published.
    fn tell(&mut self, io: &mut impl PassIo, now: Timestamp) {
        self.publish(io, now);
        let to_wake = std::mem::take(&mut self.to_wake);
        for readers in Readers::ALL {
            if to_wake & readers.bit() != 0
                && let Err(err) = io.wake(readers)
            {
                self.handle_publish_failed(now, readers.what().1, &err);
            }
        }
    }
}
