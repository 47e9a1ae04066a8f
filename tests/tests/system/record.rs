//! `chassis record` and `chassis replay` with real processes: a driving TITAN recorded to MCAP and
//! to a candump log without a lost frame, a fully loaded bus recorded without a gap, and the
//! recordings replayed through `chassisd --bus replay:…` until the replayed state reaches the
//! recorded one — a field recording reproducing a bug at the desk.
#![allow(clippy::unwrap_used, clippy::panic, clippy::disallowed_methods)]

use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use chassis_tests::*;
use nix::sys::signal::Signal;
use serde_json::Value;

const UP: Duration = Duration::from_secs(10);

/// Waits until the recorder started as `index` says it is recording.
fn wait_recording(env: &mut Env, index: usize) {
    let ready = wait_for(UP, || env.proc(index).log_text().contains("Ctrl-C to stop"));
    assert!(
        ready.is_some(),
        "the recorder did not start\n{}",
        env.logs()
    );
}

/// Sends `request` as teleop every 20 ms for `duration`, then a stop.
fn drive(robot: &mut Robot, request: VelocityRequest, duration: Duration) {
    let mut teleop = robot.source("teleop").unwrap();
    let end = Instant::now() + duration;
    while Instant::now() < end {
        teleop.send(request).unwrap();
        let _ = robot.wait_state(Duration::from_millis(20));
    }
    teleop.stop().unwrap();
}

/// Waits until the robot stands still, then returns its state.
fn standing(robot: &mut Robot) -> ChassisState {
    let still = comes_to_rest(robot, Duration::from_secs(5), 0.005);
    assert!(still.is_some(), "the robot did not stop");
    pause(Duration::from_millis(300));
    state(robot)
}

/// Stops a recorder with SIGINT and checks that it finished cleanly without a lost frame.
fn stop_recorder(env: &mut Env, index: usize) -> String {
    env.proc(index).signal(Signal::SIGINT);
    let code = env.proc(index).wait_exit(Duration::from_secs(10));
    let log = env.proc(index).log_text();
    assert_eq!(code, Some(0), "recorder exit\n{}", env.logs());
    assert!(log.contains("no frame lost (0 sequence gaps)"), "{log}");
    log
}

/// An MCAP recording, read back with the `mcap` crate.
#[derive(Debug, Default)]
struct McapRecording {
    metadata: BTreeMap<String, BTreeMap<String, String>>,
    /// (log_time, message) per topic suffix (`frames`, `state`, `mux`).
    messages: BTreeMap<String, Vec<(u64, Value)>>,
    /// Messages per Foxglove topic (`/tf`, `/pose`, `/gps`, `/log`).
    foxglove: BTreeMap<String, usize>,
}

impl McapRecording {
    fn read(path: &Path) -> Self {
        let bytes = std::fs::read(path).unwrap();
        let summary = mcap::Summary::read(&bytes)
            .unwrap()
            .unwrap_or_else(|| panic!("{}: a finished MCAP file has a summary", path.display()));
        let mut out = McapRecording::default();
        for index in &summary.metadata_indexes {
            let meta = mcap::read::metadata(&bytes, index).unwrap();
            out.metadata.insert(meta.name, meta.metadata);
        }
        for channel in summary.channels.values() {
            if !channel.topic.starts_with("/chassis/") {
                // The Foxglove view's channels (/tf, /pose, /gps, /log): its protobuf schemas.
                let schema = channel.schema.as_ref().unwrap();
                assert!(schema.name.starts_with("foxglove."), "{}", schema.name);
                assert_eq!(channel.message_encoding, "protobuf", "{}", channel.topic);
                continue;
            }
            assert_eq!(channel.message_encoding, "json", "{}", channel.topic);
            let schema = channel
                .schema
                .as_ref()
                .unwrap_or_else(|| panic!("{} has no schema", channel.topic));
            assert_eq!(schema.encoding, "jsonschema");
            let _: Value = serde_json::from_slice(&schema.data).unwrap();
        }
        for message in mcap::MessageStream::new(&bytes).unwrap() {
            let message = message.unwrap();
            assert_eq!(message.log_time, message.publish_time);
            if !message.channel.topic.starts_with("/chassis/") {
                *out.foxglove
                    .entry(message.channel.topic.clone())
                    .or_default() += 1;
                continue;
            }
            let topic = message
                .channel
                .topic
                .rsplit('/')
                .next()
                .unwrap()
                .to_string();
            let value: Value = serde_json::from_slice(&message.data).unwrap();
            out.messages
                .entry(topic)
                .or_default()
                .push((message.log_time, value));
        }
        out
    }

    fn frames(&self) -> &[(u64, Value)] {
        self.messages.get("frames").map_or(&[], Vec::as_slice)
    }

    fn rx_frames(&self) -> usize {
        self.frames()
            .iter()
            .filter(|(_, f)| f["direction"] == "rx")
            .count()
    }

    /// Frames missing from the `seq` sequence.
    fn lost(&self) -> u64 {
        let seqs: Vec<u64> = self
            .frames()
            .iter()
            .map(|(_, f)| f["seq"].as_u64().unwrap())
            .collect();
        seqs.windows(2).map(|w| w[1] - w[0] - 1).sum()
    }

    /// The received CAN frames as `ID#HEX`, in order.
    fn rx_can_lines(&self) -> impl Iterator<Item = String> + '_ {
        self.frames()
            .iter()
            .filter(|(_, f)| f["direction"] == "rx" && f["kind"] == "can")
            .map(|(_, f)| {
                format!(
                    "{:X}#{}",
                    f["can_id"].as_u64().unwrap(),
                    f["data"].as_str().unwrap()
                )
            })
    }

    fn count_rx_id(&self, id: u64) -> usize {
        self.frames()
            .iter()
            .filter(|(_, f)| f["direction"] == "rx" && f["can_id"] == id)
            .count()
    }

    fn seconds(&self) -> f64 {
        let frames = self.frames();
        match (frames.first(), frames.last()) {
            (Some(a), Some(b)) => (b.0 - a.0) as f64 / 1e9,
            _ => 0.0,
        }
    }
}

/// The 0x211 frames of a candump log; asserts every line has the `(SECS.MICROS) IFACE ID#HEX`
/// shape.
fn candump_lines(path: &Path, iface: &str) -> Vec<String> {
    let text = std::fs::read_to_string(path).unwrap();
    let lines: Vec<String> = text.lines().map(str::to_string).collect();
    for line in &lines {
        let fields: Vec<&str> = line.split(' ').collect();
        assert_eq!(fields.len(), 3, "{line}");
        let time = fields[0]
            .strip_prefix('(')
            .and_then(|t| t.strip_suffix(')'))
            .unwrap();
        let (secs, micros) = time.split_once('.').unwrap();
        assert!(
            secs.parse::<u64>().unwrap() > 1_000_000_000,
            "{line}: wall clock"
        );
        assert_eq!(micros.len(), 6, "{line}");
        assert_eq!(fields[1], iface);
        let (id, data) = fields[2].split_once('#').unwrap();
        assert!(id.len() == 3 || id.len() == 8, "{line}");
        assert!(data.len() % 2 == 0 && data.len() <= 16, "{line}");
    }
    lines
}

/// Waits until a replaying service reports its bus down after frames arrived (the recording has
/// played) and returns that state.
fn replayed(robot: &mut Robot, env: &Env) -> ChassisState {
    let mut last = None;
    let done = wait_for(Duration::from_secs(30), || {
        let s = state(robot);
        last = Some(s);
        s.has_link_flag(LinkFlags::BUS_DOWN) && s.link.rx_frames > 0
    });
    assert!(
        done.is_some(),
        "the replay did not end: {last:?}\n{}",
        env.logs()
    );
    last.unwrap()
}

/// The odometer (front, rear, m) of the last TITAN odometer frame of `frames` (candump lines
/// or bare `ID#HEX`): what the chassis reported last, and a replay of them ends on (there must
/// be one).
fn last_odometer(frames: impl IntoIterator<Item = String>) -> (f64, f64) {
    use chassis_protocols::titan::{Frame, decode};
    let profile = chassis_protocols::titan::TitanProfile::default();
    frames
        .into_iter()
        .filter_map(|line| {
            let frame = chassis_protocols::CandumpLine::parse(&line).ok()?.frame;
            match decode(&frame, &profile).ok()? {
                Frame::Odometer(o) => Some((o.front_distance_m, o.rear_distance_m)),
                _ => None,
            }
        })
        .last()
        .unwrap()
}

/// `text` without its ANSI colour codes (the services log in colour).
fn plain(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut chars = text.chars();
    while let Some(c) = chars.next() {
        if c == '\x1b' {
            for c in chars.by_ref() {
                if c == 'm' {
                    break;
                }
            }
        } else {
            out.push(c);
        }
    }
    out
}

/// The replay thread's summary line in a chassisd log.
fn replay_summary(log: &str) -> String {
    let log = plain(log);
    let line = log
        .lines()
        .find(|l| l.contains(" ended: "))
        .unwrap_or_else(|| panic!("no replay summary\n{log}"));
    line.split(" ended: ").nth(1).unwrap_or(line).to_string()
}

fn json_f64(value: &Value, path: &[&str]) -> f64 {
    let mut v = value;
    for key in path {
        v = &v[*key];
    }
    v.as_f64().unwrap_or_else(|| panic!("{path:?} in {value}"))
}

/// chassisd (labelled `label`) replaying the recording `file` as fast as it takes it, as robot
/// NAME (`tag` and the pid): its index and a connection.
fn replay_at_max(env: &mut Env, (label, tag): (&str, &str), file: &str) -> (usize, Robot) {
    let n = name(tag);
    let bus = format!("replay:{file}@max");
    let replay = env.serve_as(
        label,
        ("titan", &n),
        &["--bus", &bus, "--no-safety-monitor"],
    );
    (replay, env.robot(&n, UP))
}

#[test]
fn a_driving_titan_recorded_to_mcap_and_candump_replays_to_the_recorded_odometry_and_pose() {
    let (mut env, n, mut robot) = Env::serving(
        "record-titan",
        ("rec", "titan"),
        &["--no-safety-monitor"],
        UP,
    );
    let mcap_path = env.dir.join("drive.mcap");
    let log_path = env.dir.join("drive.log");
    let mcap_text = mcap_path.to_str().unwrap().to_string();
    let log_text = log_path.to_str().unwrap().to_string();
    let mcap_rec = env.spawn(
        "record-mcap",
        "chassis",
        &["record", &mcap_text, "--name", &n],
    );
    let log_rec = env.spawn(
        "record-candump",
        "chassis",
        &[
            "record",
            "--candump",
            &log_text,
            "--name",
            &n,
            "--iface",
            "can0",
        ],
    );
    wait_recording(&mut env, mcap_rec);
    wait_recording(&mut env, log_rec);
    let started = Instant::now();

    drive(
        &mut robot,
        VelocityRequest::twist(0.5, 0.3),
        Duration::from_secs(2),
    );
    let recorded = standing(&mut robot);
    if let Some(left) = Duration::from_secs(3).checked_sub(started.elapsed()) {
        pause(left);
    }
    assert!(
        recorded.odometry.x_m > 0.4,
        "the robot drove: {:?}",
        recorded.odometry
    );
    stop_recorder(&mut env, mcap_rec);
    stop_recorder(&mut env, log_rec);

    // The MCAP file: three JSON channels with schemas, the metadata, no sequence gap; the
    // Foxglove view's /tf and /pose beside them.
    let rec = McapRecording::read(&mcap_path);
    for topic in ["/tf", "/pose"] {
        assert!(
            rec.foxglove.get(topic).is_some_and(|&n| n > 10),
            "{:?}",
            rec.foxglove
        );
    }
    let meta = &rec.metadata["chassis"];
    assert_eq!(meta["robot"], "titan");
    assert_eq!(meta["name"], n);
    assert_eq!(meta["clock"], "CLOCK_MONOTONIC");
    let offset: i128 = meta["wall_minus_monotonic_ns"].parse().unwrap();
    assert!(
        offset > 1_000_000_000_000_000_000,
        "wall clock offset {offset}"
    );
    assert_eq!(rec.metadata["chassis.summary"]["lost_frames"], "0");
    assert!(rec.seconds() >= 2.9, "{} s of frames", rec.seconds());
    assert_eq!(rec.lost(), 0, "sequence gaps in the MCAP frames");
    let status_frames = rec.count_rx_id(0x211);
    assert!(status_frames >= 40, "{status_frames} 0x211 frames");
    assert!(rec.count_rx_id(0x221) >= 40, "motion feedback");
    assert!(
        rec.frames().iter().any(|(_, f)| f["direction"] == "tx"),
        "the service's commands are recorded too"
    );
    let states = &rec.messages["state"];
    let muxes = &rec.messages["mux"];
    assert!(states.len() >= 30, "{} states", states.len());
    assert!(muxes.len() >= 20, "{} mux decisions", muxes.len());
    // Every state sample published while recording is in the file, in order.
    let summary = &rec.metadata["chassis.summary"];
    assert_eq!(summary["lost_states"], "0");
    assert_eq!(summary["states"], states.len().to_string());
    let seqs: Vec<u64> = states
        .iter()
        .map(|(_, s)| s["seq"].as_u64().unwrap())
        .collect();
    assert!(
        seqs.windows(2).all(|w| w[1] == w[0] + 1),
        "state seq gaps: {seqs:?}"
    );
    let (_, last_state) = states.last().unwrap();
    assert!((json_f64(last_state, &["odometry", "x_m"]) - recorded.odometry.x_m).abs() < 0.01);
    let frame = &rec.frames()[0].1;
    for key in ["stamp_ns", "seq", "direction", "kind", "can_id", "data"] {
        assert!(frame.get(key).is_some(), "{key} in {frame}");
    }
    println!(
        "MCAP: {} frames ({} RX, {status_frames} × 0x211) in {:.1} s, {} states, {} mux decisions",
        rec.frames().len(),
        rec.rx_frames(),
        rec.seconds(),
        states.len(),
        muxes.len()
    );

    // The candump log: RX CAN frames only, every line a `candump -l` line, each one decodable.
    let lines = candump_lines(&log_path, "can0");
    let status_lines = lines.iter().filter(|l| l.contains(" 211#")).count();
    assert!(status_lines >= 40, "{status_lines} 0x211 lines");
    assert!(
        !lines.iter().any(|l| l.contains(" 111#")),
        "a TX command frame in an RX-only log"
    );
    let decoded = Command::new(bin("chassis"))
        .args(["decode", "--robot", "titan"])
        .stdin(std::fs::File::open(&log_path).unwrap())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .output()
        .unwrap();
    assert!(
        decoded.status.success(),
        "chassis decode: {}",
        String::from_utf8_lossy(&decoded.stderr)
    );
    let objects = String::from_utf8_lossy(&decoded.stdout).lines().count();
    assert_eq!(objects, lines.len(), "one JSON object per line");

    // Replay the MCAP file as fast as the service takes it: every RX frame arrives and decodes,
    // and what the chassis reported itself (the odometer) is reproduced exactly: the last
    // odometer frame of the file. The robot stood (below 5 mm/s) when `recorded` was read; it
    // may creep a few mm until the recorder stops.
    let mcap_odometer = last_odometer(rec.rx_can_lines());
    assert!(
        (mcap_odometer.0 - recorded.odometry.front_distance_m).abs() < 0.01,
        "the MCAP file ends on odometer {mcap_odometer:?}, the robot stood at {:?}",
        recorded.odometry
    );
    let (replay_max, mut replay) = replay_at_max(&mut env, ("replay-max", "rpm"), &mcap_text);
    let end = replayed(&mut replay, &env);
    assert_eq!(
        end.link.rx_frames,
        rec.rx_frames() as u64,
        "frames replayed"
    );
    assert_eq!(end.link.rx_decode_errors, 0);
    assert_eq!(
        (end.odometry.front_distance_m, end.odometry.rear_distance_m),
        mcap_odometer,
        "the replay's odometer against the file's last"
    );
    println!(
        "replay at max: {}",
        replay_summary(&env.proc(replay_max).log_text())
    );

    // Replay the candump log at the recorded speed with `chassis replay`: the pose, which the
    // driver integrates over the arrival times, comes out as it did on the robot.
    let slow = name("rpc");
    let out = env.chassis(&[
        "replay", &log_text, "--robot", "titan", "--name", &slow, "--json", "--quiet",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "chassis replay: {stderr}");
    assert!(stderr.contains("replay ended"), "{stderr}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let last: Value = serde_json::from_str(stdout.lines().last().unwrap()).unwrap();
    assert_eq!(
        last["link"]["rx_frames"].as_u64().unwrap(),
        lines.len() as u64,
        "every line replayed"
    );
    let (x, y, yaw) = (
        json_f64(&last, &["odometry", "x_m"]),
        json_f64(&last, &["odometry", "y_m"]),
        json_f64(&last, &["odometry", "yaw_rad"]),
    );
    let position_error = (x - recorded.odometry.x_m).hypot(y - recorded.odometry.y_m);
    let yaw_error = (yaw - recorded.odometry.yaw_rad).abs();
    println!(
        "candump replay at recorded speed: pose ({x:.3}, {y:.3}, {yaw:.3}) vs recorded ({:.3}, {:.3}, {:.3}): {position_error:.4} m, {yaw_error:.4} rad",
        recorded.odometry.x_m, recorded.odometry.y_m, recorded.odometry.yaw_rad
    );
    assert!(position_error < 0.05, "pose error {position_error} m");
    assert!(yaw_error < 0.05, "yaw error {yaw_error} rad");
    let log_odometer = last_odometer(lines.iter().cloned());
    assert!(
        (log_odometer.0 - recorded.odometry.front_distance_m).abs() < 0.01,
        "the log ends on odometer {log_odometer:?}, the robot stood at {:?}",
        recorded.odometry
    );
    assert_eq!(
        (
            json_f64(&last, &["odometry", "front_distance_m"]),
            json_f64(&last, &["odometry", "rear_distance_m"])
        ),
        log_odometer,
        "the replay's odometer against the log's last"
    );
}

#[test]
fn a_fully_loaded_bus_is_recorded_without_a_gap_and_replays_at_full_speed() {
    // Never beside the bench's busy loops (bench.rs), which would starve the flood.
    let _machine = chassis_tests::faults::shared();
    let (mut env, n, _robot) = Env::serving(
        "record-flood",
        ("fld", "titan"),
        &["--no-safety-monitor"],
        UP,
    );
    let flood = env.chassis(&["sim", "--name", &n, "flood", "4000"]);
    assert!(
        flood.status.success(),
        "{}",
        String::from_utf8_lossy(&flood.stderr)
    );
    let path = env.dir.join("flood.mcap");
    let text = path.to_str().unwrap().to_string();
    let out = env.chassis(&["record", &text, "--name", &n, "--duration", "3"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "chassis record: {stderr}");
    assert!(
        stderr.contains("no frame lost (0 sequence gaps)"),
        "{stderr}"
    );
    let rec = McapRecording::read(&path);
    assert_eq!(rec.lost(), 0, "sequence gaps in the file");
    let rate = rec.frames().len() as f64 / rec.seconds();
    println!(
        "recorded {} frames in {:.2} s under flood: {rate:.0} frames/s, 0 lost ({})",
        rec.frames().len(),
        rec.seconds(),
        stderr
            .lines()
            .find(|l| l.starts_with("recorded"))
            .unwrap_or("")
    );
    assert!(rate > 2000.0, "{rate:.0} frames/s: the bus was not loaded");

    // The same recording replayed as fast as the service decodes and publishes it.
    let (replay, mut robot) = replay_at_max(&mut env, ("replay", "fldr"), &text);
    let end = replayed(&mut robot, &env);
    assert_eq!(end.link.rx_frames, rec.rx_frames() as u64);
    println!(
        "replay at max: {}",
        replay_summary(&env.proc(replay).log_text())
    );
}

#[test]
fn an_xbot_records_to_mcap_only_and_its_serial_stream_replays_to_the_recorded_pose() {
    let (mut env, n, mut robot) = Env::serving(
        "record-xbot",
        ("xrec", "xbot"),
        &["--no-safety-monitor"],
        UP,
    );
    let refused = env.chassis(&[
        "record",
        "--candump",
        env.dir.join("x.log").to_str().unwrap(),
        "--name",
        &n,
    ]);
    assert!(!refused.status.success());
    assert!(
        String::from_utf8_lossy(&refused.stderr).contains("RS232"),
        "{}",
        String::from_utf8_lossy(&refused.stderr)
    );

    let path = env.dir.join("xbot.mcap");
    let text = path.to_str().unwrap().to_string();
    let recorder = env.spawn("record", "chassis", &["record", &text, "--name", &n]);
    wait_recording(&mut env, recorder);
    drive(
        &mut robot,
        VelocityRequest::twist(0.3, 0.4),
        Duration::from_millis(1500),
    );
    let recorded = standing(&mut robot);
    stop_recorder(&mut env, recorder);
    let rec = McapRecording::read(&path);
    assert_eq!(rec.metadata["chassis"]["robot"], "xbot");
    assert!(rec.frames().iter().all(|(_, f)| f["kind"] == "serial"));

    // The simulated XBot's wheel separation is known to `--bus sim` only: give it to the replay,
    // which then integrates the pose from the replayed encoders exactly as the robot did.
    let config = env.write("xbot.toml", XBOT_PROFILE);
    let out = env.chassis(&[
        "replay",
        &text,
        "--max-speed",
        "--name",
        &name("xrp"),
        "--config",
        &config,
        "--json",
        "--quiet",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "chassis replay: {stderr}");
    let last: Value =
        serde_json::from_str(String::from_utf8_lossy(&out.stdout).lines().last().unwrap()).unwrap();
    let (x, y) = (
        json_f64(&last, &["odometry", "x_m"]),
        json_f64(&last, &["odometry", "y_m"]),
    );
    let error = (x - recorded.odometry.x_m).hypot(y - recorded.odometry.y_m);
    assert!(
        error < 0.01,
        "replayed pose ({x}, {y}) vs recorded {:?}",
        recorded.odometry
    );
    assert!(
        (json_f64(&last, &["odometry", "left_distance_m"]) - recorded.odometry.left_distance_m)
            .abs()
            < 0.01
    );
}
