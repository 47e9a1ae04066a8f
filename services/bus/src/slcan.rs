//! Lawicel slcan: CAN through a serial CAN adapter (CANable, USBtin, …) without kernel CAN.
//!
//! The text itself (frames, acks, BEL errors, the line splitter) is sans-IO, in
//! [`chassis_protocols::slcan`]. [`SlcanBus`] is the host side over a [`ByteBus`];
//! [`SlcanAdapter`] plays the adapter for the simulated chassis (`chassisd sim --bus
//! slcan-pty:LINK`).

use std::os::fd::RawFd;

use chassis_protocols::CanFrame;
use chassis_protocols::slcan::{BEL, CR, LineParser, Token, bitrate_command, encode_frame};

use super::{BusError, ByteBus, CanBus};

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
        while self.pending.is_empty() && self.fill()? {}
        Ok(self.pending.pop_front())
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
        while self.pending.is_empty() && self.fill()? {}
        Ok(self.pending.pop_front())
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
