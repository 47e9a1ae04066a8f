//! Sans-IO wire protocols of the AgileX TITAN, the AgileX SCOUT MINI and the XBot.
//!
//! Everything here is pure: frames go in as values, frames come out as values, and time is a
//! parameter. No socket, serial port, IPC or clock is touched, so the same code runs on a real
//! bus, against the simulated firmware and in unit tests (the `Cargo.toml` carries no I/O crate).
//!
//! * [`titan`], [`agilex_v1`], [`agilex_v2`], [`xbot`]: one folder per protocol family, each with
//!   its wire layouts (zerocopy structs with big- or little-endian fields), a typed frame enum,
//!   `decode`/`encode` for every frame of the manual in both directions, its driver, its
//!   simulated firmware and its profile, behind the one trait [`family::Family`].
//! * [`registry`]: the robots, as data: each one's bus, body, sensors and profiles.
//! * [`nmea`]: the NMEA 0183 sentences of the XBot's GPS receiver.
//! * [`can`]: the CAN frame type and the can-utils text forms; [`slcan`]: a serial CAN
//!   adapter's text.
//!
//! Frame structs hold SI values in ISO 8855 axes (x forward, y left, left turn positive); each
//! codec is the only place that knows its vendor's units and signs.

mod agilex_driver;
pub mod agilex_v1;
pub mod agilex_v2;
pub mod can;
pub mod command;
#[cfg(test)]
mod conformance;
pub mod description;
pub mod driver;
mod error;
pub mod family;
pub mod firmware;
pub mod frame_json;
pub mod kind;
#[cfg(test)]
mod loopback;
pub mod nmea;
pub mod pair;
pub mod profile;
pub mod registry;
#[cfg(test)]
mod sim_bench;
pub mod slcan;
pub mod snapshot;
pub mod time;
pub mod titan;
mod wire_layout;
pub mod xbot;

pub use can::{CanFrame, CanFrameError, CandumpLine};
pub use command::{
    BadControlRequest, Command, CommandError, ControlAction, Planned, Turn, command_to_request,
    request_to_action,
};
pub use driver::{BoxedDriver, ControlOutcome, Driver, DriverConfig, DriverEvent, Rx, WireItem};
pub use error::{DecodeError, EncodeError};
pub use family::{Family, Profile};
pub use firmware::{BoxedFirmware, Firmware, InjectedCounts, Injection, SimTruth};
pub use frame_json::Codec;
pub use kind::{RobotKind, UnknownRobot};
pub use profile::{ProfileError, ProfileTableError, Protocol, ProtocolError};
pub use registry::RobotEntry;
pub use time::Timestamp;

/// Who sends a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Direction {
    /// Computer → chassis (commands).
    ToChassis,
    /// Chassis → computer (feedback).
    FromChassis,
}
