//! chassisd on SocketCAN, with real processes on a kernel vcan interface: the service against
//! `chassisd sim` driving end to end, can-utils on the same bus (`cansend` into the service,
//! `candump` of what it sends decoded by `chassis decode`, a `cangen` flood), and the interface
//! going down and coming back mid-drive.
//!
//! They need a kernel with CAN and root for `ip link`, so they are ignored on a normal host;
//! `scripts/vm-tests` runs them with `--ignored --test-threads=1` inside a VM
//! (`scripts/vm/run-in-vm`). They share one interface, CHASSIS_VCAN (default vcan0), so they
//! run one at a time. Lines starting with `figure:` are the measurements the report collects.
// Test code: helpers outside #[test] functions may unwrap, panic and read the wall clock.
#![allow(clippy::unwrap_used, clippy::panic, clippy::disallowed_methods)]

use std::fs::File;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use chassis_tests::*;
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

/// Under an emulated CPU everything starts slower than on a host.
const UP: Duration = Duration::from_secs(30);

fn iface() -> String {
    std::env::var("CHASSIS_VCAN").unwrap_or_else(|_| "vcan0".into())
}

fn figure(text: impl AsRef<str>) {
    println!("figure: {}", text.as_ref());
}

fn ms(d: Duration) -> String {
    format!("{:.0} ms", d.as_secs_f64() * 1e3)
}

fn ip(args: &[&str]) {
    let out = Command::new("ip").args(args).output().unwrap();
    assert!(
        out.status.success(),
        "ip {}: {}",
        args.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
}

fn cansend(frame: &str) {
    let iface = iface();
    let status = Command::new("cansend").args([&iface, frame]).status();
    assert!(
        status.as_ref().is_ok_and(|s| s.success()),
        "cansend {iface} {frame}: {status:?}"
    );
}

/// A can-utils process in the background, stopped (SIGINT, as Ctrl-C) when dropped.
struct Tool(Child);

impl Tool {
    fn spawn(program: &str, args: &[&str], stdout: Stdio) -> Self {
        let child = Command::new(program)
            .args(args)
            .stdin(Stdio::null())
            .stdout(stdout)
            .spawn()
            .unwrap_or_else(|e| panic!("starting {program}: {e}"));
        Self(child)
    }

    fn stop(&mut self) {
        if let Ok(pid) = i32::try_from(self.0.id()) {
            let _ = kill(Pid::from_raw(pid), Signal::SIGINT);
        }
        let end = Instant::now() + Duration::from_secs(3);
        while Instant::now() < end {
            if matches!(self.0.try_wait(), Ok(Some(_))) {
                return;
            }
            pause(Duration::from_millis(10));
        }
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

impl Drop for Tool {
    fn drop(&mut self) {
        self.stop();
    }
}

/// Sends `request` every 20 ms until `done(state)` holds or `timeout` passes; returns the time
/// it took.
fn drive_until(
    robot: &mut Robot,
    teleop: &mut Source,
    request: VelocityRequest,
    timeout: Duration,
    mut done: impl FnMut(&ChassisState) -> bool,
) -> Option<Duration> {
    let start = Instant::now();
    while start.elapsed() < timeout {
        teleop.send(request).unwrap();
        if let Ok(Some(state)) = robot.wait_state(Duration::from_millis(20))
            && done(&state)
        {
            return Some(start.elapsed());
        }
    }
    None
}

/// `chassisd sim --robot titan` and `chassisd --robot titan`, both on the vcan interface.
fn titan_on_vcan(env: &mut Env, n: &str) -> (usize, usize) {
    let bus = format!("can:{}", iface());
    let sim = env.sim("sim", "titan", &[], n, &bus);
    let service = env.serve("titan", n, &["--bus", &bus, "--no-safety-monitor"]);
    (sim, service)
}

/// A test's environment (`test` names it) with `chassisd --robot titan` alone on the vcan
/// interface as chassis/NAME (`tag` and the pid): the environment, NAME and a connection.
fn service_on_vcan(test: &str, tag: &str) -> (Env, String, Robot) {
    let bus = format!("can:{}", iface());
    Env::serving(
        test,
        (tag, "titan"),
        &["--bus", &bus, "--no-safety-monitor"],
        UP,
    )
}

fn in_command_mode(s: &ChassisState) -> bool {
    s.system.control_mode == ControlMode::COMMAND
        && s.link_flags & (LinkFlags::CHASSIS_SILENT | LinkFlags::BUS_DOWN) == 0
}

#[test]
#[ignore = "needs kernel CAN (vcan) and root: scripts/vm-tests runs it in a VM"]
fn chassisd_drives_the_simulated_titan_across_vcan_end_to_end() {
    let mut env = Env::new("vcan-drive");
    let n = name("vd");
    let started = Instant::now();
    titan_on_vcan(&mut env, &n);
    let mut robot = env.robot(&n, UP);
    figure(format!(
        "service and simulator on {}: first state after {}",
        iface(),
        ms(started.elapsed())
    ));
    let ready = wait_for(UP, || in_command_mode(&state(&mut robot)));
    assert!(
        ready.is_some(),
        "the simulated chassis never reported command mode\n{}",
        env.logs()
    );

    let tap = robot.frames(2048).unwrap();
    tap.drain(|_| {}).unwrap();
    let mut teleop = source(&mut robot, "teleop");
    let go = VelocityRequest::twist(0.3, 0.0);
    let asked_ns = now_ns();
    let reached = drive_until(&mut robot, &mut teleop, go, Duration::from_secs(10), |s| {
        s.motion.linear_mps > 0.25
    });
    let reached = reached.unwrap_or_else(|| panic!("never reached 0.25 m/s\n{}", env.logs()));
    figure(format!(
        "teleop 0.3 m/s → 0.25 m/s reported back in {}",
        ms(reached)
    ));

    // On the wire: the simulator's feedback came in, our commands went out, and the first moving
    // 0x111 followed the request.
    let (mut rx_ids, mut first_moving_ns) = (Vec::new(), None);
    tap.drain(|f| {
        if f.direction == FrameDirection::RX {
            rx_ids.push(f.can_id);
        } else if f.can_id == 0x111 && f.payload()[..2] != [0, 0] && first_moving_ns.is_none() {
            first_moving_ns = Some(f.stamp_ns);
        }
    })
    .unwrap();
    for id in [0x211, 0x221, 0x311] {
        assert!(rx_ids.contains(&id), "no 0x{id:X} from the simulator");
    }
    let first = first_moving_ns.unwrap_or_else(|| panic!("no moving 0x111 sent"));
    figure(format!(
        "teleop request → first moving 0x111 on {}: {:.2} ms",
        iface(),
        first.saturating_sub(asked_ns) as f64 / 1e6
    ));

    let stopped = drive_until(
        &mut robot,
        &mut teleop,
        VelocityRequest::twist(0.0, 0.0),
        Duration::from_secs(10),
        |s| s.motion.linear_mps.abs() < 0.01,
    );
    assert!(stopped.is_some(), "did not stop\n{}", env.logs());
    let s = state(&mut robot);
    assert!(s.odometry.x_m > 0.05, "travelled {} m", s.odometry.x_m);
    assert_eq!(s.link.bus_reconnects, 0);
    figure(format!(
        "stop after {} (travelled {:.2} m)",
        ms(stopped.unwrap()),
        s.odometry.x_m
    ));
}

#[test]
#[ignore = "needs kernel CAN (vcan) and root: scripts/vm-tests runs it in a VM"]
fn frames_from_cansend_update_the_state_of_a_service_without_a_chassis() {
    let (env, _, mut robot) = service_on_vcan("vcan-cansend", "vs");
    // No chassis on the bus: the service says so.
    let silent = wait_for(Duration::from_secs(5), || {
        state(&mut robot).link_flags & LinkFlags::CHASSIS_SILENT != 0
    });
    assert!(silent.is_some(), "no CHASSIS_SILENT without a chassis");
    let before = state(&mut robot);
    assert_eq!(before.system.battery_voltage_v, 0.0);
    let tap = robot.frames(2048).unwrap();
    tap.drain(|_| {}).unwrap();

    // A fake chassis: status (command mode, 48.0 V, no fault) and motion feedback (0.5 m/s).
    let sent = Instant::now();
    cansend("211#000101E000000000");
    cansend("221#01F4000000000000");
    let seen = wait_for(Duration::from_secs(5), || {
        let s = state(&mut robot);
        s.system.battery_voltage_v == 48.0 && s.motion.linear_mps == 0.5
    });
    assert!(
        seen.is_some(),
        "the cansend frames did not reach the state: {:?}\n{}",
        state(&mut robot).system,
        env.logs()
    );
    figure(format!(
        "cansend 0x211 + 0x221 → state updated in {} (two cansend processes included)",
        ms(sent.elapsed())
    ));
    let s = state(&mut robot);
    assert_eq!(s.system.control_mode, ControlMode::COMMAND);
    assert!(s.link.rx_frames >= before.link.rx_frames + 2);
    let mut tapped = Vec::new();
    tap.drain(|f| {
        if f.direction == FrameDirection::RX {
            tapped.push((f.can_id, f.payload().to_vec()));
        }
    })
    .unwrap();
    assert!(tapped.contains(&(0x211, vec![0x00, 0x01, 0x01, 0xE0, 0, 0, 0, 0])));
    assert!(tapped.contains(&(0x221, vec![0x01, 0xF4, 0, 0, 0, 0, 0, 0])));

    // A fault word from the fake chassis: the over-current bit (b6 bit 7).
    cansend("211#0001019000008000");
    let fault = wait_for(Duration::from_secs(5), || {
        let s = state(&mut robot);
        s.system.fault_flags & FaultFlags::OVER_CURRENT != 0 && s.system.battery_voltage_v == 40.0
    });
    assert!(fault.is_some(), "{:?}", state(&mut robot).system);
}

/// `(seconds, id, data)` of a `candump -L` line: `(1700000000.000000) vcan0 111#00…`.
fn candump_line(line: &str) -> Option<(f64, u32, String)> {
    let (stamp, rest) = line.trim().strip_prefix('(')?.split_once(") ")?;
    let (_iface, frame) = rest.split_once(' ')?;
    let (id, data) = frame.split_once('#')?;
    Some((
        stamp.parse().ok()?,
        u32::from_str_radix(id, 16).ok()?,
        data.to_string(),
    ))
}

#[test]
#[ignore = "needs kernel CAN (vcan) and root: scripts/vm-tests runs it in a VM"]
fn candump_of_what_the_service_sends_decodes_with_chassis_decode() {
    let mut env = Env::new("vcan-candump");
    let n = name("vc");
    let iface = iface();
    let log = env.dir.join("candump.log");
    let mut dump = Tool::spawn(
        "candump",
        &["-L", &iface],
        Stdio::from(File::create(&log).unwrap()),
    );
    // candump is listening once it has seen a frame: send a harmless marker (a steering-zero
    // acknowledgement, which chassis decode knows) until it shows.
    let listening = wait_for(Duration::from_secs(10), || {
        cansend("43A#EE");
        pause(Duration::from_millis(50));
        std::fs::read_to_string(&log).is_ok_and(|t| t.contains("43A#EE"))
    });
    assert!(listening.is_some(), "candump never listened");

    let bus = format!("can:{iface}");
    env.serve("titan", &n, &["--bus", &bus, "--no-safety-monitor"]);
    let mut robot = env.robot(&n, UP);
    // A status frame reporting standby: the service asks for command mode again.
    pause(Duration::from_millis(500));
    cansend("211#000001E000000000");
    pause(Duration::from_millis(1500));
    let _ = state(&mut robot);
    dump.stop();

    let text = std::fs::read_to_string(&log).unwrap();
    let decode = Command::new(bin("chassis"))
        .args(["decode", "--robot", "titan"])
        .stdin(File::open(&log).unwrap())
        .output()
        .unwrap();
    let stdout = env.succeeded(&format!("chassis decode failed on\n{text}"), &decode);
    let heartbeats = stdout
        .lines()
        .filter(|l| {
            l.contains(r#""id":"0x111""#)
                && l.contains(r#""frame":"motion_command""#)
                && l.contains(r#""linear_mps":0.0"#)
        })
        .count();
    let modes = stdout
        .lines()
        .filter(|l| l.contains(r#""id":"0x421""#) && l.contains(r#""mode":1"#))
        .count();
    assert!(heartbeats >= 20, "{heartbeats} heartbeats in\n{stdout}");
    assert!(
        modes >= 2,
        "0x421 at start and after the standby report: {modes}\n{stdout}"
    );
    assert_eq!(
        stdout.lines().count(),
        text.lines().count(),
        "every candump line decodes"
    );

    // The chassis drops to standby when 0x111 pauses for 500 ms: the gaps on the wire.
    let stamps: Vec<f64> = text
        .lines()
        .filter_map(candump_line)
        .filter(|(_, id, _)| *id == 0x111)
        .map(|(t, _, _)| t)
        .collect();
    let gaps: Vec<f64> = stamps.windows(2).map(|w| w[1] - w[0]).collect();
    let mean = gaps.iter().sum::<f64>() / gaps.len().max(1) as f64;
    let worst = gaps.iter().copied().fold(0.0, f64::max);
    figure(format!(
        "candump: {} frames decoded, {heartbeats} heartbeats 0x111 every {:.1} ms (worst gap {:.1} ms), {modes} × 0x421",
        text.lines().count(),
        mean * 1e3,
        worst * 1e3
    ));
    assert!(worst < 0.5, "a heartbeat gap of {worst} s");
}

#[test]
#[ignore = "needs kernel CAN (vcan) and root: scripts/vm-tests runs it in a VM"]
fn a_cangen_flood_of_unknown_frames_does_not_stop_the_drive() {
    let mut env = Env::new("vcan-flood");
    let n = name("vf");
    titan_on_vcan(&mut env, &n);
    let mut robot = env.robot(&n, UP);
    assert!(wait_for(UP, || in_command_mode(&state(&mut robot))).is_some());
    let before = state(&mut robot).link.rx_unknown_id;
    let iface = iface();
    // 0x7F0, 8 random bytes, one frame per millisecond: an id no TITAN frame uses.
    let mut flood = Tool::spawn(
        "cangen",
        &[&iface, "-I", "7F0", "-L", "8", "-D", "r", "-g", "1"],
        Stdio::null(),
    );
    let mut teleop = source(&mut robot, "teleop");
    let reached = drive_until(
        &mut robot,
        &mut teleop,
        VelocityRequest::twist(0.3, 0.0),
        Duration::from_secs(10),
        |s| s.motion.linear_mps > 0.25,
    );
    let s = state(&mut robot);
    flood.stop();
    assert!(
        reached.is_some(),
        "no drive under the flood\n{}",
        env.logs()
    );
    let unknown = s.link.rx_unknown_id - before;
    assert!(unknown > 100, "only {unknown} flood frames seen");
    assert_eq!(s.link_flags & LinkFlags::CHASSIS_SILENT, 0);
    figure(format!(
        "under a cangen flood ({unknown} unknown frames counted): 0.25 m/s reached in {}",
        ms(reached.unwrap())
    ));
}

#[test]
#[ignore = "needs kernel CAN (vcan) and root: scripts/vm-tests runs it in a VM"]
fn the_interface_going_down_and_up_mid_drive_is_detected_and_survived() {
    let mut env = Env::new("vcan-down");
    let n = name("vu");
    let iface = iface();
    let (sim, service) = titan_on_vcan(&mut env, &n);
    let mut robot = env.robot(&n, UP);
    assert!(wait_for(UP, || in_command_mode(&state(&mut robot))).is_some());
    let mut teleop = source(&mut robot, "teleop");
    let go = VelocityRequest::twist(0.3, 0.0);
    let moving = drive_until(&mut robot, &mut teleop, go, Duration::from_secs(10), |s| {
        s.motion.linear_mps > 0.25
    });
    assert!(
        moving.is_some(),
        "no drive before the fault\n{}",
        env.logs()
    );
    let reconnects_before = state(&mut robot).link.bus_reconnects;

    // Down, mid-drive, while teleop keeps asking.
    ip(&["link", "set", &iface, "down"]);
    let mut first_flags = 0;
    let detected = drive_until(&mut robot, &mut teleop, go, Duration::from_secs(5), |s| {
        first_flags = s.link_flags & (LinkFlags::BUS_DOWN | LinkFlags::CHASSIS_SILENT);
        first_flags != 0
    });
    let detected = detected.unwrap_or_else(|| panic!("the loss was not reported\n{}", env.logs()));
    figure(format!(
        "{iface} down → {} in the state after {}",
        LinkFlags::names(first_flags).join("+"),
        ms(detected)
    ));

    // While it is down the loss stays reported: BUS_DOWN stays set and the service does not
    // "reopen" an interface that is still down (each reopen counts as a reconnection).
    let hold = Instant::now();
    let (mut samples, mut clear_samples) = (0, 0);
    let mut reconnects_while_down = 0;
    while hold.elapsed() < Duration::from_millis(1500) {
        teleop.send(go).unwrap();
        if let Ok(Some(s)) = robot.wait_state(Duration::from_millis(20)) {
            samples += 1;
            if hold.elapsed() > Duration::from_millis(300)
                && s.link_flags & LinkFlags::BUS_DOWN == 0
            {
                clear_samples += 1;
            }
            reconnects_while_down = s.link.bus_reconnects - reconnects_before;
        }
    }
    assert_eq!(
        (reconnects_while_down, clear_samples),
        (0, 0),
        "while {iface} was down: {reconnects_while_down} reconnections, BUS_DOWN clear in \
         {clear_samples} of {samples} states (reopen flapping)\n{}",
        env.logs()
    );

    // Up again. The simulated chassis kept running without its bus (its command timeout stopped
    // it) and reopens it by itself; one that ended is started again, as a power-cycled chassis
    // would come back.
    let up_at = Instant::now();
    let up_ns = now_ns();
    ip(&["link", "set", &iface, "up"]);
    let sim_ended = env.proc(sim).wait_exit(Duration::from_secs(2)).is_some();
    if sim_ended {
        let bus = format!("can:{iface}");
        env.sim("sim2", "titan", &[], &n, &bus);
    }
    let reopened = wait_for(Duration::from_secs(10), || {
        state(&mut robot).link_flags & LinkFlags::BUS_DOWN == 0
    })
    .map(|_| up_at.elapsed());
    let reopened = reopened.unwrap_or_else(|| panic!("the bus was never reopened\n{}", env.logs()));
    // Teleop kept asking: the bus coming back starts nothing until teleop asks for zero.
    let standing = stands_until_zero(&mut robot, up_ns, ("teleop", BUS_AND_ITS_FAULT), || {
        teleop.send(go).unwrap()
    });
    assert!(
        standing.as_ref().is_ok_and(StoodUntilZero::stood),
        "moved after the bus came back by itself: {standing:?}\n{}",
        env.logs()
    );
    teleop.stop().unwrap();
    let driving = drive_until(&mut robot, &mut teleop, go, Duration::from_secs(20), |s| {
        s.link_flags & (LinkFlags::BUS_DOWN | LinkFlags::CHASSIS_SILENT) == 0
            && s.motion.linear_mps > 0.1
    });
    assert!(
        driving.is_some(),
        "no motion after the bus came back\n{}",
        env.logs()
    );
    let driving = up_at.elapsed();
    let s = state(&mut robot);
    let standing = standing.unwrap_or_else(|e| panic!("{e}"));
    figure(format!(
        "{iface} up → bus reopened after {}; stood {} ({} states, fastest {:.3} m/s) waiting \
         for teleop's zero; driving again after {} (simulator restarted: {})",
        ms(reopened),
        ms(STOOD_FOR),
        standing.samples,
        standing.fastest_mps,
        ms(driving),
        if sim_ended { "yes" } else { "no" }
    ));
    assert_eq!(
        s.link.bus_reconnects,
        reconnects_before + 1,
        "one reconnection expected\n{}",
        env.logs()
    );
    // Reported, not asserted: the wait set detaching the old bus descriptor after the bus (and
    // so the descriptor) was already dropped.
    let log = env.proc(service).log_text();
    figure(format!(
        "service log after the reconnection: {} error lines, {} iceoryx2 \"Failed to detach\" warnings",
        log.lines().filter(|l| l.contains("ERROR")).count(),
        log.matches("Failed to detach").count()
    ));
}

/// Sends a raw frame with `can_id` (flags included) and 8 data bytes on the interface, as a
/// driver's error frame reaches every socket: vcan has no controller of its own, so the
/// kernel's error frames for one are written here, byte for byte as `can_change_state()`,
/// `can_bus_off()` and `can_restart()` (drivers/net/can/dev/dev.c) fill them.
fn send_raw(can_id: u32, data: [u8; 8]) {
    use socketcan::{CanSocket, Socket};
    let socket = CanSocket::open(&iface()).unwrap();
    let mut raw = socketcan::frame::can_frame_default();
    raw.can_id = can_id;
    raw.can_dlc = 8;
    raw.data = data;
    socket.write_frame(&socketcan::CanFrame::from(raw)).unwrap();
}

/// `CAN_ERR_FLAG` | the class bits.
const CAN_ERR: u32 = 0x2000_0000;

fn doctor(env: &Env, n: &str, robot: &str) -> (Option<i32>, String) {
    doctor_listening(env, robot, n, &format!("can:{}", iface()))
}

fn verdict_of<'a>(report: &'a str, key: &str) -> &'a str {
    doctor_line(report, key).0
}

#[test]
#[ignore = "needs kernel CAN (vcan) and root: scripts/vm-tests runs it in a VM"]
fn the_doctor_on_socketcan_down_silent_and_with_the_simulated_titan() {
    let mut env = Env::new("vcan-doctor");
    let iface = iface();
    let n = name("vx");

    ip(&["link", "set", &iface, "down"]);
    let (code, report) = doctor(&env, &n, "titan");
    ip(&["link", "set", &iface, "up"]);
    assert_eq!(code, Some(1), "{report}");
    assert_eq!(verdict_of(&report, "interface"), "ok", "{report}");
    assert_eq!(verdict_of(&report, "up"), "FAIL", "{report}");
    assert!(
        report.contains(&format!("fix: sudo ip link set {iface} up")),
        "{report}"
    );

    // Up, nobody on the bus.
    let (code, report) = doctor(&env, &n, "titan");
    assert_eq!(code, Some(1), "{report}");
    assert_eq!(verdict_of(&report, "bitrate"), "skip", "{report}");
    assert_eq!(verdict_of(&report, "frames"), "FAIL", "{report}");
    assert!(report.contains("nothing heard in 1.0 s"), "{report}");

    // The simulated TITAN on the bus: heard, a TITAN's frames, in standby until chassisd asks.
    let bus = format!("can:{iface}");
    env.sim("sim", "titan", &[], &name("vy"), &bus);
    let (heard, report) = until_passes(UP, || doctor(&env, &n, "titan"));
    assert!(heard.is_some(), "{report}\n{}", env.logs());
    assert_eq!(verdict_of(&report, "frames"), "ok", "{report}");
    assert_eq!(verdict_of(&report, "robot"), "ok", "{report}");
    assert_eq!(verdict_of(&report, "e-stop"), "ok", "{report}");
    figure("chassis doctor on vcan: down, silent and the simulated TITAN as expected");

    // The same robot asked for as a SCOUT MINI: its V1/V2 rule hears V2 and the frames fit.
    let (_, report) = doctor(&env, &n, "scout-mini");
    assert!(report.contains("AgileX v2"), "{report}");
}

#[test]
#[ignore = "needs kernel CAN (vcan) and root: scripts/vm-tests runs it in a VM"]
fn error_frames_on_the_socket_are_published_as_bus_off_and_restart_and_the_doctor_fails() {
    let (env, n, mut robot) = service_on_vcan("vcan-busoff", "vb");
    // Teleop asks for 0.3 m/s throughout (no chassis here: the mux's output is what is
    // commanded).
    let mut teleop = source(&mut robot, "teleop");
    let go = VelocityRequest::twist(0.3, 0.0);
    let commanding = |robot: &mut Robot, teleop: &mut Source, v: f32| {
        wait_for(UP, || {
            teleop.send(go).unwrap();
            (mux(robot).output.linear_x_mps - v).abs() < 1e-3
        })
    };
    assert!(commanding(&mut robot, &mut teleop, 0.3).is_some());

    // can_bus_off(): CAN_ERR_BUSOFF, no data.
    send_raw(CAN_ERR | 0x040, [0; 8]);
    let off = wait_for(UP, || {
        state(&mut robot).has_link_flag(LinkFlags::CAN_BUS_OFF)
    });
    assert!(off.is_some(), "no bus-off published\n{}", env.logs());
    let s = state(&mut robot);
    assert_eq!(
        (
            s.link.can_state,
            s.link.can_bus_off,
            s.link.can_error_frames
        ),
        (ControllerState::BUS_OFF, 1, 1)
    );
    figure(format!(
        "an error frame (bus-off) on {} → published in {}",
        iface(),
        ms(off.unwrap())
    ));
    let status = env.chassis(&["status", "--name", &n]);
    let text = String::from_utf8_lossy(&status.stdout);
    assert!(text.contains("BUS-OFF"), "{text}");
    assert!(text.contains("can        bus-off"), "{text}");
    let (code, report) = doctor(&env, &n, "titan");
    assert_eq!(code, Some(1), "{report}");
    assert_eq!(verdict_of(&report, "controller"), "FAIL", "{report}");
    assert!(
        env.logs().contains("the CAN controller is bus-off"),
        "{}",
        env.logs()
    );
    // Bus-off holds zero, naming the bus.
    let m = mux(&mut robot);
    assert_eq!(
        (m.zero_reason, m.stop, m.output.linear_x_mps),
        (ZeroReason::HELD, Stop::BUS, 0.0),
        "{}",
        m.why()
    );

    // can_restart(): CAN_ERR_RESTARTED.
    let restarted = now_ns();
    send_raw(CAN_ERR | 0x100, [0; 8]);
    let back = wait_for(UP, || {
        let s = state(&mut robot);
        s.link.can_state == ControllerState::ERROR_ACTIVE && s.link.can_restarts == 1
    });
    assert!(back.is_some(), "no restart published\n{}", env.logs());
    assert!(!state(&mut robot).has_link_flag(LinkFlags::CAN_BUS_OFF));
    // Back on the bus, teleop still asking: motion starts only from a zero.
    let waiting = wait_for(Duration::from_secs(2), || {
        teleop.send(go).unwrap();
        let m = mux(&mut robot);
        m.stamp_ns > restarted
            && m.zero_reason == ZeroReason::AWAITING_ZERO
            && m.stop == Stop::BUS
            && m.output == BodyVelocity::ZERO
    });
    assert!(waiting.is_some(), "{}", mux(&mut robot).why());
    teleop.stop().unwrap();
    let driving = commanding(&mut robot, &mut teleop, 0.3);
    assert!(driving.is_some(), "{}", mux(&mut robot).why());
    figure(format!(
        "bus-off then restart on {} → zero held, then waiting for teleop's zero after the \
         restart ({}), commanding again {} after it",
        iface(),
        ms(waiting.unwrap()),
        ms(driving.unwrap())
    ));

    // can_change_state() to error-passive on the transmit side, counters 128/5.
    send_raw(CAN_ERR | 0x004 | 0x200, [0, 0x20, 0, 0, 0, 0, 128, 5]);
    let passive = wait_for(UP, || {
        state(&mut robot).has_link_flag(LinkFlags::CAN_ERROR_PASSIVE)
    });
    assert!(
        passive.is_some(),
        "no error-passive published\n{}",
        env.logs()
    );
    let s = state(&mut robot);
    assert_eq!(
        (
            s.link.can_tx_error_count,
            s.link.can_rx_error_count,
            s.link.can_error_passive
        ),
        (128, 5, 1)
    );
}
