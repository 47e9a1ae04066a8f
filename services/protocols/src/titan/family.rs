//! The TITAN family behind [`Family`]: its driver, firmware, frame describer and its part of
//! the robot's description.

use chassis_interfaces::{
    BatteryLevels, DescriptionFlags, FaultFlags, MotionLimits, RobotDescription, WireProtocol,
};

use crate::CanFrame;
use crate::command::{Command, CommandError};
use crate::error::DecodeError;
use crate::family::{Family, Profile, both_ways, family_parts, millis};
use crate::frame_json::{
    BoxedCodec, Codec, FrameJson, driver_status_names, frame_json, insert_bms_alarms,
    insert_faults, insert_switches,
};
use crate::kind::RobotKind;
use crate::profile::{ProfileError, ProfileTableError, positive, timeouts, with_overrides};

use super::{Frame, TitanDriver, TitanProfile, TitanSim, body, decode, frames_for, kinematics};

impl Family for TitanProfile {
    fn robot(&self) -> RobotKind {
        RobotKind::Titan
    }

    /// Checks the values make a drivable robot.
    fn validate(&self) -> Result<(), ProfileError> {
        positive("wheelbase_m", self.wheelbase_m)?;
        positive("track_m", self.track_m)?;
        positive("max_linear_mps", self.max_linear_mps)?;
        positive("max_linear_steering_mps", self.max_linear_steering_mps)?;
        positive("max_steer_rad", self.max_steer_rad)?;
        if self.max_steer_rad >= std::f64::consts::FRAC_PI_2 {
            return Err(ProfileError::SteerBeyondRightAngle);
        }
        if self.steer_speed_limit_above_rad.is_nan() || self.steer_speed_limit_above_rad < 0.0 {
            return Err(ProfileError::NegativeSteerSpeedLimit);
        }
        timeouts(self.heartbeat_period_ms, self.command_timeout_ms)
    }

    fn with_table(&self, table: &toml::Table) -> Result<Profile, ProfileTableError> {
        Ok(with_overrides(self, table)?.into())
    }

    /// Standby (0x421 `00`): the chassis obeys no motion frame until CAN command mode is asked again.
    fn drive_cut(&self, cut: bool) -> Option<Command> {
        Some(Command::Mode { take_control: !cut })
    }

    family_parts!(TitanDriver, TitanSim, heartbeat_period_ms);

    fn codec(&self) -> BoxedCodec {
        Box::new(TitanCodec(self.clone()))
    }

    fn describe(&self, d: &mut RobotDescription) {
        d.protocol = WireProtocol::OWN;
        d.set_model("titan");
        d.robot_limits = MotionLimits {
            steer_rad: self.max_steer_rad,
            ..both_ways(self.max_linear_mps, 0.0, f64::NAN)
        };
        d.geometry.wheelbase_m = self.wheelbase_m;
        d.geometry.track_m = self.track_m;
        // Both axles steer: the turn centre lies on the line half way between them, and the
        // body's centre runs half a track outside the inner wheels.
        d.geometry.min_turn_radius_m = kinematics::min_turn_radius_m(self);
        d.battery = BatteryLevels {
            // The TITAN manual: charge when the remote shows less than 15 % or the tail display
            // less than 45 V; below 10 % the chassis cuts drive power.
            low_v: 45.0,
            low_soc_pct: self.low_battery_warning_soc_pct,
            critical_soc_pct: self.low_battery_cutoff_soc_pct,
            ..d.battery
        };
        d.command_timeout_ms = millis(self.command_timeout_ms);
        d.flags |= DescriptionFlags::LIGHTS;
    }

    fn command_lines(&self, command: &Command) -> Result<(Vec<String>, u32), CommandError> {
        frames_for(command, self)?.lines(|f, _| f.encode(self).map(|c| c.to_candump()))
    }
}

/// The TITAN's frames as JSON, with its fault word, driver status, BMS alarms and RC levers by
/// name.
#[derive(Debug)]
struct TitanCodec(TitanProfile);

impl Codec for TitanCodec {
    fn robot(&self) -> RobotKind {
        RobotKind::Titan
    }

    fn decode_can(&self, frame: &CanFrame) -> Result<FrameJson, DecodeError> {
        let decoded = decode(frame, &self.0)?;
        let mut json = frame_json(
            RobotKind::Titan,
            (decoded.id().into(), 3),
            decoded.direction(),
            None,
            &decoded,
        );
        match &decoded {
            Frame::SystemStatus(s) => {
                let body = if s.body_status == body::EXCEPTION {
                    FaultFlags::BODY_EXCEPTION
                } else {
                    0
                };
                insert_faults(
                    &mut json,
                    super::normalize_faults(s.vendor_fault_word) | body,
                );
            }
            Frame::MotorSlow(m) => {
                json.insert(
                    "driver_status_flags".into(),
                    driver_status_names(m.driver_status).into(),
                );
            }
            Frame::BmsAlarm(b) => insert_bms_alarms(&mut json, b),
            Frame::Rc(r) => insert_switches(&mut json, r),
            _ => {}
        }
        Ok(json)
    }
}
