//! The simulated TITAN firmware alone, fed frames through the codec on simulated time.

use std::collections::BTreeMap;
use std::time::Duration;

use chassis_interfaces::{ControlMode, FaultFlags};

use super::TitanSim;
use crate::can::CanFrame;
use crate::driver::Rx;
use crate::firmware::{Firmware, Injection};
use crate::sim_bench::BenchFirmware;
use crate::time::Timestamp;
use crate::titan::BmsData;
use crate::titan::TitanProfile;
use crate::titan::{
    ClearFault, Frame, ModeCommand, MotionCommand, ParkingBrake, Switch, SystemStatus, clear_code,
    decode, fault, id, mode,
};

const T0: Timestamp = Timestamp::from_millis(1_000);

fn ms(v: u64) -> Duration {
    Duration::from_millis(v)
}

fn motion(linear_mps: f64, steer_rad: f64) -> MotionCommand {
    MotionCommand {
        linear_mps,
        steer_rad,
    }
}

/// The firmware on simulated time, with an optional 20 ms 0x111 heartbeat from "the computer".
type Bench = crate::sim_bench::Bench<TitanSim>;

impl BenchFirmware for TitanSim {
    type Item = CanFrame;
    type Command = MotionCommand;
    type Profile = TitanProfile;
    const HEARTBEAT_PERIOD: Duration = Duration::from_millis(20);

    fn bench_profile(&self) -> &TitanProfile {
        self.profile()
    }

    fn send_heartbeat(bench: &mut Bench, command: MotionCommand) {
        bench.send(Frame::MotionCommand(command));
    }
}

impl Bench {
    fn new() -> Self {
        Self::with(TitanSim::new(TitanProfile::default(), T0), T0)
    }

    /// Asks for control mode `mode` (0x421).
    fn ask_mode(&mut self, mode: u8) {
        self.send(Frame::Mode(ModeCommand { mode }));
    }

    /// In CAN command mode with the brake released.
    fn driving() -> Self {
        let mut b = Self::new();
        b.ask_mode(mode::CAN_COMMAND);
        b.send(Frame::ParkingBrake(ParkingBrake { engage: false }));
        b
    }

    /// [`Bench::driving`] with `command` as the 0x111 heartbeat for `warm_up`.
    fn moving(command: MotionCommand, warm_up: Duration) -> Self {
        let mut b = Self::driving();
        b.heartbeat(Some(command));
        b.run_for(warm_up);
        b
    }

    fn send(&mut self, frame: Frame) {
        let can = frame.encode(&self.profile).unwrap();
        self.send_raw(can);
    }

    fn send_raw(&mut self, can: CanFrame) {
        self.sim.handle_rx(self.now, Rx::Can(&can));
        self.drain();
    }

    /// The latest frame with id `frame_id` the chassis sent, as it went on the wire.
    fn last_raw(&self, frame_id: u16) -> CanFrame {
        self.sent
            .iter()
            .rev()
            .find(|(_, f)| f.id() == u32::from(frame_id))
            .unwrap()
            .1
    }

    fn decoded(&self, frame_id: u16) -> Vec<(Timestamp, Frame)> {
        self.sent
            .iter()
            .filter(|(_, f)| f.id() == u32::from(frame_id))
            .map(|(t, f)| (*t, decode(f, &self.profile).unwrap()))
            .collect()
    }

    fn last(&self, frame_id: u16) -> Frame {
        self.decoded(frame_id).last().unwrap().1
    }

    /// The fault word of the latest 0x211.
    fn faults(&self) -> u32 {
        self.status().vendor_fault_word
    }

    fn status(&self) -> SystemStatus {
        let Frame::SystemStatus(s) = self.last(id::SYSTEM_STATUS) else {
            panic!()
        };
        s
    }
}

#[test]
fn the_chassis_starts_in_standby_and_ignores_motion_commands() {
    let mut b = Bench::new();
    b.run_for(ms(100));
    let s = b.status();
    assert_eq!(
        (s.mode, s.body_status, s.vendor_fault_word),
        (mode::STANDBY, 0, 0)
    );
    assert!(
        s.battery_voltage_v > 51.0 && s.battery_voltage_v <= 52.0,
        "{s:?}"
    );
    let t = b.sim.truth();
    assert_eq!(t.control_mode, ControlMode::STANDBY);
    assert!(t.brake_engaged);
    assert!(t.soc_pct > 99.99 && t.soc_pct <= 100.0, "{}", t.soc_pct);
    assert!(b.decoded(id::RC).is_empty(), "no transmitter at power-up");

    b.send(Frame::ParkingBrake(ParkingBrake { engage: false }));
    b.heartbeat(Some(motion(1.0, 0.0)));
    b.run_for(ms(1000));
    let t = b.sim.truth();
    assert_eq!(t.linear_mps, 0.0);
    assert!(t.brake_engaged, "standby ignores the brake frame");
    assert_eq!(t.commands_received, 0);
    assert!(b.sim.truth().commands_ignored > 40);
    assert_eq!(b.faults(), 0, "no heartbeat is expected in standby");
}

#[test]
fn can_command_mode_moves_the_robot_only_after_the_brake_is_released() {
    let mut b = Bench::new();
    b.ask_mode(mode::CAN_COMMAND);
    b.heartbeat(Some(motion(0.5, 0.0)));
    b.run_for(ms(1000));
    assert_eq!(b.status().mode, mode::CAN_COMMAND);
    assert_eq!(b.sim.truth().control_mode, ControlMode::COMMAND);
    assert_eq!(b.v(), 0.0, "the parking brake is still engaged");

    b.send(Frame::ParkingBrake(ParkingBrake { engage: false }));
    b.run_for(ms(3000));
    assert!((b.v() - 0.5).abs() < 1e-3, "{}", b.v());
    assert!(!b.sim.truth().brake_engaged);

    b.send(Frame::ParkingBrake(ParkingBrake { engage: true }));
    b.run_for(ms(1000));
    assert!(b.v().abs() < 1e-3, "engaging the brake stops the robot");
}

#[test]
fn speed_follows_a_first_order_response_and_the_odometers_advance() {
    let mut b = Bench::moving(motion(1.0, 0.0), ms(300));
    // One time constant: 1 - 1/e.
    assert!((b.v() - (1.0 - (-1.0f64).exp())).abs() < 0.01, "{}", b.v());
    b.run_for(ms(3000));
    assert!((b.v() - 1.0).abs() < 1e-3);

    // ∫(1 - e^(-t/τ)) dt over 3.3 s = 3.3 - 0.3·(1 - e^-11).
    let expected = 3.3 - 0.3 * (1.0 - (-11.0f64).exp());
    let Frame::Odometer(o) = b.last(id::ODOMETER) else {
        panic!()
    };
    assert!((o.front_distance_m - expected).abs() < 0.03, "{o:?}");
    assert!((o.rear_distance_m - expected).abs() < 0.03, "{o:?}");
    assert!((b.sim.truth().x_m - expected).abs() < 0.01);
    assert!(b.sim.truth().y_m.abs() < 1e-9);

    let Frame::MotionFeedback(m) = b.last(id::MOTION_FEEDBACK) else {
        panic!()
    };
    assert!((m.linear_mps - 1.0).abs() < 0.002);
    let Frame::MotorFast(m1) = b.last(id::MOTOR_FAST_1) else {
        panic!()
    };
    let rpm = 60.0 * TitanSim::GEAR_RATIO / (std::f64::consts::TAU * TitanSim::WHEEL_RADIUS_M);
    assert!((m1.rpm - rpm).abs() <= 1.0, "{m1:?}");
    let counts = expected * TitanSim::GEAR_RATIO * TitanSim::ENCODER_PULSES_PER_REV
        / (std::f64::consts::TAU * TitanSim::WHEEL_RADIUS_M);
    assert!(
        (f64::from(m1.position_counts) - counts).abs() < 1500.0,
        "{m1:?}"
    );
    assert!(m1.current_a > 2.0, "{m1:?}");
}

#[test]
fn a_missing_heartbeat_faults_to_standby_and_command_mode_returns_when_it_resumes() {
    let mut b = Bench::moving(motion(0.5, 0.0), ms(2000));
    b.heartbeat(None);
    let last = b.last_heartbeat.unwrap();
    b.run_for((last + ms(500)).saturating_since(b.now));
    assert_eq!(
        b.sim.truth().control_mode,
        ControlMode::COMMAND,
        "500 ms is still in time"
    );
    b.run_for(ms(1));
    let t = b.sim.truth();
    assert_eq!(t.control_mode, ControlMode::STANDBY);
    assert_ne!(t.fault_flags & FaultFlags::HEARTBEAT_LOST, 0);
    b.run_for(ms(1000));
    let s = b.status();
    assert_eq!(s.mode, mode::STANDBY);
    assert_ne!(s.vendor_fault_word & fault::HEARTBEAT_LOST, 0);
    assert_eq!(s.body_status, 0x02);
    assert!(b.v().abs() < 1e-3, "the robot stops in standby");

    // The heartbeat resumes: fault gone, CAN command mode back, no 0x421 or brake frame needed.
    b.heartbeat(Some(motion(0.5, 0.0)));
    b.run_for(ms(1));
    let t = b.sim.truth();
    assert_eq!(t.control_mode, ControlMode::COMMAND);
    assert_eq!(t.fault_flags & FaultFlags::HEARTBEAT_LOST, 0);
    b.run_for(ms(3000));
    assert!((b.v() - 0.5).abs() < 1e-3);
    assert_eq!(b.faults(), 0);
}

#[test]
fn an_explicit_standby_is_not_undone_by_the_heartbeat() {
    let mut b = Bench::moving(motion(0.5, 0.0), ms(1000));
    b.ask_mode(mode::STANDBY);
    b.run_for(ms(2000));
    assert_eq!(b.sim.truth().control_mode, ControlMode::STANDBY);
    assert!(b.v().abs() < 1e-3);
    assert_eq!(b.faults(), 0, "standby on request is no fault");
}

#[test]
fn an_rc_takeover_reports_remote_mode_and_ignores_can_commands() {
    let mut b = Bench::moving(motion(1.0, 0.0), ms(2000));
    assert!(b.decoded(id::RC).is_empty());
    let received = b.sim.truth().commands_received;

    assert!(b.inject(Injection::RcTakeover(true)));
    let since = b.now;
    b.ask_mode(mode::CAN_COMMAND);
    b.run_for(ms(1000));
    assert_eq!(b.status().mode, mode::REMOTE);
    assert_eq!(b.sim.truth().control_mode, ControlMode::REMOTE);
    assert!(b.v().abs() < 1e-3, "sticks centred: the robot stops");
    assert_eq!(
        b.sim.truth().commands_received,
        received,
        "CAN commands are ignored"
    );
    let rc: Vec<_> = b
        .decoded(id::RC)
        .into_iter()
        .filter(|(t, _)| *t >= since)
        .collect();
    assert_eq!(rc.len(), 50);
    for pair in rc.windows(2) {
        let (Frame::Rc(a), Frame::Rc(c)) = (pair[0].1, pair[1].1) else {
            panic!()
        };
        assert_eq!(a.switch_b, 1, "SWB in the middle: remote control");
        assert_eq!(c.counter, a.counter.wrapping_add(1), "rolling counter");
        assert_eq!(pair[1].0.saturating_since(pair[0].0), ms(20));
    }

    // Transmitter off: standby, the driver must ask for CAN command mode again.
    assert!(b.inject(Injection::RcTakeover(false)));
    let off = b.now;
    b.run_for(ms(500));
    assert_eq!(b.sim.truth().control_mode, ControlMode::STANDBY);
    assert!(b.decoded(id::RC).iter().all(|(t, _)| *t <= off));
    assert_eq!(b.sim.truth().fault_flags, 0);
    b.ask_mode(mode::CAN_COMMAND);
    b.run_for(ms(2000));
    assert_eq!(b.sim.truth().control_mode, ControlMode::COMMAND);
    assert!((b.v() - 1.0).abs() < 0.01, "the brake stayed released");
}

#[test]
fn a_reboot_goes_quiet_then_powers_up_in_standby_with_the_brake_engaged() {
    let mut b = Bench::moving(motion(1.0, 0.0), ms(2000));
    b.heartbeat(Some(motion(0.0, 0.0)));
    b.run_for(ms(2000));
    b.heartbeat(None);
    let Frame::Odometer(o) = b.last(id::ODOMETER) else {
        panic!()
    };
    assert!(o.front_distance_m > 1.0);

    assert!(b.inject(Injection::Reboot));
    let reboot = b.now;
    let t = b.sim.truth();
    assert_eq!(
        (t.boots, t.control_mode, t.brake_engaged),
        (1, ControlMode::STANDBY, true)
    );
    b.run_for(ms(100));
    b.ask_mode(mode::CAN_COMMAND);
    b.run_for(ms(199));
    assert_eq!(b.sent_since(reboot), 0, "silent while booting");
    b.run_for(ms(1));
    assert!(b.sent_since(reboot) > 0, "feedback resumes after 300 ms");
    b.run_for(ms(200));
    let first = b.sent.iter().find(|(t, _)| *t > reboot).unwrap().0;
    assert_eq!(first, reboot + TitanSim::DEFAULT_BOOT_TIME);
    let s = b.status();
    assert_eq!(
        (s.mode, s.vendor_fault_word),
        (mode::STANDBY, 0),
        "the 0x421 sent while booting was lost"
    );
    let Frame::Odometer(o) = b.last(id::ODOMETER) else {
        panic!()
    };
    assert_eq!((o.front_distance_m, o.rear_distance_m), (0.0, 0.0));
    let Frame::MotorFast(m) = b.last(id::MOTOR_FAST_1) else {
        panic!()
    };
    assert!(m.position_counts.abs() < 5, "{m:?}");
    assert!(b.sim.truth().brake_engaged);
}

#[test]
fn feedback_periods_are_exactly_20_100_and_500_ms() {
    let mut b = Bench::driving();
    b.inject(Injection::RcTakeover(true));
    b.run_for(ms(10_000));
    let end = T0 + ms(10_000);
    let mut count: BTreeMap<u32, usize> = BTreeMap::new();
    for (t, f) in &b.sent {
        if *t < end {
            *count.entry(f.id()).or_default() += 1;
        }
    }
    let expect = |ids: &[u16], n: usize| {
        for i in ids {
            assert_eq!(count.get(&u32::from(*i)).copied(), Some(n), "0x{i:03X}");
        }
    };
    expect(
        &[
            0x211, 0x221, 0x241, 0x251, 0x252, 0x253, 0x254, 0x271, 0x281, 0x311,
        ],
        500,
    );
    expect(&[0x261, 0x262, 0x263, 0x264], 100);
    expect(&[0x361, 0x362, 0x363, 0x364, 0x365, 0x366], 20);
    assert_eq!(count.len(), 20, "{count:?}");
    for (frame_id, period) in [(0x211, 20), (0x261, 100), (0x361, 500)] {
        let times: Vec<_> = b.decoded(frame_id).into_iter().map(|(t, _)| t).collect();
        assert_eq!(times[0], T0);
        for pair in times.windows(2) {
            assert_eq!(pair[1].saturating_since(pair[0]), ms(period));
        }
    }
}

#[test]
fn silent_mode_stops_every_transmission_until_it_is_left() {
    let mut b = Bench::moving(motion(0.5, 0.0), ms(100));
    b.send(Frame::SilentMode(Switch { enter: true }));
    let quiet = b.now;
    b.run_for(ms(2000));
    assert_eq!(b.sent_since(quiet), 0);
    assert!(b.sim.silent_mode());
    assert!((b.v() - 0.5).abs() < 0.01, "commands are still obeyed");
    b.send(Frame::SilentMode(Switch { enter: false }));
    let back = b.now;
    b.run_for(ms(20));
    assert!(b.decoded(id::SYSTEM_STATUS).iter().any(|(t, _)| *t > back));
}

#[test]
fn the_steering_zero_request_is_acknowledged_after_50_ms() {
    let mut b = Bench::new();
    b.send(Frame::SteeringZero);
    b.run_for(ms(200));
    assert!(
        b.decoded(id::STEERING_ZERO_ACK).is_empty(),
        "standby ignores 0x431"
    );

    b.ask_mode(mode::CAN_COMMAND);
    b.heartbeat(Some(motion(0.0, 0.0)));
    b.run_for(ms(7));
    let asked = b.now;
    b.send(Frame::SteeringZero);
    b.run_for(ms(500));
    let acks = b.decoded(id::STEERING_ZERO_ACK);
    assert_eq!(acks, vec![(asked + ms(50), Frame::SteeringZeroAck)]);
    let raw = b.sent.iter().find(|(_, f)| f.id() == 0x43A).unwrap().1;
    assert_eq!(raw.data(), &[0xEE]);
}

#[test]
fn below_ten_percent_the_chassis_cuts_drive_and_reports_under_voltage() {
    let mut b = Bench::moving(motion(1.0, 0.0), ms(2000));

    assert!(b.inject(Injection::Battery { soc_pct: 14.0 }));
    b.run_for(ms(1000));
    let Frame::BmsAlarm(a) = b.last(0x362) else {
        panic!()
    };
    assert_ne!(a.warning_1 & 0b100, 0, "low-battery warning");
    assert_eq!(a.alarm_1, 0);
    let t = b.sim.truth();
    assert_ne!(t.fault_flags & FaultFlags::BATTERY_LOW, 0);
    assert_eq!(t.fault_flags & FaultFlags::BATTERY_UNDER_VOLTAGE, 0);
    assert!(
        (b.v() - 1.0).abs() < 0.01,
        "a warning does not stop the robot"
    );

    b.inject(Injection::Battery { soc_pct: 9.5 });
    b.run_for(ms(1000));
    assert!(b.v().abs() < 1e-3, "drive cut below 10 %");
    assert_ne!(b.faults() & fault::BATTERY_UNDER_VOLTAGE, 0);
    let Frame::BmsData(d) = b.last(0x361) else {
        panic!()
    };
    assert_eq!(d.soc_pct, 9.0);
    let Frame::BmsAlarm(a) = b.last(0x362) else {
        panic!()
    };
    assert_ne!(a.alarm_1 & 0b100, 0);
    assert_ne!(
        b.sim.truth().fault_flags & FaultFlags::BATTERY_UNDER_VOLTAGE,
        0
    );

    // Clearing fails while the battery is flat, and charging alone does not restore power.
    b.send(Frame::ClearFault(ClearFault {
        code: clear_code::BATTERY_UNDER_VOLTAGE,
    }));
    b.inject(Injection::Battery { soc_pct: 50.0 });
    b.send(Frame::ClearFault(ClearFault {
        code: clear_code::ALL_NON_SEVERE,
    }));
    b.run_for(ms(1000));
    assert!(b.v().abs() < 1e-3);
    assert_ne!(b.faults() & fault::BATTERY_UNDER_VOLTAGE, 0);

    b.send(Frame::ClearFault(ClearFault {
        code: clear_code::BATTERY_UNDER_VOLTAGE,
    }));
    b.run_for(ms(3000));
    assert_eq!(b.faults(), 0);
    assert!((b.v() - 1.0).abs() < 0.01, "power restored");
}

#[test]
fn the_bumper_stops_the_robot_while_pressed() {
    let mut b = Bench::moving(motion(1.0, 0.0), ms(2000));
    assert!(b.inject(Injection::Bumper(true)));
    b.run_for(ms(1000));
    assert!(b.v().abs() < 1e-3);
    assert_eq!(b.faults(), fault::BUMPER);
    assert_ne!(b.sim.truth().fault_flags & FaultFlags::BUMPER, 0);
    b.inject(Injection::Bumper(false));
    b.run_for(ms(3000));
    assert_eq!(b.faults(), 0);
    assert!((b.v() - 1.0).abs() < 0.01);
}

#[test]
fn a_lost_motor_driver_stops_drive_and_its_frames_until_cleared() {
    let mut b = Bench::moving(motion(1.0, 0.0), ms(2000));
    assert!(b.inject(Injection::MotorDriverLoss {
        motor: 2,
        lost: true
    }));
    let lost = b.now;
    b.send(Frame::ClearFault(ClearFault { code: 0x02 }));
    b.run_for(ms(1000));
    assert!(b.v().abs() < 1e-3);
    assert_eq!(b.faults(), fault::MOTOR_2_COMM_LOST);
    for (frame_id, present) in [(0x251, true), (0x252, false), (0x262, false), (0x263, true)] {
        let any = b.decoded(frame_id).iter().any(|(t, _)| *t > lost);
        assert_eq!(any, present, "0x{frame_id:03X}");
    }

    b.inject(Injection::MotorDriverLoss {
        motor: 2,
        lost: false,
    });
    let back = b.now;
    b.run_for(ms(1000));
    assert!(b.decoded(0x252).iter().any(|(t, _)| *t > back));
    assert_eq!(b.faults(), fault::MOTOR_2_COMM_LOST, "latched");
    assert!(b.v().abs() < 1e-3);
    b.send(Frame::ClearFault(ClearFault { code: 0x02 }));
    b.run_for(ms(3000));
    assert_eq!(b.faults(), 0);
    assert!((b.v() - 1.0).abs() < 0.01);

    for motor in [0, 5] {
        assert!(!b.inject(Injection::MotorDriverLoss { motor, lost: true }));
    }
}

#[test]
fn out_of_range_commands_are_clamped_and_counted() {
    let mut b = Bench::moving(motion(5.0, 0.0), ms(4000));
    assert!((b.v() - 3.0).abs() < 1e-3, "{}", b.v());
    assert!(b.sim.commands_clamped() > 100);
    b.heartbeat(Some(motion(2.5, 0.2)));
    b.run_for(ms(4000));
    assert!((b.v() - 1.5).abs() < 1e-3, "{}", b.v());
    assert!((b.sim.truth().steer_rad - 0.2).abs() < 1e-9);
    b.heartbeat(Some(motion(1.0, -0.5)));
    b.run_for(ms(2000));
    assert!((b.sim.truth().steer_rad + 0.367).abs() < 1e-9);
    let clamped = b.sim.commands_clamped();
    b.heartbeat(Some(motion(1.0, 0.3)));
    b.run_for(ms(1000));
    assert_eq!(
        b.sim.commands_clamped(),
        clamped,
        "valid commands are not clamped"
    );
}

#[test]
fn off_road_switches_only_while_standing_still() {
    let mut b = Bench::moving(motion(1.0, 0.0), ms(1000));
    b.send(Frame::OffRoad(Switch { enter: true }));
    assert!(!b.sim.off_road(), "ignored while moving");
    b.heartbeat(Some(motion(0.0, 0.0)));
    b.run_for(ms(3000));
    b.send(Frame::OffRoad(Switch { enter: true }));
    assert!(b.sim.off_road());
    b.send(Frame::OffRoad(Switch { enter: false }));
    assert!(!b.sim.off_road());
}

#[test]
fn steering_slews_and_is_reported_through_the_profile_sign() {
    let mut b = Bench::moving(motion(0.5, 0.2), ms(100));
    assert!((b.sim.truth().steer_rad - 0.1).abs() < 1e-9, "1 rad/s slew");
    b.run_for(ms(2000));
    let t = b.sim.truth();
    assert!((t.steer_rad - 0.2).abs() < 1e-12);
    assert!(
        t.angular_radps > 0.0 && t.y_m > 0.0 && t.yaw_rad > 0.0,
        "a left turn yaws left"
    );

    let Frame::MotionFeedback(m) = b.last(id::MOTION_FEEDBACK) else {
        panic!()
    };
    assert!((m.steer_rad - 0.2).abs() < 1e-9, "decoded left positive");
    let Frame::SteeringFeedback(s) = b.last(id::STEERING_FEEDBACK) else {
        panic!()
    };
    assert_eq!(
        (s.front_steer_rad, s.rear_steer_rad),
        (0.2, -0.2),
        "rear steers opposite"
    );
    // Default profile: the wire reports a left turn negative.
    let raw = b.last_raw(0x221);
    assert_eq!(&raw.data()[6..8], &(-200i16).to_be_bytes());
    let raw = b.last_raw(0x271);
    assert_eq!(&raw.data()[0..4], &[0xFF, 0x38, 0x00, 0xC8]);

    // The tight-turn inner wheels are slower than the outer ones.
    let Frame::AxleSpeed(a) = b.last(id::AXLE_SPEED) else {
        panic!()
    };
    assert!(a.front_axle_mps > 0.5 && (a.front_axle_mps - a.rear_axle_mps).abs() < 1e-9);
    let rpm = |m: u16| match b.last(m) {
        Frame::MotorFast(f) => f.rpm,
        _ => panic!(),
    };
    assert!(
        rpm(0x251) < rpm(0x252),
        "left wheels are inside a left turn"
    );

    let flipped = TitanProfile {
        steering_feedback_left_positive: true,
        ..TitanProfile::default()
    };
    let mut b = Bench::with(TitanSim::new(flipped, T0).with_steer_rate_radps(0.0), T0);
    b.ask_mode(mode::CAN_COMMAND);
    b.heartbeat(Some(motion(0.0, 0.2)));
    b.run_for(ms(100));
    let raw = b.last_raw(0x221);
    assert_eq!(&raw.data()[6..8], &200i16.to_be_bytes());
}

#[test]
fn malformed_frames_and_another_nodes_feedback_are_counted_and_ignored() {
    let mut b = Bench::new();
    for text in ["7F0#0102", "421#05", "111#01", "441#07", "131#"] {
        b.send_raw(CanFrame::from_candump(text).unwrap());
    }
    b.send_raw(CanFrame::new_extended(0x111, &[0; 8]).unwrap());
    let t = b.sim.truth();
    assert_eq!(t.decode_errors, 6);
    assert_eq!(t.commands_received, 0);

    // Another node's feedback is valid but not for the chassis.
    b.send(Frame::SystemStatus(SystemStatus::default()));
    assert_eq!(b.sim.truth().frames_ignored, 1);
    assert_eq!(b.sim.truth().decode_errors, 6);
    b.run_for(ms(100));
    assert_eq!(b.sim.truth().control_mode, ControlMode::STANDBY);
}

#[test]
fn injections_titan_lacks_are_refused() {
    let mut b = Bench::new();
    assert!(!b.inject(Injection::BadChecksums(3)));
    assert!(!b.inject(Injection::ObstacleAhead(Some(0.5))));
    assert!(!b.inject(Injection::ObstacleBehind(None)));
}

#[test]
fn the_battery_drains_visibly_and_its_voltage_dips_under_load() {
    let mut b = Bench::driving();
    b.run_for(ms(1000));
    let Frame::BmsData(idle) = b.last(0x361) else {
        panic!()
    };
    b.heartbeat(Some(motion(1.0, 0.0)));
    b.run_for(Duration::from_secs(600));
    // 12 A for 10 min from one 24 Ah battery: 8.3 %.
    let soc = b.sim.truth().soc_pct;
    assert!((91.0..92.5).contains(&soc), "{soc}");
    let Frame::BmsData(load) = b.last(0x361) else {
        panic!()
    };
    assert!(load.voltage_v < idle.voltage_v - 0.5, "{idle:?} {load:?}");
    assert!((load.current_a - 12.0).abs() < 0.2, "{load:?}");
    assert_eq!(
        b.last(0x365),
        Frame::BmsData(BmsData {
            group: 2,
            ..Default::default()
        }),
        "battery 2 not fitted"
    );

    let mut b = Bench::with(
        TitanSim::new(TitanProfile::default(), T0).with_batteries(2),
        T0,
    );
    b.run_for(ms(600));
    let (Frame::BmsData(pack), Frame::BmsData(second)) = (b.last(0x361), b.last(0x365)) else {
        panic!()
    };
    assert!((second.current_a - pack.current_a / 2.0).abs() < 0.06);
    assert_eq!(second.soc_pct, pack.soc_pct);
}
