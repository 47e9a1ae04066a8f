//! chassis-bus: the bus backends of a robot base behind two small traits, one for CAN
//! ([`CanBus`]) and one for byte streams ([`ByteBus`]), the CAN controller's state as the
//! service keeps it ([`can_controller`]), and the process's monotonic clock that stamps what they
//! read ([`clock`]). A backend knows nothing about robots; it moves frames or bytes and says when
//! the bus is gone. Every backend is non-blocking and exposes a file descriptor, so one event loop
//! can wait on the bus and on everything else at once. `chassisd`, `chassisd sim` and `chassis
//! doctor` open their buses here; one conformance suite ([`conformance`]) runs on every backend.
//!
//! | spec | backend |
//! | --- | --- |
//! | `sim` | the robot's simulated firmware in a thread, over a socket pair (opened by `chassisd`) |
//! | `can:IFACE` | SocketCAN ([`socketcan`]) |
//! | `serial:PATH[@BAUD]` | a serial port or pty ([`serialport`]), 8N1 |
//! | `slcan:PATH[@BAUD]` | a Lawicel slcan adapter on a serial port (CAN without kernel CAN) |
//! | `replay:FILE[@SPEED\|@max]` | a recording (MCAP or candump log) played back in a thread, over a socket pair ([`replay`]) |
//!
//! `chassisd sim` (the firmware as its own process) also accepts `pty:LINK` and
//! `slcan-pty:LINK`: it creates a pseudo-terminal, links its device path to LINK, and speaks the
//! raw link or an slcan adapter's side of it.

use std::fmt;
use std::io;
use std::os::fd::RawFd;
use std::str::FromStr;

use chassis_protocols::{CanFrame, Rx, WireItem};
use thiserror::Error;

use crate::can_controller::ControllerReport;

pub mod can_controller;
pub mod clock;
pub mod conformance;
pub mod datagram;
pub mod mcap_read;
pub mod replay;
pub mod serial;
pub mod slcan;
pub mod socketcan;

/// Why a bus operation failed.
#[derive(Debug, Error)]
pub enum BusError {
    /// The bus is gone (interface down, port unplugged, pty closed): reopen it.
    #[error("{name} is gone: {source}")]
    Disconnected {
        name: String,
        #[source]
        source: io::Error,
    },
    /// One frame could not be sent (transmit queue full); the bus is still there.
    #[error("{name}: frame dropped: {source}")]
    TxDropped {
        name: String,
        #[source]
        source: io::Error,
    },
    /// Opening the bus failed.
    #[error("cannot open {name}: {reason}")]
    Open { name: String, reason: String },
    /// The peer broke the link protocol (an slcan adapter refusing a command).
    #[error("{name}: {reason}")]
    Protocol { name: String, reason: String },
}

impl BusError {
    pub fn is_disconnect(&self) -> bool {
        matches!(self, BusError::Disconnected { .. })
    }
}

/// Maps an I/O error of `name` to "nothing to do now" (`Ok(())`), a dropped frame, or a lost bus.
pub(crate) fn classify(name: &str, err: io::Error, sending: bool) -> Result<(), BusError> {
    use nix::errno::Errno;
    match err.kind() {
        io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted | io::ErrorKind::TimedOut => {
            return Ok(());
        }
        _ => {}
    }
    let errno = err.raw_os_error().map(Errno::from_raw);
    if sending && errno == Some(Errno::ENOBUFS) {
        return Err(BusError::TxDropped {
            name: name.to_string(),
            source: err,
        });
    }
    Err(BusError::Disconnected {
        name: name.to_string(),
        source: err,
    })
}

/// What a CAN bus hands in: a frame, or a report of its controller on itself (SocketCAN's error
/// frames).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CanEvent {
    Frame(CanFrame),
    Controller(ControllerReport),
}

/// A CAN bus: classic frames in and out, non-blocking.
pub trait CanBus: Send + fmt::Debug {
    /// The next received frame, `Ok(None)` when nothing is pending. The controller's reports
    /// are skipped.
    fn recv(&mut self) -> Result<Option<CanFrame>, BusError>;
    /// The next frame or report of the controller, in the order the bus delivered them. A
    /// backend without a controller of its own (a socket pair, slcan) has only frames.
    fn recv_event(&mut self) -> Result<Option<CanEvent>, BusError> {
        Ok(self.recv()?.map(CanEvent::Frame))
    }
    /// Sends one frame. A backend may buffer it until [`CanBus::flush`].
    fn send(&mut self, frame: &CanFrame) -> Result<(), BusError>;
    /// Writes whatever [`CanBus::send`] buffered. Callers flush after each batch of sends.
    fn flush(&mut self) -> Result<(), BusError> {
        Ok(())
    }
    /// Frames buffered by `send` that `flush` could not write yet (the peer is slow).
    fn unflushed(&self) -> usize {
        0
    }
    /// The descriptor that turns readable when a frame is pending.
    fn raw_fd(&self) -> RawFd;
    /// For logs: `can:vcan0`, `slcan:/dev/ttyACM0`, …
    fn name(&self) -> &str;
}

/// A byte stream (serial port, pty), non-blocking.
pub trait ByteBus: Send + fmt::Debug {
    /// Reads what is there into `buf`; `Ok(0)` when nothing is pending.
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, BusError>;
    /// Writes all of `bytes`.
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), BusError>;
    /// The descriptor that turns readable when bytes are pending.
    fn raw_fd(&self) -> RawFd;
    /// For logs: `serial:/dev/ttyUSB0@115200`, …
    fn name(&self) -> &str;
}

/// An open bus of either kind.
#[derive(Debug)]
pub enum Bus {
    Can(Box<dyn CanBus>),
    Bytes(Box<dyn ByteBus>),
}

/// One item read from a bus: received bytes or a frame, or a report of the CAN controller.
#[derive(Debug, Clone, Copy)]
pub enum Received<'a> {
    Rx(Rx<'a>),
    Controller(&'a ControllerReport),
}

/// Most items drained from the bus per wake-up, so a flooding bus cannot starve the rest of the
/// loop (the descriptor stays readable and the loop comes back at once).
pub const MAX_RX_BATCH: usize = 256;

impl Bus {
    pub fn raw_fd(&self) -> RawFd {
        match self {
            Bus::Can(bus) => bus.raw_fd(),
            Bus::Bytes(bus) => bus.raw_fd(),
        }
    }

    pub fn name(&self) -> &str {
        match self {
            Bus::Can(bus) => bus.name(),
            Bus::Bytes(bus) => bus.name(),
        }
    }

    /// Reads what is pending (at most [`MAX_RX_BATCH`] items) and hands each to `sink`. Returns
    /// how many items were read. The CAN controller's reports are read and skipped.
    pub fn receive(&mut self, mut sink: impl FnMut(Rx<'_>)) -> Result<usize, BusError> {
        self.receive_all(|item| {
            if let Received::Rx(rx) = item {
                sink(rx);
            }
        })
    }

    /// Like [`Bus::receive`], with the CAN controller's reports among the frames, in the order
    /// they were read (each counts as an item).
    pub fn receive_all(&mut self, mut sink: impl FnMut(Received<'_>)) -> Result<usize, BusError> {
        let mut count = 0;
        match self {
            Bus::Can(bus) => {
                while count < MAX_RX_BATCH {
                    match bus.recv_event()? {
                        Some(CanEvent::Frame(frame)) => sink(Received::Rx(Rx::Can(&frame))),
                        Some(CanEvent::Controller(report)) => {
                            sink(Received::Controller(&report));
                        }
                        None => break,
                    }
                    count += 1;
                }
            }
            Bus::Bytes(bus) => {
                let mut buf = [0u8; 4096];
                while count < MAX_RX_BATCH {
                    let n = bus.read(&mut buf)?;
                    if n == 0 {
                        break;
                    }
                    sink(Received::Rx(Rx::Bytes(&buf[..n])));
                    count += 1;
                }
            }
        }
        Ok(count)
    }

    /// Sends one item. A CAN frame on a byte bus (or bytes on a CAN bus) is a bug in the caller
    /// and is reported as a protocol error.
    pub fn transmit(&mut self, item: &WireItem) -> Result<(), BusError> {
        match (self, item) {
            (Bus::Can(bus), WireItem::Can(frame)) => bus.send(frame),
            (Bus::Bytes(bus), WireItem::Bytes(bytes)) => bus.write_all(bytes),
            (bus, _) => Err(BusError::Protocol {
                name: bus.name().to_string(),
                reason: "frame kind does not match the bus kind".into(),
            }),
        }
    }

    pub fn is_can(&self) -> bool {
        matches!(self, Bus::Can(_))
    }

    /// Writes what the backend buffered (see [`CanBus::flush`]).
    pub fn flush(&mut self) -> Result<(), BusError> {
        match self {
            Bus::Can(bus) => bus.flush(),
            Bus::Bytes(_) => Ok(()),
        }
    }

    /// Frames still buffered after the last flush.
    pub fn unflushed(&self) -> usize {
        match self {
            Bus::Can(bus) => bus.unflushed(),
            Bus::Bytes(_) => 0,
        }
    }
}

/// A bus named on the command line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum BusSpec {
    /// The embedded simulated chassis.
    Sim,
    /// SocketCAN interface.
    Can { iface: String },
    /// Serial port or pty slave.
    Serial { path: String, baud: Option<u32> },
    /// Lawicel slcan adapter on a serial port.
    Slcan { path: String, baud: Option<u32> },
    /// (`chassisd sim` only) a new pty linked at `link`, raw bytes.
    Pty { link: String },
    /// (`chassisd sim` only) a new pty linked at `link`, speaking an slcan adapter's side.
    SlcanPty { link: String },
    /// A recording played back at the far end of a socket pair ([`replay`]).
    Replay {
        path: String,
        speed: replay::ReplaySpeed,
    },
}

/// Why a bus spec does not parse.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum BusSpecError {
    /// Not a kind of bus this service knows, or a kind without its argument.
    #[error(
        "'{text}': expected sim, can:IFACE, serial:PATH[@BAUD], slcan:PATH[@BAUD], \
         replay:FILE[@SPEED|@max], pty:LINK or slcan-pty:LINK"
    )]
    Unknown { text: String },
    /// A known kind whose argument does not parse.
    #[error("'{text}': {reason}")]
    Argument {
        text: String,
        reason: BusArgumentError,
    },
}

/// Why the argument of a bus spec (after the colon) does not parse.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum BusArgumentError {
    #[error("'{0}' is not a baud rate")]
    BadBaud(String),
    #[error("missing path before '@'")]
    MissingPathBeforeBaud,
    #[error("missing path")]
    MissingPath,
    #[error(transparent)]
    Replay(#[from] replay::ReplaySpecError),
}

fn path_and_baud(rest: &str) -> Result<(String, Option<u32>), BusArgumentError> {
    match rest.rsplit_once('@') {
        Some((path, baud)) => {
            let baud: u32 = baud
                .parse()
                .map_err(|_| BusArgumentError::BadBaud(baud.into()))?;
            if path.is_empty() {
                return Err(BusArgumentError::MissingPathBeforeBaud);
            }
            Ok((path.to_string(), Some(baud)))
        }
        None if rest.is_empty() => Err(BusArgumentError::MissingPath),
        None => Ok((rest.to_string(), None)),
    }
}

impl FromStr for BusSpec {
    type Err = BusSpecError;
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        if text == "sim" {
            return Ok(BusSpec::Sim);
        }
        let unknown = || BusSpecError::Unknown { text: text.into() };
        let (kind, rest) = text.split_once(':').ok_or_else(unknown)?;
        let with = |reason: BusArgumentError| BusSpecError::Argument {
            text: text.into(),
            reason,
        };
        match kind {
            "can" if !rest.is_empty() => Ok(BusSpec::Can {
                iface: rest.to_string(),
            }),
            "serial" => {
                let (path, baud) = path_and_baud(rest).map_err(with)?;
                Ok(BusSpec::Serial { path, baud })
            }
            "slcan" => {
                let (path, baud) = path_and_baud(rest).map_err(with)?;
                Ok(BusSpec::Slcan { path, baud })
            }
            "pty" if !rest.is_empty() => Ok(BusSpec::Pty {
                link: rest.to_string(),
            }),
            "slcan-pty" if !rest.is_empty() => Ok(BusSpec::SlcanPty {
                link: rest.to_string(),
            }),
            "replay" => {
                let (path, speed) =
                    replay::parse_spec(rest).map_err(|e| with(BusArgumentError::Replay(e)))?;
                Ok(BusSpec::Replay { path, speed })
            }
            _ => Err(unknown()),
        }
    }
}

impl fmt::Display for BusSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BusSpec::Sim => f.write_str("sim"),
            BusSpec::Can { iface } => write!(f, "can:{iface}"),
            BusSpec::Serial { path, baud: None } => write!(f, "serial:{path}"),
            BusSpec::Serial {
                path,
                baud: Some(b),
            } => write!(f, "serial:{path}@{b}"),
            BusSpec::Slcan { path, baud: None } => write!(f, "slcan:{path}"),
            BusSpec::Slcan {
                path,
                baud: Some(b),
            } => write!(f, "slcan:{path}@{b}"),
            BusSpec::Pty { link } => write!(f, "pty:{link}"),
            BusSpec::SlcanPty { link } => write!(f, "slcan-pty:{link}"),
            BusSpec::Replay { path, speed } if *speed == replay::ReplaySpeed::RECORDED => {
                write!(f, "replay:{path}")
            }
            BusSpec::Replay { path, speed } => write!(f, "replay:{path}@{speed}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bus_specs_parse_and_print_back() {
        for text in [
            "sim",
            "can:vcan0",
            "serial:/dev/ttyUSB0",
            "serial:/dev/ttyUSB0@115200",
            "slcan:/dev/ttyACM0@921600",
            "pty:/tmp/xbot-link",
            "slcan-pty:/tmp/titan-slcan",
        ] {
            let spec: BusSpec = text.parse().unwrap();
            assert_eq!(spec.to_string(), text);
        }
    }

    #[test]
    fn bad_bus_specs_say_what_is_expected() {
        for bad in [
            "",
            "can:",
            "serial:",
            "serial:/dev/x@fast",
            "usb:1",
            "serial:@9600",
        ] {
            let err = bad.parse::<BusSpec>().unwrap_err().to_string();
            assert!(err.contains(bad) || bad.is_empty(), "{bad}: {err}");
        }
        assert!(
            "bogus"
                .parse::<BusSpec>()
                .unwrap_err()
                .to_string()
                .contains("expected sim")
        );
    }

    #[test]
    fn replay_specs_parse_and_print_back() {
        for text in [
            "replay:/tmp/run.mcap",
            "replay:run.log@max",
            "replay:/tmp/run.mcap@0.5",
            "replay:/tmp/run.mcap@2",
        ] {
            let spec: BusSpec = text.parse().unwrap();
            assert!(matches!(spec, BusSpec::Replay { .. }), "{text}");
            assert_eq!(spec.to_string(), text);
        }
        assert_eq!(
            "replay:/tmp/a.log@max".parse::<BusSpec>().unwrap(),
            BusSpec::Replay {
                path: "/tmp/a.log".into(),
                speed: replay::ReplaySpeed::Max
            }
        );
        assert_eq!(
            "replay:/tmp/a.log@1"
                .parse::<BusSpec>()
                .unwrap()
                .to_string(),
            "replay:/tmp/a.log"
        );
        for bad in ["replay:", "replay:@2", "replay:/x@fast", "replay:/x@0"] {
            let err = bad.parse::<BusSpec>().unwrap_err().to_string();
            assert!(err.contains(bad), "{bad}: {err}");
        }
    }

    #[test]
    fn would_block_is_not_an_error_and_eio_is_a_disconnect() {
        assert!(classify("x", io::ErrorKind::WouldBlock.into(), false).is_ok());
        let eio = io::Error::from_raw_os_error(nix::libc::EIO);
        assert!(classify("x", eio, false).unwrap_err().is_disconnect());
        let nobufs = io::Error::from_raw_os_error(nix::libc::ENOBUFS);
        assert!(!classify("x", nobufs, true).unwrap_err().is_disconnect());
    }
}
