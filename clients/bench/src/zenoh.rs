//! `chassis-zenoh` paths between two network namespaces joined by a veth pair (the robot's
//! computer and an operator's), beside a bare Zenoh put → subscriber over the same veth in the
//! same run (`chassis-bench role zenoh-pub` and `zenoh-sub`: the bridge's session
//! configuration, payloads the size of a `ChassisState`, stamped with `CLOCK_MONOTONIC`):
//!
//! * operator request → frame on the robot's bus: the operator side's `remote` source (its
//!   own iceoryx2 prefix) → mirror → Zenoh → robot side → chassisd → the frame written;
//! * robot state → operator: the frame read by chassisd → the state sample in an iceoryx2
//!   subscriber of the operator side's mirror.
//!
//! Needs root (`ip netns`); without it the rows are left out with a note.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::mpsc;
use std::time::Duration;

use anyhow::{Context, bail};
use chassis_client::{ChassisState, Robot, Source, Ticker, now_ns, termination_requested};
use chassis_protocols::RobotKind;
use chassis_zenoh::net::{self, Net, Role};
use clap::Args;
use zenoh::Wait as _;
use zenoh::qos::{CongestionControl, Priority};

use crate::baseline::{Named, last_of};
use crate::paths::{
    self, BusKind, Children, LoopMode, ServiceConfig, StateRecorder, period_text, wait_until,
};
use crate::report::{Leg, PathKind, Report, Row};
use crate::stats::Latencies;

const ROBOT_ADDR: &str = "10.77.0.1";
const OPERATOR_ADDR: &str = "10.77.0.2";
const BRIDGE_PORT: u16 = 7447;
const RAW_PORT: u16 = 7449;

/// The rows' placement.
pub const PLACEMENT: &str = "2 netns, veth";
/// The rows' names: the bare Zenoh hop (one row as many samples as the command row, one as the
/// state rows) and the bridge's three paths.
pub const RAW_COMMAND: &str = "Zenoh put → subscriber, 840 B, as many as the command row";
pub const RAW_STATE: &str = "Zenoh put → subscriber, 840 B, as many as the state rows";
pub const COMMAND: &str = "operator's remote source → robot's frame written (titan sim)";
pub const STATE: &str = "robot's frame read → state in the operator's iceoryx2 (titan sim)";
pub const BRIDGE: &str = "robot's state published → in the operator's iceoryx2 (the bridge's part)";

/// Runs `ip` with `args` (split at spaces).
fn ip(args: &str) -> anyhow::Result<()> {
    let out = Command::new("ip")
        .args(args.split(' '))
        .output()
        .with_context(|| format!("running ip {args} (install iproute2)"))?;
    if !out.status.success() {
        bail!("ip {args}: {}", String::from_utf8_lossy(&out.stderr).trim());
    }
    Ok(())
}

/// Network namespaces, each with its loopback up, removed on drop.
pub(crate) struct Netns(Vec<String>);

impl Netns {
    pub fn new(names: &[String]) -> anyhow::Result<Self> {
        let mut made = Netns(Vec::new());
        for name in names {
            ip(&format!("netns add {name}"))?;
            made.0.push(name.clone());
            ip(&format!("-n {name} link set lo up"))?;
        }
        Ok(made)
    }

    /// The robot's and the operator's namespaces, joined by a veth pair.
    fn pair() -> anyhow::Result<Self> {
        let id = std::process::id() % 100_000;
        let ns = Netns::new(&[format!("cbr{id}"), format!("cbo{id}")])?;
        let (robot, operator) = (ns.robot(), ns.operator());
        ip(&format!("link add {robot} type veth peer name {operator}"))?;
        for (name, addr) in [(robot, ROBOT_ADDR), (operator, OPERATOR_ADDR)] {
            ip(&format!("link set {name} netns {name}"))?;
            ip(&format!("-n {name} addr add {addr}/24 dev {name}"))?;
            ip(&format!("-n {name} link set {name} up"))?;
        }
        Ok(ns)
    }

    /// The first namespace.
    pub fn robot(&self) -> &str {
        &self.0[0]
    }

    fn operator(&self) -> &str {
        &self.0[1]
    }
}

impl Drop for Netns {
    fn drop(&mut self) {
        for ns in &self.0 {
            let _ = Command::new("ip").args(["netns", "del", ns]).status();
        }
    }
}

/// What the chassis-zenoh processes log: warnings, Zenoh's own only when errors.
pub const ZENOH_LOG: &str = "warn,zenoh=error";

/// `program args…` (split at spaces) in network namespace `ns`.
fn zenoh_in(ns: &str, program: &Path, args: &str) -> Command {
    let mut cmd = Command::new("ip");
    cmd.args(["netns", "exec", ns])
        .arg(program)
        .args(args.split(' '));
    cmd
}

/// Bare Zenoh samples received before the counted ones (sessions, routes, allocations warm).
const RAW_WARMUP: u64 = 200;

/// True when this process may make network namespaces.
pub fn possible() -> bool {
    use std::os::unix::fs::MetadataExt as _;
    // /proc/self belongs to the process's effective user.
    std::fs::metadata("/proc/self").is_ok_and(|m| m.uid() == 0)
}

/// The pace of the state row's bare hop: the median period of the states the path counted
/// (`reads`, their frames' read times), 1.7 % more ([`paths::off_grid`]), so that the bare
/// sessions are woken as often as the bridge's are on its path; 20 ms when too few were
/// counted to tell.
fn state_period(reads: &[u64]) -> Duration {
    let mut reads = reads.to_vec();
    reads.sort_unstable();
    let mut gaps: Vec<u64> = reads
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|&g| g > 0)
        .collect();
    gaps.sort_unstable();
    let median = match gaps.len() {
        n if n >= 10 => Duration::from_nanos(gaps[n / 2]),
        _ => Duration::from_millis(20),
    };
    paths::off_grid(median)
}

/// The bare Zenoh hop, robot side publishing to the operator's, alone on the link: `count`
/// samples after [`RAW_WARMUP`], one per `pace`; the counted latencies, ns, in order.
fn bare_hop(
    netns: &Netns,
    (prefix, operator_prefix): (&str, &str),
    dir: &Path,
    count: u64,
    pace: Duration,
) -> anyhow::Result<Vec<u64>> {
    let raw = format!("tcp/{ROBOT_ADDR}:{RAW_PORT}");
    let tag = pace.as_micros();
    let raw_file = dir.join(format!("zenoh-raw-{tag}.ns"));
    let wanted = RAW_WARMUP + count;
    // Twice the time the samples take at their pace, and discovery.
    let timeout = (2.0 * wanted as f64 * pace.as_secs_f64() + 30.0).ceil();
    let sub_log = dir.join(format!("zenoh-raw-sub-{tag}"));
    let bench = std::env::current_exe().context("finding chassis-bench itself")?;
    let (operator, robot) = (netns.operator(), netns.robot());
    let args =
        format!("role zenoh-sub --connect {raw} --insecure --count {wanted} --timeout {timeout}");
    let mut sub = zenoh_in(operator, &bench, &args);
    let (sub_prefix, what) = ((operator_prefix, ZENOH_LOG), "the bare hop's subscriber");
    let mut sub = paths::spawn_logged(sub.arg("--out").arg(&raw_file), sub_prefix, &sub_log, what)?;
    let args =
        format!("role zenoh-pub --listen {raw} --insecure --interval-us {tag} --timeout {timeout}");
    let pub_log = dir.join(format!("zenoh-raw-pub-{tag}"));
    let (publisher, what) = (
        &mut zenoh_in(robot, &bench, &args),
        "the bare hop's publisher",
    );
    let mut publisher = paths::spawn_logged(publisher, (prefix, ZENOH_LOG), &pub_log, what)?;
    let status = sub.wait()?;
    let _ = publisher.wait();
    if !status.success() {
        bail!(
            "the bare Zenoh baseline failed; see {}-err.log",
            sub_log.display()
        );
    }
    std::fs::read_to_string(&raw_file)?
        .lines()
        .map(|line| line.trim().parse::<u64>().context("a latency in ns"))
        .skip(usize::try_from(RAW_WARMUP).unwrap_or(usize::MAX))
        .collect()
}

/// What [`measure`] brings: the bridge's paths and the bare hops beside them.
struct Measured {
    command: paths::CommandFigures,
    state: StateRecorder,
    /// The bridge's own part of each state: published → in the operator's iceoryx2.
    bridged: Latencies,
    raw_command: Vec<u64>,
    raw_state: Vec<u64>,
    /// The bare state hop's pace.
    state_period: Duration,
    split: crate::parts::Split,
}

/// Measures the Zenoh paths — `commands` requests one per [`paths::COMMAND_INTERVAL`], `states`
/// state samples — and their bare hops.
fn measure(prefix: &str, dir: &Path, commands: u64, states: u64) -> anyhow::Result<Measured> {
    let interval = paths::COMMAND_INTERVAL;
    let netns = Netns::pair()?;
    // chassisd keeps its pass trace: the state row's split starts with its notification.
    let titan_sim = (RobotKind::Titan, BusKind::Sim, LoopMode::Event);
    let (service, mut robot) =
        paths::start(titan_sim, None, ServiceConfig::Bench, true, prefix, dir)?;
    let name = service.name.clone();
    let operator_prefix = format!("{prefix}op_");
    let prefixes = (prefix, operator_prefix.as_str());

    // The command row's bare Zenoh hop first, alone on the link, at the command path's pace;
    // the state row's after the bridges stop, at the states' own (known then).
    let raw_command = bare_hop(&netns, prefixes, dir, commands, interval)?;

    // Each side keeps its stamps of the states it carries and writes them as it stops.
    let export_trace = dir.join("zenoh-robot.trace");
    let mirror_trace = dir.join("zenoh-operator.trace");
    let program = paths::sibling("chassis-zenoh")?;
    let bridge = format!("tcp/{ROBOT_ADDR}:{BRIDGE_PORT}");
    let args = format!("--name {name} --listen {bridge} --insecure");
    let mut robot_side = zenoh_in(netns.robot(), &program, &args);
    robot_side.env(chassis_ipc::Trace::ZenohExport.env(), &export_trace);
    let args = format!("--name {name} --connect {bridge} --insecure --mirror");
    let mut mirror = zenoh_in(netns.operator(), &program, &args);
    mirror.env(chassis_ipc::Trace::ZenohMirror.env(), &mirror_trace);
    let (robot_log, mirror_log) = (dir.join("zenoh-robot"), dir.join("zenoh-operator"));
    let (robot_what, mirror_what) = ("chassis-zenoh (robot side)", "chassis-zenoh --mirror");
    let (robot_logged, mirror_logged) = ((prefix, ZENOH_LOG), (&*operator_prefix, ZENOH_LOG));
    let children = Children(vec![
        paths::spawn_logged(&mut robot_side, robot_logged, &robot_log, robot_what)?,
        paths::spawn_logged(&mut mirror, mirror_logged, &mirror_log, mirror_what)?,
    ]);
    let mut operator = wait_until("the mirror served no state", 20, || {
        let mut r = Robot::connect_with_prefix(&name, Some(&operator_prefix)).ok()?;
        r.wait_state(Duration::from_millis(100)).ok().flatten()?;
        Some(r)
    })?;
    let mut remote: Source = wait_until("the mirror offered no remote source", 20, || {
        operator.source("remote").ok()
    })?;
    let (titan, sizes) = ((RobotKind::Titan, false), (commands, interval));
    let command = paths::command_path(&mut robot, titan, &mut remote, sizes, paths::Reach::Exact)?;

    // Robot state → the operator's iceoryx2 subscriber. The robot side forwards the newest
    // sample of each read of the bus: `seq` has gaps.
    let mut state = StateRecorder::with_gaps();
    let mut bridged = Latencies::new();
    let each = |s: &ChassisState, received| bridged.record_between(s.published_ns, received);
    paths::state_path(
        &operator,
        Some(&mut remote),
        &mut state,
        (states, false),
        each,
    )?;
    drop((remote, operator, children));
    let reads: Vec<u64> = state.samples.iter().map(|&(read, ..)| read).collect();
    let state_period = state_period(&reads);
    let raw_state = bare_hop(&netns, prefixes, dir, states, state_period)?;
    drop(robot);
    let passes = service.stop()?;
    drop(netns);
    // The mirror's iceoryx2 files, under the operator's prefix of this run only.
    for (path, e) in chassis_ipc::remove_ipc_files(&operator_prefix) {
        eprintln!("cannot remove {}: {e}", path.display());
    }
    let samples: Vec<(u64, u64)> = (state.samples.iter())
        .map(|&(read, _, received)| (read, received))
        .collect();
    let read_trace = crate::parts::read_trace;
    let split = crate::parts::zenoh_state(
        &samples,
        &read_trace(&export_trace, chassis_ipc::Trace::ZenohExport)?,
        &read_trace(&mirror_trace, chassis_ipc::Trace::ZenohMirror)?,
        &passes,
    );
    Ok(Measured {
        command,
        state,
        bridged,
        raw_command,
        raw_state,
        state_period,
        split,
    })
}

/// Measures the Zenoh paths and their bare hops ([`measure`]) and adds their rows to `report`.
pub fn run(
    prefix: &str,
    dir: &Path,
    commands: u64,
    states: u64,
    report: &mut Report,
) -> anyhow::Result<()> {
    let m = measure(prefix, dir, commands, states)?;
    // chassis-zenoh bridges the TITAN on the simulated bus.
    let run = "titan sim".to_string();
    let pace_command = format!(
        "{} (the command path's)",
        period_text(paths::COMMAND_INTERVAL)
    );
    let pace_state = format!(
        "{} (the period of the states the path counted, 1.7 % more)",
        period_text(m.state_period)
    );
    let (command_count, state_count) = (m.command.latencies.count(), m.state.latencies.count());
    for (what, count, hops, pace) in [
        (RAW_COMMAND, command_count, &m.raw_command, pace_command),
        (RAW_STATE, state_count, &m.raw_state, pace_state),
    ] {
        let conditions = format!(
            "one sample every {pace} from the robot's namespace to the operator's, bare \
             sessions configured as chassis-zenoh's, same run, chassisd running, the \
             bridges not; the last {count} of {} after a warm-up",
            hops.len()
        );
        let l = last_of(hops, count);
        (report.rows).push(Row::hop(&run, what.into(), PLACEMENT, l, conditions));
    }
    let (sent, lost, at) = (m.command.latencies, m.command.missed, PLACEMENT);
    for (leg, what, l, missed, raw) in [
        (Leg::RemoteCommand, COMMAND, sent, lost, RAW_COMMAND),
        (Leg::RemoteState, STATE, m.state.latencies, 0, RAW_STATE),
        (Leg::RemoteBridge, BRIDGE, m.bridged, 0, RAW_STATE),
    ] {
        let what = what.to_string();
        let row = Row::new(PathKind::Zenoh, leg, &run, what, "event", at, l, missed);
        let baseline = Some(format!("{raw}, {at}"));
        report.rows.push(Row { baseline, ..row });
    }
    report.parts.push(crate::report::Parts {
        path: crate::report::ZENOH_PARTS.into(),
        of: (PathKind::Zenoh, Leg::RemoteState),
        run,
        what: STATE.into(),
        mode: "event".into(),
        placement: PLACEMENT.into(),
        split: m.split,
    });
    Ok(())
}

/// The key the bare hop runs on.
const KEY: &str = "chassis-bench/raw";

#[derive(Debug, Args)]
pub struct RawArgs {
    /// Serve on this endpoint (the publisher's side, like the robot side).
    #[arg(long)]
    listen: Vec<String>,
    /// Connect to this endpoint (the subscriber's side, like the mirror).
    #[arg(long)]
    connect: Vec<String>,
    /// Allow plain TCP beyond loopback.
    #[arg(long)]
    insecure: bool,
    /// Samples to receive (subscriber).
    #[arg(long, default_value_t = 1000)]
    count: u64,
    /// Publisher: time between two samples, µs (the pace of the path the hop divides).
    #[arg(long, default_value_t = 4000)]
    interval_us: u64,
    /// Subscriber: where to write the latencies, one ns figure a line.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Give up after this long, s.
    #[arg(long, default_value_t = 60)]
    timeout: u64,
}

fn session(args: &RawArgs) -> anyhow::Result<zenoh::Session> {
    let (role, endpoints) = if args.listen.is_empty() {
        (Role::Operator, args.connect.clone())
    } else {
        (Role::Robot, args.listen.clone())
    };
    let insecure = args.insecure;
    let net = Net {
        role,
        endpoints,
        certs: None,
        insecure,
        lease_ms: 3000,
    };
    net::open(net::config(&net, "bench", &[])?)
}

/// Publishes stamped samples once a subscriber is there, until it has had its count (it leaves)
/// or the time is up: a few samples may be lost to the link.
pub fn publish(args: &RawArgs) -> anyhow::Result<()> {
    chassis_client::install_signal_handlers();
    let session = session(args)?;
    let publisher = session
        .declare_publisher(KEY)
        .congestion_control(CongestionControl::Drop)
        .priority(Priority::DataHigh)
        .express(true)
        .wait()
        .named("publisher")?;
    let deadline = now_ns() + args.timeout * 1_000_000_000;
    let mut ticker = Ticker::new(Duration::from_micros(args.interval_us.max(1)));
    let matching = || {
        anyhow::Ok(
            publisher
                .matching_status()
                .wait()
                .named("matching")?
                .matching(),
        )
    };
    while !matching()? {
        if now_ns() > deadline || termination_requested() {
            bail!("no subscriber within {} s", args.timeout);
        }
        ticker.wait();
    }
    let mut payload = vec![0u8; size_of::<ChassisState>()];
    while now_ns() < deadline && !termination_requested() && matching()? {
        ticker.wait();
        payload[..8].copy_from_slice(&now_ns().to_ne_bytes());
        publisher.put(payload.clone()).wait().named("put")?;
    }
    let _ = session.close().wait();
    Ok(())
}

/// Receives `count` samples and writes their put → callback latencies.
pub fn subscribe(args: &RawArgs) -> anyhow::Result<()> {
    let session = session(args)?;
    let (tx, rx) = mpsc::channel::<u64>();
    let subscriber = session
        .declare_subscriber(KEY)
        .callback(move |sample| {
            let received = now_ns();
            let bytes = sample.payload().to_bytes();
            if let Some(stamp) = bytes.get(..8).and_then(|b| <[u8; 8]>::try_from(b).ok()) {
                let _ = tx.send(received.saturating_sub(u64::from_ne_bytes(stamp)));
            }
        })
        .wait()
        .named("subscriber")?;
    let mut latencies = Vec::new();
    let timeout = Duration::from_secs(args.timeout);
    while (latencies.len() as u64) < args.count {
        match rx.recv_timeout(timeout) {
            Ok(ns) => latencies.push(ns),
            Err(_) => bail!(
                "{} of {} samples within {timeout:?}",
                latencies.len(),
                args.count
            ),
        }
    }
    drop(subscriber);
    let _ = session.close().wait();
    let path = args.out.clone().context("--out FILE is needed")?;
    let mut file =
        std::fs::File::create(&path).with_context(|| format!("writing {}", path.display()))?;
    for ns in latencies {
        writeln!(file, "{ns}")?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_state_rows_bare_hop_keeps_the_counted_states_period_off_the_chassis_grid() {
        // A state every 20 ms, two of them not counted (a 40 ms gap each), out of order.
        let reads: Vec<u64> = (0..30u64)
            .filter(|i| ![7, 19].contains(i))
            .map(|i| i * 20_000_000)
            .rev()
            .collect();
        assert_eq!(state_period(&reads), Duration::from_micros(20_340));
        assert_eq!(state_period(&reads[..5]), Duration::from_micros(20_340));
        assert_eq!(
            state_period(&[0, 7_000_000, 14_000_000]),
            Duration::from_micros(20_340)
        );
        let fast: Vec<u64> = (0..50u64).map(|i| i * 2_000_000).collect();
        assert_eq!(state_period(&fast), Duration::from_micros(2_034));
    }
}
