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
//!
//! **Why not the `nmea` crate.** The AeroRust `nmea` crate (0.8.0; sans-IO, `no_std`, no line
//! reader) reads every receiver sentence of the tests as this module does, and the same values
//! from generated sentences wherever both accept them (`tests/crosscheck.rs`). The service keeps
//! this reader because, on a checksum-valid line (a receiver's fault, or a corruption the XOR
//! misses), the crate takes what this reader rejects and the fix would carry: `inf`, `NaN` or an
//! exponent in any number (a latitude of +inf), 91° of latitude, 67 minutes of arc, a
//! lower-case talker, a character after the checksum. It rejects sentences receivers send: a GGA
//! with an empty quality, a GSA with empty DOPs or a whole-number PDOP, a GLL without the NMEA
//! 2.0 status, a `GNGSV`, a leap second. It misreads a VTG whose speed is in km/h only (no speed),
//! an RMC with an empty variation but its `E` (the mode is lost), a GSV with a satellite below
//! the horizon or an empty slot (satellites dropped). It has no DGPS age or station, VTG mode or
//! km/h, or GSA slots, and it writes no sentence ([`Sentence::to_sentence`] feeds the round-trip
//! tests and the fuzz target). A wrapper checking each case would keep most of this parser.
//! `tests/crosscheck.rs` pins every case: a crate update that closes one fails there. Parsing
//! costs the same (`cargo bench -p chassis-protocols --bench codecs -- nmea`).

/// NMEA 0183's standard line rate: a GPS receiver's unless its profile or spec says otherwise.
pub const NMEA_0183_BAUD: u32 = 4800;

mod fix;
mod reader;
mod sentence;

pub use fix::apply;
pub use reader::{DEFAULT_MAX_LINE_LEN, LineReader, MAX_QUEUED_LINES};
pub use sentence::*;

#[cfg(test)]
mod tests;
