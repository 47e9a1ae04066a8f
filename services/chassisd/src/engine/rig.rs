//! The engine against a simulated chassis on simulated time: the scenario harness one level up
//! from `chassis_protocols::pair::Pair`.
//!
//! A [`Rig`] runs the engine exactly as the shell does (one pass per wake-up, in the shell's
//! order), wired to the robot's simulated firmware by a wire with a one-way latency. Clients are
//! scripted: requests and control calls are scheduled at instants, and they wake the engine as a
//! notification would. The clock jumps from one deadline to the next (the engine's, the
//! firmware's, the wire's, the script's), so thousands of simulated seconds run in seconds and
//! every time a scenario asserts is exact.
//!
//! Everything the engine publishes is kept ([`Rig::states`], [`Rig::muxes`], [`Rig::responses`]),
//! every item it writes is on [`Rig::wire`], and invariants that must hold at every instant are
//! checked as the run goes (every published state numbered one above the last; see
//! [`Rig::check`] for the safety rules checked against the wire).

use std::collections::VecDeque;
use std::time::Duration;

use chassis_interfaces::{
    BusFrame, ChassisState, ControlRequest, ControlResponse, MuxStatus, RobotDescription,
    VelocityRequest,
};
use chassis_protocols::{
    DriverConfig, Injection, Profile, RobotKind, Timestamp, Transmit, scout_mini, titan,
};

use super::{Device, Engine, EngineConfig, HeldLock, ListenerChange, Publication, Ticket, Wake};
use crate::bus::MAX_RX_BATCH;
use crate::mux::{Mux, MuxConfig};
use crate::sim::BoxedFirmware;

/// Where every rig starts.
pub const T0: Timestamp = Timestamp::from_millis(1_000);
/// One-way latency of the simulated wire (as `Pair`'s).
pub const LATENCY: Duration = Duration::from_micros(250);

/// An item the engine wrote, and when.
#[derive(Debug, Clone, PartialEq)]
pub struct Sent {
    pub at: Timestamp,
    pub item: Transmit,
}

/// A scripted client action.
#[derive(Debug, Clone)]
enum Action {
    Request(usize, VelocityRequest),
    Control(ControlRequest),
}

/// The engine, a simulated chassis and scripted clients on simulated time.
pub struct Rig {
    pub engine: Engine,
    pub firmware: BoxedFirmware,
    pub profile: Profile,
    pub mux_config: MuxConfig,
    now: Timestamp,
    to_firmware: VecDeque<(Timestamp, Transmit)>,
    /// Frames in the service's receive queue (the kernel's), with their arrival.
    to_engine: VecDeque<(Timestamp, Transmit)>,
    script: Vec<(Timestamp, Action)>,
    /// The bus works; while false everything sent is lost, reads fail and reopening fails.
    bus_ok: bool,
    /// The bus failed and the engine has not been told yet.
    bus_failed: bool,
    /// The receive gate (the shell stops watching a paused bus).
    gate_open: bool,
    next_ticket: Ticket,
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
    /// Listener changes the wake budget asked for.
    pub listener_changes: Vec<(Timestamp, ListenerChange)>,
    /// Every held set the engine asked to keep (the shell's state file), and when.
    pub kept_locks: Vec<(Timestamp, Vec<HeldLock>)>,
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
    /// Steps at the same instant without progress (a side asking for a deadline in the past).
    pub stalls: u64,
}

impl std::fmt::Debug for Rig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Rig")
            .field("now", &self.now)
            .field("engine", &self.engine)
            .finish_non_exhaustive()
    }
}

impl Rig {
    /// `robot` with `mux`, and `adjust` applied to the engine's settings.
    pub fn with(robot: RobotKind, mux: MuxConfig, adjust: impl FnOnce(&mut EngineConfig)) -> Self {
        let mut profile = robot.entry().defaults();
        if let Profile::Xbot(p) = &mut profile {
            p.wheel_separation_m =
                Some(chassis_protocols::xbot::XbotSim::DEFAULT_WHEEL_SEPARATION_M);
        }
        let mut config = EngineConfig {
            tick: Duration::from_millis(20),
            mux_status_period: Duration::from_millis(100),
            reconnect_initial: Duration::from_millis(100),
            reconnect_max: Duration::from_millis(2000),
            rx_moderation: Duration::from_micros(4000),
            gps: false,
            descriptions: Vec::new(),
        };
        adjust(&mut config);
        let entry = robot.entry();
        let driver = (entry.driver)(&profile, &DriverConfig::default(), T0);
        let engine = Engine::new(
            config,
            driver,
            Mux::new(&mux).expect("a valid mux configuration"),
            T0,
        );
        let mut rig = Self {
            engine,
            firmware: (entry.firmware)(&profile, T0),
            profile,
            mux_config: mux,
            now: T0,
            to_firmware: VecDeque::new(),
            to_engine: VecDeque::new(),
            script: Vec::new(),
            bus_ok: true,
            bus_failed: false,
            gate_open: true,
            next_ticket: 0,
            wire: Vec::new(),
            states: Vec::new(),
            muxes: Vec::new(),
            frames: Vec::new(),
            descriptions: Vec::new(),
            responses: Vec::new(),
            passes: Vec::new(),
            listener_changes: Vec::new(),
            kept_locks: Vec::new(),
            opens: Vec::new(),
            state_times: Vec::new(),
            bus_reads: 0,
            frames_read: 0,
            worst_rx_wait: Duration::ZERO,
            frames_sent_to_engine: 0,
            stalls: 0,
        };
        rig.engine.publish_all(T0);
        rig.collect();
        rig
    }

    pub fn now(&self) -> Timestamp {
        self.now
    }

    /// The index of the configured source `name`.
    pub fn source(&self, name: &str) -> usize {
        self.mux_config
            .sources
            .iter()
            .position(|s| s.name == name)
            .expect("a configured source")
    }

    /// Source `name` publishes `request` at `at` (stamped then).
    pub fn request_at(&mut self, at: Timestamp, name: &str, mut request: VelocityRequest) {
        request.stamp_ns = at.as_nanos();
        let index = self.source(name);
        self.schedule(at, Action::Request(index, request));
    }

    /// Source `name` publishes `request` now.
    pub fn request(&mut self, name: &str, request: VelocityRequest) {
        self.request_at(self.now, name, request);
    }

    /// Source `name` publishes `request` every `period` from now until `until` (excluded).
    pub fn publish_every(
        &mut self,
        name: &str,
        request: VelocityRequest,
        period: Duration,
        until: Timestamp,
    ) {
        let mut at = self.now;
        while at < until {
            self.request_at(at, name, request);
            at += period;
        }
    }

    /// A control request arrives at `at`; returns its ticket.
    pub fn control_at(&mut self, at: Timestamp, mut request: ControlRequest) -> Ticket {
        self.next_ticket += 1;
        request.seq = self.next_ticket;
        request.stamp_ns = at.as_nanos();
        self.schedule(at, Action::Control(request));
        self.next_ticket
    }

    /// The answer to `ticket`, if it came.
    pub fn response(&self, ticket: Ticket) -> Option<(ControlResponse, Timestamp)> {
        self.responses
            .iter()
            .find(|(t, _, _)| *t == ticket)
            .map(|(_, r, at)| (*r, *at))
    }

    fn schedule(&mut self, at: Timestamp, action: Action) {
        let at = at.max(self.now);
        let index = self.script.partition_point(|(t, _)| *t <= at);
        self.script.insert(index, (at, action));
    }

    /// Injects a fault into the simulated chassis now.
    pub fn inject(&mut self, injection: Injection) -> bool {
        let now = self.now;
        let ok = self.firmware.inject(now, injection);
        self.flush_firmware();
        ok
    }

    /// The bus fails now (a cable pulled): the engine learns it at its next read.
    pub fn cut_bus(&mut self) {
        self.bus_ok = false;
        // A service that has already closed the bus has nothing to learn.
        self.bus_failed = self.engine.is_bus_up();
        self.frames_sent_to_engine -= self.to_engine.len() as u64;
        self.to_engine.clear();
        self.to_firmware.clear();
    }

    /// The bus can be opened again.
    pub fn restore_bus(&mut self) {
        self.bus_ok = true;
    }

    /// Runs until `until`.
    pub fn run_until(&mut self, until: Timestamp) {
        let mut same = 0u32;
        while self.now < until {
            let before = self.now;
            self.step(until);
            if self.now == before {
                same += 1;
                if same > 10_000 {
                    self.stalls += 1;
                    self.now += Duration::from_micros(1);
                    same = 0;
                }
            } else {
                same = 0;
            }
        }
    }

    /// Runs for `duration`.
    pub fn run_for(&mut self, duration: Duration) {
        let until = self.now + duration;
        self.run_until(until);
    }

    /// The next instant something happens.
    fn next_event(&self) -> Timestamp {
        [
            Some(self.engine.poll_timeout()),
            self.firmware.poll_timeout(),
            self.to_firmware.front().map(|(t, _)| *t),
            self.to_engine
                .front()
                .filter(|_| self.gate_open)
                .map(|(t, _)| *t),
            self.script.first().map(|(t, _)| *t),
            (self.bus_failed && self.gate_open).then_some(self.now),
        ]
        .into_iter()
        .flatten()
        .min()
        .unwrap_or(Timestamp::from_nanos(u64::MAX))
    }

    fn step(&mut self, until: Timestamp) {
        let next = self.next_event().min(until).max(self.now);
        self.now = next;
        let now = self.now;
        // The chassis side first: what reached it, its deadlines, what it sends back.
        while let Some((_, item)) = self.to_firmware.front().filter(|(t, _)| *t <= now) {
            let item = item.clone();
            self.to_firmware.pop_front();
            self.firmware.handle_rx(now, item.as_rx());
        }
        if self.firmware.poll_timeout().is_some_and(|t| t <= now) {
            self.firmware.handle_timeout(now);
        }
        self.flush_firmware();
        // What wakes the service.
        let mut wake = Wake::default();
        for (at, action) in &self.script {
            if *at > now {
                break;
            }
            match action {
                Action::Request(index, _) => wake.sources |= 1 << index,
                Action::Control(_) => wake.control = true,
            }
        }
        if !self.gate_open && !self.engine.is_rx_paused(now) {
            self.gate_open = true;
            wake.bus = true;
        }
        wake.bus |= self.gate_open
            && (self.bus_failed || self.to_engine.front().is_some_and(|(t, _)| *t <= now));
        if wake.is_activity() || self.engine.poll_timeout() <= now {
            self.pass(now, wake);
        }
    }

    fn flush_firmware(&mut self) {
        let now = self.now;
        while let Some(item) = self.firmware.poll_transmit(now) {
            // Nobody reads a bus the service has closed: what the chassis sends then is lost.
            if self.bus_ok && self.engine.is_bus_up() {
                self.frames_sent_to_engine += 1;
                self.to_engine.push_back((now + LATENCY, item));
            }
        }
    }

    /// One pass, in the shell's order (`crate::service::Shell::pass`).
    fn pass(&mut self, now: Timestamp, wake: Wake) {
        self.passes.push(now);
        let reads = self.engine.begin_pass(now, wake);
        // The sources and control requests due now.
        let due = self.script.partition_point(|(t, _)| *t <= now);
        let mut later = Vec::new();
        for (at, action) in self.script.drain(..due) {
            match action {
                Action::Request(index, request) if reads.sources & (1 << index) != 0 => {
                    self.engine.handle_request(now, index, &request).ok();
                }
                Action::Control(request) if reads.control => {
                    self.engine.handle_control(now, request.seq, &request);
                }
                action => later.push((at, action)),
            }
        }
        self.script.splice(0..0, later);
        self.transmit(now);
        if reads.bus {
            self.read_bus(now);
        }
        self.engine.handle_timeout(now);
        self.transmit(now);
        self.engine.end_pass(now);
        while let Some(device) = self.engine.poll_open(now) {
            self.opens.push((now, device));
            if device == Device::Bus && self.bus_ok {
                self.bus_failed = false;
                self.engine.handle_opened(now, device, "sim");
            } else {
                self.engine
                    .handle_open_failed(now, device, &"no such device (simulated)");
            }
        }
        self.collect();
        if let Some(held) = self.engine.poll_held_locks() {
            self.kept_locks.push((now, held));
        }
        self.gate_open = !self.engine.is_rx_paused(now);
        for change in self.engine.spend_wakeups(now, wake.sources) {
            self.listener_changes.push((now, change));
        }
    }

    fn transmit(&mut self, now: Timestamp) {
        while let Some(item) = self.engine.poll_transmit(now) {
            if !self.bus_ok {
                self.bus_failed = false;
                self.engine.handle_bus_lost(now, &"simulated bus cut");
                continue;
            }
            self.to_firmware.push_back((now + LATENCY, item.clone()));
            self.engine.handle_sent(now, &item);
            self.wire.push(Sent { at: now, item });
        }
    }

    fn read_bus(&mut self, now: Timestamp) {
        if self.bus_failed {
            self.frames_sent_to_engine -= self.to_engine.len() as u64;
            self.to_engine.clear();
            self.bus_failed = false;
            self.engine.handle_bus_lost(now, &"simulated bus cut");
            return;
        }
        self.bus_reads += 1;
        let mut items = 0;
        while items < MAX_RX_BATCH {
            let Some((arrived, item)) = self.to_engine.front().filter(|(t, _)| *t <= now) else {
                break;
            };
            self.worst_rx_wait = self.worst_rx_wait.max(now.saturating_since(*arrived));
            let item = item.clone();
            self.to_engine.pop_front();
            self.frames_read += 1;
            items += match &item {
                Transmit::Can(_) => 1,
                Transmit::Bytes(bytes) => bytes.len().div_ceil(8),
            };
            self.engine.handle_rx(now, item.as_rx());
        }
        self.engine.handle_bus_read(now, items, false);
    }

    /// Takes what the engine published, checking the numbering.
    fn collect(&mut self) {
        while let Some(publication) = self.engine.poll_publication() {
            match publication {
                Publication::State(state) => {
                    if let Some(last) = self.states.last() {
                        assert_eq!(state.seq, last.seq + 1, "state numbering at {:?}", self.now);
                    }
                    self.state_times.push((state.seq, self.now));
                    self.states.push(*state);
                }
                Publication::Mux(status) => {
                    if let Some(last) = self.muxes.last() {
                        assert_eq!(status.seq, last.seq + 1, "mux numbering at {:?}", self.now);
                    }
                    self.muxes.push(*status);
                }
                Publication::Frame(frame) => self.frames.push(frame),
                Publication::Description(description) => {
                    self.descriptions.push((*description, self.now))
                }
                Publication::Response { ticket, response } => {
                    self.responses.push((ticket, response, self.now))
                }
            }
        }
    }

    /// The speed an item commands, if it is a motion frame (TITAN and AgileX V2 0x111, SCOUT MINI
    /// V1 0x130).
    pub fn commanded_speed(&self, item: &Transmit) -> Option<f64> {
        let frame = item.as_can()?;
        match &self.profile {
            Profile::Titan(p) => match titan::decode(frame, p) {
                Ok(titan::Frame::MotionCommand(c)) => Some(c.linear_mps),
                _ => None,
            },
            Profile::ScoutMini(p) => match scout_mini::decode(frame, p) {
                Ok(scout_mini::Decoded {
                    frame: scout_mini::Frame::MotionCommand(c),
                    ..
                }) => Some(c.linear_mps),
                _ => None,
            },
            Profile::V2(p) => match chassis_protocols::agilex_v2::decode(frame, p) {
                Ok(chassis_protocols::agilex_v2::Frame::MotionCommand(c)) => Some(c.linear_mps),
                _ => None,
            },
            Profile::Xbot(_) => None,
        }
    }

    /// The motion frames on the wire: when, and the speed each commanded.
    pub fn motion(&self) -> Vec<(Timestamp, f64)> {
        self.wire
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
        self.frames_sent_to_engine - self.frames_read - self.to_engine.len() as u64
    }

    /// Forgets the logs (a long run checks them as it goes), keeping the newest state and mux
    /// status for the numbering checks.
    pub fn forget(&mut self) {
        let n = self.states.len().saturating_sub(1);
        self.states.drain(..n);
        let n = self.muxes.len().saturating_sub(1);
        self.muxes.drain(..n);
        self.wire.clear();
        self.frames.clear();
        self.state_times.clear();
        self.passes.clear();
        self.responses.clear();
    }

    /// The newest published mux status.
    pub fn mux(&self) -> &MuxStatus {
        self.muxes
            .last()
            .expect("the mux status is published at start")
    }

    /// The newest published state.
    pub fn state(&self) -> &ChassisState {
        self.states.last().expect("the state is published at start")
    }
}
