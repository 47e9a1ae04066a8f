//! `chassis-zenoh`: a robot's services mirrored to another computer over Zenoh.
//!
//! On the robot, beside chassisd:
//!
//! ```text
//! chassis-zenoh --name titan --listen tls/192.168.1.20:7447 --certs /etc/chassis/zenoh
//! ```
//!
//! publishes `chassis/titan/state` and `chassis/titan/mux` (the fixed-layout bytes, encoding
//! `application/octet-stream;<type name>`), `…/frames` (batches of `BusFrame`), JSON twins
//! `…/state/json` and `…/mux/json` (10 Hz), a liveliness token `chassis/titan/alive`, answers
//! `chassis/titan/control` (a `ControlRequest` → chassisd's `ControlResponse`) and takes
//! `chassis/titan/cmd/<source>` for the sources chassisd's config marks `remote = true` only
//! (never the required safety source), re-stamping each request on arrival.
//!
//! On the operator's computer:
//!
//! ```text
//! chassis-zenoh --name titan --connect tls/192.168.1.20:7447 --certs ~/.config/chassis/zenoh --mirror
//! ```
//!
//! recreates state, mux, frames, control and the remote sources in the local iceoryx2, so that
//! `chassis top --name titan` and `chassis-teleop --name titan --source remote` work there.
//!
//! A fleet from one operator's computer: `--connect` each robot's endpoint (repeatable) with
//! `--mirror-all` (or `--robots titan,scout$*`) instead of `--name … --mirror`: every robot found
//! through Zenoh's liveliness is mirrored under its name, robots switched on later too, and a
//! robot whose link is lost is shown so (`LinkFlags::REMOTE_LOST`) within a second. An e-stop
//! asked of a robot that does not answer stays asked: the mirror delivers it when the robot is
//! heard again, and shows it pending meanwhile (see `estop.rs`).
//!
//! `chassis-zenoh gen-certs DIR --host 192.168.1.20` makes the certificates (a CA, the robot's,
//! the operator's). Plain `tcp/` is refused beyond loopback unless `--insecure`.

mod certs;
mod convert;
mod estop;
mod export;
mod fleet;
mod link_watch;
mod mirror;

use chassis_zenoh::net;

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use clap::{Parser, Subcommand};

/// A robot's services mirrored to another computer over Zenoh.
#[derive(Debug, Parser)]
#[command(
    name = "chassis-zenoh",
    version,
    args_conflicts_with_subcommands = true
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    /// The robot's name (chassisd --name).
    #[arg(long)]
    name: Option<String>,
    /// Robot side: serve the robot on this endpoint (tcp/ADDR:PORT or tls/ADDR:PORT; repeatable).
    #[arg(long, conflicts_with = "connect")]
    listen: Vec<String>,
    /// Operator side: the robot side's endpoint (repeatable).
    #[arg(long)]
    connect: Vec<String>,
    /// Operator side: recreate the robot's services in this computer's iceoryx2.
    #[arg(long, requires = "connect")]
    mirror: bool,
    /// Operator side: mirror every robot found on the endpoints given (Zenoh liveliness), each
    /// under its name, including robots that appear later. No --name.
    #[arg(long, requires = "connect", conflicts_with_all = ["mirror", "name"])]
    mirror_all: bool,
    /// Operator side: mirror the robots these names or key-expression chunks name (comma
    /// separated: `titan,scout1`, `scout$*`), found as --mirror-all finds them.
    #[arg(long, value_delimiter = ',', requires = "connect", conflicts_with_all = ["mirror", "name"])]
    robots: Vec<String>,
    /// The directory `chassis-zenoh gen-certs` wrote (for tls/ endpoints).
    #[arg(long)]
    certs: Option<PathBuf>,
    /// Allow plain TCP beyond loopback: anyone on that network can drive the robot.
    #[arg(long)]
    insecure: bool,
    /// Robot side: most binary state samples per second (0: the newest of every read of the bus).
    #[arg(long, default_value_t = 0.0)]
    state_hz: f64,
    /// Robot side: JSON twins per second.
    #[arg(long, default_value_t = 10.0)]
    json_hz: f64,
    /// Link lease, ms: a link silent for this long is closed (and reopened when it comes back).
    #[arg(long, default_value_t = 3000)]
    lease_ms: u64,
    /// Robot side: how long to wait for chassisd at start, s.
    #[arg(long, default_value_t = 10.0)]
    wait: f64,
    /// Robot side: oldest a velocity request may be when it arrives, ms (judged on its stamp
    /// against the operator side's clock, measured on the session); older ones are dropped.
    #[arg(long, default_value_t = 250)]
    max_age_ms: u64,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Make a CA and certificates for both sides in DIR.
    GenCerts {
        dir: PathBuf,
        /// The robot's address or DNS name as the operator connects to it (repeatable;
        /// default: localhost and 127.0.0.1).
        #[arg(long)]
        host: Vec<String>,
    },
}

fn run(cli: Cli) -> anyhow::Result<()> {
    if let Some(Command::GenCerts { dir, host }) = cli.command {
        certs::generate(&dir, &host)?;
        eprintln!(
            "chassis-zenoh: wrote {dir}/{{{},{},{},{},{},{}}}: copy ca.pem, robot.pem and \
             robot-key.pem to the robot, ca.pem, operator.pem and operator-key.pem to the \
             operator's computer; keep ca-key.pem apart",
            net::CA_CERT,
            certs::CA_KEY,
            net::ROBOT_CERT,
            net::ROBOT_KEY,
            net::OPERATOR_CERT,
            net::OPERATOR_KEY,
            dir = dir.display()
        );
        return Ok(());
    }
    if cli.mirror_all || !cli.robots.is_empty() {
        chassis_client::install_signal_handlers();
        let patterns = if cli.robots.is_empty() {
            vec!["*".to_string()]
        } else {
            cli.robots.clone()
        };
        for pattern in &patterns {
            fleet::check_pattern(pattern)?;
        }
        return fleet::run(&fleet::Config {
            net: net::Net {
                role: net::Role::Operator,
                endpoints: cli.connect,
                certs: cli.certs,
                insecure: cli.insecure,
                lease_ms: cli.lease_ms,
            },
            patterns,
        });
    }
    let Some(name) = cli.name.clone() else {
        anyhow::bail!("--name ROBOT is needed (or --mirror-all, or the gen-certs command)");
    };
    if !chassis_client::valid_robot_name(&name) {
        anyhow::bail!("'{name}' is not a valid robot name (1-16 of a-z 0-9 - _)");
    }
    chassis_client::install_signal_handlers();
    let net = |role, endpoints: Vec<String>| net::Net {
        role,
        endpoints,
        certs: cli.certs.clone(),
        insecure: cli.insecure,
        lease_ms: cli.lease_ms,
    };
    if !cli.listen.is_empty() {
        if !(cli.json_hz > 0.0 && cli.state_hz >= 0.0) {
            anyhow::bail!("--json-hz must be above 0 and --state-hz at least 0");
        }
        export::run(&export::Config {
            name,
            net: net(net::Role::Robot, cli.listen),
            state_hz: cli.state_hz,
            json_hz: cli.json_hz,
            wait: Duration::from_secs_f64(cli.wait.max(0.0)),
            max_age: Duration::from_millis(cli.max_age_ms),
        })
    } else if cli.mirror {
        mirror::run(&mirror::Config {
            name,
            net: net(net::Role::Operator, cli.connect),
        })
    } else {
        anyhow::bail!(
            "say which side: --listen ENDPOINT (robot side) or --connect ENDPOINT --mirror (operator side)"
        )
    }
}

fn main() -> ExitCode {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env();
    tracing_subscriber::fmt()
        .with_env_filter(filter.unwrap_or_else(|_| "warn,zenoh=error".into()))
        .with_writer(std::io::stderr)
        .init();
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("chassis-zenoh: {err:#}");
            ExitCode::FAILURE
        }
    }
}
