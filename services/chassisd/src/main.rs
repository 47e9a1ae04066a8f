//! `chassisd`: the chassis hardware service.

use std::path::PathBuf;
use std::process::ExitCode;

use chassis_bus::BusSpec;
use chassis_protocols::RobotKind;
use chassisd_config::{Config, ConfigError, LoopMode, Overrides, RawConfig};
use clap::{Args, Parser, Subcommand};
use tracing::error;

#[derive(Debug, Parser)]
#[command(
    name = "chassisd",
    version,
    about = "The chassis hardware service: owns the robot's bus, publishes its state over \
             iceoryx2 and drives it from a priority mux",
    args_conflicts_with_subcommands = true
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Cmd>,
    #[command(flatten)]
    service: ServiceArgs,
}

#[derive(Debug, Subcommand)]
enum Cmd {
    /// Run the simulated chassis as its own process on a real bus: pty:LINK (XBot),
    /// slcan-pty:LINK (CAN robots over an emulated slcan adapter), serial:PATH, slcan:PATH or
    /// can:IFACE.
    Sim(ServiceArgs),
}

#[derive(Debug, Args)]
struct ServiceArgs {
    // The registry's robots, listed by the registry.
    #[arg(
        long,
        help = format!("{}.", chassis_protocols::kind::names().join(", "))
    )]
    robot: Option<RobotKind>,
    /// AgileX wire protocol: v1 or v2 (default on a real CAN bus: detected for scout-mini, scout
    /// and bunker; on the simulator: the robot's own, SCOUT MINI v1, the others v2).
    #[arg(long)]
    protocol: Option<chassis_protocols::Protocol>,
    /// sim (default), can:IFACE, serial:PATH[@BAUD], slcan:PATH[@BAUD].
    #[arg(long)]
    bus: Option<BusSpec>,
    /// Namespace of the robot's services, chassis/<NAME>/… (default: the robot).
    #[arg(long)]
    name: Option<String>,
    /// A TOML configuration file (see --print-config).
    #[arg(long)]
    config: Option<PathBuf>,
    /// The XBot's GPS receiver: serial:PATH[@BAUD] (NMEA 0183, default 4800 8N1).
    #[arg(long)]
    gps: Option<BusSpec>,
    /// Drive without a safety monitor: lift the rule that the required source must be alive.
    #[arg(long)]
    no_safety_monitor: bool,
    /// Print the effective configuration (TOML, with every default) and exit.
    #[arg(long)]
    print_config: bool,
    /// How the loop waits: event (block; default), spin (poll continuously), hybrid (poll
    /// for --spin-us after each activity, then block).
    #[arg(long = "loop", value_enum)]
    loop_mode: Option<LoopMode>,
    /// Hybrid loop: microseconds to keep polling after each activity.
    #[arg(long)]
    spin_us: Option<u64>,
    /// Pin the loop's thread to this CPU.
    #[arg(long)]
    cpu: Option<usize>,
    /// Real-time mode: the loop's thread at SCHED_FIFO with priority PRIO (1-99), memory
    /// locked; when the system refuses, a warning and normal scheduling.
    #[arg(long, value_name = "PRIO")]
    realtime: Option<u8>,
    /// Where the held locks are kept across restarts (default: $STATE_DIRECTORY, else
    /// $XDG_STATE_HOME/chassisd/NAME, else ~/.local/state/chassisd/NAME).
    #[arg(long, value_name = "DIR")]
    state_dir: Option<PathBuf>,
}

fn load(args: ServiceArgs, simulator: bool) -> Result<(Config, bool), ConfigError> {
    let raw = match &args.config {
        Some(path) => RawConfig::load(path)?,
        None => RawConfig::default(),
    };
    let config = raw.validate(Overrides {
        robot: args.robot,
        protocol: args.protocol,
        name: args.name,
        bus: args.bus,
        gps: args.gps,
        no_safety_monitor: args.no_safety_monitor,
        simulator,
        loop_mode: args.loop_mode,
        spin_us: args.spin_us,
        cpu: args.cpu,
        realtime: args.realtime,
        state_dir: args.state_dir,
    })?;
    Ok((config, args.print_config))
}

fn main() -> ExitCode {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env();
    tracing_subscriber::fmt()
        .with_env_filter(filter.unwrap_or_else(|_| "info".into()))
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    let (is_sim, args) = match cli.command {
        Some(Cmd::Sim(args)) => (true, args),
        None => (false, cli.service),
    };
    let (config, print) = match load(args, is_sim) {
        Ok(loaded) => loaded,
        Err(err) => {
            eprintln!("chassisd: {err}");
            return ExitCode::from(2);
        }
    };
    if print {
        return match config.to_toml() {
            Ok(text) => {
                print!("{text}");
                ExitCode::SUCCESS
            }
            Err(err) => {
                eprintln!("chassisd: {err}");
                ExitCode::FAILURE
            }
        };
    }
    let result = if is_sim {
        chassisd::sim_process::run(&config).map_err(|e| e.to_string())
    } else {
        chassisd::service::run(config).map_err(|e| e.to_string())
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            error!("{err}");
            eprintln!("chassisd: {err}");
            ExitCode::FAILURE
        }
    }
}
