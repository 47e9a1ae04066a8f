//! The follower against each robot's real driver and simulated chassis, wired back to back by
//! `chassis_protocols::pair::Pair` on simulated time: the state the driver publishes (its
//! integrated odometry pose) in, the twist to the driver out, every 20 ms. Deterministic and
//! clock-free; the chassis' true pose shows how far the odometry the planner trusts drifts.
#![allow(clippy::unwrap_used, clippy::panic)]

use std::time::Duration;

use chassis_client::Twist;
use chassis_planner::geometry::{Point, Pose};
use chassis_planner::kinematics::{Kinematics, RobotModel};
use chassis_planner::path::Path;
use chassis_planner::shapes::{self, Shape};
use chassis_planner::tracker::{Activity, Measured, Tracker, TrackerConfig};
use chassis_protocols::Profile;
use chassis_protocols::agilex_v2::{V2Driver, V2Sim};
use chassis_protocols::driver::{Driver, DriverConfig};
use chassis_protocols::firmware::Firmware;
use chassis_protocols::pair::Pair;
use chassis_protocols::profile::{ScoutMiniProfile, TitanProfile, XbotProfile};
use chassis_protocols::scout_mini::{ScoutMiniDriver, ScoutMiniSim};
use chassis_protocols::time::Timestamp;
use chassis_protocols::titan::{TitanDriver, TitanSim};
use chassis_protocols::xbot::{XbotDriver, XbotSim};

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
    model: RobotModel,
    local: &Path,
) -> Outcome {
    // Let the driver take control of the chassis.
    pair.run_for(Duration::from_millis(500));
    let kin = Kinematics::of(model);
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
        };
        let step = tracker.update(&m, PERIOD.as_secs_f64()).unwrap();
        if step.activity == Activity::Done {
            break;
        }
        assert!(time_s < 90.0, "{model:?} did not arrive: {step:?}");
        pair.set_command(Twist {
            linear_x_mps: step.command.linear_mps as f32,
            angular_z_radps: step.command.angular_radps as f32,
            ..Twist::ZERO
        });
        pair.run_for(PERIOD);
        time_s += PERIOD.as_secs_f64();
    }
    pair.set_command(Twist::ZERO);
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

fn drive(model: RobotModel, shape: Shape) -> Outcome {
    let kin = Kinematics::of(model);
    let path = shapes::build(shape, shape.default_size_m(&kin), 1, &kin).unwrap();
    let config = DriverConfig::default();
    let outcome = match model {
        RobotModel::Titan => {
            let p = TitanProfile::default();
            let mut pair = Pair::new(
                TitanDriver::new(p.clone(), config, T0),
                TitanSim::new(p, T0),
                T0,
            );
            follow(&mut pair, model, &path)
        }
        RobotModel::ScoutMini => {
            let p = ScoutMiniProfile::default();
            let mut pair = Pair::new(
                ScoutMiniDriver::new(p.clone(), config, T0),
                ScoutMiniSim::new(p, T0),
                T0,
            );
            follow(&mut pair, model, &path)
        }
        RobotModel::Xbot => {
            let p = XbotProfile {
                wheel_separation_m: Some(XbotSim::DEFAULT_WHEEL_SEPARATION_M),
                ..XbotProfile::default()
            };
            let mut pair = Pair::new(
                XbotDriver::new(p.clone(), config, T0),
                XbotSim::new(p, T0),
                T0,
            );
            follow(&mut pair, model, &path)
        }
        v2 => {
            let robot: chassis_protocols::RobotKind = v2.name().parse().unwrap();
            let Profile::V2(p) = robot.entry().defaults() else {
                panic!("{robot} is not an AgileX V2 robot");
            };
            let mut pair = Pair::new(V2Driver::new(p.clone(), config, T0), V2Sim::new(p, T0), T0);
            follow(&mut pair, model, &path)
        }
    };
    eprintln!(
        "{model:?} {shape:?}: odometry {:.4} m from the goal, truly {:.4} m; odometry drift \
         {:.4} m, {:.4} rad; {:.1} s",
        outcome.goal_error_m,
        outcome.true_goal_error_m,
        outcome.odometry_drift_m,
        outcome.odometry_yaw_drift_rad,
        outcome.time_s
    );
    outcome
}

const ROBOTS: [RobotModel; 9] = [
    RobotModel::Titan,
    RobotModel::ScoutMini,
    RobotModel::Xbot,
    RobotModel::Scout,
    RobotModel::Hunter,
    RobotModel::HunterSe,
    RobotModel::Tracer,
    RobotModel::Bunker,
    RobotModel::RangerMini,
];

#[test]
fn every_robot_reaches_the_goal_of_its_square_on_its_real_driver_and_simulated_chassis() {
    for model in ROBOTS {
        let o = drive(model, Shape::Square);
        assert!(o.goal_error_m < 0.05, "{model:?}: {o:?}");
        assert!(o.true_goal_error_m < 0.10, "{model:?}: {o:?}");
    }
}

#[test]
fn every_robot_reaches_the_goal_of_its_figure_eight_on_its_real_driver_and_simulated_chassis() {
    for model in ROBOTS {
        let o = drive(model, Shape::FigureEight);
        assert!(o.goal_error_m < 0.05, "{model:?}: {o:?}");
        assert!(o.true_goal_error_m < 0.10, "{model:?}: {o:?}");
    }
}
