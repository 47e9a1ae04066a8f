//! The TITAN frames for each robot-independent [`Command`].

use chassis_interfaces::{ClampFlags, FaultClear, Velocity};

use super::codec::{
    ClearFault, Frame, ModeCommand, MotionCommand, ParkingBrake, Switch, clear_code, mode,
};
use super::kinematics::{steer_command, twist_to_command};
use crate::RobotKind;
use crate::command::{Command, CommandError, Planned, Turn};
use crate::titan::TitanProfile;

/// The TITAN 0x441 code for a normalized [`FaultClear`] code.
pub fn clear_code_for(which: u8) -> Option<u8> {
    Some(match which {
        FaultClear::ALL => clear_code::ALL_NON_SEVERE,
        FaultClear::MOTOR_1_COMM..=FaultClear::MOTOR_4_COMM => {
            clear_code::MOTOR_1_COMM + (which - FaultClear::MOTOR_1_COMM)
        }
        FaultClear::BATTERY_UNDER_VOLTAGE => clear_code::BATTERY_UNDER_VOLTAGE,
        FaultClear::RC_LINK => clear_code::RC_LINK_LOST,
        FaultClear::FRONT_STEERING_ENCODER => clear_code::FRONT_STEERING_ENCODER,
        FaultClear::REAR_STEERING_ENCODER => clear_code::REAR_STEERING_ENCODER,
        FaultClear::OVER_CURRENT => clear_code::OVER_CURRENT,
        FaultClear::OVER_TEMPERATURE => clear_code::OVER_TEMPERATURE,
        _ => return None,
    })
}

/// The 0x111 motion command for a velocity, within the profile's limits. Lateral speed is
/// dropped and flagged (TITAN cannot move sideways).
pub fn motion_command(velocity: &Velocity, profile: &TitanProfile) -> (MotionCommand, u32) {
    let linear_x_mps = velocity.linear_x_mps().into();
    let planned = match Turn::of(velocity) {
        Turn::YawRate(w) => twist_to_command(linear_x_mps, w, profile),
        Turn::Steer(s) => steer_command(linear_x_mps, s, profile),
    };
    let mut flags = planned.clamp_flags;
    if velocity.linear_y_mps() != 0.0 {
        flags |= ClampFlags::LATERAL_UNSUPPORTED;
    }
    (
        MotionCommand {
            linear_mps: planned.linear_mps,
            steer_rad: planned.steer_rad,
        },
        flags,
    )
}

/// The frames TITAN needs for `command`.
pub fn frames_for(
    command: &Command,
    profile: &TitanProfile,
) -> Result<Planned<Frame>, CommandError> {
    let robot = RobotKind::Titan;
    Ok(match *command {
        Command::Velocity(velocity) => {
            let (motion, clamp_flags) = motion_command(&velocity, profile);
            Planned {
                frames: vec![Frame::MotionCommand(motion)],
                clamp_flags,
            }
        }
        Command::Mode { take_control } => Planned::one(Frame::Mode(ModeCommand {
            mode: if take_control {
                mode::CAN_COMMAND
            } else {
                mode::STANDBY
            },
        })),
        Command::Brake { engage } => Planned::one(Frame::ParkingBrake(ParkingBrake { engage })),
        Command::ClearFaults { which } => {
            let code =
                clear_code_for(which).ok_or_else(|| CommandError::no_fault_clear(robot, which))?;
            Planned::one(Frame::ClearFault(ClearFault { code }))
        }
        Command::OffRoad { enter } => Planned::one(Frame::OffRoad(Switch { enter })),
        Command::SteeringZero => Planned::one(Frame::SteeringZero),
        Command::Silent { enter } => Planned::one(Frame::SilentMode(Switch { enter })),
        Command::Lights { .. } => {
            return Err(CommandError::unsupported(robot, "light control on the bus"));
        }
        Command::Lift { .. } | Command::Servos { .. } | Command::Power { .. } => {
            return Err(CommandError::lacks(robot, command));
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_normalized_clear_code_but_over_voltage_maps_to_a_defined_titan_code() {
        for (code, name) in FaultClear::NAMES {
            match clear_code_for(code) {
                Some(titan) => assert!(clear_code::is_defined(titan), "{name}"),
                None => assert_eq!(code, FaultClear::BATTERY_OVER_VOLTAGE, "{name}"),
            }
        }
        assert_eq!(clear_code_for(FaultClear::MOTOR_3_COMM), Some(0x03));
    }

    #[test]
    fn lateral_speed_is_flagged_not_sent() {
        let lateral = Velocity::new(0.5, 0.2, 0.0).unwrap();
        let (m, flags) = motion_command(&lateral, &TitanProfile::default());
        assert_eq!(m.linear_mps, 0.5);
        assert_ne!(flags & ClampFlags::LATERAL_UNSUPPORTED, 0);
    }

    #[test]
    fn functions_titan_lacks_are_clear_errors() {
        let err =
            frames_for(&Command::Power { enable: true }, &TitanProfile::default()).unwrap_err();
        assert_eq!(
            err.to_string(),
            "titan has no drive power switch on the bus"
        );
    }
}
