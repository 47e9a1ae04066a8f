//! AgileX TITAN: front/rear dual Ackermann, CAN 2.0B 500 kbit/s, big-endian, no checksum.

mod codec;
pub mod kinematics;

pub use codec::*;

#[cfg(test)]
mod tests;
