//! The safety monitor (`chassis-safety`) with the real processes: chassisd on the simulated
//! chassis with its `safety` source required, the monitor, the CLI, and the test as the teleop
//! and planner clients. The monitor knows no robot: its speed and battery levels come from the
//! description chassisd publishes (tested here on protocol-V2 robots and through a `[profile]`
//! override), and for every robot of the registry in `chassis-safety`'s own tests.
// Test code: helpers outside #[test] functions may unwrap, panic and read the wall clock.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::disallowed_methods
)]

use std::time::{Duration, Instant};

use chassis_tests::*;
use nix::sys::signal::Signal;

const UP: Duration = Duration::from_secs(10);

/// Starts chassisd on the simulated `robot` (safety source required) and the monitor; returns
/// the connection once the monitor's heartbeats reach the mux, and the monitor's index.
fn start(env: &mut Env, robot: &str, n: &str) -> (Robot, usize) {
    start_with(env, &["--robot", robot, "--name", n], n)
}

/// [`start`] in a new environment (`test` names it) for robot NAME (`tag` and the pid): the
/// environment, NAME, the connection and the monitor's index.
fn started(test: &str, (tag, robot): (&str, &str)) -> (Env, String, Robot, usize) {
    let mut env = Env::new(test);
    let n = name(tag);
    let (connection, monitor) = start(&mut env, robot, &n);
    (env, n, connection, monitor)
}

/// [`start`] with chassisd's arguments.
fn start_with(env: &mut Env, chassisd: &[&str], n: &str) -> (Robot, usize) {
    env.chassisd("chassisd", chassisd);
    let mut r = env.robot(n, UP);
    let monitor = env.spawn("safety", "chassis-safety", &["--name", n]);
    let alive = wait_for(UP, || {
        mux(&mut r)
            .sources()
            .iter()
            .any(|s| s.name() == "safety" && s.has(SourceFlags::FRESH))
    });
    assert!(
        alive.is_some(),
        "the monitor never reached the mux\n{}",
        env.logs()
    );
    (r, monitor)
}

/// Sends every request every 20 ms for `duration`; returns the lowest and highest forward speed
/// seen.
fn drive(
    robot: &mut Robot,
    sources: &mut [(&mut Source, VelocityRequest)],
    duration: Duration,
) -> (f32, f32) {
    let end = Instant::now() + duration;
    let (mut low, mut high) = (f32::MAX, f32::MIN);
    while Instant::now() < end {
        for (s, r) in sources.iter_mut() {
            s.send(*r).unwrap();
        }
        if let Ok(Some(state)) = robot.wait_state(Duration::from_millis(20)) {
            low = low.min(state.motion.linear_mps);
            high = high.max(state.motion.linear_mps);
        }
    }
    (low, high)
}

/// [`drive`] with one source and request; returns the highest forward speed seen.
fn drive_one(robot: &mut Robot, source: &mut Source, go: VelocityRequest, d: Duration) -> f32 {
    drive(robot, &mut [(source, go)], d).1
}

/// [`drive_one`], then the robot must stand.
fn stands_still(robot: &mut Robot, source: &mut Source, go: VelocityRequest, d: Duration) {
    let high = drive_one(robot, source, go, d);
    let still = state(robot).motion.linear_mps.abs();
    assert!(still < 0.01, "rolling at {still} (peak {high})");
}

/// The teleop source of a robot the test just started, checked to drive at 0.3 m/s within a
/// second; returns it with its request.
fn teleop_drives(env: &Env, robot: &mut Robot) -> (Source, VelocityRequest) {
    let mut teleop = source(robot, "teleop");
    let go = VelocityRequest::twist(0.3, 0.0);
    let high = drive_one(robot, &mut teleop, go, Duration::from_secs(1));
    assert!(high > 0.2, "peak {high}\n{}", env.logs());
    (teleop, go)
}

/// Keeps sending `go` until the monitor is the active source and the output is zero (at most
/// `timeout`); returns the time it took, or fails the test with `what` stopped the robot.
fn stopped_by_the_monitor(
    env: &Env,
    robot: &mut Robot,
    teleop: &mut Source,
    go: VelocityRequest,
    timeout: Duration,
    what: &str,
) -> Duration {
    drive_until(robot, &mut [(teleop, go)], timeout, |m, _| {
        m.output == BodyVelocity::ZERO && m.active().is_some_and(|s| s.name() == "safety")
    })
    .unwrap_or_else(|| panic!("no stop for {what}\n{}", env.logs()))
}

/// [`drive_until`] with one source and its request, for at most `ms` milliseconds.
fn until_one(
    robot: &mut Robot,
    (source, go): (&mut Source, VelocityRequest),
    ms: u64,
    condition: impl FnMut(&MuxStatus, &ChassisState) -> bool,
) -> Option<Duration> {
    drive_until(
        robot,
        &mut [(source, go)],
        Duration::from_millis(ms),
        condition,
    )
}

/// The mux commands zero.
fn output_zero(m: &MuxStatus, _: &ChassisState) -> bool {
    m.output == BodyVelocity::ZERO
}

/// Teleop drives: it is the active source and the robot moves faster than `speed`.
fn teleop_above(speed: f32) -> impl FnMut(&MuxStatus, &ChassisState) -> bool {
    move |m, s| m.active().is_some_and(|a| a.name() == "teleop") && s.motion.linear_mps > speed
}

/// Keeps sending while waiting for `condition` on the mux status; returns the time it took.
fn drive_until(
    robot: &mut Robot,
    sources: &mut [(&mut Source, VelocityRequest)],
    timeout: Duration,
    mut condition: impl FnMut(&MuxStatus, &ChassisState) -> bool,
) -> Option<Duration> {
    let start = Instant::now();
    let mut last_sent = Instant::now() - Duration::from_secs(1);
    while start.elapsed() < timeout {
        if last_sent.elapsed() >= Duration::from_millis(20) {
            for (s, r) in sources.iter_mut() {
                s.send(*r).unwrap();
            }
            last_sent = Instant::now();
        }
        let _ = robot.wait_mux(Duration::from_millis(5));
        let (Some(m), Some(s)) = (robot.latest_mux().unwrap(), robot.latest_state().unwrap())
        else {
            continue;
        };
        if condition(&m, &s) {
            return Some(start.elapsed());
        }
    }
    None
}

/// The monitor's latest `SafetyStatus`.
fn safety(robot: &Robot) -> SafetyStatus {
    let mut sub = robot
        .subscriber::<SafetyStatus>(SafetyStatus::SERVICE)
        .unwrap()
        .expect("the monitor made chassis/<name>/safety");
    sub.wait(Duration::from_secs(1))
        .unwrap()
        .expect("a safety status within 1 s")
}

/// Injects a fault into the simulated chassis; returns the service's answer stamp (the
/// injection happened just before it).
fn inject(robot: &mut Robot, kind: u8, on: bool, value: f64) -> u64 {
    let request = SimRequest {
        kind,
        flag: u8::from(on),
        value,
        ..SimRequest::default()
    };
    sim_ok(robot, request)
}

#[test]
fn the_monitor_stops_teleop_and_planner_at_an_obstacle_ahead_of_the_xbot_but_lets_it_reverse() {
    let (env, n, mut robot, _) = started("safety-obstacle", ("sob", "xbot"));
    let mut planner = source(&mut robot, "planner");
    let mut teleop = source(&mut robot, "teleop");
    let ahead = VelocityRequest::twist(0.3, 0.0);

    // The planner drives.
    let moving = drive_until(
        &mut robot,
        &mut [(&mut planner, ahead)],
        Duration::from_secs(5),
        |_, s| s.motion.linear_mps > 0.25,
    );
    assert!(moving.is_some(), "the planner cannot drive\n{}", env.logs());

    // An obstacle 0.3 m ahead: inside the 0.35 m stop zone.
    let injected = inject(&mut robot, SimKind::OBSTACLE_AHEAD, true, 0.3);
    let mut blocked_ns = 0;
    let blocked = drive_until(
        &mut robot,
        &mut [(&mut planner, ahead)],
        Duration::from_secs(3),
        |m, _| {
            blocked_ns = m.stamp_ns;
            m.output.linear_x_mps <= 0.0
        },
    );
    assert!(
        blocked.is_some(),
        "the planner still drives into the obstacle\n{}",
        env.logs()
    );
    let still = drive_until(
        &mut robot,
        &mut [(&mut planner, ahead)],
        Duration::from_secs(3),
        |_, s| s.motion.linear_mps.abs() < 0.01,
    )
    .unwrap();
    let s = safety(&robot);
    let decided_ns = s.last_trigger_ns[usize::from(SafetyRule::ULTRASONIC)];
    let ms = |ns: u64| ns.saturating_sub(injected) as f64 / 1e6;
    eprintln!(
        "obstacle injected → monitor decided after {:.1} ms (incl. the next 20 ms sensor \
         report) → mux output vx ≤ 0 after {:.1} ms → robot still {still:?} later",
        ms(decided_ns),
        ms(blocked_ns)
    );
    assert!(ms(blocked_ns) < 150.0, "{} ms", ms(blocked_ns));
    assert!(blocked_ns >= decided_ns);
    assert!(s.is_active(SafetyRule::ULTRASONIC), "{s:?}");
    assert_eq!(s.action, SafetyAction::SLOW);
    assert_eq!(s.limit_forward_mps, 0.0);
    assert_eq!(s.limit_reverse_mps, SafetyStatus::UNLIMITED);
    assert!(s.last_text().contains("stop zone"), "{}", s.last_text());
    let m = mux(&mut robot);
    assert_ne!(m.clamp_flags & ClampFlags::SAFETY_LIMIT, 0);
    let status = env.chassis_ok(&["status", "--name", &n]);
    assert!(status.contains("SLOW by ultrasonic"), "{status}");

    // Teleop (higher priority) cannot push through either.
    let (_, high) = drive(
        &mut robot,
        &mut [(&mut planner, ahead), (&mut teleop, ahead)],
        Duration::from_millis(800),
    );
    assert!(
        high < 0.02,
        "teleop moved towards the obstacle at {high} m/s"
    );
    assert_eq!(mux(&mut robot).active().unwrap().name(), "teleop");
    assert!(mux(&mut robot).output.linear_x_mps <= 0.0);

    // Reversing away is allowed.
    let x0 = state(&mut robot).odometry.x_m;
    let (low, _) = drive(
        &mut robot,
        &mut [(&mut teleop, VelocityRequest::twist(-0.2, 0.0))],
        Duration::from_millis(1500),
    );
    let x1 = state(&mut robot).odometry.x_m;
    assert!(low < -0.15, "reversed at {low} m/s");
    assert!(x1 < x0 - 0.1, "moved from {x0} m to {x1} m");

    // The obstacle goes: forward again (after the 300 ms release time).
    env.chassis_ok(&["sim", "--name", &n, "obstacle-ahead", "--clear"]);
    let high = drive_one(&mut robot, &mut teleop, ahead, Duration::from_millis(1500));
    assert!(
        high > 0.25,
        "no forward motion after the obstacle left: {high}"
    );
    assert_eq!(safety(&robot).action, SafetyAction::NONE);
}

#[test]
fn sigkill_of_the_safety_monitor_stops_the_robot_within_the_source_timeout() {
    let (mut env, _, mut robot, monitor) = started("safety-kill", ("skl", "titan"));
    let mut teleop = source(&mut robot, "teleop");
    let go = VelocityRequest::twist(0.4, 0.0);
    let high = drive_one(&mut robot, &mut teleop, go, Duration::from_millis(1500));
    assert!(high > 0.3, "peak {high} m/s with the monitor alive");

    env.proc(monitor).signal(Signal::SIGKILL);
    let stopped = until_one(&mut robot, (&mut teleop, go), 2000, |m, _| {
        m.zero_reason == ZeroReason::REQUIRED_SOURCE_STALE && m.output == BodyVelocity::ZERO
    })
    .unwrap_or_else(|| panic!("no safe stop after the kill\n{}", env.logs()));
    eprintln!("safety monitor SIGKILLed → mux output zero after {stopped:?} (timeout 200 ms)");
    assert!(
        stopped <= Duration::from_millis(250),
        "safe stop after {stopped:?}"
    );
    stands_still(&mut robot, &mut teleop, go, Duration::from_millis(1500));
}

#[test]
fn the_bumper_latches_the_estop_which_holds_until_the_operator_releases_it() {
    let (mut env, n, mut robot, _) = started("safety-latch", ("slt", "titan"));
    let (mut teleop, go) = teleop_drives(&env, &mut robot);

    let estop = mux(&mut robot).lock_index("estop").unwrap();
    let pressed = inject(&mut robot, SimKind::BUMPER, true, 0.0);
    let latched = until_one(&mut robot, (&mut teleop, go), 3000, |m, _| {
        m.locks()[estop].held == 1
    });
    assert!(latched.is_some(), "no latch\n{}", env.logs());
    let m = mux(&mut robot);
    assert_eq!(m.locks()[estop].holder, 0, "held by the safety source");
    eprintln!(
        "bumper pressed → estop lock engaged after {:.1} ms",
        m.locks()[estop].since_ns.saturating_sub(pressed) as f64 / 1e6
    );
    env.chassis_ok(&["sim", "--name", &n, "bumper", "off"]);

    // Teleop keeps asking; the lock holds after the bumper is released.
    let end = Instant::now() + Duration::from_millis(2000);
    while Instant::now() < end {
        teleop.send(go).unwrap();
        let m = mux(&mut robot);
        assert_eq!(
            m.output,
            BodyVelocity::ZERO,
            "commanded motion under the latch"
        );
    }
    let s = state(&mut robot);
    assert_eq!(
        s.system.fault_flags & FaultFlags::BUMPER,
        0,
        "bumper still on"
    );
    assert!(
        s.motion.linear_mps.abs() < 0.01,
        "rolling at {}",
        s.motion.linear_mps
    );
    let status = safety(&robot);
    assert_eq!(status.action, SafetyAction::LATCH);
    assert!(status.is_active(SafetyRule::BUMPER));
    assert_eq!(status.estop, EstopState::HELD_BY_MONITOR);
    assert_eq!(status.trigger_count(SafetyRule::BUMPER), 1);
    let text = env.chassis_ok(&["status", "--name", &n]);
    assert!(text.contains("LATCH by bumper"), "{text}");

    let out = env.chassis_ok(&["control", "--name", &n, "estop-release"]);
    assert!(out.contains("estop released"), "{out}");
    // A release never starts motion (tests/tests/system/latch.rs): teleop asks for zero, then drives.
    // Without it the test passed only when the CLI calls above outlasted teleop's timeout.
    teleop.send(VelocityRequest::twist(0.0, 0.0)).unwrap();
    let high = drive_one(&mut robot, &mut teleop, go, Duration::from_millis(1500));
    assert!(
        high > 0.2,
        "no motion after the release: {high}\n{}",
        env.logs()
    );
    let status = safety(&robot);
    assert_eq!(status.action, SafetyAction::NONE);
    assert_eq!(status.estop, EstopState::FREE);
    assert!(env.proc(0).is_running(), "chassisd died\n{}", env.logs());
}

#[test]
fn sigusr1_to_the_monitor_latches_the_operator_estop_until_it_is_released() {
    let (mut env, n, mut robot, monitor) = started("safety-usr1", ("sus", "xbot"));
    let (mut teleop, go) = teleop_drives(&env, &mut robot);
    env.proc(monitor).signal(Signal::SIGUSR1);
    let estop = mux(&mut robot).lock_index("estop").unwrap();
    let latched = until_one(&mut robot, (&mut teleop, go), 2000, |m, _| {
        m.locks()[estop].held == 1 && m.output == BodyVelocity::ZERO
    });
    assert!(latched.is_some(), "no latch\n{}", env.logs());
    eprintln!(
        "SIGUSR1 → estop held, output zero after {:?}",
        latched.unwrap()
    );
    let status = safety(&robot);
    assert!(status.is_active(SafetyRule::OPERATOR), "{status:?}");
    assert_eq!(status.action, SafetyAction::LATCH);
    let high = drive_one(&mut robot, &mut teleop, go, Duration::from_secs(1));
    assert!(
        state(&mut robot).motion.linear_mps.abs() < 0.01,
        "peak {high}"
    );
    env.chassis_ok(&["control", "--name", &n, "estop-release"]);
    // A release never starts motion (tests/tests/system/latch.rs): teleop asks for zero, then drives.
    teleop.send(VelocityRequest::twist(0.0, 0.0)).unwrap();
    let high = drive_one(&mut robot, &mut teleop, go, Duration::from_millis(1500));
    assert!(
        high > 0.2,
        "no motion after the release and teleop's zero: {high}\n{}",
        env.logs()
    );
    assert!(env.proc(monitor).is_running());
}

/// Starts `kind` as `n` with the monitor, drives, empties its battery to `percent`: the
/// monitor must stop the robot by its battery rule with `check` true of its text; fills it to
/// 60 %: the robot must drive again. `check_log` then judges the monitor's log.
fn a_low_battery_stops_and_a_charged_one_drives(
    test: &str,
    kind: &str,
    n: &str,
    percent: &str,
    check: impl Fn(&str) -> bool,
    check_log: impl FnOnce(&str),
) {
    let mut env = Env::new(test);
    let (mut robot, monitor) = start(&mut env, kind, n);
    let (mut teleop, go) = teleop_drives(&env, &mut robot);

    env.chassis_ok(&["sim", "--name", n, "battery", percent]);
    let timeout = Duration::from_secs(5);
    let stopped =
        stopped_by_the_monitor(&env, &mut robot, &mut teleop, go, timeout, "a low battery");
    eprintln!("{kind} battery {percent} % → safety stop after {stopped:?} (1 s trigger time)");
    let status = safety(&robot);
    assert!(status.is_active(SafetyRule::BATTERY), "{status:?}");
    assert_eq!(status.action, SafetyAction::STOP);
    assert!(check(status.last_text()), "{}", status.last_text());
    check_log(&env.proc(monitor).log_text());
    stands_still(&mut robot, &mut teleop, go, Duration::from_secs(1));

    env.chassis_ok(&["sim", "--name", n, "battery", "60"]);
    let high = drive_one(&mut robot, &mut teleop, go, Duration::from_secs(3));
    assert!(
        high > 0.2,
        "no motion with a charged battery: {high}\n{}",
        env.logs()
    );
}

#[test]
fn a_low_battery_stops_the_robot_and_a_charged_one_lets_it_drive_again() {
    // 12 %: below the monitor's 15 %, above the 10 % at which the TITAN cuts power itself.
    a_low_battery_stops_and_a_charged_one_drives(
        "safety-battery",
        "titan",
        &name("sbt"),
        "12",
        |text| text.contains("% < 15 %"),
        |_| {},
    );
}

#[test]
fn a_silent_chassis_stops_the_robot_until_it_talks_again() {
    let (env, n, mut robot, _) = started("safety-silent", ("ssl", "titan"));
    let (mut teleop, go) = teleop_drives(&env, &mut robot);

    env.chassis_ok(&["sim", "--name", &n, "silence", "1.5"]);
    let stopped = until_one(&mut robot, (&mut teleop, go), 2000, output_zero)
        .unwrap_or_else(|| panic!("no stop while the chassis is silent\n{}", env.logs()));
    eprintln!("chassis silent → safety stop after {stopped:?}");
    assert!(safety(&robot).is_active(SafetyRule::STALE));
    // The chassis talks again after 1.5 s; motion 0.5 s after that.
    let high = drive_one(&mut robot, &mut teleop, go, Duration::from_secs(3));
    assert!(
        high > 0.2,
        "no motion after the silence: {high}\n{}",
        env.logs()
    );
    assert!(!safety(&robot).is_active(SafetyRule::STALE));
}

#[test]
fn the_monitor_waits_for_the_service_and_keeps_guarding_across_its_restart() {
    let mut env = Env::new("safety-restart");
    let n = name("srs");
    // The monitor first: no service yet. It says so and keeps trying.
    let monitor = env.spawn("safety", "chassis-safety", &["--name", &n]);
    let first = env.serve_as("first", ("titan", &n), &[]);
    let mut robot = env.robot(&n, UP);
    let mut teleop = source(&mut robot, "teleop");
    let go = VelocityRequest::twist(0.3, 0.0);
    let moving = until_one(&mut robot, (&mut teleop, go), 5000, |_, s| {
        s.motion.linear_mps > 0.2
    });
    assert!(moving.is_some(), "no motion\n{}", env.logs());

    env.proc(first).signal(Signal::SIGKILL);
    env.proc(first).wait_exit(Duration::from_secs(3));
    assert!(env.proc(monitor).is_running(), "{}", env.logs());
    let restarted = now_ns();
    env.serve_as("again", ("titan", &n), &[]);
    // Teleop kept asking through the restart: once the monitor guards again, the robot stands
    // waiting for teleop's zero (chassisd starting is a stop), and drives after it.
    let standing = stands_until_zero(
        &mut robot,
        restarted,
        ("teleop", &[Stop::SERVICE_START]),
        || {
            teleop.send(go).unwrap();
        },
    );
    assert!(
        standing.as_ref().is_ok_and(StoodUntilZero::stood),
        "{standing:?}\n{}",
        env.logs()
    );
    teleop.stop().unwrap();
    // Only samples of the new service count (the last ones of the first are still cached).
    let moving = until_one(&mut robot, (&mut teleop, go), 10000, |m, s| {
        m.stamp_ns > restarted
            && s.stamp_ns > restarted
            && m.sources()
                .iter()
                .any(|s| s.name() == "safety" && s.has(SourceFlags::FRESH))
            && s.motion.linear_mps > 0.2
    });
    assert!(
        moving.is_some(),
        "no motion after the restart\n{}",
        env.logs()
    );
    assert!(env.proc(monitor).is_running(), "{}", env.logs());

    // SIGTERM: a last stop, exit code 0.
    env.proc(monitor).signal(Signal::SIGTERM);
    let stopped = until_one(&mut robot, (&mut teleop, go), 2000, output_zero);
    assert!(
        stopped.is_some_and(|t| t < Duration::from_millis(200)),
        "{stopped:?}\n{}",
        env.logs()
    );
    assert_eq!(env.proc(monitor).wait_exit(Duration::from_secs(3)), Some(0));
    eprintln!("monitor SIGTERMed → zero after {:?}", stopped.unwrap());
}

/// Writes chassisd's configuration for a test; returns its path.
fn chassisd_config(env: &Env, text: &str) -> String {
    env.write("chassisd.toml", text)
}

/// A HUNTER whose driver is limited to 0.5 m/s by a `[profile]` override: requests beyond the
/// limit are clamped and the monitor lets it drive; the simulated chassis then runs away at
/// 1.0 m/s (`chassis sim runaway`) — under the HUNTER's own 1.5 m/s, beyond the configured limit
/// — and the monitor stops it (the speed rule) and latches the e-stop (the runaway rule: faster
/// than the command on the wire); once it obeys again and the operator released the e-stop, it
/// drives again.
#[test]
fn a_hunter_running_away_past_its_configured_limit_is_stopped_by_the_monitor() {
    let mut env = Env::new("safety-runaway");
    let n = name("srw");
    let config = chassisd_config(&env, "[profile]\nmax_linear_mps = 0.5\n");
    let (mut robot, monitor) = start_with(
        &mut env,
        &["--robot", "hunter", "--name", &n, "--config", &config],
        &n,
    );
    let mut teleop = source(&mut robot, "teleop");
    // Asking for more than the limit is a request the driver clamps, not a runaway.
    let fast = VelocityRequest::twist(0.8, 0.0);
    let high = drive_one(&mut robot, &mut teleop, fast, Duration::from_secs(2));
    assert!(
        (0.4..=0.55).contains(&high),
        "peak {high} (limit 0.5)\n{}",
        env.logs()
    );
    let status = safety(&robot);
    assert!(!status.is_active(SafetyRule::SPEED), "{status:?}");
    assert_eq!(status.action, SafetyAction::NONE);

    env.chassis_ok(&["sim", "--name", &n, "runaway", "1.0"]);
    let mut fastest = 0.0f32;
    let stopped = until_one(&mut robot, (&mut teleop, fast), 5000, |m, s| {
        fastest = fastest.max(s.motion.linear_mps);
        m.output == BodyVelocity::ZERO && m.active().is_some_and(|s| s.name() == "safety")
    })
    .unwrap_or_else(|| panic!("no stop for a runaway at 1.0 m/s\n{}", env.logs()));
    eprintln!("runaway at 1.0 m/s past a 0.5 m/s limit → safety stop after {stopped:?}");
    assert!(fastest > 0.6, "measured at most {fastest} m/s");
    let status = safety(&robot);
    assert!(status.is_active(SafetyRule::SPEED), "{status:?}");
    assert!(status.is_active(SafetyRule::RUNAWAY), "{status:?}");
    assert_eq!(status.action, SafetyAction::LATCH);
    assert!(status.trigger_count(SafetyRule::SPEED) >= 1);
    // The mux keeps the output at zero while the chassis still runs away.
    let high = drive_one(&mut robot, &mut teleop, fast, Duration::from_secs(1));
    assert!(high > 0.6, "the runaway went on: {high}");
    assert_eq!(mux(&mut robot).output, BodyVelocity::ZERO);

    env.chassis_ok(&["sim", "--name", &n, "runaway", "--clear"]);
    env.chassis_ok(&["control", "--name", &n, "estop-release"]);
    teleop.send(VelocityRequest::twist(0.0, 0.0)).unwrap();
    let again = until_one(&mut robot, (&mut teleop, fast), 5000, teleop_above(0.3));
    assert!(
        again.is_some(),
        "no motion once the chassis obeys again\n{}",
        env.logs()
    );
    assert!(!safety(&robot).is_active(SafetyRule::SPEED));
    assert!(env.proc(monitor).is_running());
}

/// A RANGER MINI (protocol V2): its description gives its under-voltage alarm, 23.5 V, and no
/// state-of-charge level, so the monitor judges the voltage although the chassis reports a state
/// of charge, and says so; a flat battery stops it, a charged one lets it drive again.
#[test]
fn a_ranger_mini_with_a_low_battery_is_stopped_by_the_monitor() {
    let n = name("srb");
    // 8 %: 22.4 V in the simulated 22-27 V pack, below 23.5 V.
    a_low_battery_stops_and_a_charged_one_drives(
        "safety-ranger-battery",
        "ranger-mini",
        &n,
        "8",
        |text| text.starts_with("battery: 22.") && text.ends_with("V < 23.50 V"),
        |log| {
            assert!(
                log.contains(&format!(
                    "battery: judging chassis/{n} by its voltage (below 23.5 V, description \
                     (chassis/{n}: battery.low_v)); it reports a state of charge, but no level \
                     is known for it"
                )),
                "{log}"
            );
        },
    );
}

/// chassisd's `[profile]` lowers the HUNTER's speed limit and raises its under-voltage alarm:
/// the running monitor's levels follow, as its log and `--print-config` against the running
/// robot say, each with where it comes from.
#[test]
fn a_profile_override_in_chassisds_config_reaches_the_monitor() {
    let mut env = Env::new("safety-profile");
    let n = name("spo");
    let config = chassisd_config(
        &env,
        "[profile]\nmax_linear_mps = 0.5\nunder_voltage_alarm_v = 25.0\n",
    );
    let (_robot, monitor) = start_with(
        &mut env,
        &["--robot", "hunter", "--name", &n, "--config", &config],
        &n,
    );
    let speed = format!(
        "speed rule: acts above 0.6 m/s either way — description (chassis/{n}: forward limit \
         0.5 m/s (the driver's limit) × limit_factor 1.1 + limit_margin_mps 0.05)"
    );
    let logged = wait_for(Duration::from_secs(5), || {
        env.proc(monitor).log_text().contains(&speed)
    });
    let log = env.proc(monitor).log_text();
    assert!(logged.is_some(), "{log}");
    assert!(
        log.contains(&format!(
            "battery rule: voltage below 25.0 V — description (chassis/{n}: battery.low_v)"
        )),
        "{log}"
    );

    let out = env.run("chassis-safety", &["--print-config", "--name", &n]);
    assert!(out.status.success(), "{out:?}");
    let text = String::from_utf8_lossy(&out.stdout);
    eprintln!("{text}");
    assert!(
        text.contains(&format!(
            "\n# max_linear_mps = 0.6  # description (chassis/{n}: forward limit 0.5 m/s \
             (the driver's limit) × limit_factor 1.1 + limit_margin_mps 0.05)\n"
        )),
        "{text}"
    );
    assert!(
        text.contains(&format!(
            "\n# min_voltage_v = 25.0  # description (chassis/{n}: battery.low_v)\n"
        )),
        "{text}"
    );
    assert!(text.contains("AgileX HUNTER 2.0 (hunter, model hunter, protocol v2)"));
    assert!(text.contains("\ntrigger_ms = 200  # default\n"), "{text}");

    // Without a running chassisd the levels are unknown, and the output says so.
    let out = env.run("chassis-safety", &["--print-config", "--name", "nobody"]);
    assert!(out.status.success(), "{out:?}");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("\n# max_linear_mps: unknown: until chassis/nobody's description is read\n"),
        "{text}"
    );
}

/// A SCOUT MINI on a real bus (slcan over a pty) is described as detecting, with its V1
/// profile's 5 m/s, until chassisd hears it speak V2 (3 m/s): the monitor takes the newer
/// description, and a runaway at 4 m/s — under the first level (5.55 m/s), over the new one
/// (3.35 m/s) — stops the robot. The runaway rule, which judges the speed against the command
/// and would stop it first, is off: this is the speed rule's level.
#[test]
fn the_monitor_takes_the_newer_description_when_protocol_detection_decides() {
    let mut env = Env::new("safety-detect");
    let n = name("sdt");
    let link = env.dir.join("scout-mini-slcan");
    let bus = Line::Slcan.bus(&link);
    // chassisd first: it serves, describes the robot as detecting, and waits for its bus.
    env.serve("scout-mini", &n, &["--bus", &bus]);
    let mut robot = env.robot(&n, UP);
    let config = env.write("safety.toml", "[rules.runaway]\nenabled = false\n");
    let monitor = env.spawn(
        "safety",
        "chassis-safety",
        &["--name", &n, "--config", &config],
    );
    let logged = |env: &mut Env, texts: &[&str]| {
        wait_for(Duration::from_secs(10), || {
            let log = env.proc(monitor).log_text();
            texts.iter().all(|t| log.contains(t))
        })
        .is_some()
    };
    let detecting = logged(
        &mut env,
        &[
            "(scout-mini, model scout-mini, protocol detecting); description seq",
            "speed rule: acts above 5.55 m/s either way",
        ],
    );
    assert!(detecting, "{}", env.logs());

    let pty = Line::Slcan.sim_bus(&link);
    env.sim("sim", "scout-mini", &["--protocol", "v2"], &n, &pty);
    let decided = logged(
        &mut env,
        &[
            "(scout-mini, model scout-mini, protocol v2); description seq",
            "speed rule: acts above 3.35 m/s either way",
        ],
    );
    assert!(decided, "{}", env.logs());

    let mut teleop = source(&mut robot, "teleop");
    let go = VelocityRequest::twist(0.5, 0.0);
    let moving = until_one(&mut robot, (&mut teleop, go), 10000, teleop_above(0.3));
    assert!(moving.is_some(), "no motion\n{}", env.logs());
    env.chassis_ok(&["sim", "--name", &n, "runaway", "4.0"]);
    let timeout = Duration::from_secs(5);
    stopped_by_the_monitor(
        &env,
        &mut robot,
        &mut teleop,
        go,
        timeout,
        "a runaway at 4 m/s",
    );
    let status = safety(&robot);
    assert!(status.is_active(SafetyRule::SPEED), "{status:?}");
    assert!(
        status.last_text().ends_with("> 3.35 m/s"),
        "{}",
        status.last_text()
    );
}
