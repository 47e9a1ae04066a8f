//! SocketCAN (Linux kernel CAN) through the `socketcan` crate.
//!
//! The socket asks for every class of error frame (`CAN_RAW_ERR_FILTER` = `CAN_ERR_MASK`): the
//! kernel's reports on the controller (error-warning, error-passive, bus-off, restarted, the
//! error counters) and on the bus (protocol violations, missing acknowledgements). The crate
//! decodes them ([`socketcan::errors::CanError`], after `linux/can/error.h`); [`report_of`]
//! turns one into a [`ControllerReport`] for the service ([`crate::can_controller`]). On a
//! bus-off the interface's `restart-ms` is read over netlink, so the log can say whether the
//! kernel will restart the controller or what to run; when the bus is opened, the controller's
//! state is read the same way (a controller already bus-off or error-passive sends no frame to say so).

use std::collections::VecDeque;
use std::os::fd::{AsRawFd, RawFd};

use chassis_interfaces::ControllerState;
use chassis_protocols::CanFrame;
use socketcan::errors::{CanError, ControllerProblems};
use socketcan::nl::CanState;
use socketcan::{
    CanInterface, CanSocket, EmbeddedFrame, ExtendedId, Id, Socket, SocketOptions, StandardId,
};

use super::{BusError, CanBus, CanEvent, classify};
use crate::can_controller::ControllerReport;

/// A raw CAN socket bound to one interface, non-blocking, with every error frame asked for.
/// Remote frames are skipped (these robots use none).
#[derive(Debug)]
pub struct SocketCan {
    socket: CanSocket,
    iface: String,
    name: String,
    /// Reports not handed out yet: the controller's state read at open.
    reports: VecDeque<ControllerReport>,
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
        socket.set_error_filter_accept_all().map_err(open_err)?;
        let reports = interface_state(iface).into_iter().collect();
        Ok(Self {
            socket,
            iface: iface.to_string(),
            name,
            reports,
        })
    }
}

/// The controller's state and `restart-ms` as the interface reports them over netlink (`ip
/// -details link show`): `None` when it reports no state (a vcan has no controller) or cannot
/// be asked.
fn interface_state(iface: &str) -> Option<ControllerReport> {
    let details = match CanInterface::open(iface).and_then(|i| i.details()) {
        Ok(details) => details,
        Err(err) => {
            tracing::debug!(iface, "reading the controller's state over netlink: {err}");
            return None;
        }
    };
    let state = match details.can.state? {
        CanState::ErrorActive => ControllerState::ERROR_ACTIVE,
        CanState::ErrorWarning => ControllerState::ERROR_WARNING,
        CanState::ErrorPassive => ControllerState::ERROR_PASSIVE,
        CanState::BusOff => ControllerState::BUS_OFF,
        CanState::Stopped | CanState::Sleeping => return None,
    };
    let counters = details.can.berr_counter.map(|c| {
        let clamp = |n: u16| u8::try_from(n).unwrap_or(u8::MAX);
        (clamp(c.txerr), clamp(c.rxerr))
    });
    Some(ControllerReport {
        state,
        counters,
        restart_ms: details.can.restart_ms,
        ..ControllerReport::default()
    })
}

/// The interface's `restart-ms`, `None` when it cannot be read.
fn restart_ms(iface: &str) -> Option<u32> {
    match CanInterface::open(iface).and_then(|i| i.restart_ms()) {
        Ok(ms) => ms,
        Err(err) => {
            tracing::debug!(iface, "reading restart-ms over netlink: {err}");
            None
        }
    }
}

/// What an error frame says about the controller (the classes of `linux/can/error.h`).
pub fn report_of(error: &CanError) -> ControllerReport {
    let mut report = ControllerReport {
        from_frame: true,
        counters: error.counters(),
        restarted: error.is_restarted(),
        no_ack: error.is_no_ack(),
        bus_error: error.is_bus_error() || error.protocol().is_some(),
        ..ControllerReport::default()
    };
    if let Some(problems) = error.controller() {
        report.overflow =
            problems.intersects(ControllerProblems::RX_OVERFLOW | ControllerProblems::TX_OVERFLOW);
        // `can_change_state()` reports the state entered, the transmit and the receive side
        // each; the worse of the two is the controller's.
        report.state = if problems
            .intersects(ControllerProblems::TX_PASSIVE | ControllerProblems::RX_PASSIVE)
        {
            ControllerState::ERROR_PASSIVE
        } else if problems
            .intersects(ControllerProblems::TX_WARNING | ControllerProblems::RX_WARNING)
        {
            ControllerState::ERROR_WARNING
        } else if problems.contains(ControllerProblems::ACTIVE) {
            ControllerState::ERROR_ACTIVE
        } else {
            ControllerState::UNKNOWN
        };
    }
    if error.is_bus_off() {
        report.state = ControllerState::BUS_OFF;
    }
    report
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
            match self.recv_event()? {
                Some(CanEvent::Frame(frame)) => return Ok(Some(frame)),
                Some(CanEvent::Controller(_)) => continue,
                None => return Ok(None),
            }
        }
    }

    fn recv_event(&mut self) -> Result<Option<CanEvent>, BusError> {
        if let Some(report) = self.reports.pop_front() {
            return Ok(Some(CanEvent::Controller(report)));
        }
        loop {
            match self.socket.read_frame() {
                Ok(socketcan::CanFrame::Error(frame)) => {
                    let mut report = report_of(&frame.into_error());
                    if report.state == ControllerState::BUS_OFF {
                        report.restart_ms = restart_ms(&self.iface);
                    }
                    return Ok(Some(CanEvent::Controller(report)));
                }
                Ok(frame) => match from_socketcan(&frame) {
                    Some(frame) => return Ok(Some(CanEvent::Frame(frame))),
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

    /// An error frame as `read(2)` delivers it: `can_id` = `CAN_ERR_FLAG` | the classes, DLC 8
    /// (`CAN_ERR_DLC`), and the data bytes each class points at. The values are those of
    /// `include/uapi/linux/can/error.h` (the classes `CAN_ERR_CRTL` 0x004, `CAN_ERR_PROT` 0x008,
    /// `CAN_ERR_ACK` 0x020, `CAN_ERR_BUSOFF` 0x040, `CAN_ERR_BUSERROR` 0x080,
    /// `CAN_ERR_RESTARTED` 0x100, `CAN_ERR_CNT` 0x200; data[1] `CAN_ERR_CRTL_RX_WARNING` 0x04,
    /// `_TX_WARNING` 0x08, `_RX_PASSIVE` 0x10, `_TX_PASSIVE` 0x20, `_ACTIVE` 0x40; data[2]
    /// `CAN_ERR_PROT_BIT0` 0x08, `CAN_ERR_PROT_TX` 0x80; data[3] `CAN_ERR_PROT_LOC_ACK` 0x19;
    /// data[6], data[7] the transmit and receive error counters), as the kernel's
    /// `can_change_state()`, `can_bus_off()` and `can_restart()` (drivers/net/can/dev/dev.c) fill
    /// them.
    fn kernel_error_frame(classes: u32, data: [u8; 8]) -> ControllerReport {
        const CAN_ERR_FLAG: u32 = 0x2000_0000;
        let mut raw = socketcan::frame::can_frame_default();
        raw.can_id = CAN_ERR_FLAG | classes;
        raw.can_dlc = 8;
        raw.data = data;
        let frame = socketcan::CanFrame::from(raw);
        let socketcan::CanFrame::Error(frame) = frame else {
            panic!("{classes:#x} is no error frame: {frame:?}");
        };
        report_of(&frame.into_error())
    }

    #[test]
    fn the_kernels_error_frames_become_the_controllers_state_and_counts() {
        // can_change_state() to warning (tx side), with the counters (CAN_ERR_CNT).
        let r = kernel_error_frame(0x004 | 0x200, [0, 0x08, 0, 0, 0, 0, 96, 3]);
        assert_eq!(
            (r.state, r.counters),
            (ControllerState::ERROR_WARNING, Some((96, 3)))
        );
        // to error-passive on both sides (tx_state == rx_state: both bits).
        let r = kernel_error_frame(0x004 | 0x200, [0, 0x30, 0, 0, 0, 0, 128, 130]);
        assert_eq!(r.state, ControllerState::ERROR_PASSIVE);
        // The receive side worse than the transmit side: only its bits are set.
        let r = kernel_error_frame(0x004 | 0x200, [0, 0x10, 0, 0, 0, 0, 100, 128]);
        assert_eq!(r.state, ControllerState::ERROR_PASSIVE);
        // back to error-active (CAN_ERR_CRTL_ACTIVE).
        let r = kernel_error_frame(0x004, [0, 0x40, 0, 0, 0, 0, 0, 0]);
        assert_eq!(r.state, ControllerState::ERROR_ACTIVE);
        // can_change_state() into bus-off sets CAN_ERR_BUSOFF only.
        let r = kernel_error_frame(0x040, [0; 8]);
        assert_eq!(r.state, ControllerState::BUS_OFF);
        assert!(r.from_frame && !r.restarted);
        // can_restart(): CAN_ERR_RESTARTED, no state byte.
        let r = kernel_error_frame(0x100, [0; 8]);
        assert!(r.restarted);
        assert_eq!(r.state, ControllerState::UNKNOWN);
        // A bus error while transmitting, at the ACK slot (an sja1000 alone on the bus).
        let r = kernel_error_frame(0x008 | 0x080 | 0x200, [0, 0, 0x88, 0x19, 0, 0, 8, 0]);
        assert!(r.bus_error && !r.no_ack);
        assert_eq!(r.counters, Some((8, 0)));
        // The receive FIFO overflowed (CAN_ERR_CRTL_RX_OVERFLOW 0x01, with the counters), as
        // QEMU's emulated SJA1000 reports it under load: frames lost, the state unchanged.
        let r = kernel_error_frame(0x004 | 0x200, [0, 0x01, 0, 0, 0, 0, 0, 0]);
        assert!(r.overflow && !r.bus_error, "{r:?}");
        assert_eq!(
            (r.state, r.counters),
            (ControllerState::UNKNOWN, Some((0, 0)))
        );
        // No acknowledgement (CAN_ERR_ACK), as m_can and flexcan report it.
        let r = kernel_error_frame(0x020 | 0x080, [0; 8]);
        assert!(r.no_ack && r.bus_error);
        assert_eq!(r.state, ControllerState::UNKNOWN);
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
