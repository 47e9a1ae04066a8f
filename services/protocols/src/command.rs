//! Robot-independent commands and the frames each robot needs for them.
//!
//! `chassis encode` prints these frames; the drivers send the same ones, so what the CLI shows is
//! what the service puts on the wire.

use thiserror::Error;

use crate::{EncodeError, Robot};

/// How a velocity command turns.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Turn {
    /// Yaw rate, rad/s, left positive.
    YawRate(f64),
    /// Inner steering angle, rad, left positive (Ackermann robots).
    Steer(f64),
}

/// Something to ask of a chassis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command {
    /// Move: forward speed, lateral speed (omni robots), and a turn.
    Velocity {
        linear_x_mps: f64,
        linear_y_mps: f64,
        turn: Turn,
    },
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
        match self {
            Command::Velocity { .. } => "velocity",
            Command::Mode { .. } => "mode",
            Command::Brake { .. } => "brake",
            Command::ClearFaults { .. } => "clear-fault",
            Command::Lights { .. } => "lights",
            Command::OffRoad { .. } => "off-road",
            Command::Lift { .. } => "lift",
            Command::Servos { .. } => "servos",
            Command::Power { .. } => "power",
            Command::SteeringZero => "steering-zero",
            Command::Silent { .. } => "silent",
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
    Unsupported { robot: Robot, what: String },
    /// An argument the robot cannot take.
    #[error("{0}")]
    Invalid(String),
    #[error(transparent)]
    Encode(#[from] EncodeError),
}

impl CommandError {
    pub(crate) fn unsupported(robot: Robot, what: impl Into<String>) -> Self {
        CommandError::Unsupported {
            robot,
            what: what.into(),
        }
    }
}
