//! `chassis-zenoh` between two network namespaces joined by a veth pair, standing in for the
//! robot's computer (10.77.0.1) and an operator's (10.77.0.2). chassisd and the robot side run
//! under the test's iceoryx2 prefix; the operator side mirrors the robot under a prefix of its
//! own, so the test drives through the network although both share this machine's /dev/shm.
//!
//! Needs root (`ip netns`, veth pairs) and iproute2; fails loudly without them. Each test makes
//! its own namespaces (unique names) and removes them, whatever happens.
#![allow(clippy::unwrap_used, clippy::panic, clippy::disallowed_methods)]

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

use chassis_tests::netns::*;
use chassis_tests::*;

const UP: Duration = Duration::from_secs(20);
const ROBOT_ADDR: &str = "10.77.0.1";
const OPERATOR_ADDR: &str = "10.77.0.2";
const PORT: u16 = 7447;

static NEXT: AtomicU32 = AtomicU32::new(0);

/// The robot's computer and the operator's, in namespaces unique to the test.
fn link() -> VethPair {
    let id = format!(
        "{}{}",
        std::process::id() % 100_000,
        NEXT.fetch_add(1, Ordering::Relaxed)
    );
    let robot = (format!("czr{id}"), ROBOT_ADDR);
    let operator = (format!("czo{id}"), OPERATOR_ADDR);
    VethPair::new((&robot.0, robot.1), (&operator.0, operator.1), false)
}

fn endpoint(proto: &str) -> String {
    format!("{proto}/{ROBOT_ADDR}:{PORT}")
}

/// A test (`test` names its environment) between two namespaces, with chassisd and the robot
/// side running for robot NAME (`tag` and the pid): the namespaces, the environment, NAME and
/// the connection to chassisd.
fn robot_over_link(test: &str, tag: &str) -> (VethPair, Env, String, Robot) {
    let link = link();
    let mut env = Env::new(test);
    let n = name(tag);
    let robot = robot_side(&mut env, &link, &n);
    (link, env, n, robot)
}

/// chassisd (with its required safety monitor running) and the robot side, plain TCP.
fn robot_side(env: &mut Env, link: &VethPair, n: &str) -> Robot {
    robot_side_with(env, link, n, "tcp", &["--insecure"])
}

/// chassisd (with its required safety monitor running) and the robot side listening on
/// `scheme` (`tcp`, `tls`), with `extra` arguments.
fn robot_side_with(env: &mut Env, link: &VethPair, n: &str, scheme: &str, extra: &[&str]) -> Robot {
    env.serve("titan", n, &[]);
    env.spawn("safety", "chassis-safety", &["--name", n]);
    let robot = env.robot(n, UP);
    let prefix = env.prefix.clone();
    let listen = endpoint(scheme);
    let mut args = vec!["--name", n, "--listen", &listen];
    args.extend_from_slice(extra);
    zenoh_in(env, "zenoh-robot", &link.robot_ns, &prefix, &args);
    robot
}

/// The operator side's mirror and a connection to it.
fn mirror(env: &mut Env, link: &VethPair, n: &str, extra: &[&str]) -> Robot {
    let connect = endpoint(if extra.contains(&"--certs") {
        "tls"
    } else {
        "tcp"
    });
    mirror_at(env, link, n, &connect, extra)
}

/// The operator side's mirror connecting to `connect`, and a connection to it.
fn mirror_at(env: &mut Env, link: &VethPair, n: &str, connect: &str, extra: &[&str]) -> Robot {
    let prefix = operator_prefix(env);
    let mut args = vec!["--name", n, "--connect", connect, "--mirror"];
    args.extend_from_slice(extra);
    zenoh_in(env, "zenoh-operator", &link.peer_ns, &prefix, &args);
    operator_robot(env, n, &prefix, UP)
}

/// Sends `linear` every 50 ms from `source` until the robot's own mux has `remote` active and
/// its state moves faster than `speed`; returns how long that took.
fn drive_until_moving(
    robot: &mut Robot,
    source: &mut Source,
    linear: f32,
    speed: f32,
    timeout: Duration,
) -> Option<Duration> {
    let start = Instant::now();
    let mut last_send = None::<Instant>;
    while start.elapsed() < timeout {
        if last_send.is_none_or(|t| t.elapsed() >= Duration::from_millis(50)) {
            source.send(VelocityRequest::twist(linear, 0.0)).unwrap();
            last_send = Some(Instant::now());
        }
        if let Ok(Some(s)) = robot.wait_state(Duration::from_millis(10))
            && s.motion.linear_mps > speed
            && robot
                .latest_mux()
                .ok()
                .flatten()
                .is_some_and(|m| active_name(&m) == "remote")
        {
            return Some(start.elapsed());
        }
    }
    None
}

#[test]
fn an_operator_drives_over_zenoh_and_a_cut_link_stops_the_robot_within_the_timeout() {
    let (link, mut env, n, mut robot) = robot_over_link("zenoh-drive", "zdr");
    let mut operator = mirror(&mut env, &link, &n, &["--insecure"]);
    let mut remote = remote_source(&env, &mut operator, UP);

    // Only the remote sources exist on the operator's side: never the safety monitor's.
    let err = operator.source("safety").unwrap_err();
    assert!(matches!(err, ClientError::UnknownSource { .. }), "{err}");

    // Drive from the operator's computer; the robot moves and its state comes back.
    let took = drive_until_moving(&mut robot, &mut remote, 0.4, 0.2, UP)
        .unwrap_or_else(|| panic!("the robot never moved\n{}", env.logs()));
    let mirrored = wait_for(Duration::from_secs(3), || {
        remote.send(VelocityRequest::twist(0.4, 0.0)).unwrap();
        operator
            .wait_state(Duration::from_millis(50))
            .ok()
            .flatten()
            .is_some_and(|s| s.motion.linear_mps > 0.2)
    });
    assert!(
        mirrored.is_some(),
        "the operator never saw the robot move\n{}",
        env.logs()
    );
    let timeout = source_timeout(&mux(&mut robot), "remote");
    eprintln!("moving {took:?} after the first request; remote timeout {timeout:?}");

    // The unchanged dashboard on the operator's side shows the robot, its mux and its bus.
    let top = Command::new(bin("chassis"))
        .args(["top", "--once", "--name", &n])
        .env(IPC_PREFIX_ENV, operator_prefix(&env))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let pid = top.id();
    let mut top = Some(top);
    let done = wait_for(Duration::from_secs(10), || {
        remote.send(VelocityRequest::twist(0.4, 0.0)).unwrap();
        pause(Duration::from_millis(40));
        top.as_mut()
            .is_some_and(|t| t.try_wait().ok().flatten().is_some())
    });
    let out = top.take().unwrap().wait_with_output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        done.is_some() && out.status.success(),
        "chassis top (pid {pid}) on the operator's side: {text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("active remote (priority 100"), "{text}");
    assert!(text.contains("RX  0x211"), "{text}");

    // A control action from the operator's computer is answered by chassisd.
    let answer = operator
        .control(
            ControlRequest::new(ControlKind::LIGHTS).with_arg(0, LightMode::ON),
            Duration::from_secs(5),
        )
        .unwrap();
    assert!(
        answer.status != ControlStatus::TIMEOUT,
        "no answer through the mirror: {}",
        answer.message()
    );

    // Cut the link mid-drive; the operator keeps sending.
    let cut_ns = now_ns();
    link.set(false);
    let mut safety_stale = false;
    let stopped = decided_after(
        &mut robot,
        cut_ns,
        Duration::from_secs(3),
        || {
            let _ = remote.send(VelocityRequest::twist(0.4, 0.0));
            pause(Duration::from_millis(20));
        },
        |m| {
            safety_stale |= m.zero_reason == ZeroReason::REQUIRED_SOURCE_STALE
                || !m.sources()[0].has(SourceFlags::FRESH);
            active_name(m) != "remote" && m.output.linear_x_mps == 0.0
        },
    )
    .unwrap_or_else(|| panic!("the robot kept driving after the cut\n{}", env.logs()));
    eprintln!(
        "link cut: the robot's mux commanded zero {:.0} ms after the cut (remote timeout {:?})",
        stopped.as_secs_f64() * 1e3,
        timeout
    );
    assert!(
        stopped <= timeout + DECISION_ALLOWANCE + Duration::from_millis(30),
        "stopped {stopped:?} after the cut; the remote source's timeout is {timeout:?}"
    );
    let m = mux(&mut robot);
    assert!(
        m.sources()[0].name() == "safety" && m.sources()[0].has(SourceFlags::FRESH),
        "{m:?}"
    );
    assert!(
        !safety_stale,
        "the safety monitor went stale during the cut"
    );
    let halted = comes_to_rest(&mut robot, Duration::from_secs(3), 0.02);
    assert!(halted.is_some(), "the robot did not come to a halt");

    // Link back: the same processes drive again.
    pause(Duration::from_millis(1000));
    link.set(true);
    let again = drive_until_moving(&mut robot, &mut remote, 0.4, 0.2, UP)
        .unwrap_or_else(|| panic!("no motion after the link came back\n{}", env.logs()));
    eprintln!("link back: moving again {again:?} after the link came up");
    for i in 0..4 {
        let running = env.proc(i).is_running();
        assert!(
            running,
            "{} exited\n{}",
            env.proc(i).name.clone(),
            env.logs()
        );
    }
    remote.stop().unwrap();
}

fn gen_certs(env: &Env, dir: &Path) {
    let out = Command::new(bin("chassis-zenoh"))
        .args(["gen-certs", dir.to_str().unwrap(), "--host", ROBOT_ADDR])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "gen-certs: {}\n{}",
        String::from_utf8_lossy(&out.stderr),
        env.logs()
    );
}

#[test]
fn under_tls_the_operator_with_its_certificate_drives_and_a_stranger_is_refused() {
    let link = link();
    let mut env = Env::new("zenoh-tls");
    let n = name("ztl");
    let certs = env.dir.join("certs");
    let stranger = env.dir.join("stranger");
    gen_certs(&env, &certs);
    gen_certs(&env, &stranger);

    // Plain TCP beyond loopback is refused unless asked for.
    let out = Command::new(bin("chassis-zenoh"))
        .args(["--name", &n, "--listen", &endpoint("tcp")])
        .env(IPC_PREFIX_ENV, &env.prefix)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(stderr.contains("refusing plain TCP"), "{stderr}");

    let certs_arg = ["--certs", certs.to_str().unwrap()];
    let mut robot = robot_side_with(&mut env, &link, &n, "tls", &certs_arg);
    let listen = endpoint("tls");
    // A mirror holding certificates of another authority, under a prefix of its own.
    let stranger_prefix = format!("{}st_", env.prefix);
    zenoh_logging(
        &mut env,
        "zenoh-stranger",
        &link.peer_ns,
        &stranger_prefix,
        &[
            "--name",
            &n,
            "--connect",
            &listen,
            "--certs",
            stranger.to_str().unwrap(),
            "--mirror",
        ],
        "info,zenoh=debug",
    );
    let mut operator = mirror(&mut env, &link, &n, &certs_arg);
    let mut remote = remote_source(&env, &mut operator, UP);
    drive_until_moving(&mut robot, &mut remote, 0.4, 0.2, UP)
        .unwrap_or_else(|| panic!("the robot never moved under TLS\n{}", env.logs()));
    remote.stop().unwrap();

    // The stranger's mirror, running as long, has seen nothing of the robot.
    let mut outsider = operator_robot(&env, &n, &stranger_prefix, UP);
    assert!(
        outsider
            .wait_state(Duration::from_secs(2))
            .unwrap()
            .is_none(),
        "a mirror without the robot's CA got state\n{}",
        env.logs()
    );
    assert!(outsider.latest_mux().unwrap().is_none());
    assert!(matches!(
        outsider.source("remote"),
        Err(ClientError::UnknownSource { .. })
    ));
    // The operator's certificate reads the state, but the access list stops its puts on
    // cmd/safety before they reach the bridge (which would log a refusal).
    let python = python();
    let stdout = read_state(
        &python,
        &env,
        &link,
        &mut robot,
        &listen,
        &["--certs", certs.to_str().unwrap()],
    );
    let summary: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    assert_eq!(summary["samples"], 50, "{summary}");
    pause(Duration::from_millis(500));
    assert!(
        !env.logs().contains("refused a velocity request"),
        "a put on cmd/safety passed the access list\n{}",
        env.logs()
    );

    // Refused for its certificate, as the TLS handshake says (not for any other failure, nor
    // passed by a mere mention of certificates being loaded).
    let log = env.proc(3).log_text();
    assert!(
        log.contains("invalid peer certificate"),
        "the stranger was not refused for its certificate\n{}",
        env.logs()
    );
}

/// The Python with `eclipse-zenoh` and the `chassis` package (scripts/zenoh-tests prepares
/// target/python-venv), or `CHASSIS_ZENOH_PYTHON`.
fn python() -> PathBuf {
    venv_python(
        "CHASSIS_ZENOH_PYTHON",
        "python-venv",
        ("zenoh, chassis", "zenoh and chassis"),
        "run scripts/zenoh-tests --prepare (it installs eclipse-zenoh and clients/python into \
         target/python-venv)",
    )
}

/// Runs tests/zenoh/read_state.py in the operator's namespace (it publishes on `cmd/safety`
/// too), expecting the robot kind `robot`'s description gives; returns its summary line.
fn read_state(
    python: &Path,
    env: &Env,
    link: &VethPair,
    robot: &mut Robot,
    connect: &str,
    extra: &[&str],
) -> String {
    let n = robot.name().to_string();
    let kind = robot
        .description(UP)
        .unwrap_or_else(|e| panic!("no description of {n}: {e}\n{}", env.logs()))
        .kind
        .to_string();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("zenoh/read_state.py");
    let out = Command::new("ip")
        .args(["netns", "exec", &link.peer_ns])
        .arg(python)
        .arg(&script)
        .args([
            "--connect",
            connect,
            "--name",
            &n,
            "--kind",
            &kind,
            "--count",
            "50",
            "--put-source",
            "safety",
        ])
        .args(extra)
        .output()
        .unwrap();
    env.succeeded("read_state.py failed", &out)
}

#[test]
fn an_independent_python_zenoh_client_reads_the_state_and_cannot_drive_safety() {
    let python = python();
    let (link, env, n, mut robot) = robot_over_link("zenoh-python", "zpy");
    let stdout = read_state(&python, &env, &link, &mut robot, &endpoint("tcp"), &[]);
    let summary: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    eprintln!("Python eclipse-zenoh reader: {summary}");
    assert_eq!(summary["samples"], 50);
    assert!(summary["matched"].as_u64().unwrap() >= 1, "{summary}");

    // The requests on cmd/safety were refused by the robot side, and counted.
    let refused = format!("refused a velocity request on chassis/{n}/cmd/safety");
    let found = wait_for(Duration::from_secs(3), || env.logs().contains(&refused));
    assert!(found.is_some(), "no refusal logged\n{}", env.logs());
}

/// Delay and loss on the link. `tc netem` where the kernel has it; otherwise (kernels built
/// without `sch_netem`) loss from nftables (`numgen random`) on the operator's end of the veth
/// and the delay from [`DelayRelay`], a relay in the operator's namespace that holds every
/// chunk for the delay in each direction.
enum Impairment {
    Netem,
    Emulated { _relay: DelayRelay },
}

const DELAY: Duration = Duration::from_millis(100);
const LOSS_PERCENT: u32 = 5;
/// Where the emulated impairment's relay listens, in the operator's namespace.
const RELAY_PORT: u16 = 7448;

impl Impairment {
    fn apply(link: &VethPair) -> Self {
        let delay = format!("{}ms", DELAY.as_millis());
        let loss = format!("{LOSS_PERCENT}%");
        let operator_if = &link.peer_if;
        let mut netem = true;
        for (ns, dev) in [
            (&link.robot_ns, &link.robot_if),
            (&link.peer_ns, operator_if),
        ] {
            let out = run_in(
                ns,
                "tc",
                &[
                    "qdisc", "add", "dev", dev, "root", "netem", "delay", &delay, "loss", &loss,
                ],
            );
            if !out.status.success() {
                let err = String::from_utf8_lossy(&out.stderr);
                assert!(
                    err.contains("qdisc kind is unknown"),
                    "tc netem failed: {err}"
                );
                netem = false;
            }
        }
        if netem {
            return Impairment::Netem;
        }
        eprintln!(
            "this kernel has no netem qdisc: {LOSS_PERCENT} % loss from nftables, {delay} each way \
             from a relay in the operator's namespace"
        );
        let ns = &link.peer_ns;
        nft(ns, "add table inet impair");
        for hook in ["input", "output"] {
            nft(
                ns,
                &format!("add chain inet impair {hook} {{ type filter hook {hook} priority 0; }}"),
            );
            let dir = if hook == "input" {
                "iifname"
            } else {
                "oifname"
            };
            nft(
                ns,
                &format!(
                    "add rule inet impair {hook} {dir} \"{operator_if}\" numgen random mod 100 < {LOSS_PERCENT} drop"
                ),
            );
        }
        Impairment::Emulated {
            _relay: DelayRelay::start(ns, DELAY),
        }
    }

    /// The endpoint the operator side connects to.
    fn endpoint(&self) -> String {
        match self {
            Impairment::Netem => endpoint("tcp"),
            Impairment::Emulated { .. } => format!("tcp/127.0.0.1:{RELAY_PORT}"),
        }
    }
}

/// A TCP relay in a network namespace: 127.0.0.1:[`RELAY_PORT`] → the robot's endpoint, each
/// chunk held `delay` in each direction (order kept).
struct DelayRelay {
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
}

impl DelayRelay {
    fn start(ns: &str, delay: Duration) -> Self {
        use std::net::{TcpListener, TcpStream};
        use std::sync::Arc;
        use std::sync::atomic::AtomicBool;
        let stop = Arc::new(AtomicBool::new(false));
        let (ready_tx, ready_rx) = std::sync::mpsc::channel();
        let path = format!("/var/run/netns/{ns}");
        let flag = stop.clone();
        std::thread::spawn(move || {
            let file = std::fs::File::open(&path).unwrap();
            nix::sched::setns(&file, nix::sched::CloneFlags::CLONE_NEWNET).unwrap();
            let listener = TcpListener::bind(("127.0.0.1", RELAY_PORT)).unwrap();
            listener.set_nonblocking(true).unwrap();
            ready_tx.send(()).unwrap();
            while !flag.load(Ordering::Relaxed) {
                let Ok((inbound, _)) = listener.accept() else {
                    pause(Duration::from_millis(20));
                    continue;
                };
                inbound.set_nonblocking(false).unwrap();
                let Ok(outbound) = TcpStream::connect((ROBOT_ADDR, PORT)) else {
                    continue;
                };
                for (from, to) in [
                    (inbound.try_clone().unwrap(), outbound.try_clone().unwrap()),
                    (outbound, inbound),
                ] {
                    let _ = from.set_nodelay(true);
                    let _ = to.set_nodelay(true);
                    pump(from, to, delay);
                }
            }
        });
        ready_rx
            .recv_timeout(Duration::from_secs(5))
            .unwrap_or_else(|e| panic!("the relay did not start: {e}"));
        DelayRelay { stop }
    }
}

/// Copies `from` to `to`, each chunk `delay` after it was read.
fn pump(mut from: std::net::TcpStream, mut to: std::net::TcpStream, delay: Duration) {
    use std::io::{Read, Write};
    let (tx, rx) = std::sync::mpsc::channel::<(Instant, Vec<u8>)>();
    std::thread::spawn(move || {
        let mut buf = vec![0u8; 65536];
        while let Ok(n) = from.read(&mut buf) {
            if n == 0
                || tx
                    .send((Instant::now() + delay, buf[..n].to_vec()))
                    .is_err()
            {
                break;
            }
        }
        let _ = from.shutdown(std::net::Shutdown::Both);
    });
    std::thread::spawn(move || {
        while let Ok((due, bytes)) = rx.recv() {
            pause(due.saturating_duration_since(Instant::now()));
            if to.write_all(&bytes).is_err() {
                break;
            }
        }
        let _ = to.shutdown(std::net::Shutdown::Both);
    });
}

impl Drop for DelayRelay {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

#[test]
fn a_slow_lossy_link_still_drives() {
    let (link, mut env, n, mut robot) = robot_over_link("zenoh-lossy", "zls");
    let impairment = Impairment::apply(&link);
    let connect = impairment.endpoint();
    let mut operator = mirror_at(&mut env, &link, &n, &connect, &["--insecure"]);
    let mut remote = remote_source(&env, &mut operator, UP);
    let first = drive_until_moving(&mut robot, &mut remote, 0.4, 0.2, UP)
        .unwrap_or_else(|| panic!("the robot never moved over the slow link\n{}", env.logs()));

    // Drive at 20 Hz for 4 s and count the robot's mux decisions that chose the remote source.
    let start = Instant::now();
    let mut last_send = None::<Instant>;
    let (mut decisions, mut remote_active, mut last_seq) = (0u32, 0u32, 0u64);
    while start.elapsed() < Duration::from_secs(4) {
        if last_send.is_none_or(|t| t.elapsed() >= Duration::from_millis(50)) {
            remote.send(VelocityRequest::twist(0.4, 0.0)).unwrap();
            last_send = Some(Instant::now());
        }
        if let Ok(Some(m)) = robot.wait_mux(Duration::from_millis(10))
            && m.seq != last_seq
        {
            last_seq = m.seq;
            decisions += 1;
            remote_active += u32::from(active_name(&m) == "remote");
        }
    }
    remote.stop().unwrap();
    let share = f64::from(remote_active) / f64::from(decisions.max(1));
    let state_back = wait_for(Duration::from_secs(5), || {
        operator
            .wait_state(Duration::from_millis(100))
            .ok()
            .flatten()
            .is_some()
    });
    eprintln!(
        "{} ms delay + {LOSS_PERCENT} % loss ({}): moving {first:?} after the first request; \
         remote active in {:.0} % of {decisions} mux decisions over 4 s of driving at 20 Hz",
        DELAY.as_millis(),
        match impairment {
            Impairment::Netem => "tc netem",
            Impairment::Emulated { .. } => "nftables + delay relay",
        },
        share * 100.0
    );
    assert!(
        state_back.is_some(),
        "no state came back over the slow link"
    );
    assert!(
        share >= 0.5,
        "the remote source was active in only {:.0} % of the decisions\n{}",
        share * 100.0,
        env.logs()
    );
}

#[test]
fn chassis_teleop_on_the_operators_computer_drives_the_robot() {
    if !tmux_available() {
        eprintln!("SKIPPED: tmux is not installed; the terminal test of chassis-teleop needs it");
        return;
    }
    let (link, mut env, n, mut robot) = robot_over_link("zenoh-teleop", "ztp");
    let mut operator = mirror(&mut env, &link, &n, &["--insecure"]);
    // The mirror offers the remote source once it has the robot's mux.
    drop(remote_source(&env, &mut operator, UP));
    let log = env.dir.join("teleop.log");
    let command = format!(
        "env {}={} RUST_LOG=info {} --name {n} --source remote 2>{}; echo chassis-teleop exited $?; sleep 60",
        IPC_PREFIX_ENV,
        quote(&operator_prefix(&env)),
        quote(&bin("chassis-teleop").to_string_lossy()),
        quote(&log.to_string_lossy()),
    );
    let tmux = Tmux::start(&env.dir, "tmux", &command);
    tmux.wait_for_text("idle — publishing nothing", UP);
    let start = Instant::now();
    let (mut peak, mut remote_won) = (0.0f32, false);
    while start.elapsed() < Duration::from_millis(2000) {
        tmux.send("w");
        if let Ok(Some(state)) = robot.wait_state(Duration::from_millis(30)) {
            peak = peak.max(state.motion.linear_mps);
        }
        if let Ok(Some(m)) = robot.latest_mux() {
            remote_won |= active_name(&m) == "remote";
        }
    }
    let screen = tmux.screen();
    assert!(
        remote_won,
        "the robot's mux never chose remote\n{screen}\n{}",
        env.logs()
    );
    assert!(
        peak > 0.05,
        "peak speed {peak} m/s while w was held\n{screen}"
    );
    assert!(screen.contains("DRIVING"), "{screen}");
}

/// The fastest the robot's chassis reported over `duration` while `source` keeps asking for
/// `linear` every 20 ms.
fn peak_while_asking(
    robot: &mut Robot,
    source: &mut Source,
    linear: f32,
    duration: Duration,
) -> f32 {
    let end = Instant::now() + duration;
    let mut peak = 0.0f32;
    while Instant::now() < end {
        source.send(VelocityRequest::twist(linear, 0.0)).unwrap();
        if let Ok(Some(s)) = robot.wait_state(Duration::from_millis(20)) {
            peak = peak.max(s.motion.linear_mps.abs());
        }
    }
    peak
}

#[test]
fn the_operator_reads_the_robots_description_and_a_release_through_the_mirror_starts_no_motion() {
    let (link, mut env, n, mut robot) = robot_over_link("zenoh-release", "zrl");
    let mut operator = mirror(&mut env, &link, &n, &["--insecure"]);

    // What the robot is, read on the operator's computer as beside chassisd: the same bytes.
    let here = robot.description(UP).unwrap();
    let there = operator
        .description(UP)
        .unwrap_or_else(|e| panic!("no description through the mirror: {e}\n{}", env.logs()));
    // (Debug text: its unknowns are NaN, which equals nothing.)
    assert!(
        format!("{there:?}") == format!("{here:?}"),
        "the mirrored description differs: {there:?}"
    );
    assert_eq!((there.name(), there.kind_name()), (n.as_str(), "titan"));
    // And by the Python client there, under the operator's prefix.
    let script = format!(
        "import json, chassis\n\
         r = chassis.Robot.connect({n:?}, prefix={prefix:?})\n\
         d = r.wait_description(10.0).summary()\n\
         print(json.dumps({{'name': d['name'], 'kind': d['kind_name'], 'sources': [s['name'] for s in d['sources']]}}))\n",
        prefix = operator_prefix(&env),
    );
    let out = Command::new(python())
        .args(["-c", &script])
        .output()
        .unwrap();
    let stdout = env.succeeded(
        "the Python client read no description through the mirror",
        &out,
    );
    let py: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    assert_eq!(
        (py["name"].as_str(), py["kind"].as_str()),
        (Some(n.as_str()), Some("titan")),
        "{py}"
    );
    assert!(
        py["sources"]
            .as_array()
            .unwrap()
            .iter()
            .any(|s| s == "remote"),
        "{py}"
    );

    // The operator drives, then engages the e-stop through the mirror while still asking.
    let mut remote = remote_source(&env, &mut operator, UP);
    drive_until_moving(&mut robot, &mut remote, 0.4, 0.2, UP)
        .unwrap_or_else(|| panic!("the robot never moved\n{}", env.logs()));
    let estop = |kind| ControlRequest::new(kind).with_name("estop");
    let engaged = operator
        .control(estop(ControlKind::LOCK_ENGAGE), Duration::from_secs(5))
        .unwrap();
    assert_eq!(engaged.status, ControlStatus::OK, "{}", engaged.message());
    // Standing still (a sample stamped after the e-stop reads no speed) before the release.
    let halted = wait_for(Duration::from_secs(5), || {
        remote.send(VelocityRequest::twist(0.4, 0.0)).unwrap();
        state(&mut robot).motion.linear_mps.abs() < 0.001
    });
    assert!(
        halted.is_some(),
        "the e-stop did not halt the robot\n{}",
        env.logs()
    );

    // Released through the mirror with the operator still asking for 0.4 m/s: nothing moves,
    // and the robot's mux says it waits for the remote source's zero.
    let released = operator
        .control(estop(ControlKind::LOCK_RELEASE), Duration::from_secs(5))
        .unwrap();
    assert_eq!(released.status, ControlStatus::OK, "{}", released.message());
    let peak = peak_while_asking(&mut robot, &mut remote, 0.4, Duration::from_millis(1500));
    assert!(
        peak < 0.01,
        "the release through the mirror started motion: {peak} m/s"
    );
    assert!(
        released.message().contains("until remote asks for zero"),
        "{}",
        released.message()
    );
    let m = mux(&mut robot);
    assert_eq!(m.zero_reason, ZeroReason::AWAITING_ZERO, "{m:?}");
    assert_eq!(m.awaiting().map(|s| s.name()), Some("remote"));

    // A zero from the operator, then motion is obeyed again.
    let zeroed = wait_for(Duration::from_secs(3), || {
        remote.send(VelocityRequest::twist(0.0, 0.0)).unwrap();
        pause(Duration::from_millis(20));
        mux(&mut robot).awaiting().is_none()
    });
    assert!(
        zeroed.is_some(),
        "the remote source's zero never reached the mux\n{}",
        env.logs()
    );
    drive_until_moving(&mut robot, &mut remote, 0.4, 0.2, UP)
        .unwrap_or_else(|| panic!("no motion after the zero\n{}", env.logs()));
    remote.stop().unwrap();
    let mut figures = Figures::faults();
    figures.add(Figure {
        rank: 730,
        fault: "the e-stop released through the Zenoh mirror while the operator asks for motion".into(),
        injection: "the operator drives `remote` at 0.4 m/s across two namespaces, engages the e-stop through the mirror's `control`, keeps asking, and releases it the same way".into(),
        behaviour: "nothing moved after the release; the robot's mux held zero awaiting the remote source's zero (AWAITING_ZERO), then drove on the operator's next requests".into(),
        figure: format!("fastest {peak:.3} m/s in the 1.5 s after the release"),
        value: f64::from(peak),
        pass: true,
        suite: "zenoh".into(),
        test: "the_operator_reads_the_robots_description_and_a_release_through_the_mirror_starts_no_motion".into(),
    });
    figures.finish();
}

/// Cuts the link with nftables (every packet dropped both ways on the operator's end) or
/// restores it. Unlike taking the veth down, the TCP connection outlives the cut, so what the
/// operator side wrote meanwhile is retransmitted when the link returns.
fn nft_cut(link: &VethPair, cut: bool) {
    let ns = &link.peer_ns;
    let operator_if = &link.peer_if;
    if !cut {
        nft(ns, "delete table inet cut");
        return;
    }
    nft(ns, "add table inet cut");
    for (hook, dir) in [("input", "iifname"), ("output", "oifname")] {
        nft(
            ns,
            &format!("add chain inet cut {hook} {{ type filter hook {hook} priority 0; }}"),
        );
        nft(
            ns,
            &format!("add rule inet cut {hook} {dir} \"{operator_if}\" drop"),
        );
    }
}

#[test]
fn requests_buffered_through_an_outage_never_drive_when_the_link_comes_back() {
    let (link, mut env, n, mut robot) = robot_over_link("zenoh-stale", "zst");
    let mut operator = mirror(&mut env, &link, &n, &["--insecure"]);
    let mut remote = remote_source(&env, &mut operator, UP);
    drive_until_moving(&mut robot, &mut remote, 0.4, 0.2, UP)
        .unwrap_or_else(|| panic!("the robot never moved\n{}", env.logs()));

    // The link goes down mid-drive; the operator keeps asking for 0.5 s, then its program
    // stops asking; the link comes back 1.2 s after the cut.
    let cut = Instant::now();
    nft_cut(&link, true);
    let mut asked = 0u32;
    while cut.elapsed() < Duration::from_millis(500) {
        remote.send(VelocityRequest::twist(0.4, 0.0)).unwrap();
        asked += 1;
        pause(Duration::from_millis(20));
    }
    let halted = comes_to_rest(&mut robot, Duration::from_secs(3), 0.001);
    assert!(
        halted.is_some(),
        "the robot kept moving through the outage\n{}",
        env.logs()
    );
    while cut.elapsed() < Duration::from_millis(1200) {
        pause(Duration::from_millis(10));
    }
    let back_ns = now_ns();
    nft_cut(&link, false);

    // Not one motion from the old requests: every mux decision and state sample after the link
    // came back asks for and shows standstill.
    let end = Instant::now() + Duration::from_secs(3);
    let (mut peak_output, mut peak_speed) = (0.0f32, 0.0f32);
    let mut samples = 0;
    while Instant::now() < end {
        if let Ok(Some(s)) = robot.wait_state(Duration::from_millis(10))
            && s.stamp_ns > back_ns
        {
            samples += 1;
            peak_speed = peak_speed.max(s.motion.linear_mps.abs());
        }
        robot
            .poll_mux(|m| {
                if m.stamp_ns > back_ns {
                    peak_output = peak_output.max(m.output.linear_x_mps.abs());
                }
            })
            .unwrap();
    }
    assert!(samples > 0, "no state after the link came back");
    assert_eq!(
        peak_output,
        0.0,
        "the mux obeyed a request made before the outage\n{}",
        env.logs()
    );
    assert!(peak_speed < 0.01, "the robot moved at {peak_speed} m/s");
    // The old requests did arrive, and were dropped as too old (not for want of a clock).
    let log = env.proc(2).log_text();
    let too_old: Vec<&str> = log
        .lines()
        .filter(|l| l.contains("dropped a velocity request") && l.contains("before it arrived"))
        .collect();
    assert!(
        !too_old.is_empty(),
        "none of the {asked} requests made during the outage arrived late (nothing was judged)\n{}",
        env.logs()
    );
    eprintln!(
        "{asked} requests asked during the outage; {} dropped as too old on the robot side, the last: {}",
        too_old.len(),
        too_old.last().copied().unwrap_or("")
    );

    // The operator drives again with new requests.
    drive_until_moving(&mut robot, &mut remote, 0.4, 0.2, UP)
        .unwrap_or_else(|| panic!("no motion from new requests\n{}", env.logs()));
    remote.stop().unwrap();
    let latest_ms = too_old
        .iter()
        .filter_map(|l| {
            l.split("made ")
                .nth(1)?
                .split(" ms")
                .next()?
                .parse::<u64>()
                .ok()
        })
        .max()
        .unwrap_or(0);
    let mut figures = Figures::faults();
    figures.add(Figure {
        rank: 740,
        fault: "remote requests buffered through a Zenoh link outage".into(),
        injection: "the operator drives `remote` at 0.4 m/s; nftables drops every packet of the link for 1.2 s; the operator asks for 0.5 s of it, then stops asking".into(),
        behaviour: "the requests held by the connection arrived when the link returned and were dropped and counted as too old (their stamps against the operator's clock, measured on the session); the mux obeyed none; new requests drove".into(),
        figure: format!(
            "{asked} asked during the outage, {} dropped as too old, the latest {latest_ms} ms after it was made (bound 250 ms); mux output after the link returned {peak_output} m/s",
            too_old.len()
        ),
        value: f64::from(peak_output),
        pass: true,
        suite: "zenoh".into(),
        test: "requests_buffered_through_an_outage_never_drive_when_the_link_comes_back".into(),
    });
    figures.finish();
}

/// SIGTERM is how systemd and an operator stop either side: it ends both with success, not with
/// the interrupted wait as an error.
#[test]
fn both_sides_end_with_success_on_sigterm() {
    let (link, mut env, n, _robot) = robot_over_link("zenoh-sigterm", "term");
    let mut operator = mirror(&mut env, &link, &n, &["--insecure"]);
    assert!(
        operator.wait_state(UP).unwrap().is_some(),
        "no state through the mirror\n{}",
        env.logs()
    );
    for side in ["zenoh-operator", "zenoh-robot"] {
        env.proc_labelled(side)
            .signal(nix::sys::signal::Signal::SIGTERM);
        let code = env.proc_labelled(side).wait_exit(Duration::from_secs(10));
        assert_eq!(code, Some(0), "{side}'s exit after SIGTERM\n{}", env.logs());
    }
}
