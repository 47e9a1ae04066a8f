//! Sans-IO wire protocols of the AgileX TITAN, the AgileX SCOUT MINI and the XBot.
//!
//! Everything here is pure: frames go in as values, frames come out as values, and time is a
//! parameter. No socket, serial port, IPC or clock is touched, so the same code runs on a real
//! bus, against the simulated firmware and in unit tests (the `Cargo.toml` carries no I/O crate).
//!
//! * [`titan`], [`scout_mini`], [`xbot`]: one module per robot, each with its wire layouts (zerocopy
//!   structs with big- or little-endian fields), a typed frame enum, and `decode`/`encode` for
//!   every frame of the manual in both directions.
//! * [`nmea`]: the NMEA 0183 sentences of the XBot's GPS receiver.
//! * [`profile`]: every physical constant and every doubtful (⚠) choice of the manuals.
//! * [`can`]: the CAN frame type and the can-utils text forms; [`slcan`]: a serial CAN
//!   adapter's text.
//!
//! Frame structs hold SI values in ISO 8855 axes (x forward, y left, left turn positive); each
//! codec is the only place that knows its vendor's units and signs.

mod agilex;
pub mod agilex_v2;
pub mod can;
pub mod command;
pub mod describe;
pub mod description;
pub mod driver;
mod error;
pub mod firmware;
pub mod nmea;
pub mod pair;
pub mod profile;
pub mod registry;
pub mod scout_mini;
#[cfg(test)]
mod sim_bench;
pub mod slcan;
pub mod time;
pub mod titan;
mod wire;
pub mod xbot;

pub use can::{CanFrame, CanFrameError, CandumpLine};
pub use command::{
    BadControlRequest, Command, CommandError, ControlAction, Planned, Turn, command_to_request,
    request_to_action,
};
pub use driver::{BoxedDriver, ControlOutcome, Driver, DriverConfig, DriverEvent, Rx, WireItem};
pub use error::{DecodeError, EncodeError};
pub use firmware::{BoxedFirmware, Firmware, InjectedCounts, Injection, SimTruth};
pub use profile::{
    Profile, ProfileError, ProfileTableError, Protocol, ProtocolError, V1Model, V1Profile,
};
pub use registry::{RobotEntry, RobotKind, UnknownRobot};
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
