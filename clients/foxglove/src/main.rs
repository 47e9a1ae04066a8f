//! `chassis-foxglove --name ROBOT[,ROBOT…] [--port 8765]`: a live Foxglove view of robots served
//! by chassisd, over the Foxglove WebSocket protocol (the official `foxglove` SDK's server).
//!
//! Open Foxglove, connect to `ws://localhost:8765`, import `clients/foxglove/layout.json`.
//!
//! | topic | schema | what |
//! | --- | --- | --- |
//! | `/tf` | `foxglove.FrameTransforms` | odom → base_link from the odometry, base_link → imu, gps and the range sensors of the robot's description |
//! | `/pose` | `foxglove.PoseInFrame` | the robot in odom |
//! | `/scene` | `foxglove.SceneUpdate` | the body's outline and range cones from the robot's description, the cones sized by their readings, the path just driven |
//! | `/gps` | `foxglove.LocationFix` | the GPS fix, when there is one |
//! | `/log` | `foxglove.Log` | faults appearing and clearing, link flags, mux changes, service calls |
//! | `/state` | `chassis.ChassisState` (JSON) | every field of the state, ≤ 50 Hz |
//! | `/mux` | `chassis.MuxStatus` (JSON) | every field of the mux decision, names spelled out |
//! | `/safety` | `chassis.SafetyStatus` (JSON) | the safety monitor's decision, names spelled out, `why` in words (`STOP by following: the chassis is in standby`), once a monitor runs |
//! | `/frames` | `chassis.Frames` (JSON) | the bus frames, decoded in the described robot's protocol, in batches every 100 ms |
//!
//! A client channel of `geometry_msgs/Twist` in JSON (Foxglove's Teleop panel) drives the robot
//! as the mux source `foxglove` (teleop's priority, 300 ms timeout; below the safety monitor and
//! the e-stop). Services: `/estop`, `/estop_release`, `/clear_faults`, `/mode`, `/brake`,
//! `/lights`, `/off_road`, `/lift`, `/servos`, `/power`, `/steering_zero`, `/silent`, each
//! answering with chassisd's response `{"ok", "status", "message"}`.
//!
//! `--read-only` offers no client publishing and only the `/estop` service: a view can always
//! stop the robot, never drive it.
//!
//! **Several robots** (`--name scout1,scout2,titan`, typically those `chassis-zenoh
//! --mirror-all` brings to an operator's computer): one server, each robot's channels and
//! services under its name (`/scout1/tf`, `/scout1/state`, `/scout1/estop`, …) and its frames
//! too (`scout1/odom` → `scout1/base_link`: each robot keeps its own odometry origin). A
//! Teleop panel drives the robot its topic names (`/scout1/cmd_vel`); a topic under no robot's
//! name is refused with a status. Each robot has its own loop and waits for its own chassisd.
//!
//! It binds 127.0.0.1: anyone who reaches the port can drive the robot. `--bind ADDRESS`
//! serves other hosts, with a warning.

mod bridge;
mod convert;
mod naming;
mod server;

use std::process::ExitCode;
use std::time::Duration;

use clap::Parser;

/// The fastest state rate a browser keeps up with, Hz.
const MAX_STATE_HZ: f64 = 50.0;

/// A live Foxglove view of a robot served by chassisd.
#[derive(Debug, Parser)]
#[command(name = "chassis-foxglove", version)]
struct Cli {
    /// The robot's name (chassisd --name). Several (`--name a --name b`, or `--name a,b`):
    /// each robot's topics and services under `/<name>/…`, its frames under `<name>/…`.
    #[arg(long, required = true, value_delimiter = ',')]
    name: Vec<String>,
    /// TCP port of the WebSocket server (0: any free port, printed at start).
    #[arg(long, default_value_t = 8765)]
    port: u16,
    /// Address to listen on. Anything but loopback lets other machines drive the robot.
    #[arg(long, default_value = "127.0.0.1")]
    bind: String,
    /// View only: refuse client channels (no Teleop) and offer only the /estop service.
    #[arg(long)]
    read_only: bool,
    /// State rate, Hz (at most 50).
    #[arg(long, default_value_t = MAX_STATE_HZ)]
    state_hz: f64,
}

fn is_loopback(bind: &str) -> bool {
    bind == "localhost"
        || bind
            .parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.is_loopback())
}

impl Cli {
    /// The bridge's configuration, checked; warns when the server reaches beyond this machine.
    fn config(self) -> anyhow::Result<server::Config> {
        if !(self.state_hz > 0.0 && self.state_hz <= MAX_STATE_HZ) {
            anyhow::bail!("--state-hz must be in (0, {MAX_STATE_HZ}]");
        }
        naming::check_names(&self.name).map_err(anyhow::Error::msg)?;
        if !is_loopback(&self.bind) {
            tracing::warn!(bind = self.bind, "serving beyond this machine");
            eprintln!(
                "chassis-foxglove: WARNING: listening on {}: anyone who reaches port {} can {} robot(s) {}",
                self.bind,
                self.port,
                if self.read_only {
                    "watch and e-stop"
                } else {
                    "DRIVE"
                },
                self.name.join(", ")
            );
        }
        Ok(server::Config {
            names: self.name,
            bind: self.bind,
            port: self.port,
            state_period: Duration::from_secs_f64(1.0 / self.state_hz),
            drive: !self.read_only,
        })
    }
}

fn main() -> ExitCode {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env();
    tracing_subscriber::fmt()
        .with_env_filter(filter.unwrap_or_else(|_| "warn".into()))
        .with_writer(std::io::stderr)
        .init();
    chassis_client::install_signal_handlers();
    match Cli::parse()
        .config()
        .and_then(|config| bridge::run(&config))
    {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("chassis-foxglove: {err:#}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_loopback_addresses_count_as_local() {
        assert!(is_loopback("127.0.0.1"));
        assert!(is_loopback("::1"));
        assert!(is_loopback("localhost"));
        assert!(!is_loopback("0.0.0.0"));
        assert!(!is_loopback("192.168.1.5"));
    }
}
