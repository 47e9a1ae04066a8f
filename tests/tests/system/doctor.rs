//! `chassis doctor` against real processes: chassisd on the simulated robot (serving, then with
//! its RC transmitter taking over), the XBot's simulated board on a serial pty (heard, then
//! unreadable for a user outside its group, then gone) and an slcan adapter's side on a pty.
//! SocketCAN is checked in the VM (tests/tests/vcan.rs).
// Test code: helpers outside #[test] functions may unwrap, panic and read the wall clock.
#![allow(clippy::unwrap_used, clippy::panic, clippy::disallowed_methods)]

use std::path::Path;
use std::time::Duration;

use chassis_tests::*;

const UP: Duration = Duration::from_secs(10);

#[test]
fn on_the_simulated_robot_the_doctor_reads_chassisd_and_fails_while_the_rc_holds_it() {
    let mut env = Env::new("doctor-sim");
    let n = name("ds");
    env.serve("titan", &n, &["--bus", "sim", "--no-safety-monitor"]);
    env.robot(&n, UP);
    let out = env.chassis(&["doctor", "--name", &n, "--bus", "sim"]);
    let report = output_text(&out);
    assert_eq!(out.status.code(), Some(0), "{report}\n{}", env.logs());
    assert_eq!(doctor_line(&report, "chassisd").0, "ok", "{report}");
    assert!(
        doctor_line(&report, "chassisd").1.contains("owns the bus"),
        "{report}"
    );
    assert_eq!(doctor_line(&report, "frames").0, "ok", "{report}");
    assert_eq!(doctor_line(&report, "mode").0, "ok", "{report}");
    assert_eq!(doctor_line(&report, "e-stop").0, "ok", "{report}");
    assert_eq!(doctor_line(&report, "state-dir").0, "ok", "{report}");
    assert_eq!(doctor_line(&report, "mux").0, "ok", "{report}");
    assert!(report.contains("verdict: ready to drive"), "{report}");
    // --json: one object per check, then the verdict.
    let out = env.chassis(&["doctor", "--name", &n, "--bus", "sim", "--json"]);
    let lines: Vec<serde_json::Value> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let last = lines.last().unwrap();
    assert_eq!(
        (last["verdict"].as_str(), last["failed"].as_u64()),
        (Some("ready"), Some(0))
    );
    assert!(
        lines
            .iter()
            .any(|c| c["check"] == "mux" && c["verdict"] == "ok"),
        "{lines:?}"
    );

    let rc = env.chassis(&["sim", "--name", &n, "rc", "on"]);
    assert!(rc.status.success(), "{}", output_text(&rc));
    let mut report = String::new();
    let failed = wait_for(UP, || {
        let out = env.chassis(&["doctor", "--name", &n, "--bus", "sim"]);
        report = output_text(&out);
        out.status.code() == Some(1)
    });
    assert!(failed.is_some(), "{report}");
    check_line(&report, "mode", "FAIL", "RC transmitter holds the robot");
    assert!(
        report.contains("verdict: 1 problem blocks driving"),
        "{report}"
    );

    // The robot called so is a TITAN: asked about it as a HUNTER, the doctor says so.
    let out = env.chassis(&["doctor", "--name", &n, "--bus", "sim", "--robot", "hunter"]);
    let report = output_text(&out);
    assert_eq!(out.status.code(), Some(1), "{report}");
    assert!(
        doctor_line(&report, "chassisd").1.contains("as a titan"),
        "{report}"
    );
}

#[test]
fn the_doctor_names_a_silent_safety_monitor_and_a_held_estop_with_their_fixes() {
    let mut env = Env::new("doctor-mux");
    let n = name("dm");
    // The safety rule on, no monitor running.
    env.serve("titan", &n, &["--bus", "sim"]);
    env.robot(&n, UP);
    let out = env.chassis(&["doctor", "--name", &n, "--bus", "sim"]);
    let report = output_text(&out);
    assert_eq!(out.status.code(), Some(1), "{report}\n{}", env.logs());
    check_line(
        &report,
        "mux",
        "FAIL",
        "the required source safety is silent",
    );
    assert!(
        report.contains(&format!("systemctl start chassis-safety@{n}")),
        "{report}"
    );

    // A stand-in monitor's heartbeats, then an operator's e-stop.
    env.publish("safety", &n, &["--source", "safety", "--heartbeat"]);
    let stop = env.chassis(&["control", "--name", &n, "estop"]);
    assert!(stop.status.success(), "{}", output_text(&stop));
    let mut report = String::new();
    let held = wait_for(UP, || {
        report = output_text(&env.chassis(&["doctor", "--name", &n, "--bus", "sim"]));
        report.contains("the lock estop") && !report.contains("required source safety")
    });
    assert!(held.is_some(), "{report}");
    assert_eq!(doctor_line(&report, "mux").0, "FAIL", "{report}");
    assert!(
        report.contains(&format!("`chassis control --name {n} estop-release`")),
        "{report}"
    );
}

/// `chassisd sim --robot ROBOT` at the far end of `line`, once its link exists; returns the
/// link and the `--bus` of the near end.
fn board(env: &mut Env, robot: &str, line: Line, tag: &str) -> (std::path::PathBuf, String) {
    let link = env.dir.join(tag);
    let (_, bus) = env.sim_on_pty(robot, &[], &name(tag), line, &link, UP);
    (link, bus)
}

/// Runs `chassis doctor --robot ROBOT --name N --bus BUS`, which must pass; returns its report.
fn passes(env: &Env, robot: &str, n: &str, bus: &str) -> String {
    let out = env.chassis(&["doctor", "--robot", robot, "--name", n, "--bus", bus]);
    let report = output_text(&out);
    assert_eq!(out.status.code(), Some(0), "{report}\n{}", env.logs());
    report
}

#[test]
fn on_a_serial_pty_the_doctor_hears_the_xbot_and_names_permission_and_missing_devices() {
    let mut env = Env::new("doctor-pty");
    let (link, bus) = board(&mut env, "xbot", Line::Serial, "xbot");
    let n = name("dx");
    let report = passes(&env, "xbot", &n, &bus);
    assert_eq!(doctor_line(&report, "device").0, "ok", "{report}");
    assert_eq!(doctor_line(&report, "permission").0, "ok", "{report}");
    check_line(&report, "frames", "ok", "xbot reports");
    assert_eq!(doctor_line(&report, "mode").0, "ok", "{report}");

    // The same port for another user: first the owner's alone (as a pty is made), then shared
    // with dialout, the user outside it.
    let pts = std::fs::canonicalize(&link).unwrap();
    let serial = format!("serial:{}", pts.display());
    let as_nobody = || {
        let out = std::process::Command::new("setpriv")
            .args(["--reuid=65534", "--regid=65534", "--clear-groups", "--"])
            .arg(bin("chassis"))
            .args(["doctor", "--robot", "xbot", "--name", &n, "--bus", &serial])
            .env("HOME", &env.dir)
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(1), "{}", output_text(&out));
        output_text(&out)
    };
    let chmod = |mode: u32| {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&pts, std::fs::Permissions::from_mode(mode)).unwrap();
    };
    chmod(0o600);
    let report = as_nobody();
    check_line(&report, "permission", "FAIL", "mode 600");
    assert!(
        report.contains("GROUP=\"dialout\", MODE=\"0660\""),
        "{report}"
    );
    // Debian's dialout group.
    std::os::unix::fs::chown(&pts, None, Some(20)).unwrap();
    chmod(0o660);
    let report = as_nobody();
    check_line(
        &report,
        "permission",
        "FAIL",
        "owner group dialout, mode 660",
    );
    assert!(
        report.contains("fix: sudo usermod -aG dialout nobody"),
        "{report}"
    );

    let gone = format!("serial:{}", env.dir.join("nothing").display());
    let out = env.chassis(&["doctor", "--robot", "xbot", "--name", &n, "--bus", &gone]);
    let report = output_text(&out);
    assert_eq!(out.status.code(), Some(1), "{report}");
    assert_eq!(doctor_line(&report, "device").0, "FAIL", "{report}");
    assert!(!Path::new(&gone).exists());
}

#[test]
fn on_an_slcan_pty_the_doctor_finds_the_adapter_and_the_titan_behind_it() {
    let mut env = Env::new("doctor-slcan");
    let (_, bus) = board(&mut env, "titan", Line::Slcan, "slcan");
    let n = name("dc");
    let report = passes(&env, "titan", &n, &bus);
    check_line(&report, "adapter", "ok", "V1013");
    assert_eq!(doctor_line(&report, "frames").0, "ok", "{report}");
    check_line(&report, "robot", "ok", "the frames fit a titan");

    // A serial robot's port named as an slcan adapter: the wrong kind of bus.
    let out = env.chassis(&["doctor", "--robot", "xbot", "--name", &n, "--bus", &bus]);
    assert_eq!(out.status.code(), Some(1), "{}", output_text(&out));
    assert_eq!(doctor_line(&output_text(&out), "bus").0, "FAIL");
}
