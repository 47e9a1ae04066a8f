//! What the TITAN driver and the protocol-V2 driver share: both speak AgileX's 0x421 / 0x131 /
//! 0x211 / 0x431 rules, so the bookkeeping around them lives here once.
//!
//! * [`ModeKeeper`]: CAN command mode asked for at start and again while the chassis reports it
//!   is not ours (a reboot, a heartbeat timeout, an RC hand-back), at most every retry period;
//!   [`mode_changed`] logs each change of the reported mode.
//! * [`BrakeKeeper`]: what the driver believes about a brake the chassis does not (or not
//!   always) report — released once before motion in CAN command mode, engaged after an idle
//!   time and on shutdown, forgotten after a reboot or an RC session.
//! * [`SteeringZero`]: one steering-zero request (0x431 → 0x43A) waiting for its
//!   acknowledgement, answered with a timeout when none comes.
//! * [`next_frame`]: the order both send in — queued frames, then at the heartbeat deadline the
//!   brake release the motion needs, then the motion frame.
//! * The feedback frames both read with the same layout (0x241 RC, 0x25x / 0x26x motors,
//!   0x361 / 0x362 battery) go into the state by the `apply_*` functions.

use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
use std::time::Duration;

use chassis_interfaces::{ChassisState, ControlMode, ControlStatus, Group, LinkFlags, RcState};

use crate::driver::{ControlOutcome, DriverCore, DriverEvent, Level};
use crate::time::Timestamp;
use crate::titan::{BmsAlarm, BmsData, MotorFast, MotorSlow};

/// What an AgileX driver sends next ([`next_frame`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Next<F> {
    /// A queued frame: a mode request, a brake, a light or a clear-fault command.
    Queued(F),
    /// At the heartbeat deadline, the parking brake's release before the motion it would hold
    /// back (after power-up, a chassis reboot or an idle engagement), already reported released;
    /// the same deadline sends the motion next.
    ReleaseBrake,
    /// The heartbeat's motion frame (0x111), counted as sent.
    Motion,
}

/// The order every AgileX driver sends in: what is queued first, then at the heartbeat deadline
/// the brake release the motion needs (only in CAN command mode, the one mode that obeys 0x131),
/// then the motion frame. Nothing while the bus is down: what was queued is dropped.
pub(crate) fn next_frame<F>(
    core: &mut DriverCore,
    queue: &mut VecDeque<F>,
    brake: &mut BrakeKeeper,
    moving: bool,
    now: Timestamp,
) -> Option<Next<F>> {
    if core.bus_down {
        queue.clear();
        return None;
    }
    if let Some(frame) = queue.pop_front() {
        return Some(Next::Queued(frame));
    }
    if !core.schedule.is_due(now) {
        return None;
    }
    let command_mode = core.state.system.control_mode == ControlMode::COMMAND;
    if brake.release_before(moving, command_mode) {
        brake.report(core, now);
        return Some(Next::ReleaseBrake);
    }
    core.schedule.sent(now);
    Some(Next::Motion)
}

/// Whether the driver wants CAN command mode, and when it last asked (0x421).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct ModeKeeper {
    want_control: bool,
    last_request: Option<Timestamp>,
    retry: Duration,
}

impl ModeKeeper {
    /// `want_control` from the driver's configuration; 0x421 at most every `retry` while the
    /// chassis keeps reporting it is not ours.
    pub(crate) fn new(want_control: bool, retry: Duration) -> Self {
        Self {
            want_control,
            last_request: None,
            retry,
        }
    }

    pub(crate) fn wants_control(&self) -> bool {
        self.want_control
    }

    /// A 0x421 went out at `now`.
    pub(crate) fn requested(&mut self, now: Timestamp) {
        self.last_request = Some(now);
    }

    /// The chassis is ours again: its next "not ours" is answered at once.
    pub(crate) fn obeyed(&mut self) {
        self.last_request = None;
    }

    /// True when a chassis reporting it is `not_ours` must be asked again now.
    pub(crate) fn ask_again(&self, now: Timestamp, not_ours: bool, bus_down: bool) -> bool {
        not_ours
            && self.want_control
            && !bus_down
            && self
                .last_request
                .is_none_or(|t| now.saturating_since(t) >= self.retry)
    }

    /// `Command::Mode`: take control (CAN command mode) or let go (standby).
    pub(crate) fn command(&mut self, take_control: bool) -> ControlOutcome {
        self.want_control = take_control;
        ControlOutcome::Done(if take_control {
            "CAN command mode requested".into()
        } else {
            "standby requested; motion commands will be ignored".into()
        })
    }
}

/// Logs a change of the reported control mode: losing command mode is worth a warning, finding
/// out the mode at power-up is not.
pub(crate) fn mode_changed(core: &mut DriverCore, old_mode: u8, new_mode: u8) {
    if new_mode == old_mode {
        return;
    }
    let level = if new_mode == ControlMode::COMMAND || old_mode == ControlMode::UNKNOWN {
        Level::Info
    } else {
        Level::Warn
    };
    core.notice(
        level,
        format!(
            "chassis mode {} -> {}",
            ControlMode::name(old_mode),
            ControlMode::name(new_mode)
        ),
    );
}

/// What the driver believes about the parking brake.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
enum BrakeBelief {
    /// Not known (power-up, a reboot, an RC session, the bus back): treated as engaged.
    Unknown,
    Engaged,
    Released,
}

/// A parking brake (0x131) as the driver keeps it. A chassis without one has a brake that is
/// always released and never asks for a frame.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct BrakeKeeper {
    fitted: bool,
    belief: BrakeBelief,
    /// Engaged on request: motion waits until it is released on request.
    held: bool,
    /// Since when the planned motion is zero.
    idle_since: Option<Timestamp>,
    /// Engage after this long idle; zero: never.
    idle_engage: Duration,
}

impl BrakeKeeper {
    /// A brake (`fitted`) believed engaged at `now`, engaged again after `idle_engage_ms` idle
    /// (0: never).
    pub(crate) fn new(fitted: bool, idle_engage_ms: u64, now: Timestamp) -> Self {
        Self {
            fitted,
            belief: if fitted {
                BrakeBelief::Unknown
            } else {
                BrakeBelief::Released
            },
            held: false,
            idle_since: Some(now),
            idle_engage: Duration::from_millis(idle_engage_ms),
        }
    }

    pub(crate) fn fitted(&self) -> bool {
        self.fitted
    }

    /// What the state reports: engaged unless known released (never, without a brake).
    pub(crate) fn engaged(&self) -> bool {
        self.fitted && self.belief != BrakeBelief::Released
    }

    /// Shows the belief in the state at `now`: most chassis never report their brake, so the
    /// belief is all the state can hold.
    pub(crate) fn report(&self, core: &mut DriverCore, now: Timestamp) {
        core.state.system.parking_brake_engaged = u8::from(self.engaged());
        core.state.touch(Group::Body, now.as_nanos());
    }

    /// Engaged on request and not released since: motion must wait.
    pub(crate) fn held(&self) -> bool {
        self.held
    }

    /// The motion planned at `now` is `moving` (or zero): the idle time counts from its end.
    pub(crate) fn planned(&mut self, now: Timestamp, moving: bool) {
        if moving {
            self.idle_since = None;
        } else if self.idle_since.is_none() {
            self.idle_since = Some(now);
        }
    }

    /// After a reboot, an RC session or the bus coming back the brake may be engaged again.
    pub(crate) fn forget(&mut self) {
        if self.fitted {
            self.belief = BrakeBelief::Unknown;
        }
    }

    /// Engaged or released on request; with `hold`, an engagement keeps motion off until a
    /// release on request.
    pub(crate) fn set(&mut self, engage: bool, hold: bool) {
        self.belief = if engage {
            BrakeBelief::Engaged
        } else {
            BrakeBelief::Released
        };
        self.held = engage && hold;
    }

    /// Engages a fitted brake (shutdown): true when a 0x131 must go out.
    pub(crate) fn engage(&mut self) -> bool {
        if self.fitted {
            self.belief = BrakeBelief::Engaged;
        }
        self.fitted
    }

    /// When [`BrakeKeeper::idle_engage_due`] turns true, if ever.
    pub(crate) fn deadline(&self) -> Option<Timestamp> {
        if !self.fitted
            || self.idle_engage.is_zero()
            || self.belief != BrakeBelief::Released
            || self.held
        {
            return None;
        }
        self.idle_since.map(|since| since + self.idle_engage)
    }

    /// True (and believed engaged from now) when a released brake has been idle long enough to
    /// be engaged at `now`: the caller sends the engagement.
    pub(crate) fn idle_engage_due(&mut self, now: Timestamp, bus_down: bool) -> bool {
        if bus_down || self.deadline().is_none_or(|due| now < due) {
            return false;
        }
        self.belief = BrakeBelief::Engaged;
        true
    }

    /// True (and believed released from now) when motion must be preceded by a release: a
    /// fitted brake not known released, in CAN command mode — standby and RC authority ignore
    /// 0x131, and a release sent then would be believed while the brake stays engaged.
    pub(crate) fn release_before(&mut self, moving: bool, command_mode: bool) -> bool {
        if !(moving && command_mode && self.fitted && self.belief != BrakeBelief::Released) {
            return false;
        }
        self.belief = BrakeBelief::Released;
        true
    }
}

/// A steering-zero request waiting for its acknowledgement, and the tokens that name them.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct SteeringZero {
    pending: Option<(u64, Timestamp)>,
    next_token: u64,
    timeout: Duration,
}

impl SteeringZero {
    pub(crate) fn new(timeout_ms: u64) -> Self {
        Self {
            pending: None,
            next_token: 1,
            timeout: Duration::from_millis(timeout_ms),
        }
    }

    /// Starts a request at `now`: its token, or a refusal while one is still waiting.
    pub(crate) fn start(
        &mut self,
        core: &mut DriverCore,
        now: Timestamp,
    ) -> Result<u64, ControlOutcome> {
        if self.pending.is_some() {
            return Err(ControlOutcome::Refused(
                "a steering zero is already waiting for its acknowledgement".into(),
            ));
        }
        let token = self.next_token;
        self.next_token += 1;
        self.pending = Some((token, now + self.timeout));
        core.set_flag(LinkFlags::STEERING_ZERO_PENDING, true);
        Ok(token)
    }

    /// The chassis answered (`done`: zero set; else refused, 0x43A 0xFF): the waiting request
    /// (if any) is answered likewise.
    pub(crate) fn answered(&mut self, core: &mut DriverCore, done: bool) {
        core.state.system.steering_zero_done = u8::from(done);
        core.set_flag(LinkFlags::STEERING_ZERO_PENDING, false);
        if let Some((token, _)) = self.pending.take() {
            let (status, message) = if done {
                (ControlStatus::OK, "steering zero set")
            } else {
                (
                    ControlStatus::REFUSED,
                    "the chassis refused the steering zero (0x43A 0xFF)",
                )
            };
            core.events.push_back(DriverEvent::ControlDone {
                token,
                status,
                message: message.into(),
            });
        }
    }

    /// Answers a request still waiting at its deadline with a timeout.
    pub(crate) fn expire(&mut self, core: &mut DriverCore, now: Timestamp) {
        let Some((token, _)) = self.pending.filter(|(_, deadline)| now >= *deadline) else {
            return;
        };
        self.pending = None;
        core.set_flag(LinkFlags::STEERING_ZERO_PENDING, false);
        core.events.push_back(DriverEvent::ControlDone {
            token,
            status: ControlStatus::TIMEOUT,
            message: format!(
                "no steering zero acknowledgement (0x43A) within {} ms",
                self.timeout.as_millis()
            ),
        });
    }

    pub(crate) fn deadline(&self) -> Option<Timestamp> {
        self.pending.map(|(_, deadline)| deadline)
    }
}

/// 0x251-0x258: motor `m.motor`'s speed, current and encoder position.
pub(crate) fn apply_motor_fast(state: &mut ChassisState, m: &MotorFast, t: u64) {
    if let Some(motor) = state.motors.get_mut(usize::from(m.motor.max(1) - 1)) {
        motor.rpm = m.rpm as f32;
        motor.current_a = m.current_a as f32;
        motor.position_counts = m.position_counts.into();
    }
    state.touch(Group::MotorDrive, t);
}

/// 0x261-0x268: motor `m.motor`'s driver voltage and temperatures, and its driver status bits
/// (`driver_status`, already in `chassis_interfaces::DriverStatus` meaning).
pub(crate) fn apply_motor_slow(state: &mut ChassisState, m: &MotorSlow, driver_status: u8, t: u64) {
    if let Some(motor) = state.motors.get_mut(usize::from(m.motor.max(1) - 1)) {
        motor.driver_voltage_v = m.driver_voltage_v as f32;
        motor.driver_temp_c = m.driver_temp_c as f32;
        motor.motor_temp_c = m.motor_temp_c as f32;
        motor.driver_status = driver_status;
    }
    state.touch(Group::MotorDriver, t);
}

/// 0x241: the RC transmitter's levers, sticks and knob.
pub(crate) fn apply_rc(state: &mut ChassisState, r: &RcState, t: u64) {
    state.rc = *r;
    state.touch(Group::Rc, t);
}

/// The state group of battery pack `group` (0: the pack, 1-2: the TITAN's extra packs).
fn bms_group(group: usize) -> Group {
    match group {
        0 => Group::BmsPack,
        1 => Group::Bms1,
        _ => Group::Bms2,
    }
}

/// 0x361 (TITAN also 0x363 / 0x365): a pack's charge, health, voltage, current and
/// temperature; the first pack's charge and current are the system's.
pub(crate) fn apply_bms_data(state: &mut ChassisState, b: &BmsData, t: u64) {
    let group = usize::from(b.group.min(2));
    if let Some(bms) = state.bms.get_mut(group) {
        bms.soc_pct = b.soc_pct as f32;
        bms.soh_pct = b.soh_pct as f32;
        bms.voltage_v = b.voltage_v as f32;
        bms.current_a = b.current_a as f32;
        bms.temperature_c = b.temperature_c as f32;
    }
    if group == 0 {
        state.system.battery_soc_pct = b.soc_pct as f32;
        state.system.battery_current_a = b.current_a as f32;
    }
    state.touch(bms_group(group), t);
}

/// 0x362 (TITAN also 0x364 / 0x366): a pack's alarm and warning bits. True while any pack
/// reports an alarm.
pub(crate) fn apply_bms_alarm(state: &mut ChassisState, b: &BmsAlarm, t: u64) -> bool {
    let group = usize::from(b.group.min(2));
    if let Some(bms) = state.bms.get_mut(group) {
        bms.alarm_flags = b.alarm_flags();
    }
    state.touch(bms_group(group), t);
    state.bms.iter().any(|b| b.alarm_flags & 0xFFFF != 0)
}

/// Sets or clears `flag` in `word`.
pub(crate) fn set_bits(word: &mut u64, flag: u64, on: bool) {
    if on {
        *word |= flag;
    } else {
        *word &= !flag;
    }
}
