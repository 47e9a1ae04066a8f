//! The follower against a simple model of every robot of the registry, stepped by hand (no
//! clock). Each robot is what chassisd describes with its registry defaults
//! (`describe(&kind.entry().defaults())`): its speed and yaw-rate limits as a driver applies
//! them, its smallest turning radius and a steering that takes time to turn for a robot that
//! steers, a first-order speed lag as the simulated chassis has, and one control period of
//! feedback delay. The robots' real drivers and simulated chassis are in `tests/drivers.rs`.

use chassis_client::{Kinematics as KinematicsKind, RobotDescription};
use chassis_protocols::description::describe;
use chassis_protocols::xbot::XbotProfile;
use chassis_protocols::{Profile, RobotKind};
use proptest::prelude::*;

use super::*;
use crate::shapes::{self, Shape};

const PERIOD_S: f64 = 0.02;
/// The simulated chassis' speed response (its slowest).
const LAG_S: f64 = 0.3;
/// A steered robot's steering goes from straight to full lock in this long.
const STEER_TIME_S: f64 = 0.4;

/// A robot as chassisd describes it with its registry defaults.
fn description(kind: RobotKind) -> RobotDescription {
    describe(&kind.entry().defaults())
}

fn kin(kind: RobotKind) -> Kinematics {
    Kinematics::from_description(&description(kind)).unwrap()
}

/// True where the description says the wheels steer (no turn on the spot as the planner drives
/// it).
fn steers(kind: RobotKind) -> bool {
    !kin(kind).turns_on_the_spot()
}

/// A robot as its description bounds it.
#[derive(Debug, Clone)]
struct Model {
    forward_mps: f64,
    reverse_mps: f64,
    angular_radps: f64,
    lateral_mps: f64,
    /// Largest curvature (robots that steer), 1/m; `None`: turns on the spot.
    max_curvature: Option<f64>,
    pose: Pose,
    v: f64,
    w: f64,
    vy: f64,
    curvature: f64,
    target_v: f64,
    target_w: f64,
    target_vy: f64,
    target_curvature: f64,
}

impl Model {
    fn new(d: &RobotDescription, pose: Pose) -> Self {
        let limits = d.effective_limits();
        let or = |value: f64, otherwise: f64| if value.is_nan() { otherwise } else { value };
        let max_curvature = match d.kinematics {
            KinematicsKind::ACKERMANN
            | KinematicsKind::DUAL_ACKERMANN
            | KinematicsKind::FOUR_WHEEL_STEER => Some(1.0 / d.geometry.min_turn_radius_m),
            _ => None,
        };
        Self {
            forward_mps: limits.forward_mps,
            reverse_mps: or(limits.reverse_mps, limits.forward_mps),
            angular_radps: or(limits.angular_radps, f64::INFINITY),
            lateral_mps: or(limits.lateral_mps, 0.0),
            max_curvature,
            pose,
            v: 0.0,
            w: 0.0,
            vy: 0.0,
            curvature: 0.0,
            target_v: 0.0,
            target_w: 0.0,
            target_vy: 0.0,
            target_curvature: 0.0,
        }
    }

    fn of(kind: RobotKind, pose: Pose) -> Self {
        Self::new(&description(kind), pose)
    }

    /// What a driver makes of a twist: its limits, and a curvature for a robot that steers (no
    /// turn while standing).
    fn command(&mut self, c: Command) {
        self.target_v = c.linear_mps.clamp(-self.reverse_mps, self.forward_mps);
        self.target_vy = c.lateral_mps.clamp(-self.lateral_mps, self.lateral_mps);
        match self.max_curvature {
            Some(max) => {
                if c.linear_mps != 0.0 {
                    self.target_curvature = (c.angular_radps / c.linear_mps).clamp(-max, max);
                }
            }
            None => {
                self.target_w = c
                    .angular_radps
                    .clamp(-self.angular_radps, self.angular_radps)
            }
        }
    }

    fn step(&mut self, dt: f64) {
        let sub = 0.005;
        let mut left = dt;
        while left > 1e-12 {
            let h = left.min(sub);
            left -= h;
            let decay = (-h / LAG_S).exp();
            let (v0, w0, vy0) = (self.v, self.w, self.vy);
            self.v = self.target_v + (self.v - self.target_v) * decay;
            self.vy = self.target_vy + (self.vy - self.target_vy) * decay;
            match self.max_curvature {
                Some(max) => {
                    let rate = max / STEER_TIME_S * h;
                    self.curvature += (self.target_curvature - self.curvature).clamp(-rate, rate);
                    self.w = self.curvature * self.v;
                }
                None => self.w = self.target_w + (self.w - self.target_w) * decay,
            }
            let v = 0.5 * (v0 + self.v);
            let vy = 0.5 * (vy0 + self.vy);
            let w = 0.5 * (w0 + self.w);
            let mid = self.pose.yaw + 0.5 * w * h;
            self.pose.x += (v * mid.cos() - vy * mid.sin()) * h;
            self.pose.y += (v * mid.sin() + vy * mid.cos()) * h;
            self.pose.yaw = wrap_angle(self.pose.yaw + w * h);
        }
    }

    fn measured(&self) -> Measured {
        Measured {
            pose: self.pose,
            linear_mps: self.v,
            angular_radps: self.w,
            lateral_mps: self.vy,
        }
    }
}

#[derive(Debug)]
struct Run {
    goal_error_m: f64,
    time_s: f64,
    max_cross_track_m: f64,
    max_curvature: f64,
    max_linear_mps: f64,
    turned_on_the_spot: bool,
    steps: Vec<Step>,
}

/// Drives `path` (in the start pose's frame) with `robot` from its pose until done, with
/// `kin`'s limits.
fn drive_model(
    kin: Kinematics,
    mut robot: Model,
    local: &Path,
    limit_s: f64,
) -> Result<Run, TrackError> {
    let start = robot.pose;
    let config = TrackerConfig::new(kin, kin.default_speed_mps);
    let mut tracker = Tracker::new(local.transformed(start), config);
    let mut seen = robot.measured();
    let mut run = Run {
        goal_error_m: f64::NAN,
        time_s: 0.0,
        max_cross_track_m: 0.0,
        max_curvature: 0.0,
        max_linear_mps: 0.0,
        turned_on_the_spot: false,
        steps: Vec::new(),
    };
    let mut t = 0.0;
    while t < limit_s {
        let step = tracker.update(&seen, PERIOD_S)?;
        let c = step.command;
        assert!(c.linear_mps.is_finite() && c.angular_radps.is_finite());
        run.max_linear_mps = run.max_linear_mps.max(c.linear_mps.abs());
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

fn drive(kind: RobotKind, local: &Path, start: Pose, limit_s: f64) -> Result<Run, TrackError> {
    drive_model(kin(kind), Model::of(kind, start), local, limit_s)
}

fn shape_for(kind: RobotKind, shape: Shape) -> Path {
    let kin = kin(kind);
    shapes::build(shape, shape.default_size_m(&kin), 1, &kin).unwrap()
}

/// Every robot drives `shape` from `start` within `limit_s`, ends within 5 cm of its goal and
/// never strays 15 cm from the path.
fn every_robot_drives_to_within_5_cm_of_its_goal(shape: Shape, start: Pose, limit_s: f64) {
    for kind in RobotKind::ALL {
        let path = shape_for(kind, shape);
        let run = drive(kind, &path, start, limit_s).unwrap();
        eprintln!(
            "{kind} {shape:?}: goal error {:.3} m after {:.1} s, max cross-track {:.3} m",
            run.goal_error_m, run.time_s, run.max_cross_track_m
        );
        assert_eq!(run.steps.last().map(|s| s.activity), Some(Activity::Done));
        assert!(run.goal_error_m < 0.05, "{kind}: {}", run.goal_error_m);
        assert!(
            run.max_cross_track_m < 0.15,
            "{kind}: {}",
            run.max_cross_track_m
        );
    }
}

#[test]
fn every_robot_drives_the_square_to_within_5_cm_of_its_goal() {
    every_robot_drives_to_within_5_cm_of_its_goal(Shape::Square, Pose::new(3.0, -1.0, 0.6), 120.0);
}

#[test]
fn every_robot_drives_the_figure_eight_to_within_5_cm_of_its_goal() {
    every_robot_drives_to_within_5_cm_of_its_goal(
        Shape::FigureEight,
        Pose::new(-2.0, 0.5, -2.0),
        180.0,
    );
}

#[test]
fn a_line_ends_within_5_cm_for_every_robot() {
    for kind in RobotKind::ALL {
        let path = shapes::build(Shape::Line, 2.0, 1, &kin(kind)).unwrap();
        let run = drive(kind, &path, Pose::default(), 60.0).unwrap();
        assert!(run.goal_error_m < 0.05, "{kind}: {}", run.goal_error_m);
        assert!(run.time_s < 8.0, "{kind}: {} s", run.time_s);
    }
}

#[test]
fn a_steered_robot_never_asks_for_more_curvature_than_it_turns_nor_turns_on_the_spot() {
    let steered: Vec<RobotKind> = RobotKind::ALL.into_iter().filter(|&k| steers(k)).collect();
    assert!(steered.contains(&RobotKind::Titan) && steered.contains(&RobotKind::Hunter));
    for kind in steered {
        let kin = kin(kind);
        let limit = kin.max_curvature();
        // What the robot turns, from its description: the follower keeps clear of it.
        let reach = 1.0 / description(kind).geometry.min_turn_radius_m;
        assert!(limit < reach, "{kind}: asks for {limit}, turns {reach}");
        for shape in [Shape::Square, Shape::FigureEight] {
            let run = drive(kind, &shape_for(kind, shape), Pose::default(), 120.0).unwrap();
            assert!(
                run.max_curvature <= limit + 1e-9,
                "{kind} {shape:?}: {}",
                run.max_curvature
            );
            assert!(!run.turned_on_the_spot, "{kind} {shape:?}");
        }
        // A waypoint behind the robot: the tightest turn toward it, never more.
        let behind = Path::new(vec![
            Point::new(0.0, 0.0),
            Point::new(-1.0, 4.0),
            Point::new(-6.0, 4.0),
        ])
        .unwrap();
        let run = drive(kind, &behind, Pose::default(), 60.0).unwrap();
        assert!(
            run.max_curvature <= limit + 1e-9,
            "{kind}: {}",
            run.max_curvature
        );
        assert!(!run.turned_on_the_spot, "{kind}");
    }
}

#[test]
fn a_robot_that_turns_on_the_spot_turns_toward_the_first_waypoint_then_drives() {
    for kind in RobotKind::ALL.into_iter().filter(|&k| !steers(k)) {
        let path = Path::new(vec![Point::new(0.0, 0.0), Point::new(0.0, 1.5)]).unwrap();
        let run = drive(kind, &path, Pose::default(), 60.0).unwrap();
        let first = run.steps[0];
        assert_eq!(first.activity, Activity::Turning, "{kind}");
        assert_eq!(first.command.linear_mps, 0.0);
        assert!(first.command.angular_radps > 0.0, "{kind} turns left");
        assert!(run.steps.iter().any(|s| s.activity == Activity::Driving));
        assert!(run.goal_error_m < 0.05, "{kind}: {}", run.goal_error_m);
    }
}

#[test]
fn square_corners_are_stops_for_robots_that_turn_on_the_spot_but_not_for_those_that_steer() {
    for kind in RobotKind::ALL {
        let kin = kin(kind);
        let tracker = Tracker::new(shape_for(kind, Shape::Square), TrackerConfig::new(kin, 0.8));
        if kin.turns_on_the_spot() {
            assert_eq!(tracker.stops(), &[2.0, 4.0, 6.0, 8.0], "{kind}");
        } else {
            assert_eq!(tracker.stops().len(), 1, "{kind}");
        }
        // The figure-eight's gentle samples are no corners.
        let eight = Tracker::new(
            shape_for(kind, Shape::FigureEight),
            TrackerConfig::new(kin, 0.8),
        );
        assert_eq!(eight.stops().len(), 1, "{kind}");
    }
}

#[test]
fn a_sideways_miss_is_corrected_by_a_robot_that_turns_on_the_spot_but_fails_for_one_that_steers() {
    let line = Path::new(vec![Point::new(0.0, 0.0), Point::new(1.0, 0.0)]).unwrap();
    let at = |y: f64| Measured {
        pose: Pose::new(1.0, y, 0.0),
        ..Measured::default()
    };
    for kind in RobotKind::ALL {
        let mut tracker = Tracker::new(line.clone(), TrackerConfig::new(kin(kind), 0.8));
        if steers(kind) {
            let err = tracker.update(&at(0.1), PERIOD_S).unwrap_err();
            assert!(
                matches!(err, TrackError::SidewaysMiss { .. }),
                "{kind}: {err}"
            );
        } else {
            let step = tracker.update(&at(0.1), PERIOD_S).unwrap();
            assert_eq!(step.activity, Activity::Correcting, "{kind}");
            assert_eq!(step.command.linear_mps, 0.0);
            assert!(
                step.command.angular_radps < 0.0,
                "{kind} turns right, toward the goal"
            );
        }
        // Within the tolerance it is simply done.
        let mut ok = Tracker::new(line.clone(), TrackerConfig::new(kin(kind), 0.8));
        assert_eq!(
            ok.update(&at(0.03), PERIOD_S).unwrap().activity,
            Activity::Done,
            "{kind}"
        );
    }
}

#[test]
fn a_robot_that_moves_sideways_corrects_a_sideways_miss_without_turning() {
    let omni = describe(&Profile::from(XbotProfile {
        omni: true,
        ..XbotProfile::default()
    }));
    let k = Kinematics::from_description(&omni).unwrap();
    assert!(k.lateral_mps > 0.0, "{k:?}");
    let line = Path::new(vec![Point::new(0.0, 0.0), Point::new(1.0, 0.0)]).unwrap();
    let mut robot = Model::new(&omni, Pose::new(1.0, 0.12, 0.0));
    let mut tracker = Tracker::new(line, TrackerConfig::new(k, 0.8));
    let mut corrected = false;
    for _ in 0..1000 {
        let step = tracker.update(&robot.measured(), PERIOD_S).unwrap();
        assert_eq!(step.command.angular_radps, 0.0, "no turn: {step:?}");
        corrected |= step.command.lateral_mps < 0.0;
        if step.activity == Activity::Done {
            break;
        }
        robot.command(step.command);
        robot.step(PERIOD_S);
    }
    assert!(corrected, "it moved sideways toward the goal");
    assert!(robot.pose.position().distance(Point::new(1.0, 0.0)) < 0.05);
    assert!(robot.pose.yaw.abs() < 1e-9);
}

#[test]
fn a_robot_pushed_off_its_path_recovers_and_still_arrives() {
    for kind in RobotKind::ALL {
        let kin = kin(kind);
        let path = shapes::build(Shape::Line, 6.0, 1, &kin).unwrap();
        let mut tracker = Tracker::new(path, TrackerConfig::new(kin, kin.default_speed_mps));
        let mut robot = Model::of(kind, Pose::default());
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
        assert!(done, "{kind}");
        assert!(
            robot.pose.position().distance(Point::new(6.0, 0.0)) < 0.05,
            "{kind}: {:?}",
            robot.pose
        );
    }
}

#[test]
fn a_configured_speed_limit_is_never_exceeded() {
    for kind in RobotKind::ALL {
        // chassisd's `[profile] max_linear_mps = 0.4` as its description carries it.
        let mut d = description(kind);
        d.robot_limits.forward_mps = 0.4;
        let k = Kinematics::from_description(&d).unwrap();
        let path = shapes::build(Shape::Square, Shape::Square.default_size_m(&k), 1, &k).unwrap();
        let run = drive_model(k, Model::new(&d, Pose::default()), &path, 180.0).unwrap();
        assert!(
            run.max_linear_mps <= 0.4 + 1e-12,
            "{kind}: {}",
            run.max_linear_mps
        );
        assert!(
            run.max_linear_mps > 0.3,
            "{kind} drove: {}",
            run.max_linear_mps
        );
        assert!(run.goal_error_m < 0.05, "{kind}: {}", run.goal_error_m);
    }
}

#[test]
fn new_limits_under_way_slow_the_robot_at_once() {
    let fast = kin(RobotKind::Tracer);
    let path = shapes::build(Shape::Line, 20.0, 1, &fast).unwrap();
    let mut tracker = Tracker::new(path, TrackerConfig::new(fast, 1.5));
    let mut robot = Model::of(RobotKind::Tracer, Pose::default());
    for _ in 0..200 {
        let step = tracker.update(&robot.measured(), PERIOD_S).unwrap();
        robot.command(step.command);
        robot.step(PERIOD_S);
    }
    assert!(robot.v > 1.2, "{}", robot.v);
    let mut d = description(RobotKind::Tracer);
    d.configured_limits.forward_mps = 0.5;
    let slow = fast
        .updated_by(&Kinematics::from_description(&d).unwrap())
        .unwrap();
    tracker.set_kinematics(slow);
    let step = tracker.update(&robot.measured(), PERIOD_S).unwrap();
    assert!(step.command.linear_mps <= 0.5, "{step:?}");
    // A robot that now turns wider than the path was built for cannot follow it.
    let titan = kin(RobotKind::Titan);
    assert!(titan.updated_by(&titan).is_some());
    assert!(titan.updated_by(&fast).is_none());
    assert!(fast.updated_by(&titan).is_none());
    let wider = titan.with_min_turn_radius(titan.min_turn_radius_m() * 2.0);
    assert!(titan.updated_by(&wider).is_none());
    assert!(wider.updated_by(&titan).is_some());
}

#[test]
fn driving_a_loop_forever_counts_laps_and_never_ends() {
    let kin = kin(RobotKind::Xbot);
    let one = shapes::build(Shape::Square, 2.0, 1, &kin).unwrap();
    let three = shapes::build(Shape::Square, 2.0, 3, &kin).unwrap();
    let mut config = TrackerConfig::new(kin, 0.8);
    config.period_m = Some(one.length_m());
    let mut tracker = Tracker::new(three, config);
    let mut robot = Model::of(RobotKind::Xbot, Pose::default());
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
    let kin = kin(RobotKind::Xbot);
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
    let kin = kin(RobotKind::ScoutMini);
    let path = shapes::build(Shape::Line, 3.0, 1, &kin).unwrap();
    let mut tracker = Tracker::new(path, TrackerConfig::new(kin, 0.8));
    let at = |x: f64| Measured {
        pose: Pose::new(x, 0.0, 0.0),
        linear_mps: 0.5,
        ..Measured::default()
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
    fn random_paths_never_produce_nan_commands_nor_exceed_the_limits(
        points in arb_path(),
        robot in 0usize..RobotKind::ALL.len(),
        x in -30.0f64..30.0,
        y in -30.0f64..30.0,
        yaw in -4.0f64..4.0,
        v in -2.0f64..2.0,
        w in -3.0f64..3.0,
        dt in 0.0f64..0.2,
    ) {
        let Ok(path) = Path::new(points) else { return Ok(()) };
        let kind = RobotKind::ALL[robot];
        let kin = kin(kind);
        let mut tracker = Tracker::new(path, TrackerConfig::new(kin, kin.default_speed_mps));
        let mut m = Measured {
            pose: Pose::new(x, y, yaw),
            linear_mps: v,
            angular_radps: w,
            lateral_mps: 0.0,
        };
        for i in 0..40 {
            match tracker.update(&m, dt) {
                Ok(step) => {
                    let c = step.command;
                    prop_assert!(c.linear_mps.is_finite());
                    prop_assert!(c.angular_radps.is_finite());
                    prop_assert!(step.cross_track_m.is_finite());
                    prop_assert!(c.linear_mps <= kin.max_linear_mps + 1e-12);
                    prop_assert!(-c.linear_mps <= kin.max_reverse_mps + 1e-12);
                    prop_assert!(c.angular_radps.abs() <= kin.max_angular_radps() + 1e-9);
                    if !kin.turns_on_the_spot() {
                        if c.linear_mps != 0.0 {
                            let k = (c.angular_radps / c.linear_mps).abs();
                            prop_assert!(k <= kin.max_curvature() + 1e-9);
                        }
                        prop_assert!(c.linear_mps != 0.0 || c.angular_radps == 0.0);
                    }
                    // Move a little as commanded.
                    m.pose.x += c.linear_mps * 0.02 * m.pose.yaw.cos();
                    m.pose.y += c.linear_mps * 0.02 * m.pose.yaw.sin();
                    m.pose.yaw = wrap_angle(m.pose.yaw + c.angular_radps * 0.02);
                    m.linear_mps = c.linear_mps;
                    m.angular_radps = c.angular_radps;
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
    let kind: RobotKind = std::env::var("ROBOT")
        .ok()
        .and_then(|r| r.parse().ok())
        .unwrap_or(RobotKind::ScoutMini);
    let shape = match std::env::var("SHAPE").as_deref() {
        Ok("eight") => Shape::FigureEight,
        Ok("line") => Shape::Line,
        _ => Shape::Square,
    };
    let path = shape_for(kind, shape);
    let kin = kin(kind);
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
    let mut robot = Model::of(kind, Pose::default());
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

#[test]
fn every_robot_of_the_registry_is_described_well_enough_to_drive() {
    for kind in RobotKind::ALL {
        let d = description(kind);
        let k = Kinematics::from_description(&d).unwrap_or_else(|e| panic!("{kind}: {e}"));
        assert!(
            k.max_linear_mps > 0.0 && k.max_linear_mps.is_finite(),
            "{kind}"
        );
        if KinematicsKind::steers(d.kinematics) {
            assert!(!k.turns_on_the_spot(), "{kind}");
        }
    }
}
