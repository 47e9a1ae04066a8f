//! The XBot frames for each robot-independent [`Command`].

use chassis_interfaces::{ClampFlags, Velocity};

use super::codec::{Frame, LiftCommand, PowerCommand, ServoCommand, VelocityCommand};
use crate::RobotKind;
use crate::command::{Command, CommandError, Planned, Turn};
use crate::xbot::XbotProfile;

/// A velocity within the profile's limits: speeds above `max_linear_mps` (and yaw rates above
/// `max_angular_rad_s`) are clamped, speeds below the board's `min_linear_mps` are sent as 0,
/// a lateral speed is kept only on omni variants. The XBot has no steering: a steering angle is
/// refused.
pub fn velocity_command(
    velocity: &Velocity,
    profile: &XbotProfile,
) -> Result<(VelocityCommand, u32), CommandError> {
    let Turn::YawRate(angular) = Turn::of(velocity) else {
        return Err(CommandError::Invalid(
            "the XBot turns by yaw rate; it has no steering angle".into(),
        ));
    };
    Ok(twist_command(
        velocity.linear_x_mps().into(),
        velocity.linear_y_mps().into(),
        angular,
        profile,
    ))
}

/// [`velocity_command`] of a twist (v, v_y, ω) whose numbers are a `Velocity`'s: finite.
pub(super) fn twist_command(
    linear_x_mps: f64,
    linear_y_mps: f64,
    angular: f64,
    profile: &XbotProfile,
) -> (VelocityCommand, u32) {
    let mut flags = 0;
    let mut speed = |value: f64, max: f64, flag: u32| {
        if value.abs() > max {
            flags |= flag;
            value.signum() * max
        } else if value != 0.0 && value.abs() < profile.min_linear_mps {
            flags |= ClampFlags::QUANTISED;
            0.0
        } else {
            value
        }
    };
    let vx = speed(
        linear_x_mps,
        profile.max_linear_mps,
        ClampFlags::LINEAR_LIMIT,
    );
    let vy = if profile.omni {
        speed(
            linear_y_mps,
            profile.max_linear_mps,
            ClampFlags::LINEAR_LIMIT,
        )
    } else {
        if linear_y_mps != 0.0 {
            flags |= ClampFlags::LATERAL_UNSUPPORTED;
        }
        0.0
    };
    let wz = if angular.abs() > profile.max_angular_rad_s {
        flags |= ClampFlags::ANGULAR_LIMIT;
        angular.signum() * profile.max_angular_rad_s
    } else {
        angular
    };
    (
        VelocityCommand {
            linear_x_mps: vx,
            linear_y_mps: vy,
            angular_z_radps: wz,
        },
        flags,
    )
}

/// The frames the XBot needs for `command`.
pub fn frames_for(
    command: &Command,
    profile: &XbotProfile,
) -> Result<Planned<Frame>, CommandError> {
    let robot = RobotKind::Xbot;
    Ok(match *command {
        Command::Velocity(velocity) => {
            let (velocity, clamp_flags) = velocity_command(&velocity, profile)?;
            Planned {
                frames: vec![Frame::Velocity(velocity)],
                clamp_flags,
            }
        }
        Command::Power { enable } => Planned::one(Frame::Power(PowerCommand { enable })),
        Command::Lift {
            enable,
            position_pct,
        } => {
            if !(0.0..=100.0).contains(&position_pct) {
                return Err(CommandError::Invalid(format!(
                    "lift position {position_pct} % is outside 0..100 %"
                )));
            }
            Planned::one(Frame::Lift(LiftCommand {
                enable,
                position_pct: position_pct.round(),
            }))
        }
        Command::Servos { pan_rad, tilt_rad } => {
            let quarter = std::f64::consts::FRAC_PI_2 + 1e-9;
            if !(pan_rad.abs() <= quarter && tilt_rad.abs() <= quarter) {
                return Err(CommandError::Invalid(format!(
                    "servo angles must be within ±90° (pan {:.1}°, tilt {:.1}°)",
                    pan_rad.to_degrees(),
                    tilt_rad.to_degrees()
                )));
            }
            Planned::one(Frame::Servos(ServoCommand { pan_rad, tilt_rad }))
        }
        Command::Mode { .. } => {
            return Err(CommandError::unsupported(
                robot,
                "control mode (it obeys the serial link whenever powered)",
            ));
        }
        Command::Brake { .. }
        | Command::ClearFaults { .. }
        | Command::Lights { .. }
        | Command::OffRoad { .. }
        | Command::SteeringZero
        | Command::Silent { .. } => return Err(CommandError::lacks(robot, command)),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> XbotProfile {
        XbotProfile::default()
    }

    fn twist(vx: f32, vy: f32, wz: f32) -> Velocity {
        Velocity::new(vx, vy, wz).unwrap()
    }

    #[test]
    fn speeds_are_limited_and_tiny_ones_are_zero() {
        let (v, flags) = velocity_command(&twist(2.0, 0.0, 0.0), &p()).unwrap();
        assert_eq!(v.linear_x_mps, 1.5);
        assert_ne!(flags & ClampFlags::LINEAR_LIMIT, 0);
        let (v, flags) = velocity_command(&twist(0.005, 0.0, 0.0), &p()).unwrap();
        assert_eq!(v.linear_x_mps, 0.0);
        assert_ne!(flags & ClampFlags::QUANTISED, 0);
    }

    #[test]
    fn lateral_speed_needs_an_omni_robot() {
        let (v, flags) = velocity_command(&twist(0.0, 0.3, 0.0), &p()).unwrap();
        assert_eq!(v.linear_y_mps, 0.0);
        assert_ne!(flags & ClampFlags::LATERAL_UNSUPPORTED, 0);
        let omni = XbotProfile { omni: true, ..p() };
        let (v, flags) = velocity_command(&twist(0.0, 0.3, 0.0), &omni).unwrap();
        assert_eq!((v.linear_y_mps, flags), (f64::from(0.3f32), 0));
    }

    #[test]
    fn manual_example_power_on_is_what_encode_prints() {
        let planned = frames_for(&Command::Power { enable: true }, &p()).unwrap();
        assert_eq!(
            planned.frames[0].encode(&p()).unwrap(),
            vec![0xAA, 0x55, 0x02, 0x01, 0x01, 0x02]
        );
    }

    #[test]
    fn steering_angles_and_missing_functions_are_refused() {
        assert!(velocity_command(&Velocity::steer(0.3, 0.1).unwrap(), &p()).is_err());
        let err = frames_for(&Command::SteeringZero, &p()).unwrap_err();
        assert_eq!(err.to_string(), "xbot has no steering to zero");
        assert!(
            frames_for(
                &Command::Lift {
                    enable: true,
                    position_pct: 120.0
                },
                &p()
            )
            .is_err()
        );
    }
}
