//! `chassis-zenoh` paths between two network namespaces joined by a veth pair (the robot's
//! computer and an operator's), beside a bare Zenoh put → subscriber over the same veth in the
//! same run:
//!
//! * operator request → frame on the robot's bus: the operator side's `remote` source (its
//!   own iceoryx2 prefix) → mirror → Zenoh → robot side → chassisd → the frame written;
//! * robot state → operator: the frame read by chassisd → the state sample in an iceoryx2
//!   subscriber of the operator side's mirror.
//!
//! Needs root (`ip netns`); without it the rows are left out with a note.

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use anyhow::{Context, bail};
use chassis_client::{Robot, STATE_BUFFER, Source, now_ns};
use chassis_protocols::RobotKind;

use crate::paths::{self, BusKind, LoopMode, ServiceConfig, StateRecorder};
use crate::stats::Latencies;

const ROBOT_ADDR: &str = "10.77.0.1";
const OPERATOR_ADDR: &str = "10.77.0.2";
const BRIDGE_PORT: u16 = 7447;
const RAW_PORT: u16 = 7449;

/// What the Zenoh run measured.
#[derive(Debug)]
pub struct ZenohFigures {
    pub command: paths::CommandFigures,
    pub state: Latencies,
    /// chassisd published the sample → the operator's iceoryx2 subscriber has it: the bridge's
    /// own part of the state path.
    pub bridge: Latencies,
    /// The bare hops after the warm-up, ns, in order, at the command path's pace.
    pub raw_command: Vec<u64>,
    /// The same at the state path's pace, [`ZenohFigures::state_period`].
    pub raw_state: Vec<u64>,
    /// The period of the states the state path counted, 1.7 % more ([`state_period`]).
    pub state_period: Duration,
    /// The state row split at both sides' stamps.
    pub state_parts: crate::parts::Split,
}

/// Two namespaces joined by a veth pair, removed on drop.
struct Netns {
    robot: String,
    operator: String,
}

fn ip(args: &[&str]) -> anyhow::Result<()> {
    let out = Command::new("ip")
        .args(args)
        .output()
        .with_context(|| format!("running ip {} (install iproute2)", args.join(" ")))?;
    if !out.status.success() {
        bail!(
            "ip {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    Ok(())
}

impl Netns {
    fn new() -> anyhow::Result<Self> {
        let id = std::process::id() % 100_000;
        let ns = Netns {
            robot: format!("cbr{id}"),
            operator: format!("cbo{id}"),
        };
        ip(&["netns", "add", &ns.robot])?;
        ip(&["netns", "add", &ns.operator])?;
        ip(&[
            "link",
            "add",
            &ns.robot,
            "type",
            "veth",
            "peer",
            "name",
            &ns.operator,
        ])?;
        for (name, addr) in [(&ns.robot, ROBOT_ADDR), (&ns.operator, OPERATOR_ADDR)] {
            ip(&["link", "set", name, "netns", name])?;
            ip(&[
                "-n",
                name,
                "addr",
                "add",
                &format!("{addr}/24"),
                "dev",
                name,
            ])?;
            ip(&["-n", name, "link", "set", name, "up"])?;
            ip(&["-n", name, "link", "set", "lo", "up"])?;
        }
        Ok(ns)
    }
}

impl Drop for Netns {
    fn drop(&mut self) {
        for ns in [&self.robot, &self.operator] {
            let _ = Command::new("ip").args(["netns", "del", ns]).status();
        }
    }
}

/// Processes stopped on drop.
struct Children(Vec<Child>);

impl Drop for Children {
    fn drop(&mut self) {
        for child in self.0.iter_mut().rev() {
            paths::stop(child);
        }
    }
}

/// `program args…` in network namespace `ns`.
fn zenoh_in(
    ns: &str,
    prefix: &str,
    program: &Path,
    args: &[&str],
    log: &Path,
) -> anyhow::Result<Command> {
    let mut cmd = Command::new("ip");
    cmd.args(["netns", "exec", ns])
        .arg(program)
        .args(args)
        .env(chassis_client::IPC_PREFIX_ENV, prefix)
        .env("RUST_LOG", "warn,zenoh=error")
        .stdout(Stdio::null())
        .stderr(Stdio::from(
            std::fs::File::create(log).with_context(|| format!("{}", log.display()))?,
        ));
    Ok(cmd)
}

/// Bare Zenoh samples received before the counted ones (sessions, routes, allocations warm).
const RAW_WARMUP: u64 = 200;

/// The rows' names: the bare Zenoh hop (one row as many samples as the command row, one as the
/// state rows) and the bridge's three paths.
pub const RAW_COMMAND: &str = "Zenoh put → subscriber, 840 B, as many as the command row";
pub const RAW_STATE: &str = "Zenoh put → subscriber, 840 B, as many as the state rows";
pub const COMMAND: &str = "operator's remote source → robot's frame written (titan sim)";
pub const STATE: &str = "robot's frame read → state in the operator's iceoryx2 (titan sim)";
pub const BRIDGE: &str = "robot's state published → in the operator's iceoryx2 (the bridge's part)";

/// True when this process may make network namespaces.
pub fn possible() -> bool {
    use std::os::unix::fs::MetadataExt as _;
    // /proc/self belongs to the process's effective user.
    std::fs::metadata("/proc/self").is_ok_and(|m| m.uid() == 0)
}

fn wait_until<T>(
    what: &str,
    timeout: Duration,
    mut f: impl FnMut() -> Option<T>,
) -> anyhow::Result<T> {
    let deadline = now_ns() + u64::try_from(timeout.as_nanos()).unwrap_or(u64::MAX / 2);
    let mut ticker = chassis_client::Ticker::new(Duration::from_millis(50));
    loop {
        if let Some(v) = f() {
            return Ok(v);
        }
        if now_ns() > deadline {
            bail!("{what} within {timeout:?}");
        }
        ticker.wait();
    }
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
    prefix: &str,
    operator_prefix: &str,
    dir: &Path,
    count: u64,
    pace: Duration,
) -> anyhow::Result<Vec<u64>> {
    let raw = format!("tcp/{ROBOT_ADDR}:{RAW_PORT}");
    let tag = pace.as_micros();
    let raw_file = dir.join(format!("zenoh-raw-{tag}.ns"));
    let wanted = RAW_WARMUP + count;
    // Twice the time the samples take at their pace, and discovery.
    let timeout = (2.0 * wanted as f64 * pace.as_secs_f64() + 30.0)
        .ceil()
        .to_string();
    let sub_log = dir.join(format!("zenoh-raw-sub-{tag}.log"));
    let bench = std::env::current_exe().context("finding chassis-bench itself")?;
    let mut sub = zenoh_in(
        &netns.operator,
        operator_prefix,
        &bench,
        &[
            "role",
            "zenoh-sub",
            "--connect",
            &raw,
            "--insecure",
            "--count",
            &wanted.to_string(),
            "--timeout",
            &timeout,
        ],
        &sub_log,
    )?
    .arg("--out")
    .arg(&raw_file)
    .spawn()
    .context("starting the bare hop's subscriber")?;
    let mut publisher = zenoh_in(
        &netns.robot,
        prefix,
        &bench,
        &[
            "role",
            "zenoh-pub",
            "--listen",
            &raw,
            "--insecure",
            "--interval-us",
            &pace.as_micros().to_string(),
            "--timeout",
            &timeout,
        ],
        &dir.join(format!("zenoh-raw-pub-{tag}.log")),
    )?
    .spawn()
    .context("starting the bare hop's publisher")?;
    let status = sub.wait()?;
    let _ = publisher.wait();
    if !status.success() {
        bail!("the bare Zenoh baseline failed; see {}", sub_log.display());
    }
    std::fs::read_to_string(&raw_file)?
        .lines()
        .map(|line| line.trim().parse::<u64>().context("a latency in ns"))
        .skip(usize::try_from(RAW_WARMUP).unwrap_or(usize::MAX))
        .collect()
}

/// Runs the Zenoh paths: `commands` requests one per `interval`, `states` state samples,
/// `raw` bare Zenoh samples.
pub fn run(
    prefix: &str,
    dir: &Path,
    commands: u64,
    interval: Duration,
    states: u64,
) -> anyhow::Result<ZenohFigures> {
    let netns = Netns::new()?;
    // chassisd keeps its pass trace: the state row's split starts with its notification.
    let (service, mut robot) = paths::start_configured(
        RobotKind::Titan,
        BusKind::Sim,
        LoopMode::Event,
        None,
        ServiceConfig::Bench,
        true,
        prefix,
        dir,
    )?;
    let name = service.name.clone();
    let operator_prefix = format!("{prefix}op_");
    let bridge = format!("tcp/{ROBOT_ADDR}:{BRIDGE_PORT}");
    let mut children = Children(Vec::new());

    // The command row's bare Zenoh hop first, alone on the link, at the command path's pace;
    // the state row's after the bridges stop, at the states' own (known then).
    let raw_command = bare_hop(&netns, prefix, &operator_prefix, dir, commands, interval)?;

    // Each side keeps its stamps of the states it carries and writes them as it stops.
    let export_trace = dir.join("zenoh-robot.trace");
    let bridge_program = paths::sibling("chassis-zenoh")?;
    let mirror_trace = dir.join("zenoh-operator.trace");
    children.0.push(
        zenoh_in(
            &netns.robot,
            prefix,
            &bridge_program,
            &["--name", &name, "--listen", &bridge, "--insecure"],
            &dir.join("zenoh-robot.log"),
        )?
        .env(chassis_ipc::Trace::ZenohExport.env(), &export_trace)
        .spawn()
        .context("starting chassis-zenoh (robot side)")?,
    );
    children.0.push(
        zenoh_in(
            &netns.operator,
            &operator_prefix,
            &bridge_program,
            &[
                "--name",
                &name,
                "--connect",
                &bridge,
                "--insecure",
                "--mirror",
            ],
            &dir.join("zenoh-operator.log"),
        )?
        .env(chassis_ipc::Trace::ZenohMirror.env(), &mirror_trace)
        .spawn()
        .context("starting chassis-zenoh --mirror")?,
    );
    let mut operator = wait_until(
        "the mirror served no state",
        Duration::from_secs(20),
        || {
            let mut r = Robot::connect_with_prefix(&name, Some(&operator_prefix)).ok()?;
            r.wait_state(Duration::from_millis(100)).ok().flatten()?;
            Some(r)
        },
    )?;
    let mut remote: Source = wait_until(
        "the mirror offered no remote source",
        Duration::from_secs(20),
        || operator.source("remote").ok(),
    )?;

    let command = paths::command_path_via(
        &mut robot,
        &mut remote,
        RobotKind::Titan,
        commands,
        interval,
        false,
        paths::Reach::Exact,
    )?;

    // Robot state → the operator's iceoryx2 subscriber, while the robot drives (so frames keep
    // changing the state).
    let stream = operator.state_stream(STATE_BUFFER)?;
    // The robot side forwards the newest sample of each read of the bus: `seq` has gaps.
    let mut recorder = StateRecorder::with_gaps();
    let mut bridge = Latencies::new();
    let mut last_request = 0u64;
    let deadline = now_ns() + 120_000_000_000;
    while recorder.latencies.count() < states && now_ns() < deadline {
        if now_ns().saturating_sub(last_request) > 50_000_000 {
            remote.send(chassis_client::VelocityRequest::twist(0.6, 0.3))?;
            last_request = now_ns();
        }
        stream.wait(Duration::from_millis(20), |s| {
            let received = now_ns();
            let fresh = recorder.latencies.count();
            recorder.sample(s, received);
            if recorder.latencies.count() > fresh {
                bridge.record_between(s.published_ns, received);
            }
        })?;
    }
    remote.stop()?;
    drop(stream);
    drop(remote);
    drop(operator);
    drop(children);
    let reads: Vec<u64> = recorder.samples.iter().map(|&(read, ..)| read).collect();
    let state_period = state_period(&reads);
    let raw_state = bare_hop(&netns, prefix, &operator_prefix, dir, states, state_period)?;
    drop(robot);
    let passes = service.stop()?;
    drop(netns);
    // The mirror's iceoryx2 files, under the operator's prefix of this run only.
    for (path, e) in chassis_ipc::remove_ipc_files(&operator_prefix) {
        eprintln!("cannot remove {}: {e}", path.display());
    }
    let samples: Vec<(u64, u64)> = recorder
        .samples
        .iter()
        .map(|&(read, _, received)| (read, received))
        .collect();
    let state_parts = crate::parts::zenoh_state(
        &samples,
        &crate::parts::read_trace(&export_trace, chassis_ipc::Trace::ZenohExport)?,
        &crate::parts::read_trace(&mirror_trace, chassis_ipc::Trace::ZenohMirror)?,
        &passes,
    );
    Ok(ZenohFigures {
        command,
        state: recorder.latencies,
        bridge,
        raw_command,
        raw_state,
        state_period,
        state_parts,
    })
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
