//! XBot: differential (optionally omni) drive, RS232, little-endian, `AA 55 len payload xor`.
//!
//! * [`Frame`], [`decode_payload`], [`Frame::encode`]: every frame of the manual, both
//!   directions, in SI units and ISO 8855 axes.
//! * [`StreamParser`]: finds the frames in the serial byte stream, resynchronises after garbage
//!   and never loses a good frame behind a bad one.

mod codec;
mod commands;
mod driver;
mod family;
mod profile;
mod sim;
mod stream;

pub use codec::*;
pub use commands::{frames_for, velocity_command};
pub use driver::{MAX_VELOCITY_FRAMES_PER_S, XbotDriver};
pub use profile::XbotProfile;
pub use sim::XbotSim;
pub use stream::*;

#[cfg(test)]
mod scenarios;
#[cfg(test)]
mod test_support;
#[cfg(test)]
mod tests;
