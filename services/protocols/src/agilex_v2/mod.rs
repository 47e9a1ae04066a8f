//! AgileX protocol V2: SCOUT 2.0, SCOUT MINI (V2 firmware, skid and omni), HUNTER 2.0 / SE,
//! TRACER, BUNKER and RANGER MINI — one codec, one driver and one simulated firmware for the
//! family, parametrised by a [`V2Profile`] per robot. CAN 2.0B 500 kbit/s, big-endian, no
//! checksum; the layouts it shares with the TITAN use the TITAN's frame types.

mod auto;
mod codec;
mod commands;
pub mod detect;
mod driver;
mod family;
pub mod kinematics;
pub mod profile;
mod sim;

pub use auto::AutoDriver;
pub use codec::*;
pub use commands::{STOP, clear_code_for, frames_for};
pub(crate) use driver::body_status;
pub use driver::{V2Driver, normalize_driver_status, normalize_faults, vehicle_state_flags};
pub use profile::{Kinematics, V2Model, V2Profile};
pub use sim::V2Sim;

#[cfg(test)]
mod names_tests;
#[cfg(test)]
mod scenarios;
#[cfg(test)]
mod tests;
