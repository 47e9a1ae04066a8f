//! The AgileX V1 family behind [`Family`]: its driver (listening for V1 or V2 first where the
//! robot may speak either), firmware, frame describer and its part of the robot's description.

use chassis_interfaces::{DescriptionFlags, RobotDescription, WireProtocol};

use crate::agilex_v2::vehicle_state_flags;
use crate::can::CanFrame;
use crate::command::{Command, CommandError};
use crate::error::DecodeError;
use crate::family::{Family, Profile, both_ways, family_parts, kebab, millis};
use crate::frame_json::{BoxedCodec, Codec, FrameJson, frame_json, insert_faults};
use crate::kind::RobotKind;
use crate::profile::{
    ProfileError, ProfileTableError, Protocol, detection, positive, timeouts,
    with_model_and_overrides,
};

use super::{Frame, V1Driver, V1Profile, V1Sim, decode, frames_for, normalize_faults};

impl Family for V1Profile {
    fn robot(&self) -> RobotKind {
        self.model.robot()
    }

    fn protocol(&self) -> Option<Protocol> {
        Some(Protocol::V1)
    }

    /// Checks the values make a drivable robot (a zero full scale would make every command
    /// unencodable).
    fn validate(&self) -> Result<(), ProfileError> {
        positive("wheelbase_m", self.wheelbase_m)?;
        positive("track_m", self.track_m)?;
        positive("linear_full_scale_mps", self.linear_full_scale_mps)?;
        positive("angular_full_scale_rad_s", self.angular_full_scale_rad_s)?;
        positive("max_linear_mps", self.max_linear_mps)?;
        positive("max_angular_rad_s", self.max_angular_rad_s)?;
        detection(self.detect_timeout_ms, self.detect_min_frames)?;
        timeouts(self.heartbeat_period_ms, self.command_timeout_ms)
    }

    fn with_table(&self, table: &toml::Table) -> Result<Profile, ProfileTableError> {
        Ok(with_model_and_overrides(self, table, V1Profile::for_model)?.into())
    }

    family_parts!(V1Driver, V1Sim, heartbeat_period_ms);

    fn codec(&self) -> BoxedCodec {
        Box::new(V1Codec(self.clone()))
    }

    fn describe(&self, d: &mut RobotDescription) {
        d.protocol = WireProtocol::V1;
        d.set_model(&kebab(&self.model));
        d.robot_limits = both_ways(self.max_linear_mps, 0.0, self.max_angular_rad_s);
        d.geometry.wheelbase_m = self.wheelbase_m;
        d.geometry.track_m = self.track_m;
        d.geometry.min_turn_radius_m = 0.0;
        d.battery.low_v = self.under_voltage_alarm_v;
        d.battery.critical_v = self.under_voltage_failure_v;
        d.battery.full_v = self.battery_full_v;
        d.command_timeout_ms = millis(self.command_timeout_ms);
        d.flags |= DescriptionFlags::LIGHTS;
    }

    fn command_lines(&self, command: &Command) -> Result<(Vec<String>, u32), CommandError> {
        frames_for(command, self)?.lines(|f, count| f.encode(count, self).map(|c| c.to_candump()))
    }
}

/// The V1 frames as JSON, with the count and the fault word by name.
#[derive(Debug)]
struct V1Codec(V1Profile);

impl Codec for V1Codec {
    fn robot(&self) -> RobotKind {
        self.0.model.robot()
    }

    fn decode_can(&self, frame: &CanFrame) -> Result<FrameJson, DecodeError> {
        let decoded = decode(frame, &self.0)?;
        let mut json = frame_json(
            self.0.model.robot(),
            (decoded.frame.id().into(), 3),
            decoded.frame.direction(),
            Some(decoded.count),
            &decoded.frame,
        );
        if let Frame::SystemStatus(s) = &decoded.frame {
            insert_faults(
                &mut json,
                normalize_faults(s.vendor_fault_word) | vehicle_state_flags(s.body_status),
            );
        }
        Ok(json)
    }
}
