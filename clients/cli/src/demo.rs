//! `chassis demo`: the whole system on a simulated robot in one command — `chassisd` on the
//! simulated chassis, the safety monitor, the planner driving figure-eights, and the dashboard.
//! With `--foxglove`, `chassis-foxglove` serves the live view on ws://localhost:8765 too.
//! Ctrl-C (or `q` in the dashboard) stops every process cleanly.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::Duration;

use anyhow::{Context, bail};
use chassis_client::{
    Robot, SourceFlags, Ticker, install_signal_handlers, now_ns, termination_requested,
};
use chassis_protocols::RobotKind;
use clap::Args;

use crate::procs::{Children, sibling};

#[derive(Debug, Args)]
pub struct DemoArgs {
    // The simulated robot, one of the registry's.
    #[arg(
        long,
        default_value = "titan",
        help = format!("The simulated robot: {}.", chassis_protocols::kind::names().join(", "))
    )]
    pub robot: RobotKind,
    /// AgileX wire protocol of the simulated chassis, v1 or v2 (default: the robot's own; SCOUT
    /// MINI: v1).
    #[arg(long)]
    pub protocol: Option<chassis_protocols::Protocol>,
    /// Name of the demo robot's services (default: demo-ROBOT).
    #[arg(long)]
    pub name: Option<String>,
    /// Stop after this many seconds (default: until Ctrl-C or `q`).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Print a status line every second instead of the live dashboard (the default when stdout
    /// is not a terminal).
    #[arg(long)]
    pub no_dashboard: bool,
    /// Figure-eight size, m (default: the planner's, which fits the robot's turning radius).
    #[arg(long)]
    pub size: Option<f64>,
    /// Serve a live Foxglove view too (`chassis-foxglove`, on 127.0.0.1).
    #[arg(long)]
    pub foxglove: bool,
    /// Port of the Foxglove view.
    #[arg(long, default_value_t = 8765)]
    pub foxglove_port: u16,
}

/// The programs a demo starts, found next to this executable.
struct Programs {
    chassisd: PathBuf,
    safety: PathBuf,
    planner: PathBuf,
    foxglove: Option<PathBuf>,
}

fn log_file(dir: &std::path::Path, label: &str) -> anyhow::Result<Stdio> {
    let path = dir.join(format!("{label}.log"));
    Ok(Stdio::from(
        std::fs::File::create(&path).with_context(|| format!("creating {}", path.display()))?,
    ))
}

pub fn run(args: &DemoArgs) -> anyhow::Result<()> {
    install_signal_handlers();
    let name = args
        .name
        .clone()
        .unwrap_or_else(|| format!("demo-{}", args.robot.name()));
    let dir: PathBuf = std::env::temp_dir().join(format!("chassis-demo-{}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    // Every program first: a missing one (the Foxglove bridge is not in the default build) is
    // named, with the command that builds it, before anything starts.
    let programs = Programs {
        chassisd: sibling("chassisd")?,
        safety: sibling("chassis-safety")?,
        planner: sibling("chassis-planner")?,
        foxglove: args
            .foxglove
            .then(|| sibling("chassis-foxglove"))
            .transpose()?,
    };
    let mut children = Children::default();

    let mut service = Command::new(&programs.chassisd);
    service
        .args(["--robot", args.robot.name(), "--name", &name])
        .stdin(Stdio::null())
        .stdout(log_file(&dir, "chassisd")?)
        .stderr(log_file(&dir, "chassisd")?);
    if let Some(protocol) = args.protocol {
        service.args(["--protocol", protocol.name()]);
    }
    children.spawn("chassisd", service)?;
    eprintln!(
        "chassisd: simulated {}{} as chassis/{name} (logs in {})",
        args.robot,
        args.protocol
            .map(|p| format!(" (protocol {p})"))
            .unwrap_or_default(),
        dir.display()
    );
    let mut robot = connect(&name, &mut children)?;

    let mut safety = Command::new(&programs.safety);
    safety
        .args(["--name", &name])
        .stdin(Stdio::null())
        .stdout(log_file(&dir, "chassis-safety")?)
        .stderr(log_file(&dir, "chassis-safety")?);
    children.spawn("chassis-safety", safety)?;
    eprintln!("chassis-safety: watching faults, battery, staleness, bumper, ranges, speed");
    // The planner starts once the monitor guards: a monitor still starting up could fall
    // silent and come back under the planner's first requests, and after that stop motion
    // starts only from a zero.
    guarded(&mut robot, &mut children)?;

    let mut planner = Command::new(&programs.planner);
    planner
        .args(["--name", &name, "--shape", "figure-eight", "--repeat"])
        .stdin(Stdio::null())
        .stdout(log_file(&dir, "chassis-planner")?)
        .stderr(log_file(&dir, "chassis-planner")?);
    if let Some(size) = args.size {
        planner.args(["--size", &size.to_string()]);
    }
    children.spawn("chassis-planner", planner)?;
    eprintln!("chassis-planner: figure-eights, over and over");

    if let Some(foxglove) = &programs.foxglove {
        let mut view = Command::new(foxglove);
        view.args(["--name", &name, "--port", &args.foxglove_port.to_string()])
            .stdin(Stdio::null())
            .stdout(log_file(&dir, "chassis-foxglove")?)
            .stderr(log_file(&dir, "chassis-foxglove")?);
        children.spawn("chassis-foxglove", view)?;
        eprintln!(
            "chassis-foxglove: open Foxglove, connect to ws://localhost:{}, import clients/foxglove/layout.json \
             (installed: /usr/share/chassisd/foxglove/layout.json)",
            args.foxglove_port
        );
    }

    let dashboard =
        !args.no_dashboard && std::io::stdout().is_terminal() && args.duration.is_none();
    let result = if dashboard {
        crate::top::run(&crate::top::TopArgs {
            name: name.clone(),
            once: false,
            collect: 1.5,
            interval_ms: 250,
        })
    } else {
        status_lines(&mut robot, &mut children, args.duration)
    };
    eprintln!("stopping the planner, the safety monitor and chassisd");
    children.stop_all(Duration::from_secs(5));
    let _ = std::fs::remove_dir_all(&dir);
    result
}

/// Connects once chassisd publishes its first state.
fn connect(name: &str, children: &mut Children) -> anyhow::Result<Robot> {
    let started = now_ns();
    let mut ticker = Ticker::new(Duration::from_millis(50));
    loop {
        starting(children)?;
        if let Ok(mut robot) = Robot::connect(name)
            && robot.wait_state(Duration::from_millis(200))?.is_some()
        {
            return Ok(robot);
        }
        if now_ns().saturating_sub(started) > 15_000_000_000 {
            bail!("chassis/{name} did not come up within 15 s");
        }
        ticker.wait();
    }
}

/// Fails when asked to stop, or when a process of the demo ended while it starts.
fn starting(children: &mut Children) -> anyhow::Result<()> {
    if termination_requested() {
        bail!("interrupted while starting");
    }
    if let Some((label, status)) = children.exited() {
        bail!("{label} exited at start ({status})");
    }
    Ok(())
}

/// Waits until the mux's required sources (the safety monitor) have been fresh for a second.
fn guarded(robot: &mut Robot, children: &mut Children) -> anyhow::Result<()> {
    let started = now_ns();
    let mut fresh_since: Option<u64> = None;
    loop {
        starting(children)?;
        let now = now_ns();
        let fresh = robot.wait_mux(Duration::from_millis(50))?.is_some_and(|m| {
            m.sources()
                .iter()
                .filter(|s| s.has(SourceFlags::REQUIRED))
                .all(|s| s.has(SourceFlags::FRESH))
        });
        fresh_since = fresh.then(|| fresh_since.unwrap_or(now));
        if fresh_since.is_some_and(|since| now.saturating_sub(since) >= 1_000_000_000) {
            return Ok(());
        }
        if now.saturating_sub(started) > 30_000_000_000 {
            bail!("the safety monitor did not guard chassis within 30 s");
        }
    }
}

/// One status line a second until `duration`, Ctrl-C, or a process of the demo ending.
fn status_lines(
    robot: &mut Robot,
    children: &mut Children,
    duration: Option<f64>,
) -> anyhow::Result<()> {
    let start = now_ns();
    let end = duration.map(|d| start + (d * 1e9) as u64);
    let mut ticker = Ticker::new(Duration::from_secs(1));
    ticker.wait();
    while !termination_requested() && end.is_none_or(|e| now_ns() < e) {
        ticker.wait();
        if let Some((label, status)) = children.exited() {
            bail!("{label} stopped ({status})");
        }
        let state = robot.latest_state()?;
        let mux = robot.latest_mux()?;
        if let (Some(state), Some(mux)) = (state, mux) {
            println!(
                "{:>5.1} s  {}  | {}",
                (now_ns() - start) as f64 / 1e9,
                crate::live::state_line(&state),
                mux.why()
            );
        }
    }
    Ok(())
}
