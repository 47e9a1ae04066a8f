//! The simulated firmware contract: the chassis side of the wire, built on the same codecs.
//!
//! A firmware is sans-IO like a driver: commands go in with their time, feedback frames come out
//! at the manual's periods, and it enforces the manual's rules (standby after power-up, the
//! 500 ms command timeout, the parking brake, RC authority, checksums). Faults are injected by
//! value. `chassisd` runs one in-process as its default bus, and `chassisd sim` runs one as its
//! own process on a real bus.
//!
//! Below the contract are the pieces every simulated chassis shares: the sub-stepped physics
//! clock, the first-order speed lag, the true pose, the battery and motor models, the bounded
//! transmit queue with its silence window, the feedback flood of load tests, and `SimBody` — the
//! state, the counters and the fault injection every simulated firmware embeds.

mod body;

use std::collections::VecDeque;
use std::time::Duration;

use chassis_interfaces::ControlMode;
use serde::Serialize;

use crate::driver::{Rx, WireItem, wrap_angle};
use crate::kind::RobotKind;
use crate::time::{Grid, Timestamp};

pub(crate) use body::{Applied, SimBody, SimBodySpec};

/// A fault or event to inject into a simulated chassis.
#[derive(Debug, Clone, PartialEq)]
pub enum Injection {
    /// Motor driver `motor` (1-4) stops answering (`lost`) or comes back.
    MotorDriverLoss { motor: u8, lost: bool },
    /// Set the battery's state of charge, % (TITAN cuts drive below 10 %).
    Battery { soc_pct: f64 },
    /// The bumper is pressed (`true`) or released.
    Bumper(bool),
    /// An RC transmitter takes over (`true`) or is switched off again.
    RcTakeover(bool),
    /// Power-cycle the chassis: it comes back as after power-up.
    Reboot,
    /// Stop transmitting for this long (commands are still obeyed).
    Silence(Duration),
    /// Put these raw bytes on the wire now (serial robots; CAN robots send them as frames with an
    /// unused id, 8 bytes each).
    Garbage(Vec<u8>),
    /// Corrupt the checksum of the next `n` frames sent (SCOUT MINI, XBot).
    BadChecksums(u32),
    /// An obstacle at this range in front (XBot ultrasonic front-centre), m; `None` clears it.
    ObstacleAhead(Option<f64>),
    /// An obstacle at this range behind (XBot IR rear-centre), m; `None` clears it.
    ObstacleBehind(Option<f64>),
    /// Send feedback as fast as the bus allows: `frames_per_s` extra frames (load tests).
    Flood { frames_per_s: u32 },
    /// The chassis' own E-stop is pressed (`true`) or released (AgileX protocol V2).
    EStop(bool),
    /// The speed loop runs away (downhill, a failing speed controller, bad feedback): the
    /// chassis drives at this forward speed, m/s (negative: reverse), whatever it is commanded
    /// and past its own limits; `None` gives the control back. Every simulated chassis has it.
    Runaway(Option<f64>),
    /// The wheels turn at this multiple of the command (at most [`MAX_GAIN`] either way): 0
    /// ignores it (a chassis that answers and does not drive), between 0 and 1 it slips, a
    /// negative gain drives against it; `None` obeys again. Every simulated chassis has it.
    Gain(Option<f64>),
}

impl Injection {
    pub fn name(&self) -> &'static str {
        match self {
            Injection::MotorDriverLoss { .. } => "motor-driver-loss",
            Injection::Battery { .. } => "battery",
            Injection::Bumper(_) => "bumper",
            Injection::RcTakeover(_) => "rc-takeover",
            Injection::Reboot => "reboot",
            Injection::Silence(_) => "silence",
            Injection::Garbage(_) => "garbage",
            Injection::BadChecksums(_) => "bad-checksums",
            Injection::ObstacleAhead(_) => "obstacle-ahead",
            Injection::ObstacleBehind(_) => "obstacle-behind",
            Injection::Flood { .. } => "flood",
            Injection::EStop(_) => "estop-switch",
            Injection::Runaway(_) => "runaway",
            Injection::Gain(_) => "gain",
        }
    }
}

/// What a simulated chassis really does, for tests to compare with what the driver reports.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct SimTruth {
    /// Body speeds the simulated chassis actually has.
    pub linear_mps: f64,
    pub lateral_mps: f64,
    pub angular_radps: f64,
    pub steer_rad: f64,
    /// Integrated true pose.
    pub x_m: f64,
    pub y_m: f64,
    pub yaw_rad: f64,
    /// `chassis_interfaces::ControlMode`.
    pub control_mode: u8,
    pub brake_engaged: bool,
    pub soc_pct: f64,
    /// Normalized `chassis_interfaces::FaultFlags` the chassis reports.
    pub fault_flags: u64,
    /// Command frames accepted.
    pub commands_received: u64,
    /// Valid command frames not obeyed (the mode, the authority, a boot).
    pub commands_ignored: u64,
    /// Valid frames only a chassis sends, put on the bus by another node: not for it.
    pub frames_ignored: u64,
    /// Frames dropped for a bad checksum.
    pub bad_checksums_received: u64,
    /// Frames that could not be decoded.
    pub decode_errors: u64,
    /// Times the chassis rebooted.
    pub boots: u32,
    /// The injected faults that left the chassis, counted as they were handed to the bus.
    pub injected: InjectedCounts,
}

/// What a simulated chassis has sent of its injected faults since power-up, counted when each
/// item leaves it ([`Firmware::poll_transmit`]): an injection still queued, or cleared by a
/// silence or a reboot before it went out, is not counted. The sender's truth a storm is
/// measured against.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct InjectedCounts {
    /// [`Injection::Garbage`] items sent: CAN frames (8 bytes each, the last shorter), or
    /// writes on a serial line.
    pub garbage_frames: u64,
    /// [`Injection::Garbage`] bytes sent.
    pub garbage_bytes: u64,
    /// Frames (serial reports) sent with a corrupted checksum ([`Injection::BadChecksums`]).
    pub bad_checksum_frames: u64,
    /// Extra frames (serial reports) sent by [`Injection::Flood`].
    pub flood_frames: u64,
}

impl InjectedCounts {
    /// One item of `bytes` garbage bytes.
    pub(crate) fn garbage(bytes: usize) -> Self {
        Self {
            garbage_frames: 1,
            garbage_bytes: bytes as u64,
            ..Self::default()
        }
    }

    /// One frame (report) with a corrupted checksum.
    pub(crate) const BAD_CHECKSUM: Self = Self {
        garbage_frames: 0,
        garbage_bytes: 0,
        bad_checksum_frames: 1,
        flood_frames: 0,
    };

    /// One extra frame (report) of a flood.
    pub(crate) const FLOOD: Self = Self {
        garbage_frames: 0,
        garbage_bytes: 0,
        bad_checksum_frames: 0,
        flood_frames: 1,
    };

    /// True when the item carries no injected fault.
    pub(crate) fn is_empty(&self) -> bool {
        *self == Self::default()
    }
}

impl std::ops::Add for InjectedCounts {
    type Output = Self;

    fn add(self, other: Self) -> Self {
        Self {
            garbage_frames: self.garbage_frames.saturating_add(other.garbage_frames),
            garbage_bytes: self.garbage_bytes.saturating_add(other.garbage_bytes),
            bad_checksum_frames: self
                .bad_checksum_frames
                .saturating_add(other.bad_checksum_frames),
            flood_frames: self.flood_frames.saturating_add(other.flood_frames),
        }
    }
}

/// A simulated firmware of any robot, as the registry makes them; it may run on a thread of its
/// own.
pub type BoxedFirmware = Box<dyn Firmware + Send>;

/// The contract every simulated firmware fulfils.
pub trait Firmware {
    fn robot(&self) -> RobotKind;

    /// Feeds what the computer sent at `now`.
    fn handle_rx(&mut self, now: Timestamp, rx: Rx<'_>);

    /// Advances the physics and processes deadlines (feedback periods, command timeout).
    fn handle_timeout(&mut self, now: Timestamp);

    /// The next frame (or serial chunk) the chassis sends.
    fn poll_transmit(&mut self, now: Timestamp) -> Option<WireItem>;

    /// When [`Firmware::handle_timeout`] must be called next.
    fn poll_timeout(&self) -> Option<Timestamp>;

    /// Injects a fault or event. Returns `false` when this robot has no such thing.
    fn inject(&mut self, now: Timestamp, injection: Injection) -> bool;

    /// What the chassis really does.
    fn truth(&self) -> SimTruth;
}

/// A boxed firmware is a firmware.
impl<F: Firmware + ?Sized> Firmware for Box<F> {
    fn robot(&self) -> RobotKind {
        (**self).robot()
    }
    fn handle_rx(&mut self, now: Timestamp, rx: Rx<'_>) {
        (**self).handle_rx(now, rx);
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
    fn inject(&mut self, now: Timestamp, injection: Injection) -> bool {
        (**self).inject(now, injection)
    }
    fn truth(&self) -> SimTruth {
        (**self).truth()
    }
}

/// Longest time a simulated chassis integrates at once; a longer gap between calls is not
/// bridged.
pub(crate) const MAX_STEP: Duration = Duration::from_millis(100);
/// Integration sub-step of the simulated physics.
const SUBSTEP: Duration = Duration::from_millis(5);
/// Frames (or serial chunks) a simulated chassis keeps for transmission when nobody polls.
const TX_QUEUE_LIMIT: usize = 4096;

/// The integration steps, s, from `*last_update` to `now` (at most [`MAX_STEP`] in all, in
/// sub-steps of 5 ms); `*last_update` moves to `now`. Nothing when `now` is not later.
pub(crate) fn substeps(last_update: &mut Timestamp, now: Timestamp) -> Substeps {
    let mut remaining = Duration::ZERO;
    if now > *last_update {
        remaining = now.saturating_since(*last_update).min(MAX_STEP);
        *last_update = now;
    }
    Substeps { remaining }
}

/// The integration steps of [`substeps`], s.
#[derive(Debug)]
pub(crate) struct Substeps {
    remaining: Duration,
}

impl Iterator for Substeps {
    type Item = f64;

    fn next(&mut self) -> Option<f64> {
        if self.remaining.is_zero() {
            return None;
        }
        let dt = self.remaining.min(SUBSTEP);
        self.remaining = self.remaining.saturating_sub(dt);
        Some(dt.as_secs_f64())
    }
}

/// One step of a first-order lag from `from` toward `to` with time constant `tau_s` (0:
/// instantaneous); within 1e-9 of the target it snaps onto it.
pub(crate) fn first_order_lag(from: f64, to: f64, tau_s: f64, dt: f64) -> f64 {
    let next = if tau_s > 0.0 {
        to + (from - to) * (-dt / tau_s).exp()
    } else {
        to
    };
    if (next - to).abs() < 1e-9 { to } else { next }
}

/// The true pose of a simulated chassis, in the frame it started in.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Pose {
    pub(crate) x_m: f64,
    pub(crate) y_m: f64,
    pub(crate) yaw_rad: f64,
}

impl Pose {
    /// Moves by the body speeds (forward, lateral, yaw rate) held for `dt` seconds, at the
    /// heading of the step's midpoint.
    pub(crate) fn advance(
        &mut self,
        linear_mps: f64,
        lateral_mps: f64,
        angular_radps: f64,
        dt: f64,
    ) {
        let heading = self.yaw_rad + 0.5 * angular_radps * dt;
        let (sin, cos) = heading.sin_cos();
        self.x_m += (linear_mps * cos - lateral_mps * sin) * dt;
        self.y_m += (linear_mps * sin + lateral_mps * cos) * dt;
        self.yaw_rad = wrap_angle(self.yaw_rad + angular_radps * dt);
    }
}

/// A simulated battery: open-circuit voltage linear in the state of charge, one internal
/// resistance, charge drawn by the pack current.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BatteryModel {
    /// Capacity of one battery, Ah.
    pub capacity_ah: f64,
    /// Open-circuit voltage at 100 % SOC, V.
    pub full_v: f64,
    /// Open-circuit voltage at 0 % SOC, V.
    pub empty_v: f64,
    /// Internal resistance of the pack, Ω.
    pub resistance_ohm: f64,
}

impl BatteryModel {
    /// Terminal voltage at `soc_pct` under `current_a` (positive = discharging), V.
    pub fn voltage_v(&self, soc_pct: f64, current_a: f64) -> f64 {
        let ocv = self.empty_v + (self.full_v - self.empty_v) * soc_pct / 100.0;
        (ocv - self.resistance_ohm * current_a).max(0.0)
    }

    /// The state of charge after drawing `current_a` for `dt` seconds from `packs` batteries.
    pub fn drain(&self, soc_pct: f64, current_a: f64, dt: f64, packs: f64) -> f64 {
        let used_pct = current_a * dt / 3600.0 / (self.capacity_ah * packs) * 100.0;
        (soc_pct - used_pct).max(0.0)
    }
}

/// A simulated drive motor's current: so many amperes per m/s of its wheel's speed and per m/s²
/// of its acceleration, up to its driver's limit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotorModel {
    /// Current per m/s of wheel speed, A.
    pub a_per_mps: f64,
    /// Current per m/s² of acceleration, A.
    pub a_per_mps2: f64,
    /// The motor driver's current limit, A.
    pub limit_a: f64,
}

impl MotorModel {
    /// The current signed like the torque, within ±the limit, A.
    pub fn signed_a(&self, speed_mps: f64, accel_mps2: f64) -> f64 {
        (self.a_per_mps * speed_mps + self.a_per_mps2 * accel_mps2)
            .clamp(-self.limit_a, self.limit_a)
    }

    /// The current's magnitude plus `load_a` that does not depend on the motion (holding, an
    /// extra load), up to the limit, A.
    pub fn magnitude_a(&self, speed_mps: f64, accel_mps2: f64, load_a: f64) -> f64 {
        ((self.a_per_mps * speed_mps + self.a_per_mps2 * accel_mps2).abs() + load_a)
            .min(self.limit_a)
    }
}

/// What a simulated chassis has for transmission: a bounded queue (the oldest item goes first
/// when nobody polls), the window of an injected silence, and the injected faults that left.
#[derive(Debug, Clone)]
pub(crate) struct Outbox<T> {
    /// Each item with the injected faults it carries.
    queue: VecDeque<(T, InjectedCounts)>,
    silent_until: Option<Timestamp>,
    sent: InjectedCounts,
}

impl<T> Outbox<T> {
    pub(crate) fn new() -> Self {
        Self {
            queue: VecDeque::new(),
            silent_until: None,
            sent: InjectedCounts::default(),
        }
    }

    /// Queues an item that carries no injected fault.
    pub(crate) fn push(&mut self, item: T) {
        self.push_injected(item, InjectedCounts::default());
    }

    /// Queues an item carrying `injected` faults; they count once the item leaves
    /// ([`Outbox::pop`]).
    pub(crate) fn push_injected(&mut self, item: T, injected: InjectedCounts) {
        if self.queue.len() >= TX_QUEUE_LIMIT {
            self.queue.pop_front();
        }
        self.queue.push_back((item, injected));
    }

    /// Queues an encoded item carrying `injected` faults; one that did not encode (a value its
    /// wire field cannot carry) is not sent.
    pub(crate) fn push_encoded<E>(&mut self, encoded: Result<T, E>, injected: InjectedCounts) {
        if let Ok(item) = encoded {
            self.push_injected(item, injected);
        }
    }

    /// The next item to send; the faults it carries count as injected from now.
    pub(crate) fn pop(&mut self) -> Option<T> {
        let (item, injected) = self.queue.pop_front()?;
        if !injected.is_empty() {
            self.sent = self.sent + injected;
        }
        Some(item)
    }

    /// The injected faults that have left so far.
    pub(crate) fn injected(&self) -> InjectedCounts {
        self.sent
    }

    pub(crate) fn clear(&mut self) {
        self.queue.clear();
    }

    /// [`Injection::Silence`]: nothing is sent for `duration` from `now` (overlapping silences
    /// extend each other); a non-zero silence also drops what is queued.
    pub(crate) fn silence(&mut self, now: Timestamp, duration: Duration) {
        let until = now + duration;
        self.silent_until = Some(self.silent_until.map_or(until, |t| t.max(until)));
        if !duration.is_zero() {
            self.queue.clear();
        }
    }

    /// When the injected silence ends, if one is pending.
    pub(crate) fn silent_until(&self) -> Option<Timestamp> {
        self.silent_until
    }

    /// Forgets a silence that has ended by `now`.
    pub(crate) fn expire(&mut self, now: Timestamp) {
        if self.silent_until.is_some_and(|t| now >= t) {
            self.silent_until = None;
        }
    }
}

/// [`Injection::Flood`]: extra feedback frames on their own grid, alternating between two kinds.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Flood {
    grid: Grid,
    /// The next frame is the second kind.
    toggle: bool,
}

impl Flood {
    /// `frames_per_s` extra frames a second (at most `max`), the first one interval after `now`;
    /// `None` for 0 (no flood).
    pub(crate) fn new(now: Timestamp, frames_per_s: u32, max: u32) -> Option<Self> {
        (frames_per_s > 0).then(|| {
            let interval = Duration::from_secs(1) / frames_per_s.min(max).max(1);
            Self {
                grid: Grid::new(interval, now + interval),
                toggle: false,
            }
        })
    }

    /// When the next flood frame is due.
    pub(crate) fn next(&self) -> Timestamp {
        self.grid.next()
    }

    /// When a flood frame is due at `now`: serves it and says whether it is the second kind.
    pub(crate) fn due(&mut self, now: Timestamp) -> Option<bool> {
        if !self.grid.serve_due(now) {
            return None;
        }
        let second = self.toggle;
        self.toggle = !self.toggle;
        Some(second)
    }
}

/// Who holds authority over a simulated AgileX chassis (TITAN, protocol V2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Mode {
    Standby,
    Command,
    Remote,
}

impl Mode {
    /// The normalized `chassis_interfaces::ControlMode` of the mode.
    pub(crate) fn control_mode(self) -> u8 {
        match self {
            Mode::Standby => ControlMode::STANDBY,
            Mode::Command => ControlMode::COMMAND,
            Mode::Remote => ControlMode::REMOTE,
        }
    }
}

/// An injected or configured state of charge, % (clamped to 0-100); `None` when not a number.
pub(crate) fn state_of_charge(soc_pct: f64) -> Option<f64> {
    soc_pct.is_finite().then(|| soc_pct.clamp(0.0, 100.0))
}

/// Fastest runaway a simulated chassis takes, m/s (the service rejects requests beyond 50 m/s as
/// absurd; a runaway is no request, but nothing real drives faster either).
pub const MAX_RUNAWAY_MPS: f64 = 50.0;

/// An injected runaway speed, m/s: `Some(None)` gives the control back, `None` when the speed is
/// not a number or beyond [`MAX_RUNAWAY_MPS`].
pub(crate) fn runaway_speed(speed: Option<f64>) -> Option<Option<f64>> {
    match speed {
        None => Some(None),
        Some(v) if v.is_finite() && v.abs() <= MAX_RUNAWAY_MPS => Some(Some(v)),
        Some(_) => None,
    }
}

/// Largest |gain| an injected [`Injection::Gain`] may have (faster is a runaway).
pub const MAX_GAIN: f64 = 2.0;

/// An injected gain: `Some(None)` obeys again, `None` when it is not a number or beyond
/// [`MAX_GAIN`].
pub(crate) fn gain(gain: Option<f64>) -> Option<Option<f64>> {
    match gain {
        None => Some(None),
        Some(g) if g.is_finite() && g.abs() <= MAX_GAIN => Some(Some(g)),
        Some(_) => None,
    }
}

/// The index of motor driver `motor` (numbered from 1) among `count`, if there is one.
pub(crate) fn motor_index(motor: u8, count: usize) -> Option<usize> {
    usize::from(motor).checked_sub(1).filter(|i| *i < count)
}

/// A setting that must be a finite non-negative number (anything else is 0).
pub(crate) fn non_negative(value: f64) -> f64 {
    if value.is_finite() && value > 0.0 {
        value
    } else {
        0.0
    }
}

/// The instant a command received at `last` has timed out: just past `timeout_ms` after it (a
/// command that arrives exactly at the timeout is still in time).
pub(crate) fn past_timeout(last: Timestamp, timeout_ms: u64) -> Timestamp {
    last + Duration::from_millis(timeout_ms) + Duration::from_nanos(1)
}

/// A distance as a signed 32-bit millimetre counter reports it (wrapping), back in m.
pub(crate) fn wrap_mm(distance_m: f64) -> f64 {
    let mm = (distance_m * 1000.0).round() as i64;
    // Truncation to 32 bits is the counter's wrap.
    f64::from(mm as i32) / 1000.0
}

/// Keeps an SI value inside a signed 16-bit wire field of `scale` units per SI unit.
pub(crate) fn clamp_i16(value: f64, scale: f64) -> f64 {
    let limit = f64::from(i16::MAX) / scale;
    if value.is_finite() {
        value.clamp(-limit, limit)
    } else {
        0.0
    }
}
