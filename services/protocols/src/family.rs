//! A protocol family — TITAN, AgileX V1, AgileX V2, XBot — behind one trait.
//!
//! A family is one folder (`titan/`, `agilex_v1/`, `agilex_v2/`, `xbot/`): its codec, driver,
//! simulated firmware and profile. Its profile type implements [`Family`], and everything the
//! rest of the workspace needs of a family goes through that trait: its driver and firmware, its
//! frame describer, its part of the robot's description, its heartbeat, its serial settings, its
//! TOML table. Nothing outside a family's folder matches on a family; a [`Profile`] (one robot's
//! effective profile) is a family's profile behind the trait.
//!
//! Adding a family: a folder with the four parts and a `family.rs` implementing [`Family`] for
//! its profile, one `mod` line in `lib.rs`, and registry entries (`registry.rs`) for its robots.
//! `docs/ARCHITECTURE.md` ("Adding a robot, adding a family") walks through it.

use std::any::Any;
use std::fmt;
use std::time::Duration;

use chassis_interfaces::{MotionLimits, RobotDescription};

use crate::command::{Command, CommandError};
use crate::driver::{BoxedDriver, DriverConfig};
use crate::firmware::BoxedFirmware;
use crate::frame_json::BoxedCodec;
use crate::kind::RobotKind;
use crate::profile::{ProfileError, ProfileTableError, Protocol};
use crate::time::Timestamp;

/// A protocol family, implemented by the family's profile type: what a robot of the family
/// needs beyond its registry entry.
pub trait Family: FamilyValue + fmt::Debug + Send + Sync + 'static {
    /// The robot the profile is of (a V1 or V2 `model` names it).
    fn robot(&self) -> RobotKind;

    /// The AgileX protocol of the profile, for the robots that may speak V1 or V2; `None` for a
    /// protocol of its own.
    fn protocol(&self) -> Option<Protocol> {
        None
    }

    /// Checks the values make a drivable robot.
    fn validate(&self) -> Result<(), ProfileError>;

    /// This profile with the keys of `table` (a `[profile]` table) set over it; a `model` key
    /// starts from that model's defaults. Unknown keys and wrong types are errors.
    fn with_table(&self, table: &toml::Table) -> Result<Profile, ProfileTableError>;

    /// The heartbeat period the family's driver keeps.
    fn heartbeat_period(&self) -> Duration;

    /// Baud rate of the serial control link, for a family on RS232 (`None`: a CAN family).
    fn serial_baud(&self) -> Option<u32> {
        None
    }

    /// Baud rate of the GPS receiver the family fits (`None`: none fitted; a GPS given to the
    /// service then runs at NMEA 0183's 4800 baud unless its spec names another).
    fn gps_baud(&self) -> Option<u32> {
        None
    }

    /// The family's driver for this profile.
    fn driver(&self, config: &DriverConfig, now: Timestamp) -> BoxedDriver;

    /// The family's simulated firmware for this profile, powered up at `now`.
    fn firmware(&self, now: Timestamp) -> BoxedFirmware;

    /// The family's frame describer (`chassis decode`, the Foxglove `/frames` topic).
    fn codec(&self) -> BoxedCodec;

    /// The family's part of the robot's description: protocol, model, the driver's limits,
    /// geometry, battery levels, the chassis' command timeout, flags, and the kinematics of a
    /// variant that differs from the registry's.
    fn describe(&self, description: &mut RobotDescription);

    /// How many of the registry's wheel joints the bridges publish (they need the wheel radius).
    fn wheel_joints(&self) -> u8 {
        0
    }

    /// The frames a command plans, one text line each (`ID#HEX` for CAN, spaced hex for
    /// serial), and what was clamped on the way (`ClampFlags`); counters start at 0.
    fn command_lines(&self, command: &Command) -> Result<(Vec<String>, u32), CommandError>;

    /// The command that disables (`cut`) or enables again the robot's drive for a stop of
    /// category 0 or 1 (`chassis_interfaces::StopCategory`); `None` where the protocol has no
    /// way (a SCOUT MINI on V1: its only other mode hands the chassis to the RC transmitter).
    fn drive_cut(&self, _cut: bool) -> Option<Command> {
        None
    }

    /// Fills what a simulated chassis knows and a real one's profile must be told (the XBot's
    /// wheel separation).
    fn fill_for_simulator(&mut self) {}
}

/// The [`Family`] methods every family writes alike: its driver and its simulated firmware, each
/// made from a clone of the profile (`new(profile, config, now)`, `new(profile, now)`), and, with
/// `heartbeat_period_ms`, the heartbeat period that profile field holds.
macro_rules! family_parts {
    ($driver:ty, $firmware:ty $(, $heartbeat_ms:ident)?) => {
        fn driver(
            &self,
            config: &$crate::driver::DriverConfig,
            now: $crate::time::Timestamp,
        ) -> $crate::driver::BoxedDriver {
            Box::new(<$driver>::new(self.clone(), config.clone(), now))
        }

        fn firmware(&self, now: $crate::time::Timestamp) -> $crate::firmware::BoxedFirmware {
            Box::new(<$firmware>::new(self.clone(), now))
        }

        $(
            fn heartbeat_period(&self) -> std::time::Duration {
                std::time::Duration::from_millis(self.$heartbeat_ms)
            }
        )?
    };
}
pub(crate) use family_parts;

/// What makes a family's profile a value behind the trait: cloned, compared, written as the
/// `[profile]` table of the service's config and looked at as its own type. Implemented for
/// every family that is `Clone + PartialEq + Serialize`.
pub trait FamilyValue {
    fn table(&self) -> Result<toml::Table, toml::ser::Error>;
    fn clone_box(&self) -> Box<dyn Family>;
    fn eq_dyn(&self, other: &dyn Family) -> bool;
    fn as_any(&self) -> &dyn Any;
}

impl<F: Family + Clone + PartialEq + serde::Serialize> FamilyValue for F {
    fn table(&self) -> Result<toml::Table, toml::ser::Error> {
        toml::Table::try_from(self)
    }
    fn clone_box(&self) -> Box<dyn Family> {
        Box::new(self.clone())
    }
    fn eq_dyn(&self, other: &dyn Family) -> bool {
        other.as_any().downcast_ref::<F>() == Some(self)
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

/// One robot's effective profile: its family's profile (the manuals' values with every
/// override), behind [`Family`].
pub struct Profile(Box<dyn Family>);

impl Profile {
    /// The profile as its family's own type (`None` for another family's).
    pub fn get<F: Family>(&self) -> Option<&F> {
        self.0.as_any().downcast_ref()
    }
}

impl<F: Family> From<F> for Profile {
    fn from(profile: F) -> Self {
        Profile(Box::new(profile))
    }
}

impl std::ops::Deref for Profile {
    type Target = dyn Family;
    fn deref(&self) -> &Self::Target {
        &*self.0
    }
}

impl std::ops::DerefMut for Profile {
    fn deref_mut(&mut self) -> &mut Self::Target {
        &mut *self.0
    }
}

impl Clone for Profile {
    fn clone(&self) -> Self {
        Profile(self.0.clone_box())
    }
}

impl PartialEq for Profile {
    fn eq(&self, other: &Self) -> bool {
        self.0.eq_dyn(&*other.0)
    }
}

impl fmt::Debug for Profile {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.0.fmt(f)
    }
}

/// Limits as fast backward as forward; no steering and no acceleration limit (a family's
/// [`Family::describe`]).
pub(crate) fn both_ways(linear_mps: f64, lateral_mps: f64, angular_radps: f64) -> MotionLimits {
    MotionLimits {
        forward_mps: linear_mps,
        reverse_mps: linear_mps,
        lateral_mps,
        angular_radps,
        ..MotionLimits::NONE
    }
}

/// A profile's milliseconds as the description's `u32`.
pub(crate) fn millis(ms: u64) -> u32 {
    u32::try_from(ms).unwrap_or(u32::MAX)
}

/// A model as the config spells it (`scout-mini-omni`).
pub(crate) fn kebab<T: serde::Serialize>(value: &T) -> String {
    match serde_json::to_value(value) {
        Ok(serde_json::Value::String(s)) => s,
        _ => String::new(),
    }
}
