//! `chassis-safety`: the safety monitor. See the crate docs (`src/lib.rs`) and
//! `chassis-safety --print-config` for every rule and default.

use std::path::PathBuf;
use std::process::ExitCode;

use chassis_client::valid_robot_name;
use chassis_safety::config::{Config, RawConfig};
use clap::Parser;
use tracing::error;

#[derive(Debug, Parser)]
#[command(
    name = "chassis-safety",
    version,
    about = "The safety monitor: rules over the robot's state (faults, battery, stale state, \
             bumper, ranges, speed, operator e-stop) that slow, stop or latch the e-stop; the \
             mux's required source, so if it dies the robot stops"
)]
struct Args {
    /// The robot's name (chassisd --name).
    #[arg(long, default_value = "titan")]
    name: String,
    /// A TOML configuration file (see --print-config).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Print the effective configuration (TOML, with every default) and exit.
    #[arg(long)]
    print_config: bool,
    /// The mux source to publish as (chassisd's config names it; `safety` is the required one).
    #[arg(long, default_value = "safety")]
    source: String,
}

fn load(args: &Args) -> anyhow::Result<Config> {
    for (what, name) in [("--name", &args.name), ("--source", &args.source)] {
        if !valid_robot_name(name) {
            anyhow::bail!("{what} '{name}': 1-16 of a-z 0-9 - _");
        }
    }
    let raw = match &args.config {
        Some(path) => RawConfig::load(path)?,
        None => RawConfig::default(),
    };
    Ok(raw.validate()?)
}

fn main() -> ExitCode {
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .init();
    let args = Args::parse();
    let config = match load(&args) {
        Ok(config) => config,
        Err(err) => {
            eprintln!("chassis-safety: {err}");
            return ExitCode::from(2);
        }
    };
    if args.print_config {
        return match config.to_toml() {
            Ok(text) => {
                print!("{text}");
                ExitCode::SUCCESS
            }
            Err(err) => {
                eprintln!("chassis-safety: {err}");
                ExitCode::FAILURE
            }
        };
    }
    match chassis_safety::monitor::run(config, &args.name, &args.source) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            error!("{err}");
            ExitCode::FAILURE
        }
    }
}
