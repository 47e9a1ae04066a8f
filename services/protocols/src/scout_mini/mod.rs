//! AgileX SCOUT MINI: four-wheel skid steer, CAN 2.0B 500 kbit/s, big-endian, count + checksum.

mod codec;
mod commands;
pub mod kinematics;

pub use codec::*;
pub use commands::{clear_codes_for, frames_for, velocity_command};

#[cfg(test)]
mod tests;
