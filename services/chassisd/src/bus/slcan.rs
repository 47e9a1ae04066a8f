//! Lawicel slcan: CAN through a serial CAN adapter (CANable, USBtin, …) without kernel CAN.
//!
//! ASCII over a serial line, every message ended by CR: the host sends `S6` (500 kbit/s), `O`
//! (open the channel) and frames as `tIIILDD…` (standard id) or `TIIIIIIIILDD…` (extended); the
//! adapter answers `\r` for OK, BEL (0x07) for an error, `z\r`/`Z\r` after a transmitted frame,
//! and reports received frames in the same `t…`/`T…` form (optionally with a 4-digit
//! timestamp). [`SlcanBus`] is the host side; [`SlcanAdapter`] plays the adapter for the
//! simulated chassis (`chassisd sim --bus slcan-pty:LINK`).

use std::os::fd::RawFd;

use chassis_protocols::CanFrame;

use super::{BusError, ByteBus, CanBus};

const CR: u8 = b'\r';
const BEL: u8 = 0x07;
/// Longest line worth keeping: `T` + 8 id + 1 dlc + 16 data + 4 timestamp.
const MAX_LINE: usize = 32;

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
    let rest = line.len().checked_sub(data_end)?;
    if rest != 0 && rest != 4 {
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

/// Counters of an slcan link.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct SlcanStats {
    pub errors: u64,
    pub garbage_bytes: u64,
    pub tx_acks: u64,
}

/// The host side: a [`CanBus`] over an slcan adapter on a byte bus.
#[derive(Debug)]
pub struct SlcanBus<B: ByteBus> {
    port: B,
    parser: LineParser,
    pending: std::collections::VecDeque<CanFrame>,
    stats: SlcanStats,
    name: String,
}

impl<B: ByteBus> SlcanBus<B> {
    /// Opens the channel: `C` (in case it was left open), the bit rate, `O`.
    pub fn open(mut port: B, bits_per_s: u32) -> Result<Self, BusError> {
        let name = format!("slcan:{}", port.name().trim_start_matches("serial:"));
        let rate = bitrate_command(bits_per_s).ok_or_else(|| BusError::Open {
            name: name.clone(),
            reason: format!("slcan has no command for {bits_per_s} bit/s"),
        })?;
        for command in ["C", rate, "O"] {
            port.write_all(format!("{command}\r").as_bytes())?;
        }
        Ok(Self {
            port,
            parser: LineParser::default(),
            pending: std::collections::VecDeque::new(),
            stats: SlcanStats::default(),
            name,
        })
    }

    pub fn stats(&self) -> SlcanStats {
        self.stats
    }

    fn fill(&mut self) -> Result<bool, BusError> {
        let mut buf = [0u8; 512];
        let n = self.port.read(&mut buf)?;
        let stats = &mut self.stats;
        let pending = &mut self.pending;
        self.parser.push(&buf[..n], |token| match token {
            Token::Frame(frame) => pending.push_back(frame),
            Token::Error => stats.errors += 1,
            Token::TxAck => stats.tx_acks += 1,
            Token::Garbage(len) => stats.garbage_bytes += len as u64,
            Token::Ack | Token::Line(_) => {}
        });
        Ok(n > 0)
    }
}

impl<B: ByteBus> CanBus for SlcanBus<B> {
    fn recv(&mut self) -> Result<Option<CanFrame>, BusError> {
        loop {
            if let Some(frame) = self.pending.pop_front() {
                return Ok(Some(frame));
            }
            if !self.fill()? {
                return Ok(None);
            }
        }
    }

    fn send(&mut self, frame: &CanFrame) -> Result<(), BusError> {
        self.port.write_all(&encode_frame(frame))
    }

    fn raw_fd(&self) -> RawFd {
        self.port.raw_fd()
    }

    fn name(&self) -> &str {
        &self.name
    }
}

impl<B: ByteBus> Drop for SlcanBus<B> {
    fn drop(&mut self) {
        // Close the channel so the adapter stops forwarding. Best effort: the port may already
        // be gone, and a dropped bus has nobody left to report to.
        if let Err(err) = self.port.write_all(b"C\r") {
            tracing::debug!(bus = %self.name, "closing the slcan channel: {err}");
        }
    }
}

/// The adapter side, for the simulated chassis: answers the host's commands like a CANable and
/// exposes the frames as a [`CanBus`].
#[derive(Debug)]
pub struct SlcanAdapter<B: ByteBus> {
    port: B,
    parser: LineParser,
    open: bool,
    pending: std::collections::VecDeque<CanFrame>,
    replies: Vec<u8>,
    name: String,
}

impl<B: ByteBus> SlcanAdapter<B> {
    pub fn new(port: B) -> Self {
        let name = format!("slcan-adapter:{}", port.name());
        Self {
            port,
            parser: LineParser::default(),
            open: false,
            pending: std::collections::VecDeque::new(),
            replies: Vec::new(),
            name,
        }
    }

    /// True once the host has opened the channel.
    pub fn is_open(&self) -> bool {
        self.open
    }

    fn fill(&mut self) -> Result<bool, BusError> {
        let mut buf = [0u8; 512];
        let n = self.port.read(&mut buf)?;
        let open = &mut self.open;
        let pending = &mut self.pending;
        let replies = &mut self.replies;
        self.parser.push(&buf[..n], |token| match token {
            Token::Frame(frame) if *open => {
                pending.push_back(frame);
                replies.extend_from_slice(if frame.is_extended() { b"Z\r" } else { b"z\r" });
            }
            Token::Line(line) => match line.as_slice() {
                b"O" | b"L" => {
                    *open = true;
                    replies.push(CR);
                }
                b"C" => {
                    *open = false;
                    replies.push(CR);
                }
                [b'S', b'0'..=b'8'] | [b'Z', b'0' | b'1'] => replies.push(CR),
                b"V" => replies.extend_from_slice(b"V1013\r"),
                b"N" => replies.extend_from_slice(b"NSIM1\r"),
                b"F" => replies.extend_from_slice(b"F00\r"),
                _ => replies.push(BEL),
            },
            Token::Ack => replies.push(CR),
            Token::Frame(_) | Token::Garbage(_) | Token::Error | Token::TxAck => replies.push(BEL),
        });
        if !self.replies.is_empty() {
            let replies = std::mem::take(&mut self.replies);
            self.port.write_all(&replies)?;
        }
        Ok(n > 0)
    }
}

impl<B: ByteBus> CanBus for SlcanAdapter<B> {
    fn recv(&mut self) -> Result<Option<CanFrame>, BusError> {
        loop {
            if let Some(frame) = self.pending.pop_front() {
                return Ok(Some(frame));
            }
            if !self.fill()? {
                return Ok(None);
            }
        }
    }

    fn send(&mut self, frame: &CanFrame) -> Result<(), BusError> {
        if !self.open {
            // A closed adapter forwards nothing from the bus.
            return Ok(());
        }
        self.port.write_all(&encode_frame(frame))
    }

    fn raw_fd(&self) -> RawFd {
        self.port.raw_fd()
    }

    fn name(&self) -> &str {
        &self.name
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
