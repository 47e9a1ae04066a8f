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
    /// Replay a black-box recording (a kept `blackbox/kept/*.mcap`, or the live ring: the state
    /// directory's `blackbox/`) through
    /// this engine: every mux decision and item written checked against it, and the story told.
    Explain(ExplainArgs),
}

#[derive(Debug, Args)]
struct ExplainArgs {
    file: PathBuf,
    /// One moment: HH:MM:SS[.mmm] (UTC) or +SECONDS since the recording's start.
    #[arg(long)]
    at: Option<String>,
    /// The verdict and the story as JSON.
    #[arg(long)]
    json: bool,
    /// Replay on this configuration (TOML, as --print-config writes it) instead of the recorded
    /// one.
    #[arg(long)]
    config: Option<PathBuf>,
}

/// `chassisd explain`: 0 when the replay is identical, 1 when it diverged, 2 on a bad file.
fn explain(args: &ExplainArgs) -> anyhow::Result<ExitCode> {
    use anyhow::Context;
    use chassisd::blackbox::{replay, ring};
    let bytes = if args.file.is_dir() {
        ring::read_ring(&args.file)
    } else {
        std::fs::read(&args.file)
    }
    .with_context(|| args.file.display().to_string())?;
    let events = ring::read(&bytes)?;
    let config = args
        .config
        .as_ref()
        .map(|path| std::fs::read_to_string(path).with_context(|| path.display().to_string()))
        .transpose()?;
    let run = replay::replay(&events, config.as_deref())?;
    let chapters = replay::story(&run);
    if let Some(text) = &args.at {
        let at = replay::parse_time(&run, text)
            .with_context(|| format!("--at {text}: HH:MM:SS[.mmm] or +SECONDS"))?;
        let said = replay::at(&run, at).unwrap_or_else(|| "no decision yet".into());
        if args.json {
            println!(
                "{}",
                serde_json::json!({ "at_ns": at, "explanation": said })
            );
        } else {
            println!("{said}");
        }
    } else if args.json {
        let json = serde_json::json!({ "replay": run, "story": chapters });
        println!("{}", serde_json::to_string_pretty(&json)?);
    } else {
        print!("{}", replay::render(&run, &chapters));
    }
    Ok(if run.divergence.is_some() {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    })
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
    let cli = Cli::parse();
    // The replayed engine would log what the service logged: nothing, unless RUST_LOG asks.
    let quiet = matches!(cli.command, Some(Cmd::Explain(_)));
    let filter = tracing_subscriber::EnvFilter::try_from_default_env();
    tracing_subscriber::fmt()
        .with_env_filter(filter.unwrap_or_else(|_| if quiet { "off" } else { "info" }.into()))
        .with_writer(std::io::stderr)
        .init();
    let (is_sim, args) = match cli.command {
        Some(Cmd::Sim(args)) => (true, args),
        Some(Cmd::Explain(args)) => {
            return explain(&args).unwrap_or_else(|err| {
                eprintln!("chassisd explain: {err:#}");
                ExitCode::from(2)
            });
        }
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
