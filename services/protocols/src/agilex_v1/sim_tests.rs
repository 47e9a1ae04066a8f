//! The simulated SCOUT MINI firmware alone, fed frames through the codec on simulated time.

// 0.5235 is the manual's angular full scale as printed, not an approximation of π/6.
#![allow(clippy::approx_constant)]

use std::collections::BTreeMap;
use std::time::Duration;

use chassis_interfaces::{ControlMode, FaultFlags};
use proptest::prelude::*;

use super::V1Sim;
use crate::DecodeError;
use crate::agilex_v1::V1Profile;
use crate::agilex_v1::{
    Decoded, Frame, Lights, MotionCommand, MotionFeedback, MotorFeedback, SystemStatus, body,
    checksum, clear_code, decode, fault, id, light_mode, mode,
};
use crate::can::CanFrame;
use crate::driver::Rx;
use crate::firmware::{Firmware, Injection};
use crate::sim_bench::BenchFirmware;
use crate::time::Timestamp;

const T0: Timestamp = Timestamp::from_millis(1_000);

fn ms(v: u64) -> Duration {
    Duration::from_millis(v)
}

fn drive(linear_mps: f64, angular_radps: f64) -> MotionCommand {
    MotionCommand::drive(linear_mps, angular_radps)
}

fn clear(code: u8) -> MotionCommand {
    MotionCommand {
        fault_clear: code,
        ..drive(0.0, 0.0)
    }
}

/// The same frame with its checksum byte off by one.
fn corrupted(frame: &CanFrame) -> CanFrame {
    let mut data = frame.data().to_vec();
    data[7] = data[7].wrapping_add(1);
    CanFrame::new(frame.id(), &data).unwrap()
}

/// The firmware on simulated time, with an optional 20 ms 0x130 heartbeat from "the computer".
type Bench = crate::sim_bench::Bench<V1Sim>;

impl BenchFirmware for V1Sim {
    type Item = CanFrame;
    type Command = MotionCommand;
    type Profile = V1Profile;
    const HEARTBEAT_PERIOD: Duration = Duration::from_millis(20);

    fn bench_profile(&self) -> &V1Profile {
        self.profile()
    }

    fn send_heartbeat(bench: &mut Bench, command: MotionCommand) {
        bench.send(Frame::MotionCommand(command));
    }
}

impl Bench {
    fn new() -> Self {
        Self::with(V1Sim::new(V1Profile::default(), T0), T0)
    }

    /// Driving at `linear_mps` for `warm_up`, 0x130 every 20 ms.
    fn driving(linear_mps: f64, warm_up: Duration) -> Self {
        let mut b = Self::new();
        b.heartbeat(Some(drive(linear_mps, 0.0)));
        b.run_for(warm_up);
        b
    }

    fn encode(&mut self, frame: Frame) -> CanFrame {
        let can = frame.encode(self.count, &self.profile).unwrap();
        self.count = self.count.wrapping_add(1);
        can
    }

    fn send(&mut self, frame: Frame) {
        let can = self.encode(frame);
        self.send_raw(can);
    }

    fn send_raw(&mut self, can: CanFrame) {
        self.sim.handle_rx(self.now, Rx::Can(&can));
        self.drain();
    }

    fn decoded(&self, frame_id: u16) -> Vec<(Timestamp, Decoded)> {
        self.sent
            .iter()
            .filter(|(_, f)| f.id() == u32::from(frame_id))
            .map(|(t, f)| (*t, decode(f, &self.profile).unwrap()))
            .collect()
    }

    fn last(&self, frame_id: u16) -> Frame {
        self.decoded(frame_id).last().unwrap().1.frame
    }

    fn status(&self) -> SystemStatus {
        let Frame::SystemStatus(s) = self.last(id::SYSTEM_STATUS) else {
            panic!()
        };
        s
    }

    fn motor(&self, motor: u16) -> MotorFeedback {
        let Frame::Motor(m) = self.last(id::MOTOR_1 + motor - 1) else {
            panic!()
        };
        m
    }

    /// The 0x151 fault word without the RC-disconnected bit (always set with the RC off).
    fn faults(&self) -> u16 {
        self.status().vendor_fault_word & !fault::RC_DISCONNECTED
    }
}

#[test]
fn the_chassis_powers_up_in_command_mode_with_the_rc_transmitter_off() {
    let mut b = Bench::new();
    b.run_for(ms(100));
    let s = b.status();
    assert_eq!(
        s,
        SystemStatus {
            body_status: body::NORMAL,
            mode: mode::CAN_COMMAND,
            battery_voltage_v: 29.2,
            vendor_fault_word: fault::RC_DISCONNECTED,
        }
    );
    let t = b.sim.truth();
    assert_eq!(t.control_mode, ControlMode::COMMAND);
    assert_eq!(t.fault_flags, FaultFlags::RC_LINK_LOST);
    assert!(!t.brake_engaged);
    assert!(t.soc_pct > 99.999 && t.soc_pct < 100.0, "{}", t.soc_pct);
    assert_eq!(
        b.last(id::LIGHT_STATE),
        Frame::LightState(Lights::default())
    );
    assert_eq!(b.sim.robot(), crate::RobotKind::ScoutMini);
}

#[test]
fn feedback_is_sent_every_20_ms_with_a_rolling_count_per_id_and_correct_checksums() {
    let mut b = Bench::new();
    b.run_for(ms(10_000));
    let end = T0 + ms(10_000);
    let mut count: BTreeMap<u32, usize> = BTreeMap::new();
    for (t, f) in &b.sent {
        if *t < end {
            *count.entry(f.id()).or_default() += 1;
        }
    }
    assert_eq!(
        count.into_iter().collect::<Vec<_>>(),
        [0x131, 0x141, 0x151, 0x200, 0x201, 0x202, 0x203]
            .map(|i| (i, 500))
            .to_vec()
    );
    // One slot: the documented order.
    let first: Vec<u32> = b.sent[..7].iter().map(|(_, f)| f.id()).collect();
    assert_eq!(first, [0x151, 0x131, 0x200, 0x201, 0x202, 0x203, 0x141]);
    for frame_id in [0x151, 0x131, 0x200, 0x203, 0x141] {
        let frames = b.decoded(frame_id);
        assert_eq!(frames[0].0, T0);
        assert_eq!(frames[0].1.count, 0);
        for pair in frames.windows(2) {
            assert_eq!(pair[1].0.saturating_since(pair[0].0), ms(20));
            assert_eq!(
                pair[1].1.count,
                pair[0].1.count.wrapping_add(1),
                "0x{frame_id:03X}: one count per id, wrapping"
            );
        }
        assert_eq!(frames[300].1.count, 44, "300 mod 256");
    }
    for (_, f) in &b.sent {
        let data = f.data();
        assert_eq!(data.len(), 8);
        assert_eq!(data[7], checksum(f.id() as u16, &data[..7]));
    }
}

#[test]
fn a_motion_command_is_obeyed_only_with_mode_0x01() {
    let mut b = Bench::new();
    for other in [mode::RC, mode::SERIAL] {
        b.heartbeat(Some(MotionCommand {
            mode: other,
            ..drive(1.0, 0.2)
        }));
        b.run_for(ms(1000));
        assert_eq!(b.v(), 0.0);
        assert_eq!(b.sim.truth().angular_radps, 0.0);
    }
    assert_eq!(b.sim.truth().commands_received, 0);
    // 0x130 at T0, T0 + 20 ms, …, T0 + 2000 ms.
    assert_eq!(b.sim.truth().commands_ignored, 101);
    assert_eq!(
        b.status().mode,
        mode::CAN_COMMAND,
        "the chassis' mode stays"
    );

    b.heartbeat(Some(drive(0.5, 0.0)));
    b.run_for(ms(3000));
    assert!((b.v() - 0.5).abs() < 1e-3, "{}", b.v());
    assert_eq!(b.sim.truth().commands_received, 150);
}

#[test]
fn speed_follows_a_first_order_response_and_the_pose_integrates() {
    let mut b = Bench::new();
    b.heartbeat(Some(drive(1.0, 0.0)));
    b.run_for(ms(300));
    // One time constant: 1 - 1/e.
    assert!((b.v() - (1.0 - (-1.0f64).exp())).abs() < 0.01, "{}", b.v());
    b.run_for(ms(3000));
    assert!((b.v() - 1.0).abs() < 1e-3);
    // ∫(1 - e^(-t/τ)) dt over 3.3 s = 3.3 - 0.3·(1 - e^-11).
    let expected = 3.3 - 0.3 * (1.0 - (-11.0f64).exp());
    let t = b.sim.truth();
    assert!((t.x_m - expected).abs() < 0.01, "{t:?}");
    assert!(t.y_m.abs() < 1e-9 && t.yaw_rad.abs() < 1e-9);

    let Frame::MotionFeedback(m) = b.last(id::MOTION_FEEDBACK) else {
        panic!()
    };
    assert_eq!(
        m,
        MotionFeedback {
            linear_mps: 1.0,
            angular_radps: 0.0
        }
    );
    // Hub motors: 1 m/s on a 0.0875 m wheel is 109.1 rpm; 1.2 A per m/s.
    for motor in 1..=4 {
        let m = b.motor(motor);
        assert_eq!((m.rpm, m.current_a), (109.0, 1.2), "motor {motor}");
        assert_eq!((m.driver_temp_c, m.motor_temp_c), (25.0, 25.0));
    }
    assert!((b.sim.battery_current_a() - 5.6).abs() < 1e-3);

    // Turning on the spot at 50 % of the full scale: the left side runs backwards.
    b.heartbeat(Some(drive(0.0, 0.26175)));
    b.run_for(ms(4000));
    let t = b.sim.truth();
    assert!(t.linear_mps.abs() < 1e-3 && (t.angular_radps - 0.26175).abs() < 1e-4);
    let side = 0.26175 * 0.225 / (std::f64::consts::TAU * V1Sim::WHEEL_RADIUS_M) * 60.0;
    assert_eq!(b.motor(1).rpm, -side.round());
    assert_eq!(b.motor(2).rpm, side.round());
    assert_eq!(b.motor(3).rpm, -side.round());
    let Frame::MotionFeedback(m) = b.last(id::MOTION_FEEDBACK) else {
        panic!()
    };
    assert!((m.angular_radps - 0.262).abs() < 1e-9, "{m:?}");
    assert!(t.yaw_rad > 0.7, "a left turn yaws left: {t:?}");
}

#[test]
fn without_a_0x130_for_500_ms_the_chassis_stops_without_a_fault() {
    let mut b = Bench::driving(0.5, ms(4000));
    b.heartbeat(None);
    let last = b.last_heartbeat.unwrap();
    b.run_for((last + ms(500)).saturating_since(b.now));
    assert!((b.v() - 0.5).abs() < 1e-6, "500 ms is still in time");
    b.run_for(ms(100));
    assert!(b.v() < 0.5 * (-0.3f64).exp(), "{}", b.v());
    b.run_for(ms(2000));
    assert!(b.v().abs() < 1e-3);
    assert_eq!(b.faults(), 0, "no fault bit for the timeout");
    assert_eq!(b.status().mode, mode::CAN_COMMAND);

    b.heartbeat(Some(drive(0.5, 0.0)));
    b.run_for(ms(3000));
    assert!((b.v() - 0.5).abs() < 1e-3, "the next 0x130 drives again");
}

#[test]
fn a_bad_checksum_is_dropped_and_sets_the_checksum_fault_for_500_ms() {
    let mut b = Bench::new();
    b.run_for(ms(105));
    let bad = corrupted(&b.encode(Frame::MotionCommand(drive(1.0, 0.0))));
    let at = b.now;
    b.send_raw(bad);
    b.run_for(ms(1000));
    let t = b.sim.truth();
    assert_eq!(t.bad_checksums_received, 1);
    assert_eq!((t.commands_received, t.linear_mps), (0, 0.0), "dropped");
    let flagged: Vec<Timestamp> = b
        .decoded(id::SYSTEM_STATUS)
        .into_iter()
        .filter_map(|(t, d)| match d.frame {
            Frame::SystemStatus(s) if s.vendor_fault_word & fault::COMMAND_CHECKSUM != 0 => Some(t),
            _ => None,
        })
        .collect();
    // 0x151 at T0 + 120, 140, …, 600 ms: every one in (at, at + 500 ms).
    assert_eq!(flagged.len(), 25);
    assert_eq!(flagged[0], T0 + ms(120));
    assert_eq!(*flagged.last().unwrap(), at + ms(495));
    assert_eq!(b.faults(), 0, "cleared by itself");
    assert_eq!(
        b.sim.truth().fault_flags,
        FaultFlags::RC_LINK_LOST,
        "no body exception for an alarm"
    );

    // The hold is an option.
    let mut b = Bench::with(
        V1Sim::new(V1Profile::default(), T0).with_checksum_fault_hold(ms(50)),
        T0,
    );
    let bad = corrupted(&b.encode(Frame::MotionCommand(drive(0.0, 0.0))));
    b.send_raw(bad);
    b.run_for(ms(10));
    assert_ne!(b.sim.vendor_fault_word() & fault::COMMAND_CHECKSUM, 0);
    b.run_for(ms(50));
    assert_eq!(b.sim.vendor_fault_word() & fault::COMMAND_CHECKSUM, 0);
}

#[test]
fn an_rc_takeover_reports_mode_rc_and_ignores_speeds_until_hand_back() {
    let mut b = Bench::driving(1.0, ms(2000));
    let received = b.sim.truth().commands_received;
    assert!(b.inject(Injection::RcTakeover(true)));
    b.run_for(ms(3000));
    let s = b.status();
    assert_eq!(s.mode, mode::RC);
    assert_eq!(s.vendor_fault_word, 0, "the transmitter is connected");
    let t = b.sim.truth();
    assert_eq!(t.control_mode, ControlMode::REMOTE);
    assert_eq!(t.fault_flags, 0);
    assert!(b.v().abs() < 1e-3, "sticks centred: the robot stops");
    assert_eq!(t.commands_received, received, "0x130 speeds are shielded");
    assert_eq!(b.sim.truth().commands_ignored, 150);

    // Hand back: command mode at once, the next heartbeat is obeyed, no handshake.
    assert!(b.inject(Injection::RcTakeover(false)));
    assert_eq!(b.sim.truth().control_mode, ControlMode::COMMAND);
    b.run_for(ms(20));
    assert_eq!(b.status().mode, mode::CAN_COMMAND);
    assert_eq!(b.status().vendor_fault_word, fault::RC_DISCONNECTED);
    b.run_for(ms(3000));
    assert!((b.v() - 1.0).abs() < 1e-3);
}

#[test]
fn a_reboot_goes_quiet_for_300_ms_then_powers_up_with_every_count_at_zero() {
    let mut b = Bench::driving(1.0, ms(2000));
    assert!(b.inject(Injection::Reboot));
    let reboot = b.now;
    let received = b.sim.truth().commands_received;
    assert!(b.sim.is_booting());
    b.run_for(ms(299));
    assert_eq!(b.sent_since(reboot), 0, "silent while booting");
    // The physics last ran at the 0x130 of reboot + 280 ms: e^(-2.8) of the speed, τ = 0.1 s.
    assert!(b.v() < 0.062, "drive output cut while booting: {}", b.v());
    assert_eq!(
        b.sim.truth().commands_received,
        received,
        "frames are ignored while booting"
    );
    b.run_for(ms(1));
    assert!(!b.sim.is_booting());
    b.run_for(ms(19));
    let first = b.sent.iter().find(|(t, _)| *t > reboot).unwrap().0;
    assert_eq!(first, reboot + V1Sim::DEFAULT_BOOT_TIME);
    for frame_id in [0x151, 0x131, 0x200, 0x201, 0x202, 0x203, 0x141] {
        let after: Vec<_> = b
            .decoded(frame_id)
            .into_iter()
            .filter(|(t, _)| *t > reboot)
            .collect();
        assert_eq!(after[0].1.count, 0, "0x{frame_id:03X} counts from 0 again");
    }
    let s = b.status();
    assert_eq!((s.mode, s.body_status), (mode::CAN_COMMAND, body::NORMAL));
    let t = b.sim.truth();
    assert_eq!((t.boots, t.control_mode), (1, ControlMode::COMMAND));
    // The heartbeat never stopped: the chassis drives again at once.
    b.run_for(ms(3000));
    assert!((b.v() - 1.0).abs() < 1e-3);
}

#[test]
fn the_battery_alarm_and_failure_follow_the_voltage_and_the_failure_cuts_drive() {
    let mut b = Bench::driving(1.0, ms(2000));
    // 16 %: 22.31 V open-circuit, 22.14 V at 5.6 A — below the alarm, above the failure.
    assert!(b.inject(Injection::Battery { soc_pct: 16.0 }));
    b.run_for(ms(1000));
    let s = b.status();
    assert_eq!(
        s.vendor_fault_word & !fault::RC_DISCONNECTED,
        fault::BATTERY_UNDER_VOLTAGE_ALARM
    );
    assert_eq!((s.battery_voltage_v, s.body_status), (22.1, body::NORMAL));
    assert!(
        (b.v() - 1.0).abs() < 1e-3,
        "an alarm does not stop the robot"
    );
    assert_ne!(
        b.sim.truth().fault_flags & FaultFlags::BATTERY_UNDER_VOLTAGE_WARNING,
        0
    );

    // 10 %: 21.8 V — the failure latches and cuts drive.
    b.inject(Injection::Battery { soc_pct: 10.0 });
    b.run_for(ms(1000));
    assert!(b.v().abs() < 1e-3, "{}", b.v());
    let s = b.status();
    assert_eq!(
        s.vendor_fault_word & !fault::RC_DISCONNECTED,
        fault::BATTERY_UNDER_VOLTAGE_ALARM | fault::BATTERY_UNDER_VOLTAGE
    );
    assert_eq!(s.body_status, body::EXCEPTION);
    assert!(b.motor(1).current_a == 0.0, "no drive current");
    let flags = b.sim.truth().fault_flags;
    assert_ne!(flags & FaultFlags::BATTERY_UNDER_VOLTAGE, 0);
    assert_ne!(flags & FaultFlags::BODY_EXCEPTION, 0);

    // The code fails while the battery is flat; charging alone does not restore drive.
    b.send(Frame::MotionCommand(clear(
        clear_code::BATTERY_UNDER_VOLTAGE,
    )));
    b.inject(Injection::Battery { soc_pct: 50.0 });
    b.run_for(ms(1000));
    assert_eq!(
        b.faults(),
        fault::BATTERY_UNDER_VOLTAGE,
        "latched; the alarm cleared"
    );
    assert!(b.v().abs() < 1e-3);
    b.send(Frame::MotionCommand(clear(
        clear_code::BATTERY_UNDER_VOLTAGE,
    )));
    b.run_for(ms(3000));
    assert_eq!(b.faults(), 0);
    assert_eq!(b.status().body_status, body::NORMAL);
    assert!((b.v() - 1.0).abs() < 1e-3, "drive restored");
}

#[test]
fn a_hot_motor_driver_raises_the_alarm_then_latches_the_protection_until_code_0x07() {
    let mut b = Bench::driving(1.0, ms(3000));
    b.sim.set_driver_temperature_c(b.now, 60.0);
    b.run_for(ms(100));
    assert_eq!(b.faults(), fault::DRIVE_OVER_TEMP_ALARM);
    assert_eq!(b.motor(2).driver_temp_c, 60.0);
    assert_eq!(b.motor(2).motor_temp_c, 46.0, "25 + 0.6 · 35");
    assert!(
        (b.v() - 1.0).abs() < 1e-3,
        "an alarm does not stop the robot"
    );
    // 60 → 55 °C toward ≈25.1 °C with τ = 60 s takes ≈ 9.3 s.
    b.run_for(ms(8500));
    assert_eq!(b.faults(), fault::DRIVE_OVER_TEMP_ALARM);
    b.run_for(ms(2000));
    assert_eq!(b.faults(), 0, "the alarm clears itself");

    b.sim.set_driver_temperature_c(b.now, 70.0);
    b.run_for(ms(1000));
    assert_eq!(
        b.faults(),
        fault::DRIVE_OVER_TEMP_ALARM | fault::DRIVE_OVER_TEMP_PROTECTION
    );
    assert_eq!(b.status().body_status, body::EXCEPTION);
    // "The vehicle will slowly stop": τ = 1 s.
    assert!((b.v() - (-1.0f64).exp()).abs() < 0.02, "{}", b.v());
    assert_ne!(b.sim.truth().fault_flags & FaultFlags::OVER_TEMPERATURE, 0);
    // Still above 65 °C: the code clears nothing.
    b.send(Frame::MotionCommand(clear(
        clear_code::DRIVE_OVER_TEMPERATURE,
    )));
    b.run_for(ms(100));
    assert_ne!(b.faults() & fault::DRIVE_OVER_TEMP_PROTECTION, 0);
    // Cooled below 65 °C (≈ 8 s without current): latched until the code.
    b.run_for(ms(10_000));
    assert!(b.sim.driver_temperatures_c()[0] < 65.0);
    assert_eq!(
        b.faults(),
        fault::DRIVE_OVER_TEMP_ALARM | fault::DRIVE_OVER_TEMP_PROTECTION
    );
    assert!(b.v().abs() < 1e-3);
    b.send(Frame::MotionCommand(clear(
        clear_code::DRIVE_OVER_TEMPERATURE,
    )));
    b.run_for(ms(3000));
    assert_eq!(b.faults() & fault::DRIVE_OVER_TEMP_PROTECTION, 0);
    assert!((b.v() - 1.0).abs() < 1e-3, "motion commands work again");
}

#[test]
fn an_over_current_raises_the_alarm_then_latches_the_protection_until_code_0x08() {
    let mut b = Bench::driving(1.0, ms(2000));
    b.sim.set_extra_load_a(b.now, 25.0);
    // 26.2 A into a 1 s mean of I²: 15 A rms after ≈ 0.4 s, 20 A rms after ≈ 0.9 s.
    b.run_for(ms(500));
    assert_eq!(b.faults(), fault::MOTOR_OVER_CURRENT_ALARM);
    assert_eq!(b.motor(1).current_a, 26.2);
    b.run_for(ms(500));
    assert_eq!(
        b.faults(),
        fault::MOTOR_OVER_CURRENT_ALARM | fault::MOTOR_OVER_CURRENT_PROTECTION
    );
    assert_eq!(b.motor(1).current_a, 0.0, "drive output cut");
    b.run_for(ms(5000));
    assert!(b.v().abs() < 0.01, "{}", b.v());
    assert_eq!(
        b.faults(),
        fault::MOTOR_OVER_CURRENT_PROTECTION,
        "the alarm cleared"
    );
    assert_ne!(b.sim.truth().fault_flags & FaultFlags::OVER_CURRENT, 0);

    // Cleared with the load still there: it latches again about a second later.
    b.send(Frame::MotionCommand(clear(clear_code::MOTOR_OVER_CURRENT)));
    b.run_for(ms(100));
    assert_eq!(b.faults(), 0);
    b.run_for(ms(2000));
    assert_ne!(b.faults() & fault::MOTOR_OVER_CURRENT_PROTECTION, 0);

    b.sim.set_extra_load_a(b.now, 0.0);
    b.run_for(ms(3000));
    b.send(Frame::MotionCommand(clear(clear_code::MOTOR_OVER_CURRENT)));
    b.run_for(ms(3000));
    assert_eq!(b.faults(), 0);
    assert!((b.v() - 1.0).abs() < 1e-3);
}

#[test]
fn a_lost_motor_driver_cuts_drive_and_its_frame_until_its_code_clears_it() {
    let mut b = Bench::driving(1.0, ms(2000));
    assert!(b.inject(Injection::MotorDriverLoss {
        motor: 2,
        lost: true
    }));
    let lost = b.now;
    b.send(Frame::MotionCommand(clear(clear_code::MOTOR_2_COMM)));
    b.run_for(ms(1000));
    assert!(b.v().abs() < 1e-3);
    assert_eq!(b.faults(), fault::MOTOR_2_COMM);
    assert_ne!(b.sim.truth().fault_flags & FaultFlags::MOTOR_2_COMM_LOST, 0);
    for (frame_id, present) in [(0x200, true), (0x201, false), (0x202, true), (0x203, true)] {
        let any = b.decoded(frame_id).iter().any(|(t, _)| *t > lost);
        assert_eq!(any, present, "0x{frame_id:03X}");
    }

    b.inject(Injection::MotorDriverLoss {
        motor: 2,
        lost: false,
    });
    let back = b.now;
    b.run_for(ms(1000));
    assert!(b.decoded(0x201).iter().any(|(t, _)| *t > back));
    assert_eq!(b.faults(), fault::MOTOR_2_COMM, "latched");
    b.send(Frame::MotionCommand(clear(clear_code::MOTOR_1_COMM)));
    b.run_for(ms(100));
    assert_eq!(b.faults(), fault::MOTOR_2_COMM, "another motor's code");
    b.send(Frame::MotionCommand(clear(clear_code::MOTOR_2_COMM)));
    b.run_for(ms(3000));
    assert_eq!(b.faults(), 0);
    assert!((b.v() - 1.0).abs() < 1e-3);

    for motor in [0, 5] {
        assert!(!b.inject(Injection::MotorDriverLoss { motor, lost: true }));
    }
}

#[test]
fn clear_codes_are_honoured_whatever_the_mode_byte_and_under_rc() {
    let mut b = Bench::new();
    b.inject(Injection::MotorDriverLoss {
        motor: 4,
        lost: true,
    });
    b.inject(Injection::MotorDriverLoss {
        motor: 4,
        lost: false,
    });
    b.inject(Injection::RcTakeover(true));
    b.run_for(ms(100));
    assert_eq!(b.faults(), fault::MOTOR_4_COMM);
    b.send(Frame::MotionCommand(MotionCommand {
        mode: mode::RC,
        fault_clear: clear_code::MOTOR_4_COMM,
        linear_mps: 1.0,
        angular_radps: 0.0,
    }));
    b.run_for(ms(100));
    assert_eq!(b.status().vendor_fault_word, 0);
    assert_eq!(b.sim.truth().commands_received, 1);
    assert_eq!(b.v(), 0.0, "the speed in it is still shielded");
}

#[test]
fn light_commands_set_the_light_state_and_enable_0x00_hands_it_back() {
    let mut b = Bench::new();
    let custom = Lights {
        control_enabled: true,
        front_mode: light_mode::CUSTOM_BRIGHTNESS,
        front_brightness_pct: 40,
    };
    b.send(Frame::LightCommand(custom));
    b.run_for(ms(40));
    assert_eq!(b.last(id::LIGHT_STATE), Frame::LightState(custom));
    assert_eq!(b.sim.lights(), custom);

    // Obeyed under RC too.
    b.inject(Injection::RcTakeover(true));
    let breathing = Lights {
        front_mode: light_mode::BREATHING,
        front_brightness_pct: 0,
        ..custom
    };
    b.send(Frame::LightCommand(breathing));
    b.run_for(ms(40));
    assert_eq!(b.last(id::LIGHT_STATE), Frame::LightState(breathing));

    b.send(Frame::LightCommand(Lights {
        control_enabled: false,
        ..custom
    }));
    b.run_for(ms(40));
    assert_eq!(
        b.last(id::LIGHT_STATE),
        Frame::LightState(Lights::default())
    );
    assert_eq!(b.sim.truth().commands_received, 3);

    // A reboot hands the light back too.
    b.send(Frame::LightCommand(custom));
    b.inject(Injection::Reboot);
    b.run_for(ms(400));
    assert_eq!(b.sim.lights(), Lights::default());
}

#[test]
fn bad_checksums_corrupt_exactly_the_next_n_frames() {
    let mut b = Bench::new();
    b.run_for(ms(30));
    assert!(b.inject(Injection::BadChecksums(10)));
    let start = b.sent.len();
    b.run_for(ms(100));
    let results: Vec<bool> = b.sent[start..]
        .iter()
        .map(|(_, f)| decode(f, &b.profile).is_ok())
        .collect();
    assert_eq!(results.len(), 35);
    assert!(results[..10].iter().all(|ok| !ok));
    assert!(results[10..].iter().all(|ok| *ok));
    for (_, f) in &b.sent[start..start + 10] {
        assert!(matches!(
            decode(f, &b.profile),
            Err(DecodeError::BadChecksum { .. })
        ));
        // Only the checksum byte differs: the count still advanced.
        let data = f.data();
        assert_eq!(data[7], !checksum(f.id() as u16, &data[..7]));
    }
    let counts: Vec<u8> = b
        .sent
        .iter()
        .filter(|(_, f)| f.id() == 0x151)
        .map(|(_, f)| f.data()[6])
        .collect();
    assert_eq!(counts, (0..7).collect::<Vec<u8>>());
}

#[test]
fn malformed_frames_and_another_nodes_feedback_are_counted_and_ignored() {
    let mut b = Bench::new();
    let good = b.encode(Frame::MotionCommand(drive(1.0, 0.0)));
    let mut undefined_mode = good.data().to_vec();
    undefined_mode[0] = 0x05;
    undefined_mode[7] = checksum(0x130, &undefined_mode[..7]);
    for frame in [
        CanFrame::from_candump("7F0#0102").unwrap(),
        CanFrame::from_candump("130#01000A").unwrap(),
        CanFrame::new(0x130, &undefined_mode).unwrap(),
        CanFrame::new_extended(0x130, good.data()).unwrap(),
    ] {
        b.send_raw(frame);
    }
    let t = b.sim.truth();
    assert_eq!((t.decode_errors, t.bad_checksums_received), (4, 0));
    assert_eq!(t.commands_received, 0);

    // Another node's feedback is valid but not for the chassis.
    b.send(Frame::SystemStatus(SystemStatus::default()));
    assert_eq!(b.sim.truth().frames_ignored, 1);
    assert_eq!(b.sim.truth().decode_errors, 4);
    assert_eq!(b.v(), 0.0);
}

/// A second injection before the first one's frames have all gone out adds to it (the storms
/// of the fault matrix inject every 100 ms, faster than 7 frames a slot corrupt a large count),
/// and the truth counts each corrupted frame as it leaves.
#[test]
fn bad_checksum_injections_add_up_and_count_as_they_leave() {
    let mut b = Bench::new();
    b.run_for(ms(30));
    assert!(b.inject(Injection::BadChecksums(10)));
    assert_eq!(
        b.sim.truth().injected.bad_checksum_frames,
        0,
        "none sent yet"
    );
    b.run_for(ms(20));
    let halfway = b.sim.truth().injected.bad_checksum_frames;
    assert_eq!(halfway, 7, "one slot of 7 frames");
    assert!(b.inject(Injection::BadChecksums(10)));
    let start = b.sent.len();
    b.run_for(ms(200));
    let bad = b.sent[start..]
        .iter()
        .filter(|(_, f)| decode(f, &b.profile).is_err())
        .count() as u64;
    assert_eq!(halfway + bad, 20, "3 left of the first, 10 of the second");
    let injected = b.sim.truth().injected;
    assert_eq!(injected.bad_checksum_frames, 20);
    assert_eq!(
        (injected.garbage_frames, injected.flood_frames),
        (0, 0),
        "{injected:?}"
    );
}

/// Garbage and flood frames count when they leave: garbage queued and then cleared by a silence
/// never went out.
#[test]
fn garbage_and_flood_frames_count_as_they_leave() {
    let mut b = Bench::new();
    b.run_for(ms(30));
    let now = b.now;
    assert!(b.sim.inject(now, Injection::Garbage((0u8..20).collect())));
    assert_eq!(b.sim.truth().injected.garbage_frames, 0, "queued, not sent");
    assert!(b.sim.inject(now, Injection::Silence(ms(10))));
    b.run_for(ms(30));
    assert_eq!(
        b.sim.truth().injected.garbage_frames,
        0,
        "cleared, never sent"
    );
    assert!(b.inject(Injection::Garbage((0u8..20).collect())));
    let injected = b.sim.truth().injected;
    assert_eq!((injected.garbage_frames, injected.garbage_bytes), (3, 20));
    assert!(b.inject(Injection::Flood { frames_per_s: 1000 }));
    b.run_for(ms(1000));
    assert_eq!(b.sim.truth().injected.flood_frames, 1000);
    // A flood frame that is corrupted counts as both.
    assert!(b.inject(Injection::BadChecksums(10_000)));
    b.run_for(ms(100));
    let injected = b.sim.truth().injected;
    assert_eq!(injected.flood_frames, 1100);
    assert_eq!(injected.bad_checksum_frames, 100 + 35);
}

#[test]
fn injections_the_scout_mini_lacks_are_refused() {
    let mut b = Bench::new();
    assert!(!b.inject(Injection::Bumper(true)));
    assert!(!b.inject(Injection::ObstacleAhead(Some(0.5))));
    assert!(!b.inject(Injection::ObstacleBehind(None)));
    assert_eq!(b.sim.truth().fault_flags, FaultFlags::RC_LINK_LOST);
}

#[test]
fn a_flood_adds_the_requested_extra_frames() {
    let mut b = Bench::new();
    b.run_for(ms(1000));
    let start = b.now;
    b.run_for(ms(1000));
    let normal = b.sent_since(start);
    assert_eq!(normal, 350);
    assert!(b.inject(Injection::Flood { frames_per_s: 1000 }));
    let start = b.now;
    b.run_for(ms(1000));
    assert_eq!(b.sent_since(start), normal + 1000);
    // The copies count like the rest: 0x131 advanced by 50 + 500 in that second.
    let counts: Vec<u8> = b
        .decoded(id::MOTION_FEEDBACK)
        .iter()
        .filter(|(t, _)| *t > start)
        .map(|(_, d)| d.count)
        .collect();
    assert_eq!(counts.len(), 550);
    for pair in counts.windows(2) {
        assert_eq!(pair[1], pair[0].wrapping_add(1));
    }
    b.inject(Injection::Flood { frames_per_s: 0 });
    let start = b.now;
    b.run_for(ms(1000));
    assert_eq!(b.sent_since(start), normal);
}

#[test]
fn the_battery_drains_with_the_current_and_its_voltage_dips_under_load() {
    let mut b = Bench::new();
    b.run_for(ms(100));
    let idle = b.status().battery_voltage_v;
    b.heartbeat(Some(drive(1.0, 0.0)));
    b.run_for(Duration::from_secs(600));
    // 5.6 A for 10 min from 15 Ah: 6.2 %.
    let soc = b.sim.truth().soc_pct;
    assert!((93.6..93.9).contains(&soc), "{soc}");
    let load = b.status().battery_voltage_v;
    // 21 + 8.2 · 0.937 − 0.03 · 5.6 = 28.51 V.
    assert_eq!((idle, load), (29.2, 28.5));
    let sim = V1Sim::new(V1Profile::default(), T0).with_soc_pct(5.0);
    assert_ne!(
        sim.truth().fault_flags & FaultFlags::BATTERY_UNDER_VOLTAGE,
        0
    );
}

#[test]
fn the_true_full_scale_is_the_profile_the_firmware_is_built_with() {
    let example = V1Profile {
        angular_full_scale_rad_s: 0.7853,
        ..V1Profile::default()
    };
    let mut b = Bench::with(V1Sim::new(example, T0).with_speed_time_constant_s(0.0), T0);
    // The manual's second example frame: 10 % of the angular full scale.
    b.send_raw(CanFrame::from_candump("130#0100000A00000044").unwrap());
    b.run_for(ms(20));
    assert!((b.sim.truth().angular_radps - 0.07853).abs() < 1e-12);
    let Frame::MotionFeedback(m) = b.last(id::MOTION_FEEDBACK) else {
        panic!()
    };
    assert_eq!(m.angular_radps, 0.079);
}

fn arbitrary_frame() -> impl Strategy<Value = (bool, u32, Vec<u8>, u64)> {
    (
        any::<bool>(),
        prop_oneof![0u32..0x800, Just(0x130u32), Just(0x140)],
        proptest::collection::vec(any::<u8>(), 0..=8),
        0u64..700,
    )
}

proptest! {
    #[test]
    fn arbitrary_can_frames_never_panic_the_firmware(
        frames in proptest::collection::vec(arbitrary_frame(), 1..60),
        injections in proptest::collection::vec((0u8..8, any::<u8>()), 0..6),
    ) {
        let mut sim = V1Sim::new(V1Profile::default(), T0);
        let mut now = T0;
        for (i, (extended, frame_id, mut data, gap_ms)) in frames.into_iter().enumerate() {
            let arrival = now + Duration::from_millis(gap_ms);
            // Serve every deadline up to the frame's arrival, each at its own time.
            while let Some(t) = sim.poll_timeout().filter(|t| *t <= arrival) {
                prop_assert!(t >= now, "deadline in the past");
                now = t;
                sim.handle_timeout(now);
                prop_assert!(sim.poll_timeout().is_some_and(|next| next > now));
                while sim.poll_transmit(now).is_some() {}
            }
            now = arrival;
            // Half the 8-byte frames get a valid checksum, so the payload checks are reached.
            if data.len() == 8 && data[0] % 2 == 0 && frame_id <= 0x7FF {
                data[7] = checksum(frame_id as u16, &data[..7]);
            }
            let frame = if extended {
                CanFrame::new_extended(frame_id, &data).unwrap()
            } else {
                CanFrame::new(frame_id, &data).unwrap()
            };
            sim.handle_rx(now, Rx::Can(&frame));
            if let Some((kind, value)) = injections.get(i).copied() {
                let injection = match kind {
                    0 => Injection::MotorDriverLoss { motor: value % 6, lost: value % 2 == 0 },
                    1 => Injection::Battery { soc_pct: f64::from(value) },
                    2 => Injection::BadChecksums(u32::from(value % 20)),
                    3 => Injection::RcTakeover(value % 2 == 0),
                    4 => Injection::Reboot,
                    5 => Injection::Silence(Duration::from_millis(u64::from(value))),
                    6 => Injection::Garbage(vec![value; usize::from(value % 20)]),
                    _ => Injection::Flood { frames_per_s: u32::from(value % 10) * 10 },
                };
                sim.inject(now, injection);
            }
            if sim.poll_timeout().is_some_and(|t| t <= now) {
                sim.handle_timeout(now);
            }
            prop_assert!(sim.poll_timeout().is_some_and(|next| next > now));
            while sim.poll_transmit(now).is_some() {}
            let truth = sim.truth();
            prop_assert!(truth.linear_mps.abs() <= 5.0 + 1e-9);
            prop_assert!(truth.angular_radps.abs() <= 0.5235 + 1e-9);
            prop_assert!((0.0..=100.0).contains(&truth.soc_pct));
        }
    }
}
