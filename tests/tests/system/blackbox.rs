//! The black box: chassisd on the simulated chassis records its engine's inputs without being
//! asked, keeps the window around a stop nobody asked for, and `chassis explain` replays the
//! run through the same engine with every decision and item written identical — through a
//! killed safety monitor, an e-stop, a bus cut and a client flood — and finds the first decision
//! a changed priority changes.
// Test code: helpers outside #[test] functions may unwrap, panic and read the wall clock.
#![allow(clippy::unwrap_used, clippy::panic, clippy::disallowed_methods)]

use std::path::{Path, PathBuf};
use std::process::Output;
use std::time::{Duration, Instant};

use chassis_tests::*;
use nix::sys::signal::Signal;

const UP: Duration = Duration::from_secs(10);
/// A recorded mux decision, in the recording's JSON.
const MUX: &str = r#""what":{"mux""#;

/// Teleop asks for `vx` every 20 ms for `duration`; the fastest the chassis reported.
fn drive(robot: &mut Robot, teleop: &mut Source, vx: f32, duration: Duration) -> f32 {
    let end = Instant::now() + duration;
    let mut max = 0.0f32;
    while Instant::now() < end {
        teleop.send(VelocityRequest::twist(vx, 0.0)).unwrap();
        if let Ok(Some(state)) = robot.wait_state(Duration::from_millis(20)) {
            max = max.max(state.motion.linear_mps.abs());
        }
    }
    max
}

fn monitor_fresh(env: &Env, robot: &mut Robot) {
    let fresh = wait_for(UP, || {
        mux(robot)
            .sources()
            .iter()
            .any(|s| s.name() == "safety" && s.has(SourceFlags::FRESH))
    });
    assert!(
        fresh.is_some(),
        "the monitor never reached the mux\n{}",
        env.logs()
    );
}

fn explain(env: &Env, args: &[&str]) -> (Output, String) {
    let mut all = vec!["explain"];
    all.extend_from_slice(args);
    let out = env.chassis(&all);
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out, text)
}

/// `chassis explain`'s `text` says each of `lines` somewhere.
fn says(text: &str, lines: &[&str]) {
    for line in lines {
        assert!(text.contains(line), "no '{line}' in:\n{text}");
    }
}

/// The windows kept in `ring`'s `kept/`.
fn kept_windows(ring: &Path) -> Vec<PathBuf> {
    std::fs::read_dir(ring.join("kept"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect()
}

/// The one window kept in `ring`, explained.
fn the_kept_window_explained(env: &Env, ring: &Path) -> String {
    let kept = kept_windows(ring);
    let [file] = kept.as_slice() else {
        panic!("one window kept, not {kept:?}")
    };
    let (out, text) = explain(env, &[file.to_str().unwrap()]);
    assert!(out.status.success(), "{text}");
    text
}

/// At least one window was kept in `ring`'s `kept/`, and each replays identically.
fn kept_windows_replay_identically(env: &Env, ring: &Path) {
    let kept = kept_windows(ring);
    assert!(!kept.is_empty(), "no window kept\n{}", env.logs());
    for file in &kept {
        let (out, text) = explain(env, &[file.to_str().unwrap()]);
        assert!(out.status.success(), "{}: {text}", file.display());
        assert!(text.contains("identical"), "{text}");
    }
}

/// The recorded configuration with teleop's priority one higher.
fn with_teleop_priority_raised(ring: &Path) -> String {
    let header = std::fs::read_to_string(ring.join("header.jsonl")).unwrap();
    let start: serde_json::Value = serde_json::from_str(header.lines().next().unwrap()).unwrap();
    let mut config: toml::Table = toml::from_str(start["config"].as_str().unwrap()).unwrap();
    let sources = config["mux"]["source"].as_array_mut().unwrap();
    let teleop = sources
        .iter_mut()
        .find(|s| s["name"].as_str() == Some("teleop"))
        .unwrap();
    let priority = teleop["priority"].as_integer().unwrap();
    teleop["priority"] = toml::Value::Integer(priority + 1);
    toml::to_string(&config).unwrap()
}

/// The events of the ring (its header, then its compressed segments; one a line: the start
/// record first) whose line holds `holding`.
fn recorded_events(ring: &Path, holding: &str) -> Vec<usize> {
    let mut segments: Vec<PathBuf> = std::fs::read_dir(ring)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "zst"))
        .collect();
    segments.sort();
    let mut text = std::fs::read_to_string(ring.join("header.jsonl")).unwrap();
    for segment in &segments {
        let bytes = zstd::decode_all(std::fs::File::open(segment).unwrap()).unwrap();
        text.push_str(std::str::from_utf8(&bytes).unwrap());
    }
    text.lines()
        .enumerate()
        .filter(|(_, l)| l.contains(holding))
        .map(|(i, _)| i)
        .collect()
}

#[test]
fn a_recorded_incident_replays_identically_and_a_changed_priority_diverges_at_once() {
    let mut env = Env::new("blackbox");
    let n = name("bbx");
    let config = env.write("blackbox.toml", "[service]\nblackbox_mib = 64\n");
    let chassisd = env.chassisd(
        "chassisd",
        &["--robot", "titan", "--name", &n, "--config", &config],
    );
    let mut robot = env.robot(&n, UP);
    let monitor = env.spawn("safety", "chassis-safety", &["--name", &n]);
    monitor_fresh(&env, &mut robot);
    let mut teleop = source(&mut robot, "teleop");
    assert!(drive(&mut robot, &mut teleop, 0.3, Duration::from_secs(1)) > 0.2);
    // The safety monitor killed: the required source is lost and the robot stops.
    env.proc(monitor).signal(Signal::SIGKILL);
    let peak = drive(&mut robot, &mut teleop, 0.3, Duration::from_secs(1));
    assert_eq!(
        mux(&mut robot).zero_reason,
        ZeroReason::REQUIRED_SOURCE_STALE,
        "{peak}"
    );
    env.spawn("safety", "chassis-safety", &["--name", &n]);
    monitor_fresh(&env, &mut robot);
    drive(&mut robot, &mut teleop, 0.0, Duration::from_millis(200));
    assert!(drive(&mut robot, &mut teleop, 0.3, Duration::from_secs(1)) > 0.2);
    // The operator's e-stop and its release.
    env.chassis_ok(&["control", "--name", &n, "estop"]);
    drive(&mut robot, &mut teleop, 0.3, Duration::from_millis(500));
    env.chassis_ok(&["control", "--name", &n, "estop-release"]);
    drive(&mut robot, &mut teleop, 0.0, Duration::from_millis(200));
    assert!(drive(&mut robot, &mut teleop, 0.3, Duration::from_secs(1)) > 0.2);
    env.proc(chassisd).signal(Signal::SIGTERM);
    assert_eq!(
        env.proc(chassisd).wait_exit(Duration::from_secs(10)),
        Some(0)
    );

    let ring = env.state_home().join("chassisd").join(&n).join("blackbox");
    let ring_text = ring.to_str().unwrap();
    // The whole run, from the ring.
    let (out, text) = explain(&env, &[ring_text]);
    assert!(out.status.success(), "{text}\n{}", env.logs());
    says(
        &text,
        &[
            "items written: identical",
            "STOP stopped: required source safety silent",
            "STOP stopped: locked · held: estop",
            "driving from teleop",
        ],
    );
    // The window kept for the stops, from the MCAP file.
    kept_windows_replay_identically(&env, &ring);
    // The verdict for tools, and one moment: teleop driving again after the last stop.
    let (out, text) = explain(&env, &[ring_text, "--json"]);
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(json["replay"]["divergence"].is_null(), "{text}");
    let story = json["story"].as_array().unwrap();
    let last_stop = story.iter().rposition(|c| c["stop"] == true).unwrap();
    let again = story[last_stop..]
        .iter()
        .find(|c| c["driver"] == "teleop")
        .unwrap_or_else(|| panic!("teleop never drove after the last stop: {text}"));
    let since_start =
        again["at_ns"].as_u64().unwrap() - json["replay"]["start_ns"].as_u64().unwrap();
    let moment = format!("+{:.3}", since_start as f64 / 1e9 + 0.005);
    let (_, text) = explain(&env, &[ring_text, "--at", &moment]);
    says(
        &text,
        &[
            "driving from teleop",
            "safety fresh",
            "no lock held",
            "the last stop at",
            "teleop drove again at",
        ],
    );
    let decisions = json["replay"]["decisions"].as_u64().unwrap();
    assert_eq!(
        decisions as usize,
        recorded_events(&ring, MUX).len(),
        "{text}"
    );

    // One priority changed in the replay's configuration: the first publication that shows the
    // sources' priorities differs, the robot's description (the mux status comes after it).
    let changed = env.write("changed.toml", &with_teleop_priority_raised(&ring));
    let (out, text) = explain(&env, &[ring_text, "--config", &changed]);
    assert_eq!(out.status.code(), Some(1), "{text}");
    assert!(text.contains("another configuration"), "{text}");
    assert!(text.contains("replay DIVERGED"), "{text}");
    let (out, _) = explain(&env, &[ring_text, "--config", &changed, "--json"]);
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let at = json["replay"]["divergence"]["event"].as_u64().unwrap() as usize;
    let first_shown = recorded_events(&ring, r#""what":{"description""#)[0];
    assert!(first_shown < recorded_events(&ring, MUX)[0]);
    assert_eq!(at, first_shown, "diverged elsewhere: {json}");
}

/// A bus cut (the simulator at the far end of an slcan line killed and started again) and a
/// client flooding the mux, recorded and replayed: every decision and item written identical,
/// and nothing of the flood left unrecorded.
#[test]
fn a_bus_cut_and_a_client_flood_replay_identically() {
    let mut env = Env::new("blackbox-cut");
    let n = name("bbc");
    let link = env.dir.join("titan");
    let (sim, bus) = env.sim_on_pty("titan", &[], &n, Line::Slcan, &link, UP);
    let chassisd = env.serve("titan", &n, &["--bus", &bus, "--no-safety-monitor"]);
    let mut robot = env.robot(&n, UP);
    let mut teleop = source(&mut robot, "teleop");
    assert!(drive(&mut robot, &mut teleop, 0.3, Duration::from_secs(1)) > 0.2);
    // The bus cut: the chassis at the far end gone, then back.
    env.proc(sim).signal(Signal::SIGKILL);
    let _ = std::fs::remove_file(&link);
    let lost = wait_for(Duration::from_secs(3), || {
        drive(&mut robot, &mut teleop, 0.3, Duration::from_millis(20));
        mux(&mut robot).stop == Stop::BUS
    });
    assert!(
        lost.is_some(),
        "the bus cut never stopped the mux\n{}",
        env.logs()
    );
    env.sim("sim2", "titan", &[], &n, &Line::Slcan.sim_bus(&link));
    let back = wait_for(UP, || {
        drive(&mut robot, &mut teleop, 0.3, Duration::from_millis(20));
        mux(&mut robot).zero_reason == ZeroReason::AWAITING_ZERO
    });
    assert!(back.is_some(), "the bus never came back\n{}", env.logs());
    drive(&mut robot, &mut teleop, 0.0, Duration::from_millis(200));
    assert!(drive(&mut robot, &mut teleop, 0.3, Duration::from_secs(1)) > 0.2);
    // The flood: the planner as fast as one thread sends, for a second; every other request a
    // zero, which its motion starts from once teleop falls silent.
    let mut planner = source(&mut robot, "planner");
    let end = Instant::now() + Duration::from_secs(1);
    let mut sent = 0usize;
    while Instant::now() < end {
        let vx = [0.0, 0.1, 0.0, -0.1][sent % 4];
        planner.send(VelocityRequest::twist(vx, 0.0)).unwrap();
        sent += 1;
    }
    drive(&mut robot, &mut teleop, 0.0, Duration::from_millis(300));
    env.proc(chassisd).signal(Signal::SIGTERM);
    assert_eq!(
        env.proc(chassisd).wait_exit(Duration::from_secs(10)),
        Some(0)
    );

    let ring = env.state_home().join("chassisd").join(&n).join("blackbox");
    let (out, text) = explain(&env, &[ring.to_str().unwrap()]);
    assert!(out.status.success(), "{text}\n{}", env.logs());
    assert!(!text.contains("replay stopped"), "{text}");
    says(
        &text,
        &[
            "items written: identical",
            "STOP stopped: the bus is lost or bus-off",
            "waiting for a zero from teleop since the bus came back",
            "driving from planner",
        ],
    );
    let (out, _) = explain(&env, &[ring.to_str().unwrap(), "--json"]);
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let events = json["replay"]["events"].as_u64().unwrap();
    assert_eq!(json["replay"]["checked"].as_u64(), Some(events), "{json}");
    // The window kept for the bus cut, from its MCAP file.
    kept_windows_replay_identically(&env, &ring);
}

/// A ring of six seconds, on a run longer than that: the kept window has lost the run's
/// beginning, and is replayed from the engine's snapshot at the start of its oldest segment —
/// the drive and the e-stop decided again, identical to the recording; the few events before
/// the snapshot are told as recorded.
#[test]
fn a_window_whose_beginning_the_ring_let_go_of_replays_from_the_engines_snapshot() {
    let mut env = Env::new("blackbox-wrap");
    let n = name("bbw");
    let config = env.write("wrap.toml", "[service]\nblackbox_minutes = 0.1\n");
    env.chassisd(
        "chassisd",
        &[
            "--robot",
            "titan",
            "--name",
            &n,
            "--config",
            &config,
            "--no-safety-monitor",
        ],
    );
    let mut robot = env.robot(&n, UP);
    let mut teleop = source(&mut robot, "teleop");
    assert!(drive(&mut robot, &mut teleop, 0.3, Duration::from_secs(8)) > 0.2);
    env.chassis_ok(&["control", "--name", &n, "estop"]);
    let logged = wait_for(Duration::from_secs(15), || {
        env.logs().contains("black box kept: stop: stopped: locked")
    });
    assert!(logged.is_some(), "no window kept\n{}", env.logs());
    let ring = env.state_home().join("chassisd").join(&n).join("blackbox");
    let text = the_kept_window_explained(&env, &ring);
    says(
        &text,
        &[
            "from the engine's snapshot: the ring had let go of the run's beginning",
            "identical",
            "(the ring had let go of the run's beginning: replayed on from the engine's state at",
            "driving from teleop",
            "STOP stopped: locked · held: estop",
        ],
    );
    assert!(!text.contains("DIVERGED"), "{text}");
    let kept = kept_windows(&ring);
    let (out, text) = explain(&env, &[kept[0].to_str().unwrap(), "--json"]);
    assert!(out.status.success(), "{text}");
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let replay = &json["replay"];
    assert!(replay["divergence"].is_null(), "{json}");
    assert!(replay["incomplete"].is_null(), "{json}");
    assert_eq!(
        replay["resumed"].as_array().map(Vec::len),
        Some(1),
        "{json}"
    );
    assert_eq!(replay["checked"], replay["events"], "{json}");
    // Every snapshot after the one it went on from was compared.
    let snapshots = replay["snapshots"].as_u64().unwrap();
    assert!(snapshots >= 2, "{json}");
    assert_eq!(
        replay["snapshots_checked"].as_u64(),
        Some(snapshots - 1),
        "{json}"
    );
    // The stop itself was decided again.
    let stop = json["story"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["stop"] == true)
        .unwrap_or_else(|| panic!("no stop in {json}"));
    assert_eq!(stop["replayed"], true, "{json}");
}

/// With no configuration at all the black box records, and `chassis control keep` keeps its
/// window: a file that explains identically.
#[test]
fn the_black_box_records_by_default_and_keeps_its_window_when_asked() {
    let mut env = Env::new("blackbox-keep");
    let n = name("bbk");
    env.chassisd("chassisd", &["--robot", "titan", "--name", &n]);
    let mut robot = env.robot(&n, UP);
    robot.wait_state(UP).unwrap();
    let answer = env.chassis_ok(&["control", "--name", &n, "keep"]);
    assert!(answer.contains("keeps the window"), "{answer}");
    // The window goes on five seconds after the keep, then is written and logged.
    let logged = wait_for(Duration::from_secs(15), || {
        env.logs().contains("black box kept: chassis control keep")
    });
    assert!(logged.is_some(), "no window kept\n{}", env.logs());
    let ring = env.state_home().join("chassisd").join(&n).join("blackbox");
    let text = the_kept_window_explained(&env, &ring);
    assert!(text.contains("identical"), "{text}");
}
