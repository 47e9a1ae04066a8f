//! The loopback family behind [`Family`]: its driver, firmware, frame describer and its part of
//! the robot's description.

use chassis_interfaces::{RobotDescription, WireProtocol};

use crate::CanFrame;
use crate::command::{Command, CommandError};
use crate::error::DecodeError;
use crate::family::{Family, Profile, both_ways, family_parts, millis};
use crate::frame_json::{BoxedCodec, Codec, FrameJson, frame_json};
use crate::kind::RobotKind;
use crate::profile::{ProfileError, ProfileTableError, positive, timeouts, with_overrides};

use super::driver::motion_command;
use super::{Frame, LoopbackDriver, LoopbackProfile, LoopbackSim, decode};

impl Family for LoopbackProfile {
    fn robot(&self) -> RobotKind {
        self.robot
    }

    fn validate(&self) -> Result<(), ProfileError> {
        positive("max_linear_mps", self.max_linear_mps)?;
        positive("max_angular_radps", self.max_angular_radps)?;
        timeouts(self.heartbeat_period_ms, self.command_timeout_ms)
    }

    fn with_table(&self, table: &toml::Table) -> Result<Profile, ProfileTableError> {
        Ok(with_overrides(self, table)?.into())
    }

    family_parts!(LoopbackDriver, LoopbackSim, heartbeat_period_ms);

    fn codec(&self) -> BoxedCodec {
        Box::new(LoopbackCodec(self.robot))
    }

    fn describe(&self, d: &mut RobotDescription) {
        d.protocol = WireProtocol::OWN;
        d.set_model("loopback");
        d.robot_limits = both_ways(self.max_linear_mps, 0.0, self.max_angular_radps);
        d.geometry.min_turn_radius_m = 0.0;
        d.battery.full_v = LoopbackSim::BODY.battery.full_v;
        d.battery.low_v = 22.0;
        d.command_timeout_ms = millis(self.command_timeout_ms);
    }

    fn command_lines(&self, command: &Command) -> Result<(Vec<String>, u32), CommandError> {
        let Command::Velocity(velocity) = command else {
            return Err(CommandError::unsupported(self.robot, command.function()));
        };
        let (motion, flags) = motion_command(velocity, self);
        let frame = Frame::Command(motion).encode()?;
        Ok((vec![frame.to_candump()], flags))
    }
}

/// The loopback frames as JSON, under the name of the robot the profile stands in for.
#[derive(Debug)]
struct LoopbackCodec(RobotKind);

impl Codec for LoopbackCodec {
    fn robot(&self) -> RobotKind {
        self.0
    }

    fn decode_can(&self, frame: &CanFrame) -> Result<FrameJson, DecodeError> {
        let decoded = decode(frame)?;
        let id = (decoded.id().into(), 3);
        Ok(frame_json(self.0, id, decoded.direction(), None, &decoded))
    }
}
