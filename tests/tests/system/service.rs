//! chassisd with real processes: drive through the mux, preemption, timeouts, the required
//! safety source, locks, crashes and restarts, slcan and serial links over ptys.
// Test code: helpers outside #[test] functions may unwrap, panic and read the wall clock.
#![allow(clippy::unwrap_used, clippy::panic, clippy::disallowed_methods)]

use std::time::{Duration, Instant};

use chassis_tests::*;
use nix::sys::signal::Signal;

const UP: Duration = Duration::from_secs(10);

/// Sends `request` every 20 ms for `ms` milliseconds (and keeps a safety heartbeat if given);
/// returns the highest speed seen.
fn drive_for(
    robot: &mut Robot,
    teleop: &mut Source,
    mut safety: Option<&mut Source>,
    request: VelocityRequest,
    ms: u64,
) -> f32 {
    let end = Instant::now() + Duration::from_millis(ms);
    let mut max = 0.0f32;
    while Instant::now() < end {
        teleop.send(request).unwrap();
        if let Some(s) = safety.as_deref_mut() {
            s.heartbeat().unwrap();
        }
        if let Ok(Some(state)) = robot.wait_state(Duration::from_millis(20)) {
            max = max.max(state.motion.linear_mps.abs());
        }
    }
    max
}

/// SIGKILLs process `index`, the client of source `source`; returns how long after the kill the
/// mux decided `condition` (at most 2 s, `between` running meanwhile) and the source's timeout
/// the running mux reports.
fn sigkill_then(
    (env, robot): (&mut Env, &mut Robot),
    (index, source): (usize, &str),
    between: impl FnMut(),
    condition: impl FnMut(&MuxStatus) -> bool,
) -> (Option<Duration>, Duration) {
    let timeout = source_timeout(&mux(robot), source);
    let killed = now_ns();
    env.proc(index).signal(Signal::SIGKILL);
    let decided = decided_after(robot, killed, Duration::from_secs(2), between, condition);
    (decided, timeout)
}

#[test]
fn chassis_pub_drives_the_simulated_titan_and_it_stops_afterwards() {
    let (mut env, n, mut robot) =
        Env::serving("pub-drive", ("pub", "titan"), &["--no-safety-monitor"], UP);
    // What a user watches: `chassis echo state`, one JSON object per sample printed.
    let echo = env.spawn(
        "echo",
        "chassis",
        &["echo", "state", "--json", "--name", &n],
    );
    pause(Duration::from_millis(300));
    let publisher = env.publish(
        "pub",
        &n,
        &["--source", "teleop", "--vx", "0.3", "--duration", "2"],
    );
    let moving = max_speed(&mut robot, Duration::from_millis(2200));
    assert!(moving > 0.25, "peak speed {moving} m/s");
    assert_eq!(
        env.proc(publisher).wait_exit(Duration::from_secs(5)),
        Some(0)
    );
    let stopped = comes_to_rest(&mut robot, Duration::from_secs(3), 0.01);
    assert!(
        stopped.is_some(),
        "still moving after the publisher stopped\n{}",
        env.logs()
    );
    let s = state(&mut robot);
    assert!(s.odometry.x_m > 0.3, "travelled {} m", s.odometry.x_m);
    assert_eq!(s.command.linear_mps, 0.0);

    // `chassis echo state` showed the robot standing, moving, then standing again.
    pause(Duration::from_millis(300));
    env.proc(echo).signal(Signal::SIGINT);
    env.proc(echo).wait_exit(Duration::from_secs(3));
    let speeds: Vec<f64> = env
        .proc(echo)
        .log_text()
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter_map(|v| v["motion"]["linear_mps"].as_f64())
        .collect();
    let peak = speeds.iter().position(|v| *v > 0.25);
    assert!(
        speeds.first().is_some_and(|v| v.abs() < 0.01) && peak.is_some(),
        "chassis echo state: {speeds:?}\n{}",
        env.logs()
    );
    assert!(
        peak.is_some_and(|p| speeds[p..].iter().any(|v| v.abs() < 0.01)),
        "chassis echo state never showed the stop: {speeds:?}"
    );
}

#[test]
fn the_robot_moves_only_while_the_required_safety_monitor_is_alive() {
    let (mut env, n, mut robot) = Env::serving("required", ("req", "titan"), &[], UP);
    let mut teleop = source(&mut robot, "teleop");
    let request = VelocityRequest::twist(0.4, 0.0);
    let peak = drive_for(&mut robot, &mut teleop, None, request, 800);
    assert!(peak < 0.01, "moved to {peak} m/s without a safety monitor");
    assert_eq!(
        mux(&mut robot).zero_reason,
        ZeroReason::REQUIRED_SOURCE_STALE
    );

    let heartbeat = env.publish(
        "safety",
        &n,
        &["--source", "safety", "--heartbeat", "--rate", "20"],
    );
    let peak = drive_for(&mut robot, &mut teleop, None, request, 1500);
    assert!(peak > 0.3, "peak {peak} m/s with the monitor alive");

    // SIGKILL the monitor: its last heartbeat came before the kill, so the mux stops at most the
    // source's timeout after the kill (plus the allowance for a late decision or a late look).
    let (stopped, timeout) = sigkill_then(
        (&mut env, &mut robot),
        (heartbeat, "safety"),
        || teleop.send(request).unwrap(),
        |m| m.zero_reason == ZeroReason::REQUIRED_SOURCE_STALE && m.output == BodyVelocity::ZERO,
    );
    let stopped = stopped.unwrap_or_else(|| panic!("no safe stop\n{}", env.logs()));
    assert!(
        stopped <= timeout + DECISION_ALLOWANCE,
        "safe stop {stopped:?} after the kill (timeout {timeout:?})"
    );
    assert_eq!(mux(&mut robot).output, BodyVelocity::ZERO);
    eprintln!("required source killed → zero command after {stopped:?}");
}

#[test]
fn teleop_preempts_the_planner_and_hands_back_when_it_goes_quiet() {
    let (env, _, mut robot) =
        Env::serving("preempt", ("pre", "titan"), &["--no-safety-monitor"], UP);
    let mut planner = source(&mut robot, "planner");
    let mut teleop = source(&mut robot, "teleop");
    let until =
        |robot: &mut Robot, planner: &mut Source, teleop: Option<&mut Source>, want: &str| {
            let mut teleop = teleop;
            wait_for(Duration::from_secs(2), || {
                planner.send(VelocityRequest::twist(0.2, 0.0)).unwrap();
                if let Some(t) = teleop.as_deref_mut() {
                    t.send(VelocityRequest::twist(-0.1, 0.0)).unwrap();
                }
                mux(robot).active().map(|s| s.name().to_string()).as_deref() == Some(want)
            })
        };
    assert!(until(&mut robot, &mut planner, None, "planner").is_some());
    assert!(until(&mut robot, &mut planner, Some(&mut teleop), "teleop").is_some());
    let m = mux(&mut robot);
    assert_eq!(m.requested.linear_x_mps, -0.1);
    // Teleop sends once more and goes quiet: its last request is stamped after `quiet`, so the
    // planner cannot win before the source's timeout from then, and wins at its expiry (plus
    // the allowance for a late decision or a late look).
    let timeout = source_timeout(&m, "teleop");
    let quiet = now_ns();
    teleop.send(VelocityRequest::twist(-0.1, 0.0)).unwrap();
    let handed_back = decided_after(
        &mut robot,
        quiet,
        Duration::from_secs(2),
        || planner.send(VelocityRequest::twist(0.2, 0.0)).unwrap(),
        |m| m.active().map(SourceStatus::name) == Some("planner"),
    )
    .unwrap_or_else(|| panic!("never handed back\n{}", env.logs()));
    eprintln!("teleop quiet → planner active after {handed_back:?} (timeout {timeout:?})");
    assert!(
        handed_back >= timeout,
        "handed back {handed_back:?} after teleop's last request (timeout {timeout:?})"
    );
    assert!(
        handed_back <= timeout + DECISION_ALLOWANCE,
        "handed back {handed_back:?} after teleop's last request (timeout {timeout:?})"
    );
}

#[test]
fn a_latched_estop_holds_until_the_operator_releases_it() {
    let (env, n, mut robot) = Env::serving("estop", ("est", "titan"), &[], UP);
    let mut safety = source(&mut robot, "safety");
    let mut teleop = source(&mut robot, "teleop");
    let go = VelocityRequest::twist(0.3, 0.0);
    let peak = drive_for(&mut robot, &mut teleop, Some(&mut safety), go, 1000);
    assert!(peak > 0.2, "peak {peak}");
    let estop = mux(&mut robot).lock_index("estop").unwrap();
    safety.stop_and_lock(1 << estop).unwrap();
    // The safety source goes back to heartbeats; teleop keeps asking; the lock holds.
    let end = Instant::now() + Duration::from_millis(1500);
    while Instant::now() < end {
        teleop.send(go).unwrap();
        safety.heartbeat().unwrap();
        // Safety's own stop wins first, then (after its next heartbeat) the lock holds.
        let m = mux(&mut robot);
        assert_eq!(
            m.output,
            BodyVelocity::ZERO,
            "commanded motion under the e-stop"
        );
    }
    let s = state(&mut robot);
    assert!(
        s.motion.linear_mps.abs() < 0.01,
        "still rolling at {}",
        s.motion.linear_mps
    );
    safety.heartbeat().unwrap();
    let m = mux(&mut robot);
    assert_eq!(m.zero_reason, ZeroReason::LOCKED);
    assert_eq!(m.locks()[estop].held, 1);
    assert_eq!(m.locks()[estop].holder, 0, "held by the safety source");
    let out = env.chassis(&["control", "--name", &n, "estop-release"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("estop released"));
    // A release never starts motion (tests/tests/system/latch.rs): teleop lets go first, while the
    // safety source beats again (it was silent while `chassis control` ran: its return is a
    // stop's end too, and only a zero after it counts).
    let zero = VelocityRequest::twist(0.0, 0.0);
    drive_for(&mut robot, &mut teleop, Some(&mut safety), zero, 300);
    let peak = drive_for(&mut robot, &mut teleop, Some(&mut safety), go, 1000);
    assert!(peak > 0.2, "no motion after the release: {peak}");
}

#[test]
fn a_client_killed_mid_drive_is_harmless_and_its_source_can_be_taken_again() {
    let (mut env, n, mut robot) =
        Env::serving("client-kill", ("ck", "titan"), &["--no-safety-monitor"], UP);
    let args = [
        "pub", "velocity", "--source", "teleop", "--vx", "0.3", "--name", &n,
    ];
    let first = env.spawn("pub1", "chassis", &args);
    assert!(max_speed(&mut robot, Duration::from_millis(1200)) > 0.2);
    // The dead client's last request came before the kill: the mux commands zero at most the
    // source's timeout after it (plus the allowance for a late decision or a late look).
    let (zero, timeout) = sigkill_then(
        (&mut env, &mut robot),
        (first, "teleop"),
        || {},
        |m| m.output == BodyVelocity::ZERO,
    );
    let zero = zero.unwrap_or_else(|| panic!("still commanding after the kill\n{}", env.logs()));
    eprintln!("teleop SIGKILLed → zero command after {zero:?} (timeout {timeout:?})");
    assert!(
        zero <= timeout + DECISION_ALLOWANCE,
        "zero command {zero:?} after the kill (timeout {timeout:?})"
    );
    let second = env.spawn("pub2", "chassis", &args);
    assert!(
        max_speed(&mut robot, Duration::from_millis(1500)) > 0.2,
        "a new teleop could not drive\n{}",
        env.logs()
    );
    env.proc(second).signal(Signal::SIGINT);
    assert_eq!(env.proc(second).wait_exit(Duration::from_secs(3)), Some(0));
}

#[test]
fn a_second_chassisd_for_the_same_robot_is_refused_and_the_first_is_unharmed() {
    let mut env = Env::new("second");
    let n = name("sec");
    let first = env.serve_as("first", ("titan", &n), &["--no-safety-monitor"]);
    let mut robot = env.robot(&n, UP);
    let started = Instant::now();
    let second = env.serve_as("second", ("titan", &n), &["--no-safety-monitor"]);
    let code = env.proc(second).wait_exit(Duration::from_secs(10));
    let refused_in = started.elapsed();
    let seq = state(&mut robot).seq;
    pause(Duration::from_millis(200));
    let unharmed = env.proc(first).is_running() && state(&mut robot).seq > seq;
    let message = env.proc(second).log_text();
    let message = message
        .lines()
        .find(|l| l.contains("another chassisd"))
        .unwrap_or("")
        .trim();
    let mut figures = Figures::faults();
    figures.add(Figure {
        rank: 700,
        fault: "a second chassisd for the same robot name".into(),
        injection: "`chassisd --robot titan --name N` while one already serves N".into(),
        behaviour: format!(
            "refused at start with exit code {code:?} and \"{}\"; the first one kept \
             publishing",
            message
                .split("another chassisd")
                .nth(1)
                .map_or(String::new(), |rest| format!("another chassisd{rest}"))
        ),
        figure: format!(
            "refused {:.0} ms after its start; first instance unharmed: {unharmed}",
            refused_in.as_secs_f64() * 1e3
        ),
        value: refused_in.as_secs_f64() * 1e3,
        pass: code == Some(1) && unharmed,
        suite: "service".into(),
        test: "a_second_chassisd_for_the_same_robot_is_refused_and_the_first_is_unharmed".into(),
    });
    assert_eq!(code, Some(1), "{}", env.logs());
    assert!(
        env.proc(second)
            .log_text()
            .contains("another chassisd already serves the robot"),
        "{}",
        env.logs()
    );
    assert!(env.proc(first).is_running());
    let before = state(&mut robot).seq;
    pause(Duration::from_millis(200));
    assert!(
        state(&mut robot).seq > before,
        "the first one stopped publishing"
    );
    figures.finish();
}

#[test]
fn a_service_killed_with_sigkill_restarts_cleanly_and_clients_reconnect() {
    let mut env = Env::new("restart");
    let n = name("rs");
    let first = env.serve_as("first", ("titan", &n), &["--no-safety-monitor"]);
    let mut robot = env.robot(&n, UP);
    let mut teleop = source(&mut robot, "teleop");
    let go = VelocityRequest::twist(0.3, 0.0);
    assert!(drive_for(&mut robot, &mut teleop, None, go, 1000) > 0.2);
    env.proc(first).signal(Signal::SIGKILL);
    env.proc(first).wait_exit(Duration::from_secs(3));
    let restarted = now_ns();
    let again = env.serve_as("again", ("titan", &n), &["--no-safety-monitor"]);
    // The old client keeps its source and keeps asking; the new service reads it. chassisd
    // starting is a stop: the robot stands until teleop asks for zero.
    let standing = stands_until_zero(
        &mut robot,
        restarted,
        ("teleop", &[Stop::SERVICE_START]),
        || teleop.send(go).unwrap(),
    );
    assert!(
        standing.as_ref().is_ok_and(StoodUntilZero::stood),
        "{standing:?}\n{}",
        env.logs()
    );
    teleop.stop().unwrap();
    let zero_sent = now_ns();
    // A speed reported after the zero.
    let back = drove_again_after(
        &mut robot,
        zero_sent,
        Duration::from_secs(10),
        || teleop.send(go).unwrap(),
        |s| s.motion.linear_mps > 0.2,
    );
    assert!(
        back.is_some(),
        "no motion after the restart and teleop's zero\n{}",
        env.logs()
    );
    assert!(env.proc(again).is_running());
}

#[test]
fn sigterm_commands_zero_and_exits_zero() {
    let mut env = Env::new("sigterm");
    let n = name("term");
    let service = env.serve("titan", &n, &["--no-safety-monitor"]);
    let mut robot = env.robot(&n, UP);
    let mut teleop = source(&mut robot, "teleop");
    let go = VelocityRequest::twist(0.3, 0.0);
    drive_for(&mut robot, &mut teleop, None, go, 600);
    let tap = robot.frames(512).unwrap();
    env.proc(service).signal(Signal::SIGTERM);
    assert_eq!(env.proc(service).wait_exit(Duration::from_secs(5)), Some(0));
    let mut last_motion = None;
    let mut brake_engaged = false;
    tap.drain(|f| {
        if f.direction == FrameDirection::TX && f.can_id == 0x111 {
            last_motion = Some(f.payload().to_vec());
        }
        if f.direction == FrameDirection::TX && f.can_id == 0x131 && f.payload() == [0x00] {
            brake_engaged = true;
        }
    })
    .unwrap();
    assert_eq!(
        last_motion.as_deref(),
        Some(&[0u8; 8][..]),
        "last 0x111 is not a stop"
    );
    assert!(
        brake_engaged,
        "the parking brake was not engaged on the way out"
    );
    assert!(
        env.proc(service)
            .log_text()
            .contains("stopping: commanding zero")
    );
}

/// A signal that interrupts a client's wait is no failure: `chassis echo` stopped (Ctrl-Z) and
/// continued (`fg`) three times goes on printing, on each of its topics (the client library's
/// state, mux and frame waits), and SIGINT then ends it with 0.
#[test]
fn a_client_stopped_and_continued_goes_on_and_sigint_ends_it_with_zero() {
    let (mut env, n, _robot) = Env::serving(
        "stop-continue",
        ("stopcont", "titan"),
        &["--no-safety-monitor"],
        UP,
    );
    fn printed(env: &mut Env, echo: usize) -> usize {
        env.proc(echo).log_text().lines().count()
    }
    for topic in ["state", "mux", "frames"] {
        let echo = env.spawn(
            &format!("echo-{topic}"),
            "chassis",
            &["echo", topic, "--name", &n],
        );
        assert!(
            wait_for(UP, || printed(&mut env, echo) > 0).is_some(),
            "echo {topic} printed nothing:\n{}",
            env.logs()
        );
        env.proc(echo).stop_and_continue(3);
        let before = printed(&mut env, echo);
        let goes_on = wait_for(Duration::from_secs(3), || {
            printed(&mut env, echo) > before + 2
        });
        assert!(
            goes_on.is_some() && env.proc(echo).is_running(),
            "echo {topic} stopped printing after a stop and a continue:\n{}",
            env.proc(echo).log_text()
        );
        env.proc(echo).signal(Signal::SIGINT);
        assert_eq!(
            env.proc(echo).wait_exit(Duration::from_secs(5)),
            Some(0),
            "echo {topic} after SIGINT:\n{}",
            env.proc(echo).log_text()
        );
    }
}

/// The same for the simulated chassis of a pty: `chassisd sim` stopped and continued keeps
/// simulating (chassisd over the pty reads its feedback again); SIGTERM ends it with 0.
#[test]
fn a_simulated_chassis_stopped_and_continued_goes_on_and_sigterm_ends_it_with_zero() {
    let mut env = Env::new("sim-stop-continue");
    let n = name("simcont");
    let link = env.dir.join("titan-slcan");
    let (sim, mut robot) = env.over_pty(("titan", &n), Line::Slcan, &link, &[], UP);
    env.proc(sim).stop_and_continue(3);
    let frames = |robot: &mut Robot| state(robot).link.rx_frames;
    let before = frames(&mut robot);
    let again = wait_for(Duration::from_secs(3), || frames(&mut robot) > before + 10);
    assert!(
        again.is_some() && env.proc(sim).is_running(),
        "no feedback after the simulator was stopped and continued\n{}",
        env.logs()
    );
    env.proc(sim).signal(Signal::SIGTERM);
    assert_eq!(
        env.proc(sim).wait_exit(Duration::from_secs(5)),
        Some(0),
        "{}",
        env.proc(sim).log_text()
    );
}

#[test]
fn a_state_stream_sees_every_sample_of_a_flooded_bus_that_a_latest_value_reader_loses() {
    // Never beside the bench's busy loops (bench.rs), which would starve the flood.
    let _machine = chassis_tests::faults::shared();
    let (env, n, mut robot) =
        Env::serving("stream", ("strm", "titan"), &["--no-safety-monitor"], UP);
    // The buffer asked for is clamped to 1..=the service's maximum.
    assert_eq!(robot.state_stream(0).unwrap().buffer(), 1);
    let stream = robot.state_stream(usize::MAX).unwrap();
    assert_eq!(stream.buffer(), STATE_BUFFER);
    // Beside it, a reader with a `Robot`'s own latest-value subscriber.
    let mut latest = Robot::connect_with_prefix(&n, Some(&env.prefix)).unwrap();

    // 2000 frames/s on top of the chassis' feedback: past the saturation of the receive
    // moderation, so the service reads the bus once per 4 ms and publishes the state in bursts.
    // The extra frames are copies of the motion and motor feedback, so each one changes the
    // state (odometry, motor positions) only while the robot moves: it drives throughout.
    let mut teleop = source(&mut robot, "teleop");
    let drive = VelocityRequest::twist(0.3, 0.0);
    let answer = robot
        .sim(
            chassis_client::flood_request(2000.0),
            Duration::from_secs(3),
        )
        .unwrap();
    assert!(answer.is_ok(), "{}", answer.message());
    let moving = drive_for(&mut robot, &mut teleop, None, drive, 800);
    assert!(moving > 0.1, "peak speed {moving} m/s\n{}", env.logs());
    stream.drain(|_| {}).unwrap();
    latest.poll_states(|_| {}).unwrap();

    // A reader busy for 6 ms between reads: one or two bursts are waiting each time.
    let (mut received, mut gaps, mut lost, mut largest) = (0u64, 0u64, 0u64, 0usize);
    let mut last: Option<u64> = None;
    let (mut latest_received, mut latest_lost) = (0u64, 0u64);
    let mut latest_last: Option<u64> = None;
    let started = Instant::now();
    while started.elapsed() < Duration::from_secs(2) {
        teleop.send(drive).unwrap();
        pause(Duration::from_millis(6));
        let batch = stream
            .wait(Duration::from_millis(100), |s| {
                received += 1;
                if let Some(seq) = last
                    && s.seq != seq + 1
                {
                    gaps += 1;
                    lost += s.seq.saturating_sub(seq + 1);
                }
                last = Some(s.seq);
            })
            .unwrap();
        largest = largest.max(batch);
        latest
            .poll_states(|s| {
                latest_received += 1;
                if let Some(seq) = latest_last {
                    latest_lost += s.seq.saturating_sub(seq + 1);
                }
                latest_last = Some(s.seq);
            })
            .unwrap();
    }
    eprintln!(
        "stream: {received} samples, {gaps} gaps ({lost} lost), up to {largest} per read; \
         latest-value reader: {latest_received} received, {latest_lost} lost"
    );
    assert_eq!(
        (gaps, lost),
        (0, 0),
        "the stream lost {lost} samples in {gaps} gaps\n{}",
        env.logs()
    );
    // The flood flowed, and a read found more samples than a latest-value subscriber keeps:
    // the reader above would have lost samples without the stream's buffer.
    assert!(received >= 3000, "only {received} samples in 2 s");
    assert!(largest > 4, "at most {largest} samples per read");
    assert!(
        latest_lost > 0,
        "the latest-value reader lost nothing ({latest_received} received)"
    );
}

#[test]
fn control_requests_are_answered_with_success_or_a_reason() {
    let (env, n, _robot) = Env::serving("control", ("ctl", "titan"), &["--no-safety-monitor"], UP);
    let ok = env.chassis_ok(&["control", "--name", &n, "off-road", "on"]);
    assert_eq!(ok.trim(), "ok: off-road mode on");
    let unsupported = env.chassis(&["control", "--name", &n, "lift", "--position", "50"]);
    assert_eq!(unsupported.status.code(), Some(1));
    assert!(
        String::from_utf8_lossy(&unsupported.stderr).contains("unsupported: titan has no lift")
    );
    let zero = env.chassis_ok(&["control", "--name", &n, "steering-zero"]);
    assert_eq!(zero.trim(), "ok: steering zero set");
    let missing = env.chassis(&["status", "--name", "nobody"]);
    assert_eq!(missing.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&missing.stderr).contains("is chassisd running?"));
}

#[test]
fn titan_drives_over_slcan_ptys_against_chassisd_sim_and_survives_a_hang_up() {
    let mut env = Env::new("slcan");
    let n = name("sl");
    let link = env.dir.join("titan-slcan");
    let (sim, mut robot) = env.over_pty(("titan", &n), Line::Slcan, &link, &[], UP);
    let mut teleop = source(&mut robot, "teleop");
    let go = VelocityRequest::twist(0.3, 0.0);
    let peak = drive_for(&mut robot, &mut teleop, None, go, 2000);
    assert!(peak > 0.2, "peak {peak} over slcan\n{}", env.logs());

    // Hang-up: the simulated chassis (and its pty) vanish.
    let hang_up = HangUp {
        rank: 200,
        fault: "slcan adapter hang-up (TITAN over an slcan pty)",
        injection: "SIGKILL of `chassisd sim --bus slcan-pty:…` mid-drive, restarted",
        end: "adapter",
        above_mps: 0.1,
        source: "teleop",
        suite: "service",
        test: "titan_drives_over_slcan_ptys_against_chassisd_sim_and_survives_a_hang_up",
    };
    let (figures, back) = hang_up.run(
        (&mut env, &mut robot),
        (sim, "titan", &n),
        (Line::Slcan, &link),
        |zero| {
            let request = if zero {
                VelocityRequest::twist(0.0, 0.0)
            } else {
                go
            };
            teleop.send(request).unwrap();
        },
    );
    assert!(
        back.is_some(),
        "no motion after the zero that followed the reconnection, or the robot did not stand \
         before it\n{}",
        env.logs()
    );
    let s = state(&mut robot);
    assert!(
        s.link.bus_reconnects >= 1,
        "reconnects {}",
        s.link.bus_reconnects
    );
    figures.finish();
}

#[test]
fn a_robot_on_a_bus_of_the_wrong_kind_is_refused_at_start_with_the_kinds_it_accepts() {
    let mut env = Env::new("wrong-bus");
    let n = name("wb");
    let index = env.serve("titan", &n, &["--bus", "serial:/dev/ttyUSB0"]);
    assert_eq!(env.proc(index).wait_exit(Duration::from_secs(5)), Some(2));
    let log = env.proc(index).log_text();
    assert!(
        log.contains("titan cannot be on serial:/dev/ttyUSB0")
            && log.contains("can:IFACE, slcan:PATH[@BAUD]"),
        "{log}"
    );
}

/// SCOUT MINI, SCOUT and BUNKER exist with V1 and with V2 firmware: without `--protocol`
/// chassisd listens first and drives each in the protocol it hears.
#[test]
fn scout_mini_scout_and_bunker_without_a_protocol_flag_drive_a_v1_and_a_v2_chassis_alike() {
    for (robot, protocol) in [
        ("scout-mini", "v1"),
        ("scout-mini", "v2"),
        ("scout", "v1"),
        ("scout", "v2"),
        ("bunker", "v1"),
        ("bunker", "v2"),
    ] {
        let mut env = Env::new(&format!("detect-{robot}-{protocol}"));
        let n = name(&format!("d{}{protocol}", &robot[..2]));
        let link = env.dir.join("agilex-slcan");
        let extra = ["--protocol", protocol];
        let (_, bus) = env.sim_on_pty(robot, &extra, &n, Line::Slcan, &link, UP);
        env.serve(robot, &n, &["--bus", &bus, "--no-safety-monitor"]);
        let mut handle = env.robot(&n, UP);
        let mut teleop = source(&mut handle, "teleop");
        let go = VelocityRequest::twist(0.3, 0.0);
        let peak = drive_for(&mut handle, &mut teleop, None, go, 2000);
        assert!(
            peak > 0.2,
            "{robot} {protocol}: peak {peak}\n{}",
            env.logs()
        );
        let logs = env.logs();
        assert!(
            logs.contains(&format!(
                "{} speaks protocol {protocol}",
                robot.replace('-', " ").to_uppercase()
            )),
            "{robot} {protocol}: no detection line\n{logs}"
        );
        let status = env.chassis(&["status", "--name", &n]);
        let status = String::from_utf8_lossy(&status.stdout);
        assert!(
            status.contains(&format!("protocol {protocol}")),
            "{robot} {protocol}: {status}"
        );
        // Not one frame of the other protocol reached the chassis: a V2 frame on a V1 chassis
        // is an unknown id or a bad checksum there, a V1 frame on a V2 chassis an unknown id.
        let truth = sim_truth(&mut handle);
        assert!(
            truth.get("commands") > 50.0,
            "{robot} {protocol}: {truth:?}"
        );
        assert_eq!(
            truth.get("rejected"),
            0.0,
            "{robot} {protocol}: frames of the wrong protocol reached the chassis\n{}",
            env.logs()
        );
    }
}

/// A BUNKER that says nothing: chassisd sends nothing, reports `chassis silent` with a log line
/// naming what it heard and keeps listening; once the chassis speaks V2 it decides, and what it
/// sends from then on is V2. The slcan adapter is a pty this test holds.
#[test]
fn a_silent_bunker_is_reported_and_retried_and_decided_once_it_speaks() {
    use std::io::{Read, Write};
    use std::os::fd::AsFd;

    let mut env = Env::new("detect-silent");
    let n = name("dsil");
    let pty = nix::pty::openpty(None, None).unwrap();
    let slave_path = nix::unistd::ttyname(pty.slave.as_fd()).unwrap();
    let config = env.write("bunker.toml", "[profile]\ndetect_timeout_ms = 1000\n");
    let bus = format!("slcan:{}", slave_path.display());
    env.serve(
        "bunker",
        &n,
        &["--bus", &bus, "--no-safety-monitor", "--config", &config],
    );
    let mut handle = env.robot(&n, UP);
    let silent = wait_for(Duration::from_secs(3), || {
        state(&mut handle).link_flags & LinkFlags::CHASSIS_SILENT != 0
    });
    assert!(silent.is_some(), "not reported silent\n{}", env.logs());
    let status = env.chassis(&["status", "--name", &n]);
    let status = String::from_utf8_lossy(&status.stdout);
    assert!(
        status.contains("chassis silent") && status.contains("protocol detecting"),
        "{status}"
    );
    assert!(
        env.logs().contains(
            "BUNKER protocol not detected within 1000 ms: nothing heard on the bus \
             (wiring, bit rate, chassis off?); listening again"
        ),
        "{}",
        env.logs()
    );
    // Only the adapter's setup (`C`, bit rate, `O`) came out of chassisd: no CAN frame.
    let mut master = std::fs::File::from(pty.master);
    nix::fcntl::fcntl(
        master.as_fd(),
        nix::fcntl::FcntlArg::F_SETFL(nix::fcntl::OFlag::O_NONBLOCK),
    )
    .unwrap();
    let drain = |master: &mut std::fs::File| {
        let mut text = Vec::new();
        let mut buf = [0u8; 4096];
        while let Ok(got) = master.read(&mut buf) {
            if got == 0 {
                break;
            }
            text.extend_from_slice(&buf[..got]);
        }
        String::from_utf8_lossy(&text).into_owned()
    };
    let before = drain(&mut master);
    assert_eq!(before, "C\rS6\rO\r", "sent while listening");
    // The chassis speaks V2 (0x221 motion feedback, 0x211 status in standby): decided.
    let decided = wait_for(Duration::from_secs(3), || {
        master
            .write_all(b"t22180000000000000000\rt21180000010000000000\r")
            .unwrap();
        state(&mut handle).system.wire_protocol == WireProtocol::V2
    });
    assert!(decided.is_some(), "not decided\n{}", env.logs());
    let logged = wait_for(Duration::from_secs(3), || {
        env.logs().contains("BUNKER speaks protocol v2")
    });
    assert!(logged.is_some(), "{}", env.logs());
    // A few heartbeat periods of what it sends now.
    std::thread::sleep(Duration::from_millis(200));
    let after = drain(&mut master);
    let ids: std::collections::BTreeSet<&str> = after
        .split('\r')
        .filter_map(|line| line.strip_prefix('t'))
        .filter_map(|frame| frame.get(..3))
        .collect();
    assert!(ids.contains("421") && ids.contains("111"), "{after:?}");
    assert!(
        ids.iter()
            .all(|id| ["111", "421", "411", "4A1"].contains(id)),
        "{ids:?}"
    );
}

/// A protocol-V2 chassis' own E-stop switch (`chassis sim estop-switch`): the robot stops, the
/// mux holds zero naming it; released, the robot stands while teleop keeps asking (motion starts
/// only from a zero: the mux waits for teleop's zero since the switch was released), and drives
/// again only after teleop asked for zero.
#[test]
fn a_v2_chassis_estop_switch_stops_it_and_only_a_zero_command_lets_it_drive_again() {
    let (env, _, mut robot) = Env::serving(
        "estop-switch",
        ("esw", "hunter"),
        &["--no-safety-monitor"],
        UP,
    );
    let mut teleop = source(&mut robot, "teleop");
    let go = VelocityRequest::twist(0.4, 0.0);
    let peak = drive_for(&mut robot, &mut teleop, None, go, 2000);
    assert!(peak > 0.3, "peak {peak}\n{}", env.logs());
    let switch = |robot: &mut Robot, on: bool| {
        let answer = robot
            .sim(
                SimRequest {
                    kind: SimKind::ESTOP_SWITCH,
                    flag: u8::from(on),
                    ..SimRequest::default()
                },
                Duration::from_secs(2),
            )
            .unwrap();
        assert!(answer.is_ok(), "{}", answer.message());
    };
    switch(&mut robot, true);
    drive_for(&mut robot, &mut teleop, None, go, 1000);
    let s = state(&mut robot);
    assert!(s.motion.linear_mps.abs() < 0.05, "{}", s.motion.linear_mps);
    assert_ne!(s.system.fault_flags & FaultFlags::EMERGENCY_STOP, 0);
    let m = mux(&mut robot);
    assert_eq!(
        (m.zero_reason, m.stop),
        (ZeroReason::HELD, Stop::CHASSIS_ESTOP),
        "{}",
        m.why()
    );
    let released = now_ns();
    switch(&mut robot, false);
    let standing = stands_until_zero(
        &mut robot,
        released,
        ("teleop", &[Stop::CHASSIS_ESTOP]),
        || teleop.send(go).unwrap(),
    );
    assert!(
        standing.as_ref().is_ok_and(StoodUntilZero::stood),
        "moved on its own after the release: {standing:?}"
    );
    let s = state(&mut robot);
    assert_eq!(s.system.fault_flags & FaultFlags::EMERGENCY_STOP, 0);
    let stop = VelocityRequest::twist(0.0, 0.0);
    drive_for(&mut robot, &mut teleop, None, stop, 300);
    let again = drive_for(&mut robot, &mut teleop, None, go, 2000);
    let standing = standing.unwrap_or_else(|e| panic!("{e}"));
    let mut figures = Figures::faults();
    figures.add(Figure {
        rank: 707,
        fault: "the chassis' own E-stop switch (HUNTER 2.0, protocol V2) pressed and released"
            .into(),
        injection: "`chassis sim estop-switch on` while teleop drives at 0.4 m/s, then `off` \
            while it keeps asking"
            .into(),
        behaviour: "the chassis reported its E-stop and the mux held zero naming it; released, \
            the robot stood, the mux waiting for teleop's zero since the E-stop was released \
            (the driver keeps no rule of its own), until teleop asked for zero; then it drove"
            .into(),
        figure: format!(
            "{} states over {} ms after the release, fastest {:.3} m/s (bound 0.01); {again:.2} \
             m/s after teleop's zero",
            standing.samples,
            STOOD_FOR.as_millis(),
            standing.fastest_mps
        ),
        value: standing.fastest_mps,
        pass: standing.stood() && again > 0.3,
        suite: "service".into(),
        test: "a_v2_chassis_estop_switch_stops_it_and_only_a_zero_command_lets_it_drive_again"
            .into(),
    });
    assert!(again > 0.3, "not driving again: {again}\n{}", env.logs());
    figures.finish();
}

/// The pass trace (`CHASSIS_PASS_TRACE`) keeps the passes that wrote a frame or published a
/// state: a polling loop, which flushes its bus every pass, keeps no pass for a flush that
/// carried nothing (such passes filled the trace within seconds and hid the ones that wrote).
#[test]
fn a_polling_loops_pass_trace_keeps_only_passes_that_wrote_or_published() {
    let mut env = Env::new("pass-trace");
    let n = name("trace");
    let trace = env.dir.join("passes.txt");
    let args = [
        "--robot",
        "titan",
        "--name",
        &n,
        "--no-safety-monitor",
        "--loop",
        "spin",
    ];
    let service = env.spawn_program(
        "chassisd",
        &bin("chassisd"),
        &args,
        &[(chassis_ipc::Trace::Pass.env(), trace.to_str().unwrap())],
    );
    let mut robot = env.robot(&n, UP);
    let mut teleop = source(&mut robot, "teleop");
    drive_for(
        &mut robot,
        &mut teleop,
        None,
        VelocityRequest::twist(0.3, 0.0),
        500,
    );
    env.proc(service).signal(Signal::SIGTERM);
    assert_eq!(env.proc(service).wait_exit(Duration::from_secs(5)), Some(0));
    let passes = chassis_ipc::PassStamps::parse(&std::fs::read_to_string(&trace).unwrap()).unwrap();
    assert!(
        passes.iter().any(|p| p.write_started != 0),
        "no pass wrote a frame: {} passes",
        passes.len()
    );
    let idle = passes
        .iter()
        .filter(|p| p.write_started == 0 && p.state_handed == 0)
        .count();
    assert_eq!(
        idle,
        0,
        "{idle} of {} passes kept neither wrote nor published",
        passes.len()
    );
}
