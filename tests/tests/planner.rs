//! `chassis-planner` against `chassisd` on each simulated robot: it drives a square back to its
//! start and exits 0, teleop preempts it and hands back, and a preemption longer than its
//! timeout makes it give up. The safety monitor is lifted (`--no-safety-monitor`): these tests
//! are about the planner.
// Test code: helpers outside #[test] functions may unwrap, panic and read the wall clock.
#![allow(clippy::unwrap_used, clippy::panic, clippy::disallowed_methods)]

use std::time::{Duration, Instant};

use chassis_tests::*;

const UP: Duration = Duration::from_secs(10);
/// Longest a square may take (the slowest, SCOUT MINI's, takes about 26 s).
const SQUARE_LIMIT: Duration = Duration::from_secs(40);
/// The goal must be this close (odometry), m.
const GOAL_LIMIT_M: f64 = 0.10;

fn name(tag: &str) -> String {
    // Robot names are at most 16 characters.
    format!("{tag}{}", std::process::id() % 100_000)
}

/// The square each robot drives: TITAN cannot turn tighter than 1.53 m, so its corners are
/// rounded to 1.76 m and its square needs at least 3.52 m; 4 m is its default. The others turn
/// on the spot and drive the 2 m square of the issue.
fn square_size(robot: &str) -> &'static str {
    if robot == "titan" { "4" } else { "2" }
}

/// `chassisd` on the simulated `robot`, and a connection to it.
fn start(env: &mut Env, robot: &str, tag: &str) -> (Robot, String) {
    let n = name(tag);
    env.chassisd(
        "chassisd",
        &["--robot", robot, "--name", &n, "--no-safety-monitor"],
    );
    let robot = env.robot(&n, UP);
    (robot, n)
}

fn position(s: &ChassisState) -> (f64, f64) {
    (s.odometry.x_m, s.odometry.y_m)
}

fn distance(a: (f64, f64), b: (f64, f64)) -> f64 {
    (a.0 - b.0).hypot(a.1 - b.1)
}

fn active(robot: &mut Robot) -> Option<String> {
    mux(robot).active().map(|s| s.name().to_string())
}

/// The planner's last summary line.
fn summary(log: &str) -> String {
    log.lines()
        .rev()
        .find(|l| l.starts_with("reached the goal"))
        .unwrap_or("(no summary)")
        .to_string()
}

/// Waits until the planner drives the robot at more than `speed` m/s.
fn wait_until_driving(env: &Env, robot: &mut Robot, speed: f32) {
    let driving = wait_for(Duration::from_secs(15), || {
        let s = state(robot);
        s.motion.linear_mps.abs() > speed && active(robot).as_deref() == Some("planner")
    });
    assert!(driving.is_some(), "the planner never drove\n{}", env.logs());
}

fn planner_drives_the_square_back_to_its_start(robot_kind: &str) {
    let mut env = Env::new(&format!("plan-square-{robot_kind}"));
    let (mut robot, n) = start(&mut env, robot_kind, "psq");
    let goal = position(&state(&mut robot));
    let size = square_size(robot_kind);
    let started = Instant::now();
    let planner = env.spawn(
        "planner",
        "chassis-planner",
        &["--name", &n, "--shape", "square", "--size", size],
    );
    let code = env.proc(planner).wait_exit(SQUARE_LIMIT);
    let took = started.elapsed();
    assert_eq!(code, Some(0), "the planner did not finish\n{}", env.logs());
    let end = state(&mut robot);
    let error = distance(position(&end), goal);
    let log = env.proc(planner).log_text();
    eprintln!(
        "{robot_kind}: square of {size} m: goal error {error:.3} m (odometry) after {:.1} s; \
         planner: {}",
        took.as_secs_f64(),
        summary(&log)
    );
    assert!(
        error < GOAL_LIMIT_M,
        "{robot_kind} ended {error:.3} m from its start\n{}",
        env.logs()
    );
    assert!(end.motion.linear_mps.abs() < 0.02, "still moving: {end:?}");
    assert!(log.contains("following square of"), "no start line\n{log}");
}

fn teleop_preempts_the_planner_and_hands_back(robot_kind: &str) {
    let mut env = Env::new(&format!("plan-handback-{robot_kind}"));
    let (mut robot, n) = start(&mut env, robot_kind, "pho");
    let goal = position(&state(&mut robot));
    let started = Instant::now();
    let planner = env.spawn(
        "planner",
        "chassis-planner",
        &[
            "--name",
            &n,
            "--shape",
            "square",
            "--size",
            square_size(robot_kind),
            "--preempt-timeout",
            "10",
        ],
    );
    wait_until_driving(&env, &mut robot, 0.3);

    // Teleop sends a stop for one second: it wins the mux and the robot stops.
    let mut teleop = robot.source("teleop").unwrap();
    let preempted = Instant::now();
    let mut teleop_won = false;
    while preempted.elapsed() < Duration::from_secs(1) {
        teleop.stop().unwrap();
        teleop_won |= active(&mut robot).as_deref() == Some("teleop");
        pause(Duration::from_millis(20));
    }
    assert!(teleop_won, "teleop never won the mux\n{}", env.logs());
    let held = state(&mut robot);
    assert!(
        held.motion.linear_mps.abs() < 0.1,
        "still at {} m/s after a second of teleop stops\n{}",
        held.motion.linear_mps,
        env.logs()
    );
    assert!(env.proc(planner).is_running(), "{}", env.logs());

    // Teleop goes quiet: after its 300 ms timeout the planner drives again.
    let handed_back = wait_for(Duration::from_secs(2), || {
        active(&mut robot).as_deref() == Some("planner")
    });
    assert!(handed_back.is_some(), "not handed back\n{}", env.logs());
    let resumed = wait_for(Duration::from_secs(5), || {
        state(&mut robot).motion.linear_mps.abs() > 0.1
    });
    assert!(
        resumed.is_some(),
        "the planner did not resume\n{}",
        env.logs()
    );

    let code = env.proc(planner).wait_exit(SQUARE_LIMIT);
    let took = started.elapsed();
    assert_eq!(code, Some(0), "the planner did not finish\n{}", env.logs());
    let error = distance(position(&state(&mut robot)), goal);
    let log = env.proc(planner).log_text();
    eprintln!(
        "{robot_kind}: square with a 1 s teleop stop: goal error {error:.3} m after {:.1} s; \
         planner: {}",
        took.as_secs_f64(),
        summary(&log)
    );
    assert!(error < GOAL_LIMIT_M, "{error:.3} m\n{}", env.logs());
    assert!(log.contains("preempted by teleop"), "{log}");
    assert!(log.contains("resumed after"), "{log}");
}

fn a_preemption_longer_than_the_timeout_makes_the_planner_give_up(robot_kind: &str) {
    let mut env = Env::new(&format!("plan-timeout-{robot_kind}"));
    let (mut robot, n) = start(&mut env, robot_kind, "pto");
    let planner = env.spawn(
        "planner",
        "chassis-planner",
        &[
            "--name",
            &n,
            "--shape",
            "line",
            "--size",
            "4",
            "--preempt-timeout",
            "1",
        ],
    );
    wait_until_driving(&env, &mut robot, 0.2);
    let mut teleop = robot.source("teleop").unwrap();
    let preempted = Instant::now();
    let mut code = None;
    while preempted.elapsed() < Duration::from_secs(5) {
        teleop.stop().unwrap();
        if let Ok(Some(status)) = env.proc(planner).child.try_wait() {
            code = Some(status.code());
            break;
        }
        pause(Duration::from_millis(20));
    }
    let gave_up = preempted.elapsed();
    let log = env.proc(planner).log_text();
    eprintln!(
        "{robot_kind}: preempted with --preempt-timeout 1: the planner exited {code:?} after \
         {:.2} s",
        gave_up.as_secs_f64()
    );
    assert_eq!(code, Some(Some(1)), "{}", env.logs());
    assert!(
        gave_up > Duration::from_millis(900) && gave_up < Duration::from_secs(3),
        "gave up after {gave_up:?}\n{log}"
    );
    assert!(
        log.contains("chassis-planner: preempted by teleop for")
            && log.contains("longer than the preemption timeout (1 s)"),
        "{log}"
    );
    assert_eq!(active(&mut robot).as_deref(), Some("teleop"));
}

#[test]
fn an_xbot_without_its_wheel_separation_has_no_pose_and_the_planner_says_so() {
    // Over a real serial link (a pty to `chassisd sim`) the service does not know the wheel
    // separation of the simulated board, so it publishes no pose.
    let mut env = Env::new("plan-nopose");
    let n = name("pnp");
    let link = env.dir.join("xbot");
    let sim_bus = format!("pty:{}", link.display());
    env.chassisd(
        "sim",
        &["sim", "--robot", "xbot", "--name", &n, "--bus", &sim_bus],
    );
    assert!(
        wait_for(UP, || link.exists()).is_some(),
        "no pty link\n{}",
        env.logs()
    );
    let bus = format!("serial:{}", link.display());
    env.chassisd(
        "chassisd",
        &[
            "--robot",
            "xbot",
            "--name",
            &n,
            "--bus",
            &bus,
            "--no-safety-monitor",
        ],
    );
    let mut robot = env.robot(&n, UP);
    assert!(!state(&mut robot).is_valid(Group::Pose));
    let planner = env.spawn(
        "planner",
        "chassis-planner",
        &["--name", &n, "--shape", "line"],
    );
    let code = env.proc(planner).wait_exit(Duration::from_secs(10));
    let log = env.proc(planner).log_text();
    assert_eq!(code, Some(1), "{}", env.logs());
    assert!(
        log.contains("publishes no pose") && log.contains("wheel_separation_m"),
        "{log}"
    );
    assert!(state(&mut robot).motion.linear_mps.abs() < 0.01);
}

#[test]
fn titan_drives_a_square_with_rounded_corners_back_to_its_start() {
    planner_drives_the_square_back_to_its_start("titan");
}

#[test]
fn scout_mini_drives_a_square_back_to_its_start_turning_on_the_spot() {
    planner_drives_the_square_back_to_its_start("scout-mini");
}

#[test]
fn xbot_drives_a_square_back_to_its_start_turning_on_the_spot() {
    planner_drives_the_square_back_to_its_start("xbot");
}

#[test]
fn teleop_preempts_the_titan_planner_and_hands_back() {
    teleop_preempts_the_planner_and_hands_back("titan");
}

#[test]
fn teleop_preempts_the_scout_mini_planner_and_hands_back() {
    teleop_preempts_the_planner_and_hands_back("scout-mini");
}

#[test]
fn teleop_preempts_the_xbot_planner_and_hands_back() {
    teleop_preempts_the_planner_and_hands_back("xbot");
}

#[test]
fn a_titan_planner_preempted_longer_than_its_timeout_exits_non_zero() {
    a_preemption_longer_than_the_timeout_makes_the_planner_give_up("titan");
}

#[test]
fn a_scout_mini_planner_preempted_longer_than_its_timeout_exits_non_zero() {
    a_preemption_longer_than_the_timeout_makes_the_planner_give_up("scout-mini");
}

#[test]
fn an_xbot_planner_preempted_longer_than_its_timeout_exits_non_zero() {
    a_preemption_longer_than_the_timeout_makes_the_planner_give_up("xbot");
}
