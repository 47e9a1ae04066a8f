//! `chassis demo`: the whole system in one command, and Ctrl-C stopping all of it.

// Test code: helpers outside #[test] functions may unwrap, panic and read the wall clock.
#![allow(clippy::unwrap_used, clippy::panic, clippy::disallowed_methods)]

use std::time::{Duration, Instant};

use chassis_protocols::{Protocol, RobotKind};
use chassis_tests::*;
use nix::sys::signal::Signal;

/// Processes whose command line names the robot `name`.
fn processes_named(name: &str) -> Vec<String> {
    let mut found = Vec::new();
    for entry in std::fs::read_dir("/proc").unwrap().flatten() {
        if let Ok(cmdline) = std::fs::read(entry.path().join("cmdline")) {
            let text = String::from_utf8_lossy(&cmdline).replace('\0', " ");
            if text.contains(&format!("--name {name}")) && !text.contains("chassis demo") {
                found.push(text);
            }
        }
    }
    found
}

#[test]
fn chassis_demo_drives_figure_eights_under_the_safety_monitor_and_ctrl_c_stops_everything() {
    let mut env = Env::new("demo");
    let name = format!("dm{}", std::process::id() % 100_000);
    let demo = env.spawn(
        "demo",
        "chassis",
        &["demo", "--robot", "xbot", "--name", &name, "--no-dashboard"],
    );
    let mut robot = env.robot(&name, Duration::from_secs(15));
    // The planner drives, the required safety monitor is alive.
    let driving = wait_for(Duration::from_secs(15), || {
        let m = mux(&mut robot);
        m.active().map(SourceStatus::name) == Some("planner")
            && m.zero_reason == ZeroReason::NONE
            && state(&mut robot).motion.linear_mps.abs() > 0.2
    });
    assert!(driving.is_some(), "the demo is not driving\n{}", env.logs());
    let safety = mux(&mut robot).sources()[0];
    assert_eq!(safety.name(), "safety");
    // `has` is true if any of the flags given is set: each flag is asserted on its own.
    assert!(safety.has(SourceFlags::REQUIRED), "{safety:?}");
    assert!(safety.has(SourceFlags::FRESH), "{safety:?}");
    assert_eq!(
        processes_named(&name).len(),
        3,
        "{:?}",
        processes_named(&name)
    );
    let reported = wait_for(Duration::from_secs(5), || {
        env.proc(demo).log_text().contains("driving from planner")
    });
    assert!(reported.is_some(), "no status line\n{}", env.logs());

    env.proc(demo).signal(Signal::SIGINT);
    let stopped = Instant::now();
    assert_eq!(
        env.proc(demo).wait_exit(Duration::from_secs(10)),
        Some(0),
        "{}",
        env.logs()
    );
    let gone = wait_for(Duration::from_secs(5), || processes_named(&name).is_empty());
    assert!(gone.is_some(), "left behind: {:?}", processes_named(&name));
    eprintln!(
        "Ctrl-C → every demo process gone after {:?}",
        stopped.elapsed()
    );
}

/// The Foxglove bridge is not in the default build: `chassis demo --foxglove` without it names
/// the command that builds it, before it starts anything.
#[test]
fn chassis_demo_with_foxglove_but_no_bridge_says_how_to_build_it_and_starts_nothing() {
    let env = Env::new("demo-no-foxglove");
    // A release directory as a fresh `cargo build --release` leaves it: the core's programs,
    // no bridge. The others are never started, so empty files stand in for them.
    let release = env.dir.join("release");
    std::fs::create_dir_all(&release).unwrap();
    let chassis = release.join("chassis");
    std::fs::copy(bin("chassis"), &chassis).unwrap();
    for program in ["chassisd", "chassis-safety", "chassis-planner"] {
        std::fs::write(release.join(program), "").unwrap();
    }
    let name = format!("nf{}", std::process::id() % 100_000);
    let out = std::process::Command::new(&chassis)
        .args(["demo", "--foxglove", "--no-dashboard", "--name", &name])
        .env(IPC_PREFIX_ENV, &env.prefix)
        .stdin(std::process::Stdio::null())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "{} is missing: build it with `cargo build --release -p chassis-foxglove`",
            release.join("chassis-foxglove").display()
        )),
        "{stderr}"
    );
    assert!(!stderr.contains("chassisd: simulated"), "{stderr}");
}

/// Every AgileX protocol-V2 robot (the SCOUT MINI with V2 firmware included), and the SCOUT
/// and BUNKER with V1 firmware, run the demo on their simulated chassis: the planner drives each
/// under the safety monitor, in its protocol, and the demo ends by itself after `--duration`.
/// Three robots at a time: nine at once (27 processes of a debug build on two cores) starve a
/// safety monitor beyond its 200 ms now and then, and a monitor lost and back is a stop after
/// which the planner, which keeps asking, rightly never drives again by itself.
#[test]
fn chassis_demo_runs_every_agilex_robot_in_each_protocol() {
    const ROBOTS: [(&str, Option<&str>); 10] = [
        ("scout", None),
        ("scout-mini", Some("v2")),
        ("hunter", None),
        ("hunter-se", None),
        ("tracer", None),
        ("bunker", None),
        ("ranger-mini", None),
        ("scout", Some("v1")),
        ("bunker", Some("v1")),
        ("tracer-mini", None),
    ];
    // Every robot of the registry that speaks V2 is in the list: a new one is not left out.
    for kind in RobotKind::ALL {
        let v2 = kind
            .entry()
            .profiles()
            .any(|p| p.protocol() == Some(Protocol::V2));
        assert!(
            !v2 || ROBOTS.iter().any(|(robot, _)| *robot == kind.name()),
            "{kind} speaks V2 and is not in ROBOTS"
        );
    }
    let mut env = Env::new("demo-v2");
    let tag = std::process::id() % 10_000;
    for (group, robots) in ROBOTS.chunks(3).enumerate() {
        let mut demos = Vec::new();
        for (k, (robot, protocol)) in robots.iter().enumerate() {
            let name = format!("dv{group}{k}{tag}");
            let mut args = vec![
                "demo",
                "--robot",
                robot,
                "--name",
                &name,
                "--no-dashboard",
                "--duration",
                "8",
            ];
            if let Some(protocol) = protocol {
                args.extend(["--protocol", protocol]);
            }
            // One log per demo: SCOUT and BUNKER run twice, once per protocol.
            let label = format!("demo-{robot}-{}", protocol.unwrap_or("default"));
            let index = env.spawn(&label, "chassis", &args);
            demos.push((*robot, *protocol, name, index));
        }
        for (robot, protocol, name, _) in &demos {
            let mut handle = env.robot(name, Duration::from_secs(20));
            let driving = wait_for(Duration::from_secs(15), || {
                let m = mux(&mut handle);
                let s = state(&mut handle);
                m.active().map(SourceStatus::name) == Some("planner")
                    && m.zero_reason == ZeroReason::NONE
                    && s.motion.linear_mps.abs() > 0.1
            });
            assert!(
                driving.is_some(),
                "{robot}: not driving: {}\n{}",
                mux(&mut handle).why(),
                env.logs()
            );
            let s = state(&mut handle);
            let expected = match protocol {
                Some("v1") => WireProtocol::V1,
                _ => WireProtocol::V2,
            };
            assert_eq!(s.system.wire_protocol, expected, "{robot} {protocol:?}");
            let described = handle
                .description(Duration::from_secs(2))
                .unwrap_or_else(|e| panic!("{robot}: {e}\n{}", env.logs()));
            assert_eq!(described.kind_name(), *robot);
            assert_eq!(described.kind, s.robot);
            assert!(
                mux(&mut handle).sources()[0].has(SourceFlags::FRESH),
                "{robot}: safety monitor not alive"
            );
        }
        for (robot, _, _, index) in demos {
            assert_eq!(
                env.proc(index).wait_exit(Duration::from_secs(30)),
                Some(0),
                "{robot}\n{}",
                env.logs()
            );
            let log = env.proc(index).log_text();
            assert!(log.contains("driving from planner"), "{robot}: {log}");
        }
    }
}
