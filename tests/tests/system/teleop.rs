//! The operator's tools against a running chassisd: `chassis-teleop` in a real terminal (tmux:
//! keys sent with `send-keys`, the screen read with `capture-pane`), `chassis top --once` and
//! `chassis status`, each showing the robot as chassisd describes it. The teleop tests are
//! skipped, with a notice, where `tmux` is not installed.
#![allow(clippy::unwrap_used, clippy::panic, clippy::disallowed_methods)]

use std::time::{Duration, Instant};

use chassis_tests::*;

const UP: Duration = Duration::from_secs(10);

/// `chassis-teleop --name N` in a tmux terminal, once it shows that it publishes nothing; returns
/// the terminal and the path of teleop's log.
fn teleop_in_tmux(env: &Env, n: &str) -> (Tmux, std::path::PathBuf) {
    let log = env.dir.join("teleop.log");
    let command = format!(
        "{}; echo chassis-teleop exited $?; sleep 60",
        teleop_command(env, n, &log)
    );
    let tmux = Tmux::start(&env.dir, "tmux", &command);
    tmux.wait_for_text("idle — publishing nothing", UP);
    (tmux, log)
}

#[test]
fn teleop_in_a_terminal_drives_while_w_is_held_stops_after_and_latches_the_estop() {
    if !tmux_available() {
        eprintln!("SKIPPED: tmux is not installed; the terminal test of chassis-teleop needs it");
        return;
    }
    let (env, n, mut robot) = Env::serving(
        "teleop-tmux",
        ("tel", "titan"),
        &["--no-safety-monitor"],
        UP,
    );
    let (tmux, log) = teleop_in_tmux(&env, &n);

    // Hold `w`: a terminal's auto-repeat, as tmux delivers it, every 30 ms for 1.5 s.
    let start = Instant::now();
    let mut peak = 0.0f32;
    let mut teleop_won = false;
    while start.elapsed() < Duration::from_millis(1500) {
        tmux.send("w");
        if let Ok(Some(state)) = robot.wait_state(Duration::from_millis(30)) {
            peak = peak.max(state.motion.linear_mps);
        }
        if let Ok(Some(m)) = robot.latest_mux() {
            teleop_won |= m.active().is_some_and(|s| s.name() == "teleop");
        }
    }
    let screen = tmux.screen();
    let last_key = Instant::now();
    assert!(teleop_won, "the mux never chose teleop\n{screen}");
    assert!(
        peak > 0.05,
        "peak speed {peak} m/s while w was held\n{screen}"
    );
    assert!(screen.contains("DRIVING"), "{screen}");
    assert!(screen.contains("active     teleop"), "{screen}");
    // The robot as chassisd describes it.
    assert!(screen.contains("AgileX TITAN (titan)"), "{screen}");
    assert!(screen.contains("robot: ≤ 3.00 m/s forward"), "{screen}");

    // Let go: the hold lapses (200 ms after the last repeat), one stop goes out, the command
    // on the wire is zero at once and the simulated TITAN coasts to a halt (a first-order lag
    // of about 0.3 s).
    let commanded_zero = wait_for(Duration::from_secs(2), || {
        let m = mux(&mut robot);
        m.output.linear_x_mps == 0.0 && m.requested.linear_x_mps == 0.0
    });
    let zero_after = last_key.elapsed();
    let stopped = comes_to_rest(&mut robot, Duration::from_secs(3), 0.01);
    let stopped_after = last_key.elapsed();
    eprintln!(
        "peak {peak:.3} m/s while w was held; after the last key: commanded zero in \
         {zero_after:?}, stopped in {stopped_after:?}"
    );
    assert!(commanded_zero.is_some(), "teleop never sent its stop");
    assert!(
        zero_after < Duration::from_millis(600),
        "the stop took {zero_after:?} after the last key"
    );
    assert!(
        stopped.is_some(),
        "the robot kept moving after w was let go"
    );
    assert!(
        stopped_after < Duration::from_millis(1500),
        "stopped {stopped_after:?} after the last key"
    );
    // Then nothing more is sent: teleop goes stale and the mux has no winner.
    let quiet = wait_for(Duration::from_secs(2), || {
        let m = mux(&mut robot);
        m.sources()
            .iter()
            .find(|s| s.name() == "teleop")
            .is_some_and(|s| !s.has(SourceFlags::FRESH))
            && m.active().is_none()
    });
    assert!(quiet.is_some(), "teleop kept publishing\n{}", tmux.screen());
    tmux.wait_for_text("idle — publishing nothing", Duration::from_secs(2));

    // `e` latches the e-stop lock, held by teleop.
    tmux.send("e");
    let latched = wait_for(Duration::from_secs(3), || {
        let m = mux(&mut robot);
        let teleop = m.sources().iter().position(|s| s.name() == "teleop");
        m.lock_index("estop")
            .map(|i| m.locks()[i])
            .is_some_and(|l| l.held != 0 && teleop.is_some_and(|t| usize::from(l.holder) == t))
    });
    assert!(latched.is_some(), "no e-stop lock\n{}", tmux.screen());
    let screen = tmux.wait_for_text("E-STOP LATCHED", Duration::from_secs(2));
    assert!(
        screen.contains("release with `chassis control estop-release`"),
        "{screen}"
    );
    assert!(screen.contains("SAFETY OVERRIDE: lock estop"), "{screen}");
    let out = env.chassis(&["control", "--name", &n, "estop-release"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    // `q` quits cleanly and hands the terminal back.
    tmux.send("q");
    let screen = tmux.wait_for_text("chassis-teleop exited", Duration::from_secs(5));
    assert!(
        screen.contains("chassis-teleop exited 0"),
        "{screen}\n{}",
        std::fs::read_to_string(&log).unwrap_or_default()
    );
}

/// `chassis top --once` while `chassis pub` drives chassis/`n` at 0.2 m/s as teleop (once
/// teleop won the mux): its output.
fn top_once_while_teleop_drives(env: &mut Env, robot: &mut Robot, n: &str) -> String {
    env.publish(
        "pub",
        n,
        &["--source", "teleop", "--vx", "0.2", "--duration", "6"],
    );
    let driving = wait_for(UP, || {
        mux(robot).active().is_some_and(|s| s.name() == "teleop")
    });
    assert!(driving.is_some(), "teleop never won\n{}", env.logs());
    let out = env.chassis(&["top", "--once", "--name", n]);
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    text
}

#[test]
fn top_once_prints_rates_per_can_id_and_the_active_source() {
    let (mut env, n, mut robot) =
        Env::serving("top-once", ("top", "titan"), &["--no-safety-monitor"], UP);
    let text = top_once_while_teleop_drives(&mut env, &mut robot, &n);
    assert!(text.contains("active teleop (priority 100"), "{text}");
    // TITAN's system status arrives at 50 Hz, its motion command goes out at 50 Hz.
    let rate = |prefix: &str| -> f64 {
        let line = text
            .lines()
            .find(|l| l.starts_with(prefix))
            .unwrap_or_else(|| panic!("no '{prefix}' line:\n{text}"));
        line.split_whitespace()
            .nth(3)
            .and_then(|r| r.parse().ok())
            .unwrap_or_else(|| panic!("no rate in '{line}'"))
    };
    let rx = rate("RX  0x211");
    let tx = rate("TX  0x111");
    assert!((30.0..=70.0).contains(&rx), "0x211 at {rx}/s\n{text}");
    assert!((30.0..=70.0).contains(&tx), "0x111 at {tx}/s\n{text}");
    assert!(text.contains("system_status"), "{text}");
    assert!(text.contains("motion_command"), "{text}");
    assert!(text.contains("0 dropped (seq gaps)"), "{text}");
    assert!(text.contains("state age"), "{text}");
}

/// chassisd's `[profile] max_linear_mps = 0.3` on a TITAN: the teleop reads it from the robot's
/// description, its speed steps stop there (`+` pressed a dozen times), and holding `w` asks the
/// mux for 0.3 m/s at most — without the driver having to clamp it.
#[test]
fn teleop_in_a_terminal_steps_no_faster_than_the_limit_chassisd_describes() {
    if !tmux_available() {
        eprintln!("SKIPPED: tmux is not installed; the terminal test of chassis-teleop needs it");
        return;
    }
    let mut env = Env::new("teleop-limit");
    let n = name("tlim");
    let config = env.write("limit.toml", "[profile]\nmax_linear_mps = 0.3\n");
    env.serve("titan", &n, &["--no-safety-monitor", "--config", &config]);
    let mut robot = env.robot(&n, UP);
    let (tmux, _) = teleop_in_tmux(&env, &n);
    for _ in 0..12 {
        tmux.send("+");
    }
    // 0.3 m/s in steps of 0.1 is three steps; the yaw rate's 1.0 rad/s in steps of 0.2, five.
    let screen = tmux.wait_for_text("step 5/5: 0.30 m/s, 1.00 rad/s", UP);
    assert!(screen.contains("robot: ≤ 0.30 m/s forward"), "{screen}");
    let start = Instant::now();
    let mut asked = 0.0f32;
    let mut decisions = 0;
    let mut clamped = 0;
    while start.elapsed() < Duration::from_millis(1500) {
        tmux.send("w");
        let _ = robot.wait_state(Duration::from_millis(30));
        robot
            .poll_mux(|m| {
                if m.active().is_some_and(|s| s.name() == "teleop") {
                    decisions += 1;
                    asked = asked.max(m.requested.linear_x_mps);
                    if m.clamp_flags & ClampFlags::LINEAR_LIMIT != 0 {
                        clamped += 1;
                    }
                }
            })
            .unwrap();
    }
    eprintln!(
        "titan with max_linear_mps = 0.3: teleop asked for at most {asked} m/s in {decisions} \
         decisions, {clamped} clamped"
    );
    assert!(decisions > 10, "teleop never drove\n{}", tmux.screen());
    assert!(f64::from(asked) <= 0.3, "asked for {asked} m/s");
    assert!(asked > 0.29, "asked for {asked} m/s");
    assert_eq!(clamped, 0, "the driver clamped teleop's requests");
    tmux.send("q");
    tmux.wait_for_text("chassis-teleop exited 0", Duration::from_secs(5));
}

/// `chassis top --once` and `chassis status` (text and `--json`) on a HUNTER 2.0 with
/// `[profile] max_linear_mps = 0.4`: what the robot is, its effective limits, every frame of
/// its AgileX V2 exchange named by the registry's codec of the described robot.
#[test]
fn top_and_status_show_the_robot_as_described_and_name_every_frame() {
    let mut env = Env::new("top-hunter");
    let n = name("toph");
    let config = env.write("hunter.toml", "[profile]\nmax_linear_mps = 0.4\n");
    env.serve("hunter", &n, &["--no-safety-monitor", "--config", &config]);
    let mut robot = env.robot(&n, UP);
    let text = top_once_while_teleop_drives(&mut env, &mut robot, &n);
    assert!(text.contains("AgileX HUNTER 2.0 (hunter)"), "{text}");
    assert!(text.contains("limits    forward 0.40"), "{text}");
    assert!(text.contains("protocol v2"), "{text}");
    let rows: Vec<&str> = text
        .lines()
        .filter(|l| l.starts_with("RX  0x") || l.starts_with("TX  0x"))
        .collect();
    assert!(rows.len() >= 3, "{text}");
    for row in &rows {
        assert!(!row.contains(" ? "), "an unnamed frame: {row}\n{text}");
    }
    assert!(
        rows.iter()
            .any(|r| r.starts_with("TX  0x111") && r.contains("motion_command")),
        "{text}"
    );

    let out = env.chassis(&["status", "--name", &n]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}");
    assert!(
        text.contains("robot      AgileX HUNTER 2.0 (hunter)"),
        "{text}"
    );
    assert!(
        text.contains("limits     forward 0.40 · reverse 0.40 m/s"),
        "{text}"
    );
    assert!(text.contains("config     safety 255"), "{text}");
    let out = env.chassis(&["status", "--name", &n, "--json"]);
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let d = &json["description"];
    assert_eq!(d["kind_name"], "hunter", "{json}");
    assert_eq!(d["effective_limits"]["forward_mps"], 0.4, "{json}");
    assert_eq!(d["robot_limits"]["forward_mps"], 0.4, "{json}");
    assert_eq!(d["protocol_name"], "v2", "{json}");
    assert!(
        d["sources"]
            .as_array()
            .is_some_and(|s| s.iter().any(|s| s["name"] == "teleop")),
        "{json}"
    );
    assert!(
        json["state"].is_object() && json["mux"].is_object(),
        "{json}"
    );
}
