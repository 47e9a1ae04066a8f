//! chassisd under a supervisor: the sd-notify protocol on a notify socket this test owns
//! (`READY=1` once the state service exists, `WATCHDOG=1` from the loop, `STATUS=`, `STOPPING=1`)
//! and real-time mode, granted or refused.
// Test code: helpers outside #[test] functions may unwrap, panic and read the wall clock.
#![allow(clippy::unwrap_used, clippy::panic, clippy::disallowed_methods)]

use std::os::unix::net::UnixDatagram;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use chassis_tests::*;
use nix::sys::signal::Signal;

const UP: Duration = Duration::from_secs(10);

/// The socket systemd would own, bound by the test.
fn notify_socket(env: &Env) -> (UnixDatagram, PathBuf) {
    let path = env.dir.join("notify.sock");
    let socket = UnixDatagram::bind(&path).unwrap();
    (socket, path)
}

/// The next notification within `timeout`.
fn next(socket: &UnixDatagram, timeout: Duration) -> Option<String> {
    socket.set_read_timeout(Some(timeout)).unwrap();
    let mut buf = [0u8; 1024];
    socket
        .recv(&mut buf)
        .ok()
        .map(|n| String::from_utf8_lossy(&buf[..n]).into_owned())
}

/// Notifications until one contains `wanted` (at most `timeout`); all of them, in order.
fn until(socket: &UnixDatagram, wanted: &str, timeout: Duration, env: &Env) -> Vec<String> {
    let end = Instant::now() + timeout;
    let mut seen = Vec::new();
    while Instant::now() < end {
        if let Some(message) = next(socket, Duration::from_millis(100)) {
            let done = message.contains(wanted);
            seen.push(message);
            if done {
                return seen;
            }
        }
    }
    panic!("no {wanted} within {timeout:?}: {seen:?}\n{}", env.logs());
}

fn start_notified(env: &mut Env, n: &str, socket: &Path, watchdog_usec: Option<u64>) -> usize {
    let socket = socket.to_string_lossy().into_owned();
    let usec = watchdog_usec.map(|u| u.to_string());
    let mut envs = vec![("NOTIFY_SOCKET", socket.as_str())];
    if let Some(usec) = &usec {
        envs.push(("WATCHDOG_USEC", usec.as_str()));
    }
    env.spawn_program(
        "chassisd",
        &bin("chassisd"),
        &["--robot", "titan", "--name", n, "--no-safety-monitor"],
        &envs,
    )
}

#[test]
fn ready_comes_once_the_state_service_exists_and_status_follows_the_mux() {
    let mut env = Env::new("sd-ready");
    let n = name("sdr");
    let (socket, path) = notify_socket(&env);
    let index = start_notified(&mut env, &n, &path, None);
    let seen = until(&socket, "READY=1", UP, &env);
    // Nothing but READY first: no watchdog was asked for.
    assert_eq!(seen.len(), 1, "{seen:?}");
    assert!(seen[0].contains("STATUS=stopped: "), "{seen:?}");
    // The moment READY arrives the state service is there, with a sample in it.
    let mut robot = Robot::connect_with_prefix(&n, Some(&env.prefix))
        .unwrap_or_else(|e| panic!("READY before chassis/{n}/state: {e}\n{}", env.logs()));
    assert!(
        robot.wait_state(Duration::from_secs(1)).unwrap().is_some(),
        "no state after READY"
    );
    let out = env.chassis(&["control", "--name", &n, "estop"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let seen = until(&socket, "held: estop", Duration::from_secs(3), &env);
    // Nothing asks for motion, so the decision is "no active source", with the lock and its
    // stop category beside it: the standing TITAN's drive is cut at once.
    assert!(
        seen.last()
            .unwrap()
            .starts_with("STATUS=stopped: no active source · held: estop (category 1) · drive cut"),
        "{seen:?}"
    );
    env.proc(index).signal(Signal::SIGTERM);
    let seen = until(&socket, "STOPPING=1", Duration::from_secs(3), &env);
    assert!(!seen.iter().any(|m| m.contains("WATCHDOG")), "{seen:?}");
    assert_eq!(env.proc(index).wait_exit(Duration::from_secs(3)), Some(0));
}

/// Voluntary context switches of a thread of process `pid`: its main thread (the event loop's)
/// with `None`, else the one called `comm` (`None`: no such thread).
fn switches(pid: u32, comm: Option<&str>) -> Option<u64> {
    let dir = match comm {
        None => std::path::PathBuf::from(format!("/proc/{pid}/task/{pid}")),
        Some(comm) => std::fs::read_dir(format!("/proc/{pid}/task"))
            .ok()?
            .flatten()
            .map(|task| task.path())
            .find(|dir| {
                std::fs::read_to_string(dir.join("comm")).is_ok_and(|c| c.trim() == comm)
            })?,
    };
    std::fs::read_to_string(dir.join("status"))
        .ok()?
        .lines()
        .find_map(|l| l.strip_prefix("voluntary_ctxt_switches:"))
        .and_then(|v| v.trim().parse().ok())
}

/// The process state letter of `pid` (`T`: stopped).
fn process_state(pid: u32) -> char {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    stat.rsplit(')')
        .next()
        .and_then(|rest| rest.trim_start().chars().next())
        .unwrap_or('?')
}

/// The pings come from the event loop itself: with the loop's thread alone stalled (the test
/// hook `TEST_LOOP_STALL_ENV`: the other threads of the process run on, the simulated chassis
/// among them), no `WATCHDOG=1` arrives, and the pings resume when the loop does. A ping sent
/// by a timer thread beside the loop would go on through the stall.
#[test]
fn the_watchdog_pings_come_from_the_loop_and_stop_while_it_stalls() {
    let mut env = Env::new("sd-watchdog");
    let n = name("sdw");
    let (socket, path) = notify_socket(&env);
    let period = Duration::from_millis(400);
    let stall_file = env.dir.join("stall-loop");
    let socket_path = path.to_string_lossy().into_owned();
    let stall_path = stall_file.to_string_lossy().into_owned();
    let index = env.spawn_program(
        "chassisd",
        &bin("chassisd"),
        &["--robot", "titan", "--name", &n, "--no-safety-monitor"],
        &[
            ("NOTIFY_SOCKET", socket_path.as_str()),
            ("WATCHDOG_USEC", "400000"),
            (TEST_LOOP_STALL_ENV, stall_path.as_str()),
        ],
    );
    until(&socket, "READY=1", UP, &env);
    let pid = env.proc(index).child.id();
    assert!(
        env.proc(index)
            .log_text()
            .contains("a test hook stalls the event loop"),
        "the hook was not armed\n{}",
        env.logs()
    );
    let mut pings = Vec::new();
    let window = Duration::from_secs(2);
    let end = Instant::now() + window;
    while Instant::now() < end {
        if next(&socket, Duration::from_millis(50)).is_some_and(|m| m == "WATCHDOG=1") {
            pings.push(Instant::now());
        }
    }
    let worst = pings
        .windows(2)
        .map(|w| w[1] - w[0])
        .max()
        .unwrap_or(window);

    // Stall the loop's thread for 1 s: the request is written whole, then moved into place.
    let stall = Duration::from_millis(1000);
    let request = env.dir.join("stall-loop.new");
    std::fs::write(&request, stall.as_millis().to_string()).unwrap();
    std::fs::rename(&request, &stall_file).unwrap();
    let taken = wait_for(Duration::from_secs(1), || !stall_file.exists());
    // The loop removes the file right before it sleeps, after the pass's own ping (if one was
    // due): whatever is in the socket now was sent before the stall.
    let stalled_at = Instant::now();
    while next(&socket, Duration::from_millis(1)).is_some() {}
    let sim_before = switches(pid, Some("sim-titan"));
    let loop_before = switches(pid, None);
    let state_during = process_state(pid);
    let mut while_stalled = 0;
    let quiet_until = stalled_at + stall - Duration::from_millis(50);
    while Instant::now() < quiet_until {
        let wait = quiet_until.saturating_duration_since(Instant::now());
        if next(&socket, wait.max(Duration::from_millis(1))).is_some_and(|m| m == "WATCHDOG=1")
            && Instant::now() < quiet_until
        {
            while_stalled += 1;
        }
    }
    let sim_after = switches(pid, Some("sim-titan"));
    let loop_after = switches(pid, None);
    // The loop comes back: the first ping after the stall.
    let mut resumed = None;
    let end = stalled_at + Duration::from_secs(3);
    while resumed.is_none() && Instant::now() < end {
        if next(&socket, Duration::from_millis(20)).is_some_and(|m| m == "WATCHDOG=1") {
            resumed = Some(stalled_at.elapsed());
        }
    }
    let running = env.proc(index).is_running();
    // Other threads ran while the loop slept: the simulated chassis woke for its frames (every
    // 20 ms), the loop not at all.
    let sim_ran = sim_before
        .zip(sim_after)
        .map_or(0, |(b, a)| a.saturating_sub(b));
    let loop_ran = loop_before
        .zip(loop_after)
        .map_or(u64::MAX, |(b, a)| a.saturating_sub(b));
    let others_ran = sim_ran >= 10 && loop_ran == 0 && state_during != 'T';
    // Back within a ping period (100 ms) of the stall's end, with a loaded machine's allowance.
    let back_bound = stall + period / 4 + Duration::from_millis(200);
    let back_in_time =
        resumed.is_some_and(|r| r >= stall - Duration::from_millis(50) && r <= back_bound);
    let resumed_ms = resumed.map_or(f64::NAN, |r| r.as_secs_f64() * 1e3);
    let pass = taken.is_some()
        && worst < period
        && pings.len() >= 2 * (window.as_millis() / period.as_millis()) as usize
        && while_stalled == 0
        && others_ran
        && back_in_time
        && running;
    let mut figures = Figures::faults();
    figures.add(Figure {
        rank: 720,
        fault: "chassisd's event loop stalls (hung) under a systemd watchdog".into(),
        injection: format!(
            "WATCHDOG_USEC {} ms on a notify socket of the test's; the loop's thread alone \
             stalled for {} ms (the test hook {TEST_LOOP_STALL_ENV}; the process's other threads \
             run on)",
            period.as_millis(),
            stall.as_millis()
        ),
        behaviour: "WATCHDOG=1 from the loop four times per period; none while the loop stalled \
                    (systemd would restart the service) though the simulated chassis' thread \
                    kept running; pings again once the loop ran"
            .into(),
        figure: format!(
            "{} pings in {} s, longest gap {:.0} ms; {while_stalled} while stalled (the \
             simulated chassis' thread woke {sim_ran} times meanwhile, the loop's {loop_ran}); \
             the first ping {resumed_ms:.0} ms after the stall began",
            pings.len(),
            window.as_secs(),
            worst.as_secs_f64() * 1e3,
        ),
        value: worst.as_secs_f64() * 1e3,
        pass,
        suite: "systemd".into(),
        test: "the_watchdog_pings_come_from_the_loop_and_stop_while_it_stalls".into(),
    });
    assert!(
        taken.is_some(),
        "the loop never took the stall request\n{}",
        env.logs()
    );
    assert!(
        pings.len() >= 2 * (window.as_millis() / period.as_millis()) as usize,
        "{} pings in {window:?} with WATCHDOG_USEC {period:?}",
        pings.len()
    );
    assert!(worst < period, "a gap of {worst:?} between pings");
    assert_eq!(
        while_stalled, 0,
        "pings while the loop stalled: not from the loop"
    );
    assert!(
        others_ran,
        "the simulated chassis' thread woke {sim_ran} times, the loop's {loop_ran}, process \
         state {state_during}: not the loop alone stalled"
    );
    assert!(
        back_in_time,
        "the first ping {resumed:?} after a stall of {stall:?} (bound {back_bound:?})\n{}",
        env.logs()
    );
    assert!(running, "the stall stopped the service\n{}", env.logs());
    env.proc(index).signal(Signal::SIGKILL);
    figures.finish();
}

/// Scheduling policy and real-time priority of `pid`'s main thread (the loop's).
fn policy(pid: u32) -> (u32, u32) {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap();
    let after = &stat[stat.rfind(')').unwrap() + 1..];
    let fields: Vec<&str> = after.split_whitespace().collect();
    // Fields 40 (rt_priority) and 41 (policy) of proc(5); `after` starts at field 3.
    (fields[38].parse().unwrap(), fields[37].parse().unwrap())
}

/// The CPUs the simulated chassis' thread (`sim-titan`) of `pid` may run on, as proc(5)'s
/// `Cpus_allowed_list` writes them.
fn sim_cpus_allowed(pid: u32) -> String {
    let tasks = std::fs::read_dir(format!("/proc/{pid}/task")).unwrap();
    for task in tasks.flatten() {
        let comm = std::fs::read_to_string(task.path().join("comm")).unwrap_or_default();
        if comm.trim() == "sim-titan" {
            let status = std::fs::read_to_string(task.path().join("status")).unwrap();
            let line = status
                .lines()
                .find_map(|l| l.strip_prefix("Cpus_allowed_list:"))
                .unwrap();
            return line.trim().to_string();
        }
    }
    panic!("chassisd {pid} has no sim-titan thread");
}

const SCHED_FIFO: u32 = 1;
const SCHED_OTHER: u32 = 0;

/// Teleop drives the robot: the service runs whatever its scheduling.
fn assert_drives(env: &Env, n: &str) {
    let mut robot = env.robot(n, UP);
    let mut teleop = robot.source("teleop").unwrap();
    let end = Instant::now() + Duration::from_secs(1);
    let mut peak = 0.0f32;
    while Instant::now() < end {
        teleop.send(VelocityRequest::twist(0.3, 0.0)).unwrap();
        if let Ok(Some(s)) = robot.wait_state(Duration::from_millis(20)) {
            peak = peak.max(s.motion.linear_mps.abs());
        }
    }
    assert!(peak > 0.2, "no motion: {peak}\n{}", env.logs());
}

/// Real-time mode is granted exactly where the machine grants SCHED_FIFO to this user — `chrt`
/// asks the kernel for it with the same limits and privileges, so a chassisd refused where it
/// should be granted fails, as does one granted where it cannot be — and granted, the loop runs
/// at it. The package's installation test (scripts/package-install-tests) proves the grant to
/// the unprivileged user of the unit (its AmbientCapabilities).
#[test]
fn realtime_mode_runs_the_loop_at_sched_fifo_where_the_machine_grants_it() {
    let grants = std::process::Command::new("chrt")
        .args(["--fifo", "10", "true"])
        .stderr(std::process::Stdio::null())
        .status()
        .unwrap()
        .success();
    let mut env = Env::new("rt-granted");
    let n = name("rtg");
    let index = env.serve(
        "titan",
        &n,
        &["--no-safety-monitor", "--realtime", "10", "--cpu", "0"],
    );
    assert_drives(&env, &n);
    let pid = env.proc(index).child.id();
    let log = env.proc(index).log_text();
    if grants {
        assert!(
            log.contains("real-time mode: the loop runs at SCHED_FIFO"),
            "{log}"
        );
        assert_eq!(policy(pid), (SCHED_FIFO, 10));
        // The simulated chassis shares the pinned real-time loop's CPU.
        assert_eq!(sim_cpus_allowed(pid), "0");
    } else {
        // A machine without the privilege: the warning and normal scheduling.
        assert!(log.contains("SCHED_FIFO priority 10 refused"), "{log}");
        assert!(log.contains("normal scheduling"), "{log}");
        assert_eq!(policy(pid).0, SCHED_OTHER);
        assert_ne!(sim_cpus_allowed(pid), "0");
    }
}

#[test]
fn a_refused_realtime_mode_warns_and_runs_with_normal_scheduling() {
    let setpriv = Path::new("/usr/bin/setpriv");
    if !setpriv.exists() || !Path::new("/usr/bin/prlimit").exists() {
        eprintln!(
            "skipped: setpriv and prlimit (util-linux) are needed to take the privilege away"
        );
        return;
    }
    let mut env = Env::new("rt-refused");
    let n = name("rtr");
    let chassisd = bin("chassisd").to_string_lossy().into_owned();
    // With RLIMIT_RTPRIO 0 the kernel refuses SCHED_FIFO to an unprivileged process; root keeps
    // CAP_SYS_NICE and CAP_IPC_LOCK unless they are taken away (setpriv).
    let mut args = vec!["--rtprio=0", "--"];
    let root = std::fs::metadata("/proc/self").is_ok_and(|m| {
        use std::os::unix::fs::MetadataExt;
        m.uid() == 0
    });
    if root {
        args.extend([
            "/usr/bin/setpriv",
            "--bounding-set=-sys_nice,-ipc_lock",
            "--inh-caps=-sys_nice,-ipc_lock",
        ]);
    }
    args.extend([
        chassisd.as_str(),
        "--robot",
        "titan",
        "--name",
        &n,
        "--no-safety-monitor",
        "--realtime",
        "10",
        "--cpu",
        "0",
    ]);
    let index = env.spawn_program("chassisd", Path::new("/usr/bin/prlimit"), &args, &[]);
    assert_drives(&env, &n);
    let log = env.proc(index).log_text();
    assert!(log.contains("WARN"), "{log}");
    assert!(log.contains("SCHED_FIFO priority 10 refused"), "{log}");
    assert!(
        log.contains("the loop runs with normal scheduling"),
        "{log}"
    );
    // prlimit execs setpriv, which execs chassisd: the pid is chassisd's.
    let pid = env.proc(index).child.id();
    assert_eq!(policy(pid).0, SCHED_OTHER);
    // A loop at normal scheduling leaves the other CPUs to its simulated chassis.
    assert_ne!(sim_cpus_allowed(pid), "0");
}
