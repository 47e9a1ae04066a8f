//! The shell's side of a pass: the [`PassIo`] the engine runs its pass on ([`Engine::run_pass`]
//! owns the order). Each method moves bytes between the engine and the iceoryx2 ports, the bus
//! and the GPS port, and stamps what it reads or writes with the clock.
// The shell owns the clock: it stamps what it reads and writes, and hands the time to the engine.
#![allow(clippy::disallowed_methods)]

use chassis_bus::clock;
use chassis_bus::{BusError, MAX_RX_BATCH, Received};
use chassis_interfaces::{ControlRequest, ControlResponse, ControlStatus, VelocityRequest};
use chassis_protocols::{Rx, Timestamp, WireItem};
use iceoryx2::port::notifier::NotifierNotifyError;
use iceoryx2::port::{LoanError, SendError};
use tracing::{debug, info, warn};

use super::trace::PassStamps;
use super::{Next, Shell, clocks};
use crate::engine::{
    BusItem, Device, Engine, HeldLock, PassIo, Readers, Ticket, ToPublish, Wake, WriteError,
    Written,
};
use crate::ipc::Ports;
use crate::lockfile::LockFileError;
use crate::setup::Devices;
use crate::sim::carry_out;

/// Why an operation of a pass failed.
#[derive(Debug, thiserror::Error)]
pub(super) enum PassError {
    #[error(transparent)]
    Bus(#[from] BusError),
    #[error(transparent)]
    Locks(#[from] LockFileError),
    #[error(transparent)]
    Loan(#[from] LoanError),
    #[error(transparent)]
    Send(#[from] SendError),
    #[error(transparent)]
    Notify(#[from] NotifierNotifyError),
}

/// Hands the robot's description to readers that joined since the last tick: iceoryx2 delivers
/// a publisher's history when the publisher updates its connections, and the description is
/// published only when it changes. A reader waiting for it is woken by the next state sample.
fn refresh_description_readers(ports: &Ports) {
    use iceoryx2::port::update_connections::UpdateConnections;
    if let Err(e) = ports.description.publisher.update_connections() {
        debug!("robot description: connecting new readers: {e}");
    }
}

impl<D: Devices> Shell<D> {
    /// One pass after a wake-up, in the engine's order ([`Engine::run_pass`]). Returns whether
    /// a descriptor was lost or (re)opened (the wait set must be rebuilt).
    pub(super) fn pass(&mut self, ports: &Ports, engine: &mut Engine, wake: Wake) -> Next {
        if wake.is_activity() {
            self.last_activity = clock::now();
        }
        if let Some(trace) = &mut self.trace {
            // What the service did outside a pass (its first publications) is not a pass's.
            trace.current = PassStamps {
                waited_since: trace.waiting_since,
                ..PassStamps::default()
            };
        }
        self.step(ports, engine, super::Step::Pass(wake));
        if let Some(trace) = &mut self.trace {
            trace.end_pass();
        }
        if engine.served_tick() {
            refresh_description_readers(ports);
        }
        std::mem::replace(&mut self.next, Next::Continue)
    }

    /// The ports and devices lent to the engine for one pass.
    pub(super) fn io<'a>(&'a mut self, ports: &'a Ports) -> ShellIo<'a, D> {
        ShellIo { shell: self, ports }
    }
}

/// The shell's ports and devices, lent to one pass of the engine.
pub(super) struct ShellIo<'a, D> {
    shell: &'a mut Shell<D>,
    ports: &'a Ports,
}

impl<D> ShellIo<'_, D> {
    /// With the pass trace on, `slot` of the pass under way takes the time now (once a pass).
    fn stamp(&mut self, slot: fn(&mut PassStamps) -> &mut u64) {
        if let Some(trace) = &mut self.shell.trace {
            PassStamps::first(slot(&mut trace.current), clock::now().as_nanos());
        }
    }
}

impl<D: Devices> PassIo for ShellIo<'_, D> {
    type Error = PassError;

    fn now(&mut self) -> Timestamp {
        let now = clock::now();
        if let Some(trace) = &mut self.shell.trace {
            PassStamps::first(&mut trace.current.woke, now.as_nanos());
        }
        now
    }

    /// Samples are read before the notification is consumed (a sample is in shared memory
    /// before its notification is sent): that system call waits until the command is out, in
    /// [`PassIo::acknowledge`].
    fn read_requests(&mut self, sources: u32, mut take: impl FnMut(usize, &VelocityRequest)) {
        let mut took = false;
        for (index, inlet) in self.ports.sources.iter().enumerate() {
            if sources & (1 << index) == 0 {
                continue;
            }
            loop {
                match inlet.subscriber.receive() {
                    Ok(Some(sample)) => {
                        took = true;
                        take(index, &sample);
                    }
                    Ok(None) => break,
                    Err(e) => {
                        debug!(source = inlet.name, "receive: {e}");
                        break;
                    }
                }
            }
        }
        if took {
            self.stamp(|p| &mut p.requests_read);
        }
    }

    fn read_control(&mut self, mut take: impl FnMut(Ticket, &ControlRequest)) {
        let control = &self.ports.control;
        if let Err(e) = control.listener.try_wait(|_| {}) {
            debug!("consuming control notifications: {e}");
        }
        loop {
            let active = match control.server.receive() {
                Ok(Some(active)) => active,
                Ok(None) => break,
                Err(e) => {
                    debug!("control receive: {e}");
                    break;
                }
            };
            self.shell.next_ticket += 1;
            let ticket = self.shell.next_ticket;
            let request = *active.payload();
            self.shell.pending.insert(ticket, active);
            take(ticket, &request);
        }
    }

    fn serve_simulator(&mut self, now: Timestamp) {
        let Some(desk) = &self.ports.sim else {
            return;
        };
        if let Err(e) = desk.listener.try_wait(|_| {}) {
            debug!("consuming simulator notifications: {e}");
        }
        while let Ok(Some(active)) = desk.server.receive() {
            let request = *active.payload();
            let (status, message) = carry_out(
                &request,
                self.shell.sim.as_ref(),
                (ControlStatus::UNSUPPORTED, "the bus is not the simulator"),
            );
            info!(status = ControlStatus::name(status), "simulator: {message}");
            let mut response = ControlResponse::new(request.seq, status, &message);
            response.stamp_ns = now.as_nanos();
            if let Err(e) = active.send_copy(response) {
                warn!("cannot answer a simulator request: {e}");
            }
            if let Err(e) = desk.notifier.notify() {
                warn!("cannot wake the simulator's clients: {e}");
            }
        }
    }

    /// Only a listener that fired is read: an idle one would cost a system call for nothing.
    fn acknowledge(&mut self, sources: u32) {
        for (index, inlet) in self.ports.sources.iter().enumerate() {
            if sources & (1 << index) != 0
                && let Err(e) = inlet.listener.try_wait(|_| {})
            {
                debug!(source = inlet.name, "consuming notifications: {e}");
            }
        }
    }

    fn write(&mut self, item: &WireItem) -> Result<Written, WriteError<PassError>> {
        self.stamp(|p| &mut p.write_started);
        let Some(bus) = self.shell.bus.as_mut() else {
            return Err(WriteError::Lost(no_bus()));
        };
        match bus.transmit(item) {
            Ok(()) => {
                let written = clock::now();
                Ok(if bus.unflushed() == 0 {
                    if let Some(trace) = &mut self.shell.trace {
                        PassStamps::first(&mut trace.current.written, written.as_nanos());
                    }
                    Written::Out(written)
                } else {
                    Written::Held(written)
                })
            }
            Err(err) => Err(classify(err)),
        }
    }

    fn flush(&mut self) -> Result<Timestamp, WriteError<PassError>> {
        let Some(bus) = self.shell.bus.as_mut() else {
            return Err(WriteError::Lost(no_bus()));
        };
        let held = bus.unflushed() > 0;
        match bus.flush() {
            Ok(()) => {
                let flushed = clock::now();
                // A held frame is out when the flush that carried it returned: its tap stamp. A
                // flush that carried nothing wrote nothing (a polling loop flushes every pass).
                if held && let Some(trace) = &mut self.shell.trace {
                    PassStamps::first(&mut trace.current.written, flushed.as_nanos());
                }
                Ok(flushed)
            }
            Err(err) => Err(classify(err)),
        }
    }

    fn read_bus(&mut self, into: &mut Vec<(Timestamp, BusItem)>) -> Result<bool, PassError> {
        let Some(bus) = self.shell.bus.as_mut() else {
            return Err(no_bus());
        };
        let count = bus.receive_all(|item| {
            let stamp = clock::now();
            into.push((
                stamp,
                match item {
                    Received::Rx(Rx::Can(frame)) => BusItem::Rx(WireItem::Can(*frame)),
                    Received::Rx(Rx::Bytes(bytes)) => BusItem::Rx(WireItem::Bytes(bytes.to_vec())),
                    Received::Controller(report) => BusItem::Controller(*report),
                },
            ));
        })?;
        Ok(count >= MAX_RX_BATCH)
    }

    fn read_gps(&mut self, mut take: impl FnMut(&[u8])) -> Result<(), PassError> {
        let Some(gps) = self.shell.gps.as_mut() else {
            return Ok(());
        };
        gps.receive(|rx| {
            if let Rx::Bytes(bytes) = rx {
                take(bytes);
            }
        })?;
        Ok(())
    }

    fn open(&mut self, now: Timestamp, device: Device) -> Result<&str, PassError> {
        let shell = &mut *self.shell;
        let opened = match device {
            Device::Bus => {
                // A simulator thread that ended is replaced by a fresh (power-up) one.
                shell.sim = None;
                let (bus, sim) = shell.devices.open_bus(now)?;
                shell.sim = sim;
                shell.bus.insert(bus)
            }
            Device::Gps => shell.gps.insert(shell.devices.open_gps()?),
        };
        shell.next = Next::Rewire;
        Ok(opened.name())
    }

    /// The descriptor stays open until the wait set that watches it is gone.
    fn close(&mut self, device: Device) {
        let shell = &mut *self.shell;
        let failed = match device {
            Device::Bus => shell.bus.take(),
            Device::Gps => shell.gps.take(),
        };
        shell.retired.extend(failed);
        shell.next = Next::Rewire;
    }

    fn keep_locks(&mut self, held: &[HeldLock]) -> Result<(), PassError> {
        self.shell.lock_file.store(held, clocks(clock::now()))?;
        debug!(file = %self.shell.lock_file.path().display(), "held locks kept");
        Ok(())
    }

    fn publish(&mut self, publication: ToPublish) -> Result<(), PassError> {
        let ports = self.ports;
        match publication {
            ToPublish::State(mut sample) => {
                let slot = ports.state.publisher.loan_uninit()?;
                sample.published_ns = clock::now().as_nanos();
                sample.link.recorder_dropped = self.shell.recorder_dropped;
                slot.write_payload(*sample).send()?;
                if let Some(trace) = &mut self.shell.trace {
                    PassStamps::first(&mut trace.current.state_handed, sample.published_ns);
                }
                self.stamp(|p| &mut p.state_sent);
            }
            ToPublish::Frame(frame) => {
                ports.frames.publisher.send_copy(frame)?;
            }
            ToPublish::Mux(status) => {
                ports.mux.publisher.send_copy(*status)?;
            }
            ToPublish::Description(description) => {
                ports.description.publisher.send_copy(*description)?;
            }
            ToPublish::Response { ticket, response } => {
                if let Some(active) = self.shell.pending.remove(&ticket) {
                    active.send_copy(response)?;
                }
            }
        }
        Ok(())
    }

    fn wake(&mut self, readers: Readers) -> Result<(), PassError> {
        let ports = self.ports;
        let notifier = match readers {
            Readers::State => &ports.state.notifier,
            Readers::Frames => &ports.frames.notifier,
            Readers::Mux => &ports.mux.notifier,
            Readers::Description => &ports.description.notifier,
            Readers::Control => &ports.control.notifier,
        };
        if readers == Readers::State {
            self.stamp(|p| &mut p.state_wake_begun);
        }
        notifier.notify()?;
        if readers == Readers::State {
            self.stamp(|p| &mut p.state_readers_woken);
        }
        Ok(())
    }
}

/// A failed write: the bus gone, or this item dropped.
fn classify(err: BusError) -> WriteError<PassError> {
    if err.is_disconnect() {
        WriteError::Lost(err.into())
    } else {
        WriteError::Dropped(err.into())
    }
}

/// The engine asked for a device the shell has not got (it was closed): a lost device.
fn no_bus() -> PassError {
    PassError::Bus(BusError::Open {
        name: "bus".into(),
        reason: "not open".into(),
    })
}
