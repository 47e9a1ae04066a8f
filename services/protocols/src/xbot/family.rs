//! The XBot family behind [`Family`]: its driver, firmware, frame describer (a stream parser
//! over the serial bytes) and its part of the robot's description.

use std::time::Duration;

use chassis_interfaces::{Kinematics, RobotDescription, WireProtocol};

use crate::command::{Command, CommandError, spaced_hex};
use crate::family::{Family, Profile, both_ways, family_parts, millis};
use crate::frame_json::{BoxedCodec, Codec, FrameJson, SerialError, frame_json};
use crate::kind::RobotKind;
use crate::profile::{ProfileError, ProfileTableError, positive, with_overrides};

use super::{StreamParser, XbotDriver, XbotProfile, XbotSim, frames_for};

impl Family for XbotProfile {
    fn robot(&self) -> RobotKind {
        RobotKind::Xbot
    }

    /// Checks the values make a drivable robot, and the heartbeat rate the manual asks for.
    fn validate(&self) -> Result<(), ProfileError> {
        if self.baud == 0 || self.gps_baud == 0 {
            return Err(ProfileError::ZeroBaud);
        }
        positive("wheel_diameter_m", self.wheel_diameter_m)?;
        positive("encoder_counts_per_rev", self.encoder_counts_per_rev)?;
        if let Some(separation) = self.wheel_separation_m {
            positive("wheel_separation_m", separation)?;
        }
        positive("max_linear_mps", self.max_linear_mps)?;
        positive("max_angular_rad_s", self.max_angular_rad_s)?;
        if self.min_linear_mps.is_nan()
            || self.min_linear_mps < 0.0
            || self.min_linear_mps >= self.max_linear_mps
        {
            return Err(ProfileError::MinLinear);
        }
        if self.heartbeat_hz.is_nan() || self.heartbeat_hz <= 5.0 || self.heartbeat_hz >= 10.0 {
            return Err(ProfileError::HeartbeatRate {
                hz: self.heartbeat_hz,
            });
        }
        if self.command_timeout_ms == 0 {
            return Err(ProfileError::ZeroCommandTimeout);
        }
        Ok(())
    }

    fn with_table(&self, table: &toml::Table) -> Result<Profile, ProfileTableError> {
        Ok(with_overrides(self, table)?.into())
    }

    fn heartbeat_period(&self) -> Duration {
        Duration::from_secs_f64(1.0 / self.heartbeat_hz)
    }

    fn serial_baud(&self) -> Option<u32> {
        Some(self.baud)
    }

    fn gps_baud(&self) -> Option<u32> {
        Some(self.gps_baud)
    }

    /// Drive power off (0x01 `00`): the wheels stop and the stored command is dropped.
    fn drive_cut(&self, cut: bool) -> Option<Command> {
        Some(Command::Power { enable: !cut })
    }

    family_parts!(XbotDriver, XbotSim);

    fn codec(&self) -> BoxedCodec {
        Box::new(XbotCodec {
            profile: self.clone(),
            parser: StreamParser::new(),
        })
    }

    fn describe(&self, d: &mut RobotDescription) {
        d.protocol = WireProtocol::OWN;
        d.set_model(if self.omni { "xbot-omni" } else { "xbot" });
        if self.omni {
            d.kinematics = Kinematics::OMNI;
        }
        let lateral_mps = if self.omni { self.max_linear_mps } else { 0.0 };
        d.robot_limits = both_ways(self.max_linear_mps, lateral_mps, self.max_angular_rad_s);
        d.geometry.track_m = self.wheel_separation_m.unwrap_or(f64::NAN);
        d.geometry.wheel_radius_m = self.wheel_diameter_m / 2.0;
        d.geometry.travel_per_count_m = self.metres_per_count();
        d.geometry.min_turn_radius_m = 0.0;
        d.battery.full_v = self.battery_full_v;
        d.battery.low_v = self.battery_low_v;
        d.command_timeout_ms = millis(self.command_timeout_ms);
    }

    /// The manual gives the wheel's diameter: the front pair on a two-wheel base, all four on
    /// an omni one.
    fn wheel_joints(&self) -> u8 {
        if self.omni { 4 } else { 2 }
    }

    fn command_lines(&self, command: &Command) -> Result<(Vec<String>, u32), CommandError> {
        frames_for(command, self)?.lines(|f, _| f.encode(self).map(|bytes| spaced_hex(&bytes)))
    }

    fn fill_for_simulator(&mut self) {
        if self.wheel_separation_m.is_none() {
            self.wheel_separation_m = Some(XbotSim::DEFAULT_WHEEL_SEPARATION_M);
        }
    }
}

/// The XBot's serial stream as JSON frames.
#[derive(Debug)]
struct XbotCodec {
    profile: XbotProfile,
    parser: StreamParser,
}

impl Codec for XbotCodec {
    fn robot(&self) -> RobotKind {
        RobotKind::Xbot
    }

    fn push_serial(&mut self, bytes: &[u8]) -> Vec<Result<FrameJson, SerialError>> {
        self.parser.push(bytes);
        let mut out = Vec::new();
        while let Some(item) = self.parser.next_frame(&self.profile) {
            out.push(match item {
                Ok(frame) => Ok(frame_json(
                    RobotKind::Xbot,
                    (frame.command_id().into(), 2),
                    frame.direction(),
                    None,
                    &frame,
                )),
                Err(err) => Err(SerialError::Rejected(err)),
            });
        }
        out
    }

    fn serial_bytes_discarded(&self) -> u64 {
        self.parser.bytes_discarded()
    }
}
