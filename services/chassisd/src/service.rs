//! The service's event loop: one thread owns the bus, the driver, the mux and every port.
//!
//! An iceoryx2 `WaitSet` waits on the bus descriptor, the GPS descriptor, the listeners of every
//! source, of `control` and of `sim`, and the tick — with a timeout at the driver's or the mux's
//! next deadline. Nothing sleeps and nothing polls. Single-threaded means decode, mux and
//! transmit never lock each other and ports never cross threads.

use std::collections::HashMap;
use std::time::Duration;

use chassis_interfaces::{
    BusFrame, ChassisState, ControlResponse, ControlStatus, FrameDirection, FrameKind, GROUP_SLOTS,
    GpsFix, Group, LinkFlags, MuxStatus, SourceStatus, ZeroReason,
};
use chassis_protocols::{
    ControlAction, ControlOutcome, Driver, DriverConfig, DriverEvent, Profile, Rx, Timestamp,
    Transmit, nmea, request_to_action, scout_mini, time::Grid, titan, xbot,
};
use iceoryx2::active_request::ActiveRequest;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use iceoryx2_bb_posix::file_descriptor::{FileDescriptor, FileDescriptorBased};
use iceoryx2_bb_posix::file_descriptor_set::SynchronousMultiplexing;
use tracing::{debug, error, info, info_span, warn};
use zerocopy::IntoBytes;

use crate::bus::{Bus, BusError, BusSpec, datagram, serial, slcan, socketcan};
use crate::clock;
use crate::config::{Config, LoopMode};
use crate::ipc::{Inlet, IpcError, Ports};
use crate::moderation::{RxGate, RxModeration};
use crate::mux::Mux;
use crate::sim::{SimHandle, firmware_for, injection_of};

/// The robot's driver behind the common contract.
pub type BoxedDriver = Box<dyn Driver>;

/// The driver of `profile`'s robot.
pub fn driver_for(profile: &Profile, config: &DriverConfig, now: Timestamp) -> BoxedDriver {
    match profile {
        Profile::Titan(p) => Box::new(titan::TitanDriver::new(p.clone(), config.clone(), now)),
        Profile::ScoutMini(p) => Box::new(scout_mini::ScoutMiniDriver::new(
            p.clone(),
            config.clone(),
            now,
        )),
        Profile::Xbot(p) => Box::new(xbot::XbotDriver::new(p.clone(), config.clone(), now)),
    }
}

/// Why the service stopped.
#[derive(Debug, thiserror::Error)]
pub enum ServiceError {
    #[error(transparent)]
    Ipc(#[from] IpcError),
    #[error("{0}")]
    Setup(String),
    #[error("iceoryx2 wait set: {0}")]
    WaitSet(String),
}

/// A bus descriptor the wait set can watch (it does not own the descriptor).
#[derive(Debug)]
struct FdAttachment(FileDescriptor);

impl FdAttachment {
    fn new(raw: i32) -> Option<Self> {
        FileDescriptor::non_owning_new(raw).map(Self)
    }
}

impl FileDescriptorBased for FdAttachment {
    fn file_descriptor(&self) -> &FileDescriptor {
        &self.0
    }
}

impl SynchronousMultiplexing for FdAttachment {}

/// Opens the bus named by `spec` for the service (the simulator gets its own thread).
pub fn open_bus(spec: &BusSpec, config: &Config) -> Result<(Bus, Option<SimHandle>), BusError> {
    let robot = config.robot;
    let serial_baud = |baud: Option<u32>| {
        baud.unwrap_or(match &config.profile {
            Profile::Xbot(p) => p.baud,
            _ => 115_200,
        })
    };
    Ok(match spec {
        BusSpec::Sim => {
            let now = clock::now();
            let firmware = firmware_for(&config.profile, now);
            let io = |e: std::io::Error| BusError::Open {
                name: "sim".into(),
                reason: e.to_string(),
            };
            let (ours, theirs) = if robot.is_can() {
                let (a, b) = datagram::PairCan::pair("sim").map_err(io)?;
                (Bus::Can(Box::new(a)), Bus::Can(Box::new(b)))
            } else {
                let (a, b) = datagram::StreamBytes::pair("sim").map_err(io)?;
                (Bus::Bytes(Box::new(a)), Bus::Bytes(Box::new(b)))
            };
            // A pinned loop leaves the other CPUs to its simulated chassis.
            let others: Vec<usize> = match config.cpu {
                Some(cpu) => (0..std::thread::available_parallelism().map_or(1, |n| n.get()))
                    .filter(|&c| c != cpu)
                    .collect(),
                None => Vec::new(),
            };
            let handle = SimHandle::spawn_on(firmware, theirs, &others).map_err(io)?;
            (ours, Some(handle))
        }
        BusSpec::Can { iface } => (Bus::Can(Box::new(socketcan::SocketCan::open(iface)?)), None),
        BusSpec::Serial { path, baud } => {
            let port = serial::SerialBus::open(path, serial_baud(*baud))?;
            if robot.is_can() {
                return Err(BusError::Open {
                    name: spec.to_string(),
                    reason: format!("{robot} is a CAN robot: use can:IFACE or slcan:PATH"),
                });
            }
            (Bus::Bytes(Box::new(port)), None)
        }
        BusSpec::Slcan { path, baud } => {
            if !robot.is_can() {
                return Err(BusError::Open {
                    name: spec.to_string(),
                    reason: format!("{robot} speaks RS232: use serial:PATH"),
                });
            }
            let port = serial::SerialBus::open(path, serial_baud(*baud))?;
            let bus = slcan::SlcanBus::open(port, config.bus_settings.can_bitrate)?;
            (Bus::Can(Box::new(bus)), None)
        }
        BusSpec::Replay { path, speed } => (crate::bus::replay::open(path, *speed, robot)?, None),
        BusSpec::Pty { .. } | BusSpec::SlcanPty { .. } => {
            return Err(BusError::Open {
                name: spec.to_string(),
                reason: "pty links are made by `chassisd sim`, not opened by the service".into(),
            });
        }
    })
}

/// At most one log line per second per kind, with the number held back.
#[derive(Debug, Default)]
struct Throttle {
    last: Option<Timestamp>,
    held_back: u64,
}

impl Throttle {
    /// `Some(n)` when a line may be written now (`n` = lines held back since the last one).
    fn allow(&mut self, now: Timestamp) -> Option<u64> {
        match self.last {
            Some(t) if now.saturating_since(t) < Duration::from_secs(1) => {
                self.held_back += 1;
                None
            }
            _ => {
                self.last = Some(now);
                Some(std::mem::take(&mut self.held_back))
            }
        }
    }
}

type PendingControl =
    ActiveRequest<ipc::Service, chassis_interfaces::ControlRequest, (), ControlResponse, ()>;

/// What woke the loop.
#[derive(Debug, Default, Clone, Copy)]
struct Fired {
    bus: bool,
    gps: bool,
    /// One bit per source inlet whose listener fired (at most `MAX_SOURCES`, 8).
    sources: u32,
    control: bool,
    sim: bool,
    tick: bool,
    /// The loop polled instead of blocking (spin, or hybrid while hot): read every source's
    /// shared memory, without waiting for its notification to come through the kernel.
    polled: bool,
}

/// How an iteration ended.
enum Next {
    Continue,
    /// The bus (or GPS) was lost or reopened: rebuild the wait set.
    Rewire,
}

/// Everything the loop mutates.
struct Core {
    config: Config,
    driver: BoxedDriver,
    mux: Mux,
    bus: Option<Bus>,
    sim: Option<SimHandle>,
    bus_retry_at: Option<Timestamp>,
    bus_backoff: Duration,
    gps: Option<Bus>,
    gps_reader: nmea::LineReader,
    gps_fix: GpsFix,
    gps_stamp_ns: u64,
    gps_retry_at: Option<Timestamp>,
    state_seq: u64,
    frame_seq: u64,
    mux_seq: u64,
    last_state_body: Option<ChassisState>,
    last_state_publish: Timestamp,
    last_mux_publish: Timestamp,
    last_rx_frames: u64,
    pending_controls: HashMap<u64, (PendingControl, u64)>,
    last_zero_reason: u8,
    last_active: u8,
    throttle_rx: Throttle,
    throttle_rejected: Throttle,
    throttle_tx: Throttle,
    throttle_publish: Throttle,
    throttle_flood: Throttle,
    /// The loop's own tick: mux re-evaluation, smoothing, state refresh.
    tick: Grid,
    /// When something last woke the loop (hybrid mode keeps polling for a while after it).
    last_activity: Timestamp,
    /// Buses (and GPS ports) that failed: their descriptors stay open until the wait set that
    /// watches them is gone.
    retired: Vec<Bus>,
    /// Frames between the bus and their publication, kept to spare an allocation per batch.
    scratch: Vec<(Timestamp, Transmit)>,
    /// Whether the bus descriptor is watched (see [`RxModeration`]).
    rx_moderation: RxModeration,
    /// Samples were published since readers were last woken.
    wake_state_readers: bool,
    wake_frame_readers: bool,
}

/// The part of a state sample that changes only when the chassis reports something new.
fn state_body(state: &ChassisState) -> ChassisState {
    ChassisState {
        seq: 0,
        stamp_ns: 0,
        group_stamp_ns: [0; GROUP_SLOTS],
        link: Default::default(),
        ..*state
    }
}

impl Core {
    fn publish_state(&mut self, ports: &Ports, now: Timestamp) {
        let mut state = *self.driver.state();
        if self.gps_stamp_ns != 0 {
            state.gps = self.gps_fix;
            state.touch(Group::Gps, self.gps_stamp_ns);
        }
        if self.config.gps.is_some() && self.gps.is_none() {
            state.link_flags |= LinkFlags::GPS_DOWN;
        }
        self.state_seq += 1;
        state.seq = self.state_seq;
        self.last_rx_frames = state.link.rx_frames;
        self.last_state_body = Some(state_body(&state));
        self.last_state_publish = now;
        let sent = ports
            .state
            .publisher
            .loan_uninit()
            .map(|sample| sample.write_payload(state))
            .map_err(|e| format!("{e:?}"))
            .and_then(|sample| sample.send().map_err(|e| format!("{e:?}")));
        match sent {
            Ok(_) => self.wake_state_readers = true,
            Err(reason) => {
                if let Some(held) = self.throttle_publish.allow(now) {
                    warn!(held_back = held, "cannot publish state: {reason}");
                }
            }
        }
    }

    /// Publishes the state if the frames just handled changed it.
    fn publish_state_if_changed(&mut self, ports: &Ports, now: Timestamp) {
        let body = state_body(self.driver.state());
        let changed = self
            .last_state_body
            .is_none_or(|last| last.as_bytes() != body.as_bytes());
        if changed {
            self.publish_state(ports, now);
        }
    }

    fn publish_frame(
        &mut self,
        ports: &Ports,
        stamp: Timestamp,
        direction: u8,
        kind: u8,
        item: Rx<'_>,
    ) {
        let publish = |frame: BusFrame| {
            let _ = ports.frames.publisher.send_copy(frame);
        };
        match item {
            Rx::Can(can) => {
                self.frame_seq += 1;
                let mut frame = BusFrame {
                    stamp_ns: stamp.as_nanos(),
                    seq: self.frame_seq,
                    can_id: can.id(),
                    direction,
                    kind: FrameKind::CAN,
                    flags: if can.is_extended() {
                        BusFrame::EXTENDED_ID
                    } else {
                        0
                    },
                    ..BusFrame::default()
                };
                frame.set_payload(can.data());
                publish(frame);
            }
            Rx::Bytes(bytes) => {
                for chunk in bytes.chunks(BusFrame::DATA_LEN) {
                    self.frame_seq += 1;
                    let mut frame = BusFrame {
                        stamp_ns: stamp.as_nanos(),
                        seq: self.frame_seq,
                        direction,
                        kind,
                        ..BusFrame::default()
                    };
                    frame.set_payload(chunk);
                    publish(frame);
                }
            }
        }
        self.wake_frame_readers = true;
    }

    /// Wakes the readers of what was published since the last call: one notification per batch
    /// of frames, not one per frame (every sample is already in shared memory).
    fn wake_readers(&mut self, ports: &Ports) {
        if std::mem::take(&mut self.wake_state_readers) {
            let _ = ports.state.notifier.notify();
        }
        if std::mem::take(&mut self.wake_frame_readers) {
            let _ = ports.frames.notifier.notify();
        }
    }

    fn publish_mux(&mut self, ports: &Ports, now: Timestamp) {
        let mut status: MuxStatus = *self.mux.status();
        // The robot's own limits (applied by the driver) are clamps too.
        status.clamp_flags |= self.driver.state().command.clamp_flags;
        self.mux_seq += 1;
        status.seq = self.mux_seq;
        self.last_mux_publish = now;
        if ports.mux.publisher.send_copy(status).is_ok() {
            let _ = ports.mux.notifier.notify();
        }
    }

    fn bus_lost(&mut self, now: Timestamp, err: &BusError) {
        error!("{err}; commanding nothing until it is back, retrying");
        self.retired.extend(self.bus.take());
        self.driver.set_bus_down(now, true);
        self.bus_retry_at = Some(now + self.bus_backoff);
    }

    fn try_reopen_bus(&mut self, now: Timestamp) -> Next {
        if self.bus_retry_at.is_none_or(|t| now < t) {
            return Next::Continue;
        }
        // A simulator thread that ended is replaced by a fresh (power-up) one.
        self.sim = None;
        match open_bus(&self.config.bus, &self.config) {
            Ok((bus, sim)) => {
                info!(bus = bus.name(), "bus open again");
                self.bus = Some(bus);
                self.sim = sim;
                self.bus_retry_at = None;
                self.rx_moderation.reset(now);
                self.bus_backoff =
                    Duration::from_millis(self.config.bus_settings.reconnect_initial_ms);
                self.driver.set_bus_down(now, false);
                Next::Rewire
            }
            Err(err) => {
                debug!("reopening the bus: {err}");
                self.bus_backoff = (self.bus_backoff * 2).min(Duration::from_millis(
                    self.config.bus_settings.reconnect_max_ms,
                ));
                self.bus_retry_at = Some(now + self.bus_backoff);
                Next::Continue
            }
        }
    }

    fn try_reopen_gps(&mut self, now: Timestamp) -> Next {
        let (Some(spec), None) = (&self.config.gps, &self.gps) else {
            return Next::Continue;
        };
        if self.gps_retry_at.is_some_and(|t| now < t) {
            return Next::Continue;
        }
        let BusSpec::Serial { path, baud } = spec else {
            return Next::Continue;
        };
        let gps_baud = match &self.config.profile {
            Profile::Xbot(p) => p.gps_baud,
            _ => 4800,
        };
        match serial::SerialBus::open(path, baud.unwrap_or(gps_baud)) {
            Ok(port) => {
                info!(gps = spec.to_string(), "GPS receiver open");
                self.gps = Some(Bus::Bytes(Box::new(port)));
                self.gps_retry_at = None;
                Next::Rewire
            }
            Err(err) => {
                debug!("opening the GPS receiver: {err}");
                self.gps_retry_at = Some(now + Duration::from_secs(1));
                Next::Continue
            }
        }
    }

    fn handle_bus(&mut self, ports: &Ports) -> Next {
        let Some(bus) = self.bus.as_mut() else {
            return Next::Continue;
        };
        let kind = if bus.is_can() {
            FrameKind::CAN
        } else {
            FrameKind::SERIAL
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
        for (stamp, item) in &received {
            self.publish_frame(ports, *stamp, FrameDirection::RX, kind, item.as_rx());
            self.driver.handle_rx(*stamp, item.as_rx());
            self.publish_state_if_changed(ports, *stamp);
        }
        self.scratch = received;
        self.wake_readers(ports);
        match result {
            Ok(count) => {
                let backlog = count >= crate::bus::MAX_RX_BATCH;
                self.rx_moderation.on_read(clock::now(), items, backlog);
                Next::Continue
            }
            Err(err) => {
                self.bus_lost(clock::now(), &err);
                Next::Rewire
            }
        }
    }

    fn handle_gps(&mut self, ports: &Ports, now: Timestamp) -> Next {
        let Some(gps) = self.gps.as_mut() else {
            return Next::Continue;
        };
        let mut chunks: Vec<Vec<u8>> = Vec::new();
        let result = gps.receive(|rx| {
            if let Rx::Bytes(bytes) = rx {
                chunks.push(bytes.to_vec());
            }
        });
        for chunk in &chunks {
            self.publish_frame(
                ports,
                now,
                FrameDirection::RX,
                FrameKind::GPS,
                Rx::Bytes(chunk),
            );
            self.gps_reader.push(chunk);
        }
        while let Some(line) = self.gps_reader.next_line() {
            match nmea::parse_sentence(&line) {
                Ok(sentence) => {
                    nmea::apply(&sentence, &mut self.gps_fix);
                    self.gps_stamp_ns = now.as_nanos();
                }
                Err(err) => {
                    if let Some(held) = self.throttle_rx.allow(now) {
                        warn!(held_back = held, "GPS sentence dropped: {err}");
                    }
                }
            }
        }
        match result {
            Ok(_) => Next::Continue,
            Err(err) => {
                error!("GPS receiver lost: {err}; retrying");
                self.retired.extend(self.gps.take());
                self.gps_retry_at = Some(now + Duration::from_secs(1));
                Next::Rewire
            }
        }
    }

    /// Feeds the mux every pending request of the sources that notified — of all of them on the
    /// tick (which also catches a publisher that never notifies) and when the loop polls.
    /// Samples are read before the notification is consumed (a sample is in shared memory
    /// before its notification is sent): the system call waits until the command is out, in
    /// [`Core::acknowledge_sources`].
    fn handle_sources(&mut self, ports: &Ports, now: Timestamp, fired: Fired) -> bool {
        let mut any = false;
        for (index, inlet) in ports.sources.iter().enumerate() {
            if fired.sources & (1 << index) != 0 || fired.tick || fired.polled {
                any |= self.drain_source(index, inlet, now);
            }
        }
        any
    }

    /// Consumes the notifications that woke the loop (only a listener that fired is read: an
    /// idle one would cost a system call for nothing), then reads those sources once more: a
    /// request that arrived in between had its notification consumed here.
    fn acknowledge_sources(&mut self, ports: &Ports, now: Timestamp, fired: Fired) -> bool {
        let mut any = false;
        for (index, inlet) in ports.sources.iter().enumerate() {
            if fired.sources & (1 << index) != 0 {
                let _ = inlet.listener.try_wait(|_| {});
                any |= self.drain_source(index, inlet, now);
            }
        }
        any
    }

    fn drain_source(&mut self, index: usize, inlet: &Inlet, now: Timestamp) -> bool {
        let mut any = false;
        loop {
            match inlet.subscriber.receive() {
                Ok(Some(sample)) => {
                    any = true;
                    if let Err(rejection) = self.mux.on_request(now, index, &sample)
                        && let Some(held) = self.throttle_rejected.allow(now)
                    {
                        warn!(
                            source = inlet.name,
                            held_back = held,
                            "request rejected: {rejection}"
                        );
                    }
                }
                Ok(None) => return any,
                Err(e) => {
                    debug!(source = inlet.name, "receive: {e:?}");
                    return any;
                }
            }
        }
    }

    /// Runs the mux and hands its output to the driver; sends what is due. True when the
    /// mux's decision changed.
    fn decide(&mut self, ports: &Ports, now: Timestamp, next: &mut Next) -> bool {
        let decision = self.mux.evaluate(now);
        self.driver.set_command(now, &decision.output);
        if let Next::Rewire = self.transmit(ports, now) {
            *next = Next::Rewire;
        }
        if decision.changed {
            self.log_mux_change();
        }
        decision.changed
    }

    fn respond(ports: &Ports, request: &PendingControl, response: ControlResponse) {
        if let Err(e) = request.send_copy(response) {
            warn!("cannot answer a control request: {e:?}");
        }
        let _ = ports.control.notifier.notify();
    }

    fn handle_control(&mut self, ports: &Ports, now: Timestamp) {
        let _ = ports.control.listener.try_wait(|_| {});
        loop {
            let active = match ports.control.server.receive() {
                Ok(Some(active)) => active,
                Ok(None) => break,
                Err(e) => {
                    debug!("control receive: {e:?}");
                    break;
                }
            };
            let request = *active.payload();
            let seq = request.seq;
            let response = |status: u8, message: String| {
                let mut r = ControlResponse::new(seq, status, &message);
                r.stamp_ns = now.as_nanos();
                (status, message, r)
            };
            let (status, message, answer) = match request_to_action(&request) {
                Err(reason) => response(ControlStatus::INVALID, reason),
                Ok(ControlAction::LockRelease(name)) => match self.mux.release_lock(&name) {
                    Ok(true) => response(ControlStatus::OK, format!("{name} released")),
                    Ok(false) => response(ControlStatus::OK, format!("{name} was not held")),
                    Err(reason) => response(ControlStatus::INVALID, reason),
                },
                Ok(ControlAction::LockEngage(name)) => match self.mux.engage_lock(now, &name) {
                    Ok(true) => {
                        response(ControlStatus::OK, format!("{name} engaged by the operator"))
                    }
                    Ok(false) => response(ControlStatus::OK, format!("{name} was already held")),
                    Err(reason) => response(ControlStatus::INVALID, reason),
                },
                Ok(ControlAction::Chassis(command)) => match self.driver.control(now, &command) {
                    ControlOutcome::Pending(token) => {
                        info!(
                            request = command.name(),
                            "control request waiting for the chassis"
                        );
                        self.pending_controls.insert(token, (active, seq));
                        continue;
                    }
                    outcome => response(outcome.status(), outcome.message()),
                },
            };
            let level_ok = status == ControlStatus::OK;
            if level_ok {
                info!(
                    kind = chassis_interfaces::ControlKind::name(request.kind),
                    "control: {message}"
                );
            } else {
                warn!(
                    kind = chassis_interfaces::ControlKind::name(request.kind),
                    status = ControlStatus::name(status),
                    "control refused: {message}"
                );
            }
            Self::respond(ports, &active, answer);
        }
    }

    fn handle_sim(&mut self, ports: &Ports, now: Timestamp) {
        let Some(desk) = &ports.sim else {
            return;
        };
        let _ = desk.listener.try_wait(|_| {});
        while let Ok(Some(active)) = desk.server.receive() {
            let request = *active.payload();
            let (status, message) = match (injection_of(&request), &self.sim) {
                (Err(reason), _) => (ControlStatus::INVALID, reason),
                (Ok(_), None) => (
                    ControlStatus::UNSUPPORTED,
                    "the bus is not the simulator".to_string(),
                ),
                (Ok(injection), Some(sim)) => {
                    let name = injection.name();
                    match sim.inject(injection) {
                        Ok(true) => (ControlStatus::OK, format!("{name} injected")),
                        Ok(false) => (
                            ControlStatus::UNSUPPORTED,
                            format!("the simulated {} has no {name}", sim.robot()),
                        ),
                        Err(reason) => (ControlStatus::REFUSED, reason),
                    }
                }
            };
            info!(status = ControlStatus::name(status), "simulator: {message}");
            let mut response = ControlResponse::new(request.seq, status, &message);
            response.stamp_ns = now.as_nanos();
            if let Err(e) = active.send_copy(response) {
                warn!("cannot answer a simulator request: {e:?}");
            }
            let _ = desk.notifier.notify();
        }
    }

    fn drain_driver_events(&mut self, ports: &Ports, now: Timestamp) {
        while let Some(event) = self.driver.poll_event() {
            match event {
                DriverEvent::ControlDone {
                    token,
                    status,
                    message,
                } => {
                    if let Some((active, seq)) = self.pending_controls.remove(&token) {
                        info!(status = ControlStatus::name(status), "control: {message}");
                        let mut response = ControlResponse::new(seq, status, &message);
                        response.stamp_ns = now.as_nanos();
                        Self::respond(ports, &active, response);
                    }
                }
                DriverEvent::RxDropped { reason } => {
                    if let Some(held) = self.throttle_rx.allow(now) {
                        warn!(held_back = held, "frame dropped: {reason}");
                    }
                }
                DriverEvent::Notice { level, message } => match level {
                    chassis_protocols::driver::Level::Info => info!("{message}"),
                    chassis_protocols::driver::Level::Warn => warn!("{message}"),
                    chassis_protocols::driver::Level::Error => error!("{message}"),
                },
            }
        }
    }

    fn transmit(&mut self, ports: &Ports, now: Timestamp) -> Next {
        let Some(bus) = self.bus.as_mut() else {
            // Nothing can be sent; the driver does not queue while the bus is down.
            while self.driver.poll_transmit(now).is_some() {}
            return Next::Continue;
        };
        let kind = if bus.is_can() {
            FrameKind::CAN
        } else {
            FrameKind::SERIAL
        };
        let mut sent = std::mem::take(&mut self.scratch);
        sent.clear();
        let mut failure = None;
        while let Some(item) = self.driver.poll_transmit(now) {
            match bus.transmit(&item) {
                Ok(()) => sent.push((clock::now(), item)),
                Err(err) if err.is_disconnect() => {
                    failure = Some(err);
                    break;
                }
                Err(err) => {
                    if let Some(held) = self.throttle_tx.allow(now) {
                        warn!(held_back = held, "{err}");
                    }
                }
            }
        }
        if failure.is_none()
            && let Err(err) = bus.flush()
        {
            if err.is_disconnect() {
                failure = Some(err);
            } else if let Some(held) = self.throttle_tx.allow(now) {
                warn!(held_back = held, "{err}");
            }
        }
        for (stamp, item) in &sent {
            self.publish_frame(ports, *stamp, FrameDirection::TX, kind, item.as_rx());
        }
        self.scratch = sent;
        match failure {
            Some(err) => {
                self.bus_lost(now, &err);
                Next::Rewire
            }
            None => Next::Continue,
        }
    }

    fn log_mux_change(&mut self) {
        let status = *self.mux.status();
        if status.zero_reason != self.last_zero_reason {
            let required: Vec<&str> = status
                .sources()
                .iter()
                .filter(|s| s.has(chassis_interfaces::SourceFlags::REQUIRED))
                .filter(|s| !s.has(chassis_interfaces::SourceFlags::FRESH))
                .map(SourceStatus::name)
                .collect();
            match status.zero_reason {
                ZeroReason::REQUIRED_SOURCE_STALE => error!(
                    "safe stop: required source {} is silent",
                    required.join(", ")
                ),
                ZeroReason::LOCKED => warn!("stopped: a lock blocks every source"),
                ZeroReason::NO_ACTIVE_SOURCE if self.last_zero_reason != ZeroReason::STARTING => {
                    info!("no active source: commanding zero")
                }
                _ => {}
            }
        }
        if status.active_source != self.last_active {
            match status.active() {
                Some(source) => info!(
                    source = source.name(),
                    priority = source.priority,
                    "active source"
                ),
                None => debug!("no active source"),
            }
        }
        self.last_zero_reason = status.zero_reason;
        self.last_active = status.active_source;
    }

    /// One pass after a wake-up. Requests go first and reach the bus before anything else is
    /// read: the command path is the one whose latency matters, and waking the readers of
    /// received frames could hand the CPU to them before the command is out.
    fn iteration(&mut self, ports: &Ports, mut fired: Fired) -> Next {
        let mut next = Next::Continue;
        let woke = clock::now();
        if fired.bus || fired.gps || fired.sources != 0 || fired.control || fired.sim {
            self.last_activity = woke;
        }
        if self.tick.is_due(woke) {
            self.tick.served(woke);
            fired.tick = true;
        }
        let mut requests = self.handle_sources(ports, woke, fired);
        if fired.control || fired.tick {
            self.handle_control(ports, woke);
        }
        if fired.sim || fired.tick {
            self.handle_sim(ports, woke);
        }
        let mut changed = self.decide(ports, woke, &mut next);
        if self.acknowledge_sources(ports, woke, fired) {
            requests = true;
            changed |= self.decide(ports, clock::now(), &mut next);
        }

        if (fired.bus || self.bus.is_some() && fired.tick)
            && let Next::Rewire = self.handle_bus(ports)
        {
            next = Next::Rewire;
        }
        let now = clock::now();
        if fired.gps
            && let Next::Rewire = self.handle_gps(ports, now)
        {
            next = Next::Rewire;
        }
        if self.driver.poll_timeout().is_some_and(|t| t <= now) {
            self.driver.handle_timeout(now);
        }
        // What the received frames and the driver's timers asked to send.
        if let Next::Rewire = self.transmit(ports, now) {
            next = Next::Rewire;
        }
        self.drain_driver_events(ports, now);

        let mux_period = Duration::from_secs_f64(1.0 / self.config.mux_status_hz);
        if changed
            || requests && self.mux.is_ramping()
            || now.saturating_since(self.last_mux_publish) >= mux_period
        {
            self.publish_mux(ports, now);
        }
        // On the tick, refresh the stamps readers judge staleness by (frames arrived whose
        // content did not change the sample), and publish flag changes; at least every 100 ms.
        if fired.tick {
            let rx_frames = self.driver.state().link.rx_frames;
            if rx_frames != self.last_rx_frames
                || now.saturating_since(self.last_state_publish) >= Duration::from_millis(100)
            {
                self.publish_state(ports, now);
            } else {
                self.publish_state_if_changed(ports, now);
            }
        }

        if let Next::Rewire = self.try_reopen_bus(now) {
            next = Next::Rewire;
        }
        if let Next::Rewire = self.try_reopen_gps(now) {
            next = Next::Rewire;
        }
        self.wake_readers(ports);
        next
    }

    /// How long the loop waits, by its mode: event-driven blocks until the next deadline, spin
    /// never blocks, hybrid polls for `spin_us` after each activity and then blocks.
    fn wait_time(&self, now: Timestamp) -> Duration {
        match self.config.loop_mode {
            LoopMode::Event => self.timeout(now),
            LoopMode::Spin => Duration::ZERO,
            LoopMode::Hybrid => {
                if now.saturating_since(self.last_activity)
                    < Duration::from_micros(self.config.spin_us)
                {
                    Duration::ZERO
                } else {
                    self.timeout(now)
                }
            }
        }
    }

    /// How long the loop may block before its next deadline.
    fn timeout(&self, now: Timestamp) -> Duration {
        let deadlines = [
            Some(self.tick.next()),
            self.rx_moderation.paused_until(),
            self.driver.poll_timeout(),
            self.mux.next_deadline(now),
            self.bus_retry_at,
            self.gps_retry_at,
        ];
        deadlines
            .into_iter()
            .flatten()
            .min()
            .map_or(Duration::from_millis(self.config.tick_ms), |t| {
                t.saturating_since(now)
            })
    }

    fn shutdown(&mut self, ports: &Ports) {
        let now = clock::now();
        info!("stopping: commanding zero and engaging the brake where there is one");
        self.driver.shutdown(now);
        let _ = self.transmit(ports, now);
        self.publish_state(ports, now);
        self.publish_mux(ports, now);
        self.wake_readers(ports);
        for (_, (active, seq)) in self.pending_controls.drain() {
            let response =
                ControlResponse::new(seq, ControlStatus::REFUSED, "the service is stopping");
            let _ = active.send_copy(response);
        }
    }
}

fn set_gate(gate: &mut RxGate, open: bool) {
    if let Err(e) = gate.set_open(open) {
        warn!("bus gate: {e}");
    }
}

/// Pins the calling thread to `cpu`.
pub fn pin_to_cpu(cpu: usize) -> Result<(), String> {
    use nix::sched::{CpuSet, sched_setaffinity};
    let mut set = CpuSet::new();
    set.set(cpu).map_err(|e| format!("CPU {cpu}: {e}"))?;
    sched_setaffinity(nix::unistd::Pid::from_raw(0), &set)
        .map_err(|e| format!("pinning to CPU {cpu}: {e}"))
}

/// Runs the service until SIGINT or SIGTERM. Returns after commanding zero.
pub fn run(config: Config) -> Result<(), ServiceError> {
    let span = info_span!(
        "chassisd",
        robot = config.robot.name(),
        name = config.name.as_str()
    );
    let _guard = span.enter();
    if config.no_safety_monitor {
        warn!(
            "--no-safety-monitor: the robot moves without a safety monitor; no required source \
             guards it"
        );
    }
    if let Some(cpu) = config.cpu {
        pin_to_cpu(cpu).map_err(ServiceError::Setup)?;
        info!(cpu, "loop pinned");
    }
    if config.loop_mode != LoopMode::Event {
        info!(mode = ?config.loop_mode, spin_us = config.spin_us, "loop polls instead of blocking");
    }
    let sources: Vec<String> = config.mux.sources.iter().map(|s| s.name.clone()).collect();
    let with_sim = config.bus == BusSpec::Sim;
    let ports = Ports::open(&config.name, &sources, with_sim)?;
    let now = clock::now();
    let driver = driver_for(&config.profile, &config.driver, now);
    let mux = Mux::new(&config.mux).map_err(|e| ServiceError::Setup(e.to_string()))?;
    let (bus, sim, retry) = match open_bus(&config.bus, &config) {
        Ok((bus, sim)) => (Some(bus), sim, None),
        Err(err) => {
            error!("{err}; retrying");
            (None, None, Some(now))
        }
    };
    info!(
        bus = config.bus.to_string(),
        sources = sources.join(","),
        "serving chassis/{}/",
        config.name
    );
    let mut core = Core {
        bus_backoff: Duration::from_millis(config.bus_settings.reconnect_initial_ms),
        driver,
        mux,
        bus,
        sim,
        bus_retry_at: retry,
        gps: None,
        gps_reader: nmea::LineReader::new(),
        gps_fix: GpsFix::default(),
        gps_stamp_ns: 0,
        gps_retry_at: None,
        state_seq: 0,
        frame_seq: 0,
        mux_seq: 0,
        last_state_body: None,
        last_state_publish: now,
        last_mux_publish: Timestamp::ZERO,
        last_rx_frames: 0,
        pending_controls: HashMap::new(),
        last_zero_reason: ZeroReason::STARTING,
        last_active: MuxStatus::NO_SOURCE,
        throttle_rx: Throttle::default(),
        throttle_rejected: Throttle::default(),
        throttle_tx: Throttle::default(),
        throttle_publish: Throttle::default(),
        throttle_flood: Throttle::default(),
        tick: Grid::new(Duration::from_millis(config.tick_ms), now),
        last_activity: now,
        retired: Vec::new(),
        wake_state_readers: false,
        wake_frame_readers: false,
        scratch: Vec::with_capacity(crate::bus::MAX_RX_BATCH),
        // A spinning loop spends its core anyway: it reads every frame the moment it arrives.
        rx_moderation: RxModeration::new(
            match config.loop_mode {
                LoopMode::Spin => Duration::ZERO,
                _ => Duration::from_micros(config.bus_settings.rx_moderation_us),
            },
            now,
        ),
        config,
    };
    if core.bus.is_none() {
        core.driver.set_bus_down(now, true);
    }
    let _ = core.try_reopen_gps(now);
    core.publish_state(&ports, now);
    core.wake_readers(&ports);

    let mut gate = RxGate::new().map_err(|e| ServiceError::Setup(format!("bus gate: {e}")))?;
    loop {
        // The previous session's wait set is gone: failed buses can close now.
        core.retired.clear();
        // One wait set per bus session: the bus descriptor changes when the bus is reopened.
        let waitset = WaitSetBuilder::new()
            .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
            .create::<ipc::Service>()
            .map_err(|e| ServiceError::WaitSet(format!("{e:?}")))?;
        let attach_err = |e| ServiceError::WaitSet(format!("{e:?}"));
        let gps_fd = core
            .gps
            .as_ref()
            .and_then(|b| FdAttachment::new(b.raw_fd()));
        // The bus is watched through the gate receive moderation closes while it pauses.
        gate.watch(core.bus.as_ref().map(Bus::raw_fd))
            .map_err(|e| ServiceError::Setup(format!("bus gate: {e}")))?;
        let gate_fd = core
            .bus
            .as_ref()
            .and_then(|_| FdAttachment::new(gate.raw_fd()));
        let bus_guard = gate_fd
            .as_ref()
            .map(|fd| waitset.attach_notification(fd))
            .transpose()
            .map_err(attach_err)?;
        let gps_guard = gps_fd
            .as_ref()
            .map(|fd| waitset.attach_notification(fd))
            .transpose()
            .map_err(attach_err)?;
        let mut source_guards = ports
            .sources
            .iter()
            .map(|inlet| waitset.attach_notification(&inlet.listener).map(Some))
            .collect::<Result<Vec<_>, _>>()
            .map_err(attach_err)?;
        let safety_sources = (0..ports.sources.len())
            .filter(|&i| core.mux.is_safety_source(i))
            .fold(0u32, |mask, i| mask | 1 << i);
        let mut budget = WakeBudget::new(ports.sources.len(), core.tick.next(), safety_sources);
        let control_guard = waitset
            .attach_notification(&ports.control.listener)
            .map_err(attach_err)?;
        let sim_guard = ports
            .sim
            .as_ref()
            .map(|desk| waitset.attach_notification(&desk.listener))
            .transpose()
            .map_err(attach_err)?;

        loop {
            let timeout = core.wait_time(clock::now());
            let mut fired = Fired {
                polled: timeout.is_zero(),
                ..Fired::default()
            };
            let result = waitset.wait_and_process_once_with_timeout(
                |id| {
                    if bus_guard.as_ref().is_some_and(|g| id.has_event_from(g)) {
                        fired.bus = true;
                    }
                    if gps_guard.as_ref().is_some_and(|g| id.has_event_from(g)) {
                        fired.gps = true;
                    }
                    for (index, guard) in source_guards.iter().enumerate() {
                        if guard.as_ref().is_some_and(|g| id.has_event_from(g)) {
                            fired.sources |= 1 << index;
                        }
                    }
                    if id.has_event_from(&control_guard) {
                        fired.control = true;
                    }
                    if sim_guard.as_ref().is_some_and(|g| id.has_event_from(g)) {
                        fired.sim = true;
                    }
                    CallbackProgression::Continue
                },
                timeout,
            );
            match result {
                Ok(WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt) => {
                    core.shutdown(&ports);
                    return Ok(());
                }
                Ok(_) => {}
                Err(e) => return Err(ServiceError::WaitSet(format!("{e:?}"))),
            }
            // A moderation pause that ended: read what queued meanwhile, watch the bus again.
            if !gate.is_open() && !core.rx_moderation.is_paused(clock::now()) {
                set_gate(&mut gate, true);
                fired.bus = true;
            }
            if let Next::Rewire = core.iteration(&ports, fired) {
                break;
            }
            // Close the gate for a pause that began, open it when polling ended.
            let paused = core.rx_moderation.is_paused(clock::now());
            if gate.is_open() == paused {
                set_gate(&mut gate, !paused);
            }
            // A source that wakes the loop too often is read on the tick only, until the next.
            for index in budget.spend(fired.sources, core.tick.next()) {
                let (Some(guard), Some(inlet)) =
                    (source_guards.get_mut(index), ports.sources.get(index))
                else {
                    continue;
                };
                if guard.take().is_some() {
                    if let Some(held) = core.throttle_flood.allow(clock::now()) {
                        warn!(
                            source = inlet.name,
                            held_back = held,
                            "the source woke the loop more than {} times in one tick: read on \
                             the tick only until the next",
                            WakeBudget::PER_TICK
                        );
                    }
                } else {
                    *guard = Some(
                        waitset
                            .attach_notification(&inlet.listener)
                            .map_err(attach_err)?,
                    );
                }
            }
        }
    }
}

/// Wake-ups per source and tick. A client publishing far faster than any controller needs (a
/// runaway or rogue process, 100k requests a second) would wake the loop from one notification
/// to the next: a CPU hog that the kernel then schedules in time slices, late for its deadlines
/// (the heartbeat), with every core it shares busy. Past [`WakeBudget::PER_TICK`] wake-ups in
/// one tick the source's listener is detached until the next tick: its requests are still read
/// on every tick (its newest 16 wait in its queue, and iceoryx2 coalesces its notifications), so
/// it keeps its place in the mux, while every other source still wakes the loop at once.
/// Safety-priority sources are exempt: a stop from the safety monitor never waits for a tick
/// (the monitor holds its source alone: no rogue process can publish on it).
#[derive(Debug)]
struct WakeBudget {
    spent: Vec<u32>,
    /// One bit per detached source.
    detached: u32,
    /// One bit per source never detached.
    exempt: u32,
    /// The tick the counts belong to (its deadline).
    tick: Timestamp,
}

impl WakeBudget {
    /// 1 kHz at the 20 ms tick: more than any client needs.
    const PER_TICK: u32 = 20;

    fn new(sources: usize, tick: Timestamp, exempt: u32) -> Self {
        Self {
            spent: vec![0; sources],
            detached: 0,
            exempt,
            tick,
        }
    }

    /// Counts the wake-ups of `fired` (one bit per source) in the tick whose deadline is `tick`;
    /// returns the sources whose listener must change: detached (over budget) or attached
    /// again (a new tick began).
    fn spend(&mut self, fired: u32, tick: Timestamp) -> Vec<usize> {
        let mut toggle = Vec::new();
        if tick != self.tick {
            self.tick = tick;
            self.spent.iter_mut().for_each(|n| *n = 0);
            toggle.extend((0..self.spent.len()).filter(|i| self.detached & (1 << i) != 0));
            self.detached = 0;
        }
        for (index, spent) in self.spent.iter_mut().enumerate() {
            if fired & !self.exempt & (1 << index) != 0 && self.detached & (1 << index) == 0 {
                *spent += 1;
                if *spent > Self::PER_TICK {
                    self.detached |= 1 << index;
                    toggle.push(index);
                }
            }
        }
        toggle
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_source_waking_the_loop_past_its_budget_is_detached_until_the_next_tick() {
        let tick = Timestamp::from_millis(20);
        let mut budget = WakeBudget::new(3, tick, 0);
        // Source 1 floods, source 0 wakes now and then.
        for _ in 0..WakeBudget::PER_TICK {
            assert!(budget.spend(0b010, tick).is_empty());
        }
        assert_eq!(budget.spend(0b011, tick), vec![1], "over budget: detached");
        assert!(
            budget.spend(0b001, tick).is_empty(),
            "the others are untouched"
        );
        assert!(
            budget.spend(0b010, tick).is_empty(),
            "detached: no longer counted"
        );
        // The next tick attaches it again, with a fresh budget.
        let next = Timestamp::from_millis(40);
        assert_eq!(budget.spend(0, next), vec![1]);
        for _ in 0..WakeBudget::PER_TICK {
            assert!(budget.spend(0b010, next).is_empty());
        }
        assert_eq!(budget.spend(0b010, next), vec![1]);
    }

    #[test]
    fn a_safety_source_is_never_detached() {
        let tick = Timestamp::from_millis(20);
        // Source 2 has safety priority.
        let mut budget = WakeBudget::new(3, tick, 0b100);
        for _ in 0..10 * WakeBudget::PER_TICK {
            assert!(budget.spend(0b100, tick).is_empty());
        }
        // The others still have their budget.
        for _ in 0..WakeBudget::PER_TICK {
            assert!(budget.spend(0b101, tick).is_empty());
        }
        assert_eq!(budget.spend(0b101, tick), vec![0]);
    }
}
