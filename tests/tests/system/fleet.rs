//! A fleet from one operator's computer: robots of three kinds, each in a network namespace of
//! its own (10.79.K.1), joined to the operator's namespace (10.79.K.2) by a veth pair each.
//! chassisd, the safety monitors and the robot sides of `chassis-zenoh` run under the test's
//! iceoryx2 prefix; the operator's `chassis-zenoh --mirror-all` mirrors them all under a prefix
//! of its own, where `chassis fleet` and `chassis control --all estop` look — so everything the
//! operator sees and does crosses the network, although all share this machine's /dev/shm.
//!
//! TLS with mutual authentication and each robot's access list are on, as on real robots: the
//! operator finds the robots through the one wildcard liveliness subscription the access list
//! allows. A link is cut with nftables in the operator's namespace (both directions of that
//! robot's interface dropped), the others untouched, and restored by removing that table: the
//! fleet e-stop asked while it was cut reaches that robot then.
//!
//! Needs root (`ip netns`, veth pairs, nft) and iproute2 and nftables; fails loudly without.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::disallowed_methods
)]

use std::path::Path;
use std::process::{Command, Output};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

use chassis_tests::netns::*;
use chassis_tests::*;

const UP: Duration = Duration::from_secs(30);
const PORT: u16 = 7447;
/// How soon a cut link must show as lost on the operator's side.
const LOST_WITHIN: Duration = Duration::from_secs(1);
/// How soon after its link returns a robot's chassisd must hold the fleet e-stop it missed, and
/// the fleet view show it held. The mirror delivers it as it hears the robot again (or on its 1 s
/// retry); what takes the time is Zenoh's reconnection: the operator's side retries every second
/// at most, but the robot's side closes the session it lost only once its own TCP retransmission
/// (backing off through the outage) meets the restored link and is reset — until then the new
/// connection joins the stale session and the robot's publications do not reach the operator.
/// Measured here: 2.6-3.5 s to the robot's chassisd, up to 9 s to the fleet view.
const BACK_WITHIN: Duration = Duration::from_secs(20);
/// How long `chassis fleet` may take to show a robot's e-stop as it is (a second's snapshot,
/// asked again until it does).
const SHOWN_WITHIN: Duration = Duration::from_secs(10);

static NEXT: AtomicU32 = AtomicU32::new(0);

/// The operator's namespace and one namespace per robot slot, each joined to the operator's by
/// a veth pair; removed on drop.
struct Net {
    id: String,
    operator_ns: String,
    robots: usize,
}

impl Net {
    fn new(robots: usize) -> Self {
        let id = format!(
            "{}{}",
            std::process::id() % 100_000,
            NEXT.fetch_add(1, Ordering::Relaxed)
        );
        let net = Net {
            operator_ns: format!("cfo{id}"),
            id,
            robots,
        };
        ip(&["netns", "add", &net.operator_ns]);
        ip(&["-n", &net.operator_ns, "link", "set", "lo", "up"]);
        for k in 0..robots {
            let (ns, robot_if, operator_if) =
                (net.robot_ns(k), net.robot_if(k), net.operator_if(k));
            ip(&["netns", "add", &ns]);
            ip(&[
                "link",
                "add",
                &robot_if,
                "type",
                "veth",
                "peer",
                "name",
                &operator_if,
            ]);
            ip(&["link", "set", &robot_if, "netns", &ns]);
            ip(&["link", "set", &operator_if, "netns", &net.operator_ns]);
            for (ns, dev, addr) in [
                (&ns, &robot_if, Self::robot_addr(k)),
                (&net.operator_ns, &operator_if, format!("10.79.{k}.2")),
            ] {
                ip(&["-n", ns, "addr", "add", &format!("{addr}/24"), "dev", dev]);
                ip(&["-n", ns, "link", "set", dev, "up"]);
                ip(&["-n", ns, "link", "set", "lo", "up"]);
            }
        }
        net
    }

    fn robot_ns(&self, k: usize) -> String {
        format!("cf{k}r{}", self.id)
    }

    fn robot_if(&self, k: usize) -> String {
        format!("cf{k}r{}", self.id)
    }

    fn operator_if(&self, k: usize) -> String {
        format!("cf{k}o{}", self.id)
    }

    fn robot_addr(k: usize) -> String {
        format!("10.79.{k}.1")
    }

    fn endpoint(k: usize) -> String {
        format!("tls/{}:{PORT}", Self::robot_addr(k))
    }

    /// Drops everything on robot `k`'s link, both directions, in the operator's namespace.
    fn cut(&self, k: usize) {
        let dev = self.operator_if(k);
        for rule in [
            "add table inet cut".to_string(),
            "add chain inet cut input { type filter hook input priority -10; }".to_string(),
            "add chain inet cut output { type filter hook output priority -10; }".to_string(),
            format!("add rule inet cut input iifname \"{dev}\" drop"),
            format!("add rule inet cut output oifname \"{dev}\" drop"),
        ] {
            nft(&self.operator_ns, &rule);
        }
    }

    /// Undoes [`Net::cut`].
    fn restore(&self) {
        nft(&self.operator_ns, "delete table inet cut");
    }
}

impl Drop for Net {
    fn drop(&mut self) {
        for k in 0..self.robots {
            let _ = Command::new("ip")
                .args(["netns", "del", &self.robot_ns(k)])
                .status();
        }
        let _ = Command::new("ip")
            .args(["netns", "del", &self.operator_ns])
            .status();
    }
}

/// Robot slot `k`: chassisd of `kind` named `n`, its safety monitor, and its robot side on
/// its own namespace's address, under TLS.
fn robot(env: &mut Env, net: &Net, certs: &Path, k: usize, kind: &str, n: &str) -> Robot {
    env.chassisd(&format!("chassisd-{n}"), &["--robot", kind, "--name", n]);
    env.spawn(&format!("safety-{n}"), "chassis-safety", &["--name", n]);
    let robot = env.robot(n, UP);
    let prefix = env.prefix.clone();
    let listen = Net::endpoint(k);
    zenoh_in(
        env,
        &format!("zenoh-{n}"),
        &net.robot_ns(k),
        &prefix,
        &[
            "--name",
            n,
            "--listen",
            &listen,
            "--certs",
            certs.to_str().unwrap(),
        ],
    );
    robot
}

/// `chassis args…` on the operator's computer (its prefix).
fn operator_chassis(env: &Env, args: &[&str]) -> Output {
    Command::new(bin("chassis"))
        .args(args)
        .env(IPC_PREFIX_ENV, operator_prefix(env))
        .output()
        .unwrap()
}

/// `chassis fleet --once --json` on the operator's computer: its rows by name.
fn fleet(env: &Env, collect: &str) -> serde_json::Map<String, serde_json::Value> {
    let out = operator_chassis(env, &["fleet", "--once", "--json", "--collect", collect]);
    assert!(
        out.status.success(),
        "chassis fleet: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "chassis fleet --json: {e}: {}",
            String::from_utf8_lossy(&out.stdout)
        )
    });
    doc["robots"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| (r["name"].as_str().unwrap().to_string(), r.clone()))
        .collect()
}

/// Waits at most `within` until the fleet view shows each robot's e-stop as `estops` says;
/// returns how long it took, if it did, and the rows last seen.
fn fleet_estops(
    env: &Env,
    estops: &[(&str, &str)],
    within: Duration,
) -> (Option<Duration>, serde_json::Map<String, serde_json::Value>) {
    let mut rows = serde_json::Map::new();
    let took = wait_for(within, || {
        rows = fleet(env, "1.0");
        estops
            .iter()
            .all(|(n, estop)| rows.get(*n).is_some_and(|r| r["estop"] == *estop))
    });
    (took, rows)
}

/// Waits until the fleet view shows each of `names` whole — link ok, its mux's e-stop, a
/// latency measured — and returns the rows.
fn fleet_shows(env: &Env, names: &[&str]) -> serde_json::Map<String, serde_json::Value> {
    let end = Instant::now() + UP;
    loop {
        let rows = fleet(env, "0.5");
        if names.iter().all(|n| {
            rows.get(*n).is_some_and(|r| {
                r["link"] == "ok"
                    && r["estop"] != "unknown"
                    && r["latency"]["count"].as_u64().is_some_and(|c| c > 0)
            })
        }) {
            return rows;
        }
        assert!(
            Instant::now() < end,
            "the fleet view never showed {names:?} reachable: {rows:#?}\n{}",
            env.logs()
        );
        pause(Duration::from_millis(200));
    }
}

fn operator_robot(env: &Env, n: &str) -> Robot {
    netns::operator_robot(env, n, &operator_prefix(env), UP)
}

fn estop_held(m: &MuxStatus) -> bool {
    m.locks().iter().any(|l| l.name() == "estop" && l.held != 0)
}

/// Drives `sources` at 20 Hz until every robot's own mux has `remote` active.
fn drive_until_remote_wins(env: &Env, robots: &mut [&mut Robot], sources: &mut [&mut Source]) {
    let end = Instant::now() + UP;
    loop {
        for s in sources.iter_mut() {
            s.send(VelocityRequest::twist(0.3, 0.0)).unwrap();
        }
        pause(Duration::from_millis(50));
        if robots.iter_mut().all(|r| {
            let _ = r.wait_mux(Duration::from_millis(50));
            r.latest_mux()
                .ok()
                .flatten()
                .is_some_and(|m| active_name(&m) == "remote")
        }) {
            return;
        }
        assert!(
            Instant::now() < end,
            "the remote sources never won\n{}",
            env.logs()
        );
    }
}

#[test]
fn an_operator_finds_three_robots_stops_the_lost_one_when_it_returns_and_finds_a_fourth() {
    let net = Net::new(4);
    let mut env = Env::new("fleet");
    let certs = env.dir.join("certs");
    let mut gen_args = vec!["gen-certs".to_string(), certs.to_str().unwrap().to_string()];
    for k in 0..4 {
        gen_args.push("--host".into());
        gen_args.push(Net::robot_addr(k));
    }
    let gen_args: Vec<&str> = gen_args.iter().map(String::as_str).collect();
    let out = env.run("chassis-zenoh", &gen_args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    let id = std::process::id() % 100_000;
    let names: Vec<String> = ["fa", "fb", "fc", "fd"]
        .iter()
        .map(|p| format!("{p}{id}"))
        .collect();
    let (a, b, c, d) = (&names[0], &names[1], &names[2], &names[3]);
    let mut robot_a = robot(&mut env, &net, &certs, 0, "titan", a);
    let mut robot_b = robot(&mut env, &net, &certs, 1, "scout-mini", b);
    let mut robot_c = robot(&mut env, &net, &certs, 2, "hunter", c);

    // The operator connects to every robot's endpoint (the fourth is not there yet) and
    // mirrors whatever announces itself.
    let prefix = operator_prefix(&env);
    let mut args: Vec<String> = Vec::new();
    for k in 0..4 {
        args.push("--connect".into());
        args.push(Net::endpoint(k));
    }
    args.extend([
        "--certs".into(),
        certs.to_str().unwrap().into(),
        "--mirror-all".into(),
    ]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let operator_ns = net.operator_ns.clone();
    let operator = zenoh_in(&mut env, "zenoh-operator", &operator_ns, &prefix, &args);

    // Three kinds, found and shown.
    let rows = fleet_shows(&env, &[a, b, c]);
    for (n, kind, protocol) in [
        (a, "titan", "own"),
        (b, "scout-mini", "v1"),
        (c, "hunter", "v2"),
    ] {
        let row = &rows[n.as_str()];
        assert_eq!(row["kind"], kind, "{row:#}");
        assert_eq!(row["protocol"], protocol, "{row:#}");
        assert_eq!(row["estop"], "free", "{row:#}");
        assert!(row["latency"]["count"].as_u64().unwrap() > 0, "{row:#}");
    }
    assert_eq!(rows.len(), 3, "only the three robots: {rows:#?}");

    // Drive A and B from the operator's computer.
    let mut op_a = operator_robot(&env, a);
    let mut op_b = operator_robot(&env, b);
    let mut remote_a = remote_source(&env, &mut op_a, UP);
    let mut remote_b = remote_source(&env, &mut op_b, UP);
    drive_until_remote_wins(
        &env,
        &mut [&mut robot_a, &mut robot_b],
        &mut [&mut remote_a, &mut remote_b],
    );
    let timeout_a = source_timeout(&mux(&mut robot_a), "remote");

    // Cut A's link; the operator keeps driving both.
    let cut_ns = now_ns();
    let cut = Instant::now();
    net.cut(0);
    let mut lost_after = None;
    let mut b_remote_decisions = (0u32, 0u32);
    let stopped = decided_after(
        &mut robot_a,
        cut_ns,
        Duration::from_secs(3),
        || {
            let _ = remote_a.send(VelocityRequest::twist(0.3, 0.0));
            remote_b.send(VelocityRequest::twist(0.3, 0.0)).unwrap();
            if lost_after.is_none()
                && let Ok(Some(s)) = op_a.wait_state(Duration::from_millis(10))
                && s.link_flags & LinkFlags::REMOTE_LOST != 0
            {
                lost_after = Some(cut.elapsed());
            }
            if let Ok(Some(m)) = robot_b.latest_mux() {
                b_remote_decisions.0 += 1;
                b_remote_decisions.1 += u32::from(active_name(&m) == "remote");
            }
            pause(Duration::from_millis(10));
        },
        |m| active_name(m) != "remote" && m.output.linear_x_mps == 0.0,
    )
    .unwrap_or_else(|| {
        panic!(
            "robot A kept driving after its link was cut\n{}",
            env.logs()
        )
    });
    eprintln!(
        "link of {a} cut: its mux commanded zero {:.0} ms after the cut (remote timeout {timeout_a:?})",
        stopped.as_secs_f64() * 1e3
    );
    assert!(
        stopped <= timeout_a + DECISION_ALLOWANCE + Duration::from_millis(30),
        "A stopped {stopped:?} after the cut; its remote timeout is {timeout_a:?}"
    );
    // Shown lost on the operator's side within a second.
    let lost = lost_after.or_else(|| {
        wait_for(LOST_WITHIN, || {
            remote_b.send(VelocityRequest::twist(0.3, 0.0)).unwrap();
            op_a.wait_state(Duration::from_millis(20))
                .ok()
                .flatten()
                .is_some_and(|s| s.link_flags & LinkFlags::REMOTE_LOST != 0)
        })
        .map(|_| cut.elapsed())
    });
    eprintln!("link of {a} cut: shown lost here after {lost:?}");
    assert!(
        lost.is_some_and(|t| t <= LOST_WITHIN),
        "A was not shown lost within {LOST_WITHIN:?} (after {lost:?})\n{}",
        env.logs()
    );
    // B kept driving throughout, and A's safety monitor stayed fresh.
    assert!(
        b_remote_decisions.0 > 0 && b_remote_decisions.1 == b_remote_decisions.0,
        "B's remote source lost the mux during A's cut: {b_remote_decisions:?}"
    );
    assert_eq!(active_name(&mux(&mut robot_b)), "remote");
    let m = mux(&mut robot_a);
    assert!(m.sources()[0].has(SourceFlags::FRESH), "{m:?}");

    // The fleet view: A lost, B and C ok.
    let rows = fleet(&env, "1.5");
    assert_eq!(rows[a.as_str()]["link"], "lost", "{rows:#?}");
    assert_eq!(rows[b.as_str()]["link"], "ok", "{rows:#?}");
    assert_eq!(rows[c.as_str()]["link"], "ok", "{rows:#?}");

    // The fleet-wide e-stop holds B and C and names A as not stopped.
    let out = operator_chassis(&env, &["control", "--all", "estop", "--timeout-ms", "1500"]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    eprintln!(
        "chassis control --all estop:\n{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(out.status.code(), Some(1), "{stdout}");
    let line = |n: &str| {
        stdout
            .lines()
            .find(|l| l.split_whitespace().any(|w| w == n))
            .unwrap_or_else(|| panic!("no line for {n}: {stdout}"))
            .to_string()
    };
    assert!(line(a).starts_with("NOT STOPPED"), "{stdout}");
    assert!(line(b).starts_with("stopped"), "{stdout}");
    assert!(line(c).starts_with("stopped"), "{stdout}");
    for (n, r) in [(b, &mut robot_b), (c, &mut robot_c)] {
        let m = mux(r);
        assert!(estop_held(&m), "{n} not held after the fleet e-stop: {m:?}");
    }
    assert!(
        !estop_held(&mux(&mut robot_a)),
        "A cannot have heard the e-stop"
    );
    let halted = comes_to_rest(&mut robot_b, Duration::from_secs(3), 0.02);
    assert!(
        halted.is_some(),
        "B did not come to a halt under the e-stop"
    );

    // A's mirror keeps A's e-stop asked: A is named pending, and shown so in the fleet view.
    assert!(
        line(a).contains("pending: the mirror keeps the e-stop asked"),
        "A is not named pending: {stdout}"
    );
    for n in [b, c] {
        assert!(!line(n).contains("pending"), "{n} is stopped: {stdout}");
    }
    let (shown, rows) = fleet_estops(
        &env,
        &[(a, "pending"), (b, "held"), (c, "held")],
        SHOWN_WITHIN,
    );
    assert!(
        shown.is_some(),
        "A not shown pending, B and C held: {rows:#?}"
    );
    assert!(!estop_held(&mux(&mut robot_a)), "A is still cut off");

    // A's link returns: A's own chassisd holds the e-stop within the bound, for the operator.
    net.restore();
    let restored = Instant::now();
    let delivered = wait_for(BACK_WITHIN, || {
        robot_a
            .wait_mux(Duration::from_millis(50))
            .ok()
            .flatten()
            .is_some_and(|m| estop_held(&m))
    });
    eprintln!("link of {a} restored: its chassisd holds the e-stop after {delivered:?}");
    let m = mux(&mut robot_a);
    assert!(
        delivered.is_some(),
        "A's chassisd did not hold the e-stop within {BACK_WITHIN:?} of its link's return: \
         {m:?}\n{}",
        env.logs()
    );
    let lock = m.locks().iter().find(|l| l.name() == "estop").unwrap();
    assert_eq!(lock.holder, LockStatus::HOLDER_OPERATOR, "{m:?}");
    // And the fleet view shows it held.
    let (shown, rows) = fleet_estops(&env, &[(a, "held")], BACK_WITHIN);
    eprintln!(
        "link of {a} restored: shown held here after {:?}",
        restored.elapsed()
    );
    assert!(shown.is_some(), "A not shown held: {rows:#?}");
    assert_eq!(rows[a.as_str()]["estop_holder"], "operator", "{rows:#?}");
    let log = env.proc(operator).log_text();
    assert!(
        log.contains(&format!("robot '{a}' did not take the e-stop"))
            && log.contains(&format!("robot '{a}' has the e-stop now")),
        "the mirror's log says nothing of A's pending e-stop:\n{log}"
    );

    // A robot switched on later is found.
    let _robot_d = robot(&mut env, &net, &certs, 3, "hunter-se", d);
    let rows = fleet_shows(&env, &[b, c, d]);
    assert_eq!(rows[d.as_str()]["kind"], "hunter-se", "{rows:#?}");
    assert_eq!(rows.len(), 4, "{rows:#?}");
    remote_b.stop().unwrap();
}
