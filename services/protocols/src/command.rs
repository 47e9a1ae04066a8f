//! RobotKind-independent commands and the frames each robot needs for them.
//!
//! `chassis encode` prints these frames; the drivers send the same ones, so what the CLI shows is
//! what the service puts on the wire.

use chassis_interfaces::{FaultClear, Velocity};
use thiserror::Error;

use crate::{EncodeError, RobotKind};

/// How a velocity command turns.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Turn {
    /// Yaw rate, rad/s, left positive.
    YawRate(f64),
    /// Inner steering angle, rad, left positive (Ackermann robots).
    Steer(f64),
}

impl Turn {
    /// How `velocity` asks to turn: by a steering angle or by a yaw rate.
    pub fn of(velocity: &Velocity) -> Turn {
        if velocity.uses_steer() {
            Turn::Steer(velocity.steer_rad().into())
        } else {
            Turn::YawRate(velocity.angular_z_radps().into())
        }
    }
}

/// Something to ask of a chassis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command {
    /// Move: forward speed, lateral speed (omni robots), and a turn; finite by its type.
    Velocity(Velocity),
    /// Take control (`true`: command mode) or let go (`false`: standby).
    Mode { take_control: bool },
    /// Engage or release the parking brake.
    Brake { engage: bool },
    /// Clear faults: a `chassis_interfaces::FaultClear` code.
    ClearFaults { which: u8 },
    /// Front light: `enable` false hands the lights back to the chassis.
    Lights {
        enable: bool,
        mode: u8,
        brightness_pct: u8,
    },
    /// Off-road mode (independent front/rear speed loops).
    OffRoad { enter: bool },
    /// Lift platform: position in % of travel.
    Lift { enable: bool, position_pct: f64 },
    /// Pan and tilt servos, rad (0 ahead; pan left positive, tilt up positive).
    Servos { pan_rad: f64, tilt_rad: f64 },
    /// Drive power.
    Power { enable: bool },
    /// Set the current steering position as zero.
    SteeringZero,
    /// CAN-upgrade silent mode (the chassis stops transmitting).
    Silent { enter: bool },
}

impl Command {
    /// Short name for messages (`velocity`, `brake`, …).
    pub fn name(&self) -> &'static str {
        self.names().0
    }

    /// The robot function the command needs, as an error names it when a robot has none
    /// (`parking brake`, …).
    pub fn function(&self) -> &'static str {
        self.names().1
    }

    /// The command's short name and the robot function it needs.
    fn names(&self) -> (&'static str, &'static str) {
        match self {
            Command::Velocity(_) => ("velocity", "motion"),
            Command::Mode { .. } => ("mode", "control mode"),
            Command::Brake { .. } => ("brake", "parking brake"),
            Command::ClearFaults { .. } => ("clear-fault", "fault-clear command"),
            Command::Lights { .. } => ("lights", "light control"),
            Command::OffRoad { .. } => ("off-road", "off-road mode"),
            Command::Lift { .. } => ("lift", "lift"),
            Command::Servos { .. } => ("servos", "servos"),
            Command::Power { .. } => ("power", "drive power switch on the bus"),
            Command::SteeringZero => ("steering-zero", "steering to zero"),
            Command::Silent { .. } => ("silent", "silent mode"),
        }
    }
}

/// The frames a robot needs for a command, and what was clamped on the way.
#[derive(Debug, Clone, PartialEq)]
pub struct Planned<F> {
    pub frames: Vec<F>,
    /// `chassis_interfaces::ClampFlags`.
    pub clamp_flags: u32,
}

impl<F> Planned<F> {
    pub fn one(frame: F) -> Self {
        Self {
            frames: vec![frame],
            clamp_flags: 0,
        }
    }
}

/// Why a command cannot be turned into frames.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum CommandError {
    /// The robot has no such function.
    #[error("{robot} has no {what}")]
    Unsupported { robot: RobotKind, what: String },
    /// An argument the robot cannot take.
    #[error("{0}")]
    Invalid(String),
    #[error(transparent)]
    Encode(#[from] EncodeError),
}

impl CommandError {
    pub(crate) fn unsupported(robot: RobotKind, what: impl Into<String>) -> Self {
        CommandError::Unsupported {
            robot,
            what: what.into(),
        }
    }

    /// The robot has no function for `command` ([`Command::function`]).
    pub(crate) fn lacks(robot: RobotKind, command: &Command) -> Self {
        Self::unsupported(robot, command.function())
    }

    /// The robot has no clear for the `FaultClear` code `which`.
    pub(crate) fn no_fault_clear(robot: RobotKind, which: u8) -> Self {
        Self::unsupported(
            robot,
            format!("fault to clear called {}", FaultClear::name(which)),
        )
    }
}

/// A control request as it crosses the IPC boundary, turned back into a command — or the lock
/// action it names. Velocity never travels as a control request.
#[derive(Debug, Clone, PartialEq)]
pub enum ControlAction {
    Chassis(Command),
    /// Release the named lock (operator).
    LockRelease(String),
    /// Engage the named lock (operator), stopping with a `StopCategory` (`None`: the lock's
    /// configured one).
    LockEngage(String, Option<u8>),
    /// Set the robot's standing speed limit, m/s, higher or lower (operator); `None` lifts it.
    SpeedLimit(Option<f32>),
    /// Keep the black box's window (operator).
    Keep,
}

/// The control request for a chassis command. `None` for a velocity (motion goes through the
/// mux).
pub fn command_to_request(command: &Command) -> Option<chassis_interfaces::ControlRequest> {
    use chassis_interfaces::{ControlKind, ControlMode, ControlRequest};
    let flag = |kind, on: bool| ControlRequest::new(kind).with_arg(0, u8::from(on));
    Some(match *command {
        Command::Velocity(_) => return None,
        Command::Mode { take_control } => ControlRequest::new(ControlKind::MODE).with_arg(
            0,
            if take_control {
                ControlMode::COMMAND
            } else {
                ControlMode::STANDBY
            },
        ),
        Command::Brake { engage } => flag(ControlKind::BRAKE, engage),
        Command::ClearFaults { which } => {
            ControlRequest::new(ControlKind::CLEAR_FAULTS).with_arg(0, which)
        }
        Command::Lights {
            enable,
            mode,
            brightness_pct,
        } => ControlRequest::new(ControlKind::LIGHTS)
            .with_arg(0, mode)
            .with_arg(1, brightness_pct)
            .with_arg(2, u8::from(enable)),
        Command::OffRoad { enter } => flag(ControlKind::OFF_ROAD, enter),
        Command::Lift {
            enable,
            position_pct,
        } => flag(ControlKind::LIFT, enable).with_value(0, position_pct as f32),
        Command::Servos { pan_rad, tilt_rad } => ControlRequest::new(ControlKind::SERVOS)
            .with_value(0, pan_rad as f32)
            .with_value(1, tilt_rad as f32),
        Command::Power { enable } => flag(ControlKind::POWER, enable),
        Command::SteeringZero => ControlRequest::new(ControlKind::STEERING_ZERO),
        Command::Silent { enter } => flag(ControlKind::SILENT, enter),
    })
}

/// Why a received control request makes no sense.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum BadControlRequest {
    #[error("{what}: {value} is neither 0 nor 1")]
    NotAFlag { what: &'static str, value: u8 },
    #[error("{what} is not a finite number")]
    NotFinite { what: &'static str },
    #[error("mode {0} is neither command nor standby")]
    UnknownMode(u8),
    #[error("stop category argument {0}: 0 for the lock's own, or 1 + a category 0-2")]
    UnknownCategory(u8),
    #[error("unknown control request kind {0}")]
    UnknownKind(u8),
    #[error("the speed limit is negative (a limit is more than 0 m/s; 0 lifts it)")]
    NegativeSpeedLimit,
}

/// What a received control request asks for, or why it makes no sense.
pub fn request_to_action(
    request: &chassis_interfaces::ControlRequest,
) -> Result<ControlAction, BadControlRequest> {
    use chassis_interfaces::{ControlKind, ControlMode};
    let flag = |i: usize, what: &'static str| match request.arg[i] {
        0 => Ok(false),
        1 => Ok(true),
        value => Err(BadControlRequest::NotAFlag { what, value }),
    };
    let value = |i: usize, what: &'static str| {
        let v = f64::from(request.value[i]);
        if v.is_finite() {
            Ok(v)
        } else {
            Err(BadControlRequest::NotFinite { what })
        }
    };
    let lock_name = || match request.name() {
        "" => "estop".to_string(),
        name => name.to_string(),
    };
    Ok(ControlAction::Chassis(match request.kind {
        ControlKind::MODE => Command::Mode {
            take_control: match request.arg[0] {
                ControlMode::COMMAND => true,
                ControlMode::STANDBY => false,
                other => return Err(BadControlRequest::UnknownMode(other)),
            },
        },
        ControlKind::BRAKE => Command::Brake {
            engage: flag(0, "brake")?,
        },
        ControlKind::CLEAR_FAULTS => Command::ClearFaults {
            which: request.arg[0],
        },
        ControlKind::LIGHTS => Command::Lights {
            mode: request.arg[0],
            brightness_pct: request.arg[1],
            enable: flag(2, "light control")?,
        },
        ControlKind::OFF_ROAD => Command::OffRoad {
            enter: flag(0, "off-road")?,
        },
        ControlKind::LIFT => Command::Lift {
            enable: flag(0, "lift enable")?,
            position_pct: value(0, "lift position")?,
        },
        ControlKind::SERVOS => Command::Servos {
            pan_rad: value(0, "pan")?,
            tilt_rad: value(1, "tilt")?,
        },
        ControlKind::POWER => Command::Power {
            enable: flag(0, "power")?,
        },
        ControlKind::STEERING_ZERO => Command::SteeringZero,
        ControlKind::SILENT => Command::Silent {
            enter: flag(0, "silent mode")?,
        },
        ControlKind::LOCK_RELEASE => return Ok(ControlAction::LockRelease(lock_name())),
        ControlKind::LOCK_ENGAGE => {
            let category = match request.arg[0] {
                0 => None,
                c @ 1..=3 => Some(c - 1),
                other => return Err(BadControlRequest::UnknownCategory(other)),
            };
            return Ok(ControlAction::LockEngage(lock_name(), category));
        }
        ControlKind::SPEED_LIMIT => {
            let mps = value(0, "speed limit")? as f32;
            return match mps {
                0.0 => Ok(ControlAction::SpeedLimit(None)),
                mps if mps > 0.0 => Ok(ControlAction::SpeedLimit(Some(mps))),
                _ => Err(BadControlRequest::NegativeSpeedLimit),
            };
        }
        ControlKind::KEEP => return Ok(ControlAction::Keep),
        other => return Err(BadControlRequest::UnknownKind(other)),
    }))
}

impl<F> Planned<F> {
    /// The planned frames one text line each, by `line(frame, count)` (`count` from 0: the
    /// AgileX V1 counter; a plan is a few frames), and what was clamped. Stops at the first
    /// frame that does not encode.
    pub(crate) fn lines<E>(
        &self,
        line: impl Fn(&F, u8) -> Result<String, E>,
    ) -> Result<(Vec<String>, u32), CommandError>
    where
        CommandError: From<E>,
    {
        let lines = self
            .frames
            .iter()
            .zip(0u8..)
            .map(|(f, count)| line(f, count))
            .collect::<Result<_, _>>()?;
        Ok((lines, self.clamp_flags))
    }
}

/// Serial bytes as spaced hex (`AA 55 02 01 01 02`).
pub fn spaced_hex(bytes: &[u8]) -> String {
    bytes
        .iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_chassis_command_survives_the_ipc_boundary() {
        let commands = [
            Command::Mode { take_control: true },
            Command::Mode {
                take_control: false,
            },
            Command::Brake { engage: true },
            Command::ClearFaults { which: 3 },
            Command::Lights {
                enable: true,
                mode: 3,
                brightness_pct: 40,
            },
            Command::OffRoad { enter: true },
            Command::Lift {
                enable: true,
                position_pct: 25.0,
            },
            Command::Servos {
                pan_rad: 0.5,
                tilt_rad: -0.25,
            },
            Command::Power { enable: false },
            Command::SteeringZero,
            Command::Silent { enter: true },
        ];
        for command in commands {
            let request = command_to_request(&command).unwrap();
            assert_eq!(
                request_to_action(&request),
                Ok(ControlAction::Chassis(command)),
                "{command:?}"
            );
        }
    }

    #[test]
    fn velocity_is_not_a_control_request() {
        let v = Command::Velocity(Velocity::twist(1.0, 0.0).unwrap());
        assert_eq!(command_to_request(&v), None);
    }

    #[test]
    fn lock_requests_default_to_the_estop_lock() {
        use chassis_interfaces::{ControlKind, ControlRequest};
        let r = ControlRequest::new(ControlKind::LOCK_RELEASE);
        assert_eq!(
            request_to_action(&r),
            Ok(ControlAction::LockRelease("estop".into()))
        );
        let r = ControlRequest::new(ControlKind::LOCK_ENGAGE).with_name("dock");
        assert_eq!(
            request_to_action(&r),
            Ok(ControlAction::LockEngage("dock".into(), None))
        );
    }

    #[test]
    fn malformed_requests_are_explained() {
        use chassis_interfaces::{ControlKind, ControlRequest};
        let r = ControlRequest::new(ControlKind::BRAKE).with_arg(0, 7);
        assert_eq!(
            request_to_action(&r).map_err(|e| e.to_string()),
            Err("brake: 7 is neither 0 nor 1".into())
        );
        let r = ControlRequest::new(ControlKind::LIFT)
            .with_arg(0, 1)
            .with_value(0, f32::NAN);
        assert!(request_to_action(&r).is_err());
        assert!(request_to_action(&ControlRequest::new(200)).is_err());
        let limit = |mps| {
            request_to_action(&ControlRequest::new(ControlKind::SPEED_LIMIT).with_value(0, mps))
        };
        assert_eq!(limit(0.5), Ok(ControlAction::SpeedLimit(Some(0.5))));
        assert_eq!(limit(0.0), Ok(ControlAction::SpeedLimit(None)));
        assert_eq!(limit(-0.5), Err(BadControlRequest::NegativeSpeedLimit));
        assert!(limit(f32::NAN).is_err());
    }
}
