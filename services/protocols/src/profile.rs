//! What every family's profile shares: the AgileX protocol choice, the errors of a profile and
//! of a `[profile]` table, and the checks and TOML merge each family's profile uses.
//!
//! A family's profile (`titan/profile.rs`, `agilex_v1/profile.rs`, `agilex_v2/profile.rs`,
//! `xbot/profile.rs`) holds every physical constant of its chassis and every choice where its
//! manual contradicts itself (the ⚠ entries of `PROTOCOLS.md`), with the manuals' values as
//! defaults. Profiles deserialize from the `[profile]` table of the service's TOML config, so a
//! user with a real robot can flip a doubtful parameter without a rebuild. Unknown keys are
//! rejected.

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::kind::RobotKind;

/// Which AgileX wire protocol: V1 (count and checksum in every frame) or V2 (the TITAN's family).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Protocol {
    V1,
    V2,
}

impl Protocol {
    pub fn name(self) -> &'static str {
        match self {
            Protocol::V1 => "v1",
            Protocol::V2 => "v2",
        }
    }
}

/// A protocol name that is neither `v1` nor `v2`, or one the robot does not speak.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum ProtocolError {
    #[error("unknown protocol '{name}' (expected v1 or v2)")]
    Unknown { name: String },
    #[error("{robot} does not speak protocol {protocol} here")]
    NotSpoken {
        robot: RobotKind,
        protocol: &'static str,
    },
}

impl std::str::FromStr for Protocol {
    type Err = ProtocolError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "v1" => Ok(Protocol::V1),
            "v2" => Ok(Protocol::V2),
            _ => Err(ProtocolError::Unknown { name: s.into() }),
        }
    }
}

impl std::fmt::Display for Protocol {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// `profile` with the keys of `overrides` (the `[profile]` table of the service's config) set
/// over it. Unknown keys and wrong types are errors.
pub(crate) fn with_overrides<P>(profile: &P, overrides: &toml::Table) -> Result<P, toml::de::Error>
where
    P: Serialize + serde::de::DeserializeOwned,
{
    let mut table = toml::Table::try_from(profile)
        .map_err(|e| <toml::de::Error as serde::de::Error>::custom(format!("profile: {e}")))?;
    for (key, value) in overrides {
        table.insert(key.clone(), value.clone());
    }
    toml::Value::Table(table).try_into()
}

/// A profile from a `[profile]` table: the defaults of the model the table names (`model`),
/// or `base` when it names none, with the table's keys set over them.
pub(crate) fn with_model_and_overrides<P, M>(
    base: &P,
    table: &toml::Table,
    for_model: impl Fn(M) -> P,
) -> Result<P, ProfileTableError>
where
    P: Serialize + serde::de::DeserializeOwned + Clone,
    M: serde::de::DeserializeOwned,
{
    let base = match table.get("model") {
        Some(model) => for_model(model.clone().try_into()?),
        None => base.clone(),
    };
    Ok(with_overrides(&base, table)?)
}

/// Why a profile does not make a drivable robot.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ProfileError {
    /// A length, speed, scale or rate that must be finite and above zero.
    #[error("{name} must be above zero (is {value})")]
    NotPositive { name: &'static str, value: f64 },
    /// The heartbeat does not fit inside the chassis' command timeout.
    #[error(
        "heartbeat_period_ms ({heartbeat_ms}) must be above 0 and below command_timeout_ms \
         ({timeout_ms})"
    )]
    Heartbeat { heartbeat_ms: u64, timeout_ms: u64 },
    /// A steering limit at or beyond a right angle (TITAN).
    #[error("max_steer_rad must be below π/2")]
    SteerBeyondRightAngle,
    /// A negative (or NaN) steering angle above which speed is limited (TITAN).
    #[error("steer_speed_limit_above_rad must not be negative")]
    NegativeSteerSpeedLimit,
    /// A serial line at 0 baud (XBot).
    #[error("baud rates must be above zero")]
    ZeroBaud,
    /// A dead band below zero or reaching the top speed (XBot).
    #[error("min_linear_mps must be at least 0 and below max_linear_mps")]
    MinLinear,
    /// A heartbeat rate outside the manual's bounds (XBot).
    #[error("heartbeat_hz must be above 5 and below 10 Hz (the manual's bounds), is {hz}")]
    HeartbeatRate { hz: f64 },
    /// No command timeout (XBot).
    #[error("command_timeout_ms must be above zero")]
    ZeroCommandTimeout,
}

/// Checks `value` is finite and above zero.
pub(crate) fn positive(name: &'static str, value: f64) -> Result<(), ProfileError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(ProfileError::NotPositive { name, value })
    }
}

/// Checks the protocol detection listens for a while and needs at least one frame (⚠ D-16).
pub(crate) fn detection(timeout_ms: u64, min_frames: u32) -> Result<(), ProfileError> {
    if timeout_ms == 0 {
        return Err(ProfileError::NotPositive {
            name: "detect_timeout_ms",
            value: 0.0,
        });
    }
    if min_frames == 0 {
        return Err(ProfileError::NotPositive {
            name: "detect_min_frames",
            value: 0.0,
        });
    }
    Ok(())
}

pub(crate) fn timeouts(heartbeat_ms: u64, timeout_ms: u64) -> Result<(), ProfileError> {
    if heartbeat_ms == 0 || heartbeat_ms >= timeout_ms {
        return Err(ProfileError::Heartbeat {
            heartbeat_ms,
            timeout_ms,
        });
    }
    Ok(())
}

/// Why a `[profile]` table does not make a profile.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ProfileTableError {
    #[error(transparent)]
    Protocol(#[from] ProtocolError),
    /// An unknown key or a wrong type.
    #[error(transparent)]
    Toml(#[from] toml::de::Error),
    /// A protocol-V1 or V2 `model` of another robot: `owner` is the robot the model belongs to.
    #[error("profile.model: a {owner} model is not a {robot}")]
    WrongModel { owner: RobotKind, robot: RobotKind },
}
