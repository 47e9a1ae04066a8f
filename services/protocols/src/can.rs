//! A classic CAN frame, its can-utils text forms (`123#DEADBEEF`, `candump -l` log lines), and
//! the CAN frame a `BusFrame` of chassisd's frame tap carries.

use std::fmt;

use chassis_interfaces::{BusFrame, FrameKind};
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// A [`CanFrame`] in a snapshot.
#[derive(Serialize, Deserialize)]
struct SavedFrame(u32, bool, Vec<u8>);

impl From<CanFrame> for SavedFrame {
    fn from(frame: CanFrame) -> Self {
        Self(frame.id(), frame.is_extended(), frame.data().to_vec())
    }
}

impl TryFrom<SavedFrame> for CanFrame {
    type Error = CanFrameError;
    fn try_from(SavedFrame(id, extended, data): SavedFrame) -> Result<Self, CanFrameError> {
        if extended {
            CanFrame::new_extended(id, &data)
        } else {
            CanFrame::new(id, &data)
        }
    }
}

/// A classic CAN 2.0 data frame (0-8 bytes). In a snapshot it is its id, kind and data, read
/// back through [`CanFrame::new`] (or `new_extended`): an id or a length out of range is refused.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(into = "SavedFrame", try_from = "SavedFrame")]
pub struct CanFrame {
    id: u32,
    extended: bool,
    len: u8,
    data: [u8; 8],
}

/// Why bytes or text do not make a CAN frame.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum CanFrameError {
    #[error("CAN id 0x{id:X} does not fit {bits} bits")]
    IdOutOfRange { id: u32, bits: u8 },
    #[error("{len} data bytes do not fit a classic CAN frame (at most 8)")]
    TooLong { len: usize },
    #[error("'{text}' is not a CAN frame (expected ID#HEX, e.g. 111#0096000000000000)")]
    Syntax { text: String },
    #[error("remote (RTR) frames carry no data and are not used by these robots")]
    Remote,
    #[error("a tapped serial or GPS chunk, not a CAN frame")]
    NotCan,
}

impl CanFrame {
    /// Largest 11-bit identifier.
    pub const MAX_STANDARD_ID: u32 = 0x7FF;
    /// Largest 29-bit identifier.
    pub const MAX_EXTENDED_ID: u32 = 0x1FFF_FFFF;

    /// A standard-id (11-bit) frame.
    pub fn new(id: u32, data: &[u8]) -> Result<Self, CanFrameError> {
        if id > Self::MAX_STANDARD_ID {
            return Err(CanFrameError::IdOutOfRange { id, bits: 11 });
        }
        Self::build(id, false, data)
    }

    /// An extended-id (29-bit) frame.
    pub fn new_extended(id: u32, data: &[u8]) -> Result<Self, CanFrameError> {
        if id > Self::MAX_EXTENDED_ID {
            return Err(CanFrameError::IdOutOfRange { id, bits: 29 });
        }
        Self::build(id, true, data)
    }

    fn build(id: u32, extended: bool, data: &[u8]) -> Result<Self, CanFrameError> {
        if data.len() > 8 {
            return Err(CanFrameError::TooLong { len: data.len() });
        }
        let mut buf = [0u8; 8];
        buf[..data.len()].copy_from_slice(data);
        Ok(Self {
            id,
            extended,
            // data.len() <= 8 checked above.
            len: data.len() as u8,
            data: buf,
        })
    }

    /// A standard-id frame from a fixed array (cannot fail for ids the codecs use).
    pub(crate) fn from_parts<const N: usize>(id: u16, data: [u8; N]) -> Self {
        let mut buf = [0u8; 8];
        let n = N.min(8);
        buf[..n].copy_from_slice(&data[..n]);
        Self {
            id: u32::from(id) & Self::MAX_STANDARD_ID,
            extended: false,
            len: n as u8,
            data: buf,
        }
    }

    pub fn id(&self) -> u32 {
        self.id
    }

    pub fn is_extended(&self) -> bool {
        self.extended
    }

    /// The 11-bit id, for the codecs: every robot here speaks standard frames only, so an
    /// extended one is [`crate::DecodeError::ExtendedId`].
    pub(crate) fn standard_id(&self) -> Result<u16, crate::DecodeError> {
        if self.extended {
            return Err(crate::DecodeError::ExtendedId { id: self.id });
        }
        // Standard ids are at most 0x7FF: the cast keeps every bit.
        Ok(self.id as u16)
    }

    /// The data bytes (length = DLC).
    pub fn data(&self) -> &[u8] {
        &self.data[..usize::from(self.len)]
    }

    pub fn len(&self) -> usize {
        usize::from(self.len)
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Parses the can-utils compact form: `123#DEADBEEF`, `12345678#01`, `123#` (no data),
    /// with optional `.` separators between bytes (`123#DE.AD.BE.EF`).
    pub fn from_candump(text: &str) -> Result<Self, CanFrameError> {
        let syntax = || CanFrameError::Syntax {
            text: text.to_string(),
        };
        let (id_text, data_text) = text.trim().split_once('#').ok_or_else(syntax)?;
        if data_text.starts_with('R') || data_text.starts_with('r') {
            return Err(CanFrameError::Remote);
        }
        if data_text.starts_with('#') {
            // CAN FD (`123##1...`) is not classic CAN.
            return Err(syntax());
        }
        if id_text.is_empty() || !id_text.bytes().all(|b| b.is_ascii_hexdigit()) {
            return Err(syntax());
        }
        let id = u32::from_str_radix(id_text, 16).map_err(|_| syntax())?;
        let hex: String = data_text.chars().filter(|c| *c != '.').collect();
        if !hex.len().is_multiple_of(2) || !hex.bytes().all(|b| b.is_ascii_hexdigit()) {
            return Err(syntax());
        }
        let bytes: Vec<u8> = (0..hex.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&hex[i..i + 2], 16))
            .collect::<Result<_, _>>()
            .map_err(|_| syntax())?;
        // can-utils: 3 hex digits mean a standard id, 8 an extended one.
        if id_text.len() > 3 {
            Self::new_extended(id, &bytes)
        } else {
            Self::new(id, &bytes)
        }
    }

    /// The can-utils compact form, `111#0096000000000000` (3 id digits for standard ids, 8 for
    /// extended ones).
    pub fn to_candump(&self) -> String {
        let mut out = if self.extended {
            format!("{:08X}#", self.id)
        } else {
            format!("{:03X}#", self.id)
        };
        for b in self.data() {
            out.push_str(&format!("{b:02X}"));
        }
        out
    }
}

impl fmt::Debug for CanFrame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.to_candump())
    }
}

impl fmt::Display for CanFrame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.to_candump())
    }
}

/// The CAN frame a tapped [`BusFrame`] carries: its id (29 bits where it says
/// [`BusFrame::EXTENDED_ID`]) and its data. Every reader of the frame tap that decodes CAN
/// (the Foxglove view's `/frames`, `chassis record`, `chassis top`) converts with this.
impl TryFrom<&BusFrame> for CanFrame {
    type Error = CanFrameError;

    fn try_from(frame: &BusFrame) -> Result<Self, CanFrameError> {
        if frame.kind != FrameKind::CAN {
            return Err(CanFrameError::NotCan);
        }
        if frame.flags & BusFrame::REMOTE != 0 {
            return Err(CanFrameError::Remote);
        }
        if frame.flags & BusFrame::EXTENDED_ID != 0 {
            Self::new_extended(frame.can_id, frame.payload())
        } else {
            Self::new(frame.can_id, frame.payload())
        }
    }
}

/// One line of a `candump -l` log: `(1700000000.000000) can0 123#DEADBEEF`.
#[derive(Debug, Clone, PartialEq)]
pub struct CandumpLine {
    /// Seconds since the epoch (or whatever clock the recorder used).
    pub time_s: f64,
    pub interface: String,
    pub frame: CanFrame,
}

impl CandumpLine {
    /// Parses a log line; a bare `ID#HEX` is accepted too (time 0, no interface).
    pub fn parse(line: &str) -> Result<Self, CanFrameError> {
        let syntax = || CanFrameError::Syntax {
            text: line.trim().to_string(),
        };
        let line = line.trim();
        let Some(rest) = line.strip_prefix('(') else {
            return Ok(Self {
                time_s: 0.0,
                interface: String::new(),
                frame: CanFrame::from_candump(line)?,
            });
        };
        let (time_text, rest) = rest.split_once(')').ok_or_else(syntax)?;
        let time_s: f64 = time_text.trim().parse().map_err(|_| syntax())?;
        let mut fields = rest.split_whitespace();
        let interface = fields.next().ok_or_else(syntax)?.to_string();
        let frame = CanFrame::from_candump(fields.next().ok_or_else(syntax)?)?;
        // candump -l may append a direction flag (` R` / ` T`) after the frame; ignore it.
        Ok(Self {
            time_s,
            interface,
            frame,
        })
    }

    /// The `candump -l` form: `(1700000000.000000) can0 123#DEADBEEF`.
    pub fn format(&self) -> String {
        format!(
            "({:.6}) {} {}",
            self.time_s,
            self.interface,
            self.frame.to_candump()
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn candump_text_round_trips() {
        let f = CanFrame::from_candump("111#0096000000000000").unwrap();
        assert_eq!(f.id(), 0x111);
        assert_eq!(f.data(), &[0x00, 0x96, 0, 0, 0, 0, 0, 0]);
        assert_eq!(f.to_candump(), "111#0096000000000000");
    }

    #[test]
    fn candump_accepts_dots_lower_case_and_empty_data() {
        let f = CanFrame::from_candump("43a#ee").unwrap();
        assert_eq!((f.id(), f.data()), (0x43A, &[0xEE][..]));
        let f = CanFrame::from_candump("123#DE.AD.BE.EF").unwrap();
        assert_eq!(f.data(), &[0xDE, 0xAD, 0xBE, 0xEF]);
        assert!(CanFrame::from_candump("123#").unwrap().is_empty());
    }

    #[test]
    fn candump_extended_ids_keep_eight_digits() {
        let f = CanFrame::from_candump("00000123#01").unwrap();
        assert!(f.is_extended());
        assert_eq!(f.to_candump(), "00000123#01");
    }

    #[test]
    fn candump_rejects_malformed_text() {
        for bad in [
            "", "123", "xyz#00", "123#0", "123#GG", "800#00", "123#R", "123##100",
        ] {
            assert!(CanFrame::from_candump(bad).is_err(), "{bad:?}");
        }
        assert!(CanFrame::from_candump("123#000000000000000000").is_err());
    }

    #[test]
    fn a_tapped_bus_frame_is_the_can_frame_it_carries() {
        let mut tapped = BusFrame {
            kind: FrameKind::CAN,
            can_id: 0x211,
            ..BusFrame::default()
        };
        tapped.set_payload(&[1, 2, 3]);
        let can = CanFrame::try_from(&tapped).unwrap();
        assert_eq!(
            (can.id(), can.is_extended(), can.data()),
            (0x211, false, &[1, 2, 3][..])
        );
        tapped.flags = BusFrame::EXTENDED_ID;
        tapped.can_id = 0x1234_5678;
        assert_eq!(
            CanFrame::try_from(&tapped).unwrap().to_candump(),
            "12345678#010203"
        );
        tapped.flags = 0;
        assert!(matches!(
            CanFrame::try_from(&tapped),
            Err(CanFrameError::IdOutOfRange { bits: 11, .. })
        ));
        tapped.flags = BusFrame::REMOTE;
        assert_eq!(CanFrame::try_from(&tapped), Err(CanFrameError::Remote));
        tapped.kind = FrameKind::SERIAL;
        assert_eq!(CanFrame::try_from(&tapped), Err(CanFrameError::NotCan));
    }

    #[test]
    fn candump_log_lines_parse_and_format() {
        let line = CandumpLine::parse("(1700000000.000000) can0 123#DEADBEEF").unwrap();
        assert_eq!(line.interface, "can0");
        assert_eq!(line.frame.id(), 0x123);
        assert!((line.time_s - 1_700_000_000.0).abs() < 1e-6);
        assert_eq!(line.format(), "(1700000000.000000) can0 123#DEADBEEF");
        let bare = CandumpLine::parse("211#0001020300000000").unwrap();
        assert_eq!(bare.frame.id(), 0x211);
        assert!(CandumpLine::parse("(abc) can0 123#00").is_err());
        assert!(CandumpLine::parse("(1.0) can0").is_err());
    }
}
