//! The XBot's RS232 link and its GPS receiver over pseudo-terminals, and the SCOUT MINI on its
//! simulated chassis.
// Test code: helpers outside #[test] functions may unwrap, panic and read the wall clock.
#![allow(clippy::unwrap_used, clippy::panic, clippy::disallowed_methods)]

use std::io::Write;
use std::os::fd::AsFd;
use std::time::{Duration, Instant};

use chassis_tests::*;

const UP: Duration = Duration::from_secs(10);

fn drive(robot: &mut Robot, source: &mut Source, request: VelocityRequest, for_: Duration) -> f32 {
    let end = Instant::now() + for_;
    let mut peak = 0.0f32;
    while Instant::now() < end {
        source.send(request).unwrap();
        if let Ok(Some(s)) = robot.wait_state(Duration::from_millis(20)) {
            peak = peak.max(s.motion.linear_mps.abs());
        }
    }
    peak
}

/// The length of one XBot status report on the line, bytes.
const XBOT_REPORT_BYTES: u64 = 75;

/// The bytes the service read, from its frame tap, with the tap's sequence gaps.
#[derive(Debug, Default)]
struct TapBytes {
    rx_bytes: u64,
    last_seq: u64,
    lost: u64,
}

impl TapBytes {
    fn drain(&mut self, tap: &FrameTap) {
        tap.drain(|f| {
            if self.last_seq != 0 && f.seq > self.last_seq + 1 {
                self.lost += f.seq - self.last_seq - 1;
            }
            self.last_seq = f.seq;
            if f.direction == FrameDirection::RX {
                self.rx_bytes += u64::from(f.len);
            }
        })
        .unwrap();
    }
}

#[test]
fn xbot_drives_over_a_serial_pty_against_chassisd_sim_and_reconnects_after_a_hang_up() {
    let mut env = Env::new("xbot-pty");
    let n = name("xb");
    let link = env.dir.join("xbot");
    // A real XBot's wheel separation must be measured: give the simulated board's.
    let (sim, mut robot) = env.xbot_over_pty(&n, &link, UP);
    let mut teleop = robot.source("teleop").unwrap();
    let peak = drive(
        &mut robot,
        &mut teleop,
        VelocityRequest::twist(0.4, 0.3),
        Duration::from_secs(2),
    );
    assert!(peak > 0.3, "peak {peak} m/s over the pty\n{}", env.logs());
    let s = state(&mut robot);
    assert!(s.odometry.x_m > 0.3, "pose x {}", s.odometry.x_m);
    assert!(s.odometry.yaw_rad > 0.2, "yaw {}", s.odometry.yaw_rad);
    assert!(s.is_valid(Group::Imu) && s.is_valid(Group::Ranges));
    assert_eq!(s.link.rx_bad_checksum + s.link.rx_decode_errors, 0);

    // Garbage on the line: every byte of it counted, every good report on the wire decoded,
    // still driving. The reports on the wire and the service's counters are compared at quiet
    // moments (a short injected silence of the chassis), like the storms of the fault matrix.
    let tap = robot.frames(2048).unwrap();
    let go = VelocityRequest::twist(0.4, 0.0);
    let mut wire = TapBytes::default();
    let before = quiet_moment(&mut robot, &mut teleop, go, || wire.drain(&tap));
    wire.rx_bytes = 0;
    const GARBAGE: u64 = 3000;
    let out = env.chassis(&["sim", "--name", &n, "garbage", &GARBAGE.to_string()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let end = Instant::now() + Duration::from_secs(1);
    let mut peak = 0.0f32;
    while Instant::now() < end {
        teleop.send(go).unwrap();
        wire.drain(&tap);
        if let Ok(Some(s)) = robot.wait_state(Duration::from_millis(20)) {
            peak = peak.max(s.motion.linear_mps.abs());
        }
    }
    let after = quiet_moment(&mut robot, &mut teleop, go, || wire.drain(&tap));
    let discarded = after.link.rx_bytes_discarded - before.link.rx_bytes_discarded;
    let decoded = after.link.rx_frames - before.link.rx_frames;
    // Every byte read is on the tap: what was not discarded is whole 75-byte reports.
    let good_bytes = wire.rx_bytes - discarded;
    eprintln!(
        "garbage {GARBAGE} bytes: {} bytes read, {discarded} discarded, {decoded} reports \
         decoded of {} good bytes; tap gaps {}; peak {peak:.2} m/s",
        wire.rx_bytes, good_bytes, wire.lost
    );
    assert_eq!(wire.lost, 0, "the tap lost frames");
    assert_eq!(discarded, GARBAGE, "garbage bytes counted");
    assert_eq!(good_bytes % XBOT_REPORT_BYTES, 0, "a report was cut");
    assert!(decoded > 0, "no report during the garbage");
    assert_eq!(
        decoded,
        good_bytes / XBOT_REPORT_BYTES,
        "good reports on the wire vs decoded"
    );
    assert!(peak > 0.3, "peak {peak} m/s during the garbage");

    let hang_up = HangUp {
        rank: 210,
        fault: "serial line hang-up (XBot over a pty)",
        injection: "SIGKILL of `chassisd sim --bus pty:…` mid-drive, restarted",
        end: "line",
        above_mps: 0.2,
        source: "teleop",
        suite: "serial",
        test: "xbot_drives_over_a_serial_pty_against_chassisd_sim_and_reconnects_after_a_hang_up",
    };
    let (figures, back) = hang_up.run(
        (&mut env, &mut robot),
        (sim, "xbot", &n),
        (Line::Serial, &link),
        |zero| {
            let vx = if zero { 0.0 } else { 0.4 };
            teleop.send(VelocityRequest::twist(vx, 0.0)).unwrap();
        },
    );
    assert!(
        back.is_some(),
        "no motion after the zero that followed the reconnection, or the robot did not stand \
         before it\n{}",
        env.logs()
    );
    assert!(state(&mut robot).link.bus_reconnects >= 1);
    figures.finish();
}

fn nmea(body: &str) -> String {
    let checksum = body.bytes().fold(0u8, |c, b| c ^ b);
    format!("${body}*{checksum:02X}\r\n")
}

#[test]
fn the_gps_receiver_feeds_the_fix_into_state_and_no_fix_is_reported_as_such() {
    let mut env = Env::new("gps");
    let n = name("gps");
    let pty = nix::pty::openpty(None, None).unwrap();
    let slave_path = nix::unistd::ttyname(pty.slave.as_fd()).unwrap();
    let gps = format!("serial:{}", slave_path.display());
    env.serve("xbot", &n, &["--gps", &gps, "--no-safety-monitor"]);
    let mut robot = env.robot(&n, UP);
    let mut master = std::fs::File::from(pty.master);
    let fix = nmea("GPGGA,092750.000,5321.6802,N,00630.3372,W,1,8,1.03,61.7,M,55.2,M,,");
    let got_fix = wait_for(Duration::from_secs(5), || {
        master.write_all(fix.as_bytes()).unwrap();
        let s = state(&mut robot);
        s.is_valid(Group::Gps) && s.gps.has_fix()
    });
    assert!(got_fix.is_some(), "no fix in state\n{}", env.logs());
    let s = state(&mut robot);
    assert!(
        (s.gps.latitude_deg - 53.361_336).abs() < 1e-5,
        "{}",
        s.gps.latitude_deg
    );
    assert!(
        (s.gps.longitude_deg + 6.505_62).abs() < 1e-5,
        "{}",
        s.gps.longitude_deg
    );
    assert_eq!((s.gps.fix_quality, s.gps.satellites), (1, 8));

    let no_fix = nmea("GPGGA,092751.000,,,,,0,0,,,M,,M,,");
    let lost = wait_for(Duration::from_secs(5), || {
        master.write_all(no_fix.as_bytes()).unwrap();
        !state(&mut robot).gps.has_fix()
    });
    assert!(lost.is_some(), "no-fix not reported\n{}", env.logs());
    let s = state(&mut robot);
    assert_eq!(
        (s.gps.latitude_deg, s.gps.longitude_deg),
        (0.0, 0.0),
        "no fix is not (0, 0)"
    );
    // A broken sentence is dropped and logged; the stream goes on.
    master.write_all(b"$GPGGA,garbage*00\r\n").unwrap();
    master.write_all(fix.as_bytes()).unwrap();
    assert!(wait_for(Duration::from_secs(5), || state(&mut robot).gps.has_fix()).is_some());
}

#[test]
fn scout_mini_drives_on_its_simulated_chassis_with_checksums_checked_both_ways() {
    let (env, n, mut robot) =
        Env::serving("scout", ("sm", "scout-mini"), &["--no-safety-monitor"], UP);
    let mut teleop = robot.source("teleop").unwrap();
    let peak = drive(
        &mut robot,
        &mut teleop,
        VelocityRequest::twist(0.52, 0.0),
        Duration::from_secs(2),
    );
    assert!(peak > 0.45, "peak {peak}");
    let s = state(&mut robot);
    // 0.52 m/s is 10.4 % of the 5 m/s full scale: 10 % goes on the wire.
    assert!(
        (s.command.linear_mps - 0.5).abs() < 1e-6,
        "echo {}",
        s.command.linear_mps
    );
    assert_ne!(s.command.clamp_flags & ClampFlags::QUANTISED, 0);
    let out = env.chassis(&["sim", "--name", &n, "bad-checksums", "50"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    drive(
        &mut robot,
        &mut teleop,
        VelocityRequest::twist(0.5, 0.0),
        Duration::from_millis(500),
    );
    assert_eq!(state(&mut robot).link.rx_bad_checksum, 50);
    let lights = env.chassis(&[
        "control",
        "--name",
        &n,
        "lights",
        "custom",
        "--brightness",
        "40",
    ]);
    assert!(
        lights.status.success(),
        "{}",
        String::from_utf8_lossy(&lights.stderr)
    );
    let shown = wait_for(Duration::from_secs(2), || {
        let s = state(&mut robot);
        s.lights.control_enabled == 1 && s.lights.front_brightness_pct == 40
    });
    assert!(shown.is_some(), "light state not reported\n{}", env.logs());
}
