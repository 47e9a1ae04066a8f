//! Scenario tests: [`XbotDriver`] against [`XbotSim`] through [`Pair`], on simulated time.
//!
//! Every scenario is deterministic: the wire has a fixed 250 µs latency, the garbage is from a
//! fixed-seed generator, and the clock jumps from deadline to deadline.

use std::f64::consts::PI;
use std::time::Duration;

use chassis_interfaces::{ClampFlags, Group, LinkFlags, Velocity};

use super::{Frame, StreamParser, XbotDriver, XbotSim};
use crate::Direction;
use crate::command::Command;
use crate::driver::{Driver, DriverConfig, DriverEvent, Level, WireItem};
use crate::firmware::{Firmware, Injection};
use crate::pair::Pair;
use crate::time::Timestamp;
use crate::xbot::XbotProfile;
use crate::xbot::test_support::{close, max_per_second, ms, p, twist};

type XbotPair = Pair<XbotDriver, XbotSim>;

const T0: Timestamp = Timestamp::from_millis(10_000);
const LATENCY: Duration = Duration::from_micros(250);

fn with_separation() -> XbotProfile {
    XbotProfile {
        wheel_separation_m: Some(0.45),
        ..p()
    }
}

fn pair_of(profile: XbotProfile, sim: impl FnOnce(XbotSim) -> XbotSim) -> XbotPair {
    let driver = XbotDriver::new(profile.clone(), DriverConfig::default(), T0);
    let firmware = sim(XbotSim::new(profile, T0));
    let mut pair = Pair::new(driver, firmware, T0);
    pair.latency = LATENCY;
    pair
}

fn pair() -> XbotPair {
    pair_of(p(), |s| s)
}

/// Every frame the driver put on the wire while recording, decoded.
fn to_chassis(pair: &XbotPair) -> Vec<(Timestamp, Frame)> {
    let profile = pair.driver.profile().clone();
    pair.log()
        .iter()
        .filter(|r| r.direction == Direction::ToChassis)
        .map(|r| {
            let WireItem::Bytes(bytes) = &r.item else {
                panic!("CAN from the XBot driver");
            };
            let mut parser = StreamParser::new();
            parser.push(bytes);
            (r.at, parser.next_frame(&profile).unwrap().unwrap())
        })
        .collect()
}

fn velocity_frames(pair: &XbotPair) -> Vec<(Timestamp, super::VelocityCommand)> {
    to_chassis(pair)
        .into_iter()
        .filter_map(|(t, f)| match f {
            Frame::Velocity(v) => Some((t, v)),
            _ => None,
        })
        .collect()
}

/// Runs until the board drives again: powered, and its true speed has risen 0.01 m/s above its
/// lowest since now. Returns that time.
fn motion_resumes(pair: &mut XbotPair, limit: Duration) -> Option<Timestamp> {
    let mut lowest = f64::INFINITY;
    pair.run_until_true(limit, |p| {
        let v = p.firmware.truth().linear_mps;
        lowest = lowest.min(v);
        p.firmware.is_powered() && v > lowest + 0.01
    })
}

/// A fixed-seed byte generator (xorshift), for garbage.
struct Noise(u64);

impl Noise {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    /// 1-40 random bytes; one chunk in three ends in a false start of a frame.
    fn garbage(&mut self) -> Vec<u8> {
        let len = 1 + (self.next() % 40) as usize;
        let mut bytes: Vec<u8> = (0..len).map(|_| self.next() as u8).collect();
        match self.next() % 6 {
            0 => bytes.extend([0xAA, 0x55, 0x47, 0x10, 0x01]),
            1 => bytes.extend([0xAA, 0x55]),
            2 => bytes.push(0xAA),
            _ => {}
        }
        bytes
    }
}

// ---------------------------------------------------------------------------------------------

#[test]
fn power_up_enable_drive_and_stop_agree_between_the_board_and_the_driver() {
    let mut pair = pair();
    assert!(
        !pair.firmware.is_powered(),
        "the board powers up with drive off"
    );
    pair.run_for(ms(100));
    assert!(pair.firmware.is_powered(), "the driver enabled it");
    let s = pair.driver.state();
    assert_eq!(s.system.power_enabled, 1);
    assert!(s.has_link_flag(LinkFlags::COMMAND_MODE));
    assert_eq!(s.link.rx_frames, 5, "reports at 0, 20, 40, 60, 80 ms");
    assert!(
        close(s.system.battery_voltage_v.into(), 25.92, 0.005),
        "{:?}",
        s.system
    );

    pair.set_command(twist(0.8, 0.0, 0.3));
    pair.run_for(ms(5000));
    // The report sent now reaches the driver 250 µs later.
    pair.run_for(ms(1));
    let t = pair.firmware.truth();
    let s = *pair.driver.state();
    assert!(close(t.linear_mps, 0.8, 0.005), "{t:?}");
    assert!(close(t.angular_radps, 0.3, 0.005), "{t:?}");
    assert!(
        close(s.motion.linear_mps.into(), t.linear_mps, 0.01),
        "{:?}",
        s.motion
    );
    assert!(
        close(s.motion.angular_radps.into(), t.angular_radps, 0.005),
        "gyro z"
    );
    let travel = pair.firmware.wheel_travel_m();
    assert!(
        close(s.odometry.left_distance_m, travel[0], 0.001),
        "{:?}",
        s.odometry
    );
    assert!(close(s.odometry.right_distance_m, travel[1], 0.001));
    assert!(s.odometry.left_distance_m > 3.0 && s.odometry.right_distance_m > 3.0);
    assert_eq!(s.command.linear_mps, 0.8);
    assert_eq!(s.command.clamp_flags, 0);
    assert!(
        s.motors[0].current_a > 1.0 && s.motors[1].current_a > 1.0,
        "{:?}",
        s.motors
    );

    pair.set_command(Velocity::ZERO);
    pair.run_for(ms(2000));
    let t = pair.firmware.truth();
    assert!(
        t.linear_mps.abs() < 1e-3 && t.angular_radps.abs() < 1e-3,
        "{t:?}"
    );
    assert!(pair.driver.state().motion.linear_mps.abs() < 0.005);
    assert_eq!(pair.firmware.heartbeat_timeouts(), 0);
    assert_eq!(pair.stalls, 0);
}

#[test]
fn a_heartbeat_gap_longer_than_500_ms_stops_the_board_and_driving_resumes_after() {
    let mut pair = pair();
    pair.set_command(twist(0.5, 0.0, 0.0));
    pair.record = true;
    pair.run_for(ms(3000));
    assert!(close(pair.firmware.truth().linear_mps, 0.5, 1e-3));

    pair.cut = true;
    let cut_at = pair.now();
    let last_heartbeat = velocity_frames(&pair).last().unwrap().0;
    let timed_out = pair
        .run_until_true(ms(600), |p| p.firmware.heartbeat_timeouts() == 1)
        .unwrap();
    assert_eq!(
        timed_out,
        last_heartbeat + LATENCY + ms(500) + Duration::from_nanos(1),
        "500 ms after the last 0x03 the board sets speed 0"
    );
    pair.run_until(cut_at + ms(600));
    let v = pair.firmware.truth().linear_mps;
    let decay = (-pair.now().secs_since(timed_out) / XbotSim::DEFAULT_SPEED_TIME_CONSTANT_S).exp();
    assert!(v <= 0.5 * decay + 1e-3, "{v}: slowing to a stop");
    assert!(pair.driver.state().has_link_flag(LinkFlags::CHASSIS_SILENT));
    assert!(
        pair.firmware.is_powered(),
        "a heartbeat timeout is no power-off"
    );

    pair.cut = false;
    let back = pair.now();
    let moving = motion_resumes(&mut pair, ms(1000)).unwrap();
    assert!(
        moving.saturating_since(back) < ms(100),
        "{:?}",
        moving.saturating_since(back)
    );
    pair.run_for(ms(2000));
    assert!(close(pair.firmware.truth().linear_mps, 0.5, 1e-3));
    assert!(!pair.driver.state().has_link_flag(LinkFlags::CHASSIS_SILENT));
}

#[test]
fn a_board_reboot_mid_drive_is_recovered_within_100_ms_of_the_board_talking_again() {
    let mut pair = pair();
    pair.set_command(twist(0.6, 0.0, 0.0));
    pair.run_for(ms(3000));
    let counts_before = pair.driver.state().motors[0].position_counts;
    let distance_before = pair.driver.state().odometry.left_distance_m;
    pair.take_events();
    pair.record = true;

    assert!(pair.inject(Injection::Reboot));
    let reboot = pair.now();
    let sent = pair.firmware.reports_sent();
    let talking = pair
        .run_until_true(ms(2000), |p| p.firmware.reports_sent() > sent)
        .unwrap();
    assert_eq!(talking, reboot + XbotSim::DEFAULT_BOOT_TIME);
    assert!(!pair.firmware.is_powered());
    let moving = motion_resumes(&mut pair, ms(1000)).unwrap();
    let delay = moving.saturating_since(talking);
    assert!(
        delay < ms(100),
        "motion resumed {delay:?} after the board talked again"
    );

    let enable = to_chassis(&pair)
        .into_iter()
        .find(|(t, f)| *t > reboot + ms(300) && matches!(f, Frame::Power(p) if p.enable))
        .unwrap();
    assert_eq!(
        enable.0,
        talking + LATENCY,
        "power enable at the first report back"
    );
    let events = pair.take_events();
    assert!(events.iter().any(|e| matches!(
        e,
        DriverEvent::Notice { level: Level::Warn, message } if message.contains("rebooted")
    )));
    pair.run_for(ms(2000));
    assert!(close(pair.firmware.truth().linear_mps, 0.6, 1e-3));
    let s = pair.driver.state();
    assert!(
        s.motors[0].position_counts >= counts_before,
        "the counts carry on"
    );
    assert!(s.odometry.left_distance_m > distance_before + 1.0);
    assert_eq!(pair.firmware.truth().boots, 1);
}

#[test]
fn a_reboot_shorter_than_the_silence_timeout_is_caught_by_the_encoder_jump() {
    let mut pair = pair_of(p(), |s| s.with_boot_time(ms(40)));
    pair.set_command(twist(0.6, 0.0, 0.0));
    pair.run_for(ms(3000));
    pair.take_events();
    assert!(pair.inject(Injection::Reboot));
    let reboot = pair.now();
    let moving = motion_resumes(&mut pair, ms(1000)).unwrap();
    // Talking again after 40 ms; the first report shows counters back at 0.
    let delay = moving.saturating_since(reboot + ms(40));
    assert!(delay < ms(100), "{delay:?}");
    assert!(!pair.driver.state().has_link_flag(LinkFlags::CHASSIS_SILENT));
    let events = pair.take_events();
    assert!(
        events.iter().any(|e| matches!(
            e,
            DriverEvent::Notice { message, .. } if message.contains("jumped")
        )),
        "{events:?}"
    );
}

#[test]
fn a_bad_checksum_storm_loses_no_good_report() {
    let mut pair = pair();
    pair.set_command(twist(0.4, 0.0, 0.0));
    // Two reports in five corrupted for 10 s, then 10 in a row (a 200 ms gap) every 2 s.
    for _ in 0..100 {
        pair.inject(Injection::BadChecksums(2));
        pair.run_for(ms(100));
    }
    assert!(!pair.driver.state().has_link_flag(LinkFlags::CHASSIS_SILENT));
    assert_eq!(pair.firmware.reports_corrupted(), 200);
    for _ in 0..5 {
        pair.inject(Injection::BadChecksums(10));
        pair.run_for(ms(2000));
    }
    // Off the report grid, so nothing is still on the wire.
    pair.run_for(ms(5));
    let link = pair.driver.state().link;
    let fw = &pair.firmware;
    assert_eq!(fw.reports_corrupted(), 250);
    assert_eq!(link.rx_frames, fw.reports_sent() - fw.reports_corrupted());
    assert_eq!(link.rx_bad_checksum, fw.reports_corrupted());
    assert_eq!(link.rx_decode_errors, 0);
    assert_eq!(link.rx_bytes_discarded, 250 * 75);
    assert!(
        close(fw.truth().linear_mps, 0.4, 1e-3),
        "the robot drove on"
    );
    assert_eq!(fw.heartbeat_timeouts(), 0);
}

#[test]
fn garbage_storms_at_10_100_and_1000_chunks_a_second_lose_no_good_report() {
    for rate in [10u64, 100, 1000] {
        let mut pair = pair();
        let mut noise = Noise(0x9E37_79B9_7F4A_7C15 ^ rate);
        pair.set_command(twist(0.5, 0.0, 0.2));
        let period = Duration::from_micros(1_000_000 / rate);
        let mut garbage_bytes = 0u64;
        let until = pair.now() + ms(5000);
        while pair.now() < until {
            let chunk = noise.garbage();
            garbage_bytes += chunk.len() as u64;
            assert!(pair.inject(Injection::Garbage(chunk)));
            pair.run_for(period);
        }
        pair.run_for(ms(25));
        let link = pair.driver.state().link;
        assert_eq!(link.rx_frames, pair.firmware.reports_sent(), "rate {rate}");
        assert_eq!(link.rx_bytes_discarded, garbage_bytes, "rate {rate}");
        assert!(
            link.rx_decode_errors + link.rx_bad_checksum > 0,
            "rate {rate}: false starts"
        );
        assert!(!pair.driver.state().has_link_flag(LinkFlags::CHASSIS_SILENT));
        assert!(
            close(pair.firmware.truth().linear_mps, 0.5, 1e-3),
            "rate {rate}"
        );
    }
}

#[test]
fn the_heartbeat_goes_out_every_125_ms_except_for_command_changes() {
    let mut pair = pair();
    pair.record = true;
    // 3400: a change at 3100 would find the second's change slots taken (1400 and the stop at
    // 2222) and ride the 3125 heartbeat instead.
    let changes = [(333, 0.3f32), (1400, 0.5), (2222, 0.0), (3400, 0.2)];
    for (at, vx) in changes {
        pair.run_until(T0 + ms(at));
        pair.set_command(twist(vx, 0.0, 0.0));
    }
    pair.run_until(T0 + ms(5000));
    let frames = velocity_frames(&pair);
    let mut extra = Vec::new();
    for (i, (t, v)) in frames.iter().enumerate() {
        let offset = t.saturating_since(T0);
        if offset.as_nanos() % ms(125).as_nanos() != 0 {
            assert!(
                i > 0 && frames[i - 1].1 != *v,
                "an off-grid frame must be a change"
            );
            extra.push(offset);
        }
    }
    assert_eq!(extra, vec![ms(333), ms(1400), ms(2222), ms(3400)]);
    for k in 0..=40u64 {
        assert!(
            frames.iter().any(|(t, _)| *t == T0 + ms(125 * k)),
            "slot {k}"
        );
    }
    assert_eq!(frames.len(), 41 + 4);
    assert_eq!(pair.firmware.heartbeat_timeouts(), 0);
}

#[test]
fn a_command_changing_every_millisecond_never_exceeds_10_frames_a_second() {
    for alternate_with_stops in [false, true] {
        let mut pair = pair();
        pair.record = true;
        for i in 0..5000u32 {
            let vx = if alternate_with_stops && i % 2 == 1 {
                0.0
            } else {
                0.2 + 0.05 * (i % 9) as f32
            };
            pair.set_command(twist(vx, 0.0, 0.0));
            pair.run_for(ms(1));
        }
        let frames = velocity_frames(&pair);
        let times: Vec<_> = frames.iter().map(|(t, _)| *t).collect();
        let worst = max_per_second(&times);
        assert!(worst <= 10, "{worst} frames in one second");
        assert!(worst >= 9, "heartbeats and some changes: {worst}");
        assert_eq!(pair.firmware.heartbeat_timeouts(), 0);
        // The board obeys the latest command within a heartbeat period.
        let last = frames.last().unwrap();
        assert!(pair.now().saturating_since(last.0) <= ms(125));
    }
}

#[test]
fn limits_clamp_2_mps_to_1_5_and_flag_a_lateral_request() {
    let mut pair = pair();
    pair.set_command(twist(2.0, 0.0, 0.0));
    pair.run_for(ms(5000));
    let s = *pair.driver.state();
    assert_eq!(s.command.linear_mps, 1.5);
    assert_eq!(s.command.clamp_flags, ClampFlags::LINEAR_LIMIT);
    assert!(close(pair.firmware.truth().linear_mps, 1.5, 1e-3));
    assert!(
        close(s.motion.linear_mps.into(), 1.5, 0.01),
        "{:?}",
        s.motion
    );

    pair.set_command(twist(0.3, 0.4, 0.0));
    pair.run_for(ms(3000));
    let s = *pair.driver.state();
    assert_eq!((s.command.linear_mps, s.command.lateral_mps), (0.3, 0.0));
    assert_eq!(s.command.clamp_flags, ClampFlags::LATERAL_UNSUPPORTED);
    let t = pair.firmware.truth();
    assert!(
        close(t.linear_mps, 0.3, 1e-3) && t.lateral_mps == 0.0,
        "{t:?}"
    );

    pair.set_command(twist(0.0, 0.0, 5.0));
    pair.run_for(ms(3000));
    let s = *pair.driver.state();
    assert_eq!(s.command.clamp_flags, ClampFlags::ANGULAR_LIMIT);
    assert!(close(pair.firmware.truth().angular_radps, PI, 0.01));
}

#[test]
fn the_lift_and_the_servos_reach_their_targets() {
    let mut pair = pair();
    let outcome = pair.control(&Command::Lift {
        enable: true,
        position_pct: 60.0,
    });
    assert_eq!(outcome.status(), chassis_interfaces::ControlStatus::OK);
    pair.run_for(ms(3000));
    let lift = pair.driver.state().lift;
    assert_eq!((lift.enabled, lift.target_pct), (1, 60.0));
    assert!(close(lift.encoder_counts as f64, 3_000.0, 25.0), "{lift:?}");
    assert_eq!(lift.current_a, 0.6, "moving");
    pair.run_for(ms(4000));
    let lift = pair.driver.state().lift;
    assert_eq!(pair.firmware.lift_pct(), (60.0, 60.0));
    assert_eq!((lift.encoder_counts, lift.current_a), (6_000, 0.1));

    pair.control(&Command::Servos {
        pan_rad: 0.5,
        tilt_rad: -0.3,
    });
    pair.run_for(ms(10));
    let (pan, tilt) = pair.firmware.servos_rad();
    let pt = pair.driver.state().pan_tilt;
    assert!(close(pan, pt.pan_rad.into(), 1e-6) && close(tilt, pt.tilt_rad.into(), 1e-6));
    assert!(close(pan, 29f64.to_radians(), 1e-9) && close(tilt, (-17f64).to_radians(), 1e-9));
}

#[test]
fn obstacles_show_up_in_the_ranges_the_driver_publishes() {
    let mut pair = pair();
    pair.set_command(twist(0.5, 0.0, 0.0));
    pair.run_for(ms(1000));
    assert_eq!(pair.driver.state().ranges.ultrasonic_m, [6.0; 3]);
    assert_eq!(pair.driver.state().ranges.ir_m, [0.8; 3]);
    pair.inject(Injection::ObstacleAhead(Some(0.35)));
    pair.inject(Injection::ObstacleBehind(Some(0.12)));
    pair.run_for(ms(25));
    let ranges = pair.driver.state().ranges;
    assert_eq!(ranges.ultrasonic_m, [0.404, 0.35, 0.404]);
    assert_eq!(ranges.ir_m, [0.139, 0.12, 0.139]);
    assert!(pair.driver.state().is_valid(Group::Ranges));
    assert!(
        pair.firmware.truth().linear_mps > 0.45,
        "the board itself does not stop"
    );
    pair.inject(Injection::ObstacleAhead(None));
    pair.run_for(ms(25));
    assert_eq!(pair.driver.state().ranges.ultrasonic_m, [6.0; 3]);
}

#[test]
fn with_a_wheel_separation_the_driver_pose_tracks_the_true_pose() {
    let mut pair = pair_of(with_separation(), |s| s);
    assert_eq!(pair.firmware.wheel_separation_m(), 0.45);
    pair.set_command(twist(0.5, 0.0, 0.4));
    pair.run_for(ms(10_000));
    pair.set_command(twist(0.8, 0.0, 0.0));
    pair.run_for(ms(5_000));
    pair.set_command(twist(0.0, 0.0, -1.0));
    pair.run_for(ms(3_000));
    pair.run_for(ms(1));
    let t = pair.firmware.truth();
    let s = *pair.driver.state();
    let o = s.odometry;
    assert!(
        close(o.x_m, t.x_m, 0.02) && close(o.y_m, t.y_m, 0.02),
        "{o:?} vs {t:?}"
    );
    assert!(
        crate::driver::wrap_angle(o.yaw_rad - t.yaw_rad).abs() < 0.01,
        "{o:?} vs {t:?}"
    );
    assert!(t.x_m.hypot(t.y_m) > 3.0, "{t:?}");
    assert!(close(s.motion.angular_radps.into(), t.angular_radps, 0.01));
    assert!(s.is_valid(Group::Pose));
}

#[test]
fn without_a_wheel_separation_distances_and_speeds_are_published_but_no_pose() {
    let mut pair = pair();
    pair.set_command(twist(0.5, 0.0, 0.4));
    pair.run_for(ms(10_000));
    pair.run_for(ms(1));
    let t = pair.firmware.truth();
    let s = *pair.driver.state();
    assert!(!s.is_valid(Group::Pose));
    assert_eq!(
        (s.odometry.x_m, s.odometry.y_m, s.odometry.yaw_rad),
        (0.0, 0.0, 0.0)
    );
    let travel = pair.firmware.wheel_travel_m();
    assert!(close(s.odometry.left_distance_m, travel[0], 0.001));
    assert!(close(s.odometry.right_distance_m, travel[1], 0.001));
    // 0.5 m/s ± 0.4 rad/s × 0.225 m.
    assert!(
        close(s.motion.wheel_mps[0].into(), 0.41, 0.005),
        "{:?}",
        s.motion
    );
    assert!(
        close(s.motion.wheel_mps[1].into(), 0.59, 0.005),
        "{:?}",
        s.motion
    );
    assert!(close(s.motion.linear_mps.into(), t.linear_mps, 0.005));
    assert!(
        close(s.motion.angular_radps.into(), t.angular_radps, 0.005),
        "the gyro"
    );
}

#[test]
fn a_flood_of_reports_is_decoded_without_loss() {
    let mut pair = pair();
    pair.set_command(twist(0.3, 0.0, 0.0));
    pair.inject(Injection::Flood { frames_per_s: 500 });
    pair.run_for(ms(5000));
    pair.run_for(ms(3));
    let link = pair.driver.state().link;
    assert!(
        pair.firmware.reports_sent() >= 5 * (50 + 153),
        "{}",
        pair.firmware.reports_sent()
    );
    assert_eq!(link.rx_frames, pair.firmware.reports_sent());
    assert_eq!(link.rx_decode_errors + link.rx_bad_checksum, 0);
    assert!(close(pair.firmware.truth().linear_mps, 0.3, 1e-3));
    assert!(close(
        pair.driver.state().motion.linear_mps.into(),
        0.3,
        0.02
    ));
}

#[test]
fn power_disabled_on_request_stays_off_through_a_reboot() {
    let mut pair = pair();
    pair.set_command(twist(0.5, 0.0, 0.0));
    pair.run_for(ms(2000));
    let outcome = pair.control(&Command::Power { enable: false });
    assert_eq!(outcome.status(), chassis_interfaces::ControlStatus::OK);
    pair.record = true;
    pair.run_for(ms(1000));
    assert!(!pair.firmware.is_powered());
    assert!(pair.firmware.truth().linear_mps.abs() < 1e-3);
    assert!(pair.inject(Injection::Reboot));
    pair.run_for(ms(3000));
    assert!(!pair.firmware.is_powered());
    let frames = to_chassis(&pair);
    assert!(
        !frames.iter().any(|(_, f)| matches!(f, Frame::Power(_))),
        "{frames:?}"
    );
    assert!(
        frames
            .iter()
            .all(|(_, f)| !matches!(f, Frame::Velocity(v) if v.linear_x_mps != 0.0))
    );
    assert_eq!(
        pair.driver.state().command.clamp_flags,
        ClampFlags::CHASSIS_NOT_READY
    );

    pair.control(&Command::Power { enable: true });
    pair.run_for(ms(3000));
    assert!(close(pair.firmware.truth().linear_mps, 0.5, 1e-3));
}

#[test]
fn a_long_run_of_2000_simulated_seconds_stays_consistent() {
    let mut pair = pair_of(with_separation(), |s| s);
    for k in 0..200u32 {
        let vx = 0.2 + 0.1 * (k % 8) as f32;
        let wz = if k % 3 == 0 { 0.3 } else { -0.1 };
        pair.set_command(twist(vx, 0.0, wz));
        pair.run_for(ms(10_000));
    }
    pair.run_for(ms(1));
    let link = pair.driver.state().link;
    assert_eq!(pair.firmware.reports_sent(), 100_001);
    assert_eq!(link.rx_frames, 100_001);
    assert_eq!(pair.stalls, 0);
    assert_eq!(pair.firmware.heartbeat_timeouts(), 0);
    // Heartbeats on a 125 ms grid (16 001) plus at most one change frame per command.
    let tx = link.tx_frames;
    assert!((16_001 + 1..=16_001 + 1 + 200).contains(&tx), "{tx}");
    let travel = pair.firmware.wheel_travel_m();
    let o = pair.driver.state().odometry;
    assert!(
        close(o.left_distance_m, travel[0], 0.001) && close(o.right_distance_m, travel[1], 0.001)
    );
    assert!(pair.firmware.truth().soc_pct < 100.0 && pair.firmware.truth().soc_pct > 50.0);
}
