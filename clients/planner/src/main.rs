//! `chassis-planner`: drive a robot served by `chassisd` along a path to its end and stop there.
//!
//! ```sh
//! chassisd --robot xbot --no-safety-monitor &
//! chassis-planner --name xbot --shape square --size 2
//! chassis-planner --name titan --shape figure-eight          # TITAN: 7.5 m, its turning radius
//! chassis-planner --name scout-mini --path route.csv --json
//! ```
//!
//! Exit status: 0 at the goal, 1 when the robot could not get there (fault, stale state or
//! pose, preempted longer than `--preempt-timeout`, a miss it cannot correct), 2 for bad
//! arguments or a bad path file, 130 after SIGINT / SIGTERM (the robot is stopped first).

use std::path::PathBuf;
use std::process::ExitCode;

use chassis_planner::run::{self, EXIT_INTERRUPTED, Options, Outcome, Repeat, Route};
use chassis_planner::shapes::Shape;
use clap::{ArgGroup, Parser};

/// Drive a path to its end with pure pursuit on the robot's odometry, and stop there.
///
/// The path is in the frame of the robot's pose at start (x ahead, y left, metres): the robot
/// follows the shape from wherever it stands. What the robot can do comes from the description
/// chassisd publishes (its kinematics, turning radius and effective speed limits, every
/// `[profile]` and `[mux.limits]` override included). A robot that steers its wheels (TITAN,
/// HUNTER, RANGER MINI) gets corners of 1.15 × its turning radius (TITAN: a square of at least
/// 3.59 m, default 4 m; figure-eights of at least 7.17 m, default 7.5 m); one that turns on the
/// spot stops and turns at sharp corners.
#[derive(Debug, Parser)]
#[command(name = "chassis-planner", version, group(ArgGroup::new("route").required(true).args(["path", "shape"])))]
struct Cli {
    /// The robot's name (`chassisd --name`).
    #[arg(long, default_value = "titan")]
    name: String,
    /// A waypoint file: CSV `x,y` (optional header) or TOML `[[waypoint]] x = … y = …`, metres.
    #[arg(long, value_name = "FILE")]
    path: Option<PathBuf>,
    /// A built-in path.
    #[arg(long, value_enum)]
    shape: Option<Shape>,
    /// Size of the shape, m (default 2, or the smallest multiple of 0.5 m the robot can turn).
    #[arg(long, value_name = "M", requires = "shape")]
    size: Option<f64>,
    /// Cruise speed, m/s (default 0.8, or the robot's effective limit if lower).
    #[arg(long, value_name = "M/S")]
    speed: Option<f64>,
    /// The velocity source to publish on (configured in chassisd: `planner`, priority 10).
    #[arg(long, default_value = "planner")]
    source: String,
    /// Goal reached within this distance of the last point, m.
    #[arg(long, value_name = "M", default_value_t = 0.05)]
    goal_tolerance: f64,
    /// Give up when held (preempted by another source, locked, no safety monitor, …) longer, s.
    #[arg(long, value_name = "S", default_value_t = 10.0)]
    preempt_timeout: f64,
    /// Drive a closed path N times.
    #[arg(long, value_name = "N", default_value_t = 1, conflicts_with = "repeat")]
    loops: usize,
    /// Drive a closed path until stopped (SIGINT).
    #[arg(long)]
    repeat: bool,
    /// Progress and the summary as JSON lines.
    #[arg(long)]
    json: bool,
    /// A wider smallest turning radius than the robot's, m (robots that steer).
    #[arg(long, value_name = "M")]
    min_turn_radius: Option<f64>,
    /// A lower largest yaw rate than the robot's effective limit, rad/s.
    #[arg(long, value_name = "RAD/S")]
    max_angular: Option<f64>,
}

fn options(cli: Cli) -> Options {
    let route = match (cli.path, cli.shape) {
        (Some(file), _) => Route::File(file),
        (None, shape) => Route::Shape {
            shape: shape.unwrap_or(Shape::Line),
            size_m: cli.size,
        },
    };
    Options {
        name: cli.name,
        route,
        repeat: if cli.repeat {
            Repeat::Forever
        } else {
            Repeat::Times(cli.loops)
        },
        speed_mps: cli.speed,
        source: cli.source,
        goal_tolerance_m: cli.goal_tolerance,
        preempt_timeout_s: cli.preempt_timeout,
        json: cli.json,
        min_turn_radius_m: cli.min_turn_radius,
        max_angular_radps: cli.max_angular,
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run::run(&options(cli)) {
        Ok(Outcome::Reached) => ExitCode::SUCCESS,
        Ok(Outcome::Interrupted) => ExitCode::from(EXIT_INTERRUPTED),
        Err(err) => {
            eprintln!("chassis-planner: {err}");
            ExitCode::from(err.exit_code())
        }
    }
}
