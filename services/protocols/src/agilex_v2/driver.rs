//! The protocol-V2 driver: one state machine for the whole family, over the V2 codec and the
//! shared [`DriverCore`].
//!
//! * **Heartbeat**: 0x111 every `heartbeat_period_ms` (20 ms), always — explicit zeros when
//!   there is no command; a changed command goes out at once.
//! * **Control mode** (`PROTOCOLS-V2` §5, §8 item 4): 0x421 `01` at start, and again whenever
//!   0x211 b1 reads standby while we want control (a rebooted chassis, a heartbeat timeout, an
//!   RC hand-back), at most every [`V2Driver::MODE_RETRY`]. An RC transmitter holding authority
//!   is reported ([`LinkFlags::RC_AUTHORITY`]), never fought. After a reboot or an RC hand-back
//!   the driver follows the mux's current output, as the TITAN's does.
//! * **E-stop**: 0x211 b0 is reported as [`FaultFlags::EMERGENCY_STOP`]; the service holds
//!   zero while it lasts and, after its release, until the source that would win asks for zero
//!   (chassisd's mux: motion starts only from a zero) — the driver keeps no rule of its own.
//! * **Parking brake** (HUNTER 2.0): released once before motion in CAN command mode, engaged
//!   after an idle time and on shutdown. Robots without one never see 0x131.
//! * **RANGER motion mode**: 0x141 before the 0x111 that needs a different mode.
//! * **Lights**: 0x121 repeated every `light_refresh_ms` while overridden; handing back sends one
//!   `enabled = 0` frame.

use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
use std::time::Duration;

use chassis_interfaces::{ControlMode, FaultFlags, Group, SystemState, Velocity};

use super::codec::{self, Frame, Lights, ModeCommand, Motion, MotionMode, ParkingBrake, vehicle};
use super::commands::{STOP, frames_for};
use super::kinematics::{RangerMode, body_twist, plan};
use super::profile::{self, V2Profile};
use crate::agilex_driver::{self, BrakeKeeper, ModeKeeper, Next, SteeringZero};
use crate::command::{Command, Turn};
use crate::driver::{
    ControlOutcome, Driver, DriverConfig, DriverCore, Level, PoseIntegrator, Rx, WireItem,
};
use crate::kind::RobotKind;
use crate::time::{Timestamp, earliest};

/// The protocol-V2 driver.
#[derive(Debug, Serialize, Deserialize)]
pub struct V2Driver {
    profile: V2Profile,
    robot: RobotKind,
    core: DriverCore,
    /// Frames to send: empty between passes, the only time a snapshot is taken.
    #[serde(skip)]
    queue: VecDeque<Frame>,
    pose: PoseIntegrator,
    /// What the next 0x111 carries.
    motion: Motion,
    /// What the mux asked for.
    requested: Motion,
    requested_flags: u32,
    motion_clamp_flags: u32,
    /// RANGER: the mode last sent (or reported by 0x291).
    ranger_mode: Option<RangerMode>,
    /// RANGER: the mode the present command needs, and when 0x141 last asked for it.
    wanted_mode: Option<RangerMode>,
    last_mode_command: Option<Timestamp>,
    mode: ModeKeeper,
    /// What the driver believes about the parking brake (reported only by HUNTER 2.0, b6).
    brake: BrakeKeeper,
    lights: Option<(Lights, Timestamp)>,
    steering_zero: SteeringZero,
    other_faults: u64,
    /// ⚠ D-1: `None` until CAN mode is first reported; then when to fall back to 0x4A1.
    version: VersionQuery,
}

/// Where the version query stands (⚠ D-1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
enum VersionQuery {
    /// Not asked yet (asked once the chassis first reports CAN mode).
    NotAsked,
    /// 0x411 sent; 0x4A1 follows at this time if 0x41A has not answered (`both`).
    Asked { fallback: Option<Timestamp> },
    /// Answered, given up, or never to be asked.
    Done,
}

impl V2Driver {
    /// Least time between two 0x421 while the chassis keeps reporting standby (`PROTOCOLS-V2` §5).
    pub const MODE_RETRY: Duration = Duration::from_millis(500);
    /// Least time between two 0x141 while a RANGER keeps reporting another motion mode.
    pub const MOTION_MODE_RETRY: Duration = Duration::from_millis(100);

    /// A driver starting at `now`. With `config.take_control` it asks for CAN command mode at once.
    pub fn new(profile: V2Profile, config: DriverConfig, now: Timestamp) -> Self {
        let robot = profile.model.robot();
        let mut core = DriverCore::new(
            robot.id(),
            Duration::from_millis(profile.heartbeat_period_ms),
            &config,
            now,
        );
        core.state.system.control_mode = ControlMode::UNKNOWN;
        core.state.system.wire_protocol = chassis_interfaces::WireProtocol::V2;
        let mut driver = Self {
            mode: ModeKeeper::new(config.take_control, Self::MODE_RETRY),
            brake: BrakeKeeper::new(
                profile.brake_lock_value.is_some(),
                config.brake_idle_engage_ms,
                now,
            ),
            steering_zero: SteeringZero::new(config.control_timeout_ms),
            profile,
            robot,
            core,
            queue: VecDeque::new(),
            pose: PoseIntegrator::default(),
            motion: STOP,
            requested: STOP,
            requested_flags: 0,
            motion_clamp_flags: 0,
            ranger_mode: None,
            wanted_mode: None,
            last_mode_command: None,
            lights: None,
            other_faults: 0,
            version: VersionQuery::NotAsked,
        };
        if driver.profile.version_query == profile::VersionQuery::Never {
            driver.version = VersionQuery::Done;
        }
        if driver.mode.wants_control() {
            driver.request_mode(now);
        }
        driver
    }

    pub fn profile(&self) -> &V2Profile {
        &self.profile
    }

    fn request_mode(&mut self, now: Timestamp) {
        self.queue.push_back(Frame::Mode(ModeCommand { can: true }));
        self.mode.requested(now);
    }

    /// Recomputes what the heartbeat carries from the request.
    fn update_motion(&mut self, now: Timestamp) {
        let motion = self.requested;
        let flags = self.requested_flags;
        let moving = motion != STOP;
        self.brake.planned(now, moving);
        self.core.schedule.update(&mut self.motion, motion, !moving);
        self.motion_clamp_flags = flags;
    }

    fn plan(&mut self, now: Timestamp, command: &Velocity) {
        let planned = plan(
            command.linear_x_mps().into(),
            command.linear_y_mps().into(),
            Turn::of(command),
            &self.profile,
        );
        if let Some(mode) = planned.mode {
            self.wanted_mode = Some(mode);
            if self.ranger_mode != Some(mode) {
                self.send_motion_mode(now, mode);
            }
        }
        self.requested = planned.motion;
        self.requested_flags = planned.clamp_flags;
        self.update_motion(now);
    }

    /// RANGER: 0x141 for `mode`, ahead of the next 0x111.
    fn send_motion_mode(&mut self, now: Timestamp, mode: RangerMode) {
        if let Some(code) = mode.code(&self.profile) {
            self.queue.push_back(Frame::MotionModeCommand(MotionMode {
                mode: code,
                changing: false,
            }));
            self.ranger_mode = Some(mode);
            self.last_mode_command = Some(now);
        }
    }

    /// RANGER: a chassis reporting another mode than the command needs (it rebooted into its
    /// default mode, or the RC changed it) is asked again, at most every
    /// [`V2Driver::MOTION_MODE_RETRY`], once it obeys (CAN command mode).
    fn keep_motion_mode(&mut self, now: Timestamp, reported: Option<RangerMode>) {
        if let Some(wanted) = self.wanted_mode
            && reported != Some(wanted)
            && self.core.state.system.control_mode == ControlMode::COMMAND
            && self
                .last_mode_command
                .is_none_or(|t| now.saturating_since(t) >= Self::MOTION_MODE_RETRY)
        {
            self.send_motion_mode(now, wanted);
        }
    }

    fn apply(&mut self, now: Timestamp, frame: Frame) {
        let t = now.as_nanos();
        match frame {
            Frame::SystemStatus(s) => self.apply_system(now, s),
            Frame::MotionFeedback(m) => {
                let (vx, vy, w) = body_twist(&m, self.ranger_mode, &self.profile);
                let motion = &mut self.core.state.motion;
                motion.linear_mps = vx as f32;
                motion.lateral_mps = vy as f32;
                motion.angular_radps = w as f32;
                motion.steer_rad = m.steer_rad as f32;
                self.core.state.touch(Group::Motion, t);
                self.pose
                    .update(now, vx, vy, w, &mut self.core.state.odometry);
                self.core.state.touch(Group::Pose, t);
            }
            Frame::SteeringAngles(a) => {
                self.core.state.motion.front_steer_rad = a.values[0] as f32;
                self.core.state.motion.rear_steer_rad = a.values[2] as f32;
                self.core.state.touch(Group::Steering, t);
            }
            Frame::WheelSpeeds(s) => {
                let motion = &mut self.core.state.motion;
                motion.wheel_mps = s.values.map(|v| v as f32);
                motion.front_axle_mps = ((s.values[0] + s.values[1]) / 2.0) as f32;
                motion.rear_axle_mps = ((s.values[2] + s.values[3]) / 2.0) as f32;
                self.core.state.touch(Group::WheelSpeed, t);
            }
            Frame::MotionModeState(m) if !m.changing => {
                let reported = RangerMode::from_code(m.mode, &self.profile);
                self.ranger_mode = reported;
                self.keep_motion_mode(now, reported);
            }
            Frame::Odometer(o) => {
                let odometry = &mut self.core.state.odometry;
                odometry.left_distance_m = o.left_m;
                odometry.right_distance_m = o.right_m;
                self.core.state.touch(Group::Odometry, t);
            }
            Frame::MotorFast(m) => agilex_driver::apply_motor_fast(&mut self.core.state, &m, t),
            Frame::MotorSlow(m) => {
                let status = normalize_driver_status(m.driver_status, &self.profile);
                agilex_driver::apply_motor_slow(&mut self.core.state, &m, status, t);
            }
            Frame::Rc(r) => agilex_driver::apply_rc(&mut self.core.state, &r, t),
            Frame::LightState(l) => {
                let lights = &mut self.core.state.lights;
                lights.control_enabled = u8::from(l.enabled);
                lights.front_mode = l.front_mode;
                lights.front_brightness_pct = l.front_brightness_pct;
                self.core.state.touch(Group::Lights, t);
            }
            Frame::BmsData(b) => agilex_driver::apply_bms_data(&mut self.core.state, &b, t),
            Frame::BmsAlarm(b) => {
                let any_alarm = agilex_driver::apply_bms_alarm(&mut self.core.state, &b, t);
                agilex_driver::set_bits(&mut self.other_faults, FaultFlags::BMS_ALARM, any_alarm);
            }
            // ⚠ D-6, the older layout: a protection bit is an alarm; its codes are not alarm
            // and warning bytes, so `BmsState::alarm_flags` is left alone.
            Frame::BmsProtection(p) => agilex_driver::set_bits(
                &mut self.other_faults,
                FaultFlags::BMS_ALARM,
                !p.names(true).is_empty(),
            ),
            Frame::VersionText(t) => self.core.notice(
                Level::Info,
                format!("chassis version text: {}", t.text().trim_end()),
            ),
            Frame::Version(v) => {
                self.version = VersionQuery::Done;
                let [ch, cs, dh, ds] = [v.controller_hw, v.controller_sw, v.driver_hw, v.driver_sw]
                    .map(|[major, minor]| format!("{major}.{minor}"));
                self.core.notice(
                    Level::Info,
                    format!("chassis versions: controller hw {ch} sw {cs}, driver hw {dh} sw {ds}"),
                );
            }
            Frame::SteeringZeroAck { done } => {
                self.steering_zero.answered(&mut self.core, done);
                self.core.state.touch(Group::Body, t);
            }
            // Commands from another node, and sensors without a place in the state.
            _ => {}
        }
    }

    fn apply_system(&mut self, now: Timestamp, s: codec::SystemStatus) {
        let old_mode = self.core.state.system.control_mode;
        let new_mode = match s.control {
            "can" => ControlMode::COMMAND,
            "rc" => ControlMode::REMOTE,
            "standby" => ControlMode::STANDBY,
            "uart" => ControlMode::SERIAL,
            _ => ControlMode::UNKNOWN,
        };
        let old_faults = self.core.state.system.fault_flags;
        let new_faults = normalize_faults(s.fault_word, &self.profile)
            | vehicle_state_flags(s.vehicle_state)
            | self.other_faults;
        let sys = &mut self.core.state.system;
        sys.body_status = body_status(s.vehicle_state);
        sys.battery_voltage_v = s.battery_voltage_v as f32;
        sys.vendor_fault_word = s.fault_word.into();
        if self.profile.reports_brake_in_b6() {
            // HUNTER 2.0 reports its brake in b6.
            sys.parking_brake_engaged = u8::from(s.b6 == 0x01);
        }
        self.core.system_status(now, new_mode, new_faults, true);
        if new_mode == ControlMode::COMMAND {
            if self.version == VersionQuery::NotAsked {
                self.ask_version(now);
            }
            // The retry limit is for a chassis that keeps reporting standby: a standby after CAN
            // mode (a reboot, a hand-back) is answered at once.
            self.mode.obeyed();
        }
        if new_mode == ControlMode::COMMAND
            && old_mode != ControlMode::COMMAND
            && let Some(wanted) = self.wanted_mode
        {
            // Back from standby (a reboot, a heartbeat timeout) or an RC session: the chassis
            // may be in another motion mode than the one last sent.
            self.send_motion_mode(now, wanted);
        }
        agilex_driver::mode_changed(&mut self.core, old_mode, new_mode);
        if new_mode != old_mode && new_mode != ControlMode::COMMAND && self.brake.fitted() {
            self.brake.forget();
            self.brake.report(&mut self.core, now);
        }
        self.core
            .fault_notices(old_faults, new_faults, FaultFlags::WARNINGS);
        // ⚠ D-22: where the firmware has no standby code, "RC" (0x00) also means "not ours".
        let not_ours = new_mode == ControlMode::STANDBY
            || (self.profile.mode_codes.standby.is_none() && new_mode == ControlMode::REMOTE);
        if self.mode.ask_again(now, not_ours, self.core.bus_down) {
            self.request_mode(now);
        }
    }

    /// ⚠ D-1: 0x411 (manual) or 0x4A1 (SDK); with `both`, 0x4A1 a second later if 0x41A is
    /// silent. An answer is logged; silence is normal.
    fn ask_version(&mut self, now: Timestamp) {
        self.version = match self.profile.version_query {
            profile::VersionQuery::Never => VersionQuery::Done,
            profile::VersionQuery::Sdk => {
                self.queue.push_back(Frame::SdkVersionRequest);
                VersionQuery::Done
            }
            profile::VersionQuery::Manual => {
                self.queue.push_back(Frame::VersionRequest);
                VersionQuery::Asked { fallback: None }
            }
            profile::VersionQuery::Both => {
                self.queue.push_back(Frame::VersionRequest);
                VersionQuery::Asked {
                    fallback: Some(now + Duration::from_secs(1)),
                }
            }
        };
    }
}

/// The normalized `FaultFlags` of 0x211 b4-5 under the profile's ⚠ D-3 table (and ⚠ D-20 for
/// b5 bit7). Bits the table does not name raise nothing; they stay in the vendor's word.
pub fn normalize_faults(word: u16, profile: &V2Profile) -> u64 {
    profile
        .fault_bits()
        .filter(|b| word & b.mask != 0)
        .fold(0, |flags, b| flags | b.flag)
}

/// The normalized `FaultFlags` of 0x211 b0: E-stop (0x01), exception (0x02 and anything else
/// not normal). The V1 manual gives the SCOUT MINI's 0x151 b0 the same values.
pub fn vehicle_state_flags(vehicle_state: u8) -> u64 {
    match vehicle_state {
        vehicle::NORMAL => 0,
        vehicle::ESTOP => FaultFlags::EMERGENCY_STOP,
        _ => FaultFlags::BODY_EXCEPTION,
    }
}

/// `SystemState::body_status` of 0x211 b0 (and of 0x151 b0, as [`vehicle_state_flags`]).
pub(crate) fn body_status(vehicle_state: u8) -> u8 {
    match vehicle_state {
        vehicle::NORMAL => SystemState::BODY_NORMAL,
        vehicle::ESTOP => SystemState::BODY_EMERGENCY_STOP,
        _ => SystemState::BODY_EXCEPTION,
    }
}

/// `chassis_interfaces::DriverStatus` bits of 0x26x b5: bit 6 "enabled" per ⚠ D-7.
pub fn normalize_driver_status(status: u8, profile: &V2Profile) -> u8 {
    if profile.driver_bit6_means_enabled {
        status
    } else {
        status ^ (1 << 6)
    }
}

impl Driver for V2Driver {
    crate::snapshot::whole_driver!(queue);

    fn robot(&self) -> RobotKind {
        self.robot
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
        let outcome = match *command {
            Command::Mode { take_control } => self.mode.command(take_control),
            Command::Brake { engage } => {
                self.brake.set(engage, false);
                self.brake.report(&mut self.core, now);
                ControlOutcome::Done(format!(
                    "parking brake {}",
                    if engage { "engaged" } else { "released" }
                ))
            }
            Command::Lights { enable, .. } => {
                self.lights = match planned.frames.first() {
                    Some(Frame::LightCommand(l)) if enable => Some((
                        *l,
                        now + Duration::from_millis(self.profile.light_refresh_ms),
                    )),
                    _ => None,
                };
                ControlOutcome::Done(if enable {
                    "light control taken".into()
                } else {
                    "lights handed back to the chassis".into()
                })
            }
            Command::SteeringZero => match self.steering_zero.start(&mut self.core, now) {
                Ok(token) => ControlOutcome::Pending(token),
                Err(refused) => return refused,
            },
            _ => ControlOutcome::Done(format!("{} sent", command.name())),
        };
        self.queue.extend(planned.frames);
        outcome
    }

    fn handle_timeout(&mut self, now: Timestamp) {
        if self.core.check_silence(now, "feedback") {
            self.pose.reset();
        }
        if let VersionQuery::Asked {
            fallback: Some(due),
        } = self.version
            && now >= due
        {
            self.queue.push_back(Frame::SdkVersionRequest);
            self.version = VersionQuery::Done;
        }
        if let Some((lights, due)) = self.lights
            && now >= due
            && !self.core.bus_down
        {
            self.queue.push_back(Frame::LightCommand(lights));
            self.lights = Some((
                lights,
                now + Duration::from_millis(self.profile.light_refresh_ms),
            ));
        }
        if self.brake.idle_engage_due(now, self.core.bus_down) {
            self.queue
                .push_back(Frame::ParkingBrake(ParkingBrake { engage: true }));
            self.brake.report(&mut self.core, now);
        }
        self.steering_zero.expire(&mut self.core, now);
    }

    fn poll_transmit(&mut self, now: Timestamp) -> Option<WireItem> {
        let moving = self.motion != STOP;
        let next = agilex_driver::next_frame(
            &mut self.core,
            &mut self.queue,
            &mut self.brake,
            moving,
            now,
        );
        let frame = match next? {
            Next::Queued(frame) => frame,
            // HUNTER 2.0 ignores speed while braked.
            Next::ReleaseBrake => Frame::ParkingBrake(ParkingBrake { engage: false }),
            Next::Motion => {
                let (vx, vy, w) = body_twist(&self.motion, self.ranger_mode, &self.profile);
                let echo = &mut self.core.state.command;
                echo.linear_mps = vx as f32;
                echo.lateral_mps = vy as f32;
                echo.angular_radps = w as f32;
                echo.steer_rad = self.motion.steer_rad as f32;
                echo.clamp_flags = self.motion_clamp_flags;
                self.core.state.touch(Group::Command, now.as_nanos());
                Frame::MotionCommand(self.motion)
            }
        };
        self.core
            .transmit(&frame, frame.encode(&self.profile), WireItem::Can)
    }

    fn poll_timeout(&self) -> Option<Timestamp> {
        let mut next = Some(self.core.poll_timeout()?);
        if let Some((_, due)) = self.lights {
            next = earliest(next, Some(due));
        }
        if let VersionQuery::Asked {
            fallback: Some(due),
        } = self.version
        {
            next = earliest(next, Some(due));
        }
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
            self.ranger_mode = None;
            self.pose.reset();
            if self.mode.wants_control() {
                self.request_mode(now);
            }
            self.core
                .notice(Level::Info, "bus back: taking control again");
        }
    }

    fn shutdown(&mut self, now: Timestamp) {
        self.requested = STOP;
        self.update_motion(now);
        self.queue.clear();
        self.queue.push_back(Frame::MotionCommand(STOP));
        if self.brake.engage() {
            self.queue
                .push_back(Frame::ParkingBrake(ParkingBrake { engage: true }));
            self.brake.report(&mut self.core, now);
        }
        if self.lights.take().is_some() {
            self.queue.push_back(Frame::LightCommand(Lights::default()));
        }
    }
}
