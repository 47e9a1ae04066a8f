//! The follower against simple models of the three robots, stepped by hand (no clock): the
//! limits and resolution of each robot's driver as `chassis-protocols` applies them, a
//! first-order speed lag as the simulated chassis has, TITAN's steering rate, and one control
//! period of feedback delay.

use std::f64::consts::PI;

use proptest::prelude::*;

use super::*;
use crate::kinematics::{
    RobotModel, SCOUT_MINI_ANGULAR_FULL_SCALE_RADPS, TITAN_MAX_STEER_RAD, TITAN_TRACK_M,
    TITAN_WHEELBASE_M,
};
use crate::shapes::{self, Shape};

const PERIOD_S: f64 = 0.02;

/// A robot as the simulated chassis behind its driver moves it.
#[derive(Debug, Clone)]
struct Model {
    kind: RobotModel,
    pose: Pose,
    v: f64,
    w: f64,
    steer: f64,
    target_v: f64,
    target_w: f64,
    target_steer: f64,
}

impl Model {
    fn new(kind: RobotModel, pose: Pose) -> Self {
        Self {
            kind,
            pose,
            v: 0.0,
            w: 0.0,
            steer: 0.0,
            target_v: 0.0,
            target_w: 0.0,
            target_steer: 0.0,
        }
    }

    /// The driver's conversion and limits.
    fn command(&mut self, c: Command) {
        match self.kind {
            RobotModel::ScoutMini => {
                let v = c.linear_mps.clamp(-5.0, 5.0);
                let full = SCOUT_MINI_ANGULAR_FULL_SCALE_RADPS;
                let w = c.angular_radps.clamp(-full, full);
                self.target_v = (v / 0.05).round() * 0.05;
                self.target_w = (w / (full / 100.0)).round() * full / 100.0;
            }
            RobotModel::Xbot => {
                let v = c.linear_mps.clamp(-1.5, 1.5);
                self.target_v = if v.abs() < 0.01 { 0.0 } else { v };
                self.target_w = c.angular_radps.clamp(-PI, PI);
            }
            RobotModel::Titan => {
                let (a, b) = (TITAN_WHEELBASE_M / 2.0, TITAN_TRACK_M / 2.0);
                let (v, w) = (c.linear_mps, c.angular_radps);
                let steer = if w == 0.0 {
                    0.0
                } else if v == 0.0 {
                    w.signum() * TITAN_MAX_STEER_RAD
                } else {
                    let radius = (v / w).abs();
                    let sign = (w / v).signum();
                    if radius <= b {
                        sign * TITAN_MAX_STEER_RAD
                    } else {
                        sign * (a / (radius - b)).atan().min(TITAN_MAX_STEER_RAD)
                    }
                };
                let limit = if steer.abs() > 0.087 { 1.5 } else { 3.0 };
                self.target_v = v.clamp(-limit, limit);
                self.target_steer = steer;
            }
            // The AgileX V2 robots are followed on their real driver (tests/drivers.rs).
            _ => {
                self.target_v = c.linear_mps;
                self.target_w = c.angular_radps;
            }
        }
    }

    fn lag(&self) -> f64 {
        match self.kind {
            RobotModel::Xbot => 0.2,
            _ => 0.3,
        }
    }

    fn step(&mut self, dt: f64) {
        let sub = 0.005;
        let mut left = dt;
        while left > 1e-12 {
            let h = left.min(sub);
            left -= h;
            let decay = (-h / self.lag()).exp();
            let v0 = self.v;
            self.v = self.target_v + (self.v - self.target_v) * decay;
            let w0 = self.w;
            match self.kind {
                RobotModel::Titan => {
                    let max_move = 1.0 * h;
                    self.steer += (self.target_steer - self.steer).clamp(-max_move, max_move);
                    self.w = if self.steer == 0.0 {
                        0.0
                    } else {
                        let radius = (TITAN_WHEELBASE_M / 2.0) / self.steer.abs().tan()
                            + TITAN_TRACK_M / 2.0;
                        self.steer.signum() * self.v / radius
                    };
                }
                _ => self.w = self.target_w + (self.w - self.target_w) * decay,
            }
            let v = 0.5 * (v0 + self.v);
            let w = 0.5 * (w0 + self.w);
            let mid = self.pose.yaw + 0.5 * w * h;
            self.pose.x += v * mid.cos() * h;
            self.pose.y += v * mid.sin() * h;
            self.pose.yaw = wrap_angle(self.pose.yaw + w * h);
        }
    }

    fn measured(&self) -> Measured {
        Measured {
            pose: self.pose,
            linear_mps: self.v,
            angular_radps: self.w,
        }
    }
}

#[derive(Debug)]
struct Run {
    goal_error_m: f64,
    time_s: f64,
    max_cross_track_m: f64,
    max_curvature: f64,
    turned_on_the_spot: bool,
    steps: Vec<Step>,
}

/// Drives `path` (in the start pose's frame) with `model` from `start` until done.
fn drive(kind: RobotModel, local: &Path, start: Pose, limit_s: f64) -> Result<Run, TrackError> {
    let kin = Kinematics::of(kind);
    let config = TrackerConfig::new(kin, kin.default_speed_mps);
    let mut tracker = Tracker::new(local.transformed(start), config);
    let mut robot = Model::new(kind, start);
    let mut seen = robot.measured();
    let mut run = Run {
        goal_error_m: f64::NAN,
        time_s: 0.0,
        max_cross_track_m: 0.0,
        max_curvature: 0.0,
        turned_on_the_spot: false,
        steps: Vec::new(),
    };
    let mut t = 0.0;
    while t < limit_s {
        let step = tracker.update(&seen, PERIOD_S)?;
        let c = step.command;
        assert!(c.linear_mps.is_finite() && c.angular_radps.is_finite());
        if c.linear_mps.abs() > 1e-9 {
            run.max_curvature = run
                .max_curvature
                .max((c.angular_radps / c.linear_mps).abs());
        } else if c.angular_radps != 0.0 {
            run.turned_on_the_spot = true;
        }
        if step.activity == Activity::Driving {
            run.max_cross_track_m = run.max_cross_track_m.max(step.cross_track_m.abs());
        }
        run.steps.push(step);
        if step.activity == Activity::Done {
            break;
        }
        // The state the planner reads lags the chassis by one period.
        seen = robot.measured();
        robot.command(c);
        robot.step(PERIOD_S);
        t += PERIOD_S;
    }
    run.time_s = t;
    run.goal_error_m = robot.pose.position().distance(tracker.goal());
    Ok(run)
}

fn shape_for(kind: RobotModel, shape: Shape) -> Path {
    let kin = Kinematics::of(kind);
    shapes::build(shape, shape.default_size_m(&kin), 1, &kin).unwrap()
}

const ROBOTS: [RobotModel; 3] = [RobotModel::Titan, RobotModel::ScoutMini, RobotModel::Xbot];

#[test]
fn every_robot_drives_the_square_to_within_5_cm_of_its_goal() {
    for kind in ROBOTS {
        let path = shape_for(kind, Shape::Square);
        let start = Pose::new(3.0, -1.0, 0.6);
        let run = drive(kind, &path, start, 120.0).unwrap();
        eprintln!(
            "{kind:?} square: goal error {:.3} m after {:.1} s, max cross-track {:.3} m",
            run.goal_error_m, run.time_s, run.max_cross_track_m
        );
        assert_eq!(run.steps.last().map(|s| s.activity), Some(Activity::Done));
        assert!(run.goal_error_m < 0.05, "{kind:?}: {}", run.goal_error_m);
        assert!(
            run.max_cross_track_m < 0.15,
            "{kind:?}: {}",
            run.max_cross_track_m
        );
    }
}

#[test]
fn every_robot_drives_the_figure_eight_to_within_5_cm_of_its_goal() {
    for kind in ROBOTS {
        let path = shape_for(kind, Shape::FigureEight);
        let run = drive(kind, &path, Pose::new(-2.0, 0.5, -2.0), 180.0).unwrap();
        eprintln!(
            "{kind:?} figure-eight: goal error {:.3} m after {:.1} s, max cross-track {:.3} m",
            run.goal_error_m, run.time_s, run.max_cross_track_m
        );
        assert_eq!(run.steps.last().map(|s| s.activity), Some(Activity::Done));
        assert!(run.goal_error_m < 0.05, "{kind:?}: {}", run.goal_error_m);
        assert!(
            run.max_cross_track_m < 0.15,
            "{kind:?}: {}",
            run.max_cross_track_m
        );
    }
}

#[test]
fn a_line_ends_within_5_cm_for_every_robot() {
    for kind in ROBOTS {
        let path = shapes::build(Shape::Line, 2.0, 1, &Kinematics::of(kind)).unwrap();
        let run = drive(kind, &path, Pose::default(), 60.0).unwrap();
        assert!(run.goal_error_m < 0.05, "{kind:?}: {}", run.goal_error_m);
        assert!(run.time_s < 8.0, "{kind:?}: {} s", run.time_s);
    }
}

#[test]
fn titan_curvature_never_exceeds_its_limit_and_it_never_turns_on_the_spot() {
    let kin = Kinematics::of(RobotModel::Titan);
    let limit = 1.0 / kin.min_turn_radius_m();
    for shape in [Shape::Square, Shape::FigureEight] {
        let run = drive(
            RobotModel::Titan,
            &shape_for(RobotModel::Titan, shape),
            Pose::default(),
            120.0,
        )
        .unwrap();
        assert!(
            run.max_curvature <= limit + 1e-9,
            "{shape:?}: {}",
            run.max_curvature
        );
        assert!(!run.turned_on_the_spot, "{shape:?}");
    }
    // A waypoint behind the robot: the tightest turn toward it, never more.
    let behind = Path::new(vec![
        Point::new(0.0, 0.0),
        Point::new(-1.0, 4.0),
        Point::new(-6.0, 4.0),
    ])
    .unwrap();
    let run = drive(RobotModel::Titan, &behind, Pose::default(), 60.0).unwrap();
    assert!(run.max_curvature <= limit + 1e-9, "{}", run.max_curvature);
    assert!(!run.turned_on_the_spot);
}

#[test]
fn a_differential_robot_turns_on_the_spot_toward_the_first_waypoint_then_drives() {
    for kind in [RobotModel::ScoutMini, RobotModel::Xbot] {
        let path = Path::new(vec![Point::new(0.0, 0.0), Point::new(0.0, 1.5)]).unwrap();
        let run = drive(kind, &path, Pose::default(), 60.0).unwrap();
        let first = run.steps[0];
        assert_eq!(first.activity, Activity::Turning);
        assert_eq!(first.command.linear_mps, 0.0);
        assert!(first.command.angular_radps > 0.0, "turns left");
        assert!(run.steps.iter().any(|s| s.activity == Activity::Driving));
        assert!(run.goal_error_m < 0.05, "{kind:?}: {}", run.goal_error_m);
    }
}

#[test]
fn square_corners_are_stops_for_differential_robots_but_not_for_titan() {
    let scout = Tracker::new(
        shape_for(RobotModel::ScoutMini, Shape::Square),
        TrackerConfig::new(Kinematics::of(RobotModel::ScoutMini), 0.8),
    );
    assert_eq!(scout.stops(), &[2.0, 4.0, 6.0, 8.0]);
    let titan = Tracker::new(
        shape_for(RobotModel::Titan, Shape::Square),
        TrackerConfig::new(Kinematics::of(RobotModel::Titan), 1.0),
    );
    assert_eq!(titan.stops().len(), 1);
    // The figure-eight's gentle samples are no corners.
    let eight = Tracker::new(
        shape_for(RobotModel::Xbot, Shape::FigureEight),
        TrackerConfig::new(Kinematics::of(RobotModel::Xbot), 0.8),
    );
    assert_eq!(eight.stops().len(), 1);
}

#[test]
fn a_sideways_miss_is_corrected_by_a_robot_that_turns_on_the_spot_but_fails_for_titan() {
    let line = Path::new(vec![Point::new(0.0, 0.0), Point::new(1.0, 0.0)]).unwrap();
    let at = |y: f64| Measured {
        pose: Pose::new(1.0, y, 0.0),
        ..Measured::default()
    };
    let mut xbot = Tracker::new(
        line.clone(),
        TrackerConfig::new(Kinematics::of(RobotModel::Xbot), 0.8),
    );
    let step = xbot.update(&at(0.1), PERIOD_S).unwrap();
    assert_eq!(step.activity, Activity::Correcting);
    assert_eq!(step.command.linear_mps, 0.0);
    assert!(
        step.command.angular_radps < 0.0,
        "turns right, toward the goal"
    );
    let mut titan = Tracker::new(
        line,
        TrackerConfig::new(Kinematics::of(RobotModel::Titan), 1.0),
    );
    let err = titan.update(&at(0.1), PERIOD_S).unwrap_err();
    assert!(matches!(err, TrackError::SidewaysMiss { .. }), "{err}");
    // Within the tolerance it is simply done.
    let mut ok = Tracker::new(
        Path::new(vec![Point::new(0.0, 0.0), Point::new(1.0, 0.0)]).unwrap(),
        TrackerConfig::new(Kinematics::of(RobotModel::Titan), 1.0),
    );
    assert_eq!(
        ok.update(&at(0.03), PERIOD_S).unwrap().activity,
        Activity::Done
    );
}

#[test]
fn a_robot_pushed_off_its_path_recovers_and_still_arrives() {
    for kind in ROBOTS {
        let kin = Kinematics::of(kind);
        let path = shapes::build(Shape::Line, 6.0, 1, &kin).unwrap();
        let mut tracker = Tracker::new(path, TrackerConfig::new(kin, kin.default_speed_mps));
        let mut robot = Model::new(kind, Pose::default());
        let mut done = false;
        for i in 0..4000 {
            if i == 150 {
                // Someone else drove it: half a metre aside, turned away.
                robot.pose = Pose::new(robot.pose.x, 0.5, 0.8);
            }
            let step = tracker.update(&robot.measured(), PERIOD_S).unwrap();
            if step.activity == Activity::Done {
                done = true;
                break;
            }
            robot.command(step.command);
            robot.step(PERIOD_S);
        }
        assert!(done, "{kind:?}");
        assert!(
            robot.pose.position().distance(Point::new(6.0, 0.0)) < 0.05,
            "{kind:?}"
        );
    }
}

#[test]
fn driving_a_loop_forever_counts_laps_and_never_ends() {
    let kin = Kinematics::of(RobotModel::Xbot);
    let one = shapes::build(Shape::Square, 2.0, 1, &kin).unwrap();
    let three = shapes::build(Shape::Square, 2.0, 3, &kin).unwrap();
    let mut config = TrackerConfig::new(kin, 0.8);
    config.period_m = Some(one.length_m());
    let mut tracker = Tracker::new(three, config);
    let mut robot = Model::new(RobotModel::Xbot, Pose::default());
    let mut laps = 0;
    for _ in 0..(200.0 / PERIOD_S) as usize {
        let step = tracker.update(&robot.measured(), PERIOD_S).unwrap();
        assert_ne!(step.activity, Activity::Done);
        assert_eq!(step.remaining_m, None);
        laps = step.laps;
        robot.command(step.command);
        robot.step(PERIOD_S);
    }
    assert!(laps >= 3, "{laps} laps");
    // A square has four corners a loop (the start is one when it repeats).
    assert_eq!(tracker.corner_stops(), 4);
    // Still on the square.
    let p = robot.pose.position();
    let off = (p.x.min(2.0 - p.x).abs()).min(p.y.min(2.0 - p.y).abs());
    assert!(off < 0.1, "{p:?}");
}

#[test]
fn holding_restarts_the_speed_ramp_from_what_the_robot_does() {
    let kin = Kinematics::of(RobotModel::Xbot);
    let path = shapes::build(Shape::Line, 5.0, 1, &kin).unwrap();
    let mut tracker = Tracker::new(path, TrackerConfig::new(kin, 1.0));
    let still = Measured::default();
    for _ in 0..200 {
        let _ = tracker.update(&still, PERIOD_S).unwrap();
        tracker.hold(&still);
    }
    let step = tracker.update(&still, PERIOD_S).unwrap();
    assert!(step.command.linear_mps <= 0.8 * PERIOD_S + kin.min_linear_mps + 1e-9);
}

#[test]
fn a_non_finite_measurement_stops_the_robot_and_keeps_the_progress() {
    let kin = Kinematics::of(RobotModel::ScoutMini);
    let path = shapes::build(Shape::Line, 3.0, 1, &kin).unwrap();
    let mut tracker = Tracker::new(path, TrackerConfig::new(kin, 0.8));
    let at = |x: f64| Measured {
        pose: Pose::new(x, 0.0, 0.0),
        linear_mps: 0.5,
        angular_radps: 0.0,
    };
    let before = tracker.update(&at(1.0), PERIOD_S).unwrap();
    let nan = tracker.update(&at(f64::NAN), PERIOD_S).unwrap();
    assert_eq!(nan.command, Command::STOP);
    assert_eq!(nan.progress_m, before.progress_m);
    let after = tracker.update(&at(1.01), PERIOD_S).unwrap();
    assert!(after.command.linear_mps > 0.0);
}

fn arb_path() -> impl Strategy<Value = Vec<Point>> {
    prop::collection::vec((-20.0f64..20.0, -20.0f64..20.0), 2..12)
        .prop_map(|v| v.into_iter().map(|(x, y)| Point::new(x, y)).collect())
}

proptest! {
    #[test]
    fn random_paths_never_produce_nan_commands(
        points in arb_path(),
        robot in 0usize..3,
        x in -30.0f64..30.0,
        y in -30.0f64..30.0,
        yaw in -4.0f64..4.0,
        v in -2.0f64..2.0,
        w in -3.0f64..3.0,
        dt in 0.0f64..0.2,
    ) {
        let Ok(path) = Path::new(points) else { return Ok(()) };
        let kind = ROBOTS[robot];
        let kin = Kinematics::of(kind);
        let mut tracker = Tracker::new(path, TrackerConfig::new(kin, kin.default_speed_mps));
        let mut m = Measured { pose: Pose::new(x, y, yaw), linear_mps: v, angular_radps: w };
        for i in 0..40 {
            match tracker.update(&m, dt) {
                Ok(step) => {
                    prop_assert!(step.command.linear_mps.is_finite());
                    prop_assert!(step.command.angular_radps.is_finite());
                    prop_assert!(step.cross_track_m.is_finite());
                    if kind == RobotModel::Titan && step.command.linear_mps != 0.0 {
                        let k = (step.command.angular_radps / step.command.linear_mps).abs();
                        prop_assert!(k <= kin.max_curvature() + 1e-9);
                    }
                    if kind == RobotModel::Titan {
                        prop_assert!(step.command.linear_mps != 0.0 || step.command.angular_radps == 0.0);
                    }
                    // Move a little as commanded.
                    m.pose.x += step.command.linear_mps * 0.02 * m.pose.yaw.cos();
                    m.pose.y += step.command.linear_mps * 0.02 * m.pose.yaw.sin();
                    m.pose.yaw = wrap_angle(m.pose.yaw + step.command.angular_radps * 0.02);
                    m.linear_mps = step.command.linear_mps;
                    m.angular_radps = step.command.angular_radps;
                    if i % 7 == 0 { m.linear_mps = 0.0; m.angular_radps = 0.0; }
                }
                Err(_) => break,
            }
        }
    }
}

/// Prints a run step by step — a tuning aid, not a check:
/// `ROBOT=titan SHAPE=eight LMIN=0.4 LGAIN=0.4 SPEED=1 cargo test -p chassis-planner trace --
/// --ignored --nocapture`.
#[test]
#[ignore]
fn trace() {
    let kind = match std::env::var("ROBOT").as_deref() {
        Ok("titan") => RobotModel::Titan,
        Ok("xbot") => RobotModel::Xbot,
        _ => RobotModel::ScoutMini,
    };
    let shape = match std::env::var("SHAPE").as_deref() {
        Ok("eight") => Shape::FigureEight,
        Ok("line") => Shape::Line,
        _ => Shape::Square,
    };
    let path = shape_for(kind, shape);
    let kin = Kinematics::of(kind);
    let mut config = TrackerConfig::new(kin, kin.default_speed_mps);
    let env = |k: &str, d: f64| {
        std::env::var(k)
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(d)
    };
    config.lookahead_min_m = env("LMIN", config.lookahead_min_m);
    config.lookahead_gain_s = env("LGAIN", config.lookahead_gain_s);
    config.cruise_mps = env("SPEED", config.cruise_mps);
    let every = env("EVERY", 5.0) as usize;
    let mut tracker = Tracker::new(path, config);
    let mut robot = Model::new(kind, Pose::default());
    let mut seen = robot.measured();
    let mut max_xt = 0.0f64;
    for i in 0..6000 {
        let step = tracker.update(&seen, PERIOD_S);
        let Ok(step) = step else {
            eprintln!("{step:?}");
            break;
        };
        max_xt = max_xt.max(step.cross_track_m.abs());
        if i % every == 0 || step.activity != Activity::Driving {
            eprintln!(
                "{:6.2} {:10} s {:6.3} xt {:+.3} pose ({:+.3},{:+.3},{:+.3}) v {:.3} w {:+.3} cmd {:.3} {:+.3}",
                i as f64 * PERIOD_S,
                step.activity.name(),
                step.progress_m,
                step.cross_track_m,
                robot.pose.x,
                robot.pose.y,
                robot.pose.yaw,
                robot.v,
                robot.w,
                step.command.linear_mps,
                step.command.angular_radps
            );
        }
        if step.activity == Activity::Done {
            eprintln!(
                "done after {:.2} s, goal error {:.3}, max cross-track {max_xt:.3}",
                i as f64 * PERIOD_S,
                robot.pose.position().distance(tracker.goal())
            );
            break;
        }
        seen = robot.measured();
        robot.command(step.command);
        robot.step(PERIOD_S);
    }
}
