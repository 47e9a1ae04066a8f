//! The AgileX V2 family behind [`Family`]: its driver (listening for V1 or V2 first where the
//! robot may speak either), firmware, frame describer and its part of the robot's description.

use chassis_interfaces::{
    DescriptionFlags, DriverStatus, Kinematics as KinematicsId, LightMode, MotionLimits,
    RobotDescription, WireProtocol,
};

use crate::can::CanFrame;
use crate::command::{Command, CommandError};
use crate::error::DecodeError;
use crate::family::{Family, Profile, both_ways, family_parts, kebab, millis};
use crate::frame_json::{
    BoxedCodec, Codec, FrameJson, driver_status_names, frame_json, insert_bms_alarms,
    insert_faults, insert_switches,
};
use crate::kind::RobotKind;
use crate::profile::{
    ProfileError, ProfileTableError, Protocol, detection, positive, timeouts,
    with_model_and_overrides,
};

use super::{
    Frame, Kinematics, V2Driver, V2Model, V2Profile, V2Sim, decode, frames_for, motion_mode_name,
    normalize_driver_status, normalize_faults, vehicle_state_flags,
};

impl Family for V2Profile {
    fn robot(&self) -> RobotKind {
        self.model.robot()
    }

    fn protocol(&self) -> Option<Protocol> {
        Some(Protocol::V2)
    }

    /// Checks the values make a drivable robot.
    fn validate(&self) -> Result<(), ProfileError> {
        positive("wheelbase_m", self.wheelbase_m)?;
        positive("track_m", self.track_m)?;
        positive("max_linear_mps", self.max_linear_mps)?;
        positive("bms_voltage_lsb_v", self.bms_voltage_lsb_v)?;
        positive("odometer_lsb_m", self.odometer_lsb_m)?;
        match self.kinematics {
            Kinematics::Differential | Kinematics::Omni => {
                positive("max_angular_radps", self.max_angular_radps)?;
            }
            Kinematics::Ackermann => positive("max_steer_rad", self.max_steer_rad)?,
            Kinematics::FourWheelSteer => {
                positive("max_angular_radps", self.max_angular_radps)?;
                positive("max_steer_rad", self.max_steer_rad)?;
                positive("max_crab_rad", self.max_crab_rad)?;
                positive("spin_radius_m", self.spin_radius_m)?;
            }
        }
        if self.kinematics == Kinematics::Omni {
            positive("max_lateral_mps", self.max_lateral_mps)?;
        }
        if self.max_steer_rad >= std::f64::consts::FRAC_PI_2 {
            return Err(ProfileError::SteerBeyondRightAngle);
        }
        if !(1..=8).contains(&self.actuators) {
            return Err(ProfileError::NotPositive {
                name: "actuators (1-8)",
                value: self.actuators.into(),
            });
        }
        if self.short_commands_dlc != 1 && self.short_commands_dlc != 8 {
            return Err(ProfileError::NotPositive {
                name: "short_commands_dlc (1 or 8)",
                value: self.short_commands_dlc.into(),
            });
        }
        timeouts(self.heartbeat_period_ms, self.command_timeout_ms)?;
        detection(self.detect_timeout_ms, self.detect_min_frames)
    }

    fn with_table(&self, table: &toml::Table) -> Result<Profile, ProfileTableError> {
        Ok(with_model_and_overrides(self, table, V2Profile::for_model)?.into())
    }

    /// Standby (0x421 `00`): the chassis obeys no motion frame until CAN command mode is asked again.
    fn drive_cut(&self, cut: bool) -> Option<Command> {
        Some(Command::Mode { take_control: !cut })
    }

    family_parts!(V2Driver, V2Sim, heartbeat_period_ms);

    fn codec(&self) -> BoxedCodec {
        Box::new(V2Codec(self.clone()))
    }

    fn describe(&self, d: &mut RobotDescription) {
        let p = self;
        d.protocol = WireProtocol::V2;
        d.set_model(&kebab(&p.model));
        if p.model == V2Model::ScoutMiniOmni || p.kinematics == Kinematics::Omni {
            d.kinematics = KinematicsId::OMNI;
        }
        let steers = matches!(
            p.kinematics,
            Kinematics::Ackermann | Kinematics::FourWheelSteer
        );
        d.robot_limits = MotionLimits {
            steer_rad: if steers { p.max_steer_rad } else { f64::NAN },
            ..both_ways(p.max_linear_mps, p.max_lateral_mps, p.max_angular_radps)
        };
        d.geometry.wheelbase_m = p.wheelbase_m;
        d.geometry.track_m = p.track_m;
        d.geometry.min_turn_radius_m = match p.kinematics {
            // The front inner wheel at full lock; the body's centre runs half a track outside
            // it (the driver's R = L / tan δᵢ + W/2).
            Kinematics::Ackermann => p.wheelbase_m / p.max_steer_rad.tan() + p.track_m / 2.0,
            // Four-wheel steering drives dual Ackermann down to this radius and spins on the
            // spot below it.
            Kinematics::FourWheelSteer => p.min_turn_radius_m,
            Kinematics::Differential | Kinematics::Omni => 0.0,
        };
        d.battery.low_v = p.under_voltage_alarm_v;
        d.battery.critical_v = p.under_voltage_failure_v;
        d.command_timeout_ms = millis(p.command_timeout_ms);
        if p.brake_lock_value.is_some() {
            d.flags |= DescriptionFlags::BRAKE;
        }
        if p.front_light || p.rear_light {
            d.flags |= DescriptionFlags::LIGHTS;
        }
    }

    fn command_lines(&self, command: &Command) -> Result<(Vec<String>, u32), CommandError> {
        frames_for(command, self)?.lines(|f, _| f.encode(self).map(|c| c.to_candump()))
    }
}

/// The V2 frames as JSON, named under the robot's profile.
#[derive(Debug)]
struct V2Codec(V2Profile);

impl Codec for V2Codec {
    fn robot(&self) -> RobotKind {
        self.0.model.robot()
    }

    fn decode_can(&self, frame: &CanFrame) -> Result<FrameJson, DecodeError> {
        let decoded = decode(frame, &self.0)?;
        let mut json = frame_json(
            self.0.model.robot(),
            (decoded.id().into(), 3),
            decoded.direction(),
            None,
            &decoded,
        );
        json.insert("protocol".into(), "v2".into());
        name_v2_fields(&mut json, &decoded, &self.0);
        Ok(json)
    }
}

/// Names beside the codes of a protocol-V2 frame, read under the robot's profile: 0x211's
/// vehicle state (in the frame already), its fault bits by the names of the robot's ⚠ D-3 table
/// (`fault_bits`) and as normalized flags (`faults`, `warnings`, with the E-stop or exception of
/// b0), HUNTER 2.0's brake in b6; the driver status bits after ⚠ D-7; the BMS alarms (⚠ D-6); the
/// RANGER motion mode (⚠ D-12); light modes; RC lever positions.
fn name_v2_fields(json: &mut FrameJson, frame: &Frame, profile: &V2Profile) {
    match frame {
        Frame::SystemStatus(s) => {
            json.insert(
                "fault_bits".into(),
                profile.fault_names(s.fault_word).into(),
            );
            insert_faults(
                json,
                normalize_faults(s.fault_word, profile) | vehicle_state_flags(s.vehicle_state),
            );
            if profile.reports_brake_in_b6() {
                json.insert("parking_brake_engaged".into(), (s.b6 == 0x01).into());
            }
        }
        Frame::MotorSlow(m) => {
            let status = normalize_driver_status(m.driver_status, profile);
            json.insert(
                "driver_status_flags".into(),
                driver_status_names(status).into(),
            );
            json.insert(
                "driver_enabled".into(),
                (status & DriverStatus::ENABLED != 0).into(),
            );
        }
        Frame::BmsAlarm(b) => insert_bms_alarms(json, b),
        Frame::BmsProtection(p) => {
            json.insert("protections".into(), p.names(true).into());
            json.insert("states".into(), p.names(false).into());
        }
        Frame::MotionModeState(m) | Frame::MotionModeCommand(m) => {
            json.insert(
                "motion_mode".into(),
                motion_mode_name(m.mode, profile).into(),
            );
        }
        Frame::LightState(l) | Frame::LightCommand(l) => {
            json.insert("front_light".into(), LightMode::name(l.front_mode).into());
            if profile.rear_light {
                json.insert("rear_light".into(), LightMode::name(l.rear_mode).into());
            }
        }
        Frame::Rc(r) => insert_switches(json, r),
        Frame::VersionText(t) => {
            json.insert("text".into(), t.text().into());
        }
        _ => {}
    }
}
