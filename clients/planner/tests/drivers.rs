//! The follower against each robot's real driver and simulated chassis, wired back to back by
//! `chassis_protocols::pair::Pair` on simulated time: the state the driver publishes (its
//! integrated odometry pose) in, the twist to the driver out, every 20 ms. Every robot of the
//! registry, each with the kinematics the planner reads from its description
//! (`describe(&profile)`, as chassisd publishes it). Deterministic and clock-free; the chassis'
//! true pose shows how far the odometry the planner trusts drifts.
#![allow(clippy::unwrap_used, clippy::panic)]

use std::time::Duration;

use chassis_client::Velocity;
use chassis_planner::geometry::{Point, Pose};
use chassis_planner::kinematics::Kinematics;
use chassis_planner::path::Path;
use chassis_planner::shapes::{self, Shape};
use chassis_planner::tracker::{Activity, Measured, Tracker, TrackerConfig};
use chassis_protocols::description::describe;
use chassis_protocols::driver::{Driver, DriverConfig};
use chassis_protocols::firmware::Firmware;
use chassis_protocols::pair::Pair;
use chassis_protocols::time::Timestamp;
use chassis_protocols::{Profile, RobotKind};

const T0: Timestamp = Timestamp::from_millis(1_000);
const PERIOD: Duration = Duration::from_millis(20);

#[derive(Debug)]
struct Outcome {
    /// Odometry pose to the goal, m.
    goal_error_m: f64,
    /// True pose to the goal, m.
    true_goal_error_m: f64,
    /// Odometry pose to the true pose at the end, m.
    odometry_drift_m: f64,
    odometry_yaw_drift_rad: f64,
    time_s: f64,
}

fn follow<D: Driver, F: Firmware>(
    pair: &mut Pair<D, F>,
    kind: RobotKind,
    kin: Kinematics,
    local: &Path,
) -> Outcome {
    // Let the driver take control of the chassis.
    pair.run_for(Duration::from_millis(500));
    let state = pair.driver.state();
    let start = Pose::new(
        state.odometry.x_m,
        state.odometry.y_m,
        state.odometry.yaw_rad,
    );
    let mut tracker = Tracker::new(
        local.transformed(start),
        TrackerConfig::new(kin, kin.default_speed_mps),
    );
    let goal = tracker.goal();
    let mut time_s = 0.0;
    loop {
        let s = pair.driver.state();
        let m = Measured {
            pose: Pose::new(s.odometry.x_m, s.odometry.y_m, s.odometry.yaw_rad),
            linear_mps: f64::from(s.motion.linear_mps),
            angular_radps: f64::from(s.motion.angular_radps),
            lateral_mps: f64::from(s.motion.lateral_mps),
        };
        let step = tracker.update(&m, PERIOD.as_secs_f64()).unwrap();
        if step.activity == Activity::Done {
            break;
        }
        assert!(time_s < 90.0, "{kind} did not arrive: {step:?}");
        assert!(
            step.command.linear_mps <= kin.max_linear_mps + 1e-12,
            "{kind} asked for {step:?}"
        );
        pair.set_command(
            Velocity::new(
                step.command.linear_mps as f32,
                step.command.lateral_mps as f32,
                step.command.angular_radps as f32,
            )
            .unwrap(),
        );
        pair.run_for(PERIOD);
        time_s += PERIOD.as_secs_f64();
    }
    pair.set_command(Velocity::ZERO);
    pair.run_for(Duration::from_millis(300));
    let s = pair.driver.state();
    let odometry = Point::new(s.odometry.x_m, s.odometry.y_m);
    let truth = pair.firmware.truth();
    // The chassis starts at the origin facing +x, where the driver's odometry starts too.
    let real = Point::new(truth.x_m, truth.y_m);
    Outcome {
        goal_error_m: odometry.distance(goal),
        true_goal_error_m: real.distance(goal),
        odometry_drift_m: odometry.distance(real),
        odometry_yaw_drift_rad: chassis_planner::geometry::wrap_angle(
            s.odometry.yaw_rad - truth.yaw_rad,
        ),
        time_s,
    }
}

/// The robot's profile as chassisd's simulator runs it: the registry's defaults, and the XBot
/// with its simulated board's wheel separation (its manual gives none, so the pose needs it).
fn profile_of(kind: RobotKind) -> Profile {
    let mut profile = kind.entry().defaults();
    profile.fill_for_simulator();
    profile
}

fn drive(kind: RobotKind, shape: Shape) -> Outcome {
    let entry = kind.entry();
    let profile = profile_of(kind);
    let kin = Kinematics::from_description(&describe(&profile)).unwrap();
    let path = shapes::build(shape, shape.default_size_m(&kin), 1, &kin).unwrap();
    let driver = entry.driver(&profile, false, &DriverConfig::default(), T0);
    let firmware = profile.firmware(T0);
    let mut pair = Pair::new(driver, firmware, T0);
    let outcome = follow(&mut pair, kind, kin, &path);
    eprintln!(
        "{kind} {shape:?}: odometry {:.4} m from the goal, truly {:.4} m; odometry drift \
         {:.4} m, {:.4} rad; {:.1} s",
        outcome.goal_error_m,
        outcome.true_goal_error_m,
        outcome.odometry_drift_m,
        outcome.odometry_yaw_drift_rad,
        outcome.time_s
    );
    outcome
}

/// Every robot ends `shape` within 5 cm of its goal by its odometry, 10 cm in truth.
fn every_robot_reaches_the_goal_of(shape: Shape) {
    for kind in RobotKind::ALL {
        let o = drive(kind, shape);
        assert!(o.goal_error_m < 0.05, "{kind}: {o:?}");
        assert!(o.true_goal_error_m < 0.10, "{kind}: {o:?}");
    }
}

#[test]
fn every_robot_reaches_the_goal_of_its_square_on_its_real_driver_and_simulated_chassis() {
    every_robot_reaches_the_goal_of(Shape::Square);
}

#[test]
fn every_robot_reaches_the_goal_of_its_figure_eight_on_its_real_driver_and_simulated_chassis() {
    every_robot_reaches_the_goal_of(Shape::FigureEight);
}
