//! AgileX SCOUT MINI: four-wheel skid steer, CAN 2.0B 500 kbit/s, big-endian, count + checksum.

mod codec;
mod commands;
mod driver;
pub mod kinematics;
mod sim;

pub use codec::*;
pub use commands::{clear_codes_for, frames_for, velocity_command};
pub use driver::{ScoutMiniDriver, body_flags, normalize_faults};
pub use sim::ScoutMiniSim;

#[cfg(test)]
mod scenarios;
#[cfg(test)]
mod tests;
