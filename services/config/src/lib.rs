//! chassisd's configuration: TOML → raw serde structs ([`RawConfig`]) → one validated
//! [`Config`]. One definition of the file, read by `chassisd`, `chassisd sim` and `chassis
//! doctor` (which takes the robot, name, bus and state directory from it).
//!
//! Every key has a default, so an empty file (or none) is a working configuration; unknown keys
//! are errors. Command-line options override the file. `chassisd --print-config` prints the
//! effective configuration in this format.

use std::path::{Path, PathBuf};

use chassis_bus::{BusSpec, BusSpecError};
use chassis_interfaces::{StopCategory, valid_robot_name};
use chassis_protocols::{
    DriverConfig, Profile, ProfileError, ProfileTableError, Protocol, ProtocolError, RobotKind,
};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::mux::{MuxConfig, MuxConfigError};

pub mod mux;

/// How the event loop waits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum LoopMode {
    /// Block until something happens (lowest CPU use; a wake-up costs the kernel's latency).
    #[default]
    Event,
    /// Never block: poll everything continuously (one core at 100 %, lowest latency).
    Spin,
    /// Poll for `spin_us` after each activity, then block.
    Hybrid,
}

/// `[service]`: what this process is and how its loop runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ServiceConfig {
    /// Robot: one of the registry's, by its `--robot` name (`titan`, `scout-mini`, …;
    /// `chassis_protocols::kind::names`).
    pub robot: Option<RobotKind>,
    /// AgileX wire protocol, `v1` or `v2` (`--protocol`); default: the robot's own (SCOUT MINI:
    /// v1; the other AgileX robots here: v2). SCOUT MINI, SCOUT and BUNKER on a real CAN bus
    /// without it listen first and drive in the protocol they hear.
    pub protocol: Option<Protocol>,
    /// Namespace of every iceoryx2 service, `chassis/<name>/…` (`--name`; default: the robot).
    pub name: Option<String>,
    /// The bus (`--bus`): `sim`, `can:IFACE`, `serial:PATH[@BAUD]`, `slcan:PATH[@BAUD]`.
    pub bus: Option<String>,
    /// The XBot's GPS receiver (`--gps`): `serial:PATH[@BAUD]`.
    pub gps: Option<String>,
    /// Period of the loop's tick (mux re-evaluation, smoothing, state refresh), ms.
    pub tick_ms: u64,
    /// Rate at which `MuxStatus` is published when nothing changes, Hz.
    pub mux_status_hz: f64,
    /// How the loop waits (`--loop`).
    #[serde(rename = "loop")]
    pub loop_mode: LoopMode,
    /// Hybrid mode: how long to keep polling after each activity, µs (`--spin-us`).
    pub spin_us: u64,
    /// Pin the loop's thread to this CPU (`--cpu`).
    pub cpu: Option<usize>,
    /// Real-time mode (`--realtime PRIO`): the loop's thread at SCHED_FIFO with this priority
    /// (1-99) and every page of the process locked in memory. When the system refuses, the
    /// service says so and runs with normal scheduling.
    pub realtime: Option<u8>,
    /// Where the held locks are kept across restarts (`--state-dir`; default:
    /// `$STATE_DIRECTORY` under systemd, else `$XDG_STATE_HOME/chassisd/<name>`, else
    /// `~/.local/state/chassisd/<name>`).
    pub state_dir: Option<PathBuf>,
    /// The black box: the engine's inputs kept in a ring of this many MiB in the state
    /// directory (`blackbox/`, compressed); 0 records nothing.
    pub blackbox_mib: u64,
    /// The black box: the ring's oldest part goes once it is this many minutes old, if the
    /// MiB have not made it go before.
    pub blackbox_minutes: f64,
    /// The black box: how many kept windows (`blackbox/kept/*.mcap`) stay; the oldest go.
    pub blackbox_kept: usize,
}

impl Default for ServiceConfig {
    fn default() -> Self {
        Self {
            robot: None,
            protocol: None,
            name: None,
            bus: None,
            gps: None,
            tick_ms: 20,
            mux_status_hz: 10.0,
            loop_mode: LoopMode::Event,
            spin_us: 200,
            cpu: None,
            realtime: None,
            state_dir: None,
            blackbox_mib: 64,
            blackbox_minutes: 10.0,
            blackbox_kept: 16,
        }
    }
}

/// `[bus]`: settings of the bus backends.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BusConfig {
    /// CAN bit rate an slcan adapter is set to, bit/s.
    pub can_bitrate: u32,
    /// First wait before reopening a lost bus, ms; doubles up to `reconnect_max_ms`.
    pub reconnect_initial_ms: u64,
    pub reconnect_max_ms: u64,
    /// While the bus is saturated, read it once per this many µs (everything pending at once)
    /// instead of waking per frame; ordinary feedback is always read the moment it arrives.
    /// 0 wakes for every frame whatever the load, as `loop = "spin"` does. See
    /// `chassisd::rx_moderation`.
    pub rx_moderation_us: u64,
}

impl Default for BusConfig {
    fn default() -> Self {
        Self {
            can_bitrate: 500_000,
            reconnect_initial_ms: 100,
            reconnect_max_ms: 2000,
            rx_moderation_us: 4000,
        }
    }
}

/// The file as written.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RawConfig {
    pub service: ServiceConfig,
    pub bus: BusConfig,
    pub driver: DriverConfig,
    pub mux: MuxConfig,
    /// The robot profile's parameters (see `chassis_protocols::profile`).
    pub profile: toml::Table,
}

/// Command-line choices that override the file (`chassisd`'s options).
// The fields' doc comments are `chassisd --help`, written for a terminal (`chassis/<NAME>/…`,
// `serial:PATH[@BAUD]`), not links or HTML.
#[allow(rustdoc::broken_intra_doc_links, rustdoc::invalid_html_tags)]
#[derive(Debug, Clone, Default, clap::Args)]
pub struct Overrides {
    // The registry's robots, listed by the registry.
    #[arg(
        long,
        help = format!("{}.", chassis_protocols::kind::names().join(", "))
    )]
    pub robot: Option<RobotKind>,
    /// AgileX wire protocol: v1 or v2 (default on a real CAN bus: detected for scout-mini, scout
    /// and bunker; on the simulator: the robot's own, SCOUT MINI v1, the others v2).
    #[arg(long)]
    pub protocol: Option<Protocol>,
    /// sim (default), can:IFACE, serial:PATH[@BAUD], slcan:PATH[@BAUD].
    #[arg(long)]
    pub bus: Option<BusSpec>,
    /// Namespace of the robot's services, chassis/<NAME>/… (default: the robot).
    #[arg(long)]
    pub name: Option<String>,
    /// The XBot's GPS receiver: serial:PATH[@BAUD] (NMEA 0183, default 4800 8N1).
    #[arg(long)]
    pub gps: Option<BusSpec>,
    /// Drive without a safety monitor: lift the rule that the required source must be alive.
    #[arg(long)]
    pub no_safety_monitor: bool,
    /// The configuration is for `chassisd sim` (the chassis side of a bus).
    #[arg(skip)]
    pub simulator: bool,
    /// How the loop waits: event (block; default), spin (poll continuously), hybrid (poll
    /// for --spin-us after each activity, then block).
    #[arg(long = "loop", value_enum)]
    pub loop_mode: Option<LoopMode>,
    /// Hybrid loop: microseconds to keep polling after each activity.
    #[arg(long)]
    pub spin_us: Option<u64>,
    /// Pin the loop's thread to this CPU.
    #[arg(long)]
    pub cpu: Option<usize>,
    /// Real-time mode: the loop's thread at SCHED_FIFO with priority PRIO (1-99), memory
    /// locked; when the system refuses, a warning and normal scheduling.
    #[arg(long, value_name = "PRIO")]
    pub realtime: Option<u8>,
    /// Where the held locks are kept across restarts (default: $STATE_DIRECTORY, else
    /// $XDG_STATE_HOME/chassisd/NAME, else ~/.local/state/chassisd/NAME).
    #[arg(long, value_name = "DIR")]
    pub state_dir: Option<PathBuf>,
}

/// Why a configuration is not usable.
#[derive(Debug, Error)]
pub enum ConfigError {
    #[error("reading {path}: {source}")]
    Read {
        path: String,
        source: std::io::Error,
    },
    #[error("{path}: {source}")]
    Parse {
        path: String,
        source: toml::de::Error,
    },
    #[error(
        "no robot given: pass --robot {} (or set service.robot)",
        chassis_protocols::kind::names().join("|")
    )]
    NoRobot,
    #[error("'{0}' is not a valid robot name (1-16 of a-z 0-9 - _)")]
    BadName(String),
    #[error("{key}: {reason}")]
    Bad { key: &'static str, reason: String },
    /// A bus spec (`service.bus`, `service.gps`) that does not parse.
    #[error("{key}: {source}")]
    Bus {
        key: &'static str,
        source: BusSpecError,
    },
    /// A protocol the robot does not speak.
    #[error("{0}")]
    Protocol(#[from] ProtocolError),
    /// A `[profile]` whose values do not make a drivable robot.
    #[error("profile: {0}")]
    BadProfile(#[from] ProfileError),
    #[error("[profile] for {robot}: {source}")]
    Profile {
        robot: RobotKind,
        source: toml::de::Error,
    },
    #[error("[mux]: {0}")]
    Mux(#[from] MuxConfigError),
    /// A bus the robot cannot be on (a CAN robot on a byte stream, or the reverse).
    #[error("{robot} cannot be on {bus}: {robot}'s bus is one of {accepted}")]
    WrongBus {
        robot: RobotKind,
        bus: String,
        accepted: &'static str,
    },
    #[error(
        "no place to keep the held locks: pass --state-dir (or set service.state_dir, \
         $STATE_DIRECTORY, $XDG_STATE_HOME or $HOME)"
    )]
    NoStateDir,
}

/// The validated configuration.
#[derive(Debug, Clone)]
pub struct Config {
    pub robot: RobotKind,
    /// The protocol asked for (`--protocol`, `service.protocol`); `None`: the robot's own — for a
    /// SCOUT MINI, SCOUT or BUNKER on a real CAN bus, detected by listening before anything is
    /// sent.
    pub protocol: Option<Protocol>,
    pub name: String,
    pub bus: BusSpec,
    pub gps: Option<BusSpec>,
    pub profile: Profile,
    pub driver: DriverConfig,
    pub mux: MuxConfig,
    pub bus_settings: BusConfig,
    pub tick_ms: u64,
    pub mux_status_hz: f64,
    pub loop_mode: LoopMode,
    pub spin_us: u64,
    pub cpu: Option<usize>,
    /// SCHED_FIFO priority of the loop's thread (real-time mode), if asked for.
    pub realtime: Option<u8>,
    /// The directory of the held-lock file.
    pub state_dir: PathBuf,
    /// The black box's ring, MiB (0: off) and minutes, and how many kept windows stay.
    pub blackbox_mib: u64,
    pub blackbox_minutes: f64,
    pub blackbox_kept: usize,
    /// The required-source rule was lifted on the command line.
    pub no_safety_monitor: bool,
}

impl RawConfig {
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.display().to_string(),
            source,
        })?;
        toml::from_str(&text).map_err(|source| ConfigError::Parse {
            path: path.display().to_string(),
            source,
        })
    }

    /// Applies the overrides and checks everything.
    pub fn validate(self, overrides: Overrides) -> Result<Config, ConfigError> {
        let robot = overrides
            .robot
            .or(self.service.robot)
            .ok_or(ConfigError::NoRobot)?;
        let name = overrides
            .name
            .or(self.service.name)
            .unwrap_or_else(|| robot.name().to_string());
        if !valid_robot_name(&name) {
            return Err(ConfigError::BadName(name));
        }
        let parse_bus = |key: &'static str, text: &str| {
            text.parse::<BusSpec>()
                .map_err(|source| ConfigError::Bus { key, source })
        };
        let bus = match overrides.bus {
            Some(bus) => bus,
            None => match &self.service.bus {
                Some(text) => parse_bus("service.bus", text)?,
                None => BusSpec::Sim,
            },
        };
        if !overrides.simulator && matches!(bus, BusSpec::Pty { .. } | BusSpec::SlcanPty { .. }) {
            return Err(ConfigError::Bad {
                key: "service.bus",
                reason: format!(
                    "{bus} is for `chassisd sim` (the simulated chassis), not the service"
                ),
            });
        }
        check_bus_kind(robot, &bus, overrides.simulator)?;
        let gps = match overrides.gps {
            Some(gps) => Some(gps),
            None => self
                .service
                .gps
                .as_deref()
                .map(|t| parse_bus("service.gps", t))
                .transpose()?,
        };
        if let Some(gps) = &gps
            && !matches!(gps, BusSpec::Serial { .. })
        {
            return Err(ConfigError::Bad {
                key: "service.gps",
                reason: format!("{gps}: the GPS receiver is a serial port (serial:PATH[@BAUD])"),
            });
        }
        let protocol = overrides.protocol.or(self.service.protocol);
        let mut profile = parse_profile(robot, protocol, self.profile)?;
        profile.validate()?;
        // What the simulated chassis knows and a real one's profile must be told (the XBot's
        // wheel separation).
        if bus == BusSpec::Sim {
            profile.fill_for_simulator();
        }
        if self.service.tick_ms == 0 || self.service.tick_ms > 100 {
            return Err(ConfigError::Bad {
                key: "service.tick_ms",
                reason: "must be 1 to 100 ms".into(),
            });
        }
        if !(self.service.mux_status_hz > 0.0 && self.service.mux_status_hz <= 1000.0) {
            return Err(ConfigError::Bad {
                key: "service.mux_status_hz",
                reason: "must be above 0 and at most 1000 Hz".into(),
            });
        }
        // Up to a day: a second at least, and what a Duration holds.
        if !(self.service.blackbox_minutes >= 1.0 / 60.0 && self.service.blackbox_minutes <= 1440.0)
        {
            return Err(ConfigError::Bad {
                key: "service.blackbox_minutes",
                reason: "must be from 1/60 (a second) to 1440 (a day)".into(),
            });
        }
        let mut mux = if overrides.no_safety_monitor {
            self.mux.without_required_sources()
        } else {
            self.mux
        };
        mux.validate()?;
        // The e-stop brakes and then disables the drive where the robot can disable it.
        let estop = if profile.drive_cut(true).is_some() {
            StopCategory::BRAKE_THEN_CUT
        } else {
            StopCategory::HOLD
        };
        for lock in mux.locks.iter_mut().filter(|l| l.name == "estop") {
            lock.category.get_or_insert(estop);
        }
        let realtime = overrides.realtime.or(self.service.realtime);
        if let Some(priority) = realtime
            && !(1..=99).contains(&priority)
        {
            return Err(ConfigError::Bad {
                key: "service.realtime",
                reason: format!("{priority}: a SCHED_FIFO priority is 1 to 99"),
            });
        }
        let state_dir = match overrides.state_dir.or(self.service.state_dir) {
            Some(dir) => dir,
            None => default_state_dir(&name, |key| std::env::var_os(key))
                .ok_or(ConfigError::NoStateDir)?,
        };
        Ok(Config {
            robot,
            protocol,
            name,
            bus,
            gps,
            profile,
            driver: self.driver,
            mux,
            bus_settings: self.bus,
            tick_ms: self.service.tick_ms,
            mux_status_hz: self.service.mux_status_hz,
            loop_mode: overrides.loop_mode.unwrap_or(self.service.loop_mode),
            spin_us: overrides.spin_us.unwrap_or(self.service.spin_us),
            cpu: overrides.cpu.or(self.service.cpu),
            realtime,
            state_dir,
            blackbox_mib: self.service.blackbox_mib,
            blackbox_minutes: self.service.blackbox_minutes,
            blackbox_kept: self.service.blackbox_kept,
            no_safety_monitor: overrides.no_safety_monitor,
        })
    }
}

/// The buses `robot` can be on, as the service (`simulator` false) or as `chassisd sim`.
fn check_bus_kind(robot: RobotKind, bus: &BusSpec, simulator: bool) -> Result<(), ConfigError> {
    let (fits, accepted) = match (robot.is_can(), simulator) {
        (true, false) => (
            matches!(
                bus,
                BusSpec::Sim | BusSpec::Can { .. } | BusSpec::Slcan { .. } | BusSpec::Replay { .. }
            ),
            "sim, can:IFACE, slcan:PATH[@BAUD], replay:FILE (a CAN bus)",
        ),
        (false, false) => (
            matches!(
                bus,
                BusSpec::Sim | BusSpec::Serial { .. } | BusSpec::Replay { .. }
            ),
            "sim, serial:PATH[@BAUD], replay:FILE (an RS232 byte stream)",
        ),
        (true, true) => (
            matches!(
                bus,
                BusSpec::Can { .. } | BusSpec::Slcan { .. } | BusSpec::SlcanPty { .. }
            ),
            "can:IFACE, slcan:PATH[@BAUD], slcan-pty:LINK (a CAN bus)",
        ),
        (false, true) => (
            matches!(bus, BusSpec::Serial { .. } | BusSpec::Pty { .. }),
            "serial:PATH[@BAUD], pty:LINK (an RS232 byte stream)",
        ),
    };
    if fits {
        Ok(())
    } else {
        Err(ConfigError::WrongBus {
            robot,
            bus: bus.to_string(),
            accepted,
        })
    }
}

/// The default directory of the held-lock file: `$STATE_DIRECTORY` (systemd's
/// `StateDirectory=`; the first of a colon-separated list), else
/// `$XDG_STATE_HOME/chassisd/<name>`, else `$HOME/.local/state/chassisd/<name>`. `var` reads
/// the environment.
pub fn default_state_dir(
    name: &str,
    var: impl Fn(&str) -> Option<std::ffi::OsString>,
) -> Option<PathBuf> {
    let set = |key: &str| var(key).filter(|v| !v.is_empty());
    if let Some(dirs) = set("STATE_DIRECTORY") {
        let first = dirs.to_string_lossy().split(':').next().map(PathBuf::from);
        if let Some(dir) = first.filter(|d| !d.as_os_str().is_empty()) {
            return Some(dir);
        }
    }
    if let Some(xdg) = set("XDG_STATE_HOME") {
        return Some(PathBuf::from(xdg).join("chassisd").join(name));
    }
    set("HOME").map(|home| PathBuf::from(home).join(".local/state/chassisd").join(name))
}

/// The robot's profile: its defaults (for `protocol`), with the `[profile]` keys set over them.
fn parse_profile(
    robot: RobotKind,
    protocol: Option<Protocol>,
    table: toml::Table,
) -> Result<Profile, ConfigError> {
    robot
        .entry()
        .profile_from_table(protocol, &table)
        .map_err(|e| match e {
            ProfileTableError::Toml(source) => ConfigError::Profile { robot, source },
            ProfileTableError::Protocol(e) => ConfigError::Protocol(e),
            other => ConfigError::Bad {
                key: "profile.model",
                reason: other.to_string(),
            },
        })
}

impl Config {
    /// The configuration with everything filled in, in the file's format.
    pub fn to_toml(&self) -> Result<String, toml::ser::Error> {
        let profile = self.profile.table()?;
        let raw = RawConfig {
            service: ServiceConfig {
                robot: Some(self.robot),
                protocol: self.protocol,
                name: Some(self.name.clone()),
                bus: Some(self.bus.to_string()),
                gps: self.gps.as_ref().map(ToString::to_string),
                tick_ms: self.tick_ms,
                mux_status_hz: self.mux_status_hz,
                loop_mode: self.loop_mode,
                spin_us: self.spin_us,
                cpu: self.cpu,
                realtime: self.realtime,
                state_dir: Some(self.state_dir.clone()),
                blackbox_mib: self.blackbox_mib,
                blackbox_minutes: self.blackbox_minutes,
                blackbox_kept: self.blackbox_kept,
            },
            bus: self.bus_settings.clone(),
            driver: self.driver.clone(),
            mux: self.mux.clone(),
            profile,
        };
        toml::to_string_pretty(&raw)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chassis_protocols::agilex_v1::V1Profile;
    use chassis_protocols::agilex_v2::V2Profile;
    use chassis_protocols::xbot::XbotProfile;

    fn titan() -> Overrides {
        Overrides {
            robot: Some(RobotKind::Titan),
            ..Overrides::default()
        }
    }

    #[test]
    fn an_empty_file_is_a_working_configuration() {
        let c = RawConfig::default().validate(titan()).unwrap();
        assert_eq!(c.name, "titan");
        assert_eq!(c.bus, BusSpec::Sim);
        assert_eq!(c.mux.sources.len(), 6);
        assert_eq!(c.mux.sources[5].name, "ros2");
        assert_eq!(c.mux.sources[3].name, "foxglove");
        assert!(c.mux.sources[0].required);
        let remote = &c.mux.sources[4];
        assert_eq!(
            (remote.name.as_str(), remote.priority, remote.timeout_ms),
            ("remote", 100, 300)
        );
        assert!(remote.remote && !remote.required);
        assert!(
            c.mux
                .sources
                .iter()
                .all(|s| s.remote == (s.name == "remote"))
        );
        assert_eq!(c.profile, RobotKind::Titan.entry().defaults());
    }

    #[test]
    fn the_estop_brakes_then_cuts_the_drive_where_the_robot_can_cut_it() {
        let estop = |robot: &str, file: &str| {
            let raw: RawConfig =
                toml::from_str(&format!("[service]\nrobot = \"{robot}\"\n{file}")).unwrap();
            raw.validate(Overrides::default()).unwrap().mux.locks[0].category
        };
        assert_eq!(estop("titan", ""), Some(StopCategory::BRAKE_THEN_CUT));
        assert_eq!(estop("xbot", ""), Some(StopCategory::BRAKE_THEN_CUT));
        // A SCOUT MINI speaks V1 unless told otherwise: no way to cut its drive.
        assert_eq!(estop("scout-mini", ""), Some(StopCategory::HOLD));
        let chosen = "[[mux.lock]]\nname = \"estop\"\npriority = 255\ncategory = 0\n";
        assert_eq!(estop("titan", chosen), Some(StopCategory::CUT));
        let raw: RawConfig = toml::from_str(&chosen.replace("= 0", "= 3")).unwrap();
        assert!(
            raw.validate(titan())
                .unwrap_err()
                .to_string()
                .contains("not a stop category")
        );
    }

    #[test]
    fn the_printed_configuration_reads_back_to_the_same() {
        let c = RawConfig::default().validate(titan()).unwrap();
        let text = c.to_toml().unwrap();
        assert!(text.contains("[[mux.source]]"), "{text}");
        assert!(
            text.contains("steering_feedback_left_positive = false"),
            "{text}"
        );
        let again: RawConfig = toml::from_str(&text).unwrap();
        let c2 = again.validate(Overrides::default()).unwrap();
        assert_eq!(c2.to_toml().unwrap(), text);
    }

    #[test]
    fn command_line_choices_override_the_file() {
        let raw: RawConfig = toml::from_str(
            "[service]\nrobot = \"xbot\"\nname = \"left\"\nbus = \"serial:/dev/ttyS1\"\n",
        )
        .unwrap();
        let c = raw
            .clone()
            .validate(Overrides {
                name: Some("right".into()),
                ..Overrides::default()
            })
            .unwrap();
        assert_eq!((c.robot, c.name.as_str()), (RobotKind::Xbot, "right"));
        assert_eq!(c.bus.to_string(), "serial:/dev/ttyS1");
    }

    #[test]
    fn no_safety_monitor_lifts_the_required_rule() {
        let c = RawConfig::default()
            .validate(Overrides {
                no_safety_monitor: true,
                ..titan()
            })
            .unwrap();
        assert!(c.mux.sources.iter().all(|s| !s.required));
    }

    #[test]
    fn mistakes_are_reported_with_their_place() {
        let err = toml::from_str::<RawConfig>("[service]\ntick = 5\n").unwrap_err();
        assert!(err.to_string().contains("unknown field"), "{err}");
        let raw: RawConfig = toml::from_str("[profile]\nmax_speed = 9\n").unwrap();
        let err = raw.validate(titan()).unwrap_err();
        assert!(err.to_string().starts_with("[profile] for titan"), "{err}");
        let raw: RawConfig = toml::from_str("[service]\nname = \"Bad Name\"\n").unwrap();
        assert!(matches!(
            raw.validate(titan()),
            Err(ConfigError::BadName(_))
        ));
        assert!(matches!(
            RawConfig::default().validate(Overrides::default()),
            Err(ConfigError::NoRobot)
        ));
        let raw: RawConfig = toml::from_str("[service]\ngps = \"can:vcan0\"\n").unwrap();
        assert!(raw.validate(titan()).is_err());
    }

    #[test]
    fn a_robot_on_a_bus_of_the_wrong_kind_is_refused_with_the_kinds_it_accepts() {
        let on = |robot, bus: &str, simulator| {
            RawConfig::default().validate(Overrides {
                robot: Some(robot),
                bus: Some(bus.parse().unwrap()),
                simulator,
                ..Overrides::default()
            })
        };
        let err = on(RobotKind::Titan, "serial:/dev/ttyUSB0", false).unwrap_err();
        assert!(matches!(err, ConfigError::WrongBus { .. }), "{err}");
        let text = err.to_string();
        assert!(
            text.contains("titan cannot be on serial:/dev/ttyUSB0"),
            "{text}"
        );
        assert!(text.contains("can:IFACE, slcan:PATH"), "{text}");
        let err = on(RobotKind::Xbot, "can:can0", false).unwrap_err();
        assert!(err.to_string().contains("serial:PATH"), "{err}");
        assert!(on(RobotKind::ScoutMini, "slcan:/dev/ttyACM0", false).is_ok());
        assert!(on(RobotKind::Xbot, "serial:/dev/ttyUSB0", false).is_ok());
        assert!(on(RobotKind::Titan, "slcan-pty:/tmp/x", true).is_ok());
        assert!(on(RobotKind::Titan, "pty:/tmp/x", true).is_err());
        assert!(on(RobotKind::Xbot, "slcan-pty:/tmp/x", true).is_err());
    }

    #[test]
    fn the_state_directory_follows_systemd_then_xdg_then_home() {
        let env = |pairs: &'static [(&'static str, &'static str)]| {
            move |key: &str| {
                pairs
                    .iter()
                    .find(|(k, _)| *k == key)
                    .map(|(_, v)| std::ffi::OsString::from(v))
            }
        };
        let all = env(&[
            ("STATE_DIRECTORY", "/var/lib/chassisd/r1:/var/lib/other"),
            ("XDG_STATE_HOME", "/x"),
            ("HOME", "/h"),
        ]);
        assert_eq!(
            default_state_dir("r1", all),
            Some(PathBuf::from("/var/lib/chassisd/r1"))
        );
        let xdg = env(&[("XDG_STATE_HOME", "/x"), ("HOME", "/h")]);
        assert_eq!(
            default_state_dir("r1", xdg),
            Some(PathBuf::from("/x/chassisd/r1"))
        );
        let home = env(&[("XDG_STATE_HOME", ""), ("HOME", "/h")]);
        assert_eq!(
            default_state_dir("r1", home),
            Some(PathBuf::from("/h/.local/state/chassisd/r1"))
        );
        assert_eq!(default_state_dir("r1", env(&[])), None);
    }

    #[test]
    fn a_realtime_priority_outside_1_to_99_is_refused() {
        for (priority, ok) in [(0, false), (1, true), (99, true), (100, false)] {
            let result = RawConfig::default().validate(Overrides {
                realtime: Some(priority),
                ..titan()
            });
            assert_eq!(result.is_ok(), ok, "{priority}");
        }
    }

    #[test]
    fn an_undrivable_profile_is_refused_at_load() {
        let raw: RawConfig = toml::from_str("[profile]\nlinear_full_scale_mps = 0\n").unwrap();
        let err = raw
            .validate(Overrides {
                robot: Some(RobotKind::ScoutMini),
                ..Overrides::default()
            })
            .unwrap_err();
        assert!(
            err.to_string()
                .starts_with("profile: linear_full_scale_mps"),
            "{err}"
        );
    }

    #[test]
    fn the_simulated_xbot_gets_its_known_wheel_separation() {
        let xbot = |bus| {
            RawConfig::default()
                .validate(Overrides {
                    robot: Some(RobotKind::Xbot),
                    bus,
                    ..Overrides::default()
                })
                .unwrap()
                .profile
        };
        let Some(sim) = xbot(None).get::<XbotProfile>().cloned() else {
            panic!()
        };
        assert!(sim.wheel_separation_m.is_some());
        let real = Some(BusSpec::Serial {
            path: "/dev/ttyUSB0".into(),
            baud: None,
        });
        let Some(real) = xbot(real).get::<XbotProfile>().cloned() else {
            panic!()
        };
        assert_eq!(
            real.wheel_separation_m, None,
            "a real robot's must be measured"
        );
    }

    #[test]
    fn agilex_v2_robots_take_their_protocol_and_model_from_the_file() {
        let raw: RawConfig = toml::from_str(
            "[service]\nrobot = \"scout-mini\"\nprotocol = \"v2\"\n\
             [profile]\nmodel = \"scout-mini-omni\"\nshort_commands_dlc = 1\n",
        )
        .unwrap();
        let c = raw.validate(Overrides::default()).unwrap();
        assert_eq!(c.protocol, Some(Protocol::V2));
        let Some(p) = c.profile.get::<V2Profile>() else {
            panic!("not V2: {:?}", c.profile)
        };
        assert_eq!(p.max_lateral_mps, 2.0);
        assert_eq!(p.short_commands_dlc, 1);
        // The effective configuration reads back to the same profile.
        let again: RawConfig = toml::from_str(&c.to_toml().unwrap()).unwrap();
        assert_eq!(
            again.validate(Overrides::default()).unwrap().profile,
            c.profile
        );
        let err = RawConfig::default()
            .validate(Overrides {
                robot: Some(RobotKind::Hunter),
                protocol: Some(Protocol::V1),
                ..Overrides::default()
            })
            .unwrap_err();
        assert_eq!(err.to_string(), "hunter does not speak protocol v1 here");
        let wrong: RawConfig = toml::from_str("[profile]\nmodel = \"bunker\"\n").unwrap();
        let err = wrong
            .validate(Overrides {
                robot: Some(RobotKind::Hunter),
                ..Overrides::default()
            })
            .unwrap_err();
        assert!(err.to_string().contains("not a hunter"), "{err}");
    }

    #[test]
    #[allow(clippy::approx_constant)] // 0.7853 is the reading of the manual's example
    fn a_profile_parameter_can_be_flipped_from_the_file() {
        let raw: RawConfig =
            toml::from_str("[profile]\nangular_full_scale_rad_s = 0.7853\n").unwrap();
        let c = raw
            .validate(Overrides {
                robot: Some(RobotKind::ScoutMini),
                ..Overrides::default()
            })
            .unwrap();
        let Some(p) = c.profile.get::<V1Profile>() else {
            panic!()
        };
        assert_eq!(p.angular_full_scale_rad_s, 0.7853);
    }
}
