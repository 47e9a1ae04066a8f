//! The ROS 2 bridge's paths (`clients/ros2/bench.py`, a Cyclone DDS participant standing in for
//! a ROS 2 node) on the same service as the Rust client's rows, in the same run and placement,
//! beside the raw DDS hops between the same two implementations (Cyclone DDS ↔ the bridge's
//! RustDDS) measured by the same script in the same run.
//!
//! DDS discovery multicasts: the script runs under `unshare --net` with only the loopback up, so
//! no discovery packet leaves the machine (iceoryx2 is shared memory and works across it).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use anyhow::Context as _;

use crate::python::{ScriptRun, read_latencies, read_stamps, repo, run_script};
use crate::stats::Latencies;

/// What the ROS 2 bridge's run measured.
#[derive(Debug)]
pub struct Ros2Figures {
    /// `cmd_vel` written by the peer → the motion frame written to the bus.
    pub command: Latencies,
    /// Frame read by chassisd → the `odom` carrying its pose taken by the peer.
    pub state: Latencies,
    /// Raw DDS hop, peer (Cyclone DDS) → the bridge's DDS stack (RustDDS).
    pub raw_in: Latencies,
    /// Raw DDS hop, the bridge's DDS stack → the peer.
    pub raw_out: Latencies,
    /// The pace of `raw_out`'s pings: the odoms' own period, 1.7 % more.
    pub raw_out_period: Duration,
    /// `cmd_vel` messages whose frame did not appear.
    pub missed: u64,
    /// Each counted odom's `(frame read, taken by the peer)`.
    pub odom_pairs: Vec<(u64, u64)>,
    /// The bridge's odom trace (`[read, woke, write begun, written]` a line): with chassisd's
    /// pass trace, [`crate::parts::odom`] splits the state row.
    pub odom_trace: Vec<[u64; 4]>,
}

/// The interpreter of the ROS 2 bridge's test environment (`scripts/ros2-tests` makes it, with
/// Cyclone DDS and the `chassis` package installed), if there is one.
pub fn interpreter() -> Option<PathBuf> {
    let python = repo().join("target/ros2-venv/bin/python");
    python.exists().then_some(python)
}

/// Runs `bench.py` with the interpreter `python`, beside the bridge binary `bridge`.
pub fn run(python: &Path, bridge: &Path, run: &ScriptRun<'_>) -> anyhow::Result<Ros2Figures> {
    let out = run.out("ros2");
    let mut script = Command::new("unshare");
    script
        .args(["--net", "--", "sh", "-c"])
        .arg("ip link set lo up && ip link set lo multicast on && exec \"$@\"")
        .arg("ros2-bench")
        .arg(python)
        .arg(repo().join("clients/ros2/bench.py"))
        .arg("--bridge")
        .arg(bridge)
        .arg("--echo")
        .arg(std::env::current_exe().context("finding chassis-bench itself")?);
    run.args(&mut script);
    run_script(script, &out, "the ROS 2 bridge's benchmark")?;
    let missed = std::fs::read_to_string(out.join("command.missed"))
        .ok()
        .and_then(|t| t.trim().parse().ok())
        .unwrap_or(0);
    Ok(Ros2Figures {
        command: read_latencies(&out.join("command.ns"))?,
        state: read_latencies(&out.join("state.ns"))?,
        raw_in: read_latencies(&out.join("raw-in.ns"))?,
        raw_out: read_latencies(&out.join("raw-out.ns"))?,
        raw_out_period: Duration::from_nanos(crate::python::read_count(
            &out.join("raw-out.period_ns"),
        )?),
        missed,
        odom_pairs: read_stamps::<2>(&out.join("state.pairs"))?
            .into_iter()
            .map(|[read, taken]| (read, taken))
            .collect(),
        odom_trace: crate::parts::read_trace(&out.join("odom.trace"), chassis_ipc::Trace::Odom)?,
    })
}
