//! Which robot: a leaf type every family names its robots by. What each robot *is* (its bus,
//! body, sensors and default profile) is its registry entry ([`crate::registry`]).

use serde::{Deserialize, Serialize};

/// Which kind of robot. The number is the kind's id on the wire (`ChassisState::robot`,
/// `RobotDescription::kind`); 0 means none.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
#[repr(u8)]
pub enum RobotKind {
    /// AgileX TITAN.
    Titan = 1,
    /// AgileX SCOUT MINI.
    ScoutMini = 2,
    /// XBot.
    Xbot = 3,
    /// AgileX SCOUT 2.0.
    Scout = 4,
    /// AgileX HUNTER 2.0.
    Hunter = 5,
    /// AgileX HUNTER SE.
    HunterSe = 6,
    /// AgileX TRACER.
    Tracer = 7,
    /// AgileX BUNKER / BUNKER MINI.
    Bunker = 8,
    /// AgileX RANGER MINI 2.0 / 3.0 (1.0 by its profile's `model`).
    RangerMini = 9,
    /// AgileX TRACER MINI.
    TracerMini = 10,
}

impl RobotKind {
    /// Every robot of the registry.
    pub const ALL: [RobotKind; 10] = [
        RobotKind::Titan,
        RobotKind::ScoutMini,
        RobotKind::Xbot,
        RobotKind::Scout,
        RobotKind::Hunter,
        RobotKind::HunterSe,
        RobotKind::Tracer,
        RobotKind::Bunker,
        RobotKind::RangerMini,
        RobotKind::TracerMini,
    ];

    /// The kind's id on the wire (`ChassisState::robot`).
    pub fn id(self) -> u8 {
        self as u8
    }

    /// The kind of a `ChassisState::robot` id.
    pub fn from_id(id: u8) -> Option<RobotKind> {
        RobotKind::ALL.into_iter().find(|k| k.id() == id)
    }

    /// The command-line spelling (`titan`, `scout-mini`, `hunter`, …), also the default robot
    /// name.
    pub fn name(self) -> &'static str {
        match self {
            RobotKind::Titan => "titan",
            RobotKind::ScoutMini => "scout-mini",
            RobotKind::Xbot => "xbot",
            RobotKind::Scout => "scout",
            RobotKind::Hunter => "hunter",
            RobotKind::HunterSe => "hunter-se",
            RobotKind::Tracer => "tracer",
            RobotKind::Bunker => "bunker",
            RobotKind::RangerMini => "ranger-mini",
            RobotKind::TracerMini => "tracer-mini",
        }
    }
}

/// The `--robot` spellings, for messages and help.
pub fn names() -> Vec<&'static str> {
    RobotKind::ALL.into_iter().map(RobotKind::name).collect()
}

/// A robot name that is none of the registry's.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown robot '{name}' (expected one of {})", names().join(", "))]
pub struct UnknownRobot {
    pub name: String,
}

impl std::str::FromStr for RobotKind {
    type Err = UnknownRobot;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        RobotKind::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| UnknownRobot { name: s.into() })
    }
}

impl std::fmt::Display for RobotKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}
