//! One pass of the shell: reading what the engine asks for, writing what it polls, publishing
//! what it produced. Every item is stamped with the clock when it was read or written.
// The shell owns the clock: it stamps what it reads and writes, and hands the time to the engine.
#![allow(clippy::disallowed_methods)]

use std::fmt::Display;

use chassis_interfaces::{ControlResponse, ControlStatus};
use chassis_protocols::{Rx, Timestamp, Transmit};
use tracing::{debug, info, warn};

use super::{Next, Shell};
use crate::bus::{BusError, MAX_RX_BATCH};
use crate::clock;
use crate::engine::{Device, Engine, Publication, Wake};
use crate::ipc::Ports;
use crate::setup::Devices;
use crate::sim::carry_out;

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
    /// One pass after a wake-up (see the engine's documentation for the order). Requests go
    /// first and reach the bus before anything else is read: the command path is the one whose
    /// latency matters, and waking the readers of received frames could hand the CPU to them
    /// before the command is out.
    pub(super) fn pass(&mut self, ports: &Ports, engine: &mut Engine, wake: Wake) -> Next {
        let mut next = Next::Continue;
        let woke = clock::now();
        if wake.is_activity() {
            self.last_activity = woke;
        }
        let reads = engine.begin_pass(woke, wake);
        self.read_sources(ports, engine, woke, reads.sources);
        if reads.control {
            self.read_control(ports, engine, woke);
        }
        if reads.sim {
            self.handle_sim(ports, woke);
        }
        next |= self.transmit(engine, woke);
        if self.acknowledge_sources(ports, engine, wake.sources) {
            next |= self.transmit(engine, clock::now());
        }
        if reads.bus {
            next |= self.read_bus(ports, engine);
        }
        let now = clock::now();
        if reads.gps {
            next |= self.read_gps(engine, now);
        }
        engine.handle_timeout(now);
        next |= self.transmit(engine, now);
        engine.end_pass(now);
        next |= self.open_due(engine, now);
        // On disk before anyone is told: an answered engage survives a crash.
        self.keep_locks(engine);
        self.publish(ports, engine, now);
        if reads.tick {
            refresh_description_readers(ports);
        }
        next
    }

    /// Hands every pending request of the sources in `mask` to the engine. Samples are read
    /// before the notification is consumed (a sample is in shared memory before its
    /// notification is sent): the system call waits until the command is out, in
    /// [`Shell::acknowledge_sources`].
    fn read_sources(
        &mut self,
        ports: &Ports,
        engine: &mut Engine,
        now: Timestamp,
        mask: u32,
    ) -> bool {
        let mut any = false;
        for (index, inlet) in ports.sources.iter().enumerate() {
            if mask & (1 << index) == 0 {
                continue;
            }
            loop {
                match inlet.subscriber.receive() {
                    Ok(Some(sample)) => {
                        any = true;
                        // A rejected request is counted and logged by the engine.
                        engine.handle_request(now, index, &sample).ok();
                    }
                    Ok(None) => break,
                    Err(e) => {
                        debug!(source = inlet.name, "receive: {e}");
                        break;
                    }
                }
            }
        }
        any
    }

    /// Consumes the notifications that woke the loop (only a listener that fired is read: an
    /// idle one would cost a system call for nothing), then reads those sources once more: a
    /// request that arrived in between had its notification consumed here.
    fn acknowledge_sources(&mut self, ports: &Ports, engine: &mut Engine, fired: u32) -> bool {
        for (index, inlet) in ports.sources.iter().enumerate() {
            if fired & (1 << index) != 0
                && let Err(e) = inlet.listener.try_wait(|_| {})
            {
                debug!(source = inlet.name, "consuming notifications: {e}");
            }
        }
        fired != 0 && self.read_sources(ports, engine, clock::now(), fired)
    }

    fn read_control(&mut self, ports: &Ports, engine: &mut Engine, now: Timestamp) {
        if let Err(e) = ports.control.listener.try_wait(|_| {}) {
            debug!("consuming control notifications: {e}");
        }
        loop {
            let active = match ports.control.server.receive() {
                Ok(Some(active)) => active,
                Ok(None) => break,
                Err(e) => {
                    debug!("control receive: {e}");
                    break;
                }
            };
            self.next_ticket += 1;
            let ticket = self.next_ticket;
            let request = *active.payload();
            self.pending.insert(ticket, active);
            engine.handle_control(now, ticket, &request);
        }
    }

    /// Fault injection into the simulated chassis: the simulator's business, not the engine's.
    fn handle_sim(&mut self, ports: &Ports, now: Timestamp) {
        let Some(desk) = &ports.sim else {
            return;
        };
        if let Err(e) = desk.listener.try_wait(|_| {}) {
            debug!("consuming simulator notifications: {e}");
        }
        while let Ok(Some(active)) = desk.server.receive() {
            let request = *active.payload();
            let (status, message) = carry_out(
                &request,
                self.sim.as_ref(),
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

    /// Writes what the engine polls; each item is stamped when its write returned (an item a
    /// backend buffered, when the write that carried it returned).
    pub(super) fn transmit(&mut self, engine: &mut Engine, now: Timestamp) -> Next {
        let mut sent = std::mem::take(&mut self.scratch);
        sent.clear();
        // The first of the items the backend still holds.
        let mut buffered_from = None;
        let mut lost = None;
        while let Some(item) = engine.poll_transmit(now) {
            let Some(bus) = self.bus.as_mut() else {
                break;
            };
            match bus.transmit(&item) {
                Ok(()) => {
                    let written = clock::now();
                    sent.push((written, item));
                    if bus.unflushed() == 0 {
                        restamp(&mut sent, buffered_from.take(), written);
                    } else {
                        buffered_from.get_or_insert(sent.len() - 1);
                    }
                }
                Err(err) if err.is_disconnect() => {
                    lost = Some(err);
                    break;
                }
                Err(err) => engine.handle_tx_dropped(now, &err),
            }
        }
        if lost.is_none()
            && let Some(bus) = self.bus.as_mut()
        {
            match bus.flush() {
                Ok(()) => restamp(&mut sent, buffered_from, clock::now()),
                Err(err) if err.is_disconnect() => lost = Some(err),
                Err(err) => engine.handle_tx_dropped(now, &err),
            }
        }
        for (stamp, item) in &sent {
            engine.handle_sent(*stamp, item);
        }
        self.scratch = sent;
        match lost {
            Some(err) => self.lose_bus(engine, now, &err),
            None => Next::Continue,
        }
    }

    fn lose_bus(&mut self, engine: &mut Engine, now: Timestamp, err: &BusError) -> Next {
        self.retired.extend(self.bus.take());
        engine.handle_bus_lost(now, err);
        Next::Rewire
    }

    /// Drains the bus (at most one batch): every item is stamped when read and handed to the
    /// engine; the readers of what it published are woken at once.
    fn read_bus(&mut self, ports: &Ports, engine: &mut Engine) -> Next {
        let Some(bus) = self.bus.as_mut() else {
            return Next::Continue;
        };
        let mut received = std::mem::take(&mut self.scratch);
        received.clear();
        let mut items = 0;
        let result = bus.receive(|rx| {
            let stamp = clock::now();
            items += match rx {
                Rx::Can(_) => 1,
                Rx::Bytes(bytes) => bytes.len().div_ceil(8),
            };
            received.push((
                stamp,
                match rx {
                    Rx::Can(frame) => Transmit::Can(*frame),
                    Rx::Bytes(bytes) => Transmit::Bytes(bytes.to_vec()),
                },
            ));
        });
        // Each sample goes to shared memory as soon as its frame is handled (a polling reader
        // has it at once); the readers are woken once for the whole read.
        let mut woken = Woken::default();
        for (stamp, item) in &received {
            engine.handle_rx(*stamp, item.as_rx());
            woken = self.send(ports, engine, *stamp, woken);
        }
        self.scratch = received;
        let now = clock::now();
        self.wake(ports, engine, now, woken);
        match result {
            Ok(count) => {
                engine.handle_bus_read(now, items, count >= MAX_RX_BATCH);
                Next::Continue
            }
            Err(err) => self.lose_bus(engine, now, &err),
        }
    }

    fn read_gps(&mut self, engine: &mut Engine, now: Timestamp) -> Next {
        let Some(gps) = self.gps.as_mut() else {
            return Next::Continue;
        };
        let result = gps.receive(|rx| {
            if let Rx::Bytes(bytes) = rx {
                engine.handle_gps(now, bytes);
            }
        });
        match result {
            Ok(_) => Next::Continue,
            Err(err) => {
                self.retired.extend(self.gps.take());
                engine.handle_gps_lost(now, &err);
                Next::Rewire
            }
        }
    }

    /// Opens what the engine asks for.
    pub(super) fn open_due(&mut self, engine: &mut Engine, now: Timestamp) -> Next {
        let mut next = Next::Continue;
        while let Some(device) = engine.poll_open(now) {
            match device {
                Device::Bus => {
                    // A simulator thread that ended is replaced by a fresh (power-up) one.
                    self.sim = None;
                    match self.devices.open_bus(now) {
                        Ok((bus, sim)) => {
                            engine.handle_opened(now, device, bus.name());
                            self.bus = Some(bus);
                            self.sim = sim;
                            next = Next::Rewire;
                        }
                        Err(err) => engine.handle_open_failed(now, device, &err),
                    }
                }
                Device::Gps => match self.devices.open_gps() {
                    Ok(gps) => {
                        engine.handle_opened(now, device, gps.name());
                        self.gps = Some(gps);
                        next = Next::Rewire;
                    }
                    Err(err) => engine.handle_open_failed(now, device, &err),
                },
            }
        }
        next
    }

    /// Publishes what the engine produced and wakes the readers: one notification per kind and
    /// batch, not one per sample (every sample is already in shared memory). A failure is
    /// counted by the engine and logged at most once a second.
    pub(super) fn publish(&mut self, ports: &Ports, engine: &mut Engine, now: Timestamp) {
        let woken = self.send(ports, engine, now, Woken::default());
        self.wake(ports, engine, now, woken);
    }

    /// Puts what the engine produced into shared memory, without waking anyone yet (a reader
    /// that polls finds each sample the moment it is sent); returns which readers to wake.
    fn send(&mut self, ports: &Ports, engine: &mut Engine, now: Timestamp, woken: Woken) -> Woken {
        let Woken {
            mut state,
            mut frames,
            mut mux,
            mut answered,
        } = woken;
        let failed = |engine: &mut Engine, what: &'static str, error: &dyn Display| {
            engine.handle_publish_failed(now, what, error);
        };
        while let Some(publication) = engine.poll_publication() {
            match publication {
                Publication::State(mut sample) => match ports.state.publisher.loan_uninit() {
                    Ok(slot) => {
                        sample.published_ns = clock::now().as_nanos();
                        match slot.write_payload(*sample).send() {
                            Ok(_) => state = true,
                            Err(e) => failed(engine, "state", &e),
                        }
                    }
                    Err(e) => failed(engine, "state", &e),
                },
                Publication::Frame(frame) => match ports.frames.publisher.send_copy(frame) {
                    Ok(_) => frames = true,
                    Err(e) => failed(engine, "frame", &e),
                },
                Publication::Mux(status) => match ports.mux.publisher.send_copy(*status) {
                    Ok(_) => mux = true,
                    Err(e) => failed(engine, "mux status", &e),
                },
                // Rare (at start, once detection decides): its readers are woken at once.
                Publication::Description(description) => {
                    let sent = ports.description.publisher.send_copy(*description);
                    match sent.map(|_| ports.description.notifier.notify()) {
                        Ok(Ok(_)) => {}
                        Ok(Err(e)) => failed(engine, "robot description wake-up", &e),
                        Err(e) => failed(engine, "robot description", &e),
                    }
                }
                Publication::Response { ticket, response } => {
                    if let Some(active) = self.pending.remove(&ticket) {
                        match active.send_copy(response) {
                            Ok(()) => answered = true,
                            Err(e) => failed(engine, "control response", &e),
                        }
                    }
                }
            }
        }
        Woken {
            state,
            frames,
            mux,
            answered,
        }
    }

    /// Wakes the readers of what was sent: one notification per kind and batch.
    fn wake(&self, ports: &Ports, engine: &mut Engine, now: Timestamp, woken: Woken) {
        let wake = [
            (woken.state, &ports.state.notifier, "state readers"),
            (woken.frames, &ports.frames.notifier, "frame readers"),
            (woken.mux, &ports.mux.notifier, "mux readers"),
            (woken.answered, &ports.control.notifier, "control clients"),
        ];
        for (_, notifier, what) in wake.into_iter().filter(|(any, _, _)| *any) {
            if let Err(e) = notifier.notify() {
                engine.handle_publish_failed(now, what, &e);
            }
        }
    }
}

/// Readers with something new to be woken for.
#[derive(Debug, Default, Clone, Copy)]
struct Woken {
    state: bool,
    frames: bool,
    mux: bool,
    answered: bool,
}

/// The items from `from` on were written by the write that returned at `written`.
fn restamp(sent: &mut [(Timestamp, Transmit)], from: Option<usize>, written: Timestamp) {
    if let Some(from) = from {
        for (stamp, _) in sent.iter_mut().skip(from) {
            *stamp = written;
        }
    }
}
