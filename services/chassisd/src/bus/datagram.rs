//! Socket-pair transports: CAN frames as Unix datagrams and byte streams as a Unix stream.
//!
//! The in-process simulated chassis sits at the other end of one of these, so the service talks
//! to the simulator through a real file descriptor, exactly as it talks to a real bus.

use std::io::{self, Read, Write};
use std::os::fd::{AsRawFd, RawFd};
use std::os::unix::net::{UnixDatagram, UnixStream};

use chassis_protocols::CanFrame;

use super::{BusError, ByteBus, CanBus, classify};

/// Wire form of one CAN frame in a datagram: id (u32 LE), length, flags (bit 0: extended id),
/// two spare bytes, eight data bytes.
const DATAGRAM_LEN: usize = 16;

fn to_datagram(frame: &CanFrame) -> [u8; DATAGRAM_LEN] {
    let mut buf = [0u8; DATAGRAM_LEN];
    buf[..4].copy_from_slice(&frame.id().to_le_bytes());
    // A classic frame holds at most 8 bytes.
    buf[4] = frame.len() as u8;
    buf[5] = u8::from(frame.is_extended());
    buf[8..8 + frame.len()].copy_from_slice(frame.data());
    buf
}

fn from_datagram(buf: &[u8]) -> Option<CanFrame> {
    if buf.len() != DATAGRAM_LEN {
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

/// One end of a CAN link over a Unix datagram socket pair.
#[derive(Debug)]
pub struct DatagramCan {
    socket: UnixDatagram,
    name: String,
}

impl DatagramCan {
    /// Two connected ends.
    pub fn pair(name: &str) -> io::Result<(Self, Self)> {
        let (a, b) = UnixDatagram::pair()?;
        a.set_nonblocking(true)?;
        b.set_nonblocking(true)?;
        Ok((
            Self {
                socket: a,
                name: name.to_string(),
            },
            Self {
                socket: b,
                name: format!("{name} (chassis side)"),
            },
        ))
    }
}

impl CanBus for DatagramCan {
    fn recv(&mut self) -> Result<Option<CanFrame>, BusError> {
        let mut buf = [0u8; 64];
        loop {
            match self.socket.recv(&mut buf) {
                // A datagram of the wrong shape cannot come from our own peer; skip it.
                Ok(n) => match from_datagram(&buf[..n]) {
                    Some(frame) => return Ok(Some(frame)),
                    None => continue,
                },
                Err(err) => return classify(&self.name, err, false).map(|()| None),
            }
        }
    }

    fn send(&mut self, frame: &CanFrame) -> Result<(), BusError> {
        match self.socket.send(&to_datagram(frame)) {
            Ok(_) => Ok(()),
            Err(err) if err.kind() == io::ErrorKind::WouldBlock => Err(BusError::TxDropped {
                name: self.name.clone(),
                source: err,
            }),
            Err(err) => classify(&self.name, err, true),
        }
    }

    fn raw_fd(&self) -> RawFd {
        self.socket.as_raw_fd()
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
    fn can_frames_cross_a_datagram_pair_unchanged() {
        let (mut a, mut b) = DatagramCan::pair("sim").unwrap();
        assert_eq!(b.recv().unwrap(), None);
        let frame = CanFrame::from_candump("111#0096000000000000").unwrap();
        let ext = CanFrame::from_candump("18FF0001#0102").unwrap();
        a.send(&frame).unwrap();
        a.send(&ext).unwrap();
        assert_eq!(b.recv().unwrap(), Some(frame));
        assert_eq!(b.recv().unwrap(), Some(ext));
        assert_eq!(b.recv().unwrap(), None);
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
