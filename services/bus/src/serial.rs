//! Serial ports and pseudo-terminals through the `serialport` crate (8N1, no flow control).

use std::io::{self, Read, Write};
use std::os::fd::{AsRawFd, RawFd};
use std::path::{Path, PathBuf};
use std::time::Duration;

use serialport::{SerialPort, TTYPort};

use super::{BusError, ByteBus, classify};

/// How long one write may wait for room in the driver's buffer before the bytes count as
/// dropped. Reads never wait: the event loop only reads when the port is readable.
const WRITE_TIMEOUT: Duration = Duration::from_millis(20);

/// An open serial port (or pty slave), exclusive, raw 8N1.
#[derive(Debug)]
pub struct SerialBus {
    port: TTYPort,
    name: String,
}

impl SerialBus {
    pub fn open(path: &str, baud: u32) -> Result<Self, BusError> {
        let name = format!("serial:{path}@{baud}");
        let port = serialport::new(path, baud)
            .data_bits(serialport::DataBits::Eight)
            .parity(serialport::Parity::None)
            .stop_bits(serialport::StopBits::One)
            .flow_control(serialport::FlowControl::None)
            .timeout(Duration::ZERO)
            .open_native()
            .map_err(|e| BusError::Open {
                name: name.clone(),
                reason: e.to_string(),
            })?;
        Ok(Self { port, name })
    }

    fn wrap(port: TTYPort, name: String) -> Self {
        Self { port, name }
    }
}

fn read_port(port: &mut TTYPort, name: &str, buf: &mut [u8]) -> Result<usize, BusError> {
    port.set_timeout(Duration::ZERO).ok();
    match port.read(buf) {
        // Readable but nothing to read: the other end hung up.
        Ok(0) => Err(BusError::Disconnected {
            name: name.to_string(),
            source: io::ErrorKind::UnexpectedEof.into(),
        }),
        Ok(n) => Ok(n),
        Err(err) => classify(name, err, false).map(|()| 0),
    }
}

fn write_port(port: &mut TTYPort, name: &str, mut bytes: &[u8]) -> Result<(), BusError> {
    port.set_timeout(WRITE_TIMEOUT).ok();
    let result = loop {
        if bytes.is_empty() {
            break Ok(());
        }
        match port.write(bytes) {
            Ok(n) => bytes = &bytes[n..],
            Err(err) if err.kind() == io::ErrorKind::TimedOut => {
                break Err(BusError::TxDropped {
                    name: name.to_string(),
                    source: err,
                });
            }
            Err(err) => break classify(name, err, true),
        }
    };
    port.set_timeout(Duration::ZERO).ok();
    result
}

impl ByteBus for SerialBus {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, BusError> {
        read_port(&mut self.port, &self.name, buf)
    }

    fn write_all(&mut self, bytes: &[u8]) -> Result<(), BusError> {
        write_port(&mut self.port, &self.name, bytes)
    }

    fn raw_fd(&self) -> RawFd {
        self.port.as_raw_fd()
    }

    fn name(&self) -> &str {
        &self.name
    }
}

/// A new pseudo-terminal whose device path is linked at a chosen path: the chassis' end of a
/// serial link for `chassisd sim --bus pty:LINK`. The service opens LINK as `serial:LINK`; a
/// restarted simulator re-creates the link, so the service reconnects to the same path.
#[derive(Debug)]
pub struct PtyLink {
    master: TTYPort,
    /// Kept open so the line settings stay raw and the master never sees a hang-up while the
    /// service reconnects.
    _slave: TTYPort,
    link: PathBuf,
    name: String,
}

impl PtyLink {
    pub fn create(link: &Path) -> Result<Self, BusError> {
        let name = format!("pty:{}", link.display());
        let fail = |reason: String| BusError::Open {
            name: name.clone(),
            reason,
        };
        let (master, slave) = TTYPort::pair().map_err(|e| fail(e.to_string()))?;
        let device = slave
            .name()
            .ok_or_else(|| fail("the pty has no device name".into()))?;
        match std::fs::symlink_metadata(link) {
            Ok(meta) if meta.file_type().is_symlink() => {
                std::fs::remove_file(link)
                    .map_err(|e| fail(format!("replacing the old link: {e}")))?;
            }
            Ok(_) => {
                return Err(fail(format!(
                    "{} exists and is not a symlink",
                    link.display()
                )));
            }
            Err(_) => {}
        }
        std::os::unix::fs::symlink(&device, link)
            .map_err(|e| fail(format!("linking {device}: {e}")))?;
        Ok(Self {
            master,
            _slave: slave,
            link: link.to_path_buf(),
            name: format!("{name} ({device})"),
        })
    }

    /// The pty device the link points to.
    pub fn link(&self) -> &Path {
        &self.link
    }

    /// The master end as a plain byte bus (for a codec layered on top, such as slcan).
    pub fn into_bus(self) -> PtyLinkBus {
        PtyLinkBus(self)
    }
}

impl Drop for PtyLink {
    fn drop(&mut self) {
        // Only remove the link if it still points at our device.
        if std::fs::read_link(&self.link).ok().as_deref()
            == self._slave.name().as_deref().map(Path::new)
        {
            // Best effort while dropping: a link someone already removed is what we want, and
            // there is no caller left to tell otherwise.
            std::fs::remove_file(&self.link).ok();
        }
    }
}

/// [`PtyLink`] as a [`ByteBus`].
#[derive(Debug)]
pub struct PtyLinkBus(PtyLink);

impl ByteBus for PtyLinkBus {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, BusError> {
        read_port(&mut self.0.master, &self.0.name, buf)
    }

    fn write_all(&mut self, bytes: &[u8]) -> Result<(), BusError> {
        write_port(&mut self.0.master, &self.0.name, bytes)
    }

    fn raw_fd(&self) -> RawFd {
        self.0.master.as_raw_fd()
    }

    fn name(&self) -> &str {
        &self.0.name
    }
}

/// Opens the master end of a fresh pty pair as a [`SerialBus`] pair (tests).
pub fn pty_pair() -> Result<(SerialBus, SerialBus), BusError> {
    let (master, slave) = TTYPort::pair().map_err(|e| BusError::Open {
        name: "pty".into(),
        reason: e.to_string(),
    })?;
    let device = slave.name().unwrap_or_else(|| "pty".into());
    Ok((
        SerialBus::wrap(master, format!("pty-master:{device}")),
        SerialBus::wrap(slave, format!("serial:{device}")),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read_all(bus: &mut impl ByteBus, want: usize) -> Vec<u8> {
        let mut out = Vec::new();
        let mut buf = [0u8; 256];
        for _ in 0..200 {
            let n = bus.read(&mut buf).unwrap();
            out.extend_from_slice(&buf[..n]);
            if out.len() >= want {
                break;
            }
            if n == 0 {
                // A 5 ms pause; an interrupted one only makes the next read come sooner.
                nix::poll::poll(&mut [], nix::poll::PollTimeout::from(5u8)).ok();
            }
        }
        out
    }

    #[test]
    fn bytes_cross_a_pty_both_ways_unchanged() {
        let (mut master, mut slave) = pty_pair().unwrap();
        // Every byte value, including CR, LF, XON/XOFF and 0xFF: the line is raw.
        let all: Vec<u8> = (0..=255u8).collect();
        slave.write_all(&all).unwrap();
        assert_eq!(read_all(&mut master, all.len()), all);
        master.write_all(&all).unwrap();
        assert_eq!(read_all(&mut slave, all.len()), all);
    }

    #[test]
    fn a_linked_pty_opens_as_a_serial_port_and_its_loss_is_a_disconnect() {
        let dir = std::env::temp_dir().join(format!("chassisd-pty-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let link = dir.join("xbot");
        let mut sim = PtyLink::create(&link).unwrap().into_bus();
        let mut port = SerialBus::open(link.to_str().unwrap(), 115_200).unwrap();
        port.write_all(b"\xAA\x55\x02\x01\x01\x02").unwrap();
        assert_eq!(read_all(&mut sim, 6), b"\xAA\x55\x02\x01\x01\x02");
        drop(sim);
        assert!(!link.exists(), "the link goes with the simulator");
        let mut buf = [0u8; 16];
        let mut result = Ok(0);
        for _ in 0..100 {
            result = port.read(&mut buf);
            if result.is_err() {
                break;
            }
            // A 5 ms pause; an interrupted one only makes the next read come sooner.
            nix::poll::poll(&mut [], nix::poll::PollTimeout::from(5u8)).ok();
        }
        assert!(result.unwrap_err().is_disconnect());
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn opening_a_missing_port_is_a_clear_error() {
        let err = SerialBus::open("/dev/does-not-exist", 115_200).unwrap_err();
        assert!(
            err.to_string()
                .starts_with("cannot open serial:/dev/does-not-exist@115200")
        );
    }
}
