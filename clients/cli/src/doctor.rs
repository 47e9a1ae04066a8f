//! `chassis doctor`: everything between this computer and the robot's bus, checked in the order
//! a person would (the device, its settings, the CAN controller, what the bus carries, the
//! robot's mode, then chassisd's own needs), each with a verdict and the exact fix.
//!
//! A check says `ok`, `warn` (driving works, something is worth fixing), `FAIL` (nothing will
//! drive until it is fixed) or `skip` (not for this bus). The exit status is 1 when any check
//! fails. When a chassisd already serves the robot, what the bus carries is read from its state
//! (a serial port is chassisd's alone); otherwise the doctor opens the bus itself and listens.

use std::collections::BTreeMap;
use std::fmt;
use std::os::fd::{BorrowedFd, RawFd};
use std::os::unix::fs::{FileTypeExt, MetadataExt};
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::Context;
use chassis_bus::can_controller;
use chassis_bus::serial::SerialBus;
use chassis_bus::socketcan::SocketCan;
use chassis_bus::{BusSpec, ByteBus, CanBus, CanEvent};
use chassis_client::{
    ChassisState, ControlMode, ControllerState, FaultFlags, LinkFlags, LockStatus, MuxStatus,
    Robot, SourceFlags, WireProtocol, deadline, now_ns,
};
use chassis_protocols::agilex_v2::detect::{Detection, Detector};
use chassis_protocols::registry::Bus as RobotBus;
use chassis_protocols::slcan::ADAPTER_BAUD;
use chassis_protocols::{CanFrame, DriverConfig, Protocol, RobotKind, Rx, Timestamp};
use chassisd_config::RawConfig;
use clap::Args;
use nix::poll::{PollFd, PollFlags, PollTimeout, poll};
use serde::Serialize;
use socketcan::nl::CanState;

#[derive(Debug, Args)]
pub struct DoctorArgs {
    /// The robot's name (chassisd --name).
    #[arg(long)]
    pub name: Option<String>,
    /// The robot (default: the config's, else titan).
    #[arg(long)]
    pub robot: Option<RobotKind>,
    /// The bus, as for chassisd: `can:IFACE`, `slcan:PATH[@BAUD]`, `serial:PATH[@BAUD]` or `sim`
    /// (default: the config's).
    #[arg(long)]
    pub bus: Option<String>,
    /// chassisd's configuration file, for the robot, name, bus and state directory.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// How long to listen to the bus, s.
    #[arg(long, default_value_t = 2.0)]
    pub listen: f64,
    /// One JSON object per check, then a summary object.
    #[arg(long)]
    pub json: bool,
}

/// What a check found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Verdict {
    Ok,
    Warn,
    Fail,
    Skip,
}

impl fmt::Display for Verdict {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Verdict::Ok => "ok",
            Verdict::Warn => "warn",
            Verdict::Fail => "FAIL",
            Verdict::Skip => "skip",
        })
    }
}

/// One line of the report.
#[derive(Debug, Clone, Serialize)]
pub struct Check {
    /// A short stable key (`interface`, `bitrate`, …) for scripts and tests.
    pub check: &'static str,
    pub verdict: Verdict,
    pub what: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fix: Option<String>,
}

fn check(check: &'static str, verdict: Verdict, what: impl Into<String>) -> Check {
    Check {
        check,
        verdict,
        what: what.into(),
        fix: None,
    }
}

fn ok(key: &'static str, what: impl Into<String>) -> Check {
    check(key, Verdict::Ok, what)
}

fn warn(key: &'static str, what: impl Into<String>) -> Check {
    check(key, Verdict::Warn, what)
}

fn fail(key: &'static str, what: impl Into<String>) -> Check {
    check(key, Verdict::Fail, what)
}

fn skip(key: &'static str, what: impl Into<String>) -> Check {
    check(key, Verdict::Skip, what)
}

impl Check {
    fn fix(mut self, fix: impl Into<String>) -> Self {
        self.fix = Some(fix.into());
        self
    }
}

/// What the doctor was asked to look at, resolved from the arguments and the config.
#[derive(Debug, Clone)]
pub struct Target {
    pub robot: RobotKind,
    pub name: String,
    pub bus: BusSpec,
    pub state_dir: Option<PathBuf>,
    pub bitrate: Option<u32>,
    pub listen: Duration,
}

fn target(args: &DoctorArgs) -> anyhow::Result<Target> {
    let raw = match &args.config {
        Some(path) => Some(RawConfig::load(path).with_context(|| format!("{}", path.display()))?),
        None => None,
    };
    let service = raw.as_ref().map(|r| &r.service);
    let robot = args
        .robot
        .or(service.and_then(|s| s.robot))
        .unwrap_or(RobotKind::Titan);
    let name = args
        .name
        .clone()
        .or(service.and_then(|s| s.name.clone()))
        .unwrap_or_else(|| robot.name().to_string());
    let bus_text = args
        .bus
        .clone()
        .or(service.and_then(|s| s.bus.clone()))
        .context("which bus? give --bus (can:can0, slcan:/dev/ttyACM0, serial:/dev/ttyUSB0, sim) or --config")?;
    let bus: BusSpec = bus_text.parse()?;
    let state_dir = service
        .and_then(|s| s.state_dir.clone())
        .or_else(|| chassisd_config::default_state_dir(&name, |key| std::env::var_os(key)));
    let bitrate = match robot.entry().bus {
        RobotBus::Can { bitrate } => Some(bitrate),
        RobotBus::Rs232 => None,
    };
    Ok(Target {
        robot,
        name,
        bus,
        state_dir,
        bitrate,
        listen: Duration::from_secs_f64(args.listen.clamp(0.1, 60.0)),
    })
}

/// `chassis doctor`: prints the report; `Ok(false)` when something blocks driving.
pub fn run(args: &DoctorArgs) -> anyhow::Result<bool> {
    let target = target(args)?;
    if !args.json {
        println!(
            "chassis doctor: {} ({}) on {}",
            target.robot.entry().display_name,
            target.name,
            target.bus
        );
    }
    let mut failed = 0;
    let mut warned = 0;
    let mut emit = |c: Check| {
        match c.verdict {
            Verdict::Fail => failed += 1,
            Verdict::Warn => warned += 1,
            _ => {}
        }
        if args.json {
            println!("{}", serde_json::to_string(&c).unwrap_or_default());
        } else {
            println!("{}", render(&c));
        }
    };
    diagnose(&target, &mut emit);
    if args.json {
        println!(
            "{}",
            serde_json::json!({ "verdict": if failed > 0 { "blocked" } else { "ready" },
                "failed": failed, "warnings": warned })
        );
    } else if failed > 0 {
        println!(
            "verdict: {failed} problem{} block{} driving",
            if failed == 1 { "" } else { "s" },
            if failed == 1 { "s" } else { "" }
        );
    } else {
        println!("verdict: ready to drive ({warned} warning(s))");
    }
    Ok(failed == 0)
}

/// One check as a line (and its fix on the next one).
pub fn render(c: &Check) -> String {
    let mut text = format!("{:<5} {:<11} {}", c.verdict.to_string(), c.check, c.what);
    if let Some(fix) = &c.fix {
        let head = match c.verdict {
            Verdict::Fail | Verdict::Warn => "fix",
            Verdict::Ok | Verdict::Skip => "next",
        };
        text.push_str(&format!("\n{:<17} {head}: {fix}", ""));
    }
    text
}

/// Runs every check for `target`, in order, handing each to `emit` as soon as it is known.
pub fn diagnose(target: &Target, emit: &mut dyn FnMut(Check)) {
    // chassisd first: when it serves the robot, it owns the bus (a serial port is exclusive)
    // and what the bus carries is read from its state.
    let (serving, served) = chassisd_serving(target);
    let mut heard = None;
    match &target.bus {
        BusSpec::Can { iface } => {
            let usable = can_interface(target, iface, emit);
            if usable && serving.is_none() {
                heard = Some(listen_can(target, iface, emit));
            }
        }
        BusSpec::Slcan { path, baud } | BusSpec::Serial { path, baud } => {
            let slcan = matches!(target.bus, BusSpec::Slcan { .. });
            wrong_bus_kind(target, slcan, emit);
            let usable = serial_device(path, emit);
            if usable && serving.is_none() {
                heard = Some(if slcan {
                    listen_slcan(target, path, *baud, emit)
                } else {
                    listen_serial(target, path, *baud, emit)
                });
            }
        }
        BusSpec::Sim => emit(ok(
            "bus",
            "the simulated chassis (inside chassisd): no device to check",
        )),
        other => emit(skip(
            "bus",
            format!("{other}: not a robot's bus (chassis doctor checks sim, can, slcan, serial)"),
        )),
    }
    match (&serving, heard) {
        (Some((state, mux)), _) => {
            from_service(target, state, emit);
            mux_check(target, mux.as_ref(), emit);
        }
        (None, Some(Some(state))) => robot_mode(&state, emit),
        _ => {}
    }
    state_directory(target, emit);
    emit(served);
    iceoryx2_directories(emit);
}

fn wrong_bus_kind(target: &Target, slcan: bool, emit: &mut dyn FnMut(Check)) {
    if slcan != target.robot.is_can() {
        let want = if target.robot.is_can() {
            "can:IFACE or slcan:PATH"
        } else {
            "serial:PATH"
        };
        emit(
            fail(
                "bus",
                format!(
                    "{} is not on this kind of bus",
                    target.robot.entry().display_name
                ),
            )
            .fix(format!("use --bus {want}")),
        );
    }
}

// ---------------------------------------------------------------------------------- SocketCAN

/// The interface's checks: exists, is CAN, is up, bit rate, controller state, restart-ms.
/// Returns whether it can be listened to.
fn can_interface(target: &Target, iface: &str, emit: &mut dyn FnMut(Check)) -> bool {
    let sys = Path::new("/sys/class/net").join(iface);
    let bitrate = target.bitrate.unwrap_or(500_000);
    let up_cmd = format!("sudo ip link set {iface} up type can bitrate {bitrate} restart-ms 100");
    if !sys.exists() {
        let others = can_interfaces();
        emit(
            fail("interface", format!("no network interface {iface}")).fix(format!(
                "plug the adapter in and look for it with `ip -details link show type can` \
                     (CAN interfaces here: {}); a gs_usb/candleLight adapter needs the module \
                     gs_usb, a PEAK one peak_usb (`sudo modprobe gs_usb`); docs/HARDWARE.md",
                if others.is_empty() {
                    "none".to_string()
                } else {
                    others.join(", ")
                }
            )),
        );
        return false;
    }
    let link_type = std::fs::read_to_string(sys.join("type")).unwrap_or_default();
    // ARPHRD_CAN.
    if link_type.trim() != "280" {
        emit(
            fail(
                "interface",
                format!(
                    "{iface} is not a CAN interface (link type {})",
                    link_type.trim()
                ),
            )
            .fix("name the CAN interface: `ip -details link show type can` lists them"),
        );
        return false;
    }
    let driver = std::fs::read_link(sys.join("device/driver"))
        .ok()
        .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()));
    let virtual_ = driver.is_none();
    emit(ok(
        "interface",
        match &driver {
            Some(d) => format!("{iface} is a CAN interface (driver {d})"),
            None => format!("{iface} is a CAN interface (virtual: no controller, no bit rate)"),
        },
    ));
    let details = socketcan::CanInterface::open(iface).and_then(|i| i.details());
    let details = match details {
        Ok(d) => d,
        Err(err) => {
            emit(warn(
                "interface",
                format!("{iface}: its settings cannot be read over netlink ({err})"),
            ));
            return true;
        }
    };
    if !details.is_up {
        emit(fail("up", format!("{iface} is down")).fix(if virtual_ {
            format!("sudo ip link set {iface} up")
        } else {
            up_cmd.clone()
        }));
        return false;
    }
    emit(ok("up", format!("{iface} is up")));
    let can = &details.can;
    if virtual_ {
        emit(skip(
            "bitrate",
            format!("{iface} is virtual: it has no bit rate"),
        ));
    } else {
        match can.bit_timing.map(|t| t.bitrate) {
            Some(rate) if rate == bitrate => emit(ok(
                "bitrate",
                format!("{rate} bit/s, the {}'s", target.robot.entry().display_name),
            )),
            Some(rate) => emit(
                fail(
                    "bitrate",
                    format!(
                        "{rate} bit/s; the {} speaks {bitrate} bit/s",
                        target.robot.entry().display_name
                    ),
                )
                .fix(format!(
                    "sudo ip link set {iface} down && sudo ip link set {iface} type can bitrate \
                     {bitrate} restart-ms 100 && sudo ip link set {iface} up"
                )),
            ),
            None => emit(warn("bitrate", format!("{iface} reports no bit rate"))),
        }
    }
    let counters = can
        .berr_counter
        .map(|c| format!(" (error counters tx {}, rx {})", c.txerr, c.rxerr))
        .unwrap_or_default();
    match can.state {
        // A vcan has no controller: the bit rate line said it is virtual.
        None if virtual_ => {}
        None => emit(skip(
            "controller",
            format!("{iface} reports no controller state"),
        )),
        Some(CanState::ErrorActive) => emit(ok("controller", format!("error-active{counters}"))),
        Some(CanState::ErrorWarning) => emit(warn(
            "controller",
            format!("error-warning{counters}: errors on the bus"),
        )),
        Some(CanState::ErrorPassive) => emit(
            warn(
                "controller",
                format!("error-passive{counters}: many errors on the bus"),
            )
            .fix(can_controller::BUS_TROUBLE),
        ),
        Some(CanState::BusOff) => emit(
            fail(
                "controller",
                format!(
                    "bus-off{counters}: the controller has left the bus ({})",
                    can_controller::BUS_TROUBLE
                ),
            )
            .fix(can_controller::bus_off_fix(iface, can.restart_ms)),
        ),
        Some(state @ (CanState::Stopped | CanState::Sleeping)) => {
            emit(fail("controller", format!("{state:?}")).fix(up_cmd.clone()))
        }
    }
    if !virtual_ {
        match can.restart_ms {
            Some(ms) if ms > 0 => emit(ok(
                "restart-ms",
                format!("{ms} ms: the kernel restarts the controller after a bus-off"),
            )),
            _ => emit(
                warn(
                    "restart-ms",
                    "0: after a bus-off the controller stays off the bus until restarted by hand",
                )
                .fix(format!(
                    "sudo ip link set {iface} down && sudo ip link set {iface} type can \
                     restart-ms 100 && sudo ip link set {iface} up (or RestartSec=100ms in its \
                     systemd-networkd .network file)"
                )),
            ),
        }
    }
    true
}

/// Waits until `fd` is readable (true) or the deadline `end_ns` passes (false).
fn readable_before(fd: RawFd, end_ns: u64) -> bool {
    let left = end_ns.saturating_sub(now_ns());
    if left == 0 {
        return false;
    }
    // SAFETY: `fd` belongs to a bus the caller holds for the whole call.
    let fd = unsafe { BorrowedFd::borrow_raw(fd) };
    let mut fds = [PollFd::new(fd, PollFlags::POLLIN)];
    // Rounded up to the next millisecond, so a short wait still waits.
    let timeout = PollTimeout::try_from(left.div_ceil(1_000_000)).unwrap_or(PollTimeout::MAX);
    // EINTR and the like: look again (the deadline ends the loop).
    poll(&mut fds, timeout).map_or(true, |n| n > 0 || now_ns() < end_ns)
}

/// The CAN interfaces of this computer.
fn can_interfaces() -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir("/sys/class/net")
        .into_iter()
        .flatten()
        .flatten()
        .filter(|e| std::fs::read_to_string(e.path().join("type")).is_ok_and(|t| t.trim() == "280"))
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// Listens on `iface` for the target's time; reports the frames and controller reports heard.
fn listen_can(target: &Target, iface: &str, emit: &mut dyn FnMut(Check)) -> Option<ChassisState> {
    let mut bus = match SocketCan::open(iface) {
        Ok(bus) => bus,
        Err(err) => {
            emit(fail("frames", format!("cannot listen: {err}")));
            return None;
        }
    };
    let mut frames = Vec::new();
    let mut errors = 0u32;
    let mut overflows = 0u32;
    let mut bus_off = false;
    let end = deadline(target.listen);
    while now_ns() < end {
        match bus.recv_event() {
            Ok(Some(CanEvent::Frame(frame))) => frames.push(frame),
            Ok(Some(CanEvent::Controller(report))) => {
                if report.overflow {
                    overflows += 1;
                }
                if report.bus_error
                    || report.no_ack
                    || report.state >= ControllerState::ERROR_WARNING
                {
                    errors += 1;
                }
                bus_off |= report.state == ControllerState::BUS_OFF;
            }
            Ok(None) if readable_before(bus.raw_fd(), end) => {}
            Ok(None) => break,
            Err(err) => {
                emit(fail("frames", format!("reading {iface}: {err}")));
                return None;
            }
        }
    }
    if errors > 0 {
        emit(
            check(
                "bus-errors",
                if bus_off {
                    Verdict::Fail
                } else {
                    Verdict::Warn
                },
                format!(
                    "{errors} report(s) of errors on the bus from the controller in {:.1} s{}",
                    target.listen.as_secs_f64(),
                    if bus_off { ", bus-off among them" } else { "" }
                ),
            )
            .fix(can_controller::BUS_TROUBLE),
        );
    }
    if overflows > 0 {
        emit(
            warn(
                "overflow",
                format!(
                    "the controller's buffer overflowed {overflows} time(s) in {:.1} s: frames \
                     were lost before this computer read them",
                    target.listen.as_secs_f64()
                ),
            )
            .fix(
                "a busy or slow computer, or a USB adapter behind a shared hub: give the \
                 adapter its own port, or chassisd a CPU (`--cpu N --realtime 80`)",
            ),
        );
    }
    can_frames(target, &frames, emit)
}

/// What the frames heard say: how many, which ids, which protocol (the V1/V2 rule) and which
/// robots of the registry they fit. Returns the state the target robot's driver makes of them.
fn can_frames(
    target: &Target,
    frames: &[CanFrame],
    emit: &mut dyn FnMut(Check),
) -> Option<ChassisState> {
    let secs = target.listen.as_secs_f64();
    if frames.is_empty() {
        emit(
            fail("frames", format!("nothing heard in {secs:.1} s")).fix(format!(
                "is the chassis on (key switch) and its CAN connector plugged? CAN H to H, L to L \
                 (swapped wires give silence or bus-off), 120 Ω termination at each end (about \
                 60 Ω between H and L with the power off), the bit rate {} bit/s",
                target.bitrate.unwrap_or(500_000)
            )),
        );
        return None;
    }
    let mut ids: BTreeMap<u32, u32> = BTreeMap::new();
    for f in frames {
        *ids.entry(f.id()).or_default() += 1;
    }
    let listed: Vec<String> = ids
        .keys()
        .take(12)
        .map(|id| format!("0x{id:03X}"))
        .collect();
    emit(ok(
        "frames",
        format!(
            "{} frames in {secs:.1} s, {} ids ({}{})",
            frames.len(),
            ids.len(),
            listed.join(" "),
            if ids.len() > 12 { " …" } else { "" }
        ),
    ));
    let fits = robots_fitting(frames);
    let protocol = if target.robot.entry().detects_protocol() {
        let mut detector = Detector::new(Timestamp::ZERO, Duration::ZERO, 3);
        for f in frames {
            detector.handle_rx(f);
        }
        match detector.poll(Timestamp::ZERO) {
            Detection::Decided(p) => {
                emit(ok(
                    "protocol",
                    format!("AgileX {p} (the V1/V2 rule chassisd applies)"),
                ));
                Some(p)
            }
            other => {
                emit(warn("protocol", other.describe()));
                None
            }
        }
    } else {
        target.robot.entry().defaults().protocol()
    };
    let names = |list: &[(RobotKind, Option<Protocol>)]| {
        list.iter()
            .map(|(r, p)| match p {
                Some(p) => format!("{r} ({p})"),
                None => r.to_string(),
            })
            .collect::<Vec<_>>()
            .join(", ")
    };
    if fits.iter().any(|(r, _)| *r == target.robot) {
        emit(ok(
            "robot",
            format!(
                "the frames fit a {}; robots they fit: {}",
                target.robot,
                names(&fits)
            ),
        ));
    } else if fits.is_empty() {
        emit(
            fail("robot", "the frames are no robot's chassisd knows")
                .fix("another device on this bus? `candump` it and compare with docs/PROTOCOLS.md"),
        );
    } else {
        emit(
            fail(
                "robot",
                format!(
                    "the frames are not a {}'s; robots they fit: {}",
                    target.robot,
                    names(&fits)
                ),
            )
            .fix("give chassisd (and the doctor) --robot for the robot on the bus"),
        );
    }
    let entry = target.robot.entry();
    let profile = entry.default_profile(protocol).ok()?;
    let mut driver = profile.driver(&DriverConfig::default(), Timestamp::ZERO);
    for f in frames {
        driver.handle_rx(Timestamp::ZERO, Rx::Can(f));
    }
    Some(*driver.state())
}

/// The robots (and protocols) whose driver decodes nearly every frame heard.
fn robots_fitting(frames: &[CanFrame]) -> Vec<(RobotKind, Option<Protocol>)> {
    let mut fits = Vec::new();
    for robot in RobotKind::ALL {
        let entry = robot.entry();
        if !robot.is_can() {
            continue;
        }
        for profile in entry.profiles() {
            let protocol = profile.protocol();
            let mut driver = profile.driver(&DriverConfig::default(), Timestamp::ZERO);
            for f in frames {
                driver.handle_rx(Timestamp::ZERO, Rx::Can(f));
            }
            let link = driver.state().link;
            let bad = link.rx_unknown_id + link.rx_decode_errors + link.rx_bad_checksum;
            // Nine in ten: a frame of another device now and then does not hide the robot.
            if link.rx_frames > 0 && bad * 10 <= frames.len() as u64 {
                fits.push((robot, protocol.filter(|_| entry.detects_protocol())));
            }
        }
    }
    fits
}

// ----------------------------------------------------------------------------- serial, slcan

/// The device's checks: exists, is a character device, this user may read and write it.
fn serial_device(path: &str, emit: &mut dyn FnMut(Check)) -> bool {
    let meta = match std::fs::metadata(path) {
        Ok(m) => m,
        Err(err) => {
            emit(fail("device", format!("{path}: {err}")).fix(
                "plug the adapter in; `ls -l /dev/serial/by-id/` names USB serial \
                     adapters by serial number (a udev rule gives a stable name: docs/HARDWARE.md)",
            ));
            return false;
        }
    };
    if !meta.file_type().is_char_device() {
        emit(
            fail("device", format!("{path} is not a character device"))
                .fix("name the serial port (/dev/ttyUSB0, /dev/ttyACM0, /dev/serial/by-id/…)"),
        );
        return false;
    }
    emit(ok("device", format!("{path} exists")));
    let access = nix::unistd::access(
        Path::new(path),
        nix::unistd::AccessFlags::R_OK | nix::unistd::AccessFlags::W_OK,
    );
    match access {
        Ok(()) => {
            emit(ok("permission", "this user may read and write it"));
            true
        }
        Err(err) => {
            let group = nix::unistd::Group::from_gid(nix::unistd::Gid::from_raw(meta.gid()))
                .ok()
                .flatten()
                .map_or_else(|| meta.gid().to_string(), |g| g.name);
            let user = nix::unistd::User::from_uid(nix::unistd::getuid())
                .ok()
                .flatten()
                .map_or_else(|| nix::unistd::getuid().to_string(), |u| u.name);
            let mode = meta.mode() & 0o777;
            let fix = if mode & 0o060 != 0o060 || meta.gid() == 0 {
                format!(
                    "the device is not shared with a group (mode {mode:o}, group {group}): a \
                     udev rule giving it GROUP=\"dialout\", MODE=\"0660\" \
                     (docs/HARDWARE.md), then `sudo usermod -aG dialout {user}` and log in again"
                )
            } else {
                format!("sudo usermod -aG {group} {user}, then log out and in again")
            };
            emit(
                fail(
                    "permission",
                    format!(
                        "{user} may not read and write {path} ({err}; owner group {group}, mode \
                         {mode:o})"
                    ),
                )
                .fix(fix),
            );
            false
        }
    }
}

fn open_serial(path: &str, baud: u32, emit: &mut dyn FnMut(Check)) -> Option<SerialBus> {
    match SerialBus::open(path, baud) {
        Ok(port) => Some(port),
        Err(err) => {
            emit(fail("open", format!("{err}")).fix(
                "another program holds the port (`fuser -v PATH` names it): stop it, or \
                     let the running chassisd serve",
            ));
            None
        }
    }
}

/// Reads what the port sends for `until`.
fn read_for(port: &mut SerialBus, until: Duration) -> Result<Vec<u8>, String> {
    let mut bytes = Vec::new();
    let mut buf = [0u8; 1024];
    let end = deadline(until);
    while now_ns() < end {
        match port.read(&mut buf) {
            Ok(0) if readable_before(port.raw_fd(), end) => {}
            Ok(0) => break,
            Ok(n) => bytes.extend_from_slice(&buf[..n]),
            Err(err) => return Err(err.to_string()),
        }
    }
    Ok(bytes)
}

/// An slcan adapter: does it answer `V` (its version), then the frames it passes on.
fn listen_slcan(
    target: &Target,
    path: &str,
    baud: Option<u32>,
    emit: &mut dyn FnMut(Check),
) -> Option<ChassisState> {
    let mut port = open_serial(path, baud.unwrap_or(ADAPTER_BAUD), emit)?;
    // Close the channel (in case it was left open), then ask for the version.
    let asked = port.write_all(b"C\r").and_then(|()| port.write_all(b"V\r"));
    let answer = asked
        .map_err(|e| e.to_string())
        .and_then(|()| read_for(&mut port, Duration::from_millis(300)));
    match answer {
        Ok(bytes) if bytes.contains(&b'V') || bytes.contains(&b'v') => {
            let text = String::from_utf8_lossy(&bytes);
            let version = text
                .split('\r')
                .find(|l| l.starts_with(['V', 'v']))
                .unwrap_or("")
                .to_string();
            emit(ok(
                "adapter",
                format!("the slcan adapter answers (version {version})"),
            ));
        }
        Ok(bytes) => {
            emit(
                fail(
                    "adapter",
                    format!("no slcan answer to `V` ({} bytes back)", bytes.len()),
                )
                .fix(
                    "is it an slcan adapter (CANable with slcan firmware, USBtin, Lawicel)? A \
                     candleLight firmware makes it a SocketCAN interface: use --bus can:can0",
                ),
            );
            return None;
        }
        Err(err) => {
            emit(fail("adapter", err));
            return None;
        }
    }
    let bitrate = target.bitrate.unwrap_or(500_000);
    let mut bus = match chassis_bus::slcan::SlcanBus::open(port, bitrate) {
        Ok(bus) => bus,
        Err(err) => {
            emit(fail("bitrate", err.to_string()));
            return None;
        }
    };
    emit(ok("bitrate", format!("channel opened at {bitrate} bit/s")));
    let mut frames = Vec::new();
    let end = deadline(target.listen);
    while now_ns() < end {
        match bus.recv() {
            Ok(Some(frame)) => frames.push(frame),
            Ok(None) if readable_before(bus.raw_fd(), end) => {}
            Ok(None) => break,
            Err(err) => {
                emit(fail("frames", err.to_string()));
                return None;
            }
        }
    }
    can_frames(target, &frames, emit)
}

/// A robot on RS232: the bytes it sends, decoded by its driver.
fn listen_serial(
    target: &Target,
    path: &str,
    baud: Option<u32>,
    emit: &mut dyn FnMut(Check),
) -> Option<ChassisState> {
    let entry = target.robot.entry();
    let profile = entry.defaults();
    let Some(baud) = baud.or(profile.serial_baud()) else {
        emit(fail(
            "frames",
            format!(
                "{} has no serial link: use can:IFACE or slcan:PATH",
                target.robot
            ),
        ));
        return None;
    };
    let mut port = open_serial(path, baud, emit)?;
    let bytes = match read_for(&mut port, target.listen) {
        Ok(bytes) => bytes,
        Err(err) => {
            emit(fail("frames", err));
            return None;
        }
    };
    let secs = target.listen.as_secs_f64();
    if bytes.is_empty() {
        emit(
            fail("frames", format!("no byte in {secs:.1} s at {baud} baud")).fix(
                "is the chassis on and the cable's TX to the robot's RX (a null-modem \
                      cable or adapter where both ends are DTE)?",
            ),
        );
        return None;
    }
    let mut driver = profile.driver(&DriverConfig::default(), Timestamp::ZERO);
    driver.handle_rx(Timestamp::ZERO, Rx::Bytes(&bytes));
    let state = *driver.state();
    let link = state.link;
    if link.rx_frames == 0 {
        emit(
            fail(
                "frames",
                format!(
                    "{} bytes in {secs:.1} s, none of them a {} report ({} bad checksums, {} \
                     bytes discarded)",
                    bytes.len(),
                    target.robot,
                    link.rx_bad_checksum,
                    link.rx_bytes_discarded
                ),
            )
            .fix(format!("another baud rate? The profile says {baud}")),
        );
        return None;
    }
    emit(ok(
        "frames",
        format!(
            "{} {} reports in {secs:.1} s ({} bytes, {} bad checksums)",
            link.rx_frames,
            target.robot,
            bytes.len(),
            link.rx_bad_checksum
        ),
    ));
    Some(state)
}

// ------------------------------------------------------------------------------- the robot

/// Control mode and E-stop from a state sample.
fn robot_mode(state: &ChassisState, emit: &mut dyn FnMut(Check)) {
    let mode = state.system.control_mode;
    if mode == ControlMode::REMOTE || state.has_link_flag(LinkFlags::RC_AUTHORITY) {
        emit(
            fail(
                "mode",
                "the RC transmitter holds the robot (remote control mode)",
            )
            .fix(
                "set the transmitter's mode switch to command (CAN/serial) control, as the \
                 robot's manual shows, or switch the transmitter off",
            ),
        );
    } else if mode == ControlMode::UNKNOWN {
        emit(warn("mode", "no status frame heard: control mode unknown"));
    } else {
        emit(ok(
            "mode",
            format!(
                "{} (chassisd asks for command mode)",
                ControlMode::name(mode)
            ),
        ));
    }
    if state.system.fault_flags & FaultFlags::EMERGENCY_STOP != 0 {
        emit(fail("e-stop", "the E-stop is pressed").fix(
            "release the chassis' E-stop button (turn it); chassisd then holds zero until \
                     the winning source has asked for zero once",
        ));
    } else {
        emit(ok("e-stop", "released"));
    }
}

/// Whether a chassisd serves `target.name`, and a fresh state sample when it does.
fn chassisd_serving(target: &Target) -> (Option<(ChassisState, Option<MuxStatus>)>, Check) {
    let name = &target.name;
    let mut robot = match Robot::connect(name) {
        Ok(robot) => robot,
        Err(chassis_client::ClientError::NotRunning { .. }) => {
            return (
                None,
                ok(
                    "chassisd",
                    format!("no chassisd serves {name} yet: the bus is free for it"),
                )
                .fix(format!(
                    "then start it: `chassisd --robot {} --name {name} --bus {}` (or \
                     `sudo systemctl start chassisd@{name}`)",
                    target.robot, target.bus
                )),
            );
        }
        Err(err @ chassis_client::ClientError::OtherUser { .. }) => {
            return (
                None,
                fail("chassisd", err.to_string()).fix(
                    "every program of the robot runs as chassisd's user (its iceoryx2 files \
                     are that user's alone)",
                ),
            );
        }
        Err(err) => {
            return (
                None,
                warn("chassisd", format!("asking for chassis/{name}: {err}")),
            );
        }
    };
    let state = robot.wait_state(Duration::from_millis(1500)).ok().flatten();
    let mux = match robot.latest_mux() {
        Ok(Some(m)) => Some(m),
        _ => robot.wait_mux(Duration::from_millis(500)).ok().flatten(),
    };
    match state {
        Some(s) if s.robot != target.robot.id() => (
            None,
            fail(
                "chassisd",
                format!(
                    "a chassisd already serves {name}, as a {}",
                    chassis_protocols::RobotKind::from_id(s.robot).map_or(
                        "robot of an unknown kind",
                        chassis_protocols::RobotKind::name
                    )
                ),
            )
            .fix("give this robot another --name, or stop that chassisd"),
        ),
        Some(s) => (
            Some((s, mux)),
            ok(
                "chassisd",
                format!(
                    "chassisd serves chassis/{name} and owns the bus (state #{})",
                    s.seq
                ),
            ),
        ),
        None => (
            None,
            fail(
                "chassisd",
                format!("a chassisd holds chassis/{name} but publishes no state"),
            )
            .fix(format!(
                "it is stuck or stopped: `journalctl -u chassisd@{name}`, then restart it"
            )),
        ),
    }
}

/// What the serving chassisd's state says: the bus, the controller, the protocol, the mode.
fn from_service(target: &Target, s: &ChassisState, emit: &mut dyn FnMut(Check)) {
    let link = s.link;
    if s.has_link_flag(LinkFlags::BUS_DOWN) {
        emit(
            fail("frames", "chassisd has lost the bus (bus_down)")
                .fix("see the checks above, and `journalctl -u chassisd@NAME`"),
        );
    } else if s.has_link_flag(LinkFlags::CAN_BUS_OFF) {
        let iface = match &target.bus {
            BusSpec::Can { iface } => iface.as_str(),
            _ => "IFACE",
        };
        emit(
            fail(
                "frames",
                format!(
                    "chassisd reports the CAN controller bus-off ({} bus-offs)",
                    link.can_bus_off
                ),
            )
            .fix(can_controller::bus_off_fix(iface, None)),
        );
    } else if s.has_link_flag(LinkFlags::CHASSIS_SILENT) {
        emit(
            fail(
                "frames",
                format!(
                    "chassisd hears nothing from the chassis ({} frames so far)",
                    link.rx_frames
                ),
            )
            .fix("is the chassis on, its connector plugged, the bit rate the robot's?"),
        );
    } else {
        emit(ok(
            "frames",
            format!(
                "chassisd hears the chassis: {} frames, {} decode errors, {} unknown ids",
                link.rx_frames, link.rx_decode_errors, link.rx_unknown_id
            ),
        ));
    }
    if link.can_state != ControllerState::UNKNOWN || link.can_error_frames > 0 {
        emit(check(
            "controller",
            match link.can_state {
                ControllerState::BUS_OFF => Verdict::Fail,
                ControllerState::ERROR_PASSIVE | ControllerState::ERROR_WARNING => Verdict::Warn,
                _ => Verdict::Ok,
            },
            format!(
                "{} (as chassisd last heard): tx {} rx {} errors, {} bus-offs, {} restarts",
                ControllerState::name(link.can_state),
                link.can_tx_error_count,
                link.can_rx_error_count,
                link.can_bus_off,
                link.can_restarts
            ),
        ));
    }
    if target.robot.entry().detects_protocol() {
        let p = s.system.wire_protocol;
        emit(check(
            "protocol",
            if p == WireProtocol::DETECTING {
                Verdict::Warn
            } else {
                Verdict::Ok
            },
            format!("chassisd speaks {}", WireProtocol::name(p)),
        ));
    }
    robot_mode(s, emit);
}

/// What chassisd's mux lets through: a required source that is silent (the safety monitor not
/// running) or a held lock (an e-stop) stops every source below it.
fn mux_check(target: &Target, mux: Option<&MuxStatus>, emit: &mut dyn FnMut(Check)) {
    let name = &target.name;
    let Some(m) = mux else {
        emit(warn("mux", "chassisd published no mux decision"));
        return;
    };
    let mut blocked = false;
    let sources = &m.sources[..usize::from(m.source_count).min(m.sources.len())];
    for s in sources {
        if s.flags & SourceFlags::REQUIRED != 0 && s.flags & SourceFlags::FRESH == 0 {
            blocked = true;
            emit(
                fail(
                    "mux",
                    format!(
                        "the required source {} is silent: nothing moves without it",
                        s.name()
                    ),
                )
                .fix(format!(
                    "start the safety monitor: `sudo systemctl start chassis-safety@{name}` or \
                     `chassis-safety --name {name}` (chassisd --no-safety-monitor lifts the rule)"
                )),
            );
        }
    }
    let locks = &m.locks[..usize::from(m.lock_count).min(m.locks.len())];
    for l in locks.iter().filter(|l| l.held != 0) {
        blocked = true;
        let release = if l.name() == "estop" {
            format!("chassis control --name {name} estop-release")
        } else {
            format!("chassis control --name {name} lock-release {}", l.name())
        };
        let holder = match l.holder {
            LockStatus::HOLDER_OPERATOR => "an operator".to_string(),
            h => sources.get(usize::from(h)).map_or_else(
                || "a source".to_string(),
                |s| format!("the source {}", s.name()),
            ),
        };
        emit(
            fail(
                "mux",
                format!(
                    "the lock {} (priority {}) is held by {holder}: sources below it do not move \
                     the robot",
                    l.name(),
                    l.priority
                ),
            )
            .fix(format!("when it is safe: `{release}`")),
        );
    }
    if !blocked {
        emit(ok("mux", "no lock held, every required source alive"));
    }
}

// ------------------------------------------------------------------------- the computer

/// Can this user create a file in `dir` (or, when it does not exist yet, in the nearest parent
/// that does, where chassisd will create it)?
fn writable(dir: &Path) -> Result<PathBuf, String> {
    let mut at = dir;
    while !at.exists() {
        at = at
            .parent()
            .ok_or_else(|| "no existing parent".to_string())?;
    }
    let probe = at.join(format!(".chassis-doctor-{}", std::process::id()));
    match std::fs::File::create(&probe) {
        Ok(_) => {
            let _ = std::fs::remove_file(&probe);
            Ok(at.to_path_buf())
        }
        Err(e) => Err(format!("{}: {e}", at.display())),
    }
}

fn state_directory(target: &Target, emit: &mut dyn FnMut(Check)) {
    let Some(dir) = &target.state_dir else {
        emit(
            warn(
                "state-dir",
                "no state directory (neither STATE_DIRECTORY, XDG_STATE_HOME nor HOME is set)",
            )
            .fix("set state_dir in chassisd's config"),
        );
        return;
    };
    match writable(dir) {
        Ok(_) => emit(ok(
            "state-dir",
            format!(
                "{} is writable (held locks survive a restart)",
                dir.display()
            ),
        )),
        Err(err) => emit(
            fail(
                "state-dir",
                format!("{} is not writable ({err})", dir.display()),
            )
            .fix("give chassisd's user the directory, or set state_dir in its config"),
        ),
    }
}

fn iceoryx2_directories(emit: &mut dyn FnMut(Check)) {
    let mut bad = Vec::new();
    for dir in ["/dev/shm", "/tmp/iceoryx2"] {
        if let Err(err) = writable(Path::new(dir)) {
            bad.push(err);
        }
    }
    if bad.is_empty() {
        emit(ok("iceoryx2", "/dev/shm and /tmp/iceoryx2 are writable"));
    } else {
        emit(fail("iceoryx2", bad.join("; ")).fix(
            "every program of the robot must share /dev/shm and /tmp/iceoryx2 with write \
                 access: run them as the same user or group (a systemd unit with PrivateTmp= \
                 does not see the others' /tmp)",
        ));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frames(text: &[&str]) -> Vec<CanFrame> {
        text.iter()
            .map(|t| CanFrame::from_candump(t).unwrap())
            .collect()
    }

    fn target(robot: RobotKind) -> Target {
        Target {
            robot,
            name: "t".into(),
            bus: BusSpec::Can {
                iface: "can0".into(),
            },
            state_dir: None,
            bitrate: Some(500_000),
            listen: Duration::from_secs(1),
        }
    }

    fn checks(target: &Target, frames: &[CanFrame]) -> (Vec<Check>, Option<ChassisState>) {
        let mut out = Vec::new();
        let state = can_frames(target, frames, &mut |c| out.push(c));
        (out, state)
    }

    fn verdict(checks: &[Check], key: &str) -> Verdict {
        checks
            .iter()
            .find(|c| c.check == key)
            .unwrap_or_else(|| panic!("no {key} in {checks:?}"))
            .verdict
    }

    #[test]
    fn a_bunkers_v2_frames_fit_the_v2_robots_and_its_estop_blocks_driving() {
        // TV8 (BUNKER MINI 2.0, E-stop pressed) and an odometry frame.
        let heard = frames(&[
            "211#0100010000800000",
            "221#0000000000000000",
            "211#0100010000800000",
            "221#0000000000000000",
            "211#0100010000800000",
            "221#0000000000000000",
        ]);
        let (c, state) = checks(&target(RobotKind::Bunker), &heard);
        assert_eq!(verdict(&c, "frames"), Verdict::Ok);
        assert_eq!(verdict(&c, "robot"), Verdict::Ok, "{c:?}");
        let protocol = c.iter().find(|c| c.check == "protocol").unwrap();
        assert!(protocol.what.starts_with("AgileX v2"), "{protocol:?}");
        let mut mode = Vec::new();
        robot_mode(&state.unwrap(), &mut |c| mode.push(c));
        assert_eq!(verdict(&mode, "e-stop"), Verdict::Fail);

        // The V2 ids are shared by every V2 robot (TITAN's too): the frames fit them all.
        let robot = c.iter().find(|c| c.check == "robot").unwrap();
        assert!(robot.what.contains("bunker (v2)"), "{robot:?}");
        assert!(!robot.what.contains("(v1)"), "{robot:?}");
    }

    #[test]
    fn v1_frames_on_a_titans_bus_are_not_a_titans() {
        // PROTOCOLS.md §2: 0x130 with a valid V1 checksum.
        let heard = frames(&["130#01000A0000000044"; 3]);
        let (c, _) = checks(&target(RobotKind::Titan), &heard);
        let robot = c.iter().find(|c| c.check == "robot").unwrap();
        assert_eq!(robot.verdict, Verdict::Fail, "{c:?}");
        assert!(robot.what.contains("scout-mini (v1)"), "{robot:?}");
        let fits = robot.what.split("they fit: ").nth(1).unwrap();
        assert_eq!(fits, "scout-mini (v1), scout (v1), bunker (v1)");
        let (c, _) = checks(&target(RobotKind::ScoutMini), &heard);
        assert_eq!(verdict(&c, "robot"), Verdict::Ok, "{c:?}");
        assert!(
            c.iter()
                .any(|c| c.check == "protocol" && c.what.starts_with("AgileX v1"))
        );
    }

    #[test]
    fn silence_fails_with_the_wiring_fix() {
        let (c, state) = checks(&target(RobotKind::Titan), &[]);
        assert!(state.is_none());
        assert_eq!(verdict(&c, "frames"), Verdict::Fail);
        assert!(c[0].fix.as_deref().unwrap().contains("CAN H to H"));
    }

    #[test]
    fn rc_control_blocks_driving() {
        let mut s = ChassisState::default();
        s.system.control_mode = ControlMode::REMOTE;
        let mut c = Vec::new();
        robot_mode(&s, &mut |x| c.push(x));
        assert_eq!(verdict(&c, "mode"), Verdict::Fail);
        s.system.control_mode = ControlMode::COMMAND;
        c.clear();
        robot_mode(&s, &mut |x| c.push(x));
        assert_eq!(verdict(&c, "mode"), Verdict::Ok);
    }

    #[test]
    fn a_line_and_its_fix_are_aligned() {
        let c = fail("up", "can0 is down").fix("sudo ip link set can0 up");
        assert_eq!(
            render(&c),
            "FAIL  up          can0 is down\n                  fix: sudo ip link set can0 up"
        );
    }
}
