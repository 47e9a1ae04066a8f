//! `chassis/<name>/robot`: chassisd describes the robot it drives — the effective profile after
//! every override, the protocol once detection decides, the mux's sources — and a client that
//! starts later reads it at once.
#![allow(clippy::unwrap_used, clippy::panic, clippy::disallowed_methods)]

use std::time::{Duration, Instant};

use chassis_tests::*;

const UP: Duration = Duration::from_secs(20);

#[test]
fn a_late_client_reads_the_description_of_the_configured_robot_with_its_overrides() {
    let mut env = Env::new("describe-hunter");
    let n = name("dh");
    let config = env.write(
        "hunter.toml",
        "[profile]\nmax_linear_mps = 0.4\n[mux.limits]\nmax_angular_radps = 0.7\nbraking_mps2 = 1.5\n",
    );
    env.serve("hunter", &n, &["--config", &config]);
    let _ = env.robot(&n, UP);
    // A client that comes an hour later (here: two seconds) reads it at once.
    std::thread::sleep(Duration::from_secs(2));
    let mut late = env.robot(&n, UP);
    let asked = Instant::now();
    let d = late
        .description(Duration::from_secs(2))
        .unwrap_or_else(|e| panic!("{e}\n{}", env.logs()));
    let waited = asked.elapsed();
    eprintln!("figure: a late client read the description after {waited:?}");
    assert!(waited < Duration::from_millis(500), "{waited:?}");
    assert_eq!(d.kind_name(), "hunter");
    assert_eq!(d.name(), n);
    assert_eq!(d.display_name(), "AgileX HUNTER 2.0");
    assert_eq!(d.kinematics, Kinematics::ACKERMANN);
    assert_eq!(d.protocol, WireProtocol::V2);
    assert_eq!(d.robot_limits.forward_mps, 0.4, "the [profile] override");
    assert_eq!(
        d.configured_limits.angular_radps, 0.7,
        "the [mux.limits] value"
    );
    assert_eq!(d.effective_limits().forward_mps, 0.4);
    // The braking figure a planner sizes its protective field from: configured, the manuals
    // giving none.
    assert!(d.robot_limits.braking_mps2.is_nan());
    assert_eq!(d.effective_limits().braking_mps2, 1.5);
    assert!(d.flags & DescriptionFlags::SIMULATED != 0);
    assert!(d.flags & DescriptionFlags::SAFETY_REQUIRED != 0);
    let safety = d
        .source("safety")
        .unwrap_or_else(|| panic!("no safety source"));
    assert!(safety.flags & SourceFlags::REQUIRED != 0);
    assert_eq!(d.source("teleop").map(|s| s.priority), Some(100));
    assert!(d.battery.low_v > 20.0, "{:?}", d.battery);
    assert_eq!(
        d.joints().iter().map(|j| j.name()).collect::<Vec<_>>(),
        ["front_steer_joint"]
    );
}

/// A SCOUT MINI on a real bus without `--protocol`: described as detecting while chassisd
/// listens, then as the protocol it heard, with that protocol's profile.
#[test]
fn the_description_follows_protocol_detection() {
    let mut env = Env::new("describe-detect");
    let n = name("dd");
    let link = env.dir.join("scout-mini-slcan");
    let extra = ["--protocol", "v2"];
    let (_, bus) = env.sim_on_pty("scout-mini", &extra, &n, Line::Slcan, &link, UP);
    env.serve("scout-mini", &n, &["--bus", &bus, "--no-safety-monitor"]);
    let mut robot = env.robot(&n, UP);
    let decided = wait_for(Duration::from_secs(10), || {
        let _ = robot.wait_state(Duration::from_millis(100));
        robot
            .latest_description()
            .unwrap()
            .is_some_and(|d| d.protocol == WireProtocol::V2)
    });
    let d = robot.latest_description().unwrap().unwrap();
    assert!(decided.is_some(), "{d:?}\n{}", env.logs());
    assert_eq!(d.kind_name(), "scout-mini");
    assert!(
        d.seq >= 2,
        "first described detecting, then V2: seq {}",
        d.seq
    );
    assert!(d.flags & DescriptionFlags::SIMULATED == 0, "a real bus");
    assert!(d.flags & DescriptionFlags::SAFETY_REQUIRED == 0);
    // The V2 SCOUT MINI's profile, not the V1 one's (its V1 full scale is 5 m/s).
    assert_eq!(d.robot_limits.forward_mps, 3.0, "{:?}", d.robot_limits);
}
