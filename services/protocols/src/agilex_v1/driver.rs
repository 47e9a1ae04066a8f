//! The SCOUT MINI driver: a pure state machine over the SCOUT MINI codec.
//!
//! Everything about its behaviour is documented on [`V1Driver`].

use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
use std::time::Duration;

use chassis_interfaces::{
    ClampFlags, ControlMode, FaultClear, FaultFlags, Group, LinkFlags, Velocity,
};

use super::codec::{self, Frame, Lights, MotionCommand, clear_code, fault, mode};
use super::commands::{frames_for, velocity_command};
use super::kinematics::SkidCommand;
use crate::agilex_v1::V1Profile;
use crate::agilex_v2::{body_status, vehicle_state_flags};
use crate::command::Command;
use crate::driver::{
    CommandSchedule, ControlOutcome, Driver, DriverConfig, DriverCore, Level, PoseIntegrator, Rx,
    WireItem, flags_of,
};
use crate::kind::RobotKind;
use crate::time::{Timestamp, earliest};

/// What the driver wants of the front light (0x140).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
enum LightRequest {
    /// Never asked for: no 0x140 is ever sent.
    Untouched,
    /// Light control by command: this 0x140 is repeated every [`V1Driver::LIGHT_PERIOD`].
    Hold(Lights),
    /// Hand the light back to the chassis: a 0x140 with the enable flag clear is repeated until
    /// 0x141 reports light control off (`sent` once at least one went out).
    Release { sent: bool },
}

/// The SCOUT MINI driver: heartbeat, authority, limits and quantisation, feedback into
/// [`ChassisState`](chassis_interfaces::ChassisState).
///
/// # On the wire
///
/// * **Heartbeat.** 0x130 every `profile.heartbeat_period_ms` (20 ms) on a fixed grid, always —
///   explicit zeros when there is no command. A changed command goes out at once (no sooner than
///   `config.min_command_interval_ms` after the previous 0x130, except a stop, which is never
///   delayed); the grid is not disturbed by it.
/// * **Authority.** There is no mode frame: while the driver wants control every 0x130 carries
///   mode 0x01 (CAN command), which is what the chassis needs to obey it. So after a chassis
///   reboot, a heartbeat gap or an RC hand-back the very next heartbeat takes control again, with
///   no handshake. [`Command::Mode`]`{ take_control: false }` lets go: the next 0x130 is an
///   urgent stop still in mode 0x01 (so the robot stops at once whatever the firmware does with
///   a mode-0x00 frame), and every later one carries mode 0x00 (RC) with zero speeds; the
///   command echo then reads zero with [`ClampFlags::CHASSIS_NOT_READY`] while a motion is
///   requested. An RC transmitter holding authority (0x151 mode 0x00) is reported as
///   [`LinkFlags::RC_AUTHORITY`], never fought: the driver keeps sending the current command,
///   which the chassis obeys again as soon as the transmitter lets go.
/// * **Rolling count.** One counter per CAN id, each starting at 0 and +1 per frame of that id
///   sent (wrapping at 255). The manual repeats "added once every command sent" in each frame's
///   own table and never mentions a shared counter; AgileX's own SDK keeps one count per message
///   type (motion command, light command). The chassis is not known to check the count.
/// * **Limits and quantisation.** A twist is limited to the profile and rounded to the wire's
///   whole percents by [`velocity_command`]; the quantised command actually sent is echoed in
///   `state.command` with its [`ClampFlags`] (`QUANTISED`, `LINEAR_LIMIT`, `ANGULAR_LIMIT`,
///   `LATERAL_UNSUPPORTED`) and [`Group::Command`] is touched whenever a 0x130 goes out. A steering
///   angle request becomes the bicycle yaw rate ω = v·tan δ / L.
/// * **Clearing faults.** The fault-clear codes ride in 0x130 b1, one frame per code
///   ([`super::clear_codes_for`]; `ALL` is eight codes). They are not mixed with zeros: each of
///   these frames keeps the current motion. The first goes out at once, the others back to back
///   (each no sooner than `min_command_interval_ms` after the previous 0x130).
/// * **Lights** (0x140). The manual gives 0x140 a 25 ms period "when used" and no receive
///   timeout. Light control by command is therefore sent at once and then repeated every 25 ms
///   on its own grid for as long as it is enabled (so a rebooted chassis gets it back without
///   bookkeeping, like the mode byte of 0x130). Handing the light back sends a 0x140 with the
///   enable flag clear, repeated every 25 ms only until 0x141 reports light control off. Lights
///   never asked for are never sent. 0x140 has its own rolling count.
/// * **Shutdown** sends a zero 0x130 at once (SCOUT MINI has no brake); the heartbeat continues
///   with zeros for as long as the owner keeps polling.
///
/// # From the wire
///
/// Every frame's checksum is checked by [`codec::decode`]: a bad one is dropped and counted in
/// `link.rx_bad_checksum`, other undecodable frames in `link.rx_decode_errors`, ids the SCOUT
/// MINI does not use (and extended ids) in `link.rx_unknown_id`; each drop is also a
/// [`DriverEvent::RxDropped`](crate::driver::DriverEvent::RxDropped). Dropped frames change nothing else, and in particular do not count
/// as signs of life for [`LinkFlags::CHASSIS_SILENT`]: a chassis whose every frame is corrupt
/// leaves the state as stale as a silent one.
///
/// | id | into `ChassisState` | group |
/// | --- | --- | --- |
/// | 0x151 | `system`: body status, control mode (0x00 → `REMOTE`, 0x01 → `COMMAND`, 0x02 → `SERIAL`), battery voltage, raw fault word and [`normalize_faults`]; `power_enabled` = no under-voltage failure; link flags `COMMAND_MODE` (chassis in CAN command mode *and* we want control) and `RC_AUTHORITY` | `System` |
/// | 0x131 | `motion.linear_mps`, `motion.angular_radps`; the pose integrated from them | `Motion`, `Pose` |
/// | 0x200-0x203 | `motors[0..4]`: current, rpm (`MotorDrive`); driver and motor temperature (`MotorDriver`) | `MotorDrive`, `MotorDriver` |
/// | 0x141 | `lights` | `Lights` |
///
/// Commands seen on the bus (0x130, 0x140 from another node) are valid frames but not state:
/// they are counted in `link.rx_frames` and otherwise ignored. Notices
/// ([`DriverEvent::Notice`](crate::driver::DriverEvent::Notice)) report control-mode changes (RC takeover and hand-back included),
/// faults set and cleared, the chassis turning silent and talking again, and the bus going down
/// and coming back.
#[derive(Debug, Serialize, Deserialize)]
pub struct V1Driver {
    profile: V1Profile,
    core: DriverCore,
    pose: PoseIntegrator,
    /// The latest request, limited and quantised.
    requested: SkidCommand,
    /// What the next heartbeat carries (its `fault_clear` is always `NONE`).
    motion: MotionCommand,
    motion_clamp_flags: u32,
    want_control: bool,
    /// Control was just released: the next 0x130 is a stop in CAN command mode.
    release_stop: bool,
    clear_codes: VecDeque<u8>,
    lights: LightRequest,
    light_schedule: CommandSchedule,
    motion_count: u8,
    light_count: u8,
}

/// A request for no motion.
const STANDING: SkidCommand = SkidCommand {
    linear_mps: 0.0,
    angular_radps: 0.0,
    linear_pct: 0,
    angular_pct: 0,
    clamp_flags: 0,
};

impl V1Driver {
    /// Period of the light command while it is used (the manual's 25 ms).
    pub const LIGHT_PERIOD: Duration = Duration::from_millis(25);

    /// A driver starting at `now`: the first 0x130 is due at once (mode 0x01 with
    /// `config.take_control`, else 0x00).
    pub fn new(profile: V1Profile, config: DriverConfig, now: Timestamp) -> Self {
        let mut core = DriverCore::new(
            profile.model.robot().id(),
            Duration::from_millis(profile.heartbeat_period_ms),
            &config,
            now,
        );
        core.state.system.control_mode = ControlMode::UNKNOWN;
        core.state.system.wire_protocol = chassis_interfaces::WireProtocol::V1;
        let want_control = config.take_control;
        Self {
            profile,
            core,
            pose: PoseIntegrator::default(),
            requested: STANDING,
            motion: wire_motion(want_control, &STANDING),
            motion_clamp_flags: 0,
            want_control,
            release_stop: false,
            clear_codes: VecDeque::new(),
            lights: LightRequest::Untouched,
            light_schedule: CommandSchedule::new(Self::LIGHT_PERIOD, Duration::ZERO, now),
            motion_count: 0,
            light_count: 0,
        }
    }

    pub fn profile(&self) -> &V1Profile {
        &self.profile
    }

    /// True while every 0x130 carries mode 0x01 (CAN command).
    pub fn wants_control(&self) -> bool {
        self.want_control
    }

    /// Fault-clear codes still waiting for their 0x130.
    pub fn pending_clear_codes(&self) -> usize {
        self.clear_codes.len()
    }

    /// Recomputes the request from a twist.
    fn plan(&mut self, command: &Velocity) {
        self.requested = velocity_command(command, &self.profile);
        self.update_motion();
    }

    /// Recomputes what the heartbeat carries from the request and the authority we want.
    fn update_motion(&mut self) {
        let motion = wire_motion(self.want_control, &self.requested);
        let mut flags = self.requested.clamp_flags;
        if !self.want_control && (self.requested.linear_pct != 0 || self.requested.angular_pct != 0)
        {
            flags |= ClampFlags::CHASSIS_NOT_READY;
        }
        let stop = motion.linear_mps == 0.0 && motion.angular_radps == 0.0;
        self.core.schedule.update(&mut self.motion, motion, stop);
        self.motion_clamp_flags = flags;
    }

    fn light_wanted(&self) -> bool {
        match self.lights {
            LightRequest::Untouched => false,
            LightRequest::Hold(_) => true,
            LightRequest::Release { sent } => !sent || self.core.state.lights.control_enabled != 0,
        }
    }

    /// Encodes and counts one frame with the count of its id.
    fn transmit(&mut self, frame: Frame) -> Option<WireItem> {
        let count = match frame {
            Frame::LightCommand(_) => &mut self.light_count,
            _ => &mut self.motion_count,
        };
        let encoded = frame.encode(*count, &self.profile);
        if encoded.is_ok() {
            *count = count.wrapping_add(1);
        }
        // Quantisation keeps every planned value on the wire's range; a failure is a bug guard
        // (or a profile with a full scale that is not positive).
        self.core.transmit(&frame, encoded, WireItem::Can)
    }

    fn motion_frame(&mut self, now: Timestamp) -> Frame {
        self.core.schedule.sent(now);
        let mut motion = self.motion;
        if self.release_stop {
            self.release_stop = false;
            motion = MotionCommand::drive(0.0, 0.0);
            // The mode-0x00 heartbeats follow on the grid.
        }
        motion.fault_clear = self.clear_codes.pop_front().unwrap_or(clear_code::NONE);
        if !self.clear_codes.is_empty() {
            self.core.schedule.command_changed(false);
        }
        let echo = &mut self.core.state.command;
        echo.linear_mps = motion.linear_mps as f32;
        echo.angular_radps = motion.angular_radps as f32;
        echo.lateral_mps = 0.0;
        echo.steer_rad = 0.0;
        echo.clamp_flags = self.motion_clamp_flags;
        self.core.state.touch(Group::Command, now.as_nanos());
        Frame::MotionCommand(motion)
    }

    fn light_frame(&mut self, now: Timestamp) -> Option<Frame> {
        self.light_schedule.sent(now);
        match &mut self.lights {
            LightRequest::Untouched => None,
            LightRequest::Hold(lights) => Some(Frame::LightCommand(*lights)),
            LightRequest::Release { sent } => {
                *sent = true;
                Some(Frame::LightCommand(Lights::default()))
            }
        }
    }

    fn apply(&mut self, now: Timestamp, frame: Frame) {
        let t = now.as_nanos();
        match frame {
            Frame::SystemStatus(s) => self.apply_system(now, s),
            Frame::MotionFeedback(m) => {
                let (v, w) = (m.linear_mps, m.angular_radps);
                self.core.state.motion.linear_mps = v as f32;
                self.core.state.motion.angular_radps = w as f32;
                self.core.state.motion.lateral_mps = 0.0;
                self.core.state.touch(Group::Motion, t);
                self.pose
                    .update(now, v, 0.0, w, &mut self.core.state.odometry);
                self.core.state.touch(Group::Pose, t);
            }
            Frame::Motor(m) => {
                let state = &mut self.core.state;
                if let Some(motor) = state.motors.get_mut(usize::from(m.motor.clamp(1, 4) - 1)) {
                    motor.current_a = m.current_a as f32;
                    motor.rpm = m.rpm as f32;
                    motor.driver_temp_c = m.driver_temp_c as f32;
                    motor.motor_temp_c = m.motor_temp_c as f32;
                }
                state.touch(Group::MotorDrive, t);
                state.touch(Group::MotorDriver, t);
            }
            Frame::LightState(l) => {
                let lights = &mut self.core.state.lights;
                lights.control_enabled = u8::from(l.control_enabled);
                lights.front_mode = l.front_mode;
                lights.front_brightness_pct = l.front_brightness_pct;
                self.core.state.touch(Group::Lights, t);
                if !l.control_enabled && self.lights == (LightRequest::Release { sent: true }) {
                    self.lights = LightRequest::Untouched;
                }
            }
            // Commands on the bus from another node: not ours to decode into state.
            Frame::MotionCommand(_) | Frame::LightCommand(_) => {}
        }
    }

    fn apply_system(&mut self, now: Timestamp, s: codec::SystemStatus) {
        let old_mode = self.core.state.system.control_mode;
        let new_mode = normalize_mode(s.mode);
        let old_faults = self.core.state.system.fault_flags;
        let new_faults = normalize_faults(s.vendor_fault_word) | vehicle_state_flags(s.body_status);
        let sys = &mut self.core.state.system;
        sys.body_status = body_status(s.body_status);
        sys.battery_voltage_v = s.battery_voltage_v as f32;
        sys.vendor_fault_word = s.vendor_fault_word.into();
        self.core
            .system_status(now, new_mode, new_faults, self.want_control);
        if new_mode != old_mode {
            let level = if new_mode == ControlMode::COMMAND {
                Level::Info
            } else {
                Level::Warn
            };
            let why = match new_mode {
                ControlMode::REMOTE => ": an RC transmitter holds authority (reported, not fought)",
                ControlMode::SERIAL => ": commands are taken from the serial port, not CAN",
                _ => "",
            };
            self.core.notice(
                level,
                format!(
                    "chassis mode {} -> {}{why}",
                    ControlMode::name(old_mode),
                    ControlMode::name(new_mode)
                ),
            );
        }
        self.core.fault_notices(
            old_faults,
            new_faults,
            FaultFlags::WARNINGS | FaultFlags::COMMAND_CHECKSUM,
        );
    }
}

/// The 0x130 the heartbeat carries for a request.
fn wire_motion(want_control: bool, requested: &SkidCommand) -> MotionCommand {
    if want_control {
        requested.motion_command()
    } else {
        MotionCommand {
            mode: mode::RC,
            ..MotionCommand::default()
        }
    }
}

/// The normalized `ControlMode` of a 0x151 mode byte.
pub(crate) fn normalize_mode(wire_mode: u8) -> u8 {
    match wire_mode {
        mode::RC => ControlMode::REMOTE,
        mode::CAN_COMMAND => ControlMode::COMMAND,
        mode::SERIAL => ControlMode::SERIAL,
        _ => ControlMode::UNKNOWN,
    }
}

/// The normalized `FaultFlags` of a 0x151 fault word (b4-b5 read big-endian).
pub fn normalize_faults(word: u16) -> u64 {
    use chassis_interfaces::FaultFlags as F;
    const MAP: [(u16, u64); 13] = [
        (fault::COMMAND_CHECKSUM, F::COMMAND_CHECKSUM),
        (fault::DRIVE_OVER_TEMP_ALARM, F::OVER_TEMPERATURE_WARNING),
        (fault::MOTOR_OVER_CURRENT_ALARM, F::OVER_CURRENT_WARNING),
        (
            fault::BATTERY_UNDER_VOLTAGE_ALARM,
            F::BATTERY_UNDER_VOLTAGE_WARNING,
        ),
        (fault::RC_DISCONNECTED, F::RC_LINK_LOST),
        (fault::BATTERY_UNDER_VOLTAGE, F::BATTERY_UNDER_VOLTAGE),
        (fault::BATTERY_OVER_VOLTAGE, F::BATTERY_OVER_VOLTAGE),
        (fault::MOTOR_1_COMM, F::MOTOR_1_COMM_LOST),
        (fault::MOTOR_2_COMM, F::MOTOR_2_COMM_LOST),
        (fault::MOTOR_3_COMM, F::MOTOR_3_COMM_LOST),
        (fault::MOTOR_4_COMM, F::MOTOR_4_COMM_LOST),
        (fault::DRIVE_OVER_TEMP_PROTECTION, F::OVER_TEMPERATURE),
        (fault::MOTOR_OVER_CURRENT_PROTECTION, F::OVER_CURRENT),
    ];
    flags_of(word, &MAP)
}

impl Driver for V1Driver {
    crate::snapshot::whole_driver!();

    fn robot(&self) -> RobotKind {
        self.profile.model.robot()
    }

    crate::driver::core_accessors!();

    fn handle_rx(&mut self, now: Timestamp, rx: Rx<'_>) {
        let profile = &self.profile;
        if let Some(decoded) = self.core.can_rx(now, rx, |f| codec::decode(f, profile)) {
            self.apply(now, decoded.frame);
        }
    }

    fn set_command(&mut self, _now: Timestamp, command: &Velocity) {
        self.plan(command);
    }

    fn control(&mut self, now: Timestamp, command: &Command) -> ControlOutcome {
        let planned = crate::driver::admit!(self.core, command, |c| frames_for(c, &self.profile));
        match *command {
            Command::Mode { take_control } => {
                let releasing = self.want_control && !take_control;
                self.want_control = take_control;
                self.update_motion();
                // A stop not yet sent stays due until control is taken back.
                self.release_stop = releasing || (self.release_stop && !take_control);
                if releasing {
                    self.core.schedule.command_changed(true);
                }
                let obeyed =
                    self.core.state.system.control_mode == ControlMode::COMMAND && take_control;
                self.core.set_flag(LinkFlags::COMMAND_MODE, obeyed);
                ControlOutcome::Done(if take_control {
                    "CAN command mode: every 0x130 carries mode 0x01".into()
                } else {
                    "control released: a stop, then 0x130 with mode 0x00 (RC); motion commands \
                     are not sent"
                        .into()
                })
            }
            Command::ClearFaults { which } => {
                let codes: Vec<u8> = planned
                    .frames
                    .iter()
                    .filter_map(|frame| match frame {
                        Frame::MotionCommand(m) if m.fault_clear != clear_code::NONE => {
                            Some(m.fault_clear)
                        }
                        _ => None,
                    })
                    .collect();
                let n = codes.len();
                self.clear_codes.extend(codes);
                self.core.schedule.command_changed(false);
                ControlOutcome::Done(format!(
                    "clear-fault {} sent ({n} code{} in 0x130 b1)",
                    FaultClear::name(which),
                    if n == 1 { "" } else { "s" }
                ))
            }
            Command::Lights { enable, .. } => {
                let Some(Frame::LightCommand(lights)) = planned.frames.first().copied() else {
                    return ControlOutcome::Invalid("no light frame for this request".into());
                };
                if let Err(err) = Frame::LightCommand(lights).encode(0, &self.profile) {
                    return ControlOutcome::Invalid(err.to_string());
                }
                self.lights = if enable {
                    LightRequest::Hold(lights)
                } else {
                    LightRequest::Release { sent: false }
                };
                self.light_schedule.restart(now);
                ControlOutcome::Done(if enable {
                    format!(
                        "light control on: front {} {} %, repeated every 25 ms",
                        chassis_interfaces::LightMode::name(lights.front_mode),
                        lights.front_brightness_pct
                    )
                } else {
                    "light handed back to the chassis".into()
                })
            }
            // `frames_for` refuses everything else on this robot; this arm is a guard.
            _ => ControlOutcome::Unsupported(format!("scout-mini has no {}", command.name())),
        }
    }

    fn handle_timeout(&mut self, now: Timestamp) {
        if self.core.check_silence(now, "valid feedback") {
            self.pose.reset();
        }
    }

    fn poll_transmit(&mut self, now: Timestamp) -> Option<WireItem> {
        if self.core.bus_down {
            return None;
        }
        if self.core.schedule.is_due(now) {
            let frame = self.motion_frame(now);
            return self.transmit(frame);
        }
        if self.light_wanted() && self.light_schedule.is_due(now) {
            let frame = self.light_frame(now)?;
            return self.transmit(frame);
        }
        None
    }

    fn poll_timeout(&self) -> Option<Timestamp> {
        let mut next = Some(self.core.poll_timeout()?);
        if self.light_wanted() {
            next = earliest(next, Some(self.light_schedule.deadline()));
        }
        next
    }

    fn set_bus_down(&mut self, now: Timestamp, down: bool) {
        if !self.core.set_bus_down(now, down) {
            return;
        }
        self.clear_codes.clear();
        self.release_stop = false;
        if !down {
            self.light_schedule.restart(now);
            self.pose.reset();
            self.core.notice(
                Level::Info,
                if self.want_control {
                    "bus back: heartbeat restarted in CAN command mode"
                } else {
                    "bus back: heartbeat restarted (control released)"
                },
            );
        }
    }

    fn shutdown(&mut self, _now: Timestamp) {
        self.plan(&Velocity::ZERO);
        // Due at once even when the command was already zero.
        self.core.schedule.command_changed(true);
    }
}

#[cfg(test)]
#[path = "driver_tests.rs"]
mod driver_tests;
