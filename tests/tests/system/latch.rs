//! Latches that survive restarts: a held e-stop outlives `kill -9` of chassisd, whenever it
//! comes, and only `estop-release` frees it; an unreadable lock file starts the service with the
//! e-stop held.
// Test code: helpers outside #[test] functions may unwrap, panic and read the wall clock.
#![allow(clippy::unwrap_used, clippy::panic, clippy::disallowed_methods)]

use std::path::PathBuf;
use std::time::{Duration, Instant};

use chassis_tests::*;
use nix::sys::signal::Signal;

const UP: Duration = Duration::from_secs(10);

fn start(env: &mut Env, label: &str, n: &str) -> usize {
    env.chassisd(
        label,
        &["--robot", "titan", "--name", n, "--no-safety-monitor"],
    )
}

/// A test's environment (`test` names it) and chassisd labelled `first` for robot NAME (`tag`
/// and the pid): the environment, NAME, chassisd's index and a connection.
fn start_first(test: &str, tag: &str) -> (Env, String, usize, Robot) {
    let mut env = Env::new(test);
    let n = name(tag);
    let first = start(&mut env, "first", &n);
    let robot = env.robot(&n, UP);
    (env, n, first, robot)
}

fn lock_file(env: &Env, n: &str) -> PathBuf {
    env.state_home()
        .join("chassisd")
        .join(n)
        .join(format!("{n}.locks.json"))
}

/// Teleop asks for 0.3 m/s every 20 ms for `duration`; the largest speed the chassis reported.
fn drive(robot: &mut Robot, teleop: &mut Source, duration: Duration) -> f32 {
    let end = Instant::now() + duration;
    let mut max = 0.0f32;
    while Instant::now() < end {
        teleop.send(VelocityRequest::twist(0.3, 0.0)).unwrap();
        if let Ok(Some(state)) = robot.wait_state(Duration::from_millis(20)) {
            max = max.max(state.motion.linear_mps.abs());
        }
    }
    max
}

fn control(env: &Env, n: &str, action: &str) -> String {
    env.chassis_ok(&["control", "--name", n, action])
}

fn estop_held(robot: &mut Robot) -> (bool, u8) {
    let m = mux(robot);
    let index = m.lock_index("estop").unwrap();
    let lock = m.locks()[index];
    (lock.held == 1, lock.holder)
}

fn kill(env: &mut Env, index: usize) {
    env.proc(index).signal(Signal::SIGKILL);
    assert_eq!(env.proc(index).wait_exit(Duration::from_secs(3)), None);
    assert!(!env.proc(index).is_running());
}

/// After a restart with the e-stop held: teleop does not move the robot, the mux says why, and
/// `estop-release` frees it.
fn assert_held_until_released(env: &Env, n: &str, robot: &mut Robot, teleop: &mut Source) {
    assert_eq!(
        estop_held(robot),
        (true, LockStatus::HOLDER_OPERATOR),
        "{}",
        env.logs()
    );
    let peak = drive(robot, teleop, Duration::from_millis(800));
    assert!(peak < 0.01, "moved at {peak} m/s under a restored e-stop");
    let m = mux(robot);
    assert_eq!(m.output, BodyVelocity::ZERO);
    assert_eq!(m.zero_reason, ZeroReason::LOCKED);
    assert!(control(env, n, "estop-release").contains("estop released"));
    // A release never starts motion: teleop lets go, then drives again.
    teleop.send(VelocityRequest::twist(0.0, 0.0)).unwrap();
    let peak = drive(robot, teleop, Duration::from_secs(1));
    assert!(peak > 0.2, "no motion after the release and a zero: {peak}");
}

/// `chassis pub velocity` keeps asking as teleop for 0.3 m/s, in a process of its own, through
/// an e-stop and its release.
fn keep_asking(env: &mut Env, n: &str) -> usize {
    env.publish(
        "pub",
        n,
        &["--source", "teleop", "--vx", "0.3", "--rate", "20"],
    )
}

/// The fastest the chassis reported over `duration`, reading only.
fn peak_speed(robot: &mut Robot, duration: Duration) -> f32 {
    max_speed_polling(robot, duration, Duration::from_millis(20))
}

/// How long [`assert_release_waits_for_teleop`] watches the robot after the release.
const WATCHED_AFTER_RELEASE: Duration = Duration::from_millis(1500);

/// After `estop-release` with teleop still asking for motion: nothing moves, the answer, the
/// mux and `chassis status` say what the robot waits for. Returns the fastest the chassis
/// reported over [`WATCHED_AFTER_RELEASE`] after the release.
fn assert_release_waits_for_teleop(env: &Env, n: &str, robot: &mut Robot) -> f32 {
    let answer = control(env, n, "estop-release");
    assert!(
        answer.contains("nothing moves until teleop asks for zero"),
        "{answer}"
    );
    let peak = peak_speed(robot, WATCHED_AFTER_RELEASE);
    assert!(
        peak < 0.01,
        "moved at {peak} m/s after the release by itself"
    );
    let m = mux(robot);
    assert_eq!(m.output, BodyVelocity::ZERO);
    assert_eq!(m.zero_reason, ZeroReason::AWAITING_ZERO);
    assert_eq!(m.awaiting().map(|s| s.name()), Some("teleop"));
    let status = env.chassis(&["status", "--name", n]);
    let status = String::from_utf8_lossy(&status.stdout).to_string();
    assert!(
        status.contains("waiting for a zero from teleop since a lock was released"),
        "{status}"
    );
    peak
}

/// ISO 13850 / IEC 60204-1: resetting a stop shall not initiate a restart. The operator's
/// release leaves the robot still while teleop asks for motion; a zero from teleop (here: it
/// stops, and a new `chassis pub` asks again) lets it drive.
#[test]
fn an_estop_release_never_restarts_motion_by_itself() {
    let mut env = Env::new("latch-reset");
    let n = name("lr");
    start(&mut env, "chassisd", &n);
    let mut robot = env.robot(&n, UP);
    let asking = keep_asking(&mut env, &n);
    let moving = wait_for(Duration::from_secs(5), || {
        peak_speed(&mut robot, Duration::from_millis(100)) > 0.2
    });
    assert!(moving.is_some(), "chassis pub never drove\n{}", env.logs());
    assert!(control(&env, &n, "estop").contains("estop engaged"));
    assert_eq!(mux(&mut robot).output, BodyVelocity::ZERO);
    let stopped = wait_for(Duration::from_secs(5), || {
        peak_speed(&mut robot, Duration::from_millis(100)) < 0.001
    });
    assert!(stopped.is_some(), "the e-stop did not stop the chassis");
    let peak_after_release = assert_release_waits_for_teleop(&env, &n, &mut robot);
    // Teleop lets go: its publisher stops (its requests time out), then asks again.
    env.proc(asking).signal(Signal::SIGTERM);
    env.proc(asking).wait_exit(Duration::from_secs(3));
    pause(Duration::from_millis(400));
    keep_asking(&mut env, &n);
    let again = wait_for(Duration::from_secs(5), || {
        peak_speed(&mut robot, Duration::from_millis(100)) > 0.2
    });
    let mut figures = Figures::faults();
    figures.add(Figure {
        rank: 705,
        fault: "the e-stop released while teleop keeps asking for motion".into(),
        injection: "`chassis pub velocity --source teleop --vx 0.3 --rate 20` drives; \
            `chassis control estop`, then `estop-release` while it keeps asking; then it is \
            stopped (SIGTERM) and a new `chassis pub` asks again (a process that starts: its \
            library asks for nothing as it connects)"
            .into(),
        behaviour: "a release never starts motion (ISO 13850): the robot stood, the mux \
            commanded zero awaiting a zero from teleop, the answer and `chassis status` said so \
            (\"waiting for a zero from teleop since a lock was released\"); the new client's \
            connection was its zero, and it drove"
            .into(),
        figure: format!(
            "fastest {peak_after_release:.3} m/s over the {} ms after the release (bound \
             0.01 m/s; teleop asked for 0.3 throughout); driving again {} after teleop asked \
             anew",
            WATCHED_AFTER_RELEASE.as_millis(),
            again.map_or("never".to_string(), |d| format!("{} ms", d.as_millis()))
        ),
        value: f64::from(peak_after_release),
        pass: peak_after_release < 0.01 && again.is_some(),
        suite: "latch".into(),
        test: "an_estop_release_never_restarts_motion_by_itself".into(),
    });
    assert!(
        again.is_some(),
        "no motion once teleop asked again\n{}",
        env.logs()
    );
    figures.finish();
}

/// Silence is not a zero: teleop asks for motion through an e-stop and its release, then falls
/// silent for longer than its timeout (a lossy link, a stalled client) and asks again on the
/// same connection. The robot stands until teleop asks for zero.
#[test]
fn a_release_followed_by_a_silence_longer_than_the_timeout_still_waits_for_a_zero() {
    let (env, n, _first, mut robot) = start_first("latch-gap", "lg");
    let mut teleop = robot.source("teleop").unwrap();
    assert!(drive(&mut robot, &mut teleop, Duration::from_millis(800)) > 0.2);
    assert!(control(&env, &n, "estop").contains("estop engaged"));
    // The chassis brakes to a stop (a tail of a few mm/s at the end); then it stands under the
    // e-stop while teleop asks.
    let stopped = wait_for(Duration::from_secs(5), || {
        drive(&mut robot, &mut teleop, Duration::from_millis(100)) < 0.001
    });
    assert!(stopped.is_some(), "the e-stop did not stop the chassis");
    let held = drive(&mut robot, &mut teleop, Duration::from_millis(500));
    let answer = control(&env, &n, "estop-release");
    assert!(
        answer.contains("nothing moves until teleop asks for zero"),
        "{answer}"
    );
    // Silent for twice teleop's 300 ms timeout: its request expires.
    let gap = Duration::from_millis(600);
    pause(gap);
    let asked_again = now_ns();
    let standing = stands_until_zero(
        &mut robot,
        asked_again,
        ("teleop", &[Stop::LOCK_RELEASED]),
        || teleop.send(VelocityRequest::twist(0.3, 0.0)).unwrap(),
    );
    teleop.stop().unwrap();
    let again = drive(&mut robot, &mut teleop, Duration::from_secs(1));
    let stood = standing.as_ref().is_ok_and(StoodUntilZero::stood);
    let mut figures = Figures::faults();
    figures.add(Figure {
        rank: 706,
        fault: "the e-stop released, then teleop silent beyond its timeout and asking again".into(),
        injection: format!(
            "teleop (one connection) drives at 0.3 m/s; `chassis control estop`, \
             `estop-release` while it asks; then it sends nothing for {} ms (its timeout: 300 \
             ms) and asks for 0.3 m/s again",
            gap.as_millis()
        ),
        behaviour: "silence is not a zero: the robot stood after the gap, the mux waiting for \
            teleop's zero since the release, until teleop asked for zero; then it drove"
            .into(),
        figure: match &standing {
            Ok(s) => format!(
                "{} states over {} ms after teleop asked again, fastest {:.3} m/s (bound 0.01); \
                 {:.3} m/s under the held e-stop; {again:.2} m/s after its zero",
                s.samples,
                STOOD_FOR.as_millis(),
                s.fastest_mps,
                held
            ),
            Err(e) => e.clone(),
        },
        value: standing.as_ref().map_or(f64::NAN, |s| s.fastest_mps),
        pass: stood && held < 0.01 && again > 0.2,
        suite: "latch".into(),
        test: "a_release_followed_by_a_silence_longer_than_the_timeout_still_waits_for_a_zero"
            .into(),
    });
    assert!(held < 0.01, "moved at {held} m/s under the e-stop");
    assert!(
        stood,
        "moved after the gap by itself: {standing:?}\n{}",
        env.logs()
    );
    assert!(
        again > 0.2,
        "no motion after teleop's zero: {again}\n{}",
        env.logs()
    );
    figures.finish();
}

/// A latch restored after a restart obeys the same rule when it is released.
#[test]
fn the_release_of_a_latch_restored_after_a_restart_never_starts_motion() {
    let (mut env, n, first, mut robot) = start_first("latch-restored-reset", "lq");
    assert!(control(&env, &n, "estop").contains("estop engaged"));
    kill(&mut env, first);
    start(&mut env, "again", &n);
    let mut robot_again = env.robot(&n, UP);
    drop(robot);
    keep_asking(&mut env, &n);
    assert!(peak_speed(&mut robot_again, Duration::from_millis(800)) < 0.01);
    assert_eq!(
        estop_held(&mut robot_again),
        (true, LockStatus::HOLDER_OPERATOR)
    );
    assert_release_waits_for_teleop(&env, &n, &mut robot_again);
    robot = robot_again;
    assert!(peak_speed(&mut robot, Duration::from_millis(100)) < 0.01);
}

#[test]
fn a_held_estop_survives_sigkill_and_only_estop_release_frees_it() {
    let (mut env, n, first, mut robot) = start_first("latch-kill", "lk");
    let mut teleop = robot.source("teleop").unwrap();
    assert!(drive(&mut robot, &mut teleop, Duration::from_millis(800)) > 0.2);
    assert!(control(&env, &n, "estop").contains("estop engaged"));
    kill(&mut env, first);
    let again = start(&mut env, "again", &n);
    let mut robot = env.robot(&n, UP);
    assert_held_until_released(&env, &n, &mut robot, &mut teleop);
    let log = env.proc(again).log_text();
    assert!(
        log.contains("WARN") && log.contains("estop restored from before the restart"),
        "{log}"
    );
    assert!(log.contains("held by operator"), "{log}");
    // The release is kept too: killed again, it comes back free. Teleop kept asking through
    // the restart: chassisd starting is a stop too, so it drives only after its zero.
    kill(&mut env, again);
    start(&mut env, "third", &n);
    let mut robot = env.robot(&n, UP);
    assert!(!estop_held(&mut robot).0, "{}", env.logs());
    let peak = drive(&mut robot, &mut teleop, Duration::from_millis(800));
    assert!(peak < 0.01, "moved at {peak} m/s after a restart by itself");
    let m = mux(&mut robot);
    assert_eq!(m.zero_reason, ZeroReason::AWAITING_ZERO, "{}", m.why());
    assert_eq!(m.stop, Stop::SERVICE_START, "{}", m.why());
    teleop.stop().unwrap();
    assert!(drive(&mut robot, &mut teleop, Duration::from_secs(1)) > 0.2);
}

/// The e-stop is engaged through the library, so the answer itself is the moment the kill is
/// measured from: its arrival here, and its own stamp (`ControlResponse::stamp_ns`, chassisd's
/// clock at the pass that answered; the pass keeps the held set in the lock file — written and
/// fsynced — before it publishes the answer, so the stamp comes a few ms before the answer
/// leaves). The first round kills as soon as the answer arrives (0 ms after it), the others are
/// aimed 0-30 ms after the answer's stamp, one in each 6 ms of it; both delays achieved are
/// reported.
#[test]
fn an_answered_estop_is_held_after_a_kill_at_any_moment_after_the_answer() {
    let mut env = Env::new("latch-random");
    let n = name("lr");
    let mut rng = Rng::from_env("latch-random");
    let mut current = start(&mut env, "run0", &n);
    let mut robot = env.robot(&n, UP);
    let mut teleop = robot.source("teleop").unwrap();
    const ROUNDS: usize = 6;
    // Answer's arrival to SIGKILL, and answer's stamp to SIGKILL, ms, as achieved.
    let mut delays: Vec<(f64, f64)> = Vec::new();
    let mut held_after = 0;
    for round in 1..=ROUNDS {
        // At once, then one draw in each sixth of the 30 ms.
        let target = if round == 1 {
            Duration::ZERO
        } else {
            let sixth = Duration::from_millis(6);
            let from = sixth * u32::try_from(round - 2).unwrap();
            rng.between(from, from + sixth)
        };
        let answer = robot
            .control(
                ControlRequest::new(ControlKind::LOCK_ENGAGE).with_name("estop"),
                Duration::from_secs(3),
            )
            .unwrap();
        let arrived = now_ns();
        assert!(answer.is_ok(), "estop: {}", answer.message());
        assert!(answer.stamp_ns > 0, "an answer without its stamp");
        // Teleop keeps asking while the kill comes.
        let kill_at = answer.stamp_ns + u64::try_from(target.as_nanos()).unwrap();
        while now_ns() < kill_at {
            teleop.send(VelocityRequest::twist(0.3, 0.0)).unwrap();
            pause(
                Duration::from_millis(2)
                    .min(Duration::from_nanos(kill_at.saturating_sub(now_ns()))),
            );
        }
        let killed_at = now_ns();
        env.proc(current).signal(Signal::SIGKILL);
        delays.push((
            ms_between(arrived, killed_at),
            ms_between(answer.stamp_ns, killed_at),
        ));
        assert_eq!(env.proc(current).wait_exit(Duration::from_secs(3)), None);
        current = start(&mut env, &format!("run{round}"), &n);
        robot = env.robot(&n, UP);
        if estop_held(&mut robot).0 {
            held_after += 1;
        }
        assert_held_until_released(&env, &n, &mut robot, &mut teleop);
    }
    let spread = |pick: fn(&(f64, f64)) -> f64| {
        let mut v: Vec<f64> = delays.iter().map(pick).collect();
        v.sort_by(f64::total_cmp);
        (v[0], v[v.len() / 2], v[v.len() - 1])
    };
    let (arrival_min, arrival_median, arrival_max) = spread(|d| d.0);
    let (stamp_min, stamp_median, stamp_max) = spread(|d| d.1);
    // The window claimed was covered: a kill at once after the answer arrived (this thread's
    // own steps, under 5 ms even on a loaded machine), one late in the 30 ms, none before the
    // answer's stamp.
    let covered = (0.0..5.0).contains(&arrival_min) && stamp_min >= 0.0 && stamp_max >= 24.0;
    let list: Vec<String> = delays
        .iter()
        .map(|(arrival, stamp)| format!("{arrival:.1} ({stamp:.1})"))
        .collect();
    let mut figures = Figures::faults();
    figures.add(Figure {
        rank: 710,
        fault: "chassisd SIGKILLed with the e-stop held, and restarted".into(),
        injection: format!(
            "e-stop engaged (`LOCK_ENGAGE estop`), then SIGKILL {} ms after chassisd's answer \
             arrived (in brackets: after the answer's stamp, taken before the lock file was \
             written); the first at once, the others aimed 0-30 ms after the stamp (one in each \
             6 ms); teleop \
             asking for 0.3 m/s meanwhile; a new chassisd",
            list.join(", ")
        ),
        behaviour: "the restarted service holds the e-stop (restored from its state file, logged at WARN); teleop does not move the robot until `estop-release`"
            .into(),
        figure: format!(
            "held after {held_after} of {ROUNDS} restarts; kills {arrival_min:.1}-{arrival_max:.1} \
             ms after the answer arrived (median {arrival_median:.1} ms), \
             {stamp_min:.1}-{stamp_max:.1} ms after its stamp (median {stamp_median:.1} ms)"
        ),
        value: held_after as f64,
        pass: held_after == ROUNDS && covered,
        suite: "latch".into(),
        test: "an_answered_estop_is_held_after_a_kill_at_any_moment_after_the_answer".into(),
    });
    assert_eq!(held_after, ROUNDS, "{}", env.logs());
    assert!(covered, "kill delays after the answer: {delays:?} ms");
    figures.finish();
}

/// Milliseconds from `from_ns` to `to_ns` (negative when `to_ns` is earlier).
fn ms_between(from_ns: u64, to_ns: u64) -> f64 {
    (i128::from(to_ns) - i128::from(from_ns)) as f64 / 1e6
}

#[test]
fn a_corrupt_lock_file_starts_the_service_with_the_estop_held() {
    let mut env = Env::new("latch-corrupt");
    let n = name("lc");
    let file = lock_file(&env, &n);
    std::fs::create_dir_all(file.parent().unwrap()).unwrap();
    std::fs::write(&file, "{\"robot\":\"").unwrap();
    let index = start(&mut env, "chassisd", &n);
    let mut robot = env.robot(&n, UP);
    let mut teleop = robot.source("teleop").unwrap();
    let log = env.proc(index).log_text();
    assert!(log.contains("ERROR"), "{log}");
    assert!(log.contains("is not a held-lock file"), "{log}");
    assert!(log.contains("starting with estop held"), "{log}");
    let aside = file.with_file_name(format!("{n}.locks.json.corrupt"));
    assert_eq!(std::fs::read_to_string(&aside).unwrap(), "{\"robot\":\"");
    // The file now says what is held.
    let kept = std::fs::read_to_string(&file).unwrap();
    assert!(
        kept.contains("\"estop\"") && kept.contains("\"operator\""),
        "{kept}"
    );
    assert_held_until_released(&env, &n, &mut robot, &mut teleop);
    let kept = std::fs::read_to_string(&file).unwrap();
    assert!(kept.contains("\"locks\":[]"), "{kept}");
}
