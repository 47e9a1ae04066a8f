//! The robot's standing speed limit across processes on the simulated chassis: a client lowers
//! it and the measured speed follows; another client cannot raise it; the operator
//! (`chassis control speed-limit`) can, and a value that is not a limit is refused.
// Test code: helpers outside #[test] functions may unwrap, panic and read the wall clock.
#![allow(clippy::unwrap_used, clippy::panic, clippy::disallowed_methods)]

use std::time::{Duration, Instant};

use chassis_tests::*;

const UP: Duration = Duration::from_secs(10);

/// Teleop asks for 1 m/s every 20 ms for `duration`; the largest speed the chassis measured.
fn drive(robot: &mut Robot, teleop: &mut Source, duration: Duration) -> f32 {
    let end = Instant::now() + duration;
    let mut max = 0.0f32;
    while Instant::now() < end {
        teleop.send(VelocityRequest::twist(1.0, 0.0)).unwrap();
        if let Ok(Some(state)) = robot.wait_state(Duration::from_millis(20)) {
            max = max.max(state.motion.linear_mps.abs());
        }
    }
    max
}

#[test]
fn a_client_lowers_the_limit_another_cannot_raise_it_and_the_operator_can() {
    let mut env = Env::new("speed_limit");
    let n = name("limit");
    env.chassisd(
        "chassisd",
        &["--robot", "titan", "--name", &n, "--no-safety-monitor"],
    );
    let mut robot = env.robot(&n, UP);
    let mut teleop = source(&mut robot, "teleop");
    let mut planner = source(&mut robot, "planner");

    planner.limit_speed(0.4).unwrap();
    drive(&mut robot, &mut teleop, Duration::from_secs(2));
    let peak = drive(&mut robot, &mut teleop, Duration::from_secs(1));
    assert!(
        (0.35..0.43).contains(&peak),
        "{peak} m/s under a 0.4 m/s limit\n{}",
        env.logs()
    );
    let m = mux(&mut robot);
    assert_eq!(m.speed_limit(), Some((0.4, "planner")));
    assert_ne!(m.clamp_flags & ClampFlags::SPEED_LIMIT, 0);
    assert_eq!(
        m.why().to_string(),
        "driving from teleop · limited to 0.4 m/s by planner"
    );

    // The teleop asks for more: nothing changes.
    teleop.limit_speed(2.0).unwrap();
    let peak = drive(&mut robot, &mut teleop, Duration::from_secs(1));
    assert!(peak < 0.43, "{peak} m/s: a client raised the limit");
    assert!(teleop.limit_speed(f32::NAN).is_err() && teleop.limit_speed(-1.0).is_err());

    let out = env.chassis(&["control", "--name", &n, "speed-limit", "--", "-1"]);
    assert!(
        output_text(&out).contains("the speed limit is negative"),
        "{}",
        output_text(&out)
    );
    let answer = env.chassis_ok(&["control", "--name", &n, "speed-limit", "0.8"]);
    assert!(
        answer.contains("speed limited to 0.8 m/s by the operator"),
        "{answer}"
    );
    drive(&mut robot, &mut teleop, Duration::from_secs(2));
    let peak = drive(&mut robot, &mut teleop, Duration::from_secs(1));
    assert!(
        (0.75..0.83).contains(&peak),
        "{peak} m/s under the operator's 0.8 m/s"
    );
    assert_eq!(mux(&mut robot).speed_limit(), Some((0.8, "operator")));
    env.chassis_ok(&["control", "--name", &n, "speed-limit", "0"]);
    drive(&mut robot, &mut teleop, Duration::from_secs(2));
    assert!(drive(&mut robot, &mut teleop, Duration::from_secs(1)) > 0.95);
    assert_eq!(mux(&mut robot).speed_limit(), None);
}
