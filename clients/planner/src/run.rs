//! The planner's loop: connect, read the robot's description (what it is and its effective
//! limits: [`Kinematics::from_description`]), build the path in the frame of the start pose,
//! then at 50 Hz read the latest state and mux status, judge them ([`Watch`]), ask the
//! [`Tracker`] for a command and publish it on the planner's source. A newer description
//! (protocol detection deciding, a restarted chassisd with another configuration) changes the
//! limits under way, or ends the run if the path no longer fits the robot. The only module that
//! reads the clock, and only through `chassis_client::now_ns` and `Ticker`.

use std::path::PathBuf;
use std::time::Duration;

use chassis_client::{
    ChassisState, ClientError, Group, Kinematics as KinematicsKind, Robot, RobotDescription,
    Source, Ticker, VelocityRequest, install_signal_handlers, now_ns, termination_requested,
};
use thiserror::Error;

use crate::geometry::{Point, Pose};
use crate::kinematics::{Kinematics, KinematicsError, robot_label};
use crate::path::{Path, PathError};
use crate::report::{Progress, Reporter, Start, Summary};
use crate::shapes::{self, CORNER_RADIUS_MARGIN, SAMPLE_STEP_M, Shape, ShapeError};
use crate::tracker::{Activity, Measured, TrackError, Tracker, TrackerConfig};
use crate::watch::{Failure, Hold, Status, Watch, WatchConfig};
use crate::waypoints::{self, WaypointError};

/// Control period.
pub const PERIOD: Duration = Duration::from_millis(20);
/// Explicit stops sent at the end (and on a signal or a failure), s.
pub const FINAL_STOP_S: f64 = 0.3;
/// Progress lines, s.
pub const PROGRESS_S: f64 = 1.0;
/// Longest wait for a new state sample, and the oldest pose followed, s.
pub const STALE_S: f64 = 1.0;
/// Longest wait at start for a state with a pose, and for the robot's description, s.
pub const STARTUP_S: f64 = 2.0;
/// Smallest goal tolerance: the follower stops within 5 mm of where it aims, m.
pub const MIN_GOAL_TOLERANCE_M: f64 = 0.01;
/// Exit code after SIGINT / SIGTERM.
pub const EXIT_INTERRUPTED: u8 = 130;

/// What to drive.
#[derive(Debug, Clone, PartialEq)]
pub enum Route {
    Shape { shape: Shape, size_m: Option<f64> },
    File(PathBuf),
}

/// How many times.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Repeat {
    Times(usize),
    Forever,
}

/// Everything the command line decides.
#[derive(Debug, Clone, PartialEq)]
pub struct Options {
    pub name: String,
    pub route: Route,
    pub repeat: Repeat,
    pub speed_mps: Option<f64>,
    pub source: String,
    pub goal_tolerance_m: f64,
    pub preempt_timeout_s: f64,
    pub json: bool,
    pub min_turn_radius_m: Option<f64>,
    pub max_angular_radps: Option<f64>,
}

/// How the run ended without an error.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// At the goal, stopped.
    Reached,
    /// SIGINT or SIGTERM: the robot was stopped.
    Interrupted,
}

/// Why the planner did not get there.
#[derive(Debug, Error)]
pub enum RunError {
    /// Bad arguments or a bad path (exit 2).
    #[error("{0}")]
    Usage(String),
    #[error(transparent)]
    Waypoints(#[from] WaypointError),
    #[error(transparent)]
    Shape(#[from] ShapeError),
    #[error(transparent)]
    Path(#[from] PathError),
    #[error(transparent)]
    Client(#[from] ClientError),
    #[error(transparent)]
    Failure(#[from] Failure),
    #[error(transparent)]
    Track(#[from] TrackError),
    /// The description gives too little to drive by.
    #[error(transparent)]
    Kinematics(#[from] KinematicsError),
    /// A newer description of the robot no longer fits the path under way.
    #[error(
        "chassis/{name} describes its robot anew (description #{seq}): {what}; the path was          built for the robot as it was"
    )]
    DescriptionChanged {
        name: String,
        seq: u64,
        what: String,
    },
    /// SIGINT or SIGTERM before the planner started driving (exit 130).
    #[error("interrupted before the start")]
    Interrupted,
}

impl RunError {
    /// 2 for a bad request, 1 when the robot could not get there.
    pub fn exit_code(&self) -> u8 {
        match self {
            RunError::Usage(_)
            | RunError::Waypoints(_)
            | RunError::Shape(_)
            | RunError::Path(_) => 2,
            RunError::Client(_)
            | RunError::Failure(_)
            | RunError::Track(_)
            | RunError::Kinematics(_)
            | RunError::DescriptionChanged { .. } => 1,
            RunError::Interrupted => EXIT_INTERRUPTED,
        }
    }
}

/// The path to drive, in the start pose's frame.
#[derive(Debug, Clone)]
pub struct Plan {
    pub path: Path,
    /// One loop's length when repeating forever.
    pub period_m: Option<f64>,
    pub description: String,
}

fn positive(name: &str, value: f64) -> Result<f64, RunError> {
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(RunError::Usage(format!(
            "{name} must be a positive number (got {value})"
        )))
    }
}

/// The robot's kinematics from its description, with the command line's overrides: a wider
/// turning radius, a lower yaw rate, never beyond what the description allows.
pub fn kinematics(options: &Options, d: &RobotDescription) -> Result<Kinematics, RunError> {
    let robot = robot_label(d);
    let mut kin = Kinematics::from_description(d)?;
    if let Some(radius) = options.min_turn_radius_m {
        if kin.turns_on_the_spot() {
            return Err(RunError::Usage(format!(
                "--min-turn-radius is for robots that steer; {robot} turns on the spot",
            )));
        }
        let radius = positive("--min-turn-radius", radius)?;
        if radius < kin.min_turn_radius_m() {
            return Err(RunError::Usage(format!(
                "--min-turn-radius {radius} is tighter than {robot} turns ({:.3} m, from its \
                 description)",
                kin.min_turn_radius_m()
            )));
        }
        kin = kin.with_min_turn_radius(radius);
    }
    if let Some(rate) = options.max_angular_radps {
        let rate = positive("--max-angular", rate)?;
        if rate > kin.max_angular_radps() {
            return Err(RunError::Usage(format!(
                "--max-angular {rate} is above {robot}'s effective yaw-rate limit ({} rad/s, \
                 from its description)",
                kin.max_angular_radps()
            )));
        }
        kin = kin.with_max_angular(rate);
    }
    Ok(kin)
}

/// The cruise speed: `--speed` within the robot's limits, or its default.
pub fn cruise_speed(options: &Options, kin: &Kinematics, robot: &str) -> Result<f64, RunError> {
    let Some(speed) = options.speed_mps else {
        return Ok(kin.default_speed_mps);
    };
    let speed = positive("--speed", speed)?;
    if speed > kin.max_linear_mps || speed < kin.min_linear_mps {
        return Err(RunError::Usage(format!(
            "--speed {speed} is outside what {robot} can do ({} to {} m/s, from its \
             description's effective limits)",
            kin.min_linear_mps, kin.max_linear_mps
        )));
    }
    Ok(speed)
}

/// What to do about a robot that publishes no pose, from its description: a robot that turns
/// by its wheel speeds integrates its pose from them and its track.
pub fn pose_hint(d: &RobotDescription) -> String {
    if d.geometry.track_m.is_finite() || KinematicsKind::steers(d.kinematics) {
        return String::new();
    }
    format!(
        ": its description gives no track (the distance between its wheels), which a {} \
         robot's odometry needs — set it in chassisd's [profile] (`chassisd --robot {} \
         --print-config` lists the parameters)",
        KinematicsKind::name(d.kinematics),
        d.kind_name()
    )
}

/// Builds the path for `kin`: a shape, or a file's waypoints (from the robot's position if they
/// do not start there), repeated, corners rounded for a robot with a turning radius.
pub fn plan(options: &Options, kin: &Kinematics) -> Result<Plan, RunError> {
    let build = |loops: usize| -> Result<(Path, String), RunError> {
        match &options.route {
            Route::Shape { shape, size_m } => {
                let size = size_m.unwrap_or_else(|| shape.default_size_m(kin));
                let path = shapes::build(*shape, size, loops, kin)?;
                Ok((path, format!("{} of {size:.2} m", shape.name())))
            }
            Route::File(file) => {
                let mut points = waypoints::read(file).map_err(|e| match e {
                    WaypointError::Read { .. } => RunError::Waypoints(e),
                    other => RunError::Usage(format!("{}: {other}", file.display())),
                })?;
                let count = points.len();
                let origin = Point::new(0.0, 0.0);
                let from_robot = points[0].distance(origin) > options.goal_tolerance_m;
                if from_robot {
                    points.insert(0, origin);
                }
                let outline = Path::new(points)?.repeated(loops, options.goal_tolerance_m)?;
                let mut text = format!("{count} waypoints of {}", file.display());
                if from_robot {
                    text += ", from the robot's position";
                }
                Ok((round_for(&outline, kin)?, text))
            }
        }
    };
    match options.repeat {
        Repeat::Times(n) => {
            let (path, description) = build(n.max(1))?;
            let description = if n > 1 {
                format!("{description}, {n} times")
            } else {
                description
            };
            Ok(Plan {
                path,
                period_m: None,
                description,
            })
        }
        Repeat::Forever => {
            let (three, description) = build(3)?;
            let (two, _) = build(2)?;
            Ok(Plan {
                period_m: Some(three.length_m() - two.length_m()),
                path: three,
                description,
            })
        }
    }
}

/// Rounds a file's corners for a robot with a turning radius: with the shapes' margin if the legs
/// allow it, else at the minimum radius itself.
fn round_for(path: &Path, kin: &Kinematics) -> Result<Path, RunError> {
    let radius = kin.min_turn_radius_m();
    if radius <= 0.0 {
        return Ok(path.clone());
    }
    Ok(path
        .rounded(radius * CORNER_RADIUS_MARGIN, SAMPLE_STEP_M)
        .or_else(|_| path.rounded(radius, SAMPLE_STEP_M))?)
}

fn pose_of(state: &ChassisState) -> Pose {
    let odometry = &state.odometry;
    Pose::new(odometry.x_m, odometry.y_m, odometry.yaw_rad)
}

fn measured(state: &ChassisState) -> Measured {
    Measured {
        pose: pose_of(state),
        linear_mps: f64::from(state.motion.linear_mps),
        angular_radps: f64::from(state.motion.angular_radps),
        lateral_mps: f64::from(state.motion.lateral_mps),
    }
}

fn seconds(ns: u64) -> f64 {
    ns as f64 / 1e9
}

fn ns(seconds: f64) -> u64 {
    // Finite and not negative by the callers; saturates.
    (seconds.max(0.0) * 1e9) as u64
}

/// Waits for a state with a pose.
fn first_state(robot: &mut Robot, name: &str, pose_hint: &str) -> Result<ChassisState, RunError> {
    let end = now_ns().saturating_add(ns(STARTUP_S));
    let mut latest = robot.latest_state()?;
    loop {
        if let Some(state) = latest
            && state.is_valid(Group::Pose)
        {
            return Ok(state);
        }
        if termination_requested() {
            return Err(RunError::Interrupted);
        }
        if now_ns() >= end {
            return Err(match latest {
                None => Failure::StaleState { seconds: STARTUP_S }.into(),
                Some(_) => Failure::no_pose(name, pose_hint).into(),
            });
        }
        if let Some(state) = robot.wait_state(Duration::from_millis(100))? {
            latest = Some(state);
        }
    }
}

/// `value` as the `f32` a request carries, never larger: a request at a limit must not read above
/// it once widened again (0.4 is 0.4000000059604645 as an `f32`), or the driver clamps it.
pub fn toward_zero(value: f64) -> f32 {
    let narrow = value as f32;
    if f64::from(narrow).abs() > value.abs() {
        if narrow > 0.0 {
            narrow.next_down()
        } else {
            narrow.next_up()
        }
    } else {
        narrow
    }
}

/// How a robot turns, for messages.
fn turning_text(kin: &Kinematics) -> String {
    if kin.turns_on_the_spot() {
        "on the spot".into()
    } else {
        format!("no tighter than {:.2} m", kin.min_turn_radius_m())
    }
}

/// Sends explicit stops for `seconds`.
fn stop_for(source: &mut Source, ticker: &mut Ticker, seconds: f64) -> Result<(), ClientError> {
    let end = now_ns().saturating_add(ns(seconds));
    loop {
        source.stop()?;
        if now_ns() >= end {
            return Ok(());
        }
        ticker.wait();
    }
}

/// Drives the plan; see the crate docs.
pub fn run(options: &Options) -> Result<Outcome, RunError> {
    install_signal_handlers();
    let goal_tolerance = positive("--goal-tolerance", options.goal_tolerance_m)?;
    if goal_tolerance < MIN_GOAL_TOLERANCE_M {
        return Err(RunError::Usage(format!(
            "--goal-tolerance must be at least {MIN_GOAL_TOLERANCE_M} m (got {goal_tolerance})"
        )));
    }
    if !(options.preempt_timeout_s.is_finite() && options.preempt_timeout_s >= 0.0) {
        return Err(RunError::Usage(format!(
            "--preempt-timeout must be a number of seconds (got {})",
            options.preempt_timeout_s
        )));
    }
    let reporter = Reporter::new(options.json);
    let mut robot = Robot::connect(&options.name)?;
    let mut description = robot.description(Duration::from_secs_f64(STARTUP_S))?;
    let robot_text = robot_label(&description);
    let state = first_state(&mut robot, &options.name, &pose_hint(&description))?;
    let kin = kinematics(options, &description)?;
    let speed = cruise_speed(options, &kin, &robot_text)?;
    let plan = plan(options, &kin)?;
    let start = pose_of(&state);
    let mut config = TrackerConfig::new(kin, speed);
    config.goal_tolerance_m = goal_tolerance;
    config.period_m = plan.period_m;
    let mut tracker = Tracker::new(plan.path.transformed(start), config);
    let mut source = robot.source(&options.source)?;
    let goal = tracker.goal();
    reporter.start(&Start {
        robot: options.name.clone(),
        described_as: match description.display_name() {
            "" => robot_text.clone(),
            display => format!("{display} ({robot_text})"),
        },
        path: plan.description.clone(),
        length_m: plan.period_m.unwrap_or_else(|| tracker.path().length_m()),
        corner_stops: tracker.corner_stops(),
        speed_mps: speed,
        kinematics: kin,
        pose: start,
        goal: (goal.x, goal.y),
        repeat_forever: plan.period_m.is_some(),
    });

    let t0 = now_ns();
    let mut watch = Watch::new(
        WatchConfig {
            name: options.name.clone(),
            pose_hint: pose_hint(&description),
            source: options.source.clone(),
            preempt_timeout_ns: ns(options.preempt_timeout_s),
            state_timeout_ns: ns(STALE_S),
            pose_timeout_ns: ns(STALE_S),
        },
        t0,
    );
    let mut ticker = Ticker::new(PERIOD);
    let mut last_tick = t0;
    let mut last_progress = t0;
    let mut last_seq = state.seq;
    let mut last_position = start.position();
    let mut travelled = 0.0;
    let mut max_cross_track = 0.0f64;
    let mut held: Option<(Hold, u64)> = None;
    let mut held_total_ns = 0u64;
    let mut latest = state;

    let fail = |source: &mut Source,
                ticker: &mut Ticker,
                error: RunError,
                now: u64|
     -> Result<Outcome, RunError> {
        let _ = stop_for(source, ticker, FINAL_STOP_S);
        reporter.failed(seconds(now.saturating_sub(t0)), &error.to_string());
        Err(error)
    };

    loop {
        ticker.wait();
        let now = now_ns();
        let dt = seconds(now.saturating_sub(last_tick));
        last_tick = now;
        if termination_requested() {
            stop_for(&mut source, &mut ticker, FINAL_STOP_S)?;
            reporter.interrupted(seconds(now.saturating_sub(t0)));
            return Ok(Outcome::Interrupted);
        }
        if let Some(newer) = robot.latest_description()?
            && (newer.seq, newer.stamp_ns) != (description.seq, description.stamp_ns)
        {
            description = newer;
            let limits = kinematics(options, &description).and_then(|k| {
                tracker.config().kinematics.updated_by(&k).ok_or_else(|| {
                    RunError::DescriptionChanged {
                        name: options.name.clone(),
                        seq: description.seq,
                        what: format!(
                            "{} now turns {}",
                            robot_label(&description),
                            turning_text(&k)
                        ),
                    }
                })
            });
            match limits {
                Ok(k) if k == tracker.config().kinematics => {}
                Ok(k) => {
                    tracker.set_kinematics(k);
                    reporter.limits(seconds(now.saturating_sub(t0)), description.seq, &k);
                }
                Err(e) => return fail(&mut source, &mut ticker, e, now),
            }
        }
        let state = robot.latest_state()?;
        let mux = robot.latest_mux()?;
        let status = match watch.observe(now, state.as_ref(), mux.as_ref()) {
            Ok(status) => status,
            Err(failure) => return fail(&mut source, &mut ticker, failure.into(), now),
        };
        if let Some(s) = state {
            latest = s;
        }
        if latest.seq != last_seq {
            last_seq = latest.seq;
            let here = pose_of(&latest).position();
            travelled += here.distance(last_position);
            last_position = here;
        }
        let m = measured(&latest);
        let step = match tracker.update(&m, dt) {
            Ok(step) => step,
            Err(e) => return fail(&mut source, &mut ticker, e.into(), now),
        };
        match (&status, held.take()) {
            (Status::Held { hold, since_ns }, previous) => {
                tracker.hold(&m);
                if previous.as_ref().is_none_or(|(h, _)| h != hold) {
                    reporter.hold(seconds(now - t0), &hold.to_string(), true, 0.0);
                }
                held = Some((hold.clone(), *since_ns));
            }
            (Status::Clear, Some((hold, since))) => {
                let for_ns = now.saturating_sub(since);
                held_total_ns += for_ns;
                reporter.hold(seconds(now - t0), &hold.to_string(), false, seconds(for_ns));
            }
            (Status::Clear, None) => {}
        }
        if step.activity == Activity::Driving {
            max_cross_track = max_cross_track.max(step.cross_track_m.abs());
        }
        if step.activity == Activity::Done {
            break;
        }
        let mut request = VelocityRequest::twist(
            toward_zero(step.command.linear_mps),
            toward_zero(step.command.angular_radps),
        );
        request.linear_y_mps = toward_zero(step.command.lateral_mps);
        source.send(request)?;
        if seconds(now.saturating_sub(last_progress)) >= PROGRESS_S {
            last_progress = now;
            reporter.progress(&Progress {
                time_s: seconds(now - t0),
                activity: step.activity.name(),
                travelled_m: travelled,
                remaining_m: step.remaining_m,
                cross_track_m: step.cross_track_m,
                goal_distance_m: step.goal_distance_m,
                pose: m.pose,
                linear_mps: m.linear_mps,
                held: held
                    .as_ref()
                    .map(|(h, since)| (h.to_string(), seconds(now.saturating_sub(*since)))),
                laps: step.laps,
            });
        }
    }
    stop_for(&mut source, &mut ticker, FINAL_STOP_S)?;
    if let Some(s) = robot.latest_state()? {
        latest = s;
    }
    let end = pose_of(&latest);
    travelled += end.position().distance(last_position);
    reporter.summary(&Summary {
        time_s: seconds(now_ns().saturating_sub(t0)),
        goal_error_m: end.position().distance(goal),
        travelled_m: travelled,
        max_cross_track_m: max_cross_track,
        held_s: seconds(held_total_ns),
        pose: end,
    });
    Ok(Outcome::Reached)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_request_at_a_limit_never_reads_above_it() {
        assert!(f64::from(0.4f32) > 0.4, "the case it is for");
        for v in [0.4, -0.4, 0.1, -0.1, 1.5, 0.6109, -3.0, 0.0, 1e-9] {
            let narrow = toward_zero(v);
            assert!(f64::from(narrow).abs() <= v.abs(), "{v}: {narrow}");
            assert!((f64::from(narrow) - v).abs() < 1e-6, "{v}: {narrow}");
        }
    }

    #[test]
    fn a_robot_without_a_track_is_told_where_to_set_it() {
        let mut d = RobotDescription {
            kinematics: KinematicsKind::DIFFERENTIAL,
            ..RobotDescription::default()
        };
        d.set_kind_name("xbot");
        let hint = pose_hint(&d);
        assert!(hint.contains("gives no track"), "{hint}");
        assert!(
            hint.contains("chassisd --robot xbot --print-config"),
            "{hint}"
        );
        d.geometry.track_m = 0.45;
        assert_eq!(pose_hint(&d), "");
        d.geometry.track_m = f64::NAN;
        d.kinematics = KinematicsKind::ACKERMANN;
        assert_eq!(pose_hint(&d), "", "a steered robot's pose needs no track");
    }
}
