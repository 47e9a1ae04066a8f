//! `chassisd`: the chassis hardware service.

use std::path::PathBuf;
use std::process::ExitCode;

use chassisd_config::{Config, ConfigError, Overrides, RawConfig};
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
    #[command(flatten)]
    overrides: Overrides,
    /// A TOML configuration file (see --print-config).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Print the effective configuration (TOML, with every default) and exit.
    #[arg(long)]
    print_config: bool,
}

fn load(args: ServiceArgs, simulator: bool) -> Result<(Config, bool), ConfigError> {
    let raw = match &args.config {
        Some(path) => RawConfig::load(path)?,
        None => RawConfig::default(),
    };
    let overrides = Overrides {
        simulator,
        ..args.overrides
    };
    Ok((raw.validate(overrides)?, args.print_config))
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
