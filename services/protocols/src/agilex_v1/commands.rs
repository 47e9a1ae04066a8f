//! The SCOUT MINI frames for each robot-independent [`Command`].

use chassis_interfaces::{ClampFlags, FaultClear, Velocity};

use super::codec::{Frame, Lights, MotionCommand, clear_code, mode};
use super::kinematics::{SkidCommand, twist_to_command};
use crate::agilex_v1::V1Profile;
use crate::command::{Command, CommandError, Planned, Turn};

/// The 0x130 fault-clear codes for a normalized [`FaultClear`] code (every code for `ALL`: the
/// chassis has no single "clear all").
pub fn clear_codes_for(which: u8) -> Option<Vec<u8>> {
    Some(match which {
        FaultClear::ALL => {
            (clear_code::BATTERY_UNDER_VOLTAGE..=clear_code::MOTOR_OVER_CURRENT).collect()
        }
        FaultClear::BATTERY_UNDER_VOLTAGE => vec![clear_code::BATTERY_UNDER_VOLTAGE],
        FaultClear::BATTERY_OVER_VOLTAGE => vec![clear_code::BATTERY_OVER_VOLTAGE],
        FaultClear::MOTOR_1_COMM..=FaultClear::MOTOR_4_COMM => {
            vec![clear_code::MOTOR_1_COMM + (which - FaultClear::MOTOR_1_COMM)]
        }
        FaultClear::OVER_TEMPERATURE => vec![clear_code::DRIVE_OVER_TEMPERATURE],
        FaultClear::OVER_CURRENT => vec![clear_code::MOTOR_OVER_CURRENT],
        _ => return None,
    })
}

/// The speed and yaw rate for a velocity within the profile's limits, quantised to the wire's
/// percent steps. A steering angle is turned into the yaw rate of a bicycle with the robot's
/// wheelbase (ω = v·tan δ / L); a lateral speed is dropped and flagged.
pub fn velocity_command(velocity: &Velocity, profile: &V1Profile) -> SkidCommand {
    let linear_x_mps = f64::from(velocity.linear_x_mps());
    let angular = match Turn::of(velocity) {
        Turn::YawRate(w) => w,
        Turn::Steer(steer) => linear_x_mps * steer.tan() / profile.wheelbase_m,
    };
    let mut command = twist_to_command(linear_x_mps, angular, profile);
    if velocity.linear_y_mps() != 0.0 {
        command.clamp_flags |= ClampFlags::LATERAL_UNSUPPORTED;
    }
    command
}

/// The frames SCOUT MINI needs for `command`. Counters are the caller's (the driver numbers every
/// frame it sends).
pub fn frames_for(command: &Command, profile: &V1Profile) -> Result<Planned<Frame>, CommandError> {
    let robot = profile.model.robot();
    let standing = MotionCommand::drive(0.0, 0.0);
    Ok(match *command {
        Command::Velocity(velocity) => {
            let c = velocity_command(&velocity, profile);
            Planned {
                frames: vec![Frame::MotionCommand(c.motion_command())],
                clamp_flags: c.clamp_flags,
            }
        }
        Command::Mode { take_control } => Planned::one(Frame::MotionCommand(MotionCommand {
            mode: if take_control {
                mode::CAN_COMMAND
            } else {
                mode::RC
            },
            ..standing
        })),
        Command::ClearFaults { which } => {
            let codes =
                clear_codes_for(which).ok_or_else(|| CommandError::no_fault_clear(robot, which))?;
            Planned {
                frames: codes
                    .into_iter()
                    .map(|code| {
                        Frame::MotionCommand(MotionCommand {
                            fault_clear: code,
                            ..standing
                        })
                    })
                    .collect(),
                clamp_flags: 0,
            }
        }
        Command::Lights {
            enable,
            mode,
            brightness_pct,
        } => Planned::one(Frame::LightCommand(Lights {
            control_enabled: enable,
            front_mode: mode,
            front_brightness_pct: brightness_pct,
        })),
        Command::Brake { .. }
        | Command::OffRoad { .. }
        | Command::Lift { .. }
        | Command::Servos { .. }
        | Command::Power { .. }
        | Command::SteeringZero
        | Command::Silent { .. } => return Err(CommandError::lacks(robot, command)),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> V1Profile {
        V1Profile::default()
    }

    #[test]
    fn clearing_all_faults_sends_every_clear_code() {
        let planned = frames_for(
            &Command::ClearFaults {
                which: FaultClear::ALL,
            },
            &p(),
        )
        .unwrap();
        let codes: Vec<u8> = planned
            .frames
            .iter()
            .map(|f| match f {
                Frame::MotionCommand(m) => m.fault_clear,
                other => panic!("{other:?}"),
            })
            .collect();
        assert_eq!(codes, (1..=8).collect::<Vec<u8>>());
        assert_eq!(clear_codes_for(FaultClear::RC_LINK), None);
    }

    #[test]
    fn velocity_is_quantised_to_whole_percents_and_flagged() {
        let c = velocity_command(&Velocity::twist(0.52, 0.0).unwrap(), &p());
        assert_eq!(c.linear_pct, 10);
        assert!((c.linear_mps - 0.5).abs() < 1e-12);
        assert_ne!(c.clamp_flags & ClampFlags::QUANTISED, 0);
    }

    #[test]
    fn a_steering_angle_becomes_the_bicycle_yaw_rate() {
        // ω = 0.5 · tan(0.02) / 0.452 = 0.0221 rad/s = 4.2 % of 0.5235 rad/s → 4 %.
        let c = velocity_command(&Velocity::steer(0.5, 0.02).unwrap(), &p());
        assert_eq!(c.angular_pct, 4);
        let c = velocity_command(&Velocity::steer(-0.5, 0.02).unwrap(), &p());
        assert_eq!(c.angular_pct, -4, "reversing with left steer yaws right");
    }

    #[test]
    fn functions_the_scout_mini_lacks_are_clear_errors() {
        let err = frames_for(&Command::Brake { engage: true }, &p()).unwrap_err();
        assert_eq!(err.to_string(), "scout-mini has no parking brake");
    }
}
