//! SocketCAN (Linux kernel CAN) through the `socketcan` crate.

use std::os::fd::{AsRawFd, RawFd};

use chassis_protocols::CanFrame;
use socketcan::{CanSocket, EmbeddedFrame, ExtendedId, Id, Socket, StandardId};

use super::{BusError, CanBus, classify};

/// A raw CAN socket bound to one interface, non-blocking. Error frames and remote frames are
/// skipped (these robots use neither).
#[derive(Debug)]
pub struct SocketCan {
    socket: CanSocket,
    name: String,
}

impl SocketCan {
    pub fn open(iface: &str) -> Result<Self, BusError> {
        let name = format!("can:{iface}");
        let open_err = |e: std::io::Error| BusError::Open {
            name: name.clone(),
            reason: e.to_string(),
        };
        let socket = CanSocket::open(iface).map_err(open_err)?;
        // Binding to an interface that is down succeeds, with ENETDOWN left pending on the
        // socket: the first read would report the bus lost again at once, and the service would
        // "reopen" it every 100 ms, clearing BUS_DOWN each time. A down interface is not open.
        if let Some(err) = socket.as_raw_socket().take_error().map_err(open_err)? {
            return Err(BusError::Open {
                reason: format!("{iface} is down ({err})"),
                name,
            });
        }
        socket.set_nonblocking(true).map_err(open_err)?;
        Ok(Self { socket, name })
    }
}

fn to_socketcan(frame: &CanFrame) -> Option<socketcan::CanFrame> {
    let id: Id = if frame.is_extended() {
        ExtendedId::new(frame.id())?.into()
    } else {
        // Standard ids are at most 0x7FF.
        StandardId::new(frame.id() as u16)?.into()
    };
    socketcan::CanFrame::new(id, frame.data())
}

fn from_socketcan(frame: &socketcan::CanFrame) -> Option<CanFrame> {
    match frame {
        socketcan::CanFrame::Data(data) => match data.id() {
            Id::Standard(id) => CanFrame::new(id.as_raw().into(), data.data()).ok(),
            Id::Extended(id) => CanFrame::new_extended(id.as_raw(), data.data()).ok(),
        },
        socketcan::CanFrame::Remote(_) | socketcan::CanFrame::Error(_) => None,
    }
}

impl CanBus for SocketCan {
    fn recv(&mut self) -> Result<Option<CanFrame>, BusError> {
        loop {
            match self.socket.read_frame() {
                Ok(frame) => match from_socketcan(&frame) {
                    Some(frame) => return Ok(Some(frame)),
                    None => continue,
                },
                Err(err) => return classify(&self.name, err, false).map(|()| None),
            }
        }
    }

    fn send(&mut self, frame: &CanFrame) -> Result<(), BusError> {
        let Some(frame) = to_socketcan(frame) else {
            return Err(BusError::Protocol {
                name: self.name.clone(),
                reason: format!("{frame} cannot be sent"),
            });
        };
        match self.socket.write_frame(&frame) {
            Ok(()) => Ok(()),
            // The socket's send buffer is full: this frame is not sent (`classify` would call a
            // would-block "nothing to do", and the frame would count as sent).
            Err(err) if err.kind() == std::io::ErrorKind::WouldBlock => Err(BusError::TxDropped {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_convert_both_ways() {
        for text in ["111#0096000000000000", "43A#EE", "18FF0001#0102", "7FF#"] {
            let frame = CanFrame::from_candump(text).unwrap();
            let kernel = to_socketcan(&frame).unwrap();
            assert_eq!(from_socketcan(&kernel), Some(frame), "{text}");
        }
    }

    #[test]
    fn opening_a_missing_interface_is_a_clear_error() {
        let err = SocketCan::open("nosuchcan0").unwrap_err();
        assert!(
            err.to_string().starts_with("cannot open can:nosuchcan0"),
            "{err}"
        );
    }
}
