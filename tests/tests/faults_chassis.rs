//! The fault matrix, the chassis: a simulated TITAN that does not do what it is told — it runs
//! away, drives against its command, ignores it, slips, or loses a motor driver mid-motion —
//! while teleop drives it at 0.5 m/s under chassis-safety, and a SCOUT MINI that turns against
//! its command on the spot (its yaw rate judged). Each row records the time from the
//! injection to the stop (the mux's output zero) and the distance the chassis travelled from
//! the injection to the stop and to its standstill, by the simulator's truth; a not-following
//! stop must name its cause in `SafetyStatus` and in `chassis status`. Figures are recorded
//! with [`Figures`] (`scripts/reliability`). The speed-limit row lowers the limit first (the
//! operator's `chassis control speed-limit`) and the chassis then runs over it.
//!
//! The stop distances: every robot of the registry, simulated, driven at 1 m/s and at its full
//! speed, stopped by the operator's e-stop of each stop category (0: the drive cut at once, 1:
//! cut once the chassis stands, 2: zero held with the drive enabled) while teleop keeps asking:
//! the time from the e-stop's answer to the standstill and the distance travelled, by the
//! simulator's truth (its chassis slows on a first-order lag toward the zero command, a shorter
//! one where the simulator documents one for a drive that does not obey), and the drive as the
//! mux status shows it.
// Test code: helpers outside #[test] functions may unwrap, panic and read the wall clock.
#![allow(clippy::unwrap_used, clippy::panic, clippy::disallowed_methods)]

use std::time::{Duration, Instant};

use chassis_protocols::RobotKind;
use chassis_tests::faults::*;
use chassis_tests::*;

const UP: Duration = Duration::from_secs(10);
const SUITE: &str = "faults_chassis";
/// The speed teleop asks for, m/s.
const SPEED_MPS: f32 = 0.5;
/// The longest a rule may take from the injection to the stop: the following rule's start
/// time (1 s at 0.5 m/s) and the chassis' lag, with room for a loaded machine.
const STOP_BOUND: Duration = Duration::from_secs(4);

/// One fault of the chassis and what must stop it.
struct Case {
    test: &'static str,
    tag: &'static str,
    rank: u32,
    fault: &'static str,
    injection: &'static str,
    behaviour: &'static str,
    request: Injected,
    /// The rule that must be in force once the robot stopped.
    rule: u8,
    /// The cause the following rule must name (`Unfollowed::NONE` for the others).
    cause: u8,
    /// The chassis stands once stopped (a runaway keeps going).
    stands: bool,
    /// The monitor's configuration beyond the defaults.
    config: &'static str,
    /// The speed limit set before the injection, m/s.
    speed_limit: Option<&'static str>,
    /// Teleop turns a SCOUT MINI on the spot at [`TURN_RADPS`] instead of driving the TITAN
    /// straight: the yaw rate is judged.
    turning: bool,
    /// The stop disables the drive at once (the monitor's latch asks for stop category 0).
    cut: bool,
}

/// The yaw rate teleop turns at, rad/s.
const TURN_RADPS: f32 = 0.4;

/// What a case drives and measures: the robot, teleop's request, the speed it reports (m/s or
/// rad/s), the simulator's truth of the position that speed moves (`x_m` or `yaw_rad`) and its
/// unit.
struct Axis {
    robot: &'static str,
    go: VelocityRequest,
    speed: fn(&ChassisState) -> f32,
    truth: &'static str,
    unit: &'static str,
}

impl Case {
    fn axis(&self) -> Axis {
        if self.turning {
            Axis {
                robot: "scout-mini",
                go: VelocityRequest::twist(0.0, TURN_RADPS),
                speed: |s| s.motion.angular_radps,
                truth: "yaw_rad",
                unit: "rad",
            }
        } else {
            Axis {
                robot: "titan",
                go: VelocityRequest::twist(SPEED_MPS, 0.0),
                speed: |s| s.motion.linear_mps,
                truth: "x_m",
                unit: "m",
            }
        }
    }
}

/// How a case makes the fault happen.
enum Injected {
    /// A fault injected into the simulated chassis.
    Sim(SimRequest),
    /// The operator's `chassis control` action (its arguments after `--name NAME`).
    Control(&'static [&'static str]),
}

fn injected(kind: u8, index: u8, value: f64) -> Injected {
    Injected::Sim(SimRequest {
        kind,
        flag: 1,
        index,
        value,
        ..SimRequest::default()
    })
}

/// The forward position of the chassis by its truth, m.
fn x_m(robot: &mut Robot) -> f64 {
    sim_truth(robot).get("x_m")
}

fn chassis_fault(case: &Case) {
    let _machine = shared();
    let mut env = Env::new(case.tag);
    let n = name(case.tag);
    let axis = case.axis();
    env.serve(axis.robot, &n, &[]);
    let mut robot = env.robot(&n, UP);
    // Long enough a release that the cause is still in force when `chassis status` reads it.
    let config = env.write(
        "safety.toml",
        &format!("[rules.following]\nrelease_ms = 5000\n{}", case.config),
    );
    env.spawn(
        "safety",
        "chassis-safety",
        &["--name", &n, "--config", &config],
    );
    // Teleop connects once the monitor drives the mux: its first request, a heartbeat, is the
    // zero motion starts from.
    let alive = wait_for(UP, || {
        source_status(&mux(&mut robot), "safety").has(SourceFlags::FRESH)
    });
    assert!(
        alive.is_some(),
        "the monitor never reached the mux\n{}",
        env.logs()
    );
    let mut teleop = source(&mut robot, "teleop");
    let full = axis.go.linear_x_mps.max(axis.go.angular_z_radps);
    let mut wire = Wire::new(&robot);
    let mut pump = Pump::new(&mut teleop, axis.go, &mut wire);
    let steady = pump.until(&mut robot, UP, |m, s| {
        source_status(m, "safety").has(SourceFlags::FRESH)
            && m.active().map(SourceStatus::name) == Some("teleop")
            && (axis.speed)(s) > full - 0.05
    });
    assert!(steady.is_some(), "no steady drive\n{}", env.logs());
    pump.run(&mut robot, Duration::from_millis(500));
    if let Some(limit) = case.speed_limit {
        env.chassis_ok(&["control", "--name", &n, "speed-limit", limit]);
        let max: f32 = limit.parse().unwrap();
        let capped = pump.until(&mut robot, UP, |_, s| s.motion.linear_mps < max + 0.02);
        assert!(
            capped.is_some(),
            "not capped to {limit} m/s\n{}",
            env.logs()
        );
        pump.run(&mut robot, Duration::from_millis(500));
    }

    let position = |robot: &mut Robot| sim_truth(robot).get(axis.truth);
    let unit = axis.unit;
    let x0 = position(&mut robot);
    let injected_at = Instant::now();
    match case.request {
        Injected::Sim(request) => {
            sim_ok(&mut robot, request);
        }
        Injected::Control(action) => {
            env.chassis_ok(&[&["control", "--name", n.as_str()], action].concat());
        }
    }
    // The drive as the first zero output found it: a category-0 latch has cut it already.
    let mut drive_at_stop = DriveState::ENABLED;
    let stopped = pump.until(&mut robot, STOP_BOUND, |m, _| {
        drive_at_stop = m.drive;
        m.output == BodyVelocity::ZERO
    });
    let x_stop = position(&mut robot);
    let status_text = env.chassis_ok(&["status", "--name", &n]);
    let standing = pump
        .until(&mut robot, STOP_BOUND, |_, s| (axis.speed)(s).abs() < 0.02)
        .is_some();
    let x_end = position(&mut robot);
    let mut sub = robot
        .subscriber::<SafetyStatus>(SafetyStatus::SERVICE)
        .unwrap()
        .unwrap();
    let status = sub.wait(Duration::from_secs(1)).unwrap().unwrap();

    let rule_held = status.is_active(case.rule);
    let named =
        case.cause == Unfollowed::NONE || status_text.contains(Unfollowed::text(case.cause));
    let cut = !case.cut || drive_at_stop == DriveState::CUT;
    let pass = stopped.is_some() && rule_held && named && standing == case.stands && cut;
    let stop_ms = stopped.map_or(f64::NAN, |d| d.as_secs_f64() * 1e3);
    let mut figures = Figures::faults();
    figures.add(fault_figure(
        SUITE,
        case.test,
        case.rank,
        case.fault,
        case.injection,
        case.behaviour,
        format!(
            "stopped {stop_ms:.0} ms after the injection ({} in force); {:.2} {unit} travelled \
             to the stop, {}",
            SafetyRule::name(case.rule),
            x_stop - x0,
            if standing {
                format!("{:.2} {unit} to the standstill", x_end - x0)
            } else {
                "still moving after the stop (the chassis does not obey)".into()
            },
        ) + &format!("; drive {} at the stop", DriveState::name(drive_at_stop)),
        stop_ms,
        pass,
    ));
    eprintln!(
        "{}: stop {stop_ms:.0} ms, {:.3} → {:.3} {unit}\n{status_text}",
        case.test,
        x_stop - x0,
        x_end - x0
    );
    assert!(
        stopped.is_some(),
        "no stop within {STOP_BOUND:?} (injected {:?} ago)\n{}",
        injected_at.elapsed(),
        env.logs()
    );
    assert!(
        rule_held,
        "{} not in force: {status:?}",
        SafetyRule::name(case.rule)
    );
    assert_eq!(
        Unfollowed::name(status.unfollowed),
        Unfollowed::name(case.cause),
        "{}",
        status.last_text()
    );
    assert!(
        named,
        "chassis status does not name the cause:\n{status_text}"
    );
    assert_eq!(standing, case.stands, "standing after the stop");
    assert!(
        cut,
        "the drive is {} at a category-0 latch's stop",
        DriveState::name(drive_at_stop)
    );
    figures.finish();
}

#[test]
fn a_chassis_running_away_from_its_command_is_latched() {
    chassis_fault(&Case {
        test: "a_chassis_running_away_from_its_command_is_latched",
        tag: "fcr",
        rank: 700,
        fault: "the chassis runs away: 1.2 m/s while commanded 0.5 m/s (TITAN)",
        injection: "`chassis sim runaway 1.2` while teleop drives at 0.5 m/s",
        behaviour: "the runaway rule latches the e-stop: the mux outputs zero until the \
                    operator releases it",
        request: injected(SimKind::RUNAWAY, 0, 1.2),
        rule: SafetyRule::RUNAWAY,
        cause: Unfollowed::NONE,
        stands: false,
        config: "",
        speed_limit: None,
        turning: false,
        cut: false,
    });
}

#[test]
fn a_chassis_driving_against_its_command_is_latched() {
    chassis_fault(&Case {
        test: "a_chassis_driving_against_its_command_is_latched",
        tag: "fcd",
        rank: 710,
        fault: "the chassis drives against its command (TITAN, wheels at −1 × the command)",
        injection: "`chassis sim gain -1` while teleop drives at 0.5 m/s",
        behaviour: "the direction rule latches the e-stop with stop category 0 (`[monitor.\
                    categories] direction = 0`): the drive is cut at once; the chassis stands",
        request: injected(SimKind::GAIN, 0, -1.0),
        rule: SafetyRule::DIRECTION,
        cause: Unfollowed::NONE,
        stands: true,
        config: "[monitor.categories]\ndirection = 0\n",
        speed_limit: None,
        turning: false,
        cut: true,
    });
}

#[test]
fn a_chassis_ignoring_its_command_is_stopped_and_the_cause_named() {
    chassis_fault(&Case {
        test: "a_chassis_ignoring_its_command_is_stopped_and_the_cause_named",
        tag: "fci",
        rank: 720,
        fault: "the chassis ignores its command and reports nothing (TITAN, wheels at 0 × the \
                command)",
        injection: "`chassis sim gain 0` while teleop drives at 0.5 m/s",
        behaviour: "the following rule stops after the time the robot needs to start; \
                    `chassis status` says the chassis reports no cause",
        request: injected(SimKind::GAIN, 0, 0.0),
        rule: SafetyRule::FOLLOWING,
        cause: Unfollowed::UNREPORTED,
        stands: true,
        config: "",
        speed_limit: None,
        turning: false,
        cut: false,
    });
}

#[test]
fn a_chassis_in_standby_is_stopped_and_the_cause_named() {
    chassis_fault(&Case {
        test: "a_chassis_in_standby_is_stopped_and_the_cause_named",
        tag: "fcb",
        rank: 725,
        fault: "the chassis in standby while commanded: it answers and does not drive (TITAN)",
        injection: "`chassis control mode standby` (the driver lets go of the chassis) while \
                    teleop drives at 0.5 m/s",
        behaviour: "the following rule stops after the time the robot needs to start; \
                    `chassis status` says the chassis is in standby",
        request: Injected::Control(&["mode", "standby"]),
        rule: SafetyRule::FOLLOWING,
        cause: Unfollowed::STANDBY,
        stands: true,
        config: "",
        speed_limit: None,
        turning: false,
        cut: false,
    });
}

#[test]
fn a_slipping_chassis_is_stopped_and_the_cause_named() {
    chassis_fault(&Case {
        test: "a_slipping_chassis_is_stopped_and_the_cause_named",
        tag: "fcs",
        rank: 730,
        fault: "the chassis slips: 10 % of the commanded speed (TITAN)",
        injection: "`chassis sim gain 0.1` while teleop drives at 0.5 m/s",
        behaviour: "the following rule stops after the time the robot needs to start; \
                    `chassis status` says the chassis reports no cause",
        request: injected(SimKind::GAIN, 0, 0.1),
        rule: SafetyRule::FOLLOWING,
        cause: Unfollowed::UNREPORTED,
        stands: true,
        config: "",
        speed_limit: None,
        turning: false,
        cut: false,
    });
}

#[test]
fn a_motor_driver_lost_mid_motion_stops_the_chassis() {
    chassis_fault(&Case {
        test: "a_motor_driver_lost_mid_motion_stops_the_chassis",
        tag: "fcm",
        rank: 740,
        fault: "a motor driver lost mid-motion (TITAN, driver 1)",
        injection: "`chassis sim motor-driver-loss 1` while teleop drives at 0.5 m/s",
        behaviour: "chassisd holds the mux at zero for the drive fault and the fault rule stops",
        request: injected(SimKind::MOTOR_DRIVER_LOSS, 1, 0.0),
        rule: SafetyRule::FAULT,
        cause: Unfollowed::NONE,
        stands: true,
        config: "",
        speed_limit: None,
        turning: false,
        cut: false,
    });
}

#[test]
fn a_chassis_running_over_its_speed_limit_is_stopped() {
    chassis_fault(&Case {
        test: "a_chassis_running_over_its_speed_limit_is_stopped",
        tag: "fcl",
        rank: 750,
        fault: "the chassis runs over a lowered speed limit: 0.3 m/s set, 1.6 × the command \
                measured (TITAN)",
        injection: "`chassis control speed-limit 0.3`, then `chassis sim gain 1.6` while teleop \
                    drives at 0.5 m/s; the runaway rule disabled, so the limit rule alone guards",
        behaviour: "the limit rule (SLS) stops once the measured speed is over the limit + \
                    0.1 m/s for 1 s; the chassis stands at the zero",
        request: injected(SimKind::GAIN, 0, 1.6),
        rule: SafetyRule::LIMIT,
        cause: Unfollowed::NONE,
        stands: true,
        config: "[rules.runaway]\nenabled = false\n[rules.limit]\nrelease_ms = 5000\n",
        speed_limit: Some("0.3"),
        turning: false,
        cut: false,
    });
}

#[test]
fn a_chassis_turning_against_its_command_is_latched() {
    chassis_fault(&Case {
        test: "a_chassis_turning_against_its_command_is_latched",
        tag: "fct",
        rank: 760,
        fault: "the chassis turns against its command (SCOUT MINI turning on the spot, wheels \
                at −1 × the command)",
        injection: "`chassis sim gain -1` while teleop turns on the spot at 0.4 rad/s",
        behaviour: "the direction rule, judging the yaw rate (the robot puts one on the wire), \
                    latches the e-stop; the chassis stands at the zero",
        request: injected(SimKind::GAIN, 0, -1.0),
        rule: SafetyRule::DIRECTION,
        cause: Unfollowed::NONE,
        stands: true,
        config: "",
        speed_limit: None,
        turning: true,
        cut: false,
    });
}

// ----- Stop distances -----

/// Up to `v` m/s, then the operator's e-stop of `category`: the time from its answer to the
/// simulator's standstill (ms), the distance travelled (m), by the simulator's truth, and the
/// drive as the mux status shows it once the robot stands; what went wrong otherwise (the speed
/// never reached, no standstill within [`STOP_BOUND`]).
fn stop_from(
    env: &Env,
    robot: &mut Robot,
    teleop: &mut Source,
    n: &str,
    v: f64,
    category: u8,
) -> Result<(f64, f64, u8), String> {
    let go = VelocityRequest::twist(v as f32, 0.0);
    let mut send = |robot: &mut Robot| {
        teleop.send(go).unwrap();
        let _ = robot.wait_state(Duration::from_millis(20));
    };
    wait_for(Duration::from_secs(20), || {
        send(robot);
        sim_truth(robot).get("linear_mps") >= 0.97 * v
    })
    .ok_or_else(|| format!("never reached {v:.2} m/s"))?;
    // The operator's e-stop, asked here rather than by a `chassis control estop` process (a
    // program's start-up is no part of the stop); the time and the distance run from its answer.
    let estop = ControlRequest::new(ControlKind::LOCK_ENGAGE)
        .with_name("estop")
        .with_arg(0, category + 1);
    let answer = robot.control(estop, Duration::from_secs(1)).unwrap();
    assert!(answer.is_ok(), "{}", answer.message());
    let x0 = x_m(robot);
    // Teleop keeps asking: the e-stop holds against it.
    let mut x_end = x0;
    let stood = wait_for(STOP_BOUND, || {
        send(robot);
        let truth = sim_truth(robot);
        x_end = truth.get("x_m");
        truth.get("linear_mps").abs() < 0.005
    })
    .ok_or_else(|| format!("from {v:.2} m/s: no standstill within {STOP_BOUND:?}"))?;
    // A category-1 stop cuts the drive once the chassis reports its standstill.
    let mut drive = DriveState::ENABLED;
    wait_for(Duration::from_millis(500), || {
        send(robot);
        drive = mux(robot).drive;
        drive != DriveState::BRAKING
    });
    env.chassis_ok(&["control", "--name", n, "estop-release"]);
    // Motion starts only from a zero.
    for _ in 0..10 {
        teleop.send(VelocityRequest::twist(0.0, 0.0)).unwrap();
        let _ = robot.wait_state(Duration::from_millis(20));
    }
    Ok((stood.as_secs_f64() * 1e3, x_end - x0, drive))
}

/// The drive a stop of `category` leaves, on a robot that can (`can_cut`) or cannot cut it.
fn expected_drive(category: u8, can_cut: bool) -> u8 {
    match category {
        StopCategory::HOLD => DriveState::ENABLED,
        _ if can_cut => DriveState::CUT,
        _ => DriveState::CANNOT_CUT,
    }
}

/// `robot`, simulated, stopped by the operator's e-stop of each category from 1 m/s and from its
/// full speed: its row recorded; true when it stood each time, its drive as the category says.
fn stop_distance(robot_name: &str, rank: u32) -> bool {
    let test = "stop_distances";
    let _machine = shared();
    let mut env = Env::new(&format!("stop-{robot_name}"));
    let n = name("fsd");
    env.serve(robot_name, &n, &["--no-safety-monitor"]);
    let mut robot = env.robot(&n, UP);
    let limits = robot.description(UP).unwrap();
    let full = limits
        .robot_limits
        .forward_mps
        .min(limits.configured_limits.forward_mps);
    // The e-stop's configured category says whether the robot can cut its drive.
    let can_cut = mux(&mut robot).locks()[0].category == StopCategory::BRAKE_THEN_CUT;
    let mut teleop = source(&mut robot, "teleop");
    let speeds: Vec<f64> = if full > 1.0 {
        vec![1.0, full]
    } else {
        vec![full]
    };
    let mut parts = Vec::new();
    let mut pass = true;
    let mut worst_ms = 0.0f64;
    for category in [
        StopCategory::CUT,
        StopCategory::BRAKE_THEN_CUT,
        StopCategory::HOLD,
    ] {
        let mut stops = Vec::new();
        for &v in &speeds {
            match stop_from(&env, &mut robot, &mut teleop, &n, v, category) {
                Ok((ms, m, drive)) => {
                    worst_ms = worst_ms.max(ms);
                    let expected = expected_drive(category, can_cut);
                    pass &= drive == expected;
                    stops.push(format!(
                        "from {v:.2} m/s {ms:.0} ms and {m:.3} m, drive {}{}",
                        DriveState::name(drive),
                        if drive == expected {
                            String::new()
                        } else {
                            format!(" (EXPECTED {})", DriveState::name(expected))
                        }
                    ));
                }
                Err(e) => {
                    pass = false;
                    stops.push(e);
                }
            }
        }
        parts.push(format!("category {category}: {}", stops.join(", ")));
    }
    let mut figures = Figures::faults();
    figures.add(fault_figure(
        SUITE,
        test,
        rank,
        &format!("the operator's e-stop of each stop category from 1 m/s and from full speed ({robot_name})"),
        "the operator's e-stop (the control request `chassis control estop --category N` \
         sends) of category 0, 1 and 2 while teleop drives straight at 1 m/s, then at the \
         robot's full speed (its description's forward limit), and keeps asking",
        "the mux holds zero against teleop and the chassis slows to a standstill within 4 s; \
         category 0 cuts the drive at once, 1 once the chassis stands, 2 leaves it enabled (a \
         robot that cannot cut its drive says so and holds zero)",
        format!("time and distance from the e-stop's answer to the standstill: {}", parts.join("; ")),
        worst_ms,
        pass,
    ));
    eprintln!("{robot_name}: {}", parts.join("; "));
    if !pass {
        eprintln!("{}", env.logs());
    }
    figures.finish();
    pass
}

#[test]
fn stop_distances() {
    let robots = RobotKind::ALL.map(RobotKind::name);
    let failed: Vec<&str> = (800..)
        .step_by(10)
        .zip(robots)
        .filter(|&(rank, robot)| !stop_distance(robot, rank))
        .map(|(_, robot)| robot)
        .collect();
    assert!(
        failed.is_empty(),
        "no standstill, or the drive not as its category says: {failed:?}"
    );
}
