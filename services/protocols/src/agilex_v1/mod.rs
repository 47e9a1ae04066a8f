//! AgileX protocol V1 (SCOUT MINI, SCOUT 2.0 and BUNKER with V1 firmware): CAN 2.0B 500 kbit/s,
//! big-endian, count + checksum in every frame.

mod codec;
mod commands;
mod driver;
mod family;
pub mod kinematics;
mod profile;
mod sim;

pub use codec::*;
pub use commands::{clear_codes_for, frames_for, velocity_command};
pub use driver::{V1Driver, normalize_faults};
pub use profile::{V1Model, V1Profile};
pub use sim::V1Sim;

#[cfg(test)]
mod scenarios;
#[cfg(test)]
mod tests;
