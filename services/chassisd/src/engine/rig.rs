//! The engine against a simulated chassis on simulated time: the scenario harness one level up
//! from `chassis_protocols::pair::Pair`.
//!
//! A [`Rig`] runs the engine's own pass ([`Engine::run_pass`], the sequence the shell runs) once
//! per wake-up, against a [`World`]: the robot's simulated firmware at the far end of a wire
//! with a one-way latency, a GPS receiver that can be plugged in, and scripted clients. Requests
//! and control calls are scheduled at instants and wake the engine as a notification would; a
//! request can also arrive while a pass runs, between its first read of the sources and the
//! acknowledgement of their listeners. The clock jumps from one deadline to the next (the
//! engine's, the firmware's, the wire's, the script's), so thousands of simulated seconds run in
//! seconds and every time a scenario asserts is exact.
//!
//! Everything the engine publishes is kept ([`World::states`], [`World::muxes`],
//! [`World::responses`]), every item it writes is on [`World::wire`], and rules of the pass are
//! checked as the run goes: every published state and mux status numbered one above the last;
//! the held locks kept before anything of the same pass is published; nothing published after
//! the pass woke its readers; each kind of reader woken at most once per pass. The safety rules
//! are checked against the wire by the scenarios (the random run of `scenarios`).

use std::collections::VecDeque;
use std::time::Duration;

use chassis_bus::MAX_RX_BATCH;
use chassis_bus::can_controller::ControllerReport;
use chassis_interfaces::{
    BusFrame, ChassisState, ControlRequest, ControlResponse, ControllerState, MuxStatus,
    RobotDescription, VelocityRequest,
};
use chassis_protocols::{
    DriverConfig, Injection, Profile, RobotKind, Timestamp, WireItem, agilex_v1, agilex_v2, titan,
};
use chassisd_config::mux::MuxConfig;

use super::{
    BusItem, Device, Engine, EngineConfig, HeldLock, ListenerChange, PassIo, Readers, Ticket,
    ToPublish, Wake, WriteError, Written,
};
use crate::mux::Mux;
use crate::sim::BoxedFirmware;

/// Where every rig starts.
pub const T0: Timestamp = Timestamp::from_millis(1_000);
/// One-way latency of the simulated wire (as `Pair`'s).
pub const LATENCY: Duration = Duration::from_micros(250);

/// An item the engine wrote, and when.
#[derive(Debug, Clone, PartialEq)]
pub struct Sent {
    pub at: Timestamp,
    pub item: WireItem,
}

/// A scripted client action.
#[derive(Debug, Clone)]
enum Action {
    /// A request of the source with this index. `meanwhile`: it lands while the pass it wakes
    /// runs, after the first read of the sources: only the read after the acknowledgement of
    /// the listeners finds it.
    Request {
        source: usize,
        request: VelocityRequest,
        meanwhile: bool,
    },
    Control(ControlRequest),
}

/// A simulated GPS receiver on its serial port.
#[derive(Debug, Default)]
struct Gps {
    /// Plugged in: opening it succeeds.
    plugged: bool,
    /// Opened by the engine and not lost since.
    open: bool,
    /// Unplugged while open: the engine learns it at its next read.
    failed: bool,
    /// Bytes it sends, and when they arrive.
    pending: VecDeque<(Timestamp, Vec<u8>)>,
}

/// Everything around the engine: the clock, the wire and the chassis, the GPS receiver, the
/// scripted clients, and the record of what the engine wrote, published and kept. It is the
/// engine's [`PassIo`] in the rig.
pub struct World {
    pub firmware: BoxedFirmware,
    pub profile: Profile,
    pub mux_config: MuxConfig,
    now: Timestamp,
    to_firmware: VecDeque<(Timestamp, WireItem)>,
    /// Frames (and the CAN controller's reports) in the service's receive queue (the
    /// kernel's), with their arrival.
    to_engine: VecDeque<(Timestamp, BusItem)>,
    script: Vec<(Timestamp, Action)>,
    gps: Gps,
    /// The bus works; while false everything sent is lost, reads fail and reopening fails.
    bus_ok: bool,
    /// The bus failed and the engine has not been told yet.
    bus_failed: bool,
    /// The CAN controller is bus-off: the bus stays open, nothing crosses it.
    bus_off: bool,
    /// The receive gate (the shell stops watching a paused bus).
    gate_open: bool,
    next_ticket: Ticket,
    /// The disk keeps what is written to it; while false every write of the held locks fails.
    disk_ok: bool,
    /// In the current pass: the listeners were acknowledged; publications handed out, and their
    /// readers (one bit per [`Readers`]); readers woken.
    acknowledged: bool,
    published_in_pass: usize,
    published_kinds: u8,
    woken_in_pass: u8,
    /// Every item the engine wrote.
    pub wire: Vec<Sent>,
    /// Every published state, mux status and frame, in order.
    pub states: Vec<ChassisState>,
    pub muxes: Vec<MuxStatus>,
    pub frames: Vec<BusFrame>,
    /// Every published description, and when.
    pub descriptions: Vec<(RobotDescription, Timestamp)>,
    /// Answers to control requests: ticket, answer, when.
    pub responses: Vec<(Ticket, ControlResponse, Timestamp)>,
    /// Passes run, and the instants of each.
    pub passes: Vec<Timestamp>,
    /// Readers woken, and when.
    pub wakes: Vec<(Timestamp, Readers)>,
    /// Listener changes the wake budget asked for.
    pub listener_changes: Vec<(Timestamp, ListenerChange)>,
    /// Every held set the engine kept (the shell's state file), and when.
    pub kept_locks: Vec<(Timestamp, Vec<HeldLock>)>,
    /// Writes of the held locks that failed (the disk was broken), and when.
    pub keep_failures: Vec<Timestamp>,
    /// Attempts to open a device, and when.
    pub opens: Vec<(Timestamp, Device)>,
    /// When each state was published: (seq, instant).
    pub state_times: Vec<(u64, Timestamp)>,
    /// Reads of the bus, frames read, and the longest a frame waited in the receive queue.
    pub bus_reads: u64,
    pub frames_read: u64,
    pub worst_rx_wait: Duration,
    /// Frames the chassis sent while the bus worked.
    frames_sent_to_engine: u64,
}

/// The engine, a simulated chassis and scripted clients on simulated time.
pub struct Rig {
    pub engine: Engine,
    pub world: World,
    /// The engine's first publications ([`Engine::start`]) are out.
    started: bool,
}

impl std::fmt::Debug for Rig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Rig")
            .field("now", &self.world.now)
            .field("engine", &self.engine)
            .finish_non_exhaustive()
    }
}

impl Rig {
    /// Steps at one instant that make the run a stalled one.
    const STALL: u32 = 10_000;

    /// `robot` with `mux`, and `adjust` applied to the engine's settings, its clients connected
    /// at [`T0`]: the library of each source but the required ones (whose heartbeats are the
    /// scenario's) sends one heartbeat as its process connects. The engine starts
    /// ([`Engine::start`]) at the first run, so a scenario can restore locks before it, as the
    /// service does.
    pub fn with(robot: RobotKind, mux: MuxConfig, adjust: impl FnOnce(&mut EngineConfig)) -> Self {
        let mut rig = Self::unconnected(robot, mux, adjust);
        let connecting: Vec<String> = rig
            .world
            .mux_config
            .sources
            .iter()
            .filter(|s| !s.required)
            .map(|s| s.name.clone())
            .collect();
        for name in connecting {
            rig.request_at(T0, &name, VelocityRequest::heartbeat());
        }
        rig
    }

    /// Like [`Rig::with`], but no client connects anew: those that publish kept asking through
    /// a restart of the service.
    pub fn unconnected(
        robot: RobotKind,
        mux: MuxConfig,
        adjust: impl FnOnce(&mut EngineConfig),
    ) -> Self {
        let mut profile = robot.entry().defaults();
        profile.fill_for_simulator();
        let mut config = EngineConfig {
            tick: Duration::from_millis(20),
            mux_status_period: Duration::from_millis(100),
            reconnect_initial: Duration::from_millis(100),
            reconnect_max: Duration::from_millis(2000),
            rx_moderation: Duration::from_micros(4000),
            gps: false,
            bus: "can:rig0".into(),
            descriptions: Vec::new(),
            recording: false,
            drive_cut: profile.drive_cut(true).zip(profile.drive_cut(false)),
        };
        adjust(&mut config);
        let driver = profile.driver(&DriverConfig::default(), T0);
        let engine = Engine::new(
            config,
            driver,
            Mux::new(&mux).expect("a valid mux configuration"),
            T0,
        );
        let world = World {
            firmware: profile.firmware(T0),
            profile,
            mux_config: mux,
            now: T0,
            to_firmware: VecDeque::new(),
            to_engine: VecDeque::new(),
            script: Vec::new(),
            gps: Gps::default(),
            bus_ok: true,
            bus_failed: false,
            bus_off: false,
            gate_open: true,
            next_ticket: 0,
            disk_ok: true,
            acknowledged: false,
            published_in_pass: 0,
            published_kinds: 0,
            woken_in_pass: 0,
            wire: Vec::new(),
            states: Vec::new(),
            muxes: Vec::new(),
            frames: Vec::new(),
            descriptions: Vec::new(),
            responses: Vec::new(),
            passes: Vec::new(),
            wakes: Vec::new(),
            listener_changes: Vec::new(),
            kept_locks: Vec::new(),
            keep_failures: Vec::new(),
            opens: Vec::new(),
            state_times: Vec::new(),
            bus_reads: 0,
            frames_read: 0,
            worst_rx_wait: Duration::ZERO,
            frames_sent_to_engine: 0,
        };
        Self {
            engine,
            world,
            started: false,
        }
    }

    pub fn now(&self) -> Timestamp {
        self.world.now
    }

    /// The index of the configured source `name`.
    pub fn source(&self, name: &str) -> usize {
        self.world
            .mux_config
            .sources
            .iter()
            .position(|s| s.name == name)
            .expect("a configured source")
    }

    /// Source `name` publishes `request` at `at` (stamped then).
    pub fn request_at(&mut self, at: Timestamp, name: &str, request: VelocityRequest) {
        self.schedule_request(at, name, request, false);
    }

    /// Source `name` publishes `request` at `at`, landing while the pass it wakes runs: after
    /// that pass has read the sources once, before it acknowledges their listeners.
    pub fn request_meanwhile(&mut self, at: Timestamp, name: &str, request: VelocityRequest) {
        self.schedule_request(at, name, request, true);
    }

    fn schedule_request(
        &mut self,
        at: Timestamp,
        name: &str,
        mut request: VelocityRequest,
        meanwhile: bool,
    ) {
        request.stamp_ns = at.as_nanos();
        let source = self.source(name);
        self.schedule(
            at,
            Action::Request {
                source,
                request,
                meanwhile,
            },
        );
    }

    /// Source `name` publishes `request` now.
    pub fn request(&mut self, name: &str, request: VelocityRequest) {
        self.request_at(self.world.now, name, request);
    }

    /// Source `name` publishes `request` every `period` from now until `until` (excluded).
    pub fn publish_every(
        &mut self,
        name: &str,
        request: VelocityRequest,
        period: Duration,
        until: Timestamp,
    ) {
        let mut at = self.world.now;
        while at < until {
            self.request_at(at, name, request);
            at += period;
        }
    }

    /// A control request arrives at `at`; returns its ticket.
    pub fn control_at(&mut self, at: Timestamp, mut request: ControlRequest) -> Ticket {
        self.world.next_ticket += 1;
        request.seq = self.world.next_ticket;
        request.stamp_ns = at.as_nanos();
        self.schedule(at, Action::Control(request));
        self.world.next_ticket
    }

    /// The answer to `ticket`, if it came.
    pub fn response(&self, ticket: Ticket) -> Option<(ControlResponse, Timestamp)> {
        self.world
            .responses
            .iter()
            .find(|(t, _, _)| *t == ticket)
            .map(|(_, r, at)| (*r, *at))
    }

    fn schedule(&mut self, at: Timestamp, action: Action) {
        let at = at.max(self.world.now);
        let index = self.world.script.partition_point(|(t, _)| *t <= at);
        self.world.script.insert(index, (at, action));
    }

    /// Injects a fault into the simulated chassis now.
    pub fn inject(&mut self, injection: Injection) -> bool {
        let now = self.world.now;
        let ok = self.world.firmware.inject(now, injection);
        self.flush_firmware();
        ok
    }

    /// The bus fails now (a cable pulled): the engine learns it at its next read.
    pub fn cut_bus(&mut self) {
        let world = &mut self.world;
        world.bus_ok = false;
        // A service that has already closed the bus has nothing to learn.
        world.bus_failed = self.engine.is_bus_up();
        world.frames_sent_to_engine -= world.to_engine.len() as u64;
        world.to_engine.clear();
        world.to_firmware.clear();
    }

    /// The bus can be opened again.
    pub fn restore_bus(&mut self) {
        self.world.bus_ok = true;
    }

    /// The CAN controller reports `report` now (it reaches the engine with the frames' latency).
    pub fn controller_reports(&mut self, report: ControllerReport) {
        let world = &mut self.world;
        world
            .to_engine
            .push_back((world.now + LATENCY, BusItem::Controller(report)));
    }

    /// The CAN controller goes bus-off now: it says so, and from now on nothing it is given
    /// is sent (the kernel refuses it) and nothing of the chassis is received.
    pub fn bus_off(&mut self) {
        self.world.bus_off = true;
        self.controller_reports(ControllerReport {
            state: ControllerState::BUS_OFF,
            restart_ms: Some(0),
            from_frame: true,
            ..ControllerReport::default()
        });
    }

    /// The CAN controller is restarted now (restart-ms, or `ip link … restart`): the bus works
    /// again, and the controller says so when `reported` (some drivers send nothing).
    pub fn restart_controller(&mut self, reported: bool) {
        self.world.bus_off = false;
        if reported {
            self.controller_reports(ControllerReport {
                restarted: true,
                from_frame: true,
                ..ControllerReport::default()
            });
        }
    }

    /// Every write of the held locks fails from now on (a full or read-only disk).
    pub fn break_disk(&mut self) {
        self.world.disk_ok = false;
    }

    /// Writes of the held locks succeed again.
    pub fn mend_disk(&mut self) {
        self.world.disk_ok = true;
    }

    /// Runs until a frame of the chassis is on its way to the engine; returns when it arrives.
    pub fn next_frame_arrival(&mut self) -> Timestamp {
        loop {
            if let Some((arrival, _)) = self.world.to_engine.back() {
                return *arrival;
            }
            self.run_for(Duration::from_micros(100));
        }
    }

    /// The GPS receiver is plugged in: the next attempt opens it.
    pub fn plug_gps(&mut self) {
        self.world.gps.plugged = true;
    }

    /// The GPS receiver is unplugged now: an open one fails at the engine's next read.
    pub fn unplug_gps(&mut self) {
        let gps = &mut self.world.gps;
        gps.plugged = false;
        gps.failed = gps.open;
        gps.pending.clear();
    }

    /// The GPS receiver sends `bytes` at `at` (lost while it is not open).
    pub fn gps_sends_at(&mut self, at: Timestamp, bytes: &[u8]) {
        let pending = &mut self.world.gps.pending;
        let index = pending.partition_point(|(t, _)| *t <= at);
        pending.insert(index, (at, bytes.to_vec()));
    }

    /// Runs until `until`. Time that stops moving (a side asking for a deadline in the past, a
    /// wake-up the engine does not serve) fails the scenario.
    pub fn run_until(&mut self, until: Timestamp) {
        if !self.started {
            self.started = true;
            let now = self.world.now;
            self.world.begin_pass();
            self.engine.start(&mut self.world, now);
            self.world.end_pass();
        }
        let mut same = 0u32;
        while self.world.now < until {
            let before = self.world.now;
            self.step(until);
            if self.world.now == before {
                same += 1;
                assert!(
                    same <= Self::STALL,
                    "stalled at {before:?}: {} steps without time moving",
                    Self::STALL
                );
            } else {
                same = 0;
            }
        }
    }

    /// Runs for `duration`.
    pub fn run_for(&mut self, duration: Duration) {
        let until = self.world.now + duration;
        self.run_until(until);
    }

    /// The orderly stop now ([`Engine::stop`]).
    pub fn stop(&mut self) {
        let now = self.world.now;
        self.world.begin_pass();
        self.engine.stop(&mut self.world, now);
        self.world.end_pass();
    }

    /// The next instant something happens.
    fn next_event(&self) -> Timestamp {
        let world = &self.world;
        [
            Some(self.engine.poll_timeout()),
            world.firmware.poll_timeout(),
            world.to_firmware.front().map(|(t, _)| *t),
            world
                .to_engine
                .front()
                .filter(|_| world.gate_open)
                .map(|(t, _)| *t),
            world.script.first().map(|(t, _)| *t),
            (world.bus_failed && world.gate_open).then_some(world.now),
            world
                .gps
                .pending
                .front()
                .filter(|_| world.gps.open)
                .map(|(t, _)| *t),
            world.gps.failed.then_some(world.now),
        ]
        .into_iter()
        .flatten()
        .min()
        .unwrap_or(Timestamp::from_nanos(u64::MAX))
    }

    fn step(&mut self, until: Timestamp) {
        let next = self.next_event().min(until).max(self.world.now);
        self.world.now = next;
        let now = next;
        // The chassis side first: what reached it, its deadlines, what it sends back.
        let world = &mut self.world;
        while let Some((_, item)) = world.to_firmware.front().filter(|(t, _)| *t <= now) {
            let item = item.clone();
            world.to_firmware.pop_front();
            world.firmware.handle_rx(now, item.as_rx());
        }
        if world.firmware.poll_timeout().is_some_and(|t| t <= now) {
            world.firmware.handle_timeout(now);
        }
        // What the receiver sent while nobody had it open is gone.
        if !world.gps.open {
            while world.gps.pending.front().is_some_and(|(t, _)| *t <= now) {
                world.gps.pending.pop_front();
            }
        }
        self.flush_firmware();
        // What wakes the service.
        let world = &mut self.world;
        let mut wake = Wake::default();
        for (at, action) in &world.script {
            if *at > now {
                break;
            }
            match action {
                Action::Request { source, .. } => wake.sources |= 1 << source,
                Action::Control(_) => wake.control = true,
            }
        }
        if !world.gate_open && !self.engine.is_rx_paused(now) {
            world.gate_open = true;
            wake.bus = true;
        }
        wake.bus |= world.gate_open
            && (world.bus_failed || world.to_engine.front().is_some_and(|(t, _)| *t <= now));
        wake.gps = world.gps.failed
            || world.gps.open && world.gps.pending.front().is_some_and(|(t, _)| *t <= now);
        if wake.is_activity() || self.engine.poll_timeout() <= now {
            self.pass(now, wake);
        }
    }

    fn flush_firmware(&mut self) {
        let world = &mut self.world;
        let now = world.now;
        while let Some(item) = world.firmware.poll_transmit(now) {
            // Nobody reads a bus the service has closed: what the chassis sends then is lost.
            if world.bus_ok && !world.bus_off && self.engine.is_bus_up() {
                world.frames_sent_to_engine += 1;
                world
                    .to_engine
                    .push_back((now + LATENCY, BusItem::Rx(item)));
            }
        }
    }

    /// One pass: the engine's own ([`Engine::run_pass`]), then what the shell's loop does
    /// between passes (the receive gate, the wake budget).
    fn pass(&mut self, now: Timestamp, wake: Wake) {
        self.world.passes.push(now);
        self.world.begin_pass();
        self.engine.run_pass(&mut self.world, wake);
        self.world.end_pass();
        self.world.gate_open = !self.engine.is_rx_paused(now);
        for change in self.engine.spend_wakeups(now, wake.sources) {
            self.world.listener_changes.push((now, change));
        }
    }

    /// The speed an item commands, if it is a motion frame (TITAN and AgileX V2 0x111, SCOUT MINI
    /// V1 0x130).
    pub fn commanded_speed(&self, item: &WireItem) -> Option<f64> {
        let frame = item.as_can()?;
        let profile = &self.world.profile;
        if let Some(p) = profile.get::<titan::TitanProfile>() {
            match titan::decode(frame, p) {
                Ok(titan::Frame::MotionCommand(c)) => Some(c.linear_mps),
                _ => None,
            }
        } else if let Some(p) = profile.get::<agilex_v1::V1Profile>() {
            match agilex_v1::decode(frame, p) {
                Ok(agilex_v1::Decoded {
                    frame: agilex_v1::Frame::MotionCommand(c),
                    ..
                }) => Some(c.linear_mps),
                _ => None,
            }
        } else if let Some(p) = profile.get::<agilex_v2::V2Profile>() {
            match agilex_v2::decode(frame, p) {
                Ok(agilex_v2::Frame::MotionCommand(c)) => Some(c.linear_mps),
                _ => None,
            }
        } else {
            None
        }
    }

    /// The motion frames on the wire: when, and the speed each commanded.
    pub fn motion(&self) -> Vec<(Timestamp, f64)> {
        self.world
            .wire
            .iter()
            .filter_map(|s| self.commanded_speed(&s.item).map(|v| (s.at, v)))
            .collect()
    }

    /// The first motion frame at or after `since` that commands a speed matching `test`.
    pub fn first_motion(&self, since: Timestamp, test: impl Fn(f64) -> bool) -> Option<Timestamp> {
        self.motion()
            .into_iter()
            .find(|&(at, v)| at >= since && test(v))
            .map(|(at, _)| at)
    }

    /// Frames the chassis sent over a working bus that the engine has not read (none may be
    /// lost; those still in the queue are not lost).
    pub fn frames_lost(&self) -> u64 {
        let world = &self.world;
        world.frames_sent_to_engine - world.frames_read - world.to_engine.len() as u64
    }

    /// Forgets the logs (a long run checks them as it goes), keeping the newest state and mux
    /// status for the numbering checks.
    pub fn forget(&mut self) {
        let world = &mut self.world;
        let n = world.states.len().saturating_sub(1);
        world.states.drain(..n);
        let n = world.muxes.len().saturating_sub(1);
        world.muxes.drain(..n);
        world.wire.clear();
        world.frames.clear();
        world.state_times.clear();
        world.passes.clear();
        world.wakes.clear();
        world.responses.clear();
    }

    /// The newest published mux status.
    pub fn mux(&self) -> &MuxStatus {
        self.world
            .muxes
            .last()
            .expect("the mux status is published at start")
    }

    /// The newest published state.
    pub fn state(&self) -> &ChassisState {
        self.world
            .states
            .last()
            .expect("the state is published at start")
    }
}

impl World {
    /// A pass (or the start, or the stop) begins: the checks of one pass start over.
    fn begin_pass(&mut self) {
        self.acknowledged = false;
        self.published_in_pass = 0;
        self.published_kinds = 0;
        self.woken_in_pass = 0;
    }

    /// A pass ended: the readers of everything it published were woken. A request that landed
    /// during the pass and was not read waits like any other (its notification wakes the loop
    /// again).
    fn end_pass(&mut self) {
        let due = self.script.partition_point(|(t, _)| *t <= self.now);
        for (_, action) in &mut self.script[..due] {
            if let Action::Request { meanwhile, .. } = action {
                *meanwhile = false;
            }
        }
        assert_eq!(
            self.woken_in_pass, self.published_kinds,
            "readers woken at {:?} (one bit per kind) are not those of what was published",
            self.now
        );
    }

    /// Takes the due actions `wanted` picks, in order, leaving the others in the script.
    fn take_due(&mut self, mut wanted: impl FnMut(&Action) -> bool) -> Vec<Action> {
        let due = self.script.partition_point(|(t, _)| *t <= self.now);
        let mut taken = Vec::new();
        let mut kept = Vec::new();
        for (at, action) in self.script.drain(..due) {
            if wanted(&action) {
                taken.push(action);
            } else {
                kept.push((at, action));
            }
        }
        self.script.splice(0..0, kept);
        taken
    }
}

impl PassIo for World {
    type Error = &'static str;

    fn now(&mut self) -> Timestamp {
        self.now
    }

    fn read_requests(&mut self, sources: u32, mut take: impl FnMut(usize, &VelocityRequest)) {
        let acknowledged = self.acknowledged;
        let readable = |action: &Action| match action {
            Action::Request {
                source, meanwhile, ..
            } => sources & (1 << source) != 0 && (acknowledged || !meanwhile),
            Action::Control(_) => false,
        };
        for action in self.take_due(readable) {
            if let Action::Request {
                source, request, ..
            } = action
            {
                take(source, &request);
            }
        }
    }

    fn read_control(&mut self, mut take: impl FnMut(Ticket, &ControlRequest)) {
        for action in self.take_due(|action| matches!(action, Action::Control(_))) {
            if let Action::Control(request) = action {
                take(request.seq, &request);
            }
        }
    }

    fn serve_simulator(&mut self, _now: Timestamp) {
        // The scenarios inject faults into the firmware directly.
    }

    fn acknowledge(&mut self, _sources: u32) {
        self.acknowledged = true;
    }

    fn write(&mut self, item: &WireItem) -> Result<Written, WriteError<Self::Error>> {
        if !self.bus_ok {
            return Err(WriteError::Lost("simulated bus cut"));
        }
        if self.bus_off {
            return Err(WriteError::Dropped("the controller is bus-off"));
        }
        self.to_firmware
            .push_back((self.now + LATENCY, item.clone()));
        self.wire.push(Sent {
            at: self.now,
            item: item.clone(),
        });
        Ok(Written::Out(self.now))
    }

    fn flush(&mut self) -> Result<Timestamp, WriteError<Self::Error>> {
        Ok(self.now)
    }

    fn read_bus(&mut self, into: &mut Vec<(Timestamp, BusItem)>) -> Result<bool, Self::Error> {
        if self.bus_failed {
            self.frames_sent_to_engine -= self.to_engine.len() as u64;
            self.to_engine.clear();
            return Err("simulated bus cut");
        }
        self.bus_reads += 1;
        let now = self.now;
        let mut count = 0;
        while count < MAX_RX_BATCH {
            let Some((arrived, item)) = self.to_engine.front().filter(|(t, _)| *t <= now) else {
                break;
            };
            self.worst_rx_wait = self.worst_rx_wait.max(now.saturating_since(*arrived));
            into.push((now, item.clone()));
            self.to_engine.pop_front();
            self.frames_read += 1;
            count += 1;
        }
        Ok(count >= MAX_RX_BATCH)
    }

    fn read_gps(&mut self, mut take: impl FnMut(&[u8])) -> Result<(), Self::Error> {
        if self.gps.failed {
            return Err("GPS receiver unplugged (simulated)");
        }
        while let Some((_, bytes)) = self.gps.pending.front().filter(|(t, _)| *t <= self.now) {
            take(bytes);
            self.gps.pending.pop_front();
        }
        Ok(())
    }

    fn open(&mut self, now: Timestamp, device: Device) -> Result<&str, Self::Error> {
        self.opens.push((now, device));
        match device {
            Device::Bus if self.bus_ok => {
                self.bus_failed = false;
                Ok("sim")
            }
            Device::Gps if self.gps.plugged => {
                self.gps.open = true;
                Ok("gps (simulated)")
            }
            _ => Err("no such device (simulated)"),
        }
    }

    fn close(&mut self, device: Device) {
        match device {
            Device::Bus => self.bus_failed = false,
            Device::Gps => {
                self.gps.open = false;
                self.gps.failed = false;
            }
        }
    }

    fn keep_locks(&mut self, held: &[HeldLock]) -> Result<(), Self::Error> {
        assert_eq!(
            self.published_in_pass, 0,
            "locks kept at {:?} after a publication of the same pass",
            self.now
        );
        if !self.disk_ok {
            self.keep_failures.push(self.now);
            return Err("no space left on device (simulated)");
        }
        self.kept_locks.push((self.now, held.to_vec()));
        Ok(())
    }

    fn publish(&mut self, publication: ToPublish) -> Result<(), Self::Error> {
        assert_eq!(
            self.woken_in_pass, 0,
            "published at {:?} after the pass woke its readers",
            self.now
        );
        self.published_in_pass += 1;
        self.published_kinds |= bit(Readers::of(&publication));
        match publication {
            ToPublish::State(state) => {
                if let Some(last) = self.states.last() {
                    assert_eq!(state.seq, last.seq + 1, "state numbering at {:?}", self.now);
                }
                self.state_times.push((state.seq, self.now));
                self.states.push(*state);
            }
            ToPublish::Mux(status) => {
                if let Some(last) = self.muxes.last() {
                    assert_eq!(status.seq, last.seq + 1, "mux numbering at {:?}", self.now);
                }
                self.muxes.push(*status);
            }
            ToPublish::Frame(frame) => self.frames.push(frame),
            ToPublish::Description(description) => self.descriptions.push((*description, self.now)),
            ToPublish::Response { ticket, response } => {
                self.responses.push((ticket, response, self.now))
            }
        }
        Ok(())
    }

    fn wake(&mut self, readers: Readers) -> Result<(), Self::Error> {
        let bit = bit(readers);
        assert_eq!(
            self.woken_in_pass & bit,
            0,
            "{readers:?} woken twice at {:?}",
            self.now
        );
        self.woken_in_pass |= bit;
        self.wakes.push((self.now, readers));
        Ok(())
    }
}

/// One bit per kind of readers.
fn bit(readers: Readers) -> u8 {
    1 << readers as u8
}
