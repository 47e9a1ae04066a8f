//! The fault matrix, processes killed and hung up: SIGKILL of chassisd at random moments (on the
//! simulated bus, and over slcan to a `chassisd sim` that stops on its own heartbeat timeout), of
//! the simulated chassis (`chassisd sim`, the XBot's serial line hangs up), and of every client
//! (the safety monitor, the planner, `chassis pub`, `chassis-teleop` in a terminal). Each test
//! measures its figure and records it with [`Figures`] (`scripts/reliability` turns the records
//! into `docs/RELIABILITY.md`); the pty hang-ups of a running chassisd are recorded by their tests
//! in `serial.rs` and `service.rs`, the storms in `faults_bus.rs`, rogue and absurd clients in
//! `faults_clients.rs`.
//!
//! Fault moments are drawn from a seeded generator; the seed is printed, and
//! `CHASSIS_FAULT_SEED=N` repeats a run.
// Test code: helpers outside #[test] functions may unwrap, panic and read the wall clock.
#![allow(clippy::unwrap_used, clippy::panic, clippy::disallowed_methods)]

use std::sync::RwLockReadGuard;
use std::time::{Duration, Instant};

use chassis_tests::faults::*;
use chassis_tests::*;
use nix::sys::signal::Signal;

const UP: Duration = Duration::from_secs(10);
const SUITE: &str = "faults_processes";

/// The rows of the table, in the order.
mod rank {
    pub const KILL_SERVICE: u32 = 100;
    pub const KILL_SERVICE_PTY: u32 = 110;
    pub const KILL_SIM: u32 = 120;
    pub const KILL_SAFETY: u32 = 130;
    pub const KILL_PLANNER: u32 = 140;
    pub const KILL_PUB: u32 = 150;
    pub const KILL_TELEOP: u32 = 160;
}

// ----- SIGKILL of the service -----

/// A fault test's start: the machine shared with the other fault tests, its environment
/// (`label`), the robot's name (`tag` and the pid) and the seeded generator of `test`.
fn fault_start(
    test: &str,
    label: &str,
    tag: &str,
) -> (RwLockReadGuard<'static, ()>, Env, String, Rng) {
    let machine = shared();
    (machine, Env::new(label), name(tag), Rng::from_env(test))
}

/// How long a fault test drives before its next fault: a random moment of up to 800 ms.
fn a_moment(rng: &mut Rng) -> Duration {
    rng.between(Duration::ZERO, Duration::from_millis(800))
}

/// The first start-up kill comes this soon after the spawn: before chassisd can have made its
/// ports (its start takes tens of milliseconds even in release mode).
const EARLY_KILL: Duration = Duration::from_millis(5);

#[test]
fn sigkill_of_chassisd_at_random_moments_never_blocks_its_restart_and_clients_reconnect() {
    let test =
        "sigkill_of_chassisd_at_random_moments_never_blocks_its_restart_and_clients_reconnect";
    let (_machine, mut env, n, mut rng) = fault_start(test, "kill-service", "ksv");
    let args = ["--robot", "titan", "--name", n.as_str()];
    let first = env.chassisd("chassisd-0", &args);
    let mut robot = env.robot(&n, UP);
    // The safety monitor and the test's teleop stay up across every kill.
    env.spawn("safety", "chassis-safety", &["--name", &n]);
    let mut teleop = robot.source("teleop").unwrap();
    let go = VelocityRequest::twist(0.4, 0.0);
    let mut wire = Wire::new(&robot);
    let driving = Pump::new(&mut teleop, go, &mut wire).until(&mut robot, UP, |m, s| {
        source_status(m, "safety").has(SourceFlags::FRESH) && s.motion.linear_mps > 0.3
    });
    assert!(driving.is_some(), "no drive at the start\n{}", env.logs());
    let files_before = ipc_files(&env.prefix).len();

    // Kill at random moments: every other kill falls into the start-up of the instance spawned
    // just before (0-150 ms after its spawn: the ports half made, or not yet), the others into
    // an instance at work (0.15-1.5 s after it served its first state). The first start-up kill
    // comes within 5 ms of the spawn, so that at least one lands before the ports are up
    // (checked below: an instance that already logged "serving" does not count).
    const KILLS: usize = 6;
    let mut service = first;
    let mut starts_ms: Vec<f64> = Vec::new();
    let (mut starting_kills, mut killed_starting) = (0, 0);
    for cycle in 1..=KILLS {
        let starting = cycle % 2 == 0;
        let delay = if starting {
            // Measured from the spawn at the end of the previous cycle; nothing in between.
            let window = if cycle == 2 {
                EARLY_KILL
            } else {
                Duration::from_millis(150)
            };
            let delay = rng.between(Duration::ZERO, window);
            pause(delay);
            delay
        } else {
            let mut pump = Pump::new(&mut teleop, go, &mut wire);
            if cycle > 1 {
                let spawned = now_ns();
                let served = pump.until(&mut robot, UP, |_, s| {
                    s.stamp_ns > spawned && s.link.rx_frames > 0
                });
                let Some(t) = served else {
                    panic!("chassisd-{} never served\n{}", cycle - 1, env.logs());
                };
                starts_ms.push(t.as_secs_f64() * 1e3);
            }
            let delay = rng.between(Duration::from_millis(150), Duration::from_millis(1500));
            pump.run(&mut robot, delay);
            delay
        };
        // The service logs "serving" once every port exists.
        let was_up = env.proc(service).log_text().contains("serving chassis/");
        env.proc(service).signal(Signal::SIGKILL);
        let code = env.proc(service).wait_exit(Duration::from_secs(3));
        assert!(
            code.is_none() && !env.proc(service).is_running(),
            "chassisd-{} was not killed (exit {code:?})",
            cycle - 1
        );
        if starting {
            starting_kills += 1;
            if !was_up {
                killed_starting += 1;
            }
        }
        eprintln!("cycle {cycle}: SIGKILL {delay:?} in (starting: {starting}, up: {was_up})");
        service = env.chassisd(&format!("chassisd-{cycle}"), &args);
    }
    // The last instance: it must serve and the monitor reconnect. Teleop kept asking through
    // the restart (the same process, its connection reused): chassisd starting is a stop, so
    // the robot stands, saying it waits for teleop's zero, until teleop sends one.
    let restarted = now_ns();
    let (waiting, stood_samples, stood_fastest) = {
        let mut pump = Pump::new(&mut teleop, go, &mut wire);
        let waiting = pump.until(&mut robot, Duration::from_secs(15), |m, _| {
            m.stamp_ns > restarted
                && source_status(m, "safety").has(SourceFlags::FRESH)
                && m.zero_reason == ZeroReason::AWAITING_ZERO
                && m.stop == Stop::SERVICE_START
                && m.awaiting().is_some_and(|s| s.name() == "teleop")
        });
        let (samples, fastest) = pump.stands(&mut robot, restarted, STOOD_FOR);
        (waiting, samples, fastest)
    };
    teleop.stop().unwrap();
    let zero_sent = now_ns();
    let mut pump = Pump::new(&mut teleop, go, &mut wire);
    // Driving again: a speed the chassis reported after teleop's zero.
    let back = drove_again_after(
        &mut robot,
        zero_sent,
        Duration::from_secs(15),
        || pump.tick(),
        |s| s.motion.linear_mps > 0.3,
    );
    let guarded = waiting;
    let stood = stood_samples >= MIN_STOOD_SAMPLES && stood_fastest < STANDING_MPS;
    let stood_ms = STOOD_FOR.as_millis();
    let files_after = ipc_files(&env.prefix).len();
    let pass = back.is_some()
        && guarded.is_some()
        && stood
        && env.proc(service).is_running()
        && killed_starting >= 1;
    let back_ms = back.map_or(f64::NAN, |(_, d)| d.as_secs_f64() * 1e3);
    let slowest = starts_ms.iter().copied().fold(0.0f64, f64::max);
    let mut figures = Figures::faults();
    figures.add(fault_figure(
        SUITE,
        test,
        rank::KILL_SERVICE,
        "SIGKILL of chassisd (simulated bus)",
        &format!(
            "{KILLS} SIGKILLs at random moments: {starting_kills} 0-150 ms after the spawn \
             (the first within {} ms; {killed_starting} of them before the instance logged \
             that it serves), the others 0.15-1.5 s into \
             serving; chassis-safety and a teleop client running; restarted at once, without \
             cleanup",
            EARLY_KILL.as_millis()
        ),
        "every restart served again with no manual cleanup (iceoryx2 reclaimed the dead \
         instance's ports); the monitor and the teleop client reconnected by themselves; \
         motion starts only from a zero: teleop kept asking through the restart and the robot \
         stood, its mux waiting for teleop's zero since chassisd started, until teleop sent one; \
         then it drove; the simulated chassis dies with the service",
        format!(
            "{stood_samples} states in the {stood_ms} ms after the last restart, fastest \
             {stood_fastest:.3} m/s while teleop asked for 0.4; driving again {back_ms:.0} ms \
             after teleop's zero (the motion stamp of the first sample above 0.3 m/s); slowest \
             start {slowest:.0} ms; iceoryx2 files \
             {files_before} before the kills, {files_after} after (a kill inside iceoryx2's node \
             creation leaves its 3 node-monitor files; they block nothing)"
        ),
        back_ms,
        pass,
    ));
    assert!(
        killed_starting >= 1,
        "no kill landed in a start-up ({starting_kills} tried)\n{}",
        env.logs()
    );
    assert!(
        guarded.is_some(),
        "the monitor did not reconnect, or the mux did not wait for teleop's zero\n{}",
        env.logs()
    );
    assert!(
        stood,
        "the robot moved after the restart by itself ({stood_samples} states, fastest \
         {stood_fastest} m/s)\n{}",
        env.logs()
    );
    assert!(
        back.is_some(),
        "no drive after teleop's zero\n{}",
        env.logs()
    );
    assert!(env.proc(service).is_running(), "{}", env.logs());
    // A kill inside iceoryx2's node creation leaves that node's three monitor files (listed as
    // undefined, not dead, so nobody removes them); nothing else may be left behind.
    assert!(
        files_after <= files_before + 3 * KILLS,
        "shared-memory files grew from {files_before} to {files_after}"
    );
    figures.finish();
}

/// A chassisd killed between making a service's shared-memory segment and sizing it leaves an
/// empty, unreadable segment; iceoryx2 0.10 waits without end to open one, and removing the dead
/// instance's node opens every service it used. Made here without luck: an instance that served
/// is killed, and its services' dynamic segments are emptied as such a kill leaves them. The next
/// instance must serve (it removes them; it used to hang before its first log line).
#[test]
fn a_restart_after_a_kill_before_a_segment_was_sized_serves() {
    let _machine = shared();
    let mut env = Env::new("kill-unsized");
    let n = name("kus");
    let args = [
        "--robot",
        "titan",
        "--name",
        n.as_str(),
        "--no-safety-monitor",
    ];
    let first = env.chassisd("chassisd-0", &args);
    drop(env.robot(&n, UP));
    env.proc(first).signal(Signal::SIGKILL);
    env.proc(first).wait_exit(Duration::from_secs(3));
    let mut emptied = Vec::new();
    for entry in std::fs::read_dir("/dev/shm").unwrap().flatten() {
        let file = entry.file_name().to_string_lossy().to_string();
        if file.starts_with(&env.prefix) && file.ends_with(".dynamic") {
            let path = entry.path();
            std::fs::File::options()
                .write(true)
                .open(&path)
                .unwrap()
                .set_len(0)
                .unwrap();
            std::fs::set_permissions(&path, std::os::unix::fs::PermissionsExt::from_mode(0o200))
                .unwrap();
            emptied.push(file);
        }
    }
    assert!(
        emptied.len() >= 4,
        "the killed instance left {} dynamic segments",
        emptied.len()
    );
    let second = env.chassisd("chassisd-1", &args);
    let served = wait_for(Duration::from_secs(5), || {
        env.proc(second).log_text().contains("serving chassis/")
    });
    assert!(
        served.is_some(),
        "the restart did not serve within 5 s after {} segments were emptied\n{}",
        emptied.len(),
        env.logs()
    );
    let mut robot = env.robot(&n, UP);
    assert!(state(&mut robot).link.rx_frames > 0, "{}", env.logs());
    assert!(
        env.proc(second).log_text().contains("never sized"),
        "the restart did not say what it removed\n{}",
        env.logs()
    );
}

#[test]
fn sigkill_of_chassisd_over_slcan_lets_the_titan_stop_on_its_own_heartbeat_timeout() {
    let test = "sigkill_of_chassisd_over_slcan_lets_the_titan_stop_on_its_own_heartbeat_timeout";
    let (_machine, mut env, n, mut rng) = fault_start(test, "kill-service-pty", "ksp");
    let link = env.dir.join("titan-slcan");
    let (_, bus) = env.sim_on_pty("titan", &[], &n, Line::Slcan, &link, UP);
    let args = [
        "--robot",
        "titan",
        "--name",
        n.as_str(),
        "--bus",
        bus.as_str(),
        "--no-safety-monitor",
    ];
    let mut service = env.chassisd("chassisd-0", &args);
    let mut robot = env.robot(&n, UP);
    let mut teleop = robot.source("teleop").unwrap();
    let go = VelocityRequest::twist(0.5, 0.0);
    let mut wire = Wire::new(&robot);
    // A dead service is dead long enough for a chassis that never stopped to show it.
    let dead = Duration::from_millis(1500);
    let mut coasts: Vec<(f64, f64)> = Vec::new();
    let mut faults_seen = 0;
    let mut failure = None;
    let mut restarted = now_ns();
    for cycle in 1..=3 {
        if cycle > 1 {
            // Teleop kept asking through the restart: it asks for zero before it drives again
            // (the last cycle's restart checks that the robot waits for it).
            teleop.stop().unwrap();
        }
        let mut pump = Pump::new(&mut teleop, go, &mut wire);
        // Driving (again, after the restart of the cycle before): a speed reported since.
        let driving = pump.drove_again(&mut robot, restarted, UP, |s| {
            s.motion.linear_mps > 0.45 && s.is_valid(Group::Odometry)
        });
        if driving.is_none() {
            failure = Some(format!("cycle {cycle}: no drive"));
            break;
        }
        pump.run(&mut robot, a_moment(&mut rng));
        let before = state(&mut robot);
        env.proc(service).signal(Signal::SIGKILL);
        env.proc(service).wait_exit(Duration::from_secs(3));
        pause(dead);
        restarted = now_ns();
        service = env.chassisd(&format!("chassisd-{cycle}"), &args);
        // The first odometer reading of the new instance: what the chassis did meanwhile; and
        // what the chassis reported in its first status frames.
        let odometer = Group::Odometry as usize;
        let system = Group::System as usize;
        let mut after: Option<ChassisState> = None;
        let mut reported_faults = 0u64;
        let mut read_until = Instant::now() + UP;
        while Instant::now() < read_until {
            if let Ok(Some(s)) = robot.wait_state(Duration::from_millis(50)) {
                if s.group_stamp_ns[system] > restarted {
                    reported_faults |= s.system.fault_flags;
                }
                if after.is_none() && s.group_stamp_ns[odometer] > restarted {
                    after = Some(s);
                    // The first status frames follow within a few periods.
                    read_until = Instant::now() + Duration::from_millis(200);
                }
            }
        }
        let Some(after) = after else {
            failure = Some(format!(
                "cycle {cycle}: the restarted service read no odometer"
            ));
            break;
        };
        let coasted = after.odometry.front_distance_m - before.odometry.front_distance_m;
        let speed = f64::from(before.motion.linear_mps);
        if reported_faults & FaultFlags::HEARTBEAT_LOST != 0 {
            faults_seen += 1;
        }
        eprintln!(
            "cycle {cycle}: coasted {coasted:.3} m from {speed:.2} m/s ({:.0} ms of travel); \
             speed after the restart {:.3} m/s, faults reported {reported_faults:#x}",
            coasted / speed * 1e3,
            after.motion.linear_mps,
        );
        coasts.push((coasted, speed));
    }
    // At most the 500 ms heartbeat timeout at speed plus the 0.1 s stop lag and a frame period.
    let worst_ms = worst(&coasts.iter().map(|(d, v)| d / v * 1e3).collect::<Vec<_>>());
    let bound_ms = 500.0 + 3.0 * 100.0 + 20.0;
    // After the last restart teleop keeps asking: the robot stands, waiting for its zero, then
    // drives (a speed reported after the zero).
    let standing = {
        let mut pump = Pump::new(&mut teleop, go, &mut wire);
        stands_until_zero(
            &mut robot,
            restarted,
            ("teleop", &[Stop::SERVICE_START]),
            || pump.tick(),
        )
    };
    let stood = standing.as_ref().is_ok_and(StoodUntilZero::stood);
    teleop.stop().unwrap();
    let zero_sent = now_ns();
    let mut pump = Pump::new(&mut teleop, go, &mut wire);
    let again = pump.drove_again(&mut robot, zero_sent, UP, |s| s.motion.linear_mps > 0.4);
    let again_ms = again.map_or(f64::NAN, |(_, d)| d.as_secs_f64() * 1e3);
    let pass =
        failure.is_none() && coasts.len() == 3 && worst_ms <= bound_ms && stood && again.is_some();
    let mut figures = Figures::faults();
    figures.add(fault_figure(
        SUITE,
        test,
        rank::KILL_SERVICE_PTY,
        "SIGKILL of chassisd (slcan over a pty to `chassisd sim`)",
        &format!(
            "3 SIGKILLs at random moments while driving at 0.5 m/s; restarted after {} ms",
            dead.as_millis()
        ),
        &format!(
            "the TITAN stopped by itself on its 500 ms heartbeat timeout (standby, body \
             exception; the restarted service read `heartbeat_lost` before the chassis cleared \
             it in {faults_seen}/3); after the restart the robot stood while teleop kept asking \
             (motion starts only from a zero) and drove again after teleop's zero"
        ),
        format!(
            "coasted at most {worst_ms:.0} ms of travel at speed after the kill (bound \
             {bound_ms:.0} ms; a chassis that kept going: {} ms); after the last restart {}; \
             driving again {again_ms:.0} ms after teleop's zero (the motion stamp of the first \
             sample above 0.4 m/s)",
            dead.as_millis(),
            match &standing {
                Ok(s) => format!(
                    "stood {} ms ({} states, fastest {:.3} m/s)",
                    STOOD_FOR.as_millis(),
                    s.samples,
                    s.fastest_mps
                ),
                Err(e) => e.clone(),
            }
        ),
        worst_ms,
        pass,
    ));
    assert!(failure.is_none(), "{failure:?}\n{}", env.logs());
    assert!(
        worst_ms <= bound_ms,
        "coasted {worst_ms:.0} ms\n{}",
        env.logs()
    );
    assert!(
        stood,
        "the robot did not stand after the last restart: {standing:?}\n{}",
        env.logs()
    );
    assert!(
        again.is_some(),
        "no drive after the last restart and teleop's zero\n{}",
        env.logs()
    );
    figures.finish();
}

#[test]
fn sigkill_of_chassisd_sim_is_reported_as_a_lost_bus_and_survived() {
    let test = "sigkill_of_chassisd_sim_is_reported_as_a_lost_bus_and_survived";
    let (_machine, mut env, n, mut rng) = fault_start(test, "kill-sim", "ksm");
    let link = env.dir.join("xbot");
    let sim_bus = Line::Serial.sim_bus(&link);
    let (mut sim, mut robot) = env.xbot_over_pty(&n, &link, UP);
    let mut teleop = robot.source("teleop").unwrap();
    let go = VelocityRequest::twist(0.4, 0.0);
    let mut wire = Wire::new(&robot);
    let mut detect_ms = Vec::new();
    let mut back_ms = Vec::new();
    let mut tx_while_down = 0usize;
    let mut tx_before = Vec::new();
    let mut stood = Vec::new();
    let mut failure = None;
    for cycle in 1..=3 {
        let mut pump = Pump::new(&mut teleop, go, &mut wire);
        let driving = pump.until(&mut robot, UP, |_, s| {
            s.link_flags & LinkFlags::BUS_DOWN == 0 && s.motion.linear_mps > 0.3
        });
        if driving.is_none() {
            failure = Some(format!("cycle {cycle}: no drive"));
            break;
        }
        pump.run(&mut robot, a_moment(&mut rng));
        // The tap sees what is written: "nothing written while down" means something only
        // if frames were seen before.
        pump.wire.pump();
        tx_before.push(
            pump.wire
                .frames
                .iter()
                .filter(|f| f.direction == FrameDirection::TX)
                .count(),
        );
        let killed = Instant::now();
        env.proc(sim).signal(Signal::SIGKILL);
        // The dead simulator's link names a pseudo-terminal number the kernel hands out again:
        // removed at once, as udev removes an unplugged adapter's node, so that the service's
        // reopening never lands on another program's terminal.
        std::fs::remove_file(&link).ok();
        let lost = pump.until(&mut robot, Duration::from_secs(3), |_, s| {
            s.link_flags & LinkFlags::BUS_DOWN != 0
        });
        let Some(lost) = lost else {
            failure = Some(format!("cycle {cycle}: the hang-up was not reported"));
            break;
        };
        detect_ms.push(lost.as_secs_f64() * 1e3);
        env.proc(sim).wait_exit(Duration::from_secs(3));
        // Nothing is written while the bus is down.
        pump.wire.clear();
        pump.run(&mut robot, Duration::from_millis(300));
        pump.wire.pump();
        tx_while_down += pump
            .wire
            .frames
            .iter()
            .filter(|f| f.direction == FrameDirection::TX)
            .count();
        let restarted = now_ns();
        sim = env.sim(&format!("sim-{cycle}"), "xbot", &[], &n, &sim_bus);
        // Teleop kept asking: the bus coming back is the end of a stop, and motion starts only
        // from a zero.
        let standing =
            stands_until_zero(&mut robot, restarted, ("teleop", BUS_AND_ITS_FAULT), || {
                pump.tick()
            });
        match standing {
            Ok(s) if s.stood() => stood.push(s),
            other => {
                failure = Some(format!(
                    "cycle {cycle}: the robot did not stand until teleop's zero: {other:?}"
                ));
                break;
            }
        }
        if let Some((teleop, _)) = pump.teleop.as_mut() {
            teleop.stop().unwrap();
        }
        let zero_sent = now_ns();
        // The state keeps the speed from before the hang-up: only a speed the chassis reported
        // after the zero shows that it drives again.
        let back = drove_again_after(
            &mut robot,
            zero_sent,
            Duration::from_secs(10),
            || pump.tick(),
            |s| s.link_flags & LinkFlags::BUS_DOWN == 0 && s.motion.linear_mps > 0.3,
        );
        let Some((_, back)) = back else {
            failure = Some(format!(
                "cycle {cycle}: no drive after the chassis came back and teleop's zero"
            ));
            break;
        };
        back_ms.push(back.as_secs_f64() * 1e3);
        eprintln!(
            "cycle {cycle}: bus down reported {lost:?} after the kill; driving again {back:?} \
             after the restart ({:?} in all)",
            killed.elapsed()
        );
    }
    let reconnects = state(&mut robot).link.bus_reconnects;
    let worst_detect = worst(&detect_ms);
    let worst_back = worst(&back_ms);
    let seen_before = tx_before.iter().copied().min().unwrap_or(0);
    let pass = failure.is_none()
        && tx_while_down == 0
        && seen_before > 0
        && stood.len() == 3
        && reconnects >= 3;
    let mut figures = Figures::faults();
    figures.add(fault_figure(
        SUITE,
        test,
        rank::KILL_SIM,
        "SIGKILL of `chassisd sim` (the XBot's serial link over a pty hangs up)",
        "3 SIGKILLs at random moments while driving at 0.4 m/s; the simulator restarted",
        "the service reported `bus_down`, wrote nothing while it was down and reopened the \
         port with backoff; motion starts only from a zero: teleop kept asking and the robot \
         stood once the chassis was back, its mux waiting for teleop's zero since the bus came \
         back, until teleop sent one; then it drove (a speed reported after the zero)",
        format!(
            "hang-up reported after at most {worst_detect:.0} ms; stood {} ms after each \
             return ({} states at least, fastest {:.3} m/s); driving again at most \
             {worst_back:.0} ms after teleop's zero (the motion stamp of the first sample above \
             0.3 m/s); {tx_while_down} frames written while down ({seen_before} at least in \
             each drive before); {reconnects} reconnections",
            STOOD_FOR.as_millis(),
            stood.iter().map(|s| s.samples).min().unwrap_or(0),
            worst(&stood.iter().map(|s| s.fastest_mps).collect::<Vec<_>>())
        ),
        worst_detect,
        pass,
    ));
    assert!(failure.is_none(), "{failure:?}\n{}", env.logs());
    assert_eq!(tx_while_down, 0, "frames written to a dead bus");
    assert!(
        seen_before > 0,
        "the tap saw no frame written before a kill"
    );
    assert!(reconnects >= 3, "{reconnects} reconnections");
    figures.finish();
}

// ----- SIGKILL of the clients -----

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Client {
    Safety,
    Planner,
    Pub,
    Teleop,
}

impl Client {
    fn source(self) -> &'static str {
        match self {
            Client::Safety => "safety",
            Client::Planner => "planner",
            Client::Pub | Client::Teleop => "teleop",
        }
    }

    fn timeout_ms(self) -> f64 {
        match self {
            Client::Safety => 200.0,
            Client::Planner => 500.0,
            Client::Pub | Client::Teleop => 300.0,
        }
    }
}

/// A running client: a process of the test's `Env`, or a program in a terminal.
enum Running {
    Proc(usize),
    Terminal(Tmux),
}

fn start_client(env: &mut Env, client: Client, n: &str, cycle: usize) -> Running {
    let label = format!("{}-{cycle}", client.source());
    match client {
        Client::Safety => Running::Proc(env.spawn(&label, "chassis-safety", &["--name", n])),
        Client::Planner => Running::Proc(env.spawn(
            &label,
            "chassis-planner",
            &["--name", n, "--shape", "figure-eight", "--repeat"],
        )),
        Client::Pub => Running::Proc(env.spawn(
            &label,
            "chassis",
            &[
                "pub", "velocity", "--source", "teleop", "--vx", "0.4", "--name", n,
            ],
        )),
        Client::Teleop => {
            let log = env.dir.join(format!("{label}.log"));
            let command = format!("exec {}", teleop_command(env, n, &log));
            Running::Terminal(Tmux::start(&env.dir, &label, &command))
        }
    }
}

/// Starts `client`, lets it drive (or guard), SIGKILLs it at a random moment, and measures
/// when the mux commanded zero and when the last motion frame went out; `CYCLES` times, each
/// restart taking the source again.
fn kill_a_client_at_random_moments(client: Client, rank: u32, test: &str, fault: &str) {
    const CYCLES: usize = 4;
    let (_machine, mut env, n, mut rng) = fault_start(
        test,
        &format!("kill-{}", client.source()),
        &format!("k{}", &client.source()[..2]),
    );
    let mut args = vec!["--robot", "titan", "--name", n.as_str()];
    if client != Client::Safety {
        args.push("--no-safety-monitor");
    }
    env.chassisd("chassisd", &args);
    let mut robot = env.robot(&n, UP);
    let mut wire = Wire::new(&robot);
    // With the monitor as the victim, the test drives as teleop.
    let mut own = (client == Client::Safety).then(|| robot.source("teleop").unwrap());
    let go = VelocityRequest::twist(0.4, 0.0);
    let timeout = client.timeout_ms();
    let mut zero_ms = Vec::new();
    let mut wire_ms = Vec::new();
    let mut still_ms = Vec::new();
    let mut retake_ms = Vec::new();
    // After each restart of the monitor: states seen, fastest speed, until the mux waited.
    let mut stood: Vec<(usize, f64, Duration)> = Vec::new();
    let mut failure = None;
    for cycle in 1..=CYCLES {
        let running = start_client(&mut env, client, &n, cycle);
        let tmux = match &running {
            Running::Terminal(t) => Some(t),
            Running::Proc(_) => None,
        };
        let started = now_ns();
        let mut pump = Pump {
            teleop: own.as_mut().map(|s| (s, go)),
            tmux,
            wire: &mut wire,
            last: Instant::now() - Duration::from_secs(1),
        };
        let source = client.source();
        if client == Client::Safety && cycle > 1 {
            // The monitor is back, teleop never stopped asking: motion starts only from a zero.
            let waiting = pump.until(&mut robot, Duration::from_secs(15), |m, _| {
                m.stamp_ns > started
                    && source_status(m, source).has(SourceFlags::FRESH)
                    && m.zero_reason == ZeroReason::AWAITING_ZERO
                    && m.stop == Stop::REQUIRED_SOURCE
                    && m.awaiting().is_some_and(|s| s.name() == "teleop")
            });
            let Some(waiting) = waiting else {
                failure = Some(format!(
                    "cycle {cycle}: the restarted monitor did not leave the robot waiting for \
                     teleop's zero: {}",
                    mux(&mut robot).why()
                ));
                break;
            };
            let back = now_ns();
            let (samples, fastest) = pump.stands(&mut robot, back, STOOD_FOR);
            stood.push((samples, fastest, waiting));
            if samples < MIN_STOOD_SAMPLES || fastest.is_nan() || fastest >= STANDING_MPS {
                failure = Some(format!(
                    "cycle {cycle}: the robot moved after the monitor's restart by itself \
                     ({samples} states, fastest {fastest} m/s)"
                ));
                break;
            }
            if let Some((teleop, _)) = pump.teleop.as_mut() {
                teleop.stop().unwrap();
            }
        }
        let driving = pump.until(&mut robot, Duration::from_secs(15), |m, s| {
            let me = source_status(m, source);
            m.stamp_ns > started
                && me.has(SourceFlags::FRESH)
                && (client == Client::Safety || me.has(SourceFlags::ACTIVE))
                && m.output.linear_x_mps.abs() > 0.05
                && s.motion.linear_mps.abs() > 0.05
        });
        let Some(driving) = driving else {
            let screen = tmux.map(Tmux::screen).unwrap_or_default();
            failure = Some(format!(
                "cycle {cycle}: the {source} client never drove\n{screen}"
            ));
            break;
        };
        retake_ms.push(driving.as_secs_f64() * 1e3);
        pump.run(
            &mut robot,
            rng.between(Duration::from_millis(100), Duration::from_millis(1000)),
        );
        let pid = match &running {
            Running::Proc(i) => env.proc(*i).pid().as_raw(),
            Running::Terminal(t) => t.pid().unwrap(),
        };
        // The keys stop with the process: a dead program reads no terminal.
        pump.tmux = None;
        let killed = now_ns();
        nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid), Signal::SIGKILL).unwrap();
        let mut zero_at = 0;
        let zero = pump.until(&mut robot, Duration::from_secs(3), |m, _| {
            let stopped =
                m.output == BodyVelocity::ZERO && !source_status(m, source).has(SourceFlags::FRESH);
            if stopped {
                zero_at = m.stamp_ns;
            }
            stopped
        });
        if zero.is_none() {
            failure = Some(format!("cycle {cycle}: still commanding after the kill"));
            break;
        }
        let still = pump.until(&mut robot, Duration::from_secs(3), |_, s| {
            s.motion.linear_mps.abs() < 0.01
        });
        pump.run(&mut robot, Duration::from_millis(50));
        // The drive before the kill put motion frames on the tap: none seen is no figure.
        let last_motion = pump.wire.last_motion_ns();
        zero_ms.push(ms(i128::from(zero_at) - i128::from(killed)));
        wire_ms.push(last_motion.map_or(f64::NAN, |t| ms(i128::from(t) - i128::from(killed))));
        still_ms.push(still.map_or(f64::NAN, |_| ms(i128::from(now_ns()) - i128::from(killed))));
        pump.wire.clear();
        eprintln!(
            "cycle {cycle}: {source} SIGKILLed → zero command after {:.1} ms, last motion frame \
             {:.1} ms after the kill, robot still after {:.0} ms",
            zero_ms[cycle - 1],
            wire_ms[cycle - 1],
            still_ms[cycle - 1]
        );
        if let Running::Proc(i) = running {
            env.proc(i).wait_exit(Duration::from_secs(3));
        }
    }
    let (zero, wire_end, still) = (worst(&zero_ms), worst(&wire_ms), worst(&still_ms));
    // The mux acts at the dead source's expiry; the loop may be a few ms late under load.
    let bound = timeout + 40.0;
    let restarts_stood = client != Client::Safety || stood.len() == CYCLES - 1;
    let pass = failure.is_none()
        && zero <= bound
        && wire_end <= bound
        && wire.lost == 0
        && still.is_finite()
        && restarts_stood;
    let mut figures = Figures::faults();
    let what = if client == Client::Safety {
        "safe stop: the required source went stale, the mux commanded zero (not smoothed) and \
         the TITAN braked; each restarted monitor took the source again, and the robot stood \
         while teleop kept asking (motion starts only from a zero: the mux waited for teleop's \
         zero since the monitor came back) until teleop sent one, then drove"
    } else {
        "the dead source expired after its timeout, the mux commanded zero (not smoothed) and \
         the TITAN braked; each restarted client took the source again and drove"
    };
    figures.add(fault_figure(
        SUITE,
        test,
        rank,
        fault,
        &format!(
            "{CYCLES} SIGKILLs at random moments (0.1-1 s into a drive at 0.4 m/s); restarted \
             after each"
        ),
        what,
        format!(
            "zero command at most {zero:.0} ms after the kill, last motion frame on the bus \
             {wire_end:.0} ms (timeout {timeout:.0} ms); robot standing after {still:.0} ms; \
             source taken again within {:.0} ms{}",
            worst(&retake_ms),
            if stood.is_empty() {
                String::new()
            } else {
                format!(
                    "; after each of {} restarts of the monitor the robot stood {} ms ({} states \
                     at least, fastest {:.3} m/s) until teleop's zero",
                    stood.len(),
                    STOOD_FOR.as_millis(),
                    stood.iter().map(|s| s.0).min().unwrap_or(0),
                    worst(&stood.iter().map(|s| s.1).collect::<Vec<_>>())
                )
            }
        ),
        zero,
        pass,
    ));
    assert!(failure.is_none(), "{failure:?}\n{}", env.logs());
    assert!(zero <= bound, "zero command {zero:.1} ms after the kill");
    assert!(
        wire_end <= bound,
        "motion frame {wire_end:.1} ms after the kill"
    );
    assert_eq!(wire.lost, 0, "the tap lost frames");
    assert!(
        still.is_finite(),
        "the robot was not seen standing after a kill"
    );
    assert!(
        restarts_stood,
        "{} restarts of the monitor judged",
        stood.len()
    );
    figures.finish();
}

#[test]
fn sigkill_of_the_safety_monitor_at_random_moments_stops_the_robot_within_its_timeout() {
    kill_a_client_at_random_moments(
        Client::Safety,
        rank::KILL_SAFETY,
        "sigkill_of_the_safety_monitor_at_random_moments_stops_the_robot_within_its_timeout",
        "SIGKILL of chassis-safety (the required source)",
    );
}

#[test]
fn sigkill_of_the_planner_at_random_moments_ends_its_motion_with_its_timeout() {
    kill_a_client_at_random_moments(
        Client::Planner,
        rank::KILL_PLANNER,
        "sigkill_of_the_planner_at_random_moments_ends_its_motion_with_its_timeout",
        "SIGKILL of chassis-planner (figure-eights)",
    );
}

#[test]
fn sigkill_of_chassis_pub_at_random_moments_ends_its_motion_with_its_timeout() {
    kill_a_client_at_random_moments(
        Client::Pub,
        rank::KILL_PUB,
        "sigkill_of_chassis_pub_at_random_moments_ends_its_motion_with_its_timeout",
        "SIGKILL of `chassis pub` (as teleop)",
    );
}

#[test]
fn sigkill_of_chassis_teleop_in_a_terminal_ends_its_motion_with_its_timeout() {
    if !tmux_available() {
        eprintln!("SKIPPED: tmux is not installed; chassis-teleop needs a terminal");
        return;
    }
    kill_a_client_at_random_moments(
        Client::Teleop,
        rank::KILL_TELEOP,
        "sigkill_of_chassis_teleop_in_a_terminal_ends_its_motion_with_its_timeout",
        "SIGKILL of chassis-teleop (a key held in a terminal)",
    );
}
