//! The service's decisions as a sans-IO state machine, in the shape of the drivers (and of
//! quinn-proto's `Connection`): inputs arrive with their time, outputs are polled.
//!
//! The engine owns the robot's driver, the mux and its locks, receive moderation, the wake
//! budget's bookkeeping, the bus and GPS reconnection timers, the GPS sentence reader and the
//! numbering of everything published, and the order of a pass. It imports no iceoryx2 and no
//! bus backend, and it never reads the clock: the shell (`crate::service`) owns the wait set,
//! the ports, the descriptors and the clock, and lends them to each pass through [`PassIo`].
//! The same engine runs the same passes against a simulated chassis on simulated time in the
//! scenarios of `engine::scenarios`.
//!
//! # One pass
//!
//! The sequence of a pass is the engine's: [`Engine::run_pass`] runs it against a [`PassIo`],
//! the caller's ports, devices and clock (the shell's iceoryx2 ports and bus descriptors; the
//! scenario rig's simulated wire and scripted clients), the command path first:
//!
//! 1. [`Engine::begin_pass`] with what woke the loop; it serves the tick and says what to read
//!    ([`Reads`]: every source, control and the bus on the tick).
//! 2. [`Engine::handle_request`] for every pending request of those sources,
//!    [`Engine::handle_control`] for every control request; then transmit:
//!    [`Engine::poll_transmit`] until `None` (the mux decides at the first poll after new
//!    input, and a changed command is out before anything else is read), every item written
//!    reported with [`Engine::handle_sent`] and the time its write returned (the tap numbers it).
//! 3. The notifications of the listeners that fired are consumed and those sources read again:
//!    a request that arrived meanwhile is handled and transmitted at once.
//! 4. A changed held set is kept (see below) before anything of the pass is published.
//! 5. The bus is drained: [`Engine::handle_rx`] per item, its publications out before the next
//!    item, then [`Engine::handle_bus_read`] (moderation, weighing each item with
//!    [`crate::rx_moderation::weight`]), or [`Engine::handle_bus_lost`]; GPS bytes with
//!    [`Engine::handle_gps`].
//! 6. [`Engine::handle_timeout`] (driver deadlines: the heartbeat, the chassis' silence), and
//!    transmit again.
//! 7. [`Engine::end_pass`]: mux status on change and at its rate, the tick's state refresh;
//!    [`Engine::poll_open`] names a device to (re)open, reported back with
//!    [`Engine::handle_opened`] / [`Engine::handle_open_failed`]; [`Engine::poll_publication`]
//!    until `None`; the readers of what was published woken once per kind.
//!
//! [`Engine::start`] and [`Engine::stop`] are the service's first and last publications, on the
//! same [`PassIo`]. The steps stay public: a scenario can feed the engine in any order to check
//! that its rules do not depend on the order.
//!
//! # Locks that outlive the process
//!
//! A held lock (the operator's or the safety monitor's e-stop, any named lock) must survive a
//! restart of the service: a latched stop is cleared only by an explicit release. The engine
//! does no I/O, so the shell keeps the file and the engine says what to keep:
//!
//! * before the first decision the shell hands in what the file held,
//!   [`Engine::restore_locks`] (each logged at WARN with its holder and age), or
//!   [`Engine::restore_failed`] when the file could not be read or understood: the e-stop is
//!   then held (the lock called `estop`, every lock when none has that name), since nothing
//!   says it was free;
//! * [`Engine::poll_held_locks`] returns the held set when it changed since the last poll (an
//!   engage, a release, a restore that had to substitute the e-stop); a pass keeps it
//!   ([`PassIo::keep_locks`]: write, fsync, rename) right after its command path — the only
//!   steps that change it — and before it hands out its first publication, so an engage is on
//!   disk before it is answered or shown in the mux status ([`Engine::start`] and
//!   [`Engine::stop`] likewise). A failed write is logged at ERROR and tried again every second.
//!
//! The engine keeps its own rules whatever the order of its inputs: a request handled before a
//! frame is decided before that frame reaches the driver ([`Engine::handle_rx`] decides first), so
//! a command is never queued behind the bus.

mod drive;
mod pass;
#[cfg(test)]
mod rig;
#[cfg(test)]
mod scenarios;
mod wake_budget;

use std::collections::{BTreeMap, VecDeque};
use std::fmt::Display;
use std::time::Duration;

use chassis_bus::can_controller::{self, Controller, ControllerReport};
use chassis_interfaces::{
    BusFrame, ChassisState, ControlKind, ControlRequest, ControlResponse, ControlStatus,
    ControllerState, FaultFlags, FrameDirection, FrameKind, GpsFix, Group, LinkFlags, LockStatus,
    MuxStatus, RobotDescription, SourceFlags, SourceStatus, Stop, StopCategory, ValidRequest,
    VelocityRequest, WireProtocol, ZeroReason,
};
use chassis_protocols::command::Command;
use chassis_protocols::driver::Level;
use chassis_protocols::snapshot::{self, SnapshotError};
use chassis_protocols::{
    ControlAction, ControlOutcome, Driver, DriverEvent, Rx, Timestamp, WireItem, nmea,
    request_to_action, time::Grid,
};
use chassisd_config::{Config, LoopMode};
use serde::{Deserialize, Serialize};
use tracing::{debug, error, info, warn};
use zerocopy::IntoBytes;

pub use pass::{PassIo, Readers, WriteError, Written};
pub use wake_budget::{ListenerChange, WakeBudget};

use crate::mux::{Mux, MuxState, Rejection, hold_bit};

/// The robot's driver behind the common contract.
pub use chassis_protocols::BoxedDriver;

/// The shell's handle of a control request waiting for its answer.
pub type Ticket = u64;

/// The engine's settings, taken from the service's [`Config`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct EngineConfig {
    /// The loop's tick: mux re-evaluation, smoothing, state refresh, reading every input.
    pub tick: Duration,
    /// `MuxStatus` is published at least this often.
    pub mux_status_period: Duration,
    /// First wait before reopening a lost bus; doubles up to `reconnect_max`.
    pub reconnect_initial: Duration,
    pub reconnect_max: Duration,
    /// Receive moderation's interval; zero reads every frame the moment it arrives.
    pub rx_moderation: Duration,
    /// A GPS receiver is configured.
    pub gps: bool,
    /// The bus, for logs (`can:can0`).
    pub bus: String,
    /// The robot's description for each protocol its driver may report speaking
    /// (`SystemState::wire_protocol`): the one matching the driver's is published at start and
    /// again when detection decides. Empty: no description is published.
    pub descriptions: Vec<RobotDescription>,
    /// The shell's black box records (`service.blackbox_mib` > 0): `chassis control keep` is
    /// answered, not refused.
    pub recording: bool,
    /// The commands that disable and enable the robot's drive for stops of category 0 and 1
    /// (`Family::drive_cut`); `None` where it has none or the service does not take control.
    pub drive_cut: Option<(Command, Command)>,
}

impl EngineConfig {
    /// Wait between two attempts to open a GPS receiver.
    pub const GPS_RETRY: Duration = Duration::from_secs(1);
    /// The state is published at least this often, on the tick.
    pub const STATE_REFRESH: Duration = Duration::from_millis(100);

    pub fn from_config(config: &Config) -> Self {
        Self {
            tick: Duration::from_millis(config.tick_ms),
            mux_status_period: Duration::from_secs_f64(1.0 / config.mux_status_hz),
            reconnect_initial: Duration::from_millis(config.bus_settings.reconnect_initial_ms),
            reconnect_max: Duration::from_millis(config.bus_settings.reconnect_max_ms),
            // A spinning loop spends its core anyway: it reads every frame the moment it arrives.
            rx_moderation: match config.loop_mode {
                LoopMode::Spin => Duration::ZERO,
                _ => Duration::from_micros(config.bus_settings.rx_moderation_us),
            },
            gps: config.gps.is_some(),
            bus: config.bus.to_string(),
            descriptions: [
                WireProtocol::OWN,
                WireProtocol::V1,
                WireProtocol::V2,
                WireProtocol::DETECTING,
            ]
            .into_iter()
            .map(|protocol| crate::description::for_config(config, protocol))
            .collect(),
            recording: config.blackbox_mib > 0,
            drive_cut: if config.driver.take_control {
                config
                    .profile
                    .drive_cut(true)
                    .zip(config.profile.drive_cut(false))
            } else {
                None
            },
        }
    }
}

/// One item read from the bus, as the engine takes it.
#[derive(Debug, Clone, PartialEq)]
pub enum BusItem {
    /// A frame, or bytes of a byte stream.
    Rx(WireItem),
    /// A report of the CAN controller on itself (a SocketCAN error frame).
    Controller(ControllerReport),
}

/// Something for the shell to publish.
#[derive(Debug, Clone, PartialEq)]
pub enum ToPublish {
    /// On `chassis/<name>/state`.
    State(Box<ChassisState>),
    /// On the frame tap `chassis/<name>/frames`.
    Frame(BusFrame),
    /// On `chassis/<name>/mux`.
    Mux(Box<MuxStatus>),
    /// On `chassis/<name>/robot`.
    Description(Box<RobotDescription>),
    /// The answer to the control request the shell handed in with `ticket`.
    Response {
        ticket: Ticket,
        response: ControlResponse,
    },
}

/// What woke the loop.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Wake {
    pub bus: bool,
    pub gps: bool,
    /// One bit per source whose listener fired.
    pub sources: u32,
    pub control: bool,
    pub sim: bool,
    /// The loop polled instead of blocking (spin, or hybrid while hot).
    pub polled: bool,
}

impl Wake {
    /// Anything but the timeout woke the loop.
    pub fn is_activity(&self) -> bool {
        self.bus || self.gps || self.sources != 0 || self.control || self.sim
    }
}

/// What the shell reads in this pass.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Reads {
    /// One bit per source to drain: those that fired, every one on the tick and when polling
    /// (a publisher that never notifies is still read).
    pub sources: u32,
    pub control: bool,
    pub sim: bool,
    pub bus: bool,
    pub gps: bool,
    /// The tick was served in this pass.
    pub tick: bool,
}

/// A device the engine wants opened.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Device {
    Bus,
    Gps,
}

/// A held lock as it outlives the process: the shell's state file keeps these.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct HeldLock {
    /// The configured lock's name, e.g. `estop`.
    pub name: String,
    /// The holding source's name, or [`HeldLock::OPERATOR`] (a control request).
    pub holder: String,
    /// When it was engaged (`CLOCK_MONOTONIC`).
    pub since: Timestamp,
}

impl HeldLock {
    /// The holder of a lock engaged by a control request.
    pub const OPERATOR: &'static str = "operator";
    /// The lock held when the held set cannot be known.
    pub const ESTOP: &'static str = "estop";
}

/// At most one log line per second per kind, with the number held back.
#[derive(Debug, Default, Serialize, Deserialize)]
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

/// A device that is open, or closed and due to be opened again.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
enum Link {
    Up,
    Down { retry_at: Timestamp },
}

/// Failures counted instead of dropped silently, with their rate-limited logs.
#[derive(Debug, Default, Serialize, Deserialize)]
struct Throttles {
    rx: Throttle,
    rejected: Throttle,
    tx: Throttle,
    flood: Throttle,
    publish: Throttle,
    controller: Throttle,
    bus_errors: Throttle,
}

/// The service's decisions: see the module documentation.
///
/// Between two passes its state is a [`Engine::snapshot`]: every field but the configuration,
/// the driver and the mux, which keep their own ([`Driver::snapshot`], [`Mux::state`]).
#[derive(Serialize, Deserialize)]
pub struct Engine {
    #[serde(skip)]
    config: EngineConfig,
    #[serde(skip, default = "stand_in_driver")]
    driver: BoxedDriver,
    #[serde(skip)]
    mux: Mux,
    bus: Link,
    bus_backoff: Duration,
    gps: Option<Link>,
    gps_reader: nmea::LineReader,
    #[serde(with = "chassis_protocols::snapshot::raw")]
    gps_fix: GpsFix,
    gps_stamp_ns: u64,
    tick: Grid,
    rx_moderation: crate::rx_moderation::RxModeration,
    budget: WakeBudget,
    /// The mux must decide before the next transmit (new input since the last decision).
    undecided: bool,
    /// When the mux last decided (a source expiring after it is a pending deadline).
    decided_at: Timestamp,
    /// In this pass: the decision changed; requests arrived; the tick was served.
    mux_changed: bool,
    requests: bool,
    on_tick: bool,
    /// The last pass served the tick.
    served_tick: bool,
    state_seq: u64,
    frame_seq: u64,
    mux_seq: u64,
    /// The protocol the last published description was of, and its sequence number.
    described_protocol: Option<u8>,
    description_seq: u64,
    #[serde(with = "chassis_protocols::snapshot::raw_option")]
    last_state_body: Option<ChassisState>,
    last_state_publish: Timestamp,
    last_mux_publish: Option<Timestamp>,
    last_rx_frames: u64,
    /// The GPS sentence stamp of the last state published.
    last_gps_stamp_ns: u64,
    /// Control requests waiting for the chassis: driver token → (ticket, request seq).
    pending_controls: BTreeMap<u64, (Ticket, u64)>,
    /// `chassis control keep` asked the black box to keep its window: taken by the shell after
    /// each pass ([`Engine::take_keep`]), so not in a snapshot.
    #[serde(skip)]
    keep_asked: bool,
    last_zero_reason: u8,
    last_active: u8,
    throttles: Throttles,
    /// Samples, answers and wake-ups the shell could not publish.
    ipc_failures: u64,
    /// Empty between passes, the only time a snapshot is taken.
    #[serde(skip)]
    publications: VecDeque<ToPublish>,
    /// Each lock's holder and since when, as the shell was last told to keep it.
    kept_locks: Vec<Option<(u8, Timestamp)>>,
    /// The held set must be kept again even if it looks unchanged (a restore substituted it).
    locks_dirty: bool,
    /// A held set not kept yet (its write failed), and when to try again.
    unkept: Option<Vec<HeldLock>>,
    keep_retry_at: Timestamp,
    /// The CAN controller's state and reports (SocketCAN).
    controller: Controller,
    /// Items read from the bus in a pass, kept to spare an allocation per pass.
    #[serde(skip)]
    rx_items: Vec<(Timestamp, BusItem)>,
    /// Items written that the backend holds, with the instant their write returned.
    tx_held: Vec<(Timestamp, WireItem)>,
    /// The readers to wake at the end of the pass, one bit per [`Readers`].
    #[serde(skip)]
    to_wake: u8,
    /// The drive as the stops of category 0 and 1 left it.
    drive: drive::Drive,
}

impl std::fmt::Debug for Engine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Engine")
            .field("robot", &self.driver.robot())
            .field("bus", &self.bus)
            .field("gps", &self.gps)
            .field("state_seq", &self.state_seq)
            .field("mux_seq", &self.mux_seq)
            .finish_non_exhaustive()
    }
}

/// Stands for the driver while a snapshot is read, until [`Engine::restore`] puts the engine's
/// own back.
fn stand_in_driver() -> BoxedDriver {
    let titan = chassis_protocols::RobotKind::Titan.entry();
    titan.driver(
        &titan.defaults(),
        false,
        &Default::default(),
        Timestamp::ZERO,
    )
}

impl Engine {
    /// Its state between two passes, as bytes: the black box keeps one at the start of each
    /// stretch of its ring, so that a window whose beginning the ring let go of is replayed from
    /// there ([`Engine::restore`]). Refused while frames or publications wait (the next pass).
    pub fn snapshot(&self) -> Result<Vec<u8>, SnapshotError> {
        if !self.publications.is_empty() {
            return Err(SnapshotError::Sending);
        }
        snapshot::save(&(self, self.mux.state(), self.driver.snapshot()?))
    }

    /// Goes on from `snapshot`, taken of an engine of the same robot: the driver as it was, the
    /// mux's state on this engine's configuration. After an error the engine is in no state
    /// anyone recorded: a replay reads on to the next snapshot.
    pub fn restore(&mut self, snapshot: &[u8]) -> Result<(), SnapshotError> {
        let (mut engine, mux, driver): (Engine, MuxState, Vec<u8>) = snapshot::load(snapshot)?;
        self.driver.restore(&driver)?;
        self.mux.restore(mux)?;
        std::mem::swap(&mut engine.config, &mut self.config);
        std::mem::swap(&mut engine.driver, &mut self.driver);
        std::mem::swap(&mut engine.mux, &mut self.mux);
        engine.drive.set_commands(engine.config.drive_cut);
        *self = engine;
        Ok(())
    }

    /// An engine at `now` around `driver` and `mux`, with the bus open (a shell that could not
    /// open it reports it lost at once: [`Engine::handle_bus_lost`]).
    pub fn new(config: EngineConfig, driver: BoxedDriver, mux: Mux, now: Timestamp) -> Self {
        let sources = mux.status().sources().len();
        let safety = (0..sources)
            .filter(|&i| mux.is_safety_source(i))
            .fold(0u32, |mask, i| mask | 1 << i);
        let tick = Grid::new(config.tick, now);
        Self {
            bus: Link::Up,
            bus_backoff: config.reconnect_initial,
            gps: config.gps.then_some(Link::Down { retry_at: now }),
            gps_reader: nmea::LineReader::new(),
            gps_fix: GpsFix::default(),
            gps_stamp_ns: 0,
            budget: WakeBudget::new(sources, tick.next(), safety),
            tick,
            rx_moderation: crate::rx_moderation::RxModeration::new(config.rx_moderation, now),
            undecided: true,
            decided_at: now,
            mux_changed: false,
            requests: false,
            on_tick: false,
            served_tick: false,
            state_seq: 0,
            frame_seq: 0,
            mux_seq: 0,
            described_protocol: None,
            description_seq: 0,
            last_state_body: None,
            last_state_publish: now,
            last_mux_publish: None,
            last_rx_frames: 0,
            last_gps_stamp_ns: 0,
            pending_controls: BTreeMap::new(),
            keep_asked: false,
            last_zero_reason: ZeroReason::STARTING,
            last_active: MuxStatus::NO_SOURCE,
            throttles: Throttles::default(),
            ipc_failures: 0,
            publications: VecDeque::new(),
            kept_locks: mux.locks().map(|(_, held)| held).collect(),
            locks_dirty: false,
            unkept: None,
            keep_retry_at: now,
            controller: Controller::default(),
            rx_items: Vec::new(),
            tx_held: Vec::new(),
            to_wake: 0,
            drive: drive::Drive::new(config.drive_cut),
            config,
            driver,
            mux,
        }
    }

    // ---- inputs -------------------------------------------------------------------------

    /// The locks held before a restart, handed in before the first decision: each is held
    /// again at once and logged at WARN. A lock the configuration no longer has holds the
    /// e-stop instead; a holder that is no longer a source becomes the operator (only a
    /// release frees it).
    pub fn restore_locks(&mut self, now: Timestamp, locks: &[HeldLock]) {
        self.undecided = true;
        let mut substituted = false;
        for lock in locks {
            let holder = if lock.holder == HeldLock::OPERATOR {
                LockStatus::HOLDER_OPERATOR
            } else {
                match self.source_index(&lock.holder) {
                    Some(index) => index,
                    None => {
                        substituted = true;
                        LockStatus::HOLDER_OPERATOR
                    }
                }
            };
            let since = lock.since.min(now);
            match self.mux.restore_lock(&lock.name, holder, since) {
                Ok(()) => warn!(
                    lock = lock.name,
                    holder = lock.holder,
                    held_for_s = now.saturating_since(since).as_secs(),
                    "{} restored from before the restart: held by {} for {} s; only a release \
                     frees it",
                    lock.name,
                    lock.holder,
                    now.saturating_since(since).as_secs()
                ),
                Err(err) => {
                    substituted = true;
                    self.hold_estop(
                        now,
                        &format!("a lock held before the restart is unknown: {err}"),
                    );
                }
            }
        }
        self.kept_locks = self.mux.locks().map(|(_, held)| held).collect();
        self.locks_dirty = substituted;
    }

    /// The locks held before a restart cannot be known (`reason`: the state file is corrupt
    /// or unreadable): the e-stop is held until the operator releases it.
    pub fn restore_failed(&mut self, now: Timestamp, reason: &dyn Display) {
        self.undecided = true;
        self.hold_estop(now, reason);
        self.locks_dirty = true;
    }

    /// Starts a pass at `now` woken by `wake`:    /// Whether the last pass served the loop's tick.
    pub fn served_tick(&self) -> bool {
        self.served_tick
    }

    /// Starts a pass at `now` woken by `wake`: serves the tick when it is due and says what to
    /// read. The mux decides again at the next transmit, whatever woke the loop.
    pub fn begin_pass(&mut self, now: Timestamp, wake: Wake) -> Reads {
        let tick = self.tick.is_due(now);
        if tick {
            self.tick.served(now);
        }
        self.on_tick |= tick;
        self.served_tick = tick;
        self.undecided = true;
        self.requests = false;
        let all = (1u32 << self.mux.status().sources().len()) - 1;
        Reads {
            sources: if tick || wake.polled {
                all
            } else {
                wake.sources & all
            },
            control: wake.control || tick,
            sim: wake.sim || tick,
            bus: self.bus == Link::Up && (wake.bus || tick),
            gps: self.gps == Some(Link::Up) && wake.gps,
            tick,
        }
    }

    /// A request of source `source` (its index in the configuration), read at `now`: whatever
    /// its process wrote into shared memory, parsed here, once, into the [`ValidRequest`] the
    /// mux takes. A rejected one (a NaN or an infinity, a negative envelope, an absurd speed,
    /// unknown lock bits) is counted against its source and logged at most once a second; the
    /// source's previous request stands.
    pub fn handle_request(
        &mut self,
        now: Timestamp,
        source: usize,
        request: &VelocityRequest,
    ) -> Result<(), Rejection> {
        self.requests = true;
        self.undecided = true;
        let result = match ValidRequest::try_from(*request) {
            Ok(request) => self.mux.on_request(now, source, &request),
            Err(invalid) => Err(self.mux.refuse(source, invalid.into())),
        };
        if let Err(rejection) = &result
            && let Some(held) = self.throttles.rejected.allow(now)
        {
            let name = self
                .mux
                .source_status(source)
                .map_or("?", SourceStatus::name);
            warn!(
                source = name,
                held_back = held,
                "request rejected: {rejection}"
            );
        }
        result
    }

    /// Whether `chassis control keep` was asked since the last call: the shell's black box keeps
    /// its window.
    pub fn take_keep(&mut self) -> bool {
        std::mem::take(&mut self.keep_asked)
    }

    /// A control request, answered now or once the chassis has answered (a
    /// [`ToPublish::Response`] with `ticket`).
    pub fn handle_control(&mut self, now: Timestamp, ticket: Ticket, request: &ControlRequest) {
        let seq = request.seq;
        let (status, message) = match request_to_action(request) {
            Err(reason) => (ControlStatus::INVALID, reason.to_string()),
            Ok(ControlAction::LockRelease(name)) => {
                self.undecided = true;
                match self.mux.release_lock(&name) {
                    Ok(true) => match self.mux.awaiting_zero().as_slice() {
                        [] => (ControlStatus::OK, format!("{name} released")),
                        waiting => (
                            ControlStatus::OK,
                            format!(
                                "{name} released; nothing moves until {} asks for zero (a \
                                 release never starts motion)",
                                waiting.join(", ")
                            ),
                        ),
                    },
                    Ok(false) => (ControlStatus::OK, format!("{name} was not held")),
                    Err(err) => (ControlStatus::INVALID, err.to_string()),
                }
            }
            Ok(ControlAction::LockEngage(name, category)) => {
                self.undecided = true;
                match self.mux.engage_lock(now, &name, category) {
                    Ok(true) => (
                        ControlStatus::OK,
                        format!("{name} engaged by the operator{}", self.cut_note(&name)),
                    ),
                    Ok(false) => (ControlStatus::OK, format!("{name} was already held")),
                    Err(err) => (ControlStatus::INVALID, err.to_string()),
                }
            }
            Ok(ControlAction::SpeedLimit(mps)) => {
                self.undecided = true;
                self.mux.set_speed_limit(mps);
                match mps {
                    Some(mps) => (
                        ControlStatus::OK,
                        format!("speed limited to {mps} m/s by the operator"),
                    ),
                    None => (ControlStatus::OK, "speed limit lifted".to_string()),
                }
            }
            Ok(ControlAction::Keep) if self.config.recording => {
                self.keep_asked = true;
                let kept = "the black box keeps the window around now (blackbox/kept/)";
                (ControlStatus::OK, kept.to_string())
            }
            Ok(ControlAction::Keep) => (
                ControlStatus::UNSUPPORTED,
                "the black box is off (service.blackbox_mib = 0): nothing to keep".to_string(),
            ),
            Ok(ControlAction::Chassis(command)) => match self.driver.control(now, &command) {
                ControlOutcome::Pending(token) => {
                    info!(
                        request = command.name(),
                        "control request waiting for the chassis"
                    );
                    self.pending_controls.insert(token, (ticket, seq));
                    return;
                }
                outcome => (outcome.status(), outcome.message()),
            },
        };
        let kind = ControlKind::name(request.kind);
        if status == ControlStatus::OK {
            info!(kind, "control: {message}");
        } else {
            warn!(
                kind,
                status = ControlStatus::name(status),
                "control refused: {message}"
            );
        }
        self.respond(now, ticket, seq, status, &message);
    }

    /// A frame (or serial chunk) read from the bus at `stamp`: tapped, handed to the driver,
    /// and the state published if it changed. A request not yet decided is decided first.
    pub fn handle_rx(&mut self, stamp: Timestamp, rx: Rx<'_>) {
        if self.undecided {
            self.decide(stamp);
        }
        self.tap(stamp, FrameDirection::RX, FrameKind::SERIAL, rx);
        if matches!(rx, Rx::Can(_)) && self.controller.state() == ControllerState::BUS_OFF {
            let change = self.controller.heard_frame();
            self.log_controller(stamp, &change);
            self.publish_state(stamp);
        }
        self.driver.handle_rx(stamp, rx);
        self.update_holds();
        self.update_drive(stamp);
        self.publish_state_if_changed(stamp);
    }

    /// A report of the CAN controller read at `stamp`: counted, logged with what to do, and
    /// the state published when the controller's state changed.
    pub fn handle_controller(&mut self, stamp: Timestamp, report: &ControllerReport) {
        let change = self.controller.apply(report);
        self.log_controller(stamp, &change);
        self.update_holds();
        if change.state.is_some() {
            self.publish_state(stamp);
        }
    }

    /// A read of the bus at `now` gave `items` frames (a byte stream: one per 8 bytes);
    /// `backlog`: it stopped at its batch limit with more pending. Feeds receive moderation.
    pub fn handle_bus_read(&mut self, now: Timestamp, items: usize, backlog: bool) {
        self.rx_moderation.on_read(now, items, backlog);
    }

    /// True while receive moderation pauses the bus: the shell stops watching its descriptor
    /// (the frames wait in the kernel) until [`Engine::poll_timeout`].
    pub fn is_rx_paused(&mut self, now: Timestamp) -> bool {
        self.rx_moderation.is_paused(now)
    }

    /// Bytes from the GPS receiver at `now`.
    pub fn handle_gps(&mut self, now: Timestamp, bytes: &[u8]) {
        self.tap(now, FrameDirection::RX, FrameKind::GPS, Rx::Bytes(bytes));
        self.gps_reader.push(bytes);
        while let Some(line) = self.gps_reader.next_line() {
            match nmea::parse_sentence(&line) {
                Ok(sentence) => {
                    nmea::apply(&sentence, &mut self.gps_fix);
                    self.gps_stamp_ns = now.as_nanos();
                }
                Err(err) => {
                    if let Some(held) = self.throttles.rx.allow(now) {
                        warn!(held_back = held, "GPS sentence dropped: {err}");
                    }
                }
            }
        }
    }

    /// An item the shell wrote to the bus; `stamp` is when the write returned.
    pub fn handle_sent(&mut self, stamp: Timestamp, item: &WireItem) {
        self.tap(stamp, FrameDirection::TX, FrameKind::SERIAL, item.as_rx());
    }

    /// One item could not be sent (transmit queue full); the bus is still there.
    pub fn handle_tx_dropped(&mut self, now: Timestamp, error: &dyn Display) {
        if let Some(held) = self.throttles.tx.allow(now) {
            warn!(held_back = held, "{error}");
        }
    }

    /// The shell could not publish `what` (a sample, an answer, a wake-up of readers): counted,
    /// logged at most once a second.
    pub fn handle_publish_failed(&mut self, now: Timestamp, what: &str, error: &dyn Display) {
        self.ipc_failures += 1;
        if let Some(held) = self.throttles.publish.allow(now) {
            warn!(
                held_back = held,
                failures = self.ipc_failures,
                "cannot publish {what}: {error}"
            );
        }
    }

    /// Publications and wake-ups that failed since start.
    pub fn ipc_failures(&self) -> u64 {
        self.ipc_failures
    }

    /// The bus is gone (or could not be opened at start): nothing is commanded until it is
    /// back; it is reopened after a backoff.
    pub fn handle_bus_lost(&mut self, now: Timestamp, error: &dyn Display) {
        error!("{error}; commanding nothing until it is back, retrying");
        self.driver.set_bus_down(now, true);
        self.bus = Link::Down {
            retry_at: now + self.bus_backoff,
        };
        self.update_holds();
    }

    /// The GPS receiver is gone: it is reopened after a second.
    pub fn handle_gps_lost(&mut self, now: Timestamp, error: &dyn Display) {
        error!("GPS receiver lost: {error}; retrying");
        self.gps = Some(Link::Down {
            retry_at: now + EngineConfig::GPS_RETRY,
        });
    }

    /// `device` was opened as [`Engine::poll_open`] asked.
    pub fn handle_opened(&mut self, now: Timestamp, device: Device, name: &str) {
        match device {
            Device::Bus => {
                info!(bus = name, "bus open again");
                // The interface was down (the controller restarted) or replaced.
                self.controller.reopened();
                self.bus = Link::Up;
                self.bus_backoff = self.config.reconnect_initial;
                self.rx_moderation.reset(now);
                self.driver.set_bus_down(now, false);
                self.update_holds();
            }
            Device::Gps => {
                info!(gps = name, "GPS receiver open");
                self.gps = Some(Link::Up);
            }
        }
    }

    /// Opening `device` failed: the next attempt waits longer (the bus: doubling up to the
    /// configured maximum).
    pub fn handle_open_failed(&mut self, now: Timestamp, device: Device, error: &dyn Display) {
        match device {
            Device::Bus => {
                debug!("reopening the bus: {error}");
                self.bus_backoff = (self.bus_backoff * 2).min(self.config.reconnect_max);
                self.bus = Link::Down {
                    retry_at: now + self.bus_backoff,
                };
            }
            Device::Gps => {
                debug!("opening the GPS receiver: {error}");
                self.gps = Some(Link::Down {
                    retry_at: now + EngineConfig::GPS_RETRY,
                });
            }
        }
    }

    /// Processes what is due at `now`: a decision not yet made, then the driver's deadlines
    /// (the heartbeat, the chassis' silence, control timeouts).
    pub fn handle_timeout(&mut self, now: Timestamp) {
        if self.undecided {
            self.decide(now);
        }
        if self.driver.poll_timeout().is_some_and(|t| t <= now) {
            self.driver.handle_timeout(now);
            self.update_holds();
        }
        self.update_drive(now);
    }

    /// Ends a pass: answers finished control requests, logs the driver's notices, publishes
    /// the mux status (on a change, while ramping after requests, and at its rate) and on the
    /// tick refreshes the state (frames or GPS sentences arrived that did not change it, and at
    /// least every 100 ms).
    pub fn end_pass(&mut self, now: Timestamp) {
        self.drain_driver_events(now);
        self.publish_description_if_changed(now);
        let period_over = self
            .last_mux_publish
            .is_none_or(|t| now.saturating_since(t) >= self.config.mux_status_period);
        if std::mem::take(&mut self.mux_changed)
            || self.requests && self.mux.is_ramping()
            || period_over
        {
            self.publish_mux(now);
        }
        if std::mem::take(&mut self.on_tick) {
            let rx_frames = self.driver.state().link.rx_frames;
            if rx_frames != self.last_rx_frames
                || self.gps_stamp_ns != self.last_gps_stamp_ns
                || now.saturating_since(self.last_state_publish) >= EngineConfig::STATE_REFRESH
            {
                self.publish_state(now);
            } else {
                self.publish_state_if_changed(now);
            }
        }
    }

    /// Counts the wake-ups of the sources in `fired` (one bit each) against their budget;
    /// returns the listeners the shell must detach (over budget) or attach again (a new tick).
    pub fn spend_wakeups(&mut self, now: Timestamp, fired: u32) -> Vec<ListenerChange> {
        let changes = self.budget.spend(fired, self.tick.next());
        for change in &changes {
            if let ListenerChange::Detach(index) = change
                && let Some(held) = self.throttles.flood.allow(now)
            {
                let name = self
                    .mux
                    .source_status(*index)
                    .map_or("?", SourceStatus::name);
                warn!(
                    source = name,
                    held_back = held,
                    "the source woke the loop more than {} times in one tick: read on the tick \
                     only until the next",
                    WakeBudget::PER_TICK
                );
            }
        }
        changes
    }

    /// Every listener is attached again (the shell made a new wait set).
    pub fn reset_wakeups(&mut self) {
        self.budget.reset(self.tick.next());
    }

    /// Orderly stop: command zero (and the brake where there is one), refuse the control
    /// requests still waiting. What follows is transmitted, then [`Engine::publish_all`]
    /// ([`Engine::stop`] does all three).
    pub fn shutdown(&mut self, now: Timestamp) {
        info!("stopping: commanding zero and engaging the brake where there is one");
        self.undecided = false;
        self.driver.shutdown(now);
        let pending = std::mem::take(&mut self.pending_controls).into_values();
        for (ticket, seq) in pending {
            self.respond(
                now,
                ticket,
                seq,
                ControlStatus::REFUSED,
                "the service is stopping",
            );
        }
    }

    /// Publishes the state and the mux status now (at start and at the end).
    pub fn publish_all(&mut self, now: Timestamp) {
        self.drain_driver_events(now);
        self.publish_description_if_changed(now);
        self.publish_state(now);
        self.publish_mux(now);
    }

    /// Publishes the description of the protocol the driver speaks when it is not the one
    /// published last (at start, and when detection decides).
    fn publish_description_if_changed(&mut self, now: Timestamp) {
        let protocol = self.driver.state().system.wire_protocol;
        if self.described_protocol == Some(protocol) {
            return;
        }
        let Some(template) = self
            .config
            .descriptions
            .iter()
            .find(|d| d.protocol == protocol)
        else {
            return;
        };
        self.described_protocol = Some(protocol);
        self.description_seq += 1;
        let mut description = Box::new(*template);
        description.seq = self.description_seq;
        description.stamp_ns = now.as_nanos();
        info!(
            protocol = WireProtocol::name(protocol),
            "describing the robot on chassis/<name>/robot"
        );
        self.publications
            .push_back(ToPublish::Description(description));
    }

    // ---- outputs ------------------------------------------------------------------------

    /// The next item to write to the bus. The mux decides first when something changed since
    /// its last decision. While the bus is down nothing is sent (the driver does not queue).
    pub fn poll_transmit(&mut self, now: Timestamp) -> Option<WireItem> {
        if self.undecided {
            self.decide(now);
        }
        if self.bus != Link::Up {
            // Nothing can be sent; the driver does not queue while the bus is down.
            while self.driver.poll_transmit(now).is_some() {}
            return None;
        }
        self.driver.poll_transmit(now)
    }

    /// The held locks when the set changed since the last call (engaged, released, restored
    /// with a substitute): to be kept (atomically) before anything else is published.
    pub fn poll_held_locks(&mut self) -> Option<Vec<HeldLock>> {
        let unchanged = self
            .mux
            .locks()
            .map(|(_, held)| held)
            .eq(self.kept_locks.iter().copied());
        if unchanged && !self.locks_dirty {
            return None;
        }
        self.locks_dirty = false;
        self.kept_locks = self.mux.locks().map(|(_, held)| held).collect();
        let held = self
            .mux
            .locks()
            .filter_map(|(name, held)| {
                held.map(|(holder, since)| HeldLock {
                    name: name.to_string(),
                    holder: self.holder_name(holder),
                    since,
                })
            })
            .collect();
        Some(held)
    }

    /// The next thing to publish.
    pub fn poll_publication(&mut self) -> Option<ToPublish> {
        self.publications.pop_front()
    }

    /// When the shell must start a pass at the latest: the tick, the end of a moderation pause,
    /// the driver's deadline, the next expiry of a source, a pending reopen.
    pub fn poll_timeout(&self) -> Timestamp {
        let retry = |link: Option<Link>| match link {
            Some(Link::Down { retry_at }) => Some(retry_at),
            _ => None,
        };
        [
            self.rx_moderation.paused_until(),
            self.driver.poll_timeout(),
            self.mux.next_deadline(self.decided_at),
            retry(Some(self.bus)),
            retry(self.gps),
        ]
        .into_iter()
        .flatten()
        .fold(self.tick.next(), Timestamp::min)
    }

    /// A device due to be (re)opened at `now`.
    pub fn poll_open(&self, now: Timestamp) -> Option<Device> {
        let due =
            |link: Option<Link>| matches!(link, Some(Link::Down { retry_at }) if retry_at <= now);
        if due(Some(self.bus)) {
            Some(Device::Bus)
        } else if due(self.gps) {
            Some(Device::Gps)
        } else {
            None
        }
    }

    /// True while the bus is open.
    pub fn is_bus_up(&self) -> bool {
        self.bus == Link::Up
    }

    /// The mux (read-only: its status, its sources).
    pub fn mux(&self) -> &Mux {
        &self.mux
    }

    /// What the driver believes.
    pub fn state(&self) -> &ChassisState {
        self.driver.state()
    }

    // ---- inside -------------------------------------------------------------------------

    /// Hands the mux the stops the bus and the chassis impose now (see `crate::mux`): the bus
    /// lost or bus-off; the chassis' E-stop; a remote-control transmitter in charge; a fault
    /// that stops the drive — each as the driver reports it in the state it keeps. (A chassis
    /// that is only silent still obeys what it is sent: no stop.) A change is decided again
    /// before the next transmit.
    fn update_holds(&mut self) {
        let state = self.driver.state();
        let faults = state.system.fault_flags;
        let holds = [
            (
                self.bus != Link::Up
                    || self.controller.state() == ControllerState::BUS_OFF
                    || state.link_flags & LinkFlags::BUS_DOWN != 0,
                Stop::BUS,
            ),
            (
                faults & FaultFlags::EMERGENCY_STOP != 0,
                Stop::CHASSIS_ESTOP,
            ),
            (
                state.link_flags & LinkFlags::RC_AUTHORITY != 0,
                Stop::REMOTE_CONTROL,
            ),
            (faults & FaultFlags::STOPS_DRIVE != 0, Stop::CHASSIS_FAULT),
        ]
        .into_iter()
        .filter(|&(held, _)| held)
        .fold(0, |bits, (_, stop)| bits | hold_bit(stop));
        let changed = holds ^ self.mux.holds();
        if changed == 0 {
            return;
        }
        for (stop, name) in Stop::NAMES {
            match (changed & hold_bit(stop) != 0, holds & hold_bit(stop) != 0) {
                (false, _) => {}
                (true, true) => warn!(stop = name, "stopped: commanding zero until it ends"),
                (true, false) => warn!(
                    stop = name,
                    "{name} ended: motion starts again only from a zero of the source that \
                     would win"
                ),
            }
        }
        self.mux.set_holds(holds);
        self.undecided = true;
    }

    fn decide(&mut self, now: Timestamp) {
        self.undecided = false;
        self.decided_at = now;
        let decision = self.mux.evaluate(now);
        self.driver.set_command(now, &decision.output);
        if decision.changed {
            self.mux_changed = true;
            self.log_mux_change();
        }
        self.update_drive(now);
    }

    /// Carries out the mux's stop category on the drive (`engine::drive`); a change is
    /// published with the mux status.
    fn update_drive(&mut self, now: Timestamp) {
        if self
            .drive
            .update(now, self.mux.stop_category(), &mut self.driver)
        {
            self.mux_changed = true;
        }
    }

    /// What an operator's engage of `lock` answers beyond "engaged": its stop category and, for
    /// a robot that cannot cut its drive, that it holds zero instead.
    fn cut_note(&self, lock: &str) -> String {
        match self.mux.lock_category(lock) {
            Some(category) if category < StopCategory::HOLD && self.config.drive_cut.is_none() => {
                format!(
                    ", stop category {}: this robot cannot cut its drive, zero is held",
                    StopCategory::text(category)
                )
            }
            Some(category) => format!(", stop category {}", StopCategory::text(category)),
            None => String::new(),
        }
    }

    /// Holds the e-stop (the lock called `estop`; every lock when none has that name) for the
    /// operator, logging why at ERROR.
    fn hold_estop(&mut self, now: Timestamp, reason: &dyn Display) {
        let names: Vec<String> = self.mux.locks().map(|(name, _)| name.to_string()).collect();
        let wanted: Vec<String> = if names.iter().any(|n| n == HeldLock::ESTOP) {
            vec![HeldLock::ESTOP.to_string()]
        } else {
            names
        };
        if wanted.is_empty() {
            error!("{reason}; no lock is configured to hold");
            return;
        }
        for name in &wanted {
            if self
                .mux
                .locks()
                .any(|(n, held)| n == name && held.is_none())
            {
                self.mux
                    .restore_lock(name, LockStatus::HOLDER_OPERATOR, now)
                    .ok();
            }
        }
        error!(
            "{reason}; starting with {} held until the operator releases it",
            wanted.join(", ")
        );
    }

    fn source_index(&self, name: &str) -> Option<u8> {
        let sources = self.mux.status().sources();
        // Fewer than MAX_SOURCES (8) sources: an index fits a u8.
        sources
            .iter()
            .position(|s| s.name() == name)
            .map(|i| i as u8)
    }

    fn holder_name(&self, holder: u8) -> String {
        if holder == LockStatus::HOLDER_OPERATOR {
            return HeldLock::OPERATOR.to_string();
        }
        self.mux
            .source_status(usize::from(holder))
            .map_or_else(|| HeldLock::OPERATOR.to_string(), |s| s.name().to_string())
    }

    fn respond(&mut self, now: Timestamp, ticket: Ticket, seq: u64, status: u8, message: &str) {
        let mut response = ControlResponse::new(seq, status, message);
        response.stamp_ns = now.as_nanos();
        self.publications
            .push_back(ToPublish::Response { ticket, response });
    }

    fn publish_state(&mut self, now: Timestamp) {
        let mut state = *self.driver.state();
        if self.gps_stamp_ns != 0 {
            state.gps = self.gps_fix;
            state.touch(Group::Gps, self.gps_stamp_ns);
        }
        if self.config.gps && self.gps != Some(Link::Up) {
            state.link_flags |= LinkFlags::GPS_DOWN;
        }
        state.link.ipc_failures = self.ipc_failures;
        self.controller.write(&mut state);
        self.state_seq += 1;
        state.seq = self.state_seq;
        self.last_rx_frames = state.link.rx_frames;
        self.last_gps_stamp_ns = self.gps_stamp_ns;
        self.last_state_body = Some(state.body());
        self.last_state_publish = now;
        self.publications
            .push_back(ToPublish::State(Box::new(state)));
    }

    fn publish_state_if_changed(&mut self, now: Timestamp) {
        let body = self.driver.state().body();
        if self
            .last_state_body
            .is_none_or(|last| last.as_bytes() != body.as_bytes())
        {
            self.publish_state(now);
        }
    }

    /// The mux status as published: the mux's decision, the robot's own clamps (applied by the
    /// driver) and the drive as the stops left it.
    pub fn mux_status(&self) -> MuxStatus {
        let mut status = *self.mux.status();
        status.clamp_flags |= self.driver.state().command.clamp_flags;
        status.drive = self.drive.state();
        status
    }

    fn publish_mux(&mut self, now: Timestamp) {
        let mut status = self.mux_status();
        self.mux_seq += 1;
        status.seq = self.mux_seq;
        self.last_mux_publish = Some(now);
        self.publications
            .push_back(ToPublish::Mux(Box::new(status)));
    }

    /// Puts `item` on the tap. `bytes_kind` is the kind of a byte chunk (serial or GPS).
    fn tap(&mut self, stamp: Timestamp, direction: u8, bytes_kind: u8, item: Rx<'_>) {
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
                self.publications.push_back(ToPublish::Frame(frame));
            }
            Rx::Bytes(bytes) => {
                for chunk in bytes.chunks(BusFrame::DATA_LEN) {
                    self.frame_seq += 1;
                    let mut frame = BusFrame {
                        stamp_ns: stamp.as_nanos(),
                        seq: self.frame_seq,
                        direction,
                        kind: bytes_kind,
                        ..BusFrame::default()
                    };
                    frame.set_payload(chunk);
                    self.publications.push_back(ToPublish::Frame(frame));
                }
            }
        }
    }

    fn drain_driver_events(&mut self, now: Timestamp) {
        while let Some(event) = self.driver.poll_event() {
            match event {
                DriverEvent::ControlDone {
                    token,
                    status,
                    message,
                } => {
                    if let Some((ticket, seq)) = self.pending_controls.remove(&token) {
                        info!(status = ControlStatus::name(status), "control: {message}");
                        self.respond(now, ticket, seq, status, &message);
                    }
                }
                DriverEvent::RxDropped { reason } => {
                    if let Some(held) = self.throttles.rx.allow(now) {
                        warn!(held_back = held, "frame dropped: {reason}");
                    }
                }
                DriverEvent::Notice { level, message } => match level {
                    Level::Info => info!("{message}"),
                    Level::Warn => warn!("{message}"),
                    Level::Error => error!("{message}"),
                },
            }
        }
    }

    /// Logs what a report of the CAN controller changed: a new state always (at most once a
    /// second, with the number held back), bus errors and missing acknowledgements at most once
    /// a second with their totals.
    fn log_controller(&mut self, now: Timestamp, change: &can_controller::Change) {
        let bus = self.config.bus.as_str();
        let iface = bus.strip_prefix("can:").unwrap_or(bus);
        let mut link = Default::default();
        if change.state.is_some() || change.restarted {
            let mut state = ChassisState::default();
            self.controller.write(&mut state);
            link = state.link;
        }
        if let Some((from, to)) = change.state
            && let Some(held) = self.throttles.controller.allow(now)
        {
            let counters = format!(
                "error counters: tx {}, rx {}",
                link.can_tx_error_count, link.can_rx_error_count
            );
            match to {
                ControllerState::BUS_OFF => error!(
                    held_back = held,
                    bus_off = link.can_bus_off,
                    "{bus}: the CAN controller is bus-off: it has left the bus ({}); nothing \
                     reaches the chassis; {}",
                    can_controller::BUS_TROUBLE,
                    can_controller::bus_off_fix(iface, self.controller.restart_ms())
                ),
                ControllerState::ERROR_PASSIVE => warn!(
                    held_back = held,
                    "{bus}: the CAN controller is error-passive ({counters}): {}",
                    can_controller::BUS_TROUBLE
                ),
                ControllerState::ERROR_WARNING => info!(
                    held_back = held,
                    "{bus}: the CAN controller is at the error warning level ({counters})"
                ),
                ControllerState::ERROR_ACTIVE
                    if matches!(
                        from,
                        ControllerState::BUS_OFF | ControllerState::ERROR_PASSIVE
                    ) =>
                {
                    info!(
                        held_back = held,
                        "{bus}: the CAN controller is error-active again"
                    )
                }
                ControllerState::UNKNOWN if from == ControllerState::BUS_OFF => info!(
                    held_back = held,
                    "{bus}: frames arrive again: the CAN controller is back on the bus"
                ),
                _ => debug!(
                    "{bus}: CAN controller {} → {}",
                    ControllerState::name(from),
                    ControllerState::name(to)
                ),
            }
        }
        if change.restarted {
            warn!(
                restarts = link.can_restarts,
                "{bus}: the CAN controller was restarted after a bus-off"
            );
        }
        if (change.bus_error || change.no_ack)
            && let Some(held) = self.throttles.bus_errors.allow(now)
        {
            let mut state = ChassisState::default();
            self.controller.write(&mut state);
            warn!(
                held_back = held,
                bus_errors = state.link.can_bus_errors,
                unacknowledged = state.link.can_no_ack,
                "{bus}: the CAN controller reports errors on the bus ({})",
                can_controller::BUS_TROUBLE
            );
        }
        if change.overflow
            && let Some(held) = self.throttles.bus_errors.allow(now)
        {
            warn!(
                held_back = held,
                "{bus}: the CAN controller's buffer overflowed: frames were lost before this \
                 computer read them (a busy or slow host, a USB adapter behind a shared hub)"
            );
        }
    }

    fn log_mux_change(&mut self) {
        let status = *self.mux.status();
        if status.zero_reason != self.last_zero_reason {
            let required: Vec<&str> = status
                .sources()
                .iter()
                .filter(|s| s.has(SourceFlags::REQUIRED) && !s.has(SourceFlags::FRESH))
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
}
