//! `chassis-safety`: the safety monitor. See the crate docs (`src/lib.rs`) and
//! `chassis-safety --print-config` for every rule and default.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use chassis_client::{Robot, RobotDescription, WireProtocol, valid_robot_name};
use chassis_protocols::RobotKind;
use chassis_safety::config::Config;
use chassis_safety::levels::Levels;
use clap::Parser;
use tracing::error;

#[derive(Debug, Parser)]
#[command(
    name = "chassis-safety",
    version,
    about = "The safety monitor: rules over the robot's state (faults, battery, stale state, \
             bumper, ranges, speed, operator e-stop) that slow, stop or latch the e-stop; the \
             mux's required source, so if it dies the robot stops. The speed and battery levels \
             come from the description chassisd publishes of the robot it drives"
)]
struct Args {
    /// The robot's name (chassisd --name).
    #[arg(long, default_value = "titan")]
    name: String,
    /// A TOML configuration file (see --print-config).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Print the effective configuration (TOML, every value with where it comes from) and
    /// exit. The speed and battery levels are those of the running robot --name, read from its
    /// description; without a running chassisd they are unknown, unless --robot names a kind.
    #[arg(long)]
    print_config: bool,
    /// With --print-config: the levels of a robot kind's defaults from the registry (what
    /// chassisd describes with no [profile] or [mux.limits] override), without connecting.
    #[arg(long, value_name = "KIND", requires = "print_config")]
    robot: Option<RobotKind>,
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
    Ok(match &args.config {
        Some(path) => Config::load(path)?,
        None => Config::defaults()?,
    })
}

/// How long `--print-config` waits for a running robot's description.
const DESCRIPTION_WAIT: Duration = Duration::from_secs(2);

/// `--print-config`: the levels of `--robot KIND`'s defaults, of the running robot, or
/// unknown.
fn print_config(args: &Args, config: &Config) -> anyhow::Result<String> {
    let describe = |d: &RobotDescription, whose: String| {
        format!(
            "Robot: {} ({}, model {}, protocol {}), {whose}.",
            d.display_name(),
            d.kind_name(),
            d.model(),
            WireProtocol::name(d.protocol)
        )
    };
    let (levels, about) = if let Some(kind) = args.robot {
        let d = chassis_protocols::description::describe(&kind.entry().defaults());
        let label = kind.to_string();
        let about = vec![
            describe(
                &d,
                "as the registry describes its defaults (no [profile] or [mux.limits] \
                 override)"
                    .to_string(),
            ),
            "A running chassisd may differ: --name NAME without --robot asks it.".to_string(),
        ];
        (Levels::resolve(config, Some(&d), &label), about)
    } else {
        let label = format!("chassis/{}", args.name);
        let read = Robot::connect(&args.name).and_then(|mut r| r.description(DESCRIPTION_WAIT));
        match read {
            Ok(d) => {
                let about = vec![describe(
                    &d,
                    format!("{label} as its chassisd describes it (seq {})", d.seq),
                )];
                (Levels::resolve(config, Some(&d), &label), about)
            }
            Err(e) => {
                let about = vec![
                    format!("No description of {label}: {e}."),
                    "The levels that come from the description are unknown until the monitor \
                     reads it; --robot KIND prints those of a kind's defaults."
                        .to_string(),
                ];
                (Levels::resolve(config, None, &label), about)
            }
        }
    };
    chassis_safety::print::print_config(config, &levels, &about)
        .context("writing the configuration as TOML")
}

fn main() -> ExitCode {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env();
    tracing_subscriber::fmt()
        .with_env_filter(filter.unwrap_or_else(|_| "info".into()))
        .with_writer(std::io::stderr)
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
        return match print_config(&args, &config) {
            Ok(text) => {
                print!("{text}");
                ExitCode::SUCCESS
            }
            Err(err) => {
                eprintln!("chassis-safety: {err:#}");
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
