//! What the service opens: the robot's driver, its bus and its GPS receiver.
//!
//! The shell (`crate::service`) asks a [`Devices`] for its bus and GPS port, at start and each
//! time the engine wants one reopened; [`Hardware`] opens the real ones named in the
//! configuration (and runs the simulated chassis for the `sim` bus). A test hands the shell its
//! own [`Devices`].

use chassis_bus::{Bus, BusError, BusSpec, datagram, serial, slcan, socketcan};
use chassis_protocols::slcan::ADAPTER_BAUD;
use chassis_protocols::{BoxedDriver, Profile, Timestamp, nmea};
use chassisd_config::Config;

use crate::realtime::{is_fifo, sim_cpus};
use crate::sim::SimHandle;

/// The driver for `config`, as the registry makes it: a robot that may speak AgileX protocol V1
/// or V2 (SCOUT MINI, SCOUT 2.0, BUNKER) on a real CAN bus with no protocol asked for listens
/// first and drives in the protocol it hears ([`chassis_protocols::RobotEntry::driver`]).
pub fn driver_for_config(config: &Config, now: Timestamp) -> BoxedDriver {
    let real_can = matches!(config.bus, BusSpec::Can { .. } | BusSpec::Slcan { .. });
    let detect = config.protocol.is_none() && real_can;
    config
        .robot
        .entry()
        .driver(&config.profile, detect, &config.driver, now)
}

/// Where the shell gets its devices.
pub trait Devices {
    /// Opens the robot's bus at `now`; the simulated bus comes with its running chassis.
    fn open_bus(&mut self, now: Timestamp) -> Result<(Bus, Option<SimHandle>), BusError>;
    /// Opens the GPS receiver (only called when one is configured).
    fn open_gps(&mut self) -> Result<Bus, BusError>;
}

/// The devices named in the configuration.
#[derive(Debug, Clone)]
pub struct Hardware {
    config: Config,
}

impl Hardware {
    pub fn new(config: &Config) -> Self {
        Self {
            config: config.clone(),
        }
    }
}

impl Devices for Hardware {
    fn open_bus(&mut self, now: Timestamp) -> Result<(Bus, Option<SimHandle>), BusError> {
        open_bus(&self.config.bus, &self.config, now)
    }

    fn open_gps(&mut self) -> Result<Bus, BusError> {
        let Some(BusSpec::Serial { path, baud }) = &self.config.gps else {
            return Err(BusError::Open {
                name: "gps".into(),
                reason: "the GPS receiver is a serial port (serial:PATH[@BAUD])".into(),
            });
        };
        let baud = baud
            .or(self.config.profile.gps_baud())
            .unwrap_or(nmea::NMEA_0183_BAUD);
        Ok(Bus::Bytes(Box::new(serial::SerialBus::open(path, baud)?)))
    }
}

/// Opens the bus named by `spec` for the service (the simulator gets its own thread, powered
/// up at `now`).
pub fn open_bus(
    spec: &BusSpec,
    config: &Config,
    now: Timestamp,
) -> Result<(Bus, Option<SimHandle>), BusError> {
    let robot = config.robot;
    Ok(match spec {
        BusSpec::Sim => {
            let firmware = config.profile.firmware(now);
            let io = |e: std::io::Error| BusError::Open {
                name: "sim".into(),
                reason: e.to_string(),
            };
            let (ours, theirs) = datagram::bus_pair("sim", robot.is_can()).map_err(io)?;
            let cpus = sim_cpus(config, is_fifo());
            let handle = SimHandle::spawn_on(firmware, theirs, &cpus).map_err(io)?;
            (ours, Some(handle))
        }
        BusSpec::Can { iface } => (Bus::Can(Box::new(socketcan::SocketCan::open(iface)?)), None),
        BusSpec::Serial { path, baud } => {
            if robot.is_can() {
                return Err(BusError::Open {
                    name: spec.to_string(),
                    reason: format!("{robot} is a CAN robot: use can:IFACE or slcan:PATH"),
                });
            }
            let port = serial::SerialBus::open(path, serial_baud(spec, *baud, &config.profile)?)?;
            (Bus::Bytes(Box::new(port)), None)
        }
        BusSpec::Slcan { path, baud } => {
            if !robot.is_can() {
                return Err(BusError::Open {
                    name: spec.to_string(),
                    reason: format!("{robot} speaks RS232: use serial:PATH"),
                });
            }
            let port = serial::SerialBus::open(path, baud.unwrap_or(ADAPTER_BAUD))?;
            let bus = slcan::SlcanBus::open(port, config.bus_settings.can_bitrate)?;
            (Bus::Can(Box::new(bus)), None)
        }
        BusSpec::Replay { path, speed } => (chassis_bus::replay::open(path, *speed, robot)?, None),
        BusSpec::Pty { .. } | BusSpec::SlcanPty { .. } => {
            return Err(BusError::Open {
                name: spec.to_string(),
                reason: "pty links are made by `chassisd sim`, not opened by the service".into(),
            });
        }
    })
}

/// The baud rate of a robot's serial control link: the spec's, else its profile's.
pub fn serial_baud(spec: &BusSpec, baud: Option<u32>, profile: &Profile) -> Result<u32, BusError> {
    baud.or(profile.serial_baud())
        .ok_or_else(|| BusError::Open {
            name: spec.to_string(),
            reason: format!(
                "{} has no serial link: use can:IFACE or slcan:PATH",
                profile.robot()
            ),
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use chassis_protocols::RobotKind;
    use chassisd_config::{Overrides, RawConfig};

    /// The robots of either firmware on a real CAN bus detect with the settings of the profile
    /// they are configured with: the SCOUT MINI's V1 one, the SCOUT's and BUNKER's V2 one.
    #[test]
    fn detection_listens_as_long_as_the_configured_profile_says() {
        let now = Timestamp::from_millis(1000);
        for (robot, detecting) in [
            ("scout-mini", true),
            ("scout", true),
            ("bunker", true),
            ("hunter", false),
        ] {
            let raw: RawConfig = toml::from_str(&format!(
                "[service]\nrobot = \"{robot}\"\nbus = \"can:can0\"\n\
                 [profile]\ndetect_timeout_ms = 1200\n"
            ))
            .unwrap();
            let config = raw.validate(Overrides::default()).unwrap();
            let driver = driver_for_config(&config, now);
            assert_eq!(driver.robot(), robot.parse::<RobotKind>().unwrap());
            let deadline = driver.poll_timeout().unwrap();
            if detecting {
                assert_eq!(
                    driver.state().system.wire_protocol,
                    chassis_interfaces::WireProtocol::DETECTING,
                    "{robot}"
                );
                assert_eq!(deadline, now + std::time::Duration::from_millis(1200));
            } else {
                assert_eq!(
                    driver.state().system.wire_protocol,
                    chassis_interfaces::WireProtocol::V2,
                    "{robot}"
                );
            }
        }
    }
}
