//! Socket-pair transports: CAN frames as fixed records on a Unix stream, and byte streams as a
//! Unix stream.
//!
//! The in-process simulated chassis (and the replay of a recording) sits at the other end of one
//! of these, so the service talks to it through a real file descriptor, exactly as it talks to a
//! real bus.

use std::io::{self, Read, Write};
use std::os::fd::{AsRawFd, RawFd};
use std::os::unix::net::UnixStream;

use chassis_protocols::CanFrame;

use super::{Bus, BusError, ByteBus, CanBus, classify};

/// Wire form of one CAN frame on the pair: id (u32 LE), length, flags (bit 0: extended id), two
/// spare bytes, eight data bytes.
const RECORD: usize = 16;
/// Bytes read per system call: up to 256 frames.
const READ_CHUNK: usize = 256 * RECORD;
/// Buffered sends are written once this much is waiting (or on `flush`).
const WRITE_AT: usize = 64 * RECORD;
/// Most bytes a sender buffers while its peer does not read; beyond, frames are dropped.
const TX_CAP: usize = 4096 * RECORD;

fn to_record(frame: &CanFrame) -> [u8; RECORD] {
    let mut buf = [0u8; RECORD];
    buf[..4].copy_from_slice(&frame.id().to_le_bytes());
    // A classic frame holds at most 8 bytes.
    buf[4] = frame.len() as u8;
    buf[5] = u8::from(frame.is_extended());
    buf[8..8 + frame.len()].copy_from_slice(frame.data());
    buf
}

fn from_record(buf: &[u8]) -> Option<CanFrame> {
    if buf.len() != RECORD {
        return None;
    }
    let id = u32::from_le_bytes([buf[0], buf[1], buf[2], buf[3]]);
    let len = usize::from(buf[4]);
    let data = buf.get(8..8 + len)?;
    if buf[5] & 1 != 0 {
        CanFrame::new_extended(id, data).ok()
    } else {
        CanFrame::new(id, data).ok()
    }
}

/// One end of a CAN link over a Unix stream socket pair, carrying fixed 16-byte records.
///
/// Reads take up to 256 frames per system call; sends are buffered until [`CanBus::flush`] (or
/// until 64 frames wait), so a burst costs one write and one read instead of one per frame.
#[derive(Debug)]
pub struct PairCan {
    stream: UnixStream,
    rx: Vec<u8>,
    rx_pos: usize,
    /// The last read came back short: the socket was empty then. The next call that finds the
    /// buffer empty reports nothing pending instead of asking the kernel again (the descriptor
    /// stays readable if more came meanwhile, so nothing waits unseen).
    drained: bool,
    tx: Vec<u8>,
    name: String,
}

impl PairCan {
    /// Two connected ends.
    pub fn pair(name: &str) -> io::Result<(Self, Self)> {
        let (a, b) = UnixStream::pair()?;
        a.set_nonblocking(true)?;
        b.set_nonblocking(true)?;
        let end = |stream, name: String| Self {
            stream,
            rx: Vec::with_capacity(READ_CHUNK),
            rx_pos: 0,
            drained: false,
            tx: Vec::with_capacity(WRITE_AT),
            name,
        };
        Ok((
            end(a, name.to_string()),
            end(b, format!("{name} (chassis side)")),
        ))
    }

    fn write_pending(&mut self) -> Result<(), BusError> {
        while !self.tx.is_empty() {
            match self.stream.write(&self.tx) {
                Ok(n) => {
                    self.tx.drain(..n);
                }
                // The peer is slow: what is left goes with the next flush.
                Err(err) if err.kind() == io::ErrorKind::WouldBlock => return Ok(()),
                Err(err) if err.kind() == io::ErrorKind::Interrupted => {}
                Err(err) => return classify(&self.name, err, true),
            }
        }
        Ok(())
    }
}

impl CanBus for PairCan {
    fn recv(&mut self) -> Result<Option<CanFrame>, BusError> {
        loop {
            if self.rx.len() - self.rx_pos >= RECORD {
                let at = self.rx_pos;
                self.rx_pos += RECORD;
                match from_record(&self.rx[at..at + RECORD]) {
                    Some(frame) => return Ok(Some(frame)),
                    // A malformed record cannot come from our own peer; skip it.
                    None => continue,
                }
            }
            if std::mem::take(&mut self.drained) {
                return Ok(None);
            }
            // Keep a partial record, drop what was consumed, read more.
            self.rx.drain(..self.rx_pos);
            self.rx_pos = 0;
            let have = self.rx.len();
            self.rx.resize(have + READ_CHUNK, 0);
            let read = self.stream.read(&mut self.rx[have..]);
            match read {
                Ok(0) => {
                    self.rx.truncate(have);
                    return Err(BusError::Disconnected {
                        name: self.name.clone(),
                        source: io::ErrorKind::UnexpectedEof.into(),
                    });
                }
                Ok(n) => {
                    self.rx.truncate(have + n);
                    self.drained = n < READ_CHUNK;
                }
                Err(err) => {
                    self.rx.truncate(have);
                    return classify(&self.name, err, false).map(|()| None);
                }
            }
        }
    }

    fn send(&mut self, frame: &CanFrame) -> Result<(), BusError> {
        if self.tx.len() + RECORD > TX_CAP {
            self.write_pending()?;
            if self.tx.len() + RECORD > TX_CAP {
                return Err(BusError::TxDropped {
                    name: self.name.clone(),
                    source: io::ErrorKind::WouldBlock.into(),
                });
            }
        }
        self.tx.extend_from_slice(&to_record(frame));
        if self.tx.len() >= WRITE_AT {
            self.write_pending()?;
        }
        Ok(())
    }

    fn flush(&mut self) -> Result<(), BusError> {
        self.write_pending()
    }

    fn unflushed(&self) -> usize {
        self.tx.len().div_ceil(RECORD)
    }

    fn raw_fd(&self) -> RawFd {
        self.stream.as_raw_fd()
    }

    fn name(&self) -> &str {
        &self.name
    }
}

/// One end of a byte link over a Unix stream socket pair.
#[derive(Debug)]
pub struct StreamBytes {
    stream: UnixStream,
    name: String,
}

impl StreamBytes {
    pub fn pair(name: &str) -> io::Result<(Self, Self)> {
        let (a, b) = UnixStream::pair()?;
        a.set_nonblocking(true)?;
        b.set_nonblocking(true)?;
        Ok((
            Self {
                stream: a,
                name: name.to_string(),
            },
            Self {
                stream: b,
                name: format!("{name} (chassis side)"),
            },
        ))
    }
}

/// A pair for a robot on CAN (`can`) or on a byte stream: the service's end, the chassis' end.
pub fn bus_pair(name: &str, can: bool) -> io::Result<(Bus, Bus)> {
    Ok(if can {
        let (a, b) = PairCan::pair(name)?;
        (Bus::Can(Box::new(a)), Bus::Can(Box::new(b)))
    } else {
        let (a, b) = StreamBytes::pair(name)?;
        (Bus::Bytes(Box::new(a)), Bus::Bytes(Box::new(b)))
    })
}

impl ByteBus for StreamBytes {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, BusError> {
        match self.stream.read(buf) {
            Ok(0) => Err(BusError::Disconnected {
                name: self.name.clone(),
                source: io::ErrorKind::UnexpectedEof.into(),
            }),
            Ok(n) => Ok(n),
            Err(err) => classify(&self.name, err, false).map(|()| 0),
        }
    }

    fn write_all(&mut self, mut bytes: &[u8]) -> Result<(), BusError> {
        while !bytes.is_empty() {
            match self.stream.write(bytes) {
                Ok(n) => bytes = &bytes[n..],
                // The peer is slow: its socket buffer is full. A serial line would drop too.
                Err(err) if err.kind() == io::ErrorKind::WouldBlock => {
                    return Err(BusError::TxDropped {
                        name: self.name.clone(),
                        source: err,
                    });
                }
                Err(err) => return classify(&self.name, err, true),
            }
        }
        Ok(())
    }

    fn raw_fd(&self) -> RawFd {
        self.stream.as_raw_fd()
    }

    fn name(&self) -> &str {
        &self.name
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn can_frames_cross_a_pair_unchanged_once_flushed() {
        let (mut a, mut b) = PairCan::pair("sim").unwrap();
        assert_eq!(b.recv().unwrap(), None);
        let frame = CanFrame::from_candump("111#0096000000000000").unwrap();
        let ext = CanFrame::from_candump("18FF0001#0102").unwrap();
        a.send(&frame).unwrap();
        a.send(&ext).unwrap();
        assert_eq!(b.recv().unwrap(), None, "buffered until flushed");
        assert_eq!(a.unflushed(), 2);
        a.flush().unwrap();
        assert_eq!(b.recv().unwrap(), Some(frame));
        assert_eq!(b.recv().unwrap(), Some(ext));
        assert_eq!(b.recv().unwrap(), None);
    }

    #[test]
    fn a_burst_crosses_in_few_system_calls_and_partial_records_wait_for_the_rest() {
        let (mut a, mut b) = PairCan::pair("sim").unwrap();
        let frames: Vec<CanFrame> = (0..1000u32)
            .map(|i| CanFrame::new(i % 0x800, &i.to_le_bytes()).unwrap())
            .collect();
        for f in &frames {
            a.send(f).unwrap();
        }
        a.flush().unwrap();
        let mut got = Vec::new();
        while let Some(f) = b.recv().unwrap() {
            got.push(f);
        }
        assert_eq!(got, frames);
        // Half a record, then the rest.
        let record = to_record(&frames[1]);
        a.stream.write_all(&record[..7]).unwrap();
        assert_eq!(b.recv().unwrap(), None);
        a.stream.write_all(&record[7..]).unwrap();
        assert_eq!(b.recv().unwrap(), Some(frames[1]));
    }

    #[test]
    fn a_closed_can_peer_is_a_disconnect() {
        let (mut a, b) = PairCan::pair("sim").unwrap();
        drop(b);
        assert!(a.recv().unwrap_err().is_disconnect());
    }

    #[test]
    fn a_closed_byte_peer_is_a_disconnect() {
        let (mut a, b) = StreamBytes::pair("sim").unwrap();
        let mut buf = [0u8; 8];
        assert_eq!(a.read(&mut buf).unwrap(), 0);
        drop(b);
        assert!(a.read(&mut buf).unwrap_err().is_disconnect());
    }
}
