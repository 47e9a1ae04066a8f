//! Loopback: a protocol family for the tests only, the smallest honest one — one command frame,
//! one feedback frame — written by the recipe of `docs/ARCHITECTURE.md` ("Adding a robot, adding
//! a family") to show that a new family is one folder and one line in `lib.rs`, and that the
//! conformance suite ([`crate::conformance`]) takes it like every real family.
//!
//! CAN 2.0A, standard ids, little-endian, no checksum:
//!
//! | id | dir | period | content |
//! | --- | --- | --- | --- |
//! | 0x010 | →chassis | `heartbeat_period_ms`, timeout `command_timeout_ms` | b0-1 `s16le` forward speed, mm/s · b2-3 `s16le` yaw rate, mrad/s |
//! | 0x020 | ←chassis | 20 ms | b0-1, b2-3 the speeds as 0x010 · b4-5 `u16le` battery voltage, 0.01 V · b6 0x01 while a command is obeyed, 0x00 after the timeout or a boot |
//!
//! It has no robot of its own (a `RobotKind` is a real robot): its profile names the registered
//! robot it stands in for ([`LoopbackProfile::robot`]), the way a protocol-V1 profile's model
//! names the robot that speaks it.

mod codec;
mod driver;
mod family;
mod profile;
mod sim;

pub use codec::{Frame, decode};
pub use driver::LoopbackDriver;
pub use profile::LoopbackProfile;
pub use sim::LoopbackSim;
