//! State fan-out: the same state path measured in 1, 4 or 16 subscriber processes at once.

use std::process::{Command, Stdio};
use std::time::Duration;

use anyhow::{Context, bail};
use chassis_client::{Robot, STATE_BUFFER, VelocityRequest, now_ns};

use crate::paths::StateRecorder;
use crate::stats::Latencies;

/// Arguments of a subscriber process (a hidden role of this binary).
#[derive(Debug, Clone, clap::Args)]
pub struct SubscribeArgs {
    #[arg(long)]
    pub name: String,
    #[arg(long)]
    pub prefix: String,
    #[arg(long)]
    pub seconds: f64,
}

/// The subscriber role: records state latencies for `seconds`, then prints them on stdout (as a
/// samples file holds them).
pub fn subscribe(args: &SubscribeArgs) -> anyhow::Result<()> {
    let robot = Robot::connect_with_prefix(&args.name, Some(&args.prefix))?;
    // Every sample, as a client that needs them all reads them.
    let stream = robot.state_stream(STATE_BUFFER)?;
    let mut recorder = StateRecorder::default();
    let end = now_ns() + (args.seconds * 1e9) as u64;
    while now_ns() < end {
        stream.wait(Duration::from_millis(20), |s| recorder.sample(s, now_ns()))?;
    }
    println!("{}", serde_json::to_string(&recorder.latencies)?);
    Ok(())
}

/// Runs `subscribers` subscriber processes for `seconds` while this process drives the robot,
/// and merges their latencies.
pub fn run(
    robot: &mut Robot,
    name: &str,
    prefix: &str,
    subscribers: usize,
    seconds: f64,
) -> anyhow::Result<Latencies> {
    let exe = std::env::current_exe()?;
    let mut children = Vec::new();
    for _ in 0..subscribers {
        children.push(
            Command::new(&exe)
                .args(["role", "subscribe", "--name", name, "--prefix", prefix])
                .args(["--seconds", &seconds.to_string()])
                .stdout(Stdio::piped())
                .stderr(Stdio::inherit())
                .spawn()
                .context("starting a subscriber")?,
        );
    }
    let mut teleop = robot.source("teleop")?;
    let end = now_ns() + ((seconds + 0.5) * 1e9) as u64;
    while now_ns() < end {
        teleop.send(VelocityRequest::twist(0.6, 0.3))?;
        robot.wait_state(Duration::from_millis(50))?;
    }
    teleop.stop()?;
    let mut merged = Latencies::new();
    for child in children {
        let out = child.wait_with_output()?;
        if !out.status.success() {
            bail!("a subscriber failed");
        }
        let latencies: Latencies =
            serde_json::from_slice(&out.stdout).context("a subscriber's histogram")?;
        merged.merge(&latencies);
    }
    Ok(merged)
}
