//! The protocol-V2 frames for each robot-independent [`Command`].

use chassis_interfaces::FaultClear;

use super::codec::{ClearFault, Frame, Lights, ModeCommand, Motion, MotionMode, ParkingBrake};
use super::kinematics::plan;
use super::profile::{FaultMap, SteeringZero, V2Profile};
use crate::command::{Command, CommandError, Planned, Turn};

/// The 0x441 code for a normalized [`FaultClear`] code under the profile (§2.3.4).
pub fn clear_code_for(which: u8, profile: &V2Profile) -> Option<u8> {
    let hunter = matches!(profile.fault_map, FaultMap::Hunter2 | FaultMap::HunterSe);
    Some(match which {
        FaultClear::ALL => profile.clear_all_code,
        FaultClear::MOTOR_1_COMM..=FaultClear::MOTOR_4_COMM if !hunter => {
            let motor = which - FaultClear::MOTOR_1_COMM + 1;
            if motor > profile.actuators {
                return None;
            }
            motor
        }
        FaultClear::BATTERY_UNDER_VOLTAGE if hunter => 0x01,
        FaultClear::RC_LINK if profile.fault_map == FaultMap::Hunter2 => 0x0A,
        FaultClear::FRONT_STEERING_ENCODER if profile.fault_map == FaultMap::Hunter2 => 0x09,
        _ => return None,
    })
}

fn robot(profile: &V2Profile) -> crate::kind::RobotKind {
    profile.model.robot()
}

/// The frames `command` needs under `profile` (a velocity: the RANGER mode first when it has one).
pub fn frames_for(command: &Command, profile: &V2Profile) -> Result<Planned<Frame>, CommandError> {
    let robot = robot(profile);
    Ok(match *command {
        Command::Velocity(v) => {
            let planned = plan(
                v.linear_x_mps().into(),
                v.linear_y_mps().into(),
                Turn::of(&v),
                profile,
            );
            let mut frames = Vec::new();
            if let Some(code) = planned.mode.and_then(|m| m.code(profile)) {
                frames.push(Frame::MotionModeCommand(MotionMode {
                    mode: code,
                    changing: false,
                }));
            }
            frames.push(Frame::MotionCommand(planned.motion));
            Planned {
                frames,
                clamp_flags: planned.clamp_flags,
            }
        }
        Command::Mode { take_control } => {
            Planned::one(Frame::Mode(ModeCommand { can: take_control }))
        }
        Command::Brake { engage } => {
            if profile.brake_lock_value.is_none() {
                return Err(CommandError::lacks(robot, command));
            }
            Planned::one(Frame::ParkingBrake(ParkingBrake { engage }))
        }
        Command::ClearFaults { which } => {
            let code = clear_code_for(which, profile)
                .ok_or_else(|| CommandError::no_fault_clear(robot, which))?;
            Planned::one(Frame::ClearFault(ClearFault { code }))
        }
        Command::Lights {
            enable,
            mode,
            brightness_pct,
        } => {
            if !profile.front_light {
                return Err(CommandError::unsupported(robot, "light control on the bus"));
            }
            if mode > 3 || brightness_pct > 100 {
                return Err(CommandError::Invalid(format!(
                    "light mode {mode} / brightness {brightness_pct} %: modes are 0-3, brightness 0-100"
                )));
            }
            // The brightness byte is only read in custom mode (0x03); 0 otherwise.
            let brightness_pct = if mode == 3 { brightness_pct } else { 0 };
            let lights = if enable {
                Lights {
                    enabled: true,
                    front_mode: mode,
                    front_brightness_pct: brightness_pct,
                    rear_mode: if profile.rear_light { mode } else { 0 },
                    rear_brightness_pct: if profile.rear_light {
                        brightness_pct
                    } else {
                        0
                    },
                    count: 0,
                }
            } else {
                Lights::default()
            };
            Planned::one(Frame::LightCommand(lights))
        }
        Command::SteeringZero => match profile.steering_zero {
            SteeringZero::Request431 => Planned::one(Frame::SteeringZero),
            SteeringZero::Offset432 => {
                return Err(CommandError::unsupported(
                    robot,
                    "steering zero by command (it takes an offset in pulses: 0x432)",
                ));
            }
            SteeringZero::None => {
                return Err(CommandError::unsupported(robot, "steering zero over CAN"));
            }
        },
        Command::OffRoad { .. }
        | Command::Silent { .. }
        | Command::Lift { .. }
        | Command::Servos { .. }
        | Command::Power { .. } => return Err(CommandError::lacks(robot, command)),
    })
}

/// A zero motion command (what the heartbeat carries when nothing moves).
pub const STOP: Motion = Motion {
    linear_mps: 0.0,
    angular_radps: 0.0,
    lateral_mps: 0.0,
    steer_rad: 0.0,
};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::agilex_v2::V2Model;
    use chassis_interfaces::Velocity;

    #[test]
    fn clear_codes_per_robot() {
        let h = V2Profile::for_model(V2Model::Hunter);
        assert_eq!(clear_code_for(FaultClear::ALL, &h), Some(0xFF));
        assert_eq!(clear_code_for(FaultClear::MOTOR_1_COMM, &h), None);
        let b = V2Profile::for_model(V2Model::Bunker);
        assert_eq!(clear_code_for(FaultClear::ALL, &b), Some(0x00));
        assert_eq!(clear_code_for(FaultClear::MOTOR_2_COMM, &b), Some(0x02));
        assert_eq!(clear_code_for(FaultClear::MOTOR_3_COMM, &b), None);
    }

    #[test]
    fn ranger_velocity_sends_its_mode_first() {
        let r = V2Profile::for_model(V2Model::RangerMini);
        let planned =
            frames_for(&Command::Velocity(Velocity::twist(0.0, 1.0).unwrap()), &r).unwrap();
        let lines: Vec<String> = planned
            .frames
            .iter()
            .map(|f| f.encode(&r).unwrap().to_candump())
            .collect();
        assert_eq!(lines, ["141#0200000000000000", "111#000003E800000000"]);
    }

    #[test]
    fn functions_a_robot_lacks_are_clear_errors() {
        let b = V2Profile::for_model(V2Model::Bunker);
        let err = frames_for(&Command::Brake { engage: true }, &b).unwrap_err();
        assert_eq!(err.to_string(), "bunker has no parking brake");
        let t = V2Profile::for_model(V2Model::Tracer);
        let lights = frames_for(
            &Command::Lights {
                enable: true,
                mode: 1,
                brightness_pct: 0,
            },
            &t,
        )
        .unwrap();
        assert_eq!(
            lights.frames[0].encode(&t).unwrap().to_candump(),
            "121#0101000000000000"
        );
    }
}
