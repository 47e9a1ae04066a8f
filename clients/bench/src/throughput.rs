//! Throughput: a recorded bus replayed into the service as fast as it drains it — read, decode,
//! publish — with the service's loop pinned to one CPU (the replay thread runs on the other).

use std::io::Write;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

use anyhow::{Context, bail};
use chassis_client::{Robot, Velocity, now_ns};
use chassis_protocols::driver::{Driver, DriverConfig};
use chassis_protocols::pair::Pair;
use chassis_protocols::titan::TitanProfile;
use chassis_protocols::{CandumpLine, Direction, Timestamp, WireItem, titan};

use crate::paths::{cpu_seconds_of_thread, sibling, spawn_logged, stop};
use crate::placement::{pause, unique};
use crate::report::Throughput;

/// Writes a candump log of a TITAN driving figure-eights for `seconds` of simulated time: what
/// its bus carries from the chassis (about 650 frames a second).
pub fn record_titan(path: &Path, seconds: u64) -> anyhow::Result<u64> {
    let profile = TitanProfile::default();
    let start = Timestamp::from_millis(1);
    let driver = titan::TitanDriver::new(profile.clone(), DriverConfig::default(), start);
    let firmware = titan::TitanSim::new(profile, start);
    let mut pair = Pair::new(driver, firmware, start);
    pair.record = true;
    let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
    let mut frames = 0u64;
    for second in 0..seconds {
        let turn = if second % 20 < 10 { 0.3 } else { -0.3 };
        pair.set_command(Velocity::twist(1.0, turn)?);
        pair.run_for(Duration::from_secs(1));
        for record in pair.log() {
            if let (Direction::FromChassis, WireItem::Can(frame)) = (record.direction, &record.item)
            {
                let line = CandumpLine {
                    time_s: record.at.as_nanos() as f64 / 1e9,
                    interface: "can0".into(),
                    frame: *frame,
                };
                writeln!(out, "{}", line.format())?;
                frames += 1;
            }
        }
        pair.clear_log();
    }
    let _ = pair.driver.state();
    out.flush()?;
    Ok(frames)
}

/// Replays `file` (of `frames` frames) at full speed into a service pinned to CPU 0.
pub fn replay(file: &Path, frames: u64, prefix: &str, dir: &Path) -> anyhow::Result<Throughput> {
    let name = format!("tp{}", unique());
    let mut chassisd = Command::new(sibling("chassisd")?);
    chassisd
        .args([
            "--robot",
            "titan",
            "--name",
            &name,
            "--no-safety-monitor",
            "--cpu",
            "0",
        ])
        .arg("--bus")
        .arg(format!("replay:{}@max", file.display()));
    let log = dir.join(&name);
    let mut child = spawn_logged(&mut chassisd, prefix, &log, "chassisd on the replay bus")?;
    let pid = child.id();
    let deadline = now_ns() + 20_000_000_000;
    let mut robot = loop {
        if let Ok(robot) = Robot::connect_with_prefix(&name, Some(prefix)) {
            break robot;
        }
        if now_ns() > deadline {
            let _ = child.kill();
            bail!("chassisd on the replay bus did not come up");
        }
        pause(Duration::from_millis(5));
    };
    // From the first frame counted to the last: the loop thread's CPU over that span.
    let mut first: Option<(u64, u64, f64)> = None;
    let mut last = (0u64, 0u64, 0.0f64);
    let end = now_ns() + 120_000_000_000;
    while now_ns() < end {
        if let Some(state) = robot.wait_state(Duration::from_millis(20))? {
            let sample = (
                now_ns(),
                state.link.rx_frames,
                cpu_seconds_of_thread(pid, pid)?,
            );
            if first.is_none() && state.link.rx_frames > 0 {
                first = Some(sample);
            }
            last = sample;
            if state.link.rx_frames >= frames {
                break;
            }
        }
    }
    stop(&mut child);
    let (t0, f0, c0) = first.context("no frame was replayed")?;
    let seconds = (last.0 - t0) as f64 / 1e9;
    let counted = last.1 - f0;
    let cpu_seconds = last.2 - c0;
    Ok(Throughput {
        frames: counted,
        seconds,
        frames_per_s: counted as f64 / seconds.max(1e-9),
        service_cpu_pct: 100.0 * cpu_seconds / seconds.max(1e-9),
        frames_per_cpu_s: counted as f64 / cpu_seconds.max(1e-9),
    })
}
