//! NMEA 0183 sentences of the XBot's GPS receiver (4800 8N1 by default).
//!
//! * [`LineReader`]: cuts the serial byte stream into sentences (`$` … CR/LF), bounded.
//! * [`parse_sentence`]: one sentence → a typed [`Sentence`]; [`Sentence::to_sentence`] is its
//!   inverse (for the GPS simulator).
//! * [`apply`]: folds a sentence into the IPC [`chassis_interfaces::GpsFix`].
//!
//! Sentences: GGA, RMC, VTG, GSA, GSV, GLL and ZDA, from any talker (`GP`, `GN`, `GL`, `GA`,
//! `GB`, …). The `*hh` checksum (XOR of the characters between `$` and `*`) is **required**: a
//! sentence without one is rejected ([`crate::DecodeError::Nmea`]), a wrong one is
//! [`crate::DecodeError::BadChecksum`]. Empty fields are normal in NMEA and read as `None`.
//! Fields that later NMEA versions append (RMC navigational status, GSA system id, GSV signal
//! id) are accepted and ignored.
//!
//! A GGA with fix quality 0, an RMC or GLL with status `V`, or a mode indicator `N` means "no
//! fix": [`apply`] then reports fix quality 0 and a position of (0, 0) that
//! [`chassis_interfaces::GpsFix::has_fix`] marks as meaningless; it never takes the empty fields
//! of such a sentence for a position.

mod fix;
mod reader;
mod sentence;

pub use fix::apply;
pub use reader::{DEFAULT_MAX_LINE_LEN, LineReader, MAX_QUEUED_LINES};
pub use sentence::*;

#[cfg(test)]
mod tests;
