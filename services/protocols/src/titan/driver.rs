//! The TITAN driver: a pure state machine over the TITAN codec.
//!
//! * Heartbeat: 0x111 every 20 ms, always — explicit zeros when there is no command.
//! * Command mode: 0x421 at start and again whenever the chassis reports standby while we want
//!   control (a rebooted or timed-out chassis is taken back); an RC transmitter holding authority
//!   is reported, never fought.
//! * Parking brake: released once before motion, in CAN command mode (the only mode that obeys
//!   0x131); engaged after an idle time and on shutdown; never a brake frame per velocity
//!   command. A brake engaged by request holds until released by request.
//! * Limits and twist → inner steering angle from [`super::kinematics`].

use std::collections::VecDeque;
use std::time::Duration;

use chassis_interfaces::{
    ChassisState, ClampFlags, ControlMode, ControlStatus, FaultFlags, Group, LinkFlags,
    RequestFlags, RobotKind, SystemState, Twist,
};

use super::codec::{self, Frame, MotionCommand, ParkingBrake, fault, mode};
use super::commands::{frames_for, motion_command};
use super::kinematics::yaw_rate;
use crate::command::{Command, Turn};
use crate::driver::{
    CommandSchedule, ControlOutcome, Driver, DriverConfig, DriverEvent, Level, LinkMonitor,
    PoseIntegrator, Rx, Transmit,
};
use crate::profile::{Robot, TitanProfile};
use crate::time::{Timestamp, earliest};

/// Speed below which the robot counts as standing still, m/s.
const STANDING_MPS: f64 = 0.01;
/// Least time between two 0x421 frames while the chassis keeps reporting standby.
const MODE_RETRY: Duration = Duration::from_millis(50);

/// What the driver believes about the parking brake (TITAN does not report it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Brake {
    /// Not known (power-up, chassis reboot): treated as engaged.
    Unknown,
    Engaged,
    Released,
}

/// The TITAN driver.
#[derive(Debug)]
pub struct TitanDriver {
    profile: TitanProfile,
    config: DriverConfig,
    state: ChassisState,
    queue: VecDeque<Frame>,
    events: VecDeque<DriverEvent>,
    schedule: CommandSchedule,
    link: LinkMonitor,
    pose: PoseIntegrator,
    /// The motion the next 0x111 carries.
    motion: MotionCommand,
    motion_clamp_flags: u32,
    want_control: bool,
    last_mode_request: Option<Timestamp>,
    brake: Brake,
    /// The brake was engaged on request: motion waits until it is released on request.
    brake_held: bool,
    idle_since: Option<Timestamp>,
    steering_zero: Option<(u64, Timestamp)>,
    next_token: u64,
    bus_down: bool,
    was_silent: bool,
    other_faults: u64,
}

impl TitanDriver {
    /// A driver starting at `now`. With `config.take_control` it asks for CAN command mode at once.
    pub fn new(profile: TitanProfile, config: DriverConfig, now: Timestamp) -> Self {
        let mut state = ChassisState {
            robot: RobotKind::TITAN,
            ..ChassisState::default()
        };
        state.system.control_mode = ControlMode::UNKNOWN;
        let schedule = CommandSchedule::new(
            Duration::from_millis(profile.heartbeat_period_ms),
            Duration::from_millis(config.min_command_interval_ms),
            now,
        );
        let link = LinkMonitor::new(Duration::from_millis(config.silence_timeout_ms), now);
        let mut driver = Self {
            want_control: config.take_control,
            profile,
            config,
            state,
            queue: VecDeque::new(),
            events: VecDeque::new(),
            schedule,
            link,
            pose: PoseIntegrator::default(),
            motion: MotionCommand::default(),
            motion_clamp_flags: 0,
            last_mode_request: None,
            brake: Brake::Unknown,
            brake_held: false,
            idle_since: Some(now),
            steering_zero: None,
            next_token: 1,
            bus_down: false,
            was_silent: false,
            other_faults: 0,
        };
        if driver.want_control {
            driver.request_mode(now);
        }
        driver
    }

    pub fn profile(&self) -> &TitanProfile {
        &self.profile
    }

    fn notice(&mut self, level: Level, message: impl Into<String>) {
        self.events.push_back(DriverEvent::Notice {
            level,
            message: message.into(),
        });
    }

    fn request_mode(&mut self, now: Timestamp) {
        self.queue.push_back(Frame::Mode(codec::ModeCommand {
            mode: mode::CAN_COMMAND,
        }));
        self.last_mode_request = Some(now);
    }

    fn is_moving(&self) -> bool {
        self.state.motion.linear_mps.abs() as f64 > STANDING_MPS || self.motion.linear_mps != 0.0
    }

    /// Recomputes the motion to send from the latest command.
    fn plan(&mut self, now: Timestamp, command: &Twist) {
        let turn = if command.flags & RequestFlags::STEER != 0 {
            Turn::Steer(command.steer_rad.into())
        } else {
            Turn::YawRate(command.angular_z_radps.into())
        };
        let (mut motion, mut flags) = match motion_command(
            command.linear_x_mps.into(),
            command.linear_y_mps.into(),
            turn,
            &self.profile,
        ) {
            Ok(planned) => planned,
            // Non-finite input: the mux rejects it first; a stop is the only safe answer here.
            Err(_) => (MotionCommand::default(), ClampFlags::CHASSIS_NOT_READY),
        };
        if self.brake_held && motion.linear_mps != 0.0 {
            motion = MotionCommand {
                linear_mps: 0.0,
                steer_rad: motion.steer_rad,
            };
            flags |= ClampFlags::CHASSIS_NOT_READY;
        }
        let moving = motion.linear_mps != 0.0;
        if moving {
            self.idle_since = None;
        } else if self.idle_since.is_none() {
            self.idle_since = Some(now);
        }
        if motion != self.motion {
            let stop = !moving;
            self.motion = motion;
            self.schedule.command_changed(stop);
        }
        self.motion_clamp_flags = flags;
    }

    fn update_body(&mut self, now: Timestamp) {
        self.state.system.parking_brake_engaged = u8::from(self.brake != Brake::Released);
        self.state.touch(Group::Body, now.as_nanos());
    }

    fn set_flag(&mut self, flag: u32, on: bool) {
        if on {
            self.state.link_flags |= flag;
        } else {
            self.state.link_flags &= !flag;
        }
    }

    fn apply(&mut self, now: Timestamp, frame: Frame) {
        let t = now.as_nanos();
        match frame {
            Frame::SystemStatus(s) => self.apply_system(now, s),
            Frame::MotionFeedback(m) => {
                let w = yaw_rate(m.linear_mps, m.steer_rad, &self.profile);
                self.state.motion.linear_mps = m.linear_mps as f32;
                self.state.motion.steer_rad = m.steer_rad as f32;
                self.state.motion.angular_radps = w as f32;
                self.state.motion.lateral_mps = 0.0;
                self.state.touch(Group::Motion, t);
                self.pose
                    .update(now, m.linear_mps, 0.0, w, &mut self.state.odometry);
                self.state.touch(Group::Pose, t);
            }
            Frame::SteeringFeedback(s) => {
                self.state.motion.front_steer_rad = s.front_steer_rad as f32;
                self.state.motion.rear_steer_rad = s.rear_steer_rad as f32;
                self.state.touch(Group::Steering, t);
            }
            Frame::AxleSpeed(a) => {
                self.state.motion.front_axle_mps = a.front_axle_mps as f32;
                self.state.motion.rear_axle_mps = a.rear_axle_mps as f32;
                self.state.touch(Group::WheelSpeed, t);
            }
            Frame::Odometer(o) => {
                self.state.odometry.front_distance_m = o.front_distance_m;
                self.state.odometry.rear_distance_m = o.rear_distance_m;
                self.state.touch(Group::Odometry, t);
            }
            Frame::MotorFast(m) => {
                if let Some(motor) = self.state.motors.get_mut(usize::from(m.motor.max(1) - 1)) {
                    motor.rpm = m.rpm as f32;
                    motor.current_a = m.current_a as f32;
                    motor.position_counts = m.position_counts.into();
                }
                self.state.touch(Group::MotorDrive, t);
            }
            Frame::MotorSlow(m) => {
                if let Some(motor) = self.state.motors.get_mut(usize::from(m.motor.max(1) - 1)) {
                    motor.driver_voltage_v = m.driver_voltage_v as f32;
                    motor.driver_temp_c = m.driver_temp_c as f32;
                    motor.motor_temp_c = m.motor_temp_c as f32;
                    motor.driver_status = m.driver_status;
                }
                self.state.touch(Group::MotorDriver, t);
            }
            Frame::Rc(r) => {
                let rc = &mut self.state.rc;
                rc.switch_a = r.switch_a;
                rc.switch_b = r.switch_b;
                rc.switch_c = r.switch_c;
                rc.switch_d = r.switch_d;
                rc.right_x_pct = r.right_x_pct;
                rc.right_y_pct = r.right_y_pct;
                rc.left_y_pct = r.left_y_pct;
                rc.left_x_pct = r.left_x_pct;
                rc.knob_a_pct = r.knob_a_pct;
                rc.counter = r.counter;
                self.state.touch(Group::Rc, t);
            }
            Frame::BmsData(b) => {
                let group = usize::from(b.group.min(2));
                if let Some(bms) = self.state.bms.get_mut(group) {
                    bms.soc_pct = b.soc_pct as f32;
                    bms.soh_pct = b.soh_pct as f32;
                    bms.voltage_v = b.voltage_v as f32;
                    bms.current_a = b.current_a as f32;
                    bms.temperature_c = b.temperature_c as f32;
                }
                if group == 0 {
                    self.state.system.battery_soc_pct = b.soc_pct as f32;
                    self.state.system.battery_current_a = b.current_a as f32;
                    let low = b.soc_pct < self.profile.low_battery_warning_soc_pct;
                    self.set_other_fault(FaultFlags::BATTERY_LOW, low);
                }
                self.state.touch(bms_group(group), t);
            }
            Frame::BmsAlarm(b) => {
                let group = usize::from(b.group.min(2));
                if let Some(bms) = self.state.bms.get_mut(group) {
                    bms.alarm_flags = b.alarm_flags();
                }
                let any_alarm = self.state.bms.iter().any(|b| b.alarm_flags & 0xFFFF != 0);
                self.set_other_fault(FaultFlags::BMS_ALARM, any_alarm);
                self.state.touch(bms_group(group), t);
            }
            Frame::SteeringZeroAck => {
                self.state.system.steering_zero_done = 1;
                self.set_flag(LinkFlags::STEERING_ZERO_PENDING, false);
                self.state.touch(Group::Body, t);
                if let Some((token, _)) = self.steering_zero.take() {
                    self.events.push_back(DriverEvent::ControlDone {
                        token,
                        status: ControlStatus::OK,
                        message: "steering zero set".into(),
                    });
                }
                self.notice(Level::Info, "steering zero position set");
            }
            // Commands on the bus from another node: not ours to decode into state.
            Frame::MotionCommand(_)
            | Frame::ParkingBrake(_)
            | Frame::Mode(_)
            | Frame::SilentMode(_)
            | Frame::OffRoad(_)
            | Frame::SteeringZero
            | Frame::ClearFault(_) => {}
        }
    }

    fn set_other_fault(&mut self, flag: u64, on: bool) {
        if on {
            self.other_faults |= flag;
        } else {
            self.other_faults &= !flag;
        }
    }

    fn apply_system(&mut self, now: Timestamp, s: codec::SystemStatus) {
        let old_mode = self.state.system.control_mode;
        let new_mode = match s.mode {
            mode::STANDBY => ControlMode::STANDBY,
            mode::CAN_COMMAND => ControlMode::COMMAND,
            mode::REMOTE => ControlMode::REMOTE,
            _ => ControlMode::UNKNOWN,
        };
        let old_faults = self.state.system.fault_flags;
        let new_faults = normalize_faults(s.vendor_fault_word)
            | self.other_faults
            | if s.body_status == codec::body::EXCEPTION {
                FaultFlags::BODY_EXCEPTION
            } else {
                0
            };
        let sys = &mut self.state.system;
        sys.body_status = match s.body_status {
            codec::body::NORMAL => SystemState::BODY_NORMAL,
            _ => SystemState::BODY_EXCEPTION,
        };
        sys.control_mode = new_mode;
        sys.battery_voltage_v = s.battery_voltage_v as f32;
        sys.vendor_fault_word = s.vendor_fault_word;
        sys.fault_flags = new_faults;
        sys.power_enabled = u8::from(new_faults & FaultFlags::BATTERY_UNDER_VOLTAGE == 0);
        self.state.touch(Group::System, now.as_nanos());
        self.set_flag(LinkFlags::COMMAND_MODE, new_mode == ControlMode::COMMAND);
        self.set_flag(LinkFlags::RC_AUTHORITY, new_mode == ControlMode::REMOTE);

        if new_mode != old_mode {
            // Losing command mode is worth a warning; finding out the mode at power-up is not.
            let level = if new_mode == ControlMode::COMMAND || old_mode == ControlMode::UNKNOWN {
                Level::Info
            } else {
                Level::Warn
            };
            self.notice(
                level,
                format!(
                    "chassis mode {} -> {}",
                    ControlMode::name(old_mode),
                    ControlMode::name(new_mode)
                ),
            );
            if new_mode == ControlMode::STANDBY || new_mode == ControlMode::REMOTE {
                // After a reboot or an RC session the brake may be engaged again.
                self.brake = Brake::Unknown;
                self.update_body(now);
            }
        }
        if new_faults != old_faults {
            let set = FaultFlags::names(new_faults & !old_faults);
            let cleared = FaultFlags::names(old_faults & !new_faults);
            if !set.is_empty() {
                let level = if new_faults & !old_faults & !FaultFlags::WARNINGS != 0 {
                    Level::Error
                } else {
                    Level::Warn
                };
                self.notice(level, format!("chassis faults set: {}", set.join(", ")));
            }
            if !cleared.is_empty() {
                self.notice(
                    Level::Info,
                    format!("chassis faults cleared: {}", cleared.join(", ")),
                );
            }
        }
        // Power-cycle recovery: a chassis in standby while we want control is asked again.
        if new_mode == ControlMode::STANDBY
            && self.want_control
            && !self.bus_down
            && self
                .last_mode_request
                .is_none_or(|t| now.saturating_since(t) >= MODE_RETRY)
        {
            self.request_mode(now);
        }
    }

    fn next_token(&mut self) -> u64 {
        let token = self.next_token;
        self.next_token += 1;
        token
    }
}

fn bms_group(group: usize) -> Group {
    match group {
        0 => Group::BmsPack,
        1 => Group::Bms1,
        _ => Group::Bms2,
    }
}

/// The normalized `FaultFlags` of a 0x211 fault word.
pub fn normalize_faults(word: u32) -> u64 {
    const MAP: [(u32, u64); 13] = [
        (
            fault::FRONT_STEERING_ENCODER,
            FaultFlags::FRONT_STEERING_ENCODER,
        ),
        (
            fault::REAR_STEERING_ENCODER,
            FaultFlags::REAR_STEERING_ENCODER,
        ),
        (fault::BUMPER, FaultFlags::BUMPER),
        (fault::MOTOR_DRIVER_ERROR, FaultFlags::MOTOR_DRIVER_ERROR),
        (fault::HEARTBEAT_LOST, FaultFlags::HEARTBEAT_LOST),
        (fault::OVER_TEMPERATURE, FaultFlags::OVER_TEMPERATURE),
        (fault::OVER_CURRENT, FaultFlags::OVER_CURRENT),
        (
            fault::BATTERY_UNDER_VOLTAGE,
            FaultFlags::BATTERY_UNDER_VOLTAGE,
        ),
        (fault::RC_LINK_LOST, FaultFlags::RC_LINK_LOST),
        (fault::MOTOR_1_COMM_LOST, FaultFlags::MOTOR_1_COMM_LOST),
        (fault::MOTOR_2_COMM_LOST, FaultFlags::MOTOR_2_COMM_LOST),
        (fault::MOTOR_3_COMM_LOST, FaultFlags::MOTOR_3_COMM_LOST),
        (fault::MOTOR_4_COMM_LOST, FaultFlags::MOTOR_4_COMM_LOST),
    ];
    MAP.iter()
        .filter(|(bit, _)| word & bit != 0)
        .fold(0, |acc, (_, flag)| acc | flag)
}

impl Driver for TitanDriver {
    fn robot(&self) -> Robot {
        Robot::Titan
    }

    fn handle_rx(&mut self, now: Timestamp, rx: Rx<'_>) {
        let Rx::Can(frame) = rx else {
            self.state.link.rx_decode_errors += 1;
            self.events.push_back(DriverEvent::RxDropped {
                reason: "serial bytes on a CAN robot's bus".into(),
            });
            return;
        };
        match codec::decode(frame, &self.profile) {
            Ok(decoded) => {
                self.link.received(now);
                self.state.link.rx_frames += 1;
                self.state.stamp_ns = now.as_nanos();
                if self.was_silent {
                    self.was_silent = false;
                    self.set_flag(LinkFlags::CHASSIS_SILENT, false);
                    self.notice(Level::Info, "chassis is talking again");
                }
                self.apply(now, decoded);
            }
            Err(err) => {
                match err {
                    crate::DecodeError::UnknownId { .. }
                    | crate::DecodeError::ExtendedId { .. } => self.state.link.rx_unknown_id += 1,
                    _ => self.state.link.rx_decode_errors += 1,
                }
                self.events.push_back(DriverEvent::RxDropped {
                    reason: format!("{frame}: {err}"),
                });
            }
        }
    }

    fn set_command(&mut self, now: Timestamp, command: &Twist) {
        self.plan(now, command);
    }

    fn control(&mut self, now: Timestamp, command: &Command) -> ControlOutcome {
        if self.bus_down {
            return ControlOutcome::Refused("the bus is down; nothing can be sent".into());
        }
        let planned = match command {
            Command::Velocity { .. } => {
                return ControlOutcome::Invalid(
                    "motion goes through the mux, not a control request".into(),
                );
            }
            _ => match frames_for(command, &self.profile) {
                Ok(planned) => planned,
                Err(err) => return err.into(),
            },
        };
        let t = now.as_nanos();
        let outcome = match *command {
            Command::Mode { take_control } => {
                self.want_control = take_control;
                ControlOutcome::Done(if take_control {
                    "CAN command mode requested".into()
                } else {
                    "standby requested; motion commands will be ignored".into()
                })
            }
            Command::Brake { engage } => {
                if engage && self.is_moving() {
                    return ControlOutcome::Refused(format!(
                        "robot is moving ({:.2} m/s): stop before engaging the parking brake",
                        self.state.motion.linear_mps
                    ));
                }
                self.brake_held = engage;
                self.brake = if engage {
                    Brake::Engaged
                } else {
                    Brake::Released
                };
                self.update_body(now);
                ControlOutcome::Done(if engage {
                    "parking brake engaged; motion waits until it is released".into()
                } else {
                    "parking brake released".into()
                })
            }
            Command::OffRoad { enter } => {
                if self.is_moving() {
                    return ControlOutcome::Refused(format!(
                        "off-road mode switches only while standing still (moving at {:.2} m/s)",
                        self.state.motion.linear_mps
                    ));
                }
                self.state.system.off_road = u8::from(enter);
                self.state.touch(Group::Body, t);
                ControlOutcome::Done(format!(
                    "off-road mode {}",
                    if enter { "on" } else { "off" }
                ))
            }
            Command::SteeringZero => {
                if self.is_moving() {
                    return ControlOutcome::Refused(
                        "steering zero is set only while standing still".into(),
                    );
                }
                if self.steering_zero.is_some() {
                    return ControlOutcome::Refused(
                        "a steering zero calibration is already waiting for its acknowledgement"
                            .into(),
                    );
                }
                let token = self.next_token();
                let deadline = now + Duration::from_millis(self.config.control_timeout_ms);
                self.steering_zero = Some((token, deadline));
                self.set_flag(LinkFlags::STEERING_ZERO_PENDING, true);
                ControlOutcome::Pending(token)
            }
            Command::Silent { enter } => {
                self.state.system.silent_mode = u8::from(enter);
                self.set_flag(LinkFlags::SILENT_MODE, enter);
                self.state.touch(Group::Body, t);
                ControlOutcome::Done(format!("silent mode {}", if enter { "on" } else { "off" }))
            }
            Command::ClearFaults { which } => ControlOutcome::Done(format!(
                "clear-fault {} sent",
                chassis_interfaces::FaultClear::name(which)
            )),
            _ => ControlOutcome::Done(format!("{} sent", command.name())),
        };
        self.queue.extend(planned.frames);
        outcome
    }

    fn handle_timeout(&mut self, now: Timestamp) {
        let silent = self.link.is_silent(now);
        if silent && !self.was_silent {
            self.was_silent = true;
            self.set_flag(LinkFlags::CHASSIS_SILENT, true);
            self.pose.reset();
            self.notice(
                Level::Warn,
                format!(
                    "chassis silent: no feedback for {} ms",
                    self.config.silence_timeout_ms
                ),
            );
        }
        if self.config.brake_idle_engage_ms > 0
            && self.brake == Brake::Released
            && !self.brake_held
            && self.idle_since.is_some_and(|since| {
                now.saturating_since(since)
                    >= Duration::from_millis(self.config.brake_idle_engage_ms)
            })
            && !self.bus_down
        {
            self.queue
                .push_back(Frame::ParkingBrake(ParkingBrake { engage: true }));
            self.brake = Brake::Engaged;
            self.update_body(now);
        }
        if let Some((token, deadline)) = self.steering_zero
            && now >= deadline
        {
            self.steering_zero = None;
            self.set_flag(LinkFlags::STEERING_ZERO_PENDING, false);
            self.events.push_back(DriverEvent::ControlDone {
                token,
                status: ControlStatus::TIMEOUT,
                message: format!(
                    "no steering zero acknowledgement (0x43A) within {} ms",
                    self.config.control_timeout_ms
                ),
            });
        }
    }

    fn poll_transmit(&mut self, now: Timestamp) -> Option<Transmit> {
        if self.bus_down {
            self.queue.clear();
            return None;
        }
        let frame = if let Some(frame) = self.queue.pop_front() {
            frame
        } else if self.schedule.is_due(now)
            && self.motion.linear_mps != 0.0
            && self.brake != Brake::Released
            && self.state.system.control_mode == ControlMode::COMMAND
        {
            // Release before motion: after power-up, a chassis reboot or an idle engagement the
            // brake goes first, then this same deadline sends the motion frame. Only in CAN
            // command mode: standby and RC authority ignore 0x131, and a release sent then would
            // be believed while the brake stays engaged. Until command mode is reported the
            // heartbeat carries the command alone (a braked chassis does not move on it).
            self.brake = Brake::Released;
            self.update_body(now);
            Frame::ParkingBrake(ParkingBrake { engage: false })
        } else if self.schedule.is_due(now) {
            self.schedule.sent(now);
            let echo = &mut self.state.command;
            echo.linear_mps = self.motion.linear_mps as f32;
            echo.steer_rad = self.motion.steer_rad as f32;
            echo.angular_radps =
                yaw_rate(self.motion.linear_mps, self.motion.steer_rad, &self.profile) as f32;
            echo.lateral_mps = 0.0;
            echo.clamp_flags = self.motion_clamp_flags;
            self.state.touch(Group::Command, now.as_nanos());
            Frame::MotionCommand(self.motion)
        } else {
            return None;
        };
        match frame.encode(&self.profile) {
            Ok(can) => {
                self.state.link.tx_frames += 1;
                Some(Transmit::Can(can))
            }
            Err(err) => {
                // Limits keep every planned value on the wire's range; this is a bug guard.
                self.state.link.tx_errors += 1;
                self.notice(
                    Level::Error,
                    format!("cannot encode {}: {err}", frame.name()),
                );
                None
            }
        }
    }

    fn poll_timeout(&self) -> Option<Timestamp> {
        if self.bus_down {
            return None;
        }
        let mut next = Some(self.schedule.deadline());
        if !self.was_silent {
            next = earliest(next, Some(self.link.deadline()));
        }
        if self.config.brake_idle_engage_ms > 0
            && self.brake == Brake::Released
            && !self.brake_held
            && let Some(since) = self.idle_since
        {
            next = earliest(
                next,
                Some(since + Duration::from_millis(self.config.brake_idle_engage_ms)),
            );
        }
        if let Some((_, deadline)) = self.steering_zero {
            next = earliest(next, Some(deadline));
        }
        next
    }

    fn poll_event(&mut self) -> Option<DriverEvent> {
        self.events.pop_front()
    }

    fn state(&self) -> &ChassisState {
        &self.state
    }

    fn set_bus_down(&mut self, now: Timestamp, down: bool) {
        if down == self.bus_down {
            return;
        }
        self.bus_down = down;
        self.set_flag(LinkFlags::BUS_DOWN, down);
        self.queue.clear();
        if down {
            self.notice(Level::Error, "bus down: nothing reaches the chassis");
        } else {
            self.state.link.bus_reconnects += 1;
            self.link.reset(now);
            self.schedule.restart(now);
            self.brake = Brake::Unknown;
            self.pose.reset();
            if self.want_control {
                self.request_mode(now);
            }
            self.notice(Level::Info, "bus back: taking control again");
        }
    }

    fn shutdown(&mut self, now: Timestamp) {
        self.plan(now, &Twist::ZERO);
        self.queue.clear();
        self.queue.push_back(Frame::MotionCommand(self.motion));
        self.queue
            .push_back(Frame::ParkingBrake(ParkingBrake { engage: true }));
        self.brake = Brake::Engaged;
        self.update_body(now);
    }
}
