//! AgileX TITAN: front/rear dual Ackermann, CAN 2.0B 500 kbit/s, big-endian, no checksum.

mod codec;
mod commands;
mod driver;
mod family;
pub mod kinematics;
mod profile;
mod sim;

pub use codec::*;
pub use commands::{clear_code_for, frames_for, motion_command};
pub use driver::{TitanDriver, normalize_faults};
pub use profile::TitanProfile;
pub use sim::TitanSim;

#[cfg(test)]
mod scenarios;
#[cfg(test)]
mod tests;
