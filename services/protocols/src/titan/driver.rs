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

use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
use std::time::Duration;

use chassis_interfaces::{
    ClampFlags, ControlMode, FaultFlags, Group, LinkFlags, SystemState, Velocity,
};

use super::codec::{self, Frame, MotionCommand, ParkingBrake, fault, mode};
use super::commands::{frames_for, motion_command};
use super::kinematics::yaw_rate;
use crate::agilex_driver::{self, BrakeKeeper, ModeKeeper, Next, SteeringZero};
use crate::command::Command;
use crate::driver::{
    ControlOutcome, Driver, DriverConfig, DriverCore, Level, PoseIntegrator, Rx, WireItem, flags_of,
};
use crate::kind::RobotKind;
use crate::time::{Timestamp, earliest};
use crate::titan::TitanProfile;

/// Speed below which the robot counts as standing still, m/s.
const STANDING_MPS: f64 = 0.01;
/// Least time between two 0x421 frames while the chassis keeps reporting standby.
const MODE_RETRY: Duration = Duration::from_millis(50);

/// The TITAN driver.
#[derive(Debug, Serialize, Deserialize)]
pub struct TitanDriver {
    profile: TitanProfile,
    core: DriverCore,
    /// Frames to send: empty between passes, the only time a snapshot is taken.
    #[serde(skip)]
    queue: VecDeque<Frame>,
    pose: PoseIntegrator,
    /// The motion the next 0x111 carries.
    motion: MotionCommand,
    motion_clamp_flags: u32,
    mode: ModeKeeper,
    /// TITAN does not report its brake: what the driver believes.
    brake: BrakeKeeper,
    steering_zero: SteeringZero,
    other_faults: u64,
}

impl TitanDriver {
    /// A driver starting at `now`. With `config.take_control` it asks for CAN command mode at once.
    pub fn new(profile: TitanProfile, config: DriverConfig, now: Timestamp) -> Self {
        let mut core = DriverCore::new(
            RobotKind::Titan.id(),
            Duration::from_millis(profile.heartbeat_period_ms),
            &config,
            now,
        );
        core.state.system.control_mode = ControlMode::UNKNOWN;
        let mut driver = Self {
            mode: ModeKeeper::new(config.take_control, MODE_RETRY),
            brake: BrakeKeeper::new(true, config.brake_idle_engage_ms, now),
            steering_zero: SteeringZero::new(config.control_timeout_ms),
            profile,
            core,
            queue: VecDeque::new(),
            pose: PoseIntegrator::default(),
            motion: MotionCommand::default(),
            motion_clamp_flags: 0,
            other_faults: 0,
        };
        if driver.mode.wants_control() {
            driver.request_mode(now);
        }
        driver
    }

    pub fn profile(&self) -> &TitanProfile {
        &self.profile
    }

    fn request_mode(&mut self, now: Timestamp) {
        self.queue.push_back(Frame::Mode(codec::ModeCommand {
            mode: mode::CAN_COMMAND,
        }));
        self.mode.requested(now);
    }

    fn is_moving(&self) -> bool {
        self.core.state.motion.linear_mps.abs() as f64 > STANDING_MPS
            || self.motion.linear_mps != 0.0
    }

    /// Recomputes the motion to send from the latest command.
    fn plan(&mut self, now: Timestamp, command: &Velocity) {
        let (mut motion, mut flags) = motion_command(command, &self.profile);
        if self.brake.held() && motion.linear_mps != 0.0 {
            motion = MotionCommand {
                linear_mps: 0.0,
                steer_rad: motion.steer_rad,
            };
            flags |= ClampFlags::CHASSIS_NOT_READY;
        }
        let moving = motion.linear_mps != 0.0;
        self.brake.planned(now, moving);
        self.core.schedule.update(&mut self.motion, motion, !moving);
        self.motion_clamp_flags = flags;
    }

    fn apply(&mut self, now: Timestamp, frame: Frame) {
        let t = now.as_nanos();
        match frame {
            Frame::SystemStatus(s) => self.apply_system(now, s),
            Frame::MotionFeedback(m) => {
                let w = yaw_rate(m.linear_mps, m.steer_rad, &self.profile);
                self.core.state.motion.linear_mps = m.linear_mps as f32;
                self.core.state.motion.steer_rad = m.steer_rad as f32;
                self.core.state.motion.angular_radps = w as f32;
                self.core.state.motion.lateral_mps = 0.0;
                self.core.state.touch(Group::Motion, t);
                self.pose
                    .update(now, m.linear_mps, 0.0, w, &mut self.core.state.odometry);
                self.core.state.touch(Group::Pose, t);
            }
            Frame::SteeringFeedback(s) => {
                self.core.state.motion.front_steer_rad = s.front_steer_rad as f32;
                self.core.state.motion.rear_steer_rad = s.rear_steer_rad as f32;
                self.core.state.touch(Group::Steering, t);
            }
            Frame::AxleSpeed(a) => {
                self.core.state.motion.front_axle_mps = a.front_axle_mps as f32;
                self.core.state.motion.rear_axle_mps = a.rear_axle_mps as f32;
                self.core.state.touch(Group::WheelSpeed, t);
            }
            Frame::Odometer(o) => {
                self.core.state.odometry.front_distance_m = o.front_distance_m;
                self.core.state.odometry.rear_distance_m = o.rear_distance_m;
                self.core.state.touch(Group::Odometry, t);
            }
            Frame::MotorFast(m) => agilex_driver::apply_motor_fast(&mut self.core.state, &m, t),
            Frame::MotorSlow(m) => {
                agilex_driver::apply_motor_slow(&mut self.core.state, &m, m.driver_status, t);
            }
            Frame::Rc(r) => agilex_driver::apply_rc(&mut self.core.state, &r, t),
            Frame::BmsData(b) => {
                agilex_driver::apply_bms_data(&mut self.core.state, &b, t);
                if b.group == 0 {
                    let low = b.soc_pct < self.profile.low_battery_warning_soc_pct;
                    agilex_driver::set_bits(&mut self.other_faults, FaultFlags::BATTERY_LOW, low);
                }
            }
            Frame::BmsAlarm(b) => {
                let any_alarm = agilex_driver::apply_bms_alarm(&mut self.core.state, &b, t);
                agilex_driver::set_bits(&mut self.other_faults, FaultFlags::BMS_ALARM, any_alarm);
            }
            Frame::SteeringZeroAck => {
                self.steering_zero.answered(&mut self.core, true);
                self.core.state.touch(Group::Body, t);
                self.core.notice(Level::Info, "steering zero position set");
            }
            // Commands on the bus from another node ([`Frame::direction`] `ToChassis`): not ours
            // to decode into state.
            _ => {}
        }
    }

    fn apply_system(&mut self, now: Timestamp, s: codec::SystemStatus) {
        let old_mode = self.core.state.system.control_mode;
        let new_mode = match s.mode {
            mode::STANDBY => ControlMode::STANDBY,
            mode::CAN_COMMAND => ControlMode::COMMAND,
            mode::REMOTE => ControlMode::REMOTE,
            _ => ControlMode::UNKNOWN,
        };
        let old_faults = self.core.state.system.fault_flags;
        let new_faults = normalize_faults(s.vendor_fault_word)
            | self.other_faults
            | if s.body_status == codec::body::EXCEPTION {
                FaultFlags::BODY_EXCEPTION
            } else {
                0
            };
        let sys = &mut self.core.state.system;
        sys.body_status = match s.body_status {
            codec::body::NORMAL => SystemState::BODY_NORMAL,
            _ => SystemState::BODY_EXCEPTION,
        };
        sys.battery_voltage_v = s.battery_voltage_v as f32;
        sys.vendor_fault_word = s.vendor_fault_word;
        self.core.system_status(now, new_mode, new_faults, true);
        agilex_driver::mode_changed(&mut self.core, old_mode, new_mode);
        if new_mode != old_mode
            && (new_mode == ControlMode::STANDBY || new_mode == ControlMode::REMOTE)
        {
            // After a reboot or an RC session the brake may be engaged again.
            self.brake.forget();
            self.brake.report(&mut self.core, now);
        }
        self.core
            .fault_notices(old_faults, new_faults, FaultFlags::WARNINGS);
        // Power-cycle recovery: a chassis in standby while we want control is asked again.
        if self
            .mode
            .ask_again(now, new_mode == ControlMode::STANDBY, self.core.bus_down)
        {
            self.request_mode(now);
        }
    }
}

/// The normalized `FaultFlags` of a 0x211 fault word.
pub fn normalize_faults(word: u32) -> u64 {
    use chassis_interfaces::FaultFlags as F;
    const MAP: [(u32, u64); 13] = [
        (fault::FRONT_STEERING_ENCODER, F::FRONT_STEERING_ENCODER),
        (fault::REAR_STEERING_ENCODER, F::REAR_STEERING_ENCODER),
        (fault::BUMPER, F::BUMPER),
        (fault::MOTOR_DRIVER_ERROR, F::MOTOR_DRIVER_ERROR),
        (fault::HEARTBEAT_LOST, F::HEARTBEAT_LOST),
        (fault::OVER_TEMPERATURE, F::OVER_TEMPERATURE),
        (fault::OVER_CURRENT, F::OVER_CURRENT),
        (fault::BATTERY_UNDER_VOLTAGE, F::BATTERY_UNDER_VOLTAGE),
        (fault::RC_LINK_LOST, F::RC_LINK_LOST),
        (fault::MOTOR_1_COMM_LOST, F::MOTOR_1_COMM_LOST),
        (fault::MOTOR_2_COMM_LOST, F::MOTOR_2_COMM_LOST),
        (fault::MOTOR_3_COMM_LOST, F::MOTOR_3_COMM_LOST),
        (fault::MOTOR_4_COMM_LOST, F::MOTOR_4_COMM_LOST),
    ];
    flags_of(word, &MAP)
}

impl Driver for TitanDriver {
    crate::snapshot::whole_driver!(queue);

    fn robot(&self) -> RobotKind {
        RobotKind::Titan
    }

    crate::driver::core_accessors!();

    fn handle_rx(&mut self, now: Timestamp, rx: Rx<'_>) {
        let profile = &self.profile;
        if let Some(frame) = self.core.can_rx(now, rx, |f| codec::decode(f, profile)) {
            self.apply(now, frame);
        }
    }

    fn set_command(&mut self, now: Timestamp, command: &Velocity) {
        self.plan(now, command);
    }

    fn control(&mut self, now: Timestamp, command: &Command) -> ControlOutcome {
        let planned = crate::driver::admit!(self.core, command, |c| frames_for(c, &self.profile));
        let t = now.as_nanos();
        let outcome = match *command {
            Command::Mode { take_control } => self.mode.command(take_control),
            Command::Brake { engage } => {
                if engage && self.is_moving() {
                    return ControlOutcome::Refused(format!(
                        "robot is moving ({:.2} m/s): stop before engaging the parking brake",
                        self.core.state.motion.linear_mps
                    ));
                }
                self.brake.set(engage, true);
                self.brake.report(&mut self.core, now);
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
                        self.core.state.motion.linear_mps
                    ));
                }
                self.core.state.system.off_road = u8::from(enter);
                self.core.state.touch(Group::Body, t);
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
                match self.steering_zero.start(&mut self.core, now) {
                    Ok(token) => ControlOutcome::Pending(token),
                    Err(refused) => return refused,
                }
            }
            Command::Silent { enter } => {
                self.core.state.system.silent_mode = u8::from(enter);
                self.core.set_flag(LinkFlags::SILENT_MODE, enter);
                self.core.state.touch(Group::Body, t);
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
        if self.core.check_silence(now, "feedback") {
            self.pose.reset();
        }
        if self.brake.idle_engage_due(now, self.core.bus_down) {
            self.queue
                .push_back(Frame::ParkingBrake(ParkingBrake { engage: true }));
            self.brake.report(&mut self.core, now);
        }
        self.steering_zero.expire(&mut self.core, now);
    }

    fn poll_transmit(&mut self, now: Timestamp) -> Option<WireItem> {
        let moving = self.motion.linear_mps != 0.0;
        let next = agilex_driver::next_frame(
            &mut self.core,
            &mut self.queue,
            &mut self.brake,
            moving,
            now,
        );
        let frame = match next? {
            Next::Queued(frame) => frame,
            // The brake is released only once command mode is reported; until then the
            // heartbeat carries the command alone (a braked chassis does not move on it).
            Next::ReleaseBrake => Frame::ParkingBrake(ParkingBrake { engage: false }),
            Next::Motion => {
                let echo = &mut self.core.state.command;
                echo.linear_mps = self.motion.linear_mps as f32;
                echo.steer_rad = self.motion.steer_rad as f32;
                echo.angular_radps =
                    yaw_rate(self.motion.linear_mps, self.motion.steer_rad, &self.profile) as f32;
                echo.lateral_mps = 0.0;
                echo.clamp_flags = self.motion_clamp_flags;
                self.core.state.touch(Group::Command, now.as_nanos());
                Frame::MotionCommand(self.motion)
            }
        };
        self.core
            .transmit(&frame, frame.encode(&self.profile), WireItem::Can)
    }

    fn poll_timeout(&self) -> Option<Timestamp> {
        let next = Some(self.core.poll_timeout()?);
        earliest(
            earliest(next, self.brake.deadline()),
            self.steering_zero.deadline(),
        )
    }

    fn set_bus_down(&mut self, now: Timestamp, down: bool) {
        if !self.core.set_bus_down(now, down) {
            return;
        }
        self.queue.clear();
        if !down {
            self.brake.forget();
            self.pose.reset();
            if self.mode.wants_control() {
                self.request_mode(now);
            }
            self.core
                .notice(Level::Info, "bus back: taking control again");
        }
    }

    fn shutdown(&mut self, now: Timestamp) {
        self.plan(now, &Velocity::ZERO);
        self.queue.clear();
        self.queue.push_back(Frame::MotionCommand(self.motion));
        self.queue
            .push_back(Frame::ParkingBrake(ParkingBrake { engage: true }));
        self.brake.engage();
        self.brake.report(&mut self.core, now);
    }
}
