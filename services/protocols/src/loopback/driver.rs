//! The loopback driver: the heartbeat carries the latest command within the profile's limits,
//! the feedback fills the state. Link health, the heartbeat grid and the bus switch are the
//! shared [`DriverCore`]'s.

use serde::{Deserialize, Serialize};
use std::convert::Infallible;
use std::time::Duration;

use chassis_interfaces::{ClampFlags, ControlMode, Group, LinkFlags, Velocity};

use super::codec::{self, Feedback, Frame, Twist};
use super::profile::LoopbackProfile;
use crate::command::{Command, CommandError};
use crate::driver::{
    ControlOutcome, Driver, DriverConfig, DriverCore, PoseIntegrator, Rx, WireItem,
};
use crate::kind::RobotKind;
use crate::time::Timestamp;

/// The loopback driver.
#[derive(Debug, Serialize, Deserialize)]
pub struct LoopbackDriver {
    profile: LoopbackProfile,
    core: DriverCore,
    pose: PoseIntegrator,
    /// What the next 0x010 carries.
    motion: Twist,
    clamp_flags: u32,
}

/// A velocity as 0x010 carries it: within the profile's limits, with what was clamped. The
/// protocol has no lateral speed and no steering: a steering request drives straight.
pub fn motion_command(command: &Velocity, profile: &LoopbackProfile) -> (Twist, u32) {
    let linear = f64::from(command.linear_x_mps());
    let angular = if command.uses_steer() {
        0.0
    } else {
        f64::from(command.angular_z_radps())
    };
    let motion = Twist {
        linear_mps: linear.clamp(-profile.max_linear_mps, profile.max_linear_mps),
        angular_radps: angular.clamp(-profile.max_angular_radps, profile.max_angular_radps),
    };
    let mut flags = 0;
    if motion.linear_mps != linear {
        flags |= ClampFlags::LINEAR_LIMIT;
    }
    if motion.angular_radps != angular {
        flags |= ClampFlags::ANGULAR_LIMIT;
    }
    if command.linear_y_mps() != 0.0 {
        flags |= ClampFlags::LATERAL_UNSUPPORTED;
    }
    if command.uses_steer() && command.steer_rad() != 0.0 {
        flags |= ClampFlags::STEER_LIMIT;
    }
    (motion, flags)
}

/// What a control action plans on this protocol: nothing, it has no function but motion.
fn plan(robot: RobotKind, command: &Command) -> Result<Infallible, CommandError> {
    Err(CommandError::unsupported(robot, command.function()))
}

impl LoopbackDriver {
    pub fn new(profile: LoopbackProfile, config: DriverConfig, now: Timestamp) -> Self {
        let heartbeat = Duration::from_millis(profile.heartbeat_period_ms);
        Self {
            core: DriverCore::new(profile.robot.id(), heartbeat, &config, now),
            profile,
            pose: PoseIntegrator::default(),
            motion: Twist::default(),
            clamp_flags: 0,
        }
    }

    fn plan(&mut self, command: &Velocity) {
        let (motion, flags) = motion_command(command, &self.profile);
        let stop = motion == Twist::default();
        self.core.schedule.update(&mut self.motion, motion, stop);
        self.clamp_flags = flags;
    }

    fn apply(&mut self, now: Timestamp, f: Feedback) {
        let t = now.as_nanos();
        let state = &mut self.core.state;
        state.motion.linear_mps = f.linear_mps as f32;
        state.motion.angular_radps = f.angular_radps as f32;
        state.touch(Group::Motion, t);
        self.pose
            .update(now, f.linear_mps, 0.0, f.angular_radps, &mut state.odometry);
        state.touch(Group::Pose, t);
        state.system.battery_voltage_v = f.battery_voltage_v as f32;
        state.system.control_mode = if f.obeying {
            ControlMode::COMMAND
        } else {
            ControlMode::STANDBY
        };
        state.system.power_enabled = 1;
        state.touch(Group::System, t);
        self.core.set_flag(LinkFlags::COMMAND_MODE, f.obeying);
    }
}

impl Driver for LoopbackDriver {
    crate::snapshot::whole_driver!();

    fn robot(&self) -> RobotKind {
        self.profile.robot
    }

    crate::driver::core_accessors!();

    fn handle_rx(&mut self, now: Timestamp, rx: Rx<'_>) {
        // Another node's command on the bus is no feedback of ours to apply.
        if let Some(Frame::Feedback(f)) = self.core.can_rx(now, rx, codec::decode) {
            self.apply(now, f);
        }
    }

    fn set_command(&mut self, _now: Timestamp, command: &Velocity) {
        self.plan(command);
    }

    fn control(&mut self, _now: Timestamp, command: &Command) -> ControlOutcome {
        let robot = self.profile.robot;
        match self.core.admit_control(command, |c| plan(robot, c)) {
            Ok(never) => match never {},
            Err(outcome) => outcome,
        }
    }

    fn handle_timeout(&mut self, now: Timestamp) {
        if self.core.check_silence(now, "feedback") {
            self.pose.reset();
        }
    }

    fn poll_transmit(&mut self, now: Timestamp) -> Option<WireItem> {
        if self.core.bus_down || !self.core.schedule.is_due(now) {
            return None;
        }
        self.core.schedule.sent(now);
        let echo = &mut self.core.state.command;
        echo.linear_mps = self.motion.linear_mps as f32;
        echo.angular_radps = self.motion.angular_radps as f32;
        echo.clamp_flags = self.clamp_flags;
        self.core.state.touch(Group::Command, now.as_nanos());
        let frame = Frame::Command(self.motion);
        self.core.transmit(&frame, frame.encode(), WireItem::Can)
    }

    fn poll_timeout(&self) -> Option<Timestamp> {
        self.core.poll_timeout()
    }

    fn set_bus_down(&mut self, now: Timestamp, down: bool) {
        if self.core.set_bus_down(now, down) {
            self.pose.reset();
        }
    }

    fn shutdown(&mut self, _now: Timestamp) {
        self.plan(&Velocity::ZERO);
        // A stop goes out at once, even when the command was already zero.
        self.core.schedule.command_changed(true);
    }
}
