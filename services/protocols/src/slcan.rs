//! Lawicel slcan, the text a serial CAN adapter (CANable, USBtin, …) speaks: sans-IO.
//!
//! ASCII over a serial line, every message ended by CR: the host sends `S6` (500 kbit/s), `O`
//! (open the channel) and frames as `tIIILDD…` (standard id) or `TIIIIIIIILDD…` (extended); the
//! adapter answers `\r` for OK, BEL (0x07) for an error, `z\r`/`Z\r` after a transmitted frame,
//! and reports received frames in the same `t…`/`T…` form (optionally with a 4-digit
//! timestamp). [`LineParser`] splits a byte stream, in any chunking, into [`Token`]s; chassisd's
//! slcan bus (host side) and its emulated adapter (for the simulated chassis) move the bytes.

use crate::can::CanFrame;

/// Ends every slcan message.
pub const CR: u8 = b'\r';
/// The serial line rate an slcan adapter is opened at unless its spec names one (a USB adapter
/// ignores it).
pub const ADAPTER_BAUD: u32 = 115_200;
/// The adapter's "command failed".
pub const BEL: u8 = 0x07;
/// Longest line worth keeping: `T` + 8 id + 1 dlc + 16 data + 4 timestamp.
pub const MAX_LINE: usize = 32;

/// The `Sn` command for a bit rate, if the protocol has one.
pub fn bitrate_command(bits_per_s: u32) -> Option<&'static str> {
    Some(match bits_per_s {
        10_000 => "S0",
        20_000 => "S1",
        50_000 => "S2",
        100_000 => "S3",
        125_000 => "S4",
        250_000 => "S5",
        500_000 => "S6",
        800_000 => "S7",
        1_000_000 => "S8",
        _ => return None,
    })
}

/// `tIIILDD…\r` / `TIIIIIIIILDD…\r`.
pub fn encode_frame(frame: &CanFrame) -> Vec<u8> {
    let mut out = if frame.is_extended() {
        format!("T{:08X}{:X}", frame.id(), frame.len())
    } else {
        format!("t{:03X}{:X}", frame.id(), frame.len())
    };
    for b in frame.data() {
        out.push_str(&format!("{b:02X}"));
    }
    out.push('\r');
    out.into_bytes()
}

fn hex_value(text: &[u8]) -> Option<u32> {
    if text.is_empty() || text.len() > 8 {
        return None;
    }
    let s = std::str::from_utf8(text).ok()?;
    if !s.bytes().all(|b| b.is_ascii_hexdigit()) {
        return None;
    }
    u32::from_str_radix(s, 16).ok()
}

/// Parses a frame line without its CR (`t1118…`), with or without a 4-digit timestamp.
pub fn decode_frame(line: &[u8]) -> Option<CanFrame> {
    let (extended, id_len) = match line.first()? {
        b't' => (false, 3),
        b'T' => (true, 8),
        _ => return None,
    };
    let id = hex_value(line.get(1..1 + id_len)?)?;
    let dlc = usize::try_from(hex_value(line.get(1 + id_len..2 + id_len)?)?).ok()?;
    if dlc > 8 {
        return None;
    }
    let data_start = 2 + id_len;
    let data_end = data_start + 2 * dlc;
    // Nothing after the data, or a timestamp of four hex digits.
    let timestamp = line.get(data_end..)?;
    if !(timestamp.is_empty()
        || timestamp.len() == 4 && timestamp.iter().all(u8::is_ascii_hexdigit))
    {
        return None;
    }
    let mut data = [0u8; 8];
    for (i, byte) in data.iter_mut().take(dlc).enumerate() {
        let at = data_start + 2 * i;
        // Two hex digits always fit a byte.
        *byte = hex_value(line.get(at..at + 2)?)? as u8;
    }
    if extended {
        CanFrame::new_extended(id, &data[..dlc]).ok()
    } else {
        CanFrame::new(id, &data[..dlc]).ok()
    }
}

/// One item of an slcan byte stream.
#[derive(Debug, Clone, PartialEq)]
pub enum Token {
    /// An empty line: OK.
    Ack,
    /// `z` / `Z`: a frame was transmitted.
    TxAck,
    /// BEL: the last command failed.
    Error,
    /// A received frame.
    Frame(CanFrame),
    /// Any other line (commands on the adapter side, version replies on the host side).
    Line(Vec<u8>),
    /// A line too long or not text: dropped.
    Garbage(usize),
}

/// Splits an slcan byte stream into [`Token`]s, in any chunking.
#[derive(Debug, Default)]
pub struct LineParser {
    line: Vec<u8>,
    overlong: usize,
}

impl LineParser {
    /// Feeds bytes; `emit` gets every complete token.
    pub fn push(&mut self, bytes: &[u8], mut emit: impl FnMut(Token)) {
        for &b in bytes {
            match b {
                BEL => emit(Token::Error),
                CR => {
                    if self.overlong > 0 {
                        emit(Token::Garbage(self.overlong));
                        self.overlong = 0;
                    } else {
                        emit(Self::token(&self.line));
                    }
                    self.line.clear();
                }
                // Some adapters end lines with CR LF.
                b'\n' if self.line.is_empty() => {}
                _ => {
                    if self.overlong > 0 || self.line.len() >= MAX_LINE {
                        self.overlong += self.line.len() + 1;
                        self.line.clear();
                    } else {
                        self.line.push(b);
                    }
                }
            }
        }
    }

    /// Bytes of the line not yet ended (never more than [`MAX_LINE`]).
    pub fn pending(&self) -> usize {
        self.line.len()
    }

    fn token(line: &[u8]) -> Token {
        match line.first() {
            None => Token::Ack,
            Some(b'z' | b'Z') if line.len() == 1 => Token::TxAck,
            Some(b't' | b'T') => match decode_frame(line) {
                Some(frame) => Token::Frame(frame),
                None => Token::Garbage(line.len()),
            },
            Some(_) => Token::Line(line.to_vec()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn frame(text: &str) -> CanFrame {
        CanFrame::from_candump(text).unwrap()
    }

    fn tokens(bytes: &[u8]) -> Vec<Token> {
        let mut p = LineParser::default();
        let mut out = Vec::new();
        p.push(bytes, |t| out.push(t));
        out
    }

    #[test]
    fn frames_encode_as_lawicel_text() {
        assert_eq!(
            encode_frame(&frame("111#0096000000000000")),
            b"t11180096000000000000\r"
        );
        assert_eq!(encode_frame(&frame("43A#EE")), b"t43A1EE\r");
        assert_eq!(encode_frame(&frame("18FF0001#0102")), b"T18FF000120102\r");
        assert_eq!(encode_frame(&frame("7FF#")), b"t7FF0\r");
    }

    #[test]
    fn frames_decode_with_and_without_timestamps() {
        assert_eq!(
            decode_frame(b"t11180096000000000000"),
            Some(frame("111#0096000000000000"))
        );
        assert_eq!(decode_frame(b"t43A1EE1A2B"), Some(frame("43A#EE")));
        assert_eq!(
            decode_frame(b"T18FF000120102"),
            Some(frame("18FF0001#0102"))
        );
        for bad in [
            &b"t11"[..],
            b"t1119",
            b"t1112AA",
            b"t1111GG",
            b"x1110",
            b"t1110AB",
        ] {
            assert_eq!(
                decode_frame(bad),
                None,
                "{:?}",
                String::from_utf8_lossy(bad)
            );
        }
    }

    /// Found by fuzzing (`slcan_stream`): a timestamp that is not four hex digits was taken.
    #[test]
    fn a_frame_line_whose_timestamp_is_not_hex_is_refused() {
        for bad in [
            &b"t12381122334455667788)9AA"[..],
            b"t43A1EEzzzz",
            b"t1110t111",
            b"T18FF00012010 \x00\x00 ",
        ] {
            assert_eq!(
                decode_frame(bad),
                None,
                "{:?}",
                String::from_utf8_lossy(bad)
            );
        }
        assert_eq!(
            decode_frame(b"t1238112233445566778899AA"),
            Some(frame("123#1122334455667788"))
        );
    }

    #[test]
    fn acks_and_bell_errors_are_tolerated_in_any_chunking() {
        let stream = b"\r\x07z\rt43A1EE\rV1013\r";
        let expected = vec![
            Token::Ack,
            Token::Error,
            Token::TxAck,
            Token::Frame(frame("43A#EE")),
            Token::Line(b"V1013".to_vec()),
        ];
        assert_eq!(tokens(stream), expected);
        let mut p = LineParser::default();
        let mut out = Vec::new();
        for b in stream {
            p.push(&[*b], |t| out.push(t));
        }
        assert_eq!(out, expected);
    }

    #[test]
    fn overlong_lines_are_dropped_and_the_next_frame_survives() {
        let mut stream = vec![b'x'; 100];
        stream.extend_from_slice(b"\rt43A1EE\r");
        let out = tokens(&stream);
        assert!(matches!(out[0], Token::Garbage(n) if n >= 100));
        assert_eq!(out[1], Token::Frame(frame("43A#EE")));
    }

    #[test]
    fn bitrates_map_to_lawicel_commands() {
        assert_eq!(bitrate_command(500_000), Some("S6"));
        assert_eq!(bitrate_command(1_000_000), Some("S8"));
        assert_eq!(bitrate_command(33_333), None);
    }

    proptest! {
        #[test]
        fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..300)) {
            let _ = tokens(&bytes);
        }

        #[test]
        fn any_frame_round_trips(id in 0u32..=0x7FF, data in proptest::collection::vec(any::<u8>(), 0..=8)) {
            let f = CanFrame::new(id, &data).unwrap();
            let text = encode_frame(&f);
            prop_assert_eq!(tokens(&text), vec![Token::Frame(f)]);
        }
    }
}
