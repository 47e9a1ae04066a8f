//! Network namespaces for the tests of the bridges between computers (`zenoh.rs`, `fleet.rs`,
//! `ros2_reach.rs`): running `ip` and programs inside a namespace, and the operator's side of a
//! Zenoh mirror (its own iceoryx2 prefix, the robot and the `remote` source it serves). Needs
//! root; nothing here touches an interface outside the namespaces a test creates.

use std::process::{Command, Output};
use std::time::{Duration, Instant};

use chassis_client::{MuxStatus, Robot, Source};

use crate::{Env, pause};

/// Runs `ip args…`; a failure fails the test with what `ip` said.
pub fn ip(args: &[&str]) {
    let out = Command::new("ip")
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("running ip {}: {e} (install iproute2)", args.join(" ")));
    assert!(
        out.status.success(),
        "ip {} failed: {}",
        args.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Runs `program args…` inside the namespace `ns` and returns what it did.
pub fn run_in(ns: &str, program: &str, args: &[&str]) -> Output {
    Command::new("ip")
        .args(["netns", "exec", ns, program])
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("running {program} in {ns}: {e}"))
}

/// The operator side's iceoryx2 prefix: another computer's.
pub fn operator_prefix(env: &Env) -> String {
    format!("{}op_", env.prefix)
}

/// The robot `n` as the operator's mirror serves it under `prefix`, once it does (within `up`).
pub fn operator_robot(env: &Env, n: &str, prefix: &str, up: Duration) -> Robot {
    let end = Instant::now() + up;
    loop {
        match Robot::connect_with_prefix(n, Some(prefix)) {
            Ok(robot) => return robot,
            Err(e) => assert!(
                Instant::now() < end,
                "the mirror never served {n}: {e}\n{}",
                env.logs()
            ),
        }
        pause(Duration::from_millis(50));
    }
}

/// The operator side's `remote` source, once the mirror has learned it from the robot's mux
/// (within `up`).
pub fn remote_source(env: &Env, robot: &mut Robot, up: Duration) -> Source {
    let end = Instant::now() + up;
    loop {
        match robot.source("remote") {
            Ok(source) => return source,
            Err(e) => assert!(
                Instant::now() < end,
                "the mirror never offered the remote source: {e}\n{}",
                env.logs()
            ),
        }
        pause(Duration::from_millis(50));
    }
}

/// The name of the mux's winner, `""` when none wins.
pub fn active_name(m: &MuxStatus) -> String {
    m.active().map_or("", |s| s.name()).to_string()
}
