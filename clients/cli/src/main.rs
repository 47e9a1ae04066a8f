//! `chassis`: the command-line tool of chassisd.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use chassis_interfaces::ClampFlags;
use chassis_protocols::{Profile, Protocol, RobotKind};
use clap::{Parser, Subcommand};

mod action;
mod decode;
mod demo;
mod described;
mod detect;
mod doctor;
mod fleet;
mod interfaces;
mod live;
mod procs;
mod record;
mod top;
mod urdf;

use action::{Action, VelocityArgs};

#[derive(Debug, Parser)]
#[command(
    name = "chassis",
    version,
    about = "Decode, encode and talk to robot chassis run by chassisd"
)]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Debug, Subcommand)]
enum Cmd {
    /// Decode frames to JSON: CAN frames as candump writes them (`123#DEADBEEF` or whole
    /// `candump -l` lines), XBot as hex bytes of the serial stream. Reads stdin when no FRAME is
    /// given. Exits 1 if any frame failed.
    Decode {
        #[command(flatten)]
        profile: ProfileArgs,
        /// Frames (CAN) or hex chunks (XBot).
        frames: Vec<String>,
    },
    /// Print the frame(s) the service would send for a command (CAN as `ID#HEX`, XBot as hex).
    Encode {
        #[command(flatten)]
        profile: ProfileArgs,
        #[command(subcommand)]
        what: EncodeWhat,
    },
    /// Print a robot's state, bus frames or mux decisions as they are published.
    Echo(live::EchoArgs),
    /// Publish requests to a running chassisd.
    Pub {
        #[command(subcommand)]
        what: PubWhat,
    },
    /// A human summary: mode, faults, battery, speeds, active source, bus health.
    Status {
        /// The robot's name (chassisd --name).
        #[arg(long, default_value = "titan")]
        name: String,
        #[arg(long)]
        json: bool,
    },
    /// Ask the running chassisd for a control action.
    Control {
        /// The robot's name (chassisd --name); accepted before or after the action.
        #[arg(long, default_value = "titan", global = true)]
        name: String,
        /// Every robot served on this computer (its own or mirrored): `estop` only. Each
        /// robot's answer is listed; a robot that does not answer within --timeout-ms is named
        /// NOT stopped and the exit status is 1. Releases stay per robot (--name).
        #[arg(long, global = true)]
        all: bool,
        /// With --all: each answer as JSON.
        #[arg(long, global = true, requires = "all")]
        json: bool,
        #[command(flatten)]
        estop: fleet::EstopArgs,
        #[command(subcommand)]
        command: live::ControlCmd,
    },
    /// Every robot served on this computer (by its chassisd, or mirrored by
    /// `chassis-zenoh --mirror-all`), one row each: kind, protocol, mode, battery, faults, the
    /// mux's winner and speed, link age and latency, e-stop. `e` e-stops them all.
    Fleet(fleet::FleetArgs),
    /// A live dashboard: state, mux decisions, bus statistics (frames/s per id, errors, drops)
    /// and end-to-end latency.
    Top(top::TopArgs),
    /// The whole system on a simulated robot: chassisd, the safety monitor, the planner driving
    /// figure-eights, and the dashboard. Ctrl-C stops every process cleanly.
    Demo(demo::DemoArgs),
    /// Record a robot's frames, state and mux decisions (MCAP, opens in Foxglove), or its CAN
    /// frames as a can-utils log (--candump).
    Record(record::RecordArgs),
    /// Play a recording back through the simulated bus, at recorded speed or --max-speed.
    Replay(record::ReplayArgs),
    /// Replay chassisd's black box (a kept `blackbox/kept/*.mcap` of its state directory, or the
    /// directory `blackbox/` itself) through chassisd's engine: every mux decision and frame
    /// checked byte for byte, the story told (`--at TIME`: one moment, `--json`); exits 1 when
    /// the replay diverged. `chassis explain -- --help` for chassisd's options.
    Explain {
        #[arg(trailing_var_arg = true, allow_hyphen_values = true, required = true)]
        args: Vec<String>,
    },
    /// Inject a fault into the simulated chassis of a running chassisd (bus sim) or of
    /// `chassisd sim`.
    Sim {
        /// The robot's name (chassisd --name); accepted before or after the fault.
        #[arg(long, default_value = "titan", global = true)]
        name: String,
        #[command(subcommand)]
        command: live::SimCmd,
    },
    /// The IPC contract: services, limits and payload layouts (--json: the whole document).
    Interfaces(interfaces::InterfacesArgs),
    /// Check everything between this computer and the robot's bus, in order: the interface or
    /// device, its bit rate and permissions, the CAN controller, the frames heard and whose
    /// they are, the robot's control mode and E-stop, chassisd, its state directory and
    /// iceoryx2. Each line gives a verdict and the fix; exits 1 when something blocks driving.
    Doctor(doctor::DoctorArgs),
    /// The robot as a URDF (for RViz, robot_state_publisher): from a running chassisd's
    /// description (--name) or a registry robot's (--robot), on standard output.
    Urdf(urdf::UrdfArgs),
    /// Which AgileX protocol (v1 or v2) a chassis' frames speak, by the rule chassisd applies to
    /// a SCOUT MINI, SCOUT or BUNKER before sending anything. Frames as for decode; stdin when
    /// none. Exits 1 without a decision.
    Detect {
        /// Consistent frames of one protocol needed to decide.
        #[arg(long, default_value_t = 3)]
        min_frames: u32,
        frames: Vec<String>,
    },
}

#[derive(Debug, Subcommand)]
enum PubWhat {
    /// Publish velocity requests as a configured source.
    Velocity(live::PubArgs),
}

// The robot and its profile, as `decode` and `encode` take them. (A doc comment here would be
// the flattened subcommands' about text.)
#[derive(Debug, clap::Args)]
struct ProfileArgs {
    #[arg(long)]
    robot: RobotKind,
    /// AgileX wire protocol, v1 (scout-mini, scout, bunker) or v2 (default: SCOUT MINI v1,
    /// the other AgileX robots v2).
    #[arg(long)]
    protocol: Option<Protocol>,
    /// A TOML file of profile parameters (the `[profile]` table of chassisd's config).
    #[arg(long)]
    profile: Option<PathBuf>,
}

#[derive(Debug, Subcommand)]
enum EncodeWhat {
    /// Motion: forward speed plus a yaw rate (--wz) or a steering angle (--steer).
    Velocity(VelocityArgs),
    #[command(flatten)]
    Action(Action),
}

/// Output into a closed pipe (`chassis echo state | head`) ends the process quietly, as for any
/// Unix tool, instead of failing every write.
fn restore_sigpipe() {
    use nix::sys::signal::{SigHandler, Signal, signal};
    // SAFETY: called first thing in main, before any thread exists; SIG_DFL installs no handler
    // code of ours.
    let _ = unsafe { signal(Signal::SIGPIPE, SigHandler::SigDfl) };
}

impl ProfileArgs {
    /// The robot's profile: the defaults for the protocol, overridden by a TOML file when one
    /// is given.
    fn load(&self) -> anyhow::Result<Profile> {
        let robot = self.robot;
        let table = match &self.profile {
            Some(path) => {
                let text = std::fs::read_to_string(path)
                    .with_context(|| format!("reading profile {}", path.display()))?;
                toml::from_str::<toml::Table>(&text)
                    .with_context(|| format!("parsing {} profile {}", robot, path.display()))?
            }
            None => toml::Table::new(),
        };
        robot
            .entry()
            .profile_from_table(self.protocol, &table)
            .with_context(|| match &self.profile {
                Some(path) => format!("{} profile {}", robot, path.display()),
                None => format!("{robot} profile"),
            })
    }
}

fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    match cli.command {
        Cmd::Decode { profile, frames } => {
            let profile = profile.load()?;
            let stdin = std::io::stdin().lock();
            let summary = decode::run(
                profile,
                &frames,
                stdin,
                &mut std::io::stdout().lock(),
                &mut std::io::stderr().lock(),
            )?;
            // 1 when a line failed to decode.
            Ok(ExitCode::from(u8::from(summary.failed > 0)))
        }
        Cmd::Encode { profile, what } => {
            let profile = profile.load()?;
            let command = match &what {
                EncodeWhat::Velocity(v) => v.to_command()?,
                EncodeWhat::Action(a) => a.to_command().map_err(anyhow::Error::msg)?,
            };
            let (lines, clamp_flags) = profile.command_lines(&command)?;
            for line in lines {
                println!("{line}");
            }
            if clamp_flags != 0 {
                eprintln!(
                    "note: clamped: {}",
                    ClampFlags::names(clamp_flags).join(", ")
                );
            }
            Ok(ExitCode::SUCCESS)
        }
        Cmd::Detect { min_frames, frames } => {
            let (detection, bad) = detect::run(&frames, std::io::stdin().lock(), min_frames)?;
            for line in bad {
                eprintln!("{line}");
            }
            Ok(match detection {
                chassis_protocols::agilex_v2::detect::Detection::Decided(protocol) => {
                    println!("{protocol}");
                    ExitCode::SUCCESS
                }
                other => {
                    eprintln!("{}", other.describe());
                    ExitCode::FAILURE
                }
            })
        }
        // 1 when a check failed.
        Cmd::Doctor(args) => Ok(ExitCode::from(u8::from(!doctor::run(&args)?))),
        Cmd::Echo(args) => live::echo(&args).map(|()| ExitCode::SUCCESS),
        Cmd::Pub {
            what: PubWhat::Velocity(args),
        } => live::publish(&args).map(|()| ExitCode::SUCCESS),
        Cmd::Status { name, json } => live::status(&name, json).map(|()| ExitCode::SUCCESS),
        Cmd::Control {
            all: true,
            json,
            estop,
            command,
            ..
        } => match command {
            live::ControlCmd::Estop { category: None } => fleet::estop_all(&estop, json),
            _ => anyhow::bail!(
                "--all takes estop only, each robot stopping with its own category: a release, \
                 a chosen category or any other action is asked of one robot at a time \
                 (--name NAME)"
            ),
        },
        Cmd::Control { name, command, .. } => {
            live::control(&name, &command).map(|()| ExitCode::SUCCESS)
        }
        Cmd::Fleet(args) => fleet::run(&args).map(|()| ExitCode::SUCCESS),
        Cmd::Sim { name, command } => live::sim(&name, &command).map(|()| ExitCode::SUCCESS),
        Cmd::Top(args) => top::run(&args).map(|()| ExitCode::SUCCESS),
        Cmd::Demo(args) => demo::run(&args).map(|()| ExitCode::SUCCESS),
        Cmd::Record(args) => record::record(&args).map(|()| ExitCode::SUCCESS),
        Cmd::Replay(args) => record::replay(&args).map(|()| ExitCode::SUCCESS),
        Cmd::Explain { args } => explain(&args),
        Cmd::Interfaces(args) => interfaces::run(&args).map(|()| ExitCode::SUCCESS),
        Cmd::Urdf(args) => urdf::run(&args).map(|()| ExitCode::SUCCESS),
    }
}

/// `chassisd explain ARGS…`: the replay runs the service's own engine.
fn explain(args: &[String]) -> anyhow::Result<ExitCode> {
    let chassisd = procs::sibling("chassisd")?;
    let status = std::process::Command::new(&chassisd)
        .arg("explain")
        .args(args)
        .status()
        .with_context(|| format!("running {}", chassisd.display()))?;
    Ok(match status.code() {
        Some(0) => ExitCode::SUCCESS,
        Some(code) => ExitCode::from(u8::try_from(code).unwrap_or(1)),
        None => ExitCode::FAILURE,
    })
}

fn main() -> ExitCode {
    restore_sigpipe();
    let cli = Cli::parse();
    match run(cli) {
        Ok(code) => code,
        Err(err) => {
            eprintln!("chassis: {err:#}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use clap::{CommandFactory, Parser};

    use super::{Cli, Cmd};

    fn name_of(args: &[&str]) -> String {
        match Cli::try_parse_from(args)
            .unwrap_or_else(|e| panic!("{args:?}: {e}"))
            .command
        {
            Cmd::Control { name, .. } | Cmd::Sim { name, .. } | Cmd::Status { name, .. } => name,
            Cmd::Echo(echo) => echo.name,
            Cmd::Top(top) => top.name,
            Cmd::Record(record) => record.name,
            other => panic!("no name in {other:?}"),
        }
    }

    #[test]
    fn the_robot_name_is_accepted_anywhere_on_the_command_line() {
        for args in [
            &["chassis", "control", "--name", "r1", "estop"][..],
            &["chassis", "control", "estop", "--name", "r1"],
            &["chassis", "control", "lock-release", "dock", "--name", "r1"],
            &["chassis", "sim", "battery", "10", "--name", "r1"],
            &["chassis", "sim", "--name", "r1", "silence", "1"],
            &["chassis", "status", "--name", "r1"],
            &["chassis", "echo", "state", "--name", "r1"],
            &["chassis", "top", "--name", "r1"],
        ] {
            assert_eq!(name_of(args), "r1", "{args:?}");
        }
        assert_eq!(name_of(&["chassis", "control", "estop"]), "titan");
    }

    #[test]
    fn control_all_is_the_fleet_estop() {
        let cli = Cli::try_parse_from([
            "chassis",
            "control",
            "--all",
            "estop",
            "--timeout-ms",
            "500",
        ])
        .unwrap();
        match cli.command {
            Cmd::Control {
                all: true, estop, ..
            } => assert_eq!(estop.timeout_ms, 500),
            other => panic!("{other:?}"),
        }
        let err = super::run(
            Cli::try_parse_from(["chassis", "control", "--all", "estop-release"]).unwrap(),
        )
        .unwrap_err();
        assert!(err.to_string().contains("one robot at a time"), "{err}");
    }

    #[test]
    fn every_subcommand_names_what_is_wrong_with_its_arguments() {
        for (args, wanted) in [
            (
                &["chassis", "control", "estop", "--nmae", "r1"][..],
                "--nmae",
            ),
            (&["chassis", "control", "--name"], "--name"),
            (&["chassis", "sim", "bumper", "--name"], "--name"),
            (&["chassis", "decode", "211#00"], "--robot"),
            (&["chassis", "status", "--name", "r1", "extra"], "extra"),
        ] {
            let err = Cli::try_parse_from(args).unwrap_err().to_string();
            assert!(err.contains(wanted), "{args:?}: {err}");
        }
        Cli::command().debug_assert();
    }
}
