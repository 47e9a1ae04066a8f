//! Network namespaces for the tests of the bridges between computers (`zenoh.rs`, `fleet.rs`,
//! `ros2_reach.rs`): running `ip` and programs inside a namespace, and the operator's side of a
//! Zenoh mirror (its own iceoryx2 prefix, the robot and the `remote` source it serves). Needs
//! root; nothing here touches an interface outside the namespaces a test creates.

use std::path::Path;
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use chassis_client::{IPC_PREFIX_ENV, MuxStatus, Robot, Source};

use crate::{Env, bin, pause};

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

/// Two network namespaces joined by a veth pair whose ends are named like their namespaces:
/// the robot's computer and a peer (an operator's, another on the robot's network), each end
/// addressed in a /24 and up with its loopback. Removed on drop: removing a namespace removes
/// its end of the pair, and so the pair.
#[derive(Debug)]
pub struct VethPair {
    pub robot_ns: String,
    pub peer_ns: String,
    pub robot_if: String,
    pub peer_if: String,
}

impl VethPair {
    /// Namespaces `robot` and `peer` with the addresses `robot_addr` and `peer_addr`; with
    /// `multicast`, multicast on both ends and their loopbacks, and 224.0.0.0/4 routed to the
    /// pair.
    pub fn new(
        (robot, robot_addr): (&str, &str),
        (peer, peer_addr): (&str, &str),
        multicast: bool,
    ) -> Self {
        let pair = Self {
            robot_ns: robot.to_string(),
            peer_ns: peer.to_string(),
            robot_if: robot.to_string(),
            peer_if: peer.to_string(),
        };
        ip(&["netns", "add", &pair.robot_ns]);
        ip(&["netns", "add", &pair.peer_ns]);
        ip(&[
            "link",
            "add",
            &pair.robot_if,
            "type",
            "veth",
            "peer",
            "name",
            &pair.peer_if,
        ]);
        ip(&["link", "set", &pair.robot_if, "netns", &pair.robot_ns]);
        ip(&["link", "set", &pair.peer_if, "netns", &pair.peer_ns]);
        for (ns, dev, addr) in [
            (&pair.robot_ns, &pair.robot_if, robot_addr),
            (&pair.peer_ns, &pair.peer_if, peer_addr),
        ] {
            ip(&["-n", ns, "addr", "add", &format!("{addr}/24"), "dev", dev]);
            if multicast {
                ip(&["-n", ns, "link", "set", dev, "multicast", "on"]);
            }
            ip(&["-n", ns, "link", "set", dev, "up"]);
            ip(&["-n", ns, "link", "set", "lo", "up"]);
            if multicast {
                ip(&["-n", ns, "link", "set", "lo", "multicast", "on"]);
                ip(&["-n", ns, "route", "add", "224.0.0.0/4", "dev", dev]);
            }
        }
        pair
    }

    /// Takes the robot's end of the pair down (`up = false`) or up again.
    pub fn set(&self, up: bool) {
        let state = if up { "up" } else { "down" };
        ip(&["-n", &self.robot_ns, "link", "set", &self.robot_if, state]);
    }
}

impl Drop for VethPair {
    fn drop(&mut self) {
        for ns in [&self.robot_ns, &self.peer_ns] {
            let _ = Command::new("ip").args(["netns", "del", ns]).status();
        }
    }
}

/// Starts `chassis-zenoh args…` inside `ns`, under `prefix`.
pub fn zenoh_in(env: &mut Env, label: &str, ns: &str, prefix: &str, args: &[&str]) -> usize {
    zenoh_logging(env, label, ns, prefix, args, "info,zenoh=warn")
}

/// [`zenoh_in`] with the log filter `log`.
pub fn zenoh_logging(
    env: &mut Env,
    label: &str,
    ns: &str,
    prefix: &str,
    args: &[&str],
    log: &str,
) -> usize {
    let bin_text = bin("chassis-zenoh").to_string_lossy().into_owned();
    let mut all = vec!["netns", "exec", ns, &bin_text];
    all.extend_from_slice(args);
    env.spawn_program(
        label,
        Path::new("ip"),
        &all,
        &[(IPC_PREFIX_ENV, prefix), ("RUST_LOG", log)],
    )
}

/// Runs `nft RULE` inside the namespace `ns`; a failure fails the test with what it said.
pub fn nft(ns: &str, rule: &str) {
    let out = run_in(ns, "nft", &[rule]);
    assert!(
        out.status.success(),
        "nft {rule}: {} (install nftables)",
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
