//! The sans-IO driver contract, and the pieces every robot driver shares.
//!
//! A driver is a value in the quinn-proto shape: frames go in with their time
//! ([`Driver::handle_rx`]), commands and control actions queue work ([`Driver::set_command`],
//! [`Driver::control`]), frames to send come out ([`Driver::poll_transmit`]), and
//! [`Driver::poll_timeout`] names the next deadline, at which the owner calls
//! [`Driver::handle_timeout`]. The state snapshot can be read at any time. A driver never sleeps,
//! reads a clock or touches a socket, so the same code runs on a real bus, against the simulated
//! firmware and in unit tests on simulated time.

use std::collections::VecDeque;
use std::time::Duration;

use chassis_interfaces::{
    ChassisState, ControlMode, ControlStatus, FaultFlags, Group, LinkFlags, OdometryState, Velocity,
};
use serde::{Deserialize, Serialize};

use crate::DecodeError;
use crate::can::CanFrame;
use crate::command::Command;
use crate::kind::RobotKind;
use crate::snapshot::SnapshotError;
use crate::time::{Grid, Timestamp, earliest};

/// What arrived from the bus.
#[derive(Debug, Clone, Copy)]
pub enum Rx<'a> {
    /// One CAN frame (TITAN, SCOUT MINI).
    Can(&'a CanFrame),
    /// A chunk of the serial byte stream, in any chunking (XBot).
    Bytes(&'a [u8]),
}

/// One item on the wire, owned, in either direction: what a driver or a simulated firmware puts
/// on the bus, and what a bus hands back as received. [`Rx`] is its borrowed form.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum WireItem {
    /// One CAN frame (TITAN, SCOUT MINI, protocol V2).
    Can(CanFrame),
    /// A chunk of a serial byte stream (XBot).
    Bytes(Vec<u8>),
}

impl WireItem {
    /// The CAN frame, if this is one.
    pub fn as_can(&self) -> Option<&CanFrame> {
        match self {
            WireItem::Can(frame) => Some(frame),
            WireItem::Bytes(_) => None,
        }
    }

    /// As a received item for the other side of the wire.
    pub fn as_rx(&self) -> Rx<'_> {
        match self {
            WireItem::Can(frame) => Rx::Can(frame),
            WireItem::Bytes(bytes) => Rx::Bytes(bytes),
        }
    }
}

/// The immediate answer to a control action.
#[derive(Debug, Clone, PartialEq)]
pub enum ControlOutcome {
    /// Done: the frames are queued.
    Done(String),
    /// Accepted; the answer comes later as [`DriverEvent::ControlDone`] with this token
    /// (e.g. steering zero waits for the chassis' acknowledgement).
    Pending(u64),
    /// Understood but not now (e.g. off-road mode while moving).
    Refused(String),
    /// This robot has no such function.
    Unsupported(String),
    /// An argument is out of range.
    Invalid(String),
}

impl ControlOutcome {
    /// The `chassis_interfaces::ControlStatus` of a finished outcome (`Pending` reads as OK).
    pub fn status(&self) -> u8 {
        match self {
            ControlOutcome::Done(_) | ControlOutcome::Pending(_) => ControlStatus::OK,
            ControlOutcome::Refused(_) => ControlStatus::REFUSED,
            ControlOutcome::Unsupported(_) => ControlStatus::UNSUPPORTED,
            ControlOutcome::Invalid(_) => ControlStatus::INVALID,
        }
    }

    pub fn message(&self) -> String {
        match self {
            ControlOutcome::Done(m)
            | ControlOutcome::Refused(m)
            | ControlOutcome::Unsupported(m)
            | ControlOutcome::Invalid(m) => m.clone(),
            ControlOutcome::Pending(token) => format!("pending ({token})"),
        }
    }
}

impl From<crate::command::CommandError> for ControlOutcome {
    fn from(err: crate::command::CommandError) -> Self {
        match err {
            crate::command::CommandError::Unsupported { .. } => {
                ControlOutcome::Unsupported(err.to_string())
            }
            _ => ControlOutcome::Invalid(err.to_string()),
        }
    }
}

/// How loud a [`DriverEvent::Notice`] is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Level {
    Info,
    Warn,
    Error,
}

/// Things that happened inside the driver that its owner may want to log or answer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum DriverEvent {
    /// A `Pending` control action finished.
    ControlDone {
        token: u64,
        /// `chassis_interfaces::ControlStatus`.
        status: u8,
        message: String,
    },
    /// A received frame was dropped (bad checksum, undecodable, unknown id); counted in
    /// `ChassisState::link`. The owner rate-limits the log lines.
    RxDropped { reason: String },
    /// A change worth a log line (mode change, RC takeover, fault set or cleared, …).
    Notice { level: Level, message: String },
}

/// A driver of any robot, as the registry makes them.
pub type BoxedDriver = Box<dyn Driver + Send>;

/// The contract every robot driver fulfils.
pub trait Driver {
    fn robot(&self) -> RobotKind;

    /// Feeds what arrived from the bus at `now`.
    fn handle_rx(&mut self, now: Timestamp, rx: Rx<'_>);

    /// The mux's output: the motion to command from now on (SI units, ISO axes), finite by its
    /// type. A changed command is sent at once (subject to
    /// [`DriverConfig::min_command_interval_ms`]); the heartbeat repeats the latest one.
    fn set_command(&mut self, now: Timestamp, command: &Velocity);

    /// A control action (mode, brake, lights, …). Motion commands go through
    /// [`Driver::set_command`]; a [`Command::Velocity`] here is `Invalid`.
    fn control(&mut self, now: Timestamp, command: &Command) -> ControlOutcome;

    /// Processes deadlines that have passed (heartbeat, silence, idle brake, control timeouts).
    fn handle_timeout(&mut self, now: Timestamp);

    /// The next frame to send, if any.
    fn poll_transmit(&mut self, now: Timestamp) -> Option<WireItem>;

    /// When [`Driver::handle_timeout`] must be called next.
    fn poll_timeout(&self) -> Option<Timestamp>;

    /// The next event, if any.
    fn poll_event(&mut self) -> Option<DriverEvent>;

    /// Everything the chassis reported, plus link health.
    fn state(&self) -> &ChassisState;

    /// The bus went away (`true`) or came back (`false`). While it is down nothing is sent; when it
    /// returns the driver re-establishes control (mode frames, brake) as after power-up.
    fn set_bus_down(&mut self, now: Timestamp, down: bool);

    /// Orderly stop: command zero and, where the robot has one, engage the parking brake. The
    /// owner drains [`Driver::poll_transmit`] afterwards.
    fn shutdown(&mut self, now: Timestamp);

    /// Everything the driver holds, its configuration included, as bytes: the black box keeps
    /// them so that a replay can go on from there ([`Driver::restore`]).
    fn snapshot(&self) -> Result<Vec<u8>, SnapshotError>;

    /// Becomes the driver `snapshot` was taken of (a driver of the same robot).
    fn restore(&mut self, snapshot: &[u8]) -> Result<(), SnapshotError>;
}

/// A boxed driver is a driver (the registry's drivers run in [`crate::pair::Pair`] and the engine).
impl<D: Driver + ?Sized> Driver for Box<D> {
    fn robot(&self) -> RobotKind {
        (**self).robot()
    }
    fn handle_rx(&mut self, now: Timestamp, rx: Rx<'_>) {
        (**self).handle_rx(now, rx);
    }
    fn set_command(&mut self, now: Timestamp, command: &Velocity) {
        (**self).set_command(now, command);
    }
    fn control(&mut self, now: Timestamp, command: &Command) -> ControlOutcome {
        (**self).control(now, command)
    }
    fn handle_timeout(&mut self, now: Timestamp) {
        (**self).handle_timeout(now);
    }
    fn poll_transmit(&mut self, now: Timestamp) -> Option<WireItem> {
        (**self).poll_transmit(now)
    }
    fn poll_timeout(&self) -> Option<Timestamp> {
        (**self).poll_timeout()
    }
    fn poll_event(&mut self) -> Option<DriverEvent> {
        (**self).poll_event()
    }
    fn state(&self) -> &ChassisState {
        (**self).state()
    }
    fn set_bus_down(&mut self, now: Timestamp, down: bool) {
        (**self).set_bus_down(now, down);
    }
    fn shutdown(&mut self, now: Timestamp) {
        (**self).shutdown(now);
    }
    fn snapshot(&self) -> Result<Vec<u8>, SnapshotError> {
        (**self).snapshot()
    }
    fn restore(&mut self, snapshot: &[u8]) -> Result<(), SnapshotError> {
        (**self).restore(snapshot)
    }
}

/// Settings every driver shares (the `[driver]` table of the service's config).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DriverConfig {
    /// No feedback for this long sets `LinkFlags::CHASSIS_SILENT`, ms.
    pub silence_timeout_ms: u64,
    /// Smallest spacing between two motion frames when the command changes faster, ms. The
    /// heartbeat keeps its own period regardless; a stop is never delayed.
    pub min_command_interval_ms: u64,
    /// Take control at start (TITAN: CAN command mode) and take it back after a chassis reboot.
    pub take_control: bool,
    /// Engage the parking brake after the command has been zero this long, ms (TITAN); 0 never.
    pub brake_idle_engage_ms: u64,
    /// How long to wait for an acknowledgement (steering zero), ms.
    pub control_timeout_ms: u64,
}

impl Default for DriverConfig {
    fn default() -> Self {
        Self {
            silence_timeout_ms: 100,
            min_command_interval_ms: 2,
            take_control: true,
            brake_idle_engage_ms: 5000,
            control_timeout_ms: 1000,
        }
    }
}

/// The heartbeat and the "send a changed command at once" rule.
///
/// The heartbeat runs on a fixed grid (`start + k·period`), so a late wake-up never shifts later
/// heartbeats and command changes in between never disturb it. A changed command is due at once,
/// but no sooner than `min_interval` after the previous motion frame — except a stop, which is
/// always due at once.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CommandSchedule {
    heartbeat: Grid,
    min_interval: Duration,
    last_sent: Option<Timestamp>,
    pending: bool,
    urgent: bool,
}

impl CommandSchedule {
    /// The first heartbeat is due at `now`.
    pub fn new(period: Duration, min_interval: Duration, now: Timestamp) -> Self {
        Self {
            heartbeat: Grid::new(period.max(Duration::from_millis(1)), now),
            min_interval,
            last_sent: None,
            pending: false,
            urgent: false,
        }
    }

    /// Takes `next` as the command the motion frames carry: when it differs from `*current` it
    /// replaces it and goes out soon ([`Self::command_changed`]; `stop` ignores the minimum
    /// interval).
    pub fn update<M: PartialEq>(&mut self, current: &mut M, next: M, stop: bool) {
        if *current != next {
            *current = next;
            self.command_changed(stop);
        }
    }

    /// The command changed: send it soon. `urgent` (a stop) ignores the minimum interval.
    pub fn command_changed(&mut self, urgent: bool) {
        self.pending = true;
        self.urgent |= urgent;
    }

    /// True when a motion frame should go out now.
    pub fn is_due(&self, now: Timestamp) -> bool {
        self.heartbeat.is_due(now) || self.pending_due().is_some_and(|t| now >= t)
    }

    fn pending_due(&self) -> Option<Timestamp> {
        self.pending.then(|| match self.last_sent {
            Some(last) if !self.urgent => last + self.min_interval,
            _ => Timestamp::ZERO,
        })
    }

    /// The heartbeat slot a motion frame sent at `now` serves (its grid time, at or before
    /// `now`), if one is due.
    pub fn heartbeat_slot(&self, now: Timestamp) -> Option<Timestamp> {
        self.heartbeat.is_due(now).then(|| self.heartbeat.next())
    }

    /// A motion frame went out at `now`.
    pub fn sent(&mut self, now: Timestamp) {
        self.last_sent = Some(now);
        self.pending = false;
        self.urgent = false;
        self.heartbeat.serve_due(now);
    }

    /// When the next motion frame is due.
    pub fn deadline(&self) -> Timestamp {
        let heartbeat = self.heartbeat.next();
        self.pending_due().map_or(heartbeat, |t| t.min(heartbeat))
    }

    /// Restart the grid at `now` (after the bus came back).
    pub fn restart(&mut self, now: Timestamp) {
        self.heartbeat.restart(now);
        self.pending = false;
        self.urgent = false;
    }

    pub fn period(&self) -> Duration {
        self.heartbeat.period()
    }
}

/// The bookkeeping every driver shares: the state snapshot, the event queue, the heartbeat
/// schedule, the silence monitor and the bus-down switch.
///
/// A robot's driver embeds one and keeps only what is its own (codec, authority, brake, lights,
/// power); the link-health rules — what counts as a sign of life, when the chassis turns silent,
/// what the bus going down and coming back resets, how transmit and receive failures are counted —
/// live here once.
#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct DriverCore {
    #[serde(with = "crate::snapshot::raw")]
    pub(crate) state: ChassisState,
    pub(crate) events: VecDeque<DriverEvent>,
    /// The motion frame's heartbeat and the "changed command at once" rule.
    pub(crate) schedule: CommandSchedule,
    pub(crate) link: LinkMonitor,
    pub(crate) bus_down: bool,
    pub(crate) was_silent: bool,
    silence_timeout_ms: u64,
}

impl DriverCore {
    /// A core starting at `now` for a robot whose motion frame repeats every `heartbeat`; the
    /// first heartbeat is due at once and silence is counted from `now`.
    pub(crate) fn new(
        robot: u8,
        heartbeat: Duration,
        config: &DriverConfig,
        now: Timestamp,
    ) -> Self {
        Self {
            state: ChassisState {
                robot,
                ..ChassisState::default()
            },
            events: VecDeque::new(),
            schedule: CommandSchedule::new(
                heartbeat,
                Duration::from_millis(config.min_command_interval_ms),
                now,
            ),
            link: LinkMonitor::new(Duration::from_millis(config.silence_timeout_ms), now),
            bus_down: false,
            was_silent: false,
            silence_timeout_ms: config.silence_timeout_ms,
        }
    }

    pub(crate) fn notice(&mut self, level: Level, message: impl Into<String>) {
        self.events.push_back(DriverEvent::Notice {
            level,
            message: message.into(),
        });
    }

    pub(crate) fn dropped(&mut self, reason: String) {
        self.events.push_back(DriverEvent::RxDropped { reason });
    }

    /// Sets or clears one of `state.link_flags`.
    pub(crate) fn set_flag(&mut self, flag: u32, on: bool) {
        if on {
            self.state.link_flags |= flag;
        } else {
            self.state.link_flags &= !flag;
        }
    }

    /// Takes a status frame's control mode and normalized faults into `state.system` and the
    /// link flags. A battery under-voltage fault means the drive power is off; command mode counts
    /// as the driver's only while it is `ours` (not after the driver let go of control).
    pub(crate) fn system_status(&mut self, now: Timestamp, mode: u8, faults: u64, ours: bool) {
        let sys = &mut self.state.system;
        sys.control_mode = mode;
        sys.fault_flags = faults;
        sys.power_enabled = u8::from(faults & FaultFlags::BATTERY_UNDER_VOLTAGE == 0);
        self.state.touch(Group::System, now.as_nanos());
        self.set_flag(
            LinkFlags::COMMAND_MODE,
            ours && mode == ControlMode::COMMAND,
        );
        self.set_flag(LinkFlags::RC_AUTHORITY, mode == ControlMode::REMOTE);
    }

    /// Something arrived on the wrong kind of bus (serial bytes on CAN, a CAN frame on serial).
    pub(crate) fn wrong_medium(&mut self, reason: &str) {
        self.state.link.rx_decode_errors += 1;
        self.dropped(reason.into());
    }

    /// A valid feedback frame arrived at `now`: a sign of life. Returns true when the chassis
    /// had been silent until now (the "talking again" notice is already queued).
    pub(crate) fn feedback(&mut self, now: Timestamp) -> bool {
        self.link.received(now);
        self.state.link.rx_frames += 1;
        self.state.stamp_ns = now.as_nanos();
        if !self.was_silent {
            return false;
        }
        self.was_silent = false;
        self.set_flag(LinkFlags::CHASSIS_SILENT, false);
        self.notice(Level::Info, "chassis is talking again");
        true
    }

    /// Decodes a CAN robot's received item: a valid frame is a sign of life ([`Self::feedback`])
    /// and is returned; anything else is counted by kind (bad checksum, unknown or extended id,
    /// undecodable) and reported as [`DriverEvent::RxDropped`].
    pub(crate) fn can_rx<T>(
        &mut self,
        now: Timestamp,
        rx: Rx<'_>,
        decode: impl FnOnce(&CanFrame) -> Result<T, DecodeError>,
    ) -> Option<T> {
        let Rx::Can(frame) = rx else {
            self.wrong_medium("serial bytes on a CAN robot's bus");
            return None;
        };
        match decode(frame) {
            Ok(decoded) => {
                self.feedback(now);
                Some(decoded)
            }
            Err(err) => {
                match err {
                    DecodeError::BadChecksum { .. } => self.state.link.rx_bad_checksum += 1,
                    DecodeError::UnknownId { .. } | DecodeError::ExtendedId { .. } => {
                        self.state.link.rx_unknown_id += 1;
                    }
                    _ => self.state.link.rx_decode_errors += 1,
                }
                self.dropped(format!("{frame}: {err}"));
                None
            }
        }
    }

    /// Turns the link silent when no feedback arrived for the timeout: sets
    /// `LinkFlags::CHASSIS_SILENT` with a notice ("no `what` for N ms"). Returns true when it
    /// turned silent just now.
    pub(crate) fn check_silence(&mut self, now: Timestamp, what: &str) -> bool {
        if self.was_silent || !self.link.is_silent(now) {
            return false;
        }
        self.was_silent = true;
        self.set_flag(LinkFlags::CHASSIS_SILENT, true);
        self.notice(
            Level::Warn,
            format!(
                "chassis silent: no {what} for {} ms",
                self.silence_timeout_ms
            ),
        );
        true
    }

    /// The deadlines every driver has: the next motion frame and, while the chassis talks, the
    /// moment it would turn silent. `None` while the bus is down.
    pub(crate) fn poll_timeout(&self) -> Option<Timestamp> {
        if self.bus_down {
            return None;
        }
        let silence = (!self.was_silent).then(|| self.link.deadline());
        earliest(Some(self.schedule.deadline()), silence)
    }

    /// The bus went down or came back. Returns false when nothing changed. Going down raises
    /// `LinkFlags::BUS_DOWN` with an error notice; coming back counts a reconnect and restarts
    /// the silence count and the heartbeat grid at `now`. The robot's own resynchronisation
    /// follows in its driver.
    pub(crate) fn set_bus_down(&mut self, now: Timestamp, down: bool) -> bool {
        if down == self.bus_down {
            return false;
        }
        self.bus_down = down;
        self.set_flag(LinkFlags::BUS_DOWN, down);
        if down {
            self.notice(Level::Error, "bus down: nothing reaches the chassis");
        } else {
            self.state.link.bus_reconnects += 1;
            self.link.reset(now);
            self.schedule.restart(now);
        }
        true
    }

    /// Counts an encoded frame on its way out. An encoding failure is a bug guard (limits keep
    /// every planned value on the wire's range): it is counted in `link.tx_errors` with an error
    /// notice naming the frame, and nothing is sent.
    pub(crate) fn transmit<T, E: std::fmt::Display>(
        &mut self,
        frame: &impl serde::Serialize,
        encoded: Result<T, E>,
        wrap: impl FnOnce(T) -> WireItem,
    ) -> Option<WireItem> {
        match encoded {
            Ok(item) => {
                self.state.link.tx_frames += 1;
                Some(wrap(item))
            }
            Err(err) => {
                self.state.link.tx_errors += 1;
                let name = crate::frame_json::frame_name(frame);
                self.notice(Level::Error, format!("cannot encode {name}: {err}"));
                None
            }
        }
    }

    /// Admits a control action and plans its frames with `plan`, or says why not: nothing is
    /// taken while the bus is down, motion goes through [`Driver::set_command`], and a command
    /// `plan` refuses answers with its [`CommandError`](crate::command::CommandError).
    pub(crate) fn admit_control<P>(
        &self,
        command: &Command,
        plan: impl FnOnce(&Command) -> Result<P, crate::command::CommandError>,
    ) -> Result<P, ControlOutcome> {
        if self.bus_down {
            return Err(ControlOutcome::Refused(
                "the bus is down; nothing can be sent".into(),
            ));
        }
        if let Command::Velocity(_) = command {
            return Err(ControlOutcome::Invalid(
                "motion goes through the mux, not a control request".into(),
            ));
        }
        plan(command).map_err(ControlOutcome::from)
    }

    /// Queues the notices of a change of the normalized fault flags: the faults set (an error
    /// when any of them is outside `warnings`, else a warning) and the faults cleared.
    pub(crate) fn fault_notices(&mut self, old: u64, new: u64, warnings: u64) {
        let set = new & !old;
        let cleared = old & !new;
        if set != 0 {
            let level = if set & !warnings != 0 {
                Level::Error
            } else {
                Level::Warn
            };
            self.notice(
                level,
                format!("chassis faults set: {}", FaultFlags::names(set).join(", ")),
            );
        }
        if cleared != 0 {
            self.notice(
                Level::Info,
                format!(
                    "chassis faults cleared: {}",
                    FaultFlags::names(cleared).join(", ")
                ),
            );
        }
    }
}

/// The [`Driver`] methods that only hand out what the embedded [`DriverCore`] (a field named
/// `core`) holds: the next event and the state snapshot.
macro_rules! core_accessors {
    () => {
        fn poll_event(&mut self) -> Option<$crate::driver::DriverEvent> {
            self.core.events.pop_front()
        }

        fn state(&self) -> &chassis_interfaces::ChassisState {
            &self.core.state
        }
    };
}
pub(crate) use core_accessors;

/// The frames `plan` makes of an admitted control action ([`DriverCore::admit_control`]), or
/// else a return from the enclosing [`Driver::control`] with the outcome that refused it.
macro_rules! admit {
    ($core:expr, $command:expr, $plan:expr) => {
        match $core.admit_control($command, $plan) {
            Ok(planned) => planned,
            Err(outcome) => return outcome,
        }
    };
}
pub(crate) use admit;

/// The normalized flags (`chassis_interfaces::FaultFlags`) of a vendor fault word: the union of
/// the flags in `map` whose vendor bit is set in `word`.
pub(crate) fn flags_of<W>(word: W, map: &[(W, u64)]) -> u64
where
    W: Copy + Default + PartialEq + std::ops::BitAnd<Output = W>,
{
    map.iter()
        .filter(|(bit, _)| word & *bit != W::default())
        .fold(0, |acc, (_, flag)| acc | flag)
}

/// "Chassis silent": no feedback for longer than a timeout.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LinkMonitor {
    timeout: Duration,
    last_rx: Timestamp,
}

impl LinkMonitor {
    /// Counting starts at `now` (a chassis that never answers turns silent after `timeout`).
    pub fn new(timeout: Duration, now: Timestamp) -> Self {
        Self {
            timeout,
            last_rx: now,
        }
    }

    pub fn received(&mut self, now: Timestamp) {
        self.last_rx = self.last_rx.max(now);
    }

    pub fn is_silent(&self, now: Timestamp) -> bool {
        now.saturating_since(self.last_rx) > self.timeout
    }

    /// When the link turns silent if nothing arrives before (just after the timeout).
    pub fn deadline(&self) -> Timestamp {
        self.last_rx + self.timeout + Duration::from_nanos(1)
    }

    /// Restart counting at `now` (after the bus came back).
    pub fn reset(&mut self, now: Timestamp) {
        self.last_rx = now;
    }
}

/// Integrates the pose from body speeds (midpoint rule), in the frame the robot started in.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct PoseIntegrator {
    last: Option<(Timestamp, f64, f64, f64)>,
}

impl PoseIntegrator {
    /// Longest gap integrated in one step; a longer silence is not bridged by extrapolation.
    pub const MAX_STEP: Duration = Duration::from_millis(200);

    /// Adds the motion since the previous sample, then remembers (v, vy, ω) at `now`.
    pub fn update(
        &mut self,
        now: Timestamp,
        linear_mps: f64,
        lateral_mps: f64,
        angular_radps: f64,
        odometry: &mut OdometryState,
    ) {
        if let Some((last, v0, vy0, w0)) = self.last {
            let dt = now.saturating_since(last).min(Self::MAX_STEP).as_secs_f64();
            let v = 0.5 * (v0 + linear_mps);
            let vy = 0.5 * (vy0 + lateral_mps);
            let w = 0.5 * (w0 + angular_radps);
            let mid_yaw = odometry.yaw_rad + 0.5 * w * dt;
            let (sin, cos) = mid_yaw.sin_cos();
            odometry.x_m += (v * cos - vy * sin) * dt;
            odometry.y_m += (v * sin + vy * cos) * dt;
            odometry.yaw_rad = wrap_angle(odometry.yaw_rad + w * dt);
        }
        self.last = Some((now, linear_mps, lateral_mps, angular_radps));
    }

    /// Forget the previous sample (after a gap or a chassis reboot).
    pub fn reset(&mut self) {
        self.last = None;
    }
}

/// Wraps an angle to (-π, π], as the odometry keeps it.
pub use chassis_interfaces::wrap_angle;

/// Unwraps a wrapping 16-bit counter (encoders) into a running 64-bit count.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
pub struct Unwrap16 {
    last: Option<u16>,
    total: i64,
}

impl Unwrap16 {
    /// Takes the next raw reading; returns the running count (the first reading is the origin
    /// offset, so counting starts at the raw value).
    pub fn update(&mut self, raw: u16) -> i64 {
        match self.last {
            None => self.total = i64::from(raw),
            Some(prev) => self.total += i64::from(raw.wrapping_sub(prev) as i16),
        }
        self.last = Some(raw);
        self.total
    }

    /// The running count.
    pub fn total(&self) -> i64 {
        self.total
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(v: u64) -> Timestamp {
        Timestamp::from_millis(v)
    }

    #[test]
    fn heartbeat_keeps_its_grid_through_command_changes() {
        let mut s =
            CommandSchedule::new(Duration::from_millis(20), Duration::from_millis(2), ms(0));
        assert!(s.is_due(ms(0)));
        s.sent(ms(0));
        assert_eq!(s.deadline(), ms(20));
        s.command_changed(false);
        assert!(s.is_due(ms(5)));
        s.sent(ms(5));
        assert_eq!(
            s.deadline(),
            ms(20),
            "a command change does not move the heartbeat"
        );
        s.command_changed(false);
        assert!(!s.is_due(ms(6)), "min interval");
        assert_eq!(s.deadline(), ms(7));
        s.sent(ms(7));
        assert!(s.is_due(ms(20)));
        s.sent(ms(21)); // a late wake-up
        assert_eq!(s.deadline(), ms(40), "the grid does not shift");
    }

    #[test]
    fn a_stop_is_never_delayed() {
        let mut s =
            CommandSchedule::new(Duration::from_millis(20), Duration::from_millis(5), ms(0));
        s.sent(ms(0));
        s.command_changed(false);
        s.sent(ms(1));
        s.command_changed(true);
        assert!(s.is_due(ms(1)));
    }

    #[test]
    fn a_long_stall_rejoins_the_grid() {
        let mut s =
            CommandSchedule::new(Duration::from_millis(20), Duration::from_millis(2), ms(0));
        s.sent(ms(0));
        s.sent(ms(95));
        assert_eq!(s.deadline(), ms(100));
    }

    #[test]
    fn link_turns_silent_only_after_the_timeout() {
        let mut l = LinkMonitor::new(Duration::from_millis(100), ms(0));
        assert!(!l.is_silent(ms(100)));
        assert!(l.is_silent(ms(101)));
        l.received(ms(150));
        assert!(!l.is_silent(ms(200)));
        assert!(l.deadline() > ms(250));
    }

    #[test]
    fn pose_integrates_a_half_circle() {
        let mut p = PoseIntegrator::default();
        let mut odo = OdometryState::default();
        // 1 m/s at 0.5 rad/s for 2π seconds: a half circle of radius 2.
        let steps = 10_000;
        let dt = std::f64::consts::TAU / f64::from(steps);
        for i in 0..=steps {
            let t = Timestamp::from_nanos((f64::from(i) * dt * 1e9) as u64);
            p.update(t, 1.0, 0.0, 0.5, &mut odo);
        }
        assert!(odo.x_m.abs() < 1e-3, "{odo:?}");
        assert!((odo.y_m - 4.0).abs() < 1e-3, "{odo:?}");
        assert!((odo.yaw_rad.abs() - std::f64::consts::PI).abs() < 1e-3);
    }

    #[test]
    fn sixteen_bit_counters_unwrap_both_ways() {
        let mut u = Unwrap16::default();
        assert_eq!(u.update(65_530), 65_530);
        assert_eq!(u.update(4), 65_540);
        assert_eq!(
            u.update(65_000),
            65_000,
            "540 counts backwards across the wrap"
        );
        assert_eq!(u.total(), 65_000);
    }
}
