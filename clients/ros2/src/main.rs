//! `chassis-ros2 --name ROBOT`: the robot served by chassisd as a ROS 2 base driver.
//!
//! In: `cmd_vel` (`geometry_msgs/Twist`, or `TwistStamped` with `--stamped`) as the mux source
//! `ros2`; `e_stop` (`std_msgs/Bool`: true engages the operator e-stop). Services `~/estop`,
//! `~/estop_release`, `~/clear_faults` (`std_srvs/Trigger`). Out: `odom`, `tf`,
//! `joint_states`, `battery_state`, `imu/data`, `range/<sensor>`, `fix`, `diagnostics`, and the
//! robot's model: `robot_description` (its URDF) and `tf_static`, transient local.
//! See docs/BRIDGES.md, "ROS 2".
//!
//! `chassis-ros2 --name ROBOT --record run.mcap [--duration S]` joins no DDS domain: it writes
//! the same state topics into a ROS 2 bag (MCAP, CDR) that `ros2 bag play` and Foxglove read
//! ([`chassis_ros2::record`]).

use std::process::ExitCode;

use anyhow::Context as _;
use chassis_ros2::bridge::{self, Entities, Options};
use chassis_ros2::convert::{Frames, RosClock};
use clap::{Parser, ValueEnum};
use ros2_client::ServiceMapping;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum Mapping {
    /// The DDS-RPC "enhanced" mapping (rmw_fastrtps_cpp, rmw_connextdds).
    Enhanced,
    /// rmw_cyclonedds_cpp's mapping.
    Cyclone,
}

#[derive(Debug, Parser)]
#[command(
    version,
    about = "A robot served by chassisd as a ROS 2 base driver, over DDS"
)]
struct Cli {
    /// The robot's name in chassisd (`chassisd --name`, default its robot).
    #[arg(long)]
    name: String,
    /// ROS namespace of the node and every topic (`/robot1`); several robots on one computer
    /// each get their own.
    #[arg(long, default_value = "/")]
    namespace: String,
    /// DDS domain (default: `ROS_DOMAIN_ID`, else 0).
    #[arg(long, env = "ROS_DOMAIN_ID", default_value_t = 0)]
    domain_id: u16,
    /// `cmd_vel` carries `geometry_msgs/TwistStamped` (as Jazzy's controllers take it).
    #[arg(long)]
    stamped: bool,
    /// Do not publish odom → base_link on `tf` (a localiser publishes it).
    #[arg(long)]
    no_tf: bool,
    /// Prefix of every frame id, e.g. `robot1/` (default: none).
    #[arg(long, default_value = "")]
    frame_prefix: String,
    /// Service mapping of the ROS 2 peers (default: from `RMW_IMPLEMENTATION`:
    /// rmw_cyclonedds_cpp → cyclone, else enhanced).
    #[arg(long, value_enum)]
    service_mapping: Option<Mapping>,
    /// Stamp messages with `CLOCK_MONOTONIC` itself instead of ROS time (a stack on steady
    /// time; chassis-bench reads latencies off the stamps this way).
    #[arg(long)]
    monotonic_stamps: bool,
    /// Record the bridge's state topics into this ROS 2 bag (MCAP, CDR, `ros2msg` schemas)
    /// instead of publishing them over DDS; stops at SIGINT/SIGTERM or after --duration.
    #[arg(long)]
    record: Option<std::path::PathBuf>,
    /// With --record: stop after this many seconds.
    #[arg(long, requires = "record")]
    duration: Option<f64>,
    /// Oldest a `TwistStamped` may be when it arrives, ms (its stamp against this computer's
    /// clock: the sender's clock must be synchronised, as ROS 2 assumes); older ones are
    /// dropped and counted.
    #[arg(long, default_value_t = 250)]
    max_age_ms: u64,
}

fn namespace(ns: &str) -> String {
    let trimmed = ns.trim_end_matches('/');
    if trimmed.is_empty() {
        "/".to_string()
    } else if trimmed.starts_with('/') {
        trimmed.to_string()
    } else {
        format!("/{trimmed}")
    }
}

fn run(cli: Cli) -> anyhow::Result<()> {
    let name = cli.name;
    if let Some(path) = &cli.record {
        let options = chassis_ros2::record::RecordOptions {
            name,
            namespace: namespace(&cli.namespace),
            frame_prefix: cli.frame_prefix,
            tf: !cli.no_tf,
            monotonic_stamps: cli.monotonic_stamps,
            duration: match cli.duration {
                Some(s) if s.is_finite() && s > 0.0 => Some(std::time::Duration::from_secs_f64(s)),
                Some(s) => anyhow::bail!("--duration {s}: a positive number of seconds"),
                None => None,
            },
        };
        let counts = chassis_ros2::record::record(path, &options)?;
        let total: u64 = counts.values().map(|&n| u64::from(n)).sum();
        tracing::info!(?counts, "{total} messages written to {}", path.display());
        return Ok(());
    }
    let service_mapping = match cli.service_mapping {
        Some(Mapping::Enhanced) => ServiceMapping::Enhanced,
        Some(Mapping::Cyclone) => ServiceMapping::Cyclone,
        None => bridge::mapping_for_rmw(std::env::var("RMW_IMPLEMENTATION").ok().as_deref()),
    };
    let reach = chassis_ros2::discovery::Reach::from_env()?;
    // Loud on purpose: who can drive the robot through this bridge.
    if reach.range == chassis_ros2::discovery::Range::Subnet {
        tracing::warn!("{}", reach.describe());
    } else {
        tracing::info!("{}", reach.describe());
    }
    eprintln!("chassis-ros2: {}", reach.describe());
    let options = Options {
        name,
        namespace: namespace(&cli.namespace),
        domain_id: cli.domain_id,
        stamped: cli.stamped,
        tf: !cli.no_tf,
        frame_prefix: cli.frame_prefix,
        service_mapping,
        monotonic_stamps: cli.monotonic_stamps,
        reach,
    };
    // The node's topics follow the robot chassisd describes: wait for it first.
    let Some(described) = bridge::describe(&options.name) else {
        return Ok(());
    };
    let Entities {
        mut node,
        commands,
        outputs,
    } = Entities::create(&options, &described.1)?;
    tracing::info!(
        namespace = %options.namespace,
        domain = options.domain_id,
        mapping = ?options.service_mapping,
        "ROS 2 node {} up",
        bridge::NODE_NAME
    );

    // The node's own housekeeping (ROS graph discovery, parameter events) runs in the background.
    let spinner = node.spinner().context("starting the node's spinner")?;
    std::thread::Builder::new()
        .name("ros2-spinner".into())
        .spawn(move || {
            if let Err(e) = smol::block_on(spinner.spin()) {
                tracing::warn!(error = ?e, "the node's spinner stopped");
            }
        })
        .context("starting the spinner thread")?;

    let frames = Frames::new(&options.frame_prefix);
    let clock = RosClock::new(options.monotonic_stamps);
    let name = options.name.clone();
    let max_age = std::time::Duration::from_millis(cli.max_age_ms);
    let commands = std::thread::Builder::new()
        .name("ros2-commands".into())
        .spawn(move || bridge::commands(&name, commands, clock, max_age))
        .context("starting the commands thread")?;
    let result = bridge::state_loop(&options.name, described, frames, clock, &outputs);
    chassis_client::request_termination();
    match commands.join() {
        Ok(Ok(drops)) => tracing::info!(?drops, "stopped"),
        Ok(Err(e)) => return Err(e),
        Err(_) => anyhow::bail!("the commands thread panicked"),
    }
    // Writers before the participant, so that RustDDS can tell the peers they are gone.
    drop(outputs);
    drop(node);
    result
}

fn main() -> ExitCode {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env();
    tracing_subscriber::fmt()
        .with_env_filter(filter.unwrap_or_else(|_| "info,rustdds=error,ros2_client=warn".into()))
        .with_writer(std::io::stderr)
        .init();
    chassis_client::install_signal_handlers();
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("{e:#}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn namespaces_are_absolute_without_a_trailing_slash() {
        assert_eq!(namespace("/"), "/");
        assert_eq!(namespace(""), "/");
        assert_eq!(namespace("robot1"), "/robot1");
        assert_eq!(namespace("/robot1/"), "/robot1");
    }
}
