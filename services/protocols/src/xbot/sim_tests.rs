//! The simulated XBot board alone, fed frames through the codec on simulated time.

use std::time::Duration;

use chassis_interfaces::ControlMode;
use proptest::prelude::*;

use super::XbotSim;
use crate::driver::Rx;
use crate::firmware::{Firmware, Injection};
use crate::sim_bench::BenchFirmware;
use crate::time::Timestamp;
use crate::xbot::XbotProfile;
use crate::xbot::test_support::{arbitrary_reads, close, ms, p};
use crate::xbot::{
    Frame, LiftCommand, PowerCommand, SensorReport, ServoCommand, StreamParser, VelocityCommand,
};

const T0: Timestamp = Timestamp::from_millis(1_000);

fn velocity(vx: f64, vy: f64, wz: f64) -> VelocityCommand {
    VelocityCommand {
        linear_x_mps: vx,
        linear_y_mps: vy,
        angular_z_radps: wz,
    }
}

/// The board on simulated time, with an optional 125 ms 0x03 heartbeat from "the computer".
type Bench = crate::sim_bench::Bench<XbotSim>;

impl BenchFirmware for XbotSim {
    type Item = Vec<u8>;
    type Command = VelocityCommand;
    type Profile = XbotProfile;
    const HEARTBEAT_PERIOD: Duration = Duration::from_millis(125);

    fn bench_profile(&self) -> &XbotProfile {
        self.profile()
    }

    fn send_heartbeat(bench: &mut Bench, command: VelocityCommand) {
        bench.send(Frame::Velocity(command));
    }
}

impl Bench {
    fn new() -> Self {
        Self::with(XbotSim::new(p(), T0), T0)
    }

    /// Drive power enabled.
    fn powered() -> Self {
        let mut b = Self::new();
        b.send(Frame::Power(PowerCommand { enable: true }));
        b
    }

    fn send(&mut self, frame: Frame) {
        let bytes = frame.encode(&self.profile).unwrap();
        self.send_raw(&bytes);
    }

    fn send_raw(&mut self, bytes: &[u8]) {
        self.sim.handle_rx(self.now, Rx::Bytes(bytes));
        self.drain();
    }

    /// Every report decoded from the byte stream, with the time its last byte was sent, and the
    /// number of rejected candidates.
    fn decoded(&self) -> (Vec<(Timestamp, SensorReport)>, u64) {
        let mut parser = StreamParser::new();
        let mut reports = Vec::new();
        for (t, bytes) in &self.sent {
            parser.push(bytes);
            while let Some(item) = parser.next_frame(&self.profile) {
                if let Ok(Frame::Sensor(r)) = item {
                    reports.push((*t, r));
                }
            }
        }
        (reports, parser.errors())
    }

    fn reports(&self) -> Vec<(Timestamp, SensorReport)> {
        self.decoded().0
    }

    fn last(&self) -> SensorReport {
        self.reports().last().unwrap().1
    }
}

#[test]
fn the_board_powers_up_with_drive_off_and_reports_every_20_ms() {
    let mut b = Bench::new();
    b.run_for(ms(999));
    let reports = b.reports();
    assert_eq!(reports.len(), 50);
    for (k, (t, r)) in reports.iter().enumerate() {
        assert_eq!(*t, T0 + ms(20 * k as u64));
        assert_eq!(u32::from(r.sensor_stamp_us), (20_000 * k as u32) % 65_536);
    }
    let r = b.last();
    assert_eq!(
        r.battery_voltage_v, 25.95,
        "26.0 V open-circuit less 1 A × 0.05 Ω"
    );
    assert_eq!(r.ultrasonic_m, [6.0; 3]);
    assert_eq!(r.ir_m, [0.8; 3]);
    assert_eq!(r.motor_current_a, [0.0; 4], "drive power is off");
    assert_eq!(r.encoder_counts, [0; 4]);
    assert!(close(r.accel_mps2[2], 9.806_65, 0.001), "{r:?}");
    assert_eq!((r.temperature_c, r.yaw_rad), (31.5, 0.0));
    let t = b.sim.truth();
    assert_eq!(t.control_mode, ControlMode::STANDBY);
    assert!(!b.sim.is_powered());
    assert_eq!(b.sim.servos_rad(), (0.0, 0.0), "90° / 90°: straight ahead");
}

#[test]
fn velocity_moves_nothing_until_power_is_enabled() {
    let mut b = Bench::new();
    b.heartbeat(Some(velocity(0.5, 0.0, 0.0)));
    b.run_for(ms(1000));
    assert_eq!(b.v(), 0.0);
    assert_eq!(
        b.sim.truth().commands_received,
        9,
        "0 ms to 1000 ms every 125 ms"
    );
    b.send(Frame::Power(PowerCommand { enable: true }));
    b.run_for(ms(2000));
    assert!(close(b.v(), 0.5, 1e-3), "{}", b.v());
    assert_eq!(b.sim.truth().control_mode, ControlMode::COMMAND);
}

#[test]
fn the_wheels_follow_a_first_order_response_and_the_encoders_count_8000_per_turn() {
    let mut b = Bench::powered();
    b.heartbeat(Some(velocity(1.0, 0.0, 0.0)));
    b.run_for(ms(200));
    // One time constant: 1 - 1/e.
    assert!(close(b.v(), 1.0 - (-1.0f64).exp(), 0.01), "{}", b.v());
    b.run_for(ms(2800));
    assert!(close(b.v(), 1.0, 1e-3));
    let t = b.sim.truth();
    // ∫(1 - e^(-t/τ)) dt over 3 s = 3 - 0.2·(1 - e^-15).
    assert!(close(t.x_m, 3.0 - 0.2, 0.01), "{t:?}");
    assert!(t.y_m.abs() < 1e-9 && t.yaw_rad.abs() < 1e-12);

    let (at, r) = *b.reports().last().unwrap();
    assert_eq!(at, b.now, "a report at 3 s");
    let metres = p().metres_per_count();
    assert_eq!(metres, std::f64::consts::PI * 0.2 / 8000.0);
    let expected = t.x_m / metres;
    let fl = f64::from(r.encoder_counts[0]);
    let fr = f64::from(r.encoder_counts[1]);
    assert!(close(fl, expected, 1.0), "{fl} vs {expected}");
    assert_eq!(fl, fr);
    assert_eq!(
        (r.encoder_counts[2], r.encoder_counts[3]),
        (0, 0),
        "two wheels only"
    );
    assert_eq!(
        r.motor_current_a,
        [1.8, 1.8, 0.0, 0.0],
        "1.5 A per m/s + 0.3 A"
    );
}

#[test]
fn a_turn_on_the_spot_shows_in_the_wheels_the_gyro_the_yaw_and_the_compass() {
    let mut b = Bench::powered();
    b.heartbeat(Some(velocity(0.0, 0.0, 0.5)));
    b.run_for(ms(3000));
    let t = b.sim.truth();
    assert!(close(t.angular_radps, 0.5, 1e-3), "{t:?}");
    assert!(t.x_m.abs() < 1e-9 && t.y_m.abs() < 1e-9);
    let w = b.sim.wheel_mps();
    assert!(
        close(w[0], -0.5 * 0.225, 1e-4) && close(w[1], 0.5 * 0.225, 1e-4),
        "{w:?}"
    );
    let r = b.last();
    let gyro_lsb = 0.015_213_984_694_731_4f64.to_radians();
    assert!(close(r.gyro_radps[2], 0.5, 2.0 * gyro_lsb), "{r:?}");
    assert!(
        close(r.yaw_rad, t.yaw_rad, 0.5 * 0.02 + 0.1f64.to_radians()),
        "{r:?} {t:?}"
    );
    let (sin, cos) = r.yaw_rad.sin_cos();
    assert!(close(r.mag_gauss[0], 0.3 * cos, 0.01) && close(r.mag_gauss[1], -0.3 * sin, 0.01));
    assert!(
        r.encoder_counts[0] > 60_000,
        "backwards from 0 wraps: {r:?}"
    );
}

#[test]
fn the_heartbeat_timeout_sets_the_speed_to_zero_after_500_ms_and_the_next_frame_drives_again() {
    let mut b = Bench::powered();
    b.heartbeat(Some(velocity(0.5, 0.0, 0.0)));
    b.run_for(ms(2000));
    b.heartbeat(None);
    let last = b.last_heartbeat.unwrap();
    b.run_for((last + ms(500)).saturating_since(b.now));
    assert_eq!(b.sim.heartbeat_timeouts(), 0, "500 ms is still in time");
    b.run_for(ms(1));
    assert_eq!(b.sim.heartbeat_timeouts(), 1);
    b.run_for(ms(1000));
    assert!(b.v().abs() < 0.01, "{}", b.v());
    assert!(b.sim.is_powered(), "a timeout is no power-off");
    b.heartbeat(Some(velocity(0.5, 0.0, 0.0)));
    b.run_for(ms(2000));
    assert!(close(b.v(), 0.5, 1e-3));
    assert_eq!(b.sim.heartbeat_timeouts(), 1);
}

#[test]
fn power_off_stops_the_wheels_and_a_fresh_command_is_needed_after_power_on() {
    let mut b = Bench::powered();
    b.heartbeat(Some(velocity(0.5, 0.0, 0.0)));
    b.run_for(ms(2000));
    b.send(Frame::Power(PowerCommand { enable: false }));
    b.run_for(ms(1000));
    assert!(b.v().abs() < 1e-3);
    assert_eq!(b.last().motor_current_a, [0.0; 4]);
    assert_eq!(b.sim.truth().control_mode, ControlMode::STANDBY);
    b.heartbeat(None);
    b.run_for(ms(100));
    b.send(Frame::Power(PowerCommand { enable: true }));
    b.run_for(ms(300));
    assert!(
        b.v().abs() < 1e-4,
        "the command given while unpowered was not kept"
    );
    b.heartbeat(Some(velocity(0.5, 0.0, 0.0)));
    b.run_for(ms(2000));
    assert!(close(b.v(), 0.5, 1e-3));
}

#[test]
fn the_sign_parameters_are_honoured_through_the_codec() {
    let flipped = XbotProfile {
        yaw_rate_left_positive: false,
        ..p()
    };
    let left_turn = Frame::Velocity(velocity(0.0, 0.0, 0.5));
    let bytes = left_turn.encode(&flipped).unwrap();
    assert_ne!(
        bytes,
        left_turn.encode(&p()).unwrap(),
        "the wire sign differs"
    );
    for (profile, expect_left) in [(flipped, true), (p(), false)] {
        let mut b = Bench::with(XbotSim::new(profile, T0), T0);
        b.send(Frame::Power(PowerCommand { enable: true }));
        for _ in 0..8 {
            b.send_raw(&bytes);
            b.run_for(ms(125));
        }
        assert_eq!(
            b.sim.truth().angular_radps > 0.1,
            expect_left,
            "{:?}",
            b.sim.truth()
        );
        assert_eq!(b.sim.truth().angular_radps < -0.1, !expect_left);
    }
}

#[test]
fn speeds_are_limited_to_1_5_mps_and_tiny_ones_are_not_executed() {
    let mut b = Bench::powered();
    b.heartbeat(Some(velocity(2.0, 0.0, 0.0)));
    b.run_for(ms(3000));
    assert!(close(b.v(), 1.5, 1e-3), "{}", b.v());
    b.heartbeat(Some(velocity(0.005, 0.0, 0.0)));
    b.run_for(ms(3000));
    assert!(b.v().abs() < 1e-5, "{}", b.v());
    // A fast turn keeps its shape: the outer wheel is held at 1.5 m/s.
    b.heartbeat(Some(velocity(1.5, 0.0, 1.0)));
    b.run_for(ms(3000));
    let w = b.sim.wheel_mps();
    assert!(close(w[1], 1.5, 1e-3), "{w:?}");
    assert!(
        close(w[0], 1.5 * (1.5 - 0.225) / (1.5 + 0.225), 1e-3),
        "{w:?}"
    );
    let t = b.sim.truth();
    assert!(close(t.angular_radps / t.linear_mps, 1.0 / 1.5, 1e-3));
}

#[test]
fn the_lift_moves_at_10_percent_per_second_and_reports_its_encoder_and_current() {
    let mut b = Bench::new();
    b.send(Frame::Lift(LiftCommand {
        enable: true,
        position_pct: 50.0,
    }));
    b.run_for(ms(2000));
    assert!(
        close(b.sim.lift_pct().0, 20.0, 1e-9),
        "{:?}",
        b.sim.lift_pct()
    );
    let r = b.last();
    assert_eq!(r.lift_current_a, 0.6);
    assert!(
        close(f64::from(r.lift_encoder_counts), 2_000.0, 1.0),
        "{r:?}"
    );
    b.run_for(ms(4000));
    assert_eq!(b.sim.lift_pct(), (50.0, 50.0));
    let r = b.last();
    assert_eq!((r.lift_encoder_counts, r.lift_current_a), (5_000, 0.1));

    b.send(Frame::Lift(LiftCommand {
        enable: false,
        position_pct: 0.0,
    }));
    b.run_for(ms(1000));
    assert_eq!(b.sim.lift_pct().0, 50.0, "a disabled lift stays");
    assert_eq!(b.last().lift_current_a, 0.0);
    b.send(Frame::Lift(LiftCommand {
        enable: true,
        position_pct: 0.0,
    }));
    b.run_for(ms(6000));
    assert_eq!(b.last().lift_encoder_counts, 0);
    assert_eq!(b.sim.lift_pct().0, 0.0);
}

#[test]
fn servos_take_the_commanded_angles_and_out_of_range_bytes_are_refused() {
    let mut b = Bench::new();
    b.send(Frame::Servos(ServoCommand {
        pan_rad: 0.5,
        tilt_rad: -0.2,
    }));
    let (pan, tilt) = b.sim.servos_rad();
    assert!(
        close(pan, 29f64.to_radians(), 1e-12),
        "whole degrees: {pan}"
    );
    assert!(close(tilt, -11f64.to_radians(), 1e-12), "{tilt}");
    // Pan 181°.
    b.send_raw(&crate::xbot::wrap_payload(&[0x05, 181, 90]).unwrap());
    assert_eq!(b.sim.truth().decode_errors, 1);
    assert!(close(b.sim.servos_rad().0, 29f64.to_radians(), 1e-12));
}

#[test]
fn obstacle_injections_show_in_the_ranges_and_do_not_stop_the_robot() {
    let mut b = Bench::powered();
    b.heartbeat(Some(velocity(0.5, 0.0, 0.0)));
    b.run_for(ms(2000));
    assert!(b.inject(Injection::ObstacleAhead(Some(0.4))));
    assert!(b.inject(Injection::ObstacleBehind(Some(0.1))));
    b.run_for(ms(100));
    let r = b.last();
    assert_eq!(r.ultrasonic_m, [0.462, 0.4, 0.462], "sides at d / cos 30°");
    assert_eq!(r.ir_m, [0.115, 0.1, 0.115]);
    assert!(
        close(b.v(), 0.5, 1e-3),
        "the board does not stop for obstacles"
    );
    assert!(b.inject(Injection::ObstacleAhead(None)));
    b.run_for(ms(40));
    assert_eq!(b.last().ultrasonic_m, [6.0; 3]);
    assert_eq!(b.last().ir_m, [0.115, 0.1, 0.115]);
    assert!(!b.inject(Injection::ObstacleAhead(Some(-1.0))));
    assert!(!b.inject(Injection::ObstacleBehind(Some(f64::NAN))));
    assert!(b.inject(Injection::ObstacleAhead(Some(100.0))));
    b.run_for(ms(40));
    assert_eq!(
        b.last().ultrasonic_m,
        [6.0; 3],
        "beyond the range reads nothing seen"
    );

    let bcd = XbotProfile {
        bcd_currents_and_ranges: true,
        ..p()
    };
    let mut b = Bench::with(XbotSim::new(bcd, T0), T0);
    b.run_for(ms(40));
    assert_eq!(
        b.last().ultrasonic_m,
        [0.999; 3],
        "four BCD digits of 0.1 cm"
    );
}

#[test]
fn a_lost_motor_driver_stops_drive_and_reads_zero_current() {
    let mut b = Bench::powered();
    b.heartbeat(Some(velocity(1.0, 0.0, 0.0)));
    b.run_for(ms(2000));
    assert!(b.inject(Injection::MotorDriverLoss {
        motor: 1,
        lost: true
    }));
    b.run_for(ms(1000));
    assert!(b.v().abs() < 1e-3);
    let r = b.last();
    assert_eq!(
        r.motor_current_a,
        [0.0, 0.3, 0.0, 0.0],
        "FR powered, holding"
    );
    assert!(b.inject(Injection::MotorDriverLoss {
        motor: 1,
        lost: false
    }));
    b.run_for(ms(2000));
    assert!(close(b.v(), 1.0, 1e-3), "not latched");
    for motor in [0, 3, 4, 5] {
        assert!(
            !b.inject(Injection::MotorDriverLoss { motor, lost: true }),
            "{motor}"
        );
    }
    let omni = XbotProfile { omni: true, ..p() };
    let mut b = Bench::with(XbotSim::new(omni, T0), T0);
    assert!(b.inject(Injection::MotorDriverLoss {
        motor: 4,
        lost: true
    }));
}

#[test]
fn the_battery_reads_in_bcd_and_drains_while_driving() {
    let mut b = Bench::powered();
    assert!(b.inject(Injection::Battery { soc_pct: 50.0 }));
    b.run_for(ms(100));
    assert_eq!(
        b.last().battery_voltage_v,
        24.42,
        "24.5 V less (1 A + 2 × 0.3 A) × 0.05 Ω"
    );
    assert!(b.inject(Injection::Battery { soc_pct: 100.0 }));
    b.heartbeat(Some(velocity(1.0, 0.0, 0.0)));
    b.run_for(ms(60_000));
    // About 1 A + 2 × 1.8 A for a minute out of 26 Ah.
    let used = 100.0 - b.sim.truth().soc_pct;
    assert!(close(used, 4.6 / 60.0 / 26.0 * 100.0, 0.01), "{used}");
}

#[test]
fn rc_and_bumper_do_not_exist_on_the_xbot() {
    let mut b = Bench::new();
    assert!(!b.inject(Injection::RcTakeover(true)));
    assert!(!b.inject(Injection::Bumper(true)));
}

#[test]
fn a_reboot_goes_quiet_for_300_ms_then_powers_up_with_drive_off_and_counters_at_zero() {
    let mut b = Bench::powered();
    b.send(Frame::Servos(ServoCommand {
        pan_rad: 0.5,
        tilt_rad: 0.5,
    }));
    b.send(Frame::Lift(LiftCommand {
        enable: true,
        position_pct: 10.0,
    }));
    b.heartbeat(Some(velocity(1.0, 0.0, 0.0)));
    b.run_for(ms(2000));
    let x_before = b.sim.truth().x_m;
    assert!(b.last().encoder_counts[0] > 20_000);

    assert!(b.inject(Injection::Reboot));
    let reboot = b.now;
    assert!(b.sim.is_booting());
    assert_eq!(b.sim.truth().boots, 1);
    b.run_for(ms(299));
    assert_eq!(b.sent_since(reboot), 0, "silent while booting");
    assert!(
        b.sim.truth().commands_ignored >= 2,
        "the heartbeats sent while booting"
    );
    b.run_for(ms(1));
    let (t, r) = *b.reports().last().unwrap();
    assert_eq!(t, reboot + ms(300));
    assert_eq!(r.sensor_stamp_us, 0);
    assert_eq!(r.encoder_counts, [0; 4]);
    assert_eq!(r.lift_encoder_counts, 0);
    assert_eq!(r.motor_current_a, [0.0; 4]);
    assert!(!b.sim.is_powered());
    assert_eq!(b.sim.servos_rad(), (0.0, 0.0));
    assert!(!b.sim.lift_enabled());
    b.run_for(ms(1000));
    assert!(b.v().abs() < 1e-3, "unpowered after the boot");
    let x_after = b.sim.truth().x_m;
    assert!(x_after > x_before, "the pose is physical and survives");
    assert_eq!(
        b.last().sensor_stamp_us,
        (1_000_000u32 % 65_536) as u16,
        "1 s after the boot"
    );
}

#[test]
fn a_flood_adds_reports_up_to_what_the_line_carries() {
    let mut b = Bench::new();
    assert!(b.inject(Injection::Flood { frames_per_s: 100 }));
    b.run_for(ms(999));
    assert_eq!(b.sim.reports_sent(), 50 + 99);
    assert_eq!(b.decoded().1, 0);
    assert!(b.inject(Injection::Flood {
        frames_per_s: 10_000
    }));
    let sent = b.sim.reports_sent();
    b.run_for(ms(1000));
    // 115200 baud / 10 bits / 75 bytes = 153 a second.
    assert_eq!(b.sim.reports_sent() - sent, 50 + 153);
    assert_eq!(b.sim.truth().injected.flood_frames, 99 + 153);
    b.inject(Injection::Flood { frames_per_s: 0 });
    let sent = b.sim.reports_sent();
    b.run_for(ms(1000));
    assert_eq!(b.sim.reports_sent() - sent, 50);
}

#[test]
fn malformed_input_is_counted_and_never_obeyed() {
    let mut b = Bench::new();
    let mut bad = Frame::Power(PowerCommand { enable: true })
        .encode(&p())
        .unwrap();
    *bad.last_mut().unwrap() ^= 0x10;
    b.send_raw(&bad);
    b.send_raw(&[0x00, 0x13, 0xAA, 0x55, 0x02, 0x09, 0x00, 0x0B]);
    let can = crate::CanFrame::new(0x111, &[0; 8]).unwrap();
    b.sim.handle_rx(b.now, Rx::Can(&can));
    b.send(Frame::Sensor(SensorReport::default()));
    let t = b.sim.truth();
    assert_eq!(t.bad_checksums_received, 1);
    assert_eq!(t.decode_errors, 2, "an unknown id and the CAN frame");
    assert_eq!(t.commands_received, 0);
    assert_eq!(
        b.sim.truth().frames_ignored,
        1,
        "a report sent to the board"
    );
    assert!(!b.sim.is_powered());
}

#[test]
fn omni_variants_move_sideways_and_report_four_wheels() {
    let omni = XbotProfile { omni: true, ..p() };
    let mut b = Bench::with(XbotSim::new(omni, T0), T0);
    b.send(Frame::Power(PowerCommand { enable: true }));
    b.heartbeat(Some(velocity(0.0, 0.3, 0.0)));
    b.run_for(ms(3000));
    let t = b.sim.truth();
    assert!(
        close(t.lateral_mps, 0.3, 1e-3) && t.linear_mps.abs() < 1e-9,
        "{t:?}"
    );
    assert!(t.y_m > 0.5, "left is +y: {t:?}");
    let w = b.sim.wheel_mps();
    assert!(close(w[0], -0.3, 1e-3) && close(w[1], 0.3, 1e-3), "{w:?}");
    assert!(close(w[2], 0.3, 1e-3) && close(w[3], -0.3, 1e-3), "{w:?}");
    let r = b.last();
    assert!(r.encoder_counts.iter().all(|c| *c != 0), "{r:?}");
    assert!(r.motor_current_a.iter().all(|a| *a > 0.5), "{r:?}");
}

#[test]
fn split_output_reassembles_to_the_same_reports() {
    let mut whole = Bench::powered();
    let mut split = Bench::with(XbotSim::new(p(), T0).with_tx_chunk_len(7), T0);
    split.send(Frame::Power(PowerCommand { enable: true }));
    for b in [&mut whole, &mut split] {
        b.heartbeat(Some(velocity(0.3, 0.0, 0.2)));
        b.run_for(ms(500));
    }
    assert_eq!(whole.reports(), split.reports());
    assert_eq!(
        split.sent.len(),
        11 * whole.sent.len(),
        "75 bytes in chunks of 7"
    );
    // A corrupted report split in chunks counts once, when its last chunk has left.
    assert!(split.inject(Injection::BadChecksums(2)));
    split.run_for(ms(20));
    assert_eq!(split.sim.truth().injected.bad_checksum_frames, 1);
    split.run_for(ms(100));
    assert_eq!(split.sim.truth().injected.bad_checksum_frames, 2);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn arbitrary_bytes_never_panic_and_every_candidate_is_counted(reads in arbitrary_reads()) {
        let mut b = Bench::new();
        for piece in &reads {
            b.send_raw(piece);
            b.run_for(ms(3));
        }
        let t = b.sim.truth();
        prop_assert_eq!(t.bad_checksums_received + t.decode_errors, b.sim.parser.errors());
        prop_assert_eq!(t.commands_received + b.sim.truth().frames_ignored, b.sim.parser.frames());
    }
}
