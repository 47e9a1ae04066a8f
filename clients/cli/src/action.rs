//! The chassis functions one can ask for, shared by `chassis encode` (which prints the frames)
//! and `chassis control` (which asks the running service).

use chassis_interfaces::{FaultClear, InvalidVelocity, LightMode, ValidRequest, VelocityRequest};
use chassis_protocols::Command;
use clap::{Args, Subcommand, ValueEnum};
use thiserror::Error;

/// on / off.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum OnOff {
    On,
    Off,
}

impl OnOff {
    pub fn is_on(self) -> bool {
        self == OnOff::On
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ModeArg {
    /// Obey this computer's commands.
    Command,
    /// Let go: the chassis ignores motion commands.
    Standby,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum BrakeArg {
    Engage,
    Release,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LightArg {
    Off,
    On,
    Breathing,
    Custom,
    /// Hand the lights back to the chassis.
    Auto,
}

/// A velocity: forward speed plus a yaw rate or a steering angle.
#[derive(Debug, Clone, Copy, PartialEq, Args)]
pub struct VelocityArgs {
    /// Forward speed, m/s.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub vx: f64,
    /// Lateral speed, m/s, left positive (omni robots).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub vy: f64,
    /// Yaw rate, rad/s, left positive.
    #[arg(long, conflicts_with = "steer", allow_negative_numbers = true)]
    pub wz: Option<f64>,
    /// Inner steering angle, rad, left positive (Ackermann robots).
    #[arg(long, allow_negative_numbers = true)]
    pub steer: Option<f64>,
}

impl VelocityArgs {
    /// The request the arguments ask for: a steering angle with `--steer`, else a yaw rate.
    pub fn request(&self) -> VelocityRequest {
        let turning = match self.steer {
            Some(steer) => VelocityRequest::steer(self.vx as f32, steer as f32),
            None => VelocityRequest::twist(self.vx as f32, self.wz.unwrap_or(0.0) as f32),
        };
        VelocityRequest {
            linear_y_mps: self.vy as f32,
            ..turning
        }
    }

    /// The command `chassis encode` prints: the request parsed as chassisd parses it (a NaN or
    /// an infinity is refused), so the frames are those the service would send.
    pub fn to_command(self) -> Result<Command, InvalidVelocity> {
        Ok(Command::Velocity(
            ValidRequest::try_from(self.request())?.velocity(),
        ))
    }
}

/// Chassis functions other than motion.
#[derive(Debug, Clone, PartialEq, Subcommand)]
pub enum Action {
    /// Take control (command) or let go (standby).
    Mode {
        #[arg(value_enum)]
        mode: ModeArg,
    },
    /// Engage or release the parking brake (TITAN).
    Brake {
        #[arg(value_enum)]
        action: BrakeArg,
    },
    /// Clear faults: all, motor-1..motor-4, battery-under-voltage, battery-over-voltage, rc-link,
    /// front-steering-encoder, rear-steering-encoder, over-current, over-temperature.
    ClearFault {
        #[arg(default_value = "all")]
        which: String,
    },
    /// Front light mode (SCOUT MINI).
    Lights {
        #[arg(value_enum)]
        mode: LightArg,
        /// Brightness in custom mode, %.
        #[arg(long, default_value_t = 100)]
        brightness: u8,
    },
    /// Off-road mode (TITAN; only while standing still).
    OffRoad {
        #[arg(value_enum)]
        state: OnOff,
    },
    /// Lift platform position (XBot).
    Lift {
        /// Position, % of travel: 0 bottom, 100 top.
        #[arg(long)]
        position: f64,
        /// Disable the lift instead of moving it.
        #[arg(long)]
        disable: bool,
    },
    /// Pan and tilt servos (XBot), degrees from straight ahead.
    Servos {
        /// Pan, degrees, left positive (-90 right … 90 left).
        #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
        pan: f64,
        /// Tilt, degrees, up positive (-90 floor … 90 up).
        #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
        tilt: f64,
    },
    /// Drive power (XBot).
    Power {
        #[arg(value_enum)]
        state: OnOff,
    },
    /// Set the current steering position as zero (TITAN).
    SteeringZero,
    /// CAN-upgrade silent mode: the chassis stops transmitting (TITAN).
    Silent {
        #[arg(value_enum)]
        state: OnOff,
    },
}

/// Why a control action on the command line is not a command.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ActionError {
    /// A fault name `FaultClear` does not know.
    #[error("unknown fault '{name}' (one of: {})", fault_names().join(", "))]
    UnknownFault { name: String },
    #[error("brightness {0} % is above 100 %")]
    Brightness(u8),
    #[error("lift position {0} % is outside 0..100 %")]
    LiftPosition(f64),
    /// A pan or tilt angle beyond ±90°.
    #[error("{axis} {degrees}° is outside -90..90°")]
    ServoAngle { axis: &'static str, degrees: f64 },
}

fn fault_names() -> Vec<&'static str> {
    FaultClear::NAMES.iter().map(|(_, n)| *n).collect()
}

impl Action {
    /// The robot-independent command.
    pub fn to_command(&self) -> Result<Command, ActionError> {
        Ok(match self {
            Action::Mode { mode } => Command::Mode {
                take_control: *mode == ModeArg::Command,
            },
            Action::Brake { action } => Command::Brake {
                engage: *action == BrakeArg::Engage,
            },
            Action::ClearFault { which } => Command::ClearFaults {
                which: FaultClear::from_name(which)
                    .ok_or_else(|| ActionError::UnknownFault { name: which.into() })?,
            },
            Action::Lights { mode, brightness } => {
                if *brightness > 100 {
                    return Err(ActionError::Brightness(*brightness));
                }
                let (enable, mode) = match mode {
                    LightArg::Off => (true, LightMode::OFF),
                    LightArg::On => (true, LightMode::ON),
                    LightArg::Breathing => (true, LightMode::BREATHING),
                    LightArg::Custom => (true, LightMode::CUSTOM),
                    LightArg::Auto => (false, LightMode::OFF),
                };
                Command::Lights {
                    enable,
                    mode,
                    brightness_pct: *brightness,
                }
            }
            Action::OffRoad { state } => Command::OffRoad {
                enter: state.is_on(),
            },
            Action::Lift { position, disable } => {
                if !(0.0..=100.0).contains(position) {
                    return Err(ActionError::LiftPosition(*position));
                }
                Command::Lift {
                    enable: !disable,
                    position_pct: *position,
                }
            }
            Action::Servos { pan, tilt } => {
                for (axis, v) in [("pan", pan), ("tilt", tilt)] {
                    if !(-90.0..=90.0).contains(v) {
                        return Err(ActionError::ServoAngle { axis, degrees: *v });
                    }
                }
                Command::Servos {
                    pan_rad: pan.to_radians(),
                    tilt_rad: tilt.to_radians(),
                }
            }
            Action::Power { state } => Command::Power {
                enable: state.is_on(),
            },
            Action::SteeringZero => Command::SteeringZero,
            Action::Silent { state } => Command::Silent {
                enter: state.is_on(),
            },
        })
    }
}
