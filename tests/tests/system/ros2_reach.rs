//! How far `chassis-ros2` reaches, between two network namespaces joined by a veth pair with
//! multicast on (the robot's computer and another on its network): a Cyclone DDS participant
//! (tests/ros2/drive_peer.py, the Python `cyclonedds` of target/ros2-venv) publishes `cmd_vel`
//! from the other namespace. By default (ROS 2's discovery switches unset) it never reaches the
//! bridge and the robot does not move; with `ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET` it drives.
//!
//! Needs root (`ip netns`, veth pairs) and scripts/ros2-tests' virtualenv; discovery runs only on
//! the namespaces' own interfaces.
#![allow(clippy::unwrap_used, clippy::panic, clippy::disallowed_methods)]

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use chassis_tests::netns::*;
use chassis_tests::*;
use nix::sys::signal::Signal;

const UP: Duration = Duration::from_secs(20);
const ROBOT_ADDR: &str = "10.78.0.1";
const PEER_ADDR: &str = "10.78.0.2";

/// The robot's computer and another on its network, in namespaces unique to the test, with
/// multicast on and routed.
fn link() -> VethPair {
    let id = std::process::id() % 100_000;
    let (robot, peer) = (format!("crr{id}"), format!("crp{id}"));
    VethPair::new((&robot, ROBOT_ADDR), (&peer, PEER_ADDR), true)
}

/// scripts/ros2-tests' Python (with `cyclonedds`), or `CHASSIS_ROS2_PYTHON`.
fn python() -> PathBuf {
    venv_python(
        "CHASSIS_ROS2_PYTHON",
        "ros2-venv",
        ("cyclonedds", "cyclonedds"),
        "run scripts/ros2-tests once (it makes target/ros2-venv)",
    )
}

/// Starts chassis-ros2 in the robot's namespace with `envs` added.
fn bridge(env: &mut Env, link: &VethPair, n: &str, domain: &str, envs: &[(&str, &str)]) -> usize {
    let bin = bin("chassis-ros2");
    let prefix = env.prefix.clone();
    let mut all = vec![(IPC_PREFIX_ENV, prefix.as_str()), ("ROS_DOMAIN_ID", domain)];
    all.extend_from_slice(envs);
    all.push(("RUST_LOG", "info,rustdds=error,ros2_client=warn"));
    env.spawn_program(
        "chassis-ros2",
        Path::new("ip"),
        &[
            "netns",
            "exec",
            &link.robot_ns,
            bin.to_str().unwrap(),
            "--name",
            n,
        ],
        &all,
    )
}

/// The peer publishes 0.3 m/s for `seconds` from the other namespace while the test watches the
/// robot's mux; returns (readers the peer matched, the ros2 source ever won, the fastest
/// output the mux asked for).
fn peer_drives(
    env: &Env,
    link: &VethPair,
    robot: &mut Robot,
    domain: &str,
    seconds: f64,
) -> (u64, bool, f32) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("ros2/drive_peer.py");
    let child = Command::new("ip")
        .args(["netns", "exec", &link.peer_ns])
        .arg(python())
        .arg(&script)
        .args(["--domain", domain, "--seconds", &seconds.to_string()])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let end = Instant::now() + Duration::from_secs_f64(seconds + 1.0);
    let (mut won, mut peak) = (false, 0.0f32);
    while Instant::now() < end {
        robot
            .poll_mux(|m| {
                if m.active().is_some_and(|s| s.name() == "ros2") {
                    won = true;
                }
                peak = peak.max(m.output.linear_x_mps.abs());
            })
            .unwrap();
        pause(Duration::from_millis(10));
    }
    let out = child.wait_with_output().unwrap();
    let stdout = env.succeeded("drive_peer.py", &out);
    let summary: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    (summary["matched"].as_u64().unwrap(), won, peak)
}

#[test]
fn a_dds_peer_on_the_robots_network_drives_only_when_the_discovery_range_allows_it() {
    let link = link();
    let mut env = Env::new("ros2-reach");
    let n = format!("rr{}", std::process::id() % 100_000);
    let domain = (40 + std::process::id() % 50).to_string();
    env.serve("titan", &n, &["--no-safety-monitor"]);
    let mut robot = env.robot(&n, UP);

    // Default: this computer only. The peer, 10.78.0.2, matches no reader and nothing moves.
    let first = bridge(&mut env, &link, &n, &domain, &[]);
    let said = wait_for(UP, || env.logs().contains("DDS reach:"));
    assert!(
        said.is_some(),
        "the bridge did not say its reach\n{}",
        env.logs()
    );
    pause(Duration::from_secs(2));
    let (matched, won, peak) = peer_drives(&env, &link, &mut robot, &domain, 5.0);
    let by_default = (matched, won, peak);
    assert_eq!(
        (matched, won, peak),
        (0, false, 0.0),
        "a peer on the robot's network reached cmd_vel by default\n{}",
        env.logs()
    );
    assert!(
        env.logs().contains("DDS reach: THIS COMPUTER ONLY"),
        "{}",
        env.logs()
    );
    env.proc(first).signal(Signal::SIGTERM);
    assert_eq!(
        env.proc(first).wait_exit(Duration::from_secs(10)),
        Some(0),
        "{}",
        env.logs()
    );

    // ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET: the same peer drives, and the bridge said it could.
    bridge(
        &mut env,
        &link,
        &n,
        &domain,
        &[("ROS_AUTOMATIC_DISCOVERY_RANGE", "SUBNET")],
    );
    let said = wait_for(UP, || env.logs().contains("DDS reach: THE WHOLE NETWORK"));
    assert!(said.is_some(), "{}", env.logs());
    pause(Duration::from_secs(2));
    let (matched, won, peak) = peer_drives(&env, &link, &mut robot, &domain, 8.0);
    eprintln!(
        "SUBNET: the peer matched {matched} reader(s); ros2 won: {won}; peak output {peak} m/s"
    );
    assert!(
        matched >= 1 && won && peak > 0.2,
        "the peer could not drive with ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET: matched {matched}, won {won}, peak {peak}\n{}",
        env.logs()
    );
    let mut figures = Figures::faults();
    figures.add(Figure {
        rank: 750,
        fault: "a DDS peer on the robot's network publishes cmd_vel".into(),
        injection: "a Cyclone DDS participant in a second namespace, over a veth pair with multicast, publishes 0.3 m/s at 20 Hz; chassis-ros2 with ROS 2's discovery switches unset, then with ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET".into(),
        behaviour: "by default the bridge's participant stays on this computer: the peer matched no reader and the mux never took `ros2`; with SUBNET it drove, and the bridge said so at start".into(),
        figure: format!(
            "default: {} readers matched, ros2 won {}, output {} m/s; SUBNET: {matched} matched, output {peak} m/s",
            by_default.0, by_default.1, by_default.2
        ),
        value: f64::from(by_default.2),
        pass: true,
        suite: "ros2_reach".into(),
        test: "a_dds_peer_on_the_robots_network_drives_only_when_the_discovery_range_allows_it".into(),
    });
    figures.finish();
}
