//! The XBot driver alone, fed hand-built byte streams on simulated time.

use std::f64::consts::{FRAC_PI_2, PI};
use std::time::Duration;

use chassis_interfaces::{
    ClampFlags, ControlMode, Group, LinkFlags, ValidRequest, Velocity, VelocityRequest,
};
use proptest::prelude::*;

use super::*;
use crate::command::Command;
use crate::driver::{ControlOutcome, Driver, DriverConfig, DriverEvent, Level, Rx, WireItem};
use crate::frame_json::frame_name;
use crate::time::Timestamp;
use crate::xbot::XbotProfile;
use crate::xbot::test_support::{arbitrary_reads, close, hex, max_per_second, ms, p, twist};
use crate::xbot::{Frame, SensorReport, StreamParser, VelocityCommand, checksum};

const T0: Timestamp = Timestamp::from_millis(1_000);

/// A plausible report: level, nothing in view, wheels at `wheels`, board stamp `stamp_us`.
fn report(wheels: [u16; 4], stamp_us: u16) -> SensorReport {
    SensorReport {
        battery_voltage_v: 25.5,
        ir_m: [0.8; 3],
        ultrasonic_m: [6.0; 3],
        motor_current_a: [0.3, 0.3, 0.0, 0.0],
        lift_current_a: 0.0,
        encoder_counts: wheels,
        lift_encoder_counts: 0,
        accel_mps2: [0.0, 0.0, 9.806_65],
        gyro_radps: [0.0; 3],
        mag_gauss: [0.3, 0.0, -0.4],
        temperature_c: 31.5,
        roll_rad: 0.0,
        pitch_rad: 0.0,
        yaw_rad: 0.0,
        sensor_stamp_us: stamp_us,
    }
}

/// The driver on simulated time; everything it sends is decoded and kept.
struct Bench {
    d: XbotDriver,
    profile: XbotProfile,
    now: Timestamp,
    sent: Vec<(Timestamp, Frame)>,
    raw: Vec<(Timestamp, Vec<u8>)>,
    events: Vec<DriverEvent>,
}

impl Bench {
    fn new() -> Self {
        Self::with(p(), DriverConfig::default())
    }

    fn with(profile: XbotProfile, config: DriverConfig) -> Self {
        let mut b = Self {
            d: XbotDriver::new(profile.clone(), config, T0),
            profile,
            now: T0,
            sent: Vec::new(),
            raw: Vec::new(),
            events: Vec::new(),
        };
        b.drain();
        b
    }

    fn drain(&mut self) {
        while let Some(item) = self.d.poll_transmit(self.now) {
            let WireItem::Bytes(bytes) = item else {
                panic!("the XBot driver sent a CAN frame");
            };
            let mut parser = StreamParser::new();
            parser.push(&bytes);
            let frame = parser.next_frame(&self.profile).unwrap().unwrap();
            assert!(
                parser.next_frame(&self.profile).is_none(),
                "one frame per item"
            );
            self.sent.push((self.now, frame));
            self.raw.push((self.now, bytes));
        }
        while let Some(event) = self.d.poll_event() {
            self.events.push(event);
        }
    }

    fn run_until(&mut self, until: Timestamp) {
        loop {
            let next = self
                .d
                .poll_timeout()
                .unwrap_or(Timestamp::from_nanos(u64::MAX));
            assert!(next >= self.now, "deadline {next:?} before {:?}", self.now);
            if next > until {
                self.now = until;
                break;
            }
            self.now = next;
            self.d.handle_timeout(self.now);
            self.drain();
            if self.d.poll_timeout().is_some_and(|t| t <= self.now) {
                panic!("stall at {:?}", self.now);
            }
        }
        self.drain();
    }

    fn run_for(&mut self, duration: Duration) {
        self.run_until(self.now + duration);
    }

    fn set(&mut self, command: Velocity) {
        self.d.set_command(self.now, &command);
        self.drain();
    }

    /// 0.8 m/s then standstill, alternating every millisecond for `millis` ms (a stop-and-go
    /// storm that fills the change window).
    fn stop_and_go(&mut self, millis: u32) {
        for i in 0..millis {
            let vx = if i % 2 == 0 { 0.8 } else { 0.0 };
            self.set(twist(vx, 0.0, 0.0));
            self.run_for(ms(1));
        }
    }

    fn control(&mut self, command: Command) -> ControlOutcome {
        let outcome = self.d.control(self.now, &command);
        self.drain();
        outcome
    }

    fn bytes(&mut self, bytes: &[u8]) {
        self.d.handle_rx(self.now, Rx::Bytes(bytes));
        self.drain();
    }

    fn feed(&mut self, report: &SensorReport) {
        let bytes = Frame::Sensor(*report).encode(&self.profile).unwrap();
        self.bytes(&bytes);
    }

    /// `n` reports 20 ms apart (time advancing), wheels moving by `step` counts each; returns
    /// the last wheel counts fed.
    fn reports(&mut self, n: usize, start: [u16; 4], step: [i16; 4]) -> [u16; 4] {
        let mut wheels = start;
        let mut stamp: u16 = 1_000;
        for i in 0..n {
            if i > 0 {
                for (w, s) in wheels.iter_mut().zip(step) {
                    *w = w.wrapping_add_signed(s);
                }
            }
            self.feed(&report(wheels, stamp));
            self.run_for(ms(20));
            stamp = stamp.wrapping_add(20_000);
        }
        wheels
    }

    fn velocities(&self) -> Vec<(Timestamp, VelocityCommand)> {
        self.sent
            .iter()
            .filter_map(|(t, f)| match f {
                Frame::Velocity(v) => Some((*t, *v)),
                _ => None,
            })
            .collect()
    }

    fn powers(&self) -> Vec<(Timestamp, bool)> {
        self.sent
            .iter()
            .filter_map(|(t, f)| match f {
                Frame::Power(p) => Some((*t, p.enable)),
                _ => None,
            })
            .collect()
    }

    fn notices(&self, level: Level) -> Vec<String> {
        self.events
            .iter()
            .filter_map(|e| match e {
                DriverEvent::Notice { level: l, message } if *l == level => Some(message.clone()),
                _ => None,
            })
            .collect()
    }

    fn state(&self) -> &chassis_interfaces::ChassisState {
        self.d.state()
    }
}

// ---------------------------------------------------------------------------------------------
// Heartbeat and the rate bound.

#[test]
fn power_enable_and_a_zero_heartbeat_go_out_at_start_then_every_125_ms() {
    let mut b = Bench::new();
    assert_eq!(
        b.raw[0],
        (T0, hex("AA 55 02 01 01 02")),
        "the manual's power on"
    );
    assert_eq!(
        b.raw[1],
        (
            T0,
            hex("AA 55 0D 03 00 00 00 00 00 00 00 00 00 00 00 00 0E")
        ),
        "explicit zeros"
    );
    b.run_for(ms(1000));
    let times: Vec<_> = b.velocities().iter().map(|(t, _)| *t).collect();
    assert_eq!(times.len(), 9);
    for (k, t) in times.iter().enumerate() {
        assert_eq!(*t, T0 + ms(125 * k as u64));
    }
    assert!(
        b.velocities()
            .iter()
            .all(|(_, v)| *v == VelocityCommand::default())
    );
    assert_eq!(b.powers(), vec![(T0, true)]);
    let s = b.state();
    assert_eq!(s.system.power_enabled, 1);
    assert_eq!(s.system.control_mode, ControlMode::COMMAND);
    assert!(s.has_link_flag(LinkFlags::COMMAND_MODE));
    assert!(
        !s.is_valid(Group::System),
        "no report yet: the battery voltage is no reading"
    );
    assert!(s.is_valid(Group::Command));
    assert_eq!(s.link.tx_frames, 10);
}

#[test]
fn without_take_control_no_power_frame_is_sent_and_the_power_state_is_unknown() {
    let config = DriverConfig {
        take_control: false,
        ..DriverConfig::default()
    };
    let mut b = Bench::with(p(), config);
    b.run_for(ms(500));
    assert!(b.powers().is_empty());
    assert_eq!(b.velocities().len(), 5, "the heartbeat runs regardless");
    assert_eq!(b.state().system.control_mode, ControlMode::UNKNOWN);
    assert_eq!(b.state().system.power_enabled, 0);
    b.set(twist(0.4, 0.0, 0.0));
    b.run_for(ms(5));
    assert_eq!(
        b.velocities().last().unwrap().1.linear_x_mps,
        0.4f32 as f64,
        "power is not ours to manage, the command goes out"
    );
}

#[test]
fn a_heartbeat_rate_outside_5_to_10_hz_is_kept_but_warned_about() {
    let profile = XbotProfile {
        heartbeat_hz: 20.0,
        ..p()
    };
    let mut b = Bench::with(profile, DriverConfig::default());
    assert_eq!(b.notices(Level::Warn).len(), 1, "{:?}", b.events);
    b.run_for(ms(1000));
    assert_eq!(b.velocities().len(), 21);
    b.set(twist(0.5, 0.0, 0.0));
    assert_eq!(
        b.velocities().last().unwrap().1.linear_x_mps,
        0.0,
        "no room for a change frame: it rides the next heartbeat"
    );
    b.run_for(ms(50));
    assert_eq!(b.velocities().last().unwrap().1.linear_x_mps, 0.5);
}

#[test]
fn an_unusable_heartbeat_rate_falls_back_to_8_hz() {
    for hz in [0.0, -3.0, f64::NAN, f64::INFINITY, 1e-320] {
        let profile = XbotProfile {
            heartbeat_hz: hz,
            ..p()
        };
        let b = Bench::with(profile, DriverConfig::default());
        let warnings = b.notices(Level::Warn);
        assert_eq!(warnings.len(), 1, "{hz}");
        assert!(warnings[0].ends_with("sending at 8 Hz"), "{warnings:?}");
        let mut b = b;
        b.run_for(ms(1000));
        assert_eq!(b.velocities().len(), 9, "{hz}");
    }
}

#[test]
fn a_changed_command_goes_out_at_once_without_moving_the_heartbeat_grid() {
    let mut b = Bench::new();
    b.run_for(ms(10));
    b.set(twist(0.5, 0.0, 0.0));
    b.run_for(ms(300));
    let v: Vec<_> = b
        .velocities()
        .iter()
        .map(|(t, v)| (t.saturating_since(T0), v.linear_x_mps))
        .collect();
    assert_eq!(
        v,
        vec![(ms(0), 0.0), (ms(10), 0.5), (ms(125), 0.5), (ms(250), 0.5)]
    );
    let echo = b.state().command;
    assert_eq!((echo.linear_mps, echo.clamp_flags), (0.5, 0));
}

#[test]
fn a_command_changing_every_millisecond_never_puts_more_than_10_frames_in_a_second() {
    let mut b = Bench::new();
    for i in 0..3000u32 {
        let vx = 0.1 + 0.1 * (i % 7) as f32;
        b.set(twist(vx, 0.0, 0.0));
        b.run_for(ms(1));
    }
    let end = b.now;
    let velocities = b.velocities();
    let times: Vec<_> = velocities.iter().map(|(t, _)| *t).collect();
    assert!(
        max_per_second(&times) <= MAX_VELOCITY_FRAMES_PER_S,
        "{times:?}"
    );
    // Every heartbeat slot is served, and one change frame per second rides between them.
    let slots = (end.saturating_since(T0).as_millis() / 125 + 1) as usize;
    for k in 0..slots {
        assert!(times.contains(&(T0 + ms(125 * k as u64))), "slot {k}");
    }
    assert_eq!(times.len(), slots + 3, "{times:?}");
    // The latest command is on the wire within one heartbeat period.
    let last = *velocities.last().unwrap();
    assert!(end.saturating_since(last.0) <= ms(125));
}

#[test]
fn stop_and_go_alternating_every_millisecond_stays_within_the_bound() {
    let mut b = Bench::new();
    b.stop_and_go(3000);
    let times: Vec<_> = b.velocities().iter().map(|(t, _)| *t).collect();
    assert_eq!(
        max_per_second(&times),
        MAX_VELOCITY_FRAMES_PER_S,
        "{times:?}"
    );
}

#[test]
fn a_stop_after_a_flood_of_changes_still_goes_out_at_once() {
    let mut b = Bench::new();
    for i in 0..500u32 {
        b.set(twist(0.2 + 0.01 * (i % 10) as f32, 0.0, 0.0));
        b.run_for(ms(1));
    }
    b.run_for(ms(3));
    let frames_before = b.velocities().len();
    b.set(Velocity::ZERO);
    let (t, v) = *b.velocities().last().unwrap();
    assert_eq!(b.velocities().len(), frames_before + 1);
    assert_eq!((t, v), (b.now, VelocityCommand::default()));
    // Now the window is full: a new motion command waits for the heartbeat.
    b.run_for(ms(2));
    b.set(twist(0.3, 0.0, 0.0));
    assert_eq!(b.velocities().last().unwrap().1, VelocityCommand::default());
    let times: Vec<_> = b.velocities().iter().map(|(t, _)| *t).collect();
    assert!(max_per_second(&times) <= MAX_VELOCITY_FRAMES_PER_S);
}

// ---------------------------------------------------------------------------------------------
// Commands and clamp flags.

#[test]
fn limits_and_clamp_flags_are_echoed_with_what_went_on_the_wire() {
    let cases: [(Velocity, f64, f64, f64, u32); 5] = [
        (
            twist(2.0, 0.0, 0.0),
            1.5,
            0.0,
            0.0,
            ClampFlags::LINEAR_LIMIT,
        ),
        (
            twist(-2.0, 0.3, 0.0),
            -1.5,
            0.0,
            0.0,
            ClampFlags::LINEAR_LIMIT | ClampFlags::LATERAL_UNSUPPORTED,
        ),
        (
            twist(0.005, 0.0, 0.2),
            0.0,
            0.0,
            0.2f32 as f64,
            ClampFlags::QUANTISED,
        ),
        (
            twist(0.3, 0.0, 4.0),
            0.3f32 as f64,
            0.0,
            PI,
            ClampFlags::ANGULAR_LIMIT,
        ),
        (
            Velocity::steer(0.5, 0.2).unwrap(),
            0.0,
            0.0,
            0.0,
            ClampFlags::STEER_LIMIT,
        ),
    ];
    for (command, vx, vy, wz, flags) in cases {
        let mut b = Bench::new();
        b.run_for(ms(200));
        b.set(command);
        b.run_for(ms(125));
        let (_, v) = *b.velocities().last().unwrap();
        // The yaw rate crosses the wire in °/s as f32.
        assert_eq!((v.linear_x_mps, v.linear_y_mps), (vx, vy), "{command:?}");
        assert!(close(v.angular_z_radps, wz, 1e-6), "{command:?}: {v:?}");
        let echo = b.state().command;
        assert_eq!(echo.clamp_flags, flags, "{command:?}");
        assert_eq!(echo.linear_mps, vx as f32);
        assert_eq!(echo.angular_radps, wz as f32);
        assert_eq!(echo.steer_rad, 0.0);
    }
}

#[test]
fn a_steering_request_with_a_zero_angle_drives_straight() {
    let mut b = Bench::new();
    b.run_for(ms(10));
    // A request may carry a yaw rate beside its steering angle: the angle is what counts.
    let request = VelocityRequest {
        angular_z_radps: 0.7,
        ..VelocityRequest::steer(0.5, 0.0)
    };
    b.set(ValidRequest::try_from(request).unwrap().velocity());
    let (_, v) = *b.velocities().last().unwrap();
    assert_eq!((v.linear_x_mps, v.angular_z_radps), (0.5, 0.0));
    assert_eq!(b.state().command.clamp_flags, 0);
}

#[test]
fn an_omni_robot_keeps_the_lateral_speed_and_the_wire_carries_the_manuals_sign() {
    let profile = XbotProfile { omni: true, ..p() };
    let mut b = Bench::with(profile, DriverConfig::default());
    b.run_for(ms(10));
    b.set(twist(0.0, 0.2, 0.0));
    let (_, v) = *b.velocities().last().unwrap();
    assert_eq!(v.linear_y_mps, 0.2f32 as f64);
    assert_eq!(b.state().command.lateral_mps, 0.2);
    // Left is negative on the wire by default: the manual's "left 0.3 m/s" bytes (which hold 0.2).
    assert_eq!(
        b.raw.last().unwrap().1,
        hex("AA 55 0D 03 00 00 00 00 CD CC 4C BE 00 00 00 00 FD")
    );
}

// ---------------------------------------------------------------------------------------------
// Control actions.

#[test]
fn power_off_sends_zero_until_power_on_and_is_never_undone_by_the_driver() {
    let mut b = Bench::new();
    b.run_for(ms(10));
    b.set(twist(0.5, 0.0, 0.0));
    assert_eq!(b.velocities().last().unwrap().1.linear_x_mps, 0.5);
    b.run_for(ms(1100));

    let outcome = b.control(Command::Power { enable: false });
    assert!(matches!(outcome, ControlOutcome::Done(_)), "{outcome:?}");
    assert_eq!(
        b.raw[b.raw.len() - 2].1,
        hex("AA 55 02 01 00 03"),
        "the manual's power off"
    );
    assert_eq!(
        *b.velocities().last().unwrap(),
        (b.now, VelocityCommand::default())
    );
    let s = b.state();
    assert_eq!(
        (s.system.power_enabled, s.system.control_mode),
        (0, ControlMode::STANDBY)
    );
    assert!(!s.has_link_flag(LinkFlags::COMMAND_MODE));
    assert_eq!(s.command.clamp_flags, ClampFlags::CHASSIS_NOT_READY);
    let off = b.now;

    // A silence and the reports coming back do not re-enable power.
    b.reports(3, [0; 4], [0; 4]);
    b.run_for(ms(300));
    assert!(b.state().has_link_flag(LinkFlags::CHASSIS_SILENT));
    b.reports(3, [0; 4], [0; 4]);
    assert!(!b.state().has_link_flag(LinkFlags::CHASSIS_SILENT));
    assert_eq!(b.powers(), vec![(T0, true), (off, false)]);
    assert!(
        b.velocities()
            .iter()
            .filter(|(t, _)| *t >= off)
            .all(|(_, v)| v.linear_x_mps == 0.0)
    );

    // Power on: enable, then the command at once (the board forgot it).
    b.run_for(ms(1100));
    let before = b.sent.len();
    b.control(Command::Power { enable: true });
    let new: Vec<_> = b.sent[before..].iter().map(|(_, f)| *f).collect();
    assert_eq!(new.len(), 2, "{new:?}");
    assert!(matches!(new[0], Frame::Power(p) if p.enable));
    assert!(matches!(new[1], Frame::Velocity(v) if v.linear_x_mps == 0.5));
    assert_eq!(b.state().system.control_mode, ControlMode::COMMAND);
}

#[test]
fn lift_and_servo_requests_send_the_manuals_frames_and_update_the_state() {
    let mut b = Bench::new();
    let outcome = b.control(Command::Lift {
        enable: true,
        position_pct: 10.2,
    });
    assert!(matches!(outcome, ControlOutcome::Done(_)));
    assert_eq!(b.raw.last().unwrap().1, hex("AA 55 03 04 01 0A 0C"));
    let lift = b.state().lift;
    assert_eq!((lift.enabled, lift.target_pct), (1, 10.0));
    assert!(b.state().is_valid(Group::Lift));

    b.control(Command::Servos {
        pan_rad: FRAC_PI_2,
        tilt_rad: 0.0,
    });
    assert_eq!(
        b.raw.last().unwrap().1,
        hex("AA 55 03 05 00 5A 5C"),
        "pan 0 (left), tilt 90"
    );
    b.control(Command::Servos {
        pan_rad: 0.3,
        tilt_rad: -0.25,
    });
    let pt = b.state().pan_tilt;
    // Whole degrees as the wire carries them: 17.19° → 17°, -14.32° → -14°.
    assert!(close(pt.pan_rad.into(), 17f64.to_radians(), 1e-6), "{pt:?}");
    assert!(
        close(pt.tilt_rad.into(), (-14f64).to_radians(), 1e-6),
        "{pt:?}"
    );
    assert!(b.state().is_valid(Group::PanTilt));
}

#[test]
fn unsupported_invalid_and_refused_requests_send_nothing() {
    let mut b = Bench::new();
    let before = b.sent.len();
    for command in [
        Command::Brake { engage: true },
        Command::Mode { take_control: true },
        Command::Lights {
            enable: true,
            mode: 1,
            brightness_pct: 50,
        },
        Command::SteeringZero,
        Command::OffRoad { enter: true },
        Command::Silent { enter: true },
        Command::ClearFaults { which: 0 },
    ] {
        let outcome = b.control(command);
        assert!(
            matches!(outcome, ControlOutcome::Unsupported(_)),
            "{outcome:?}"
        );
    }
    for command in [
        Command::Velocity(twist(0.1, 0.0, 0.0)),
        Command::Lift {
            enable: true,
            position_pct: 120.0,
        },
        Command::Lift {
            enable: true,
            position_pct: f64::NAN,
        },
        Command::Servos {
            pan_rad: 2.0,
            tilt_rad: 0.0,
        },
    ] {
        let outcome = b.control(command);
        assert!(matches!(outcome, ControlOutcome::Invalid(_)), "{outcome:?}");
    }
    assert_eq!(b.sent.len(), before);
    b.d.set_bus_down(b.now, true);
    let outcome = b.control(Command::Power { enable: false });
    assert!(matches!(outcome, ControlOutcome::Refused(_)));
}

// ---------------------------------------------------------------------------------------------
// Sensor report → state.

#[test]
fn the_manual_sensor_example_fills_the_state() {
    let mut b = Bench::new();
    b.bytes(&hex(concat!(
        "AA 55 47 10 01 62 26 03 02 00 01 00 00 00 05 0A 00 06 00 00 00 00 00 06 00 ",
        "03 00 00 00 00 00 00 05 00 00 00 00 00 00 00 00 E8 03 01 00 00 00 00 00 00 ",
        "00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 02 DC 2F",
    )));
    let s = b.state();
    assert_eq!(s.link.rx_frames, 1);
    assert_eq!(s.stamp_ns, T0.as_nanos());
    assert_eq!(s.system.battery_voltage_v, 26.62);
    assert_eq!(s.ranges.ir_m, [0.002, 0.001, 0.0]);
    assert_eq!(s.motors[0].current_a, 1.0);
    assert_eq!(s.motors[1].current_a, 0.6);
    assert_eq!(s.lift.current_a, 0.6);
    assert_eq!(s.lift.encoder_counts, 1000);
    assert_eq!(s.imu.sensor_stamp_us, 56_322);
    for group in [
        Group::System,
        Group::Ranges,
        Group::Imu,
        Group::MotorDrive,
        Group::Lift,
        Group::Odometry,
    ] {
        assert!(s.is_valid(group), "{}", group.name());
    }
    assert!(!s.is_valid(Group::Motion), "one report gives no speed");
    assert!(!s.is_valid(Group::Pose), "no wheel separation, no pose");
}

#[test]
fn every_report_field_lands_in_its_state_field() {
    let mut b = Bench::new();
    let r = SensorReport {
        battery_voltage_v: 25.34,
        ir_m: [0.051, 0.052, 0.053],
        ultrasonic_m: [1.234, 2.345, 3.456],
        motor_current_a: [1.1, 1.2, 1.3, 1.4],
        lift_current_a: 0.6,
        encoder_counts: [100, 200, 300, 400],
        lift_encoder_counts: 500,
        accel_mps2: [0.5, -0.25, 9.8],
        gyro_radps: [0.01, -0.02, 0.3],
        mag_gauss: [0.2, -0.1, -0.4],
        temperature_c: 33.25,
        roll_rad: 0.05,
        pitch_rad: -0.04,
        yaw_rad: 1.5,
        sensor_stamp_us: 43_210,
    };
    b.feed(&r);
    let s = b.state();
    assert_eq!(s.system.battery_voltage_v, 25.34);
    assert_eq!(s.ranges.ir_m, [0.051, 0.052, 0.053]);
    assert_eq!(s.ranges.ultrasonic_m, [1.234, 2.345, 3.456]);
    let currents: Vec<f32> = s.motors.iter().map(|m| m.current_a).collect();
    assert_eq!(currents, vec![1.1, 1.2, 1.3, 1.4]);
    let counts: Vec<i64> = s.motors.iter().map(|m| m.position_counts).collect();
    assert_eq!(
        counts,
        vec![100, 200, 300, 400],
        "FL, FR, RL, RR after the wire's FL FR BR BL"
    );
    assert_eq!(s.lift.encoder_counts, 500);
    let imu = s.imu;
    let near = |a: f32, b: f64, tol: f64| close(a.into(), b, tol);
    let accel_lsb = 0.000_060_86 * 9.806_65;
    let gyro_lsb = 0.015_213_984_694_731_4f64.to_radians();
    for (got, want) in imu.accel_mps2.iter().zip(r.accel_mps2) {
        assert!(near(*got, want, accel_lsb), "{imu:?}");
    }
    for (got, want) in imu.gyro_radps.iter().zip(r.gyro_radps) {
        assert!(near(*got, want, gyro_lsb), "{imu:?}");
    }
    for (got, want) in imu.mag_gauss.iter().zip(r.mag_gauss) {
        assert!(near(*got, want, 0.000_43), "{imu:?}");
    }
    let tenth = 0.1f64.to_radians();
    assert!(near(imu.roll_rad, 0.05, tenth) && near(imu.pitch_rad, -0.04, tenth));
    assert!(near(imu.yaw_rad, 1.5, tenth));
    assert_eq!((imu.temperature_c, imu.sensor_stamp_us), (33.25, 43_210));
}

#[test]
fn encoders_unwrap_across_the_wrap_and_the_distances_follow_without_a_separation() {
    let mut b = Bench::new();
    // FL forward 300 counts a report from near the top of the range, FR backward: a spin.
    b.reports(11, [65_000, 500, 0, 0], [300, -300, 0, 0]);
    let s = b.state();
    let m = p().metres_per_count();
    assert_eq!(s.motors[0].position_counts, 65_000 + 3_000);
    assert_eq!(s.motors[1].position_counts, 500 - 3_000);
    assert!(close(s.odometry.left_distance_m, 3_000.0 * m, 1e-9));
    assert!(close(s.odometry.right_distance_m, -3_000.0 * m, 1e-9));
    let wheel = 300.0 * m / 0.02;
    assert!(
        close(s.motion.wheel_mps[0].into(), wheel, 1e-4),
        "{:?}",
        s.motion
    );
    assert!(close(s.motion.wheel_mps[1].into(), -wheel, 1e-4));
    assert_eq!(s.motion.linear_mps, 0.0);
    assert_eq!(s.motion.angular_radps, 0.0, "the gyro z of these reports");
    assert!(s.is_valid(Group::Motion) && s.is_valid(Group::WheelSpeed));
    assert!(!s.is_valid(Group::Pose));
    assert_eq!(
        (s.odometry.x_m, s.odometry.y_m, s.odometry.yaw_rad),
        (0.0, 0.0, 0.0)
    );
}

#[test]
fn without_a_separation_the_yaw_rate_is_the_gyros_z_axis() {
    let mut b = Bench::new();
    let mut r = report([0; 4], 0);
    b.feed(&r);
    b.run_for(ms(20));
    r.gyro_radps = [0.0, 0.0, 0.4];
    r.encoder_counts = [100, 100, 0, 0];
    r.sensor_stamp_us = 20_000;
    b.feed(&r);
    let motion = b.state().motion;
    assert!(close(motion.angular_radps.into(), 0.4, 3e-4), "{motion:?}");
    assert!(close(
        motion.linear_mps.into(),
        100.0 * p().metres_per_count() / 0.02,
        1e-5
    ));
}

#[test]
fn with_a_separation_the_yaw_rate_and_the_pose_come_from_the_encoders() {
    let profile = XbotProfile {
        wheel_separation_m: Some(0.5),
        ..p()
    };
    let m = profile.metres_per_count();
    let mut b = Bench::with(profile, DriverConfig::default());
    // Turn on the spot: 50 reports of ±100 counts.
    let wheels = b.reports(51, [1_000, 1_000, 0, 0], [-100, 100, 0, 0]);
    let s = b.state();
    let yaw = 2.0 * 100.0 * 50.0 * m / 0.5;
    assert!(close(s.odometry.yaw_rad, yaw, 1e-9), "{:?}", s.odometry);
    assert!(s.odometry.x_m.abs() < 1e-12 && s.odometry.y_m.abs() < 1e-12);
    assert!(close(
        s.motion.angular_radps.into(),
        2.0 * 100.0 * m / 0.02 / 0.5,
        1e-4
    ));
    assert!(s.is_valid(Group::Pose));
    // Then straight on: 1000 counts.
    b.reports(11, wheels, [100, 100, 0, 0]);
    let o = b.state().odometry;
    let d = 1_000.0 * m;
    assert!(
        close(o.x_m, d * yaw.cos(), 1e-9) && close(o.y_m, d * yaw.sin(), 1e-9),
        "{o:?}"
    );
}

#[test]
fn speeds_use_the_boards_stamp_when_reports_arrive_in_a_burst() {
    let mut b = Bench::new();
    b.feed(&report([0; 4], 60_000));
    b.run_for(ms(40));
    // Two reports in one read: 20 ms apart on the board (the stamp wraps in between).
    let first = report([200, 200, 0, 0], 14_464);
    let second = report([400, 400, 0, 0], 34_464);
    let mut bytes = Frame::Sensor(first).encode(&p()).unwrap();
    bytes.extend(Frame::Sensor(second).encode(&p()).unwrap());
    b.bytes(&bytes);
    let v = 200.0 * p().metres_per_count() / 0.02;
    assert!(
        close(b.state().motion.linear_mps.into(), v, 1e-5),
        "{:?}",
        b.state().motion
    );
}

/// Reports every 20 ms of the board's time at a steady speed; some are lost to bad checksums and
/// some are read late by the service (a loaded host). The speed is the encoder travel over the
/// board's time between the two good reports, whatever the receive gap says.
#[test]
fn a_report_lost_to_a_bad_checksum_and_the_next_one_read_late_leave_the_speed_true() {
    let step: u16 = 127;
    let v = f64::from(step) * p().metres_per_count() / 0.02;
    // (reports lost before this one, how late this one is read, ms): one lost and the next
    // read 13 ms late (received 53 ms after the last good one, on the board 40 ms); three
    // lost (80 ms on the board, the stamp wrapped once) read 5 ms late; one read 25 ms late
    // and the next on time (received 15 ms apart, 20 ms on the board); one lost after a
    // report read 25 ms late (received 15 ms apart, 40 ms on the board).
    let cases: [(u16, u64); 5] = [(0, 0), (1, 13), (3, 5), (0, 25), (1, 0)];
    let mut b = Bench::new();
    let mut board_ms: u64 = 0;
    let mut wheels: u16 = 0;
    b.feed(&report([0; 4], 0));
    let mut read_late = 0;
    for (i, (lost, late)) in cases.into_iter().chain([(0, 0)]).enumerate() {
        let mut bad = Frame::Sensor(report([0; 4], 0)).encode(&p()).unwrap();
        *bad.last_mut().unwrap() ^= 0x01;
        for _ in 0..lost {
            board_ms += 20;
            wheels = wheels.wrapping_add(step);
            b.run_until(T0 + ms(board_ms));
            b.bytes(&bad);
        }
        board_ms += 20;
        wheels = wheels.wrapping_add(step);
        b.run_until(T0 + ms(board_ms + late));
        let stamp = (board_ms * 1_000 % 65_536) as u16;
        b.feed(&report([wheels, wheels, 0, 0], stamp));
        let got = f64::from(b.state().motion.linear_mps);
        assert!(
            close(got, v, 0.005),
            "case {i} ({lost} lost, read {late} ms late after one {read_late} ms late): \
             {got:.3} m/s, the wheels at {v:.3} m/s"
        );
        read_late = late;
    }
    assert_eq!(b.state().link.rx_bad_checksum, 5);
}

// ---------------------------------------------------------------------------------------------
// Link.

#[test]
fn bad_checksums_garbage_and_can_frames_are_counted_and_reported() {
    let mut b = Bench::new();
    let mut bad = Frame::Sensor(report([0; 4], 0)).encode(&p()).unwrap();
    *bad.last_mut().unwrap() ^= 0x01;
    b.bytes(&bad);
    b.bytes(&[0x01, 0x02, 0x03]);
    let unknown = [0xAA, 0x55, 0x02, 0x07, 0x00];
    b.bytes(&[unknown.as_slice(), &[checksum(0x02, &[0x07, 0x00])]].concat());
    let can = crate::CanFrame::new(0x123, &[1, 2]).unwrap();
    b.d.handle_rx(b.now, Rx::Can(&can));
    b.drain();
    b.feed(&report([0; 4], 0));
    let s = b.state();
    assert_eq!(s.link.rx_bad_checksum, 1);
    assert_eq!(
        s.link.rx_decode_errors, 2,
        "an unknown id and the CAN frame"
    );
    assert_eq!(s.link.rx_frames, 1, "the good report after all that");
    assert_eq!(s.link.rx_bytes_discarded, b.d.parser.bytes_discarded());
    assert_eq!(s.link.rx_bytes_discarded, 75 + 3 + 6);
    let dropped = b
        .events
        .iter()
        .filter(|e| matches!(e, DriverEvent::RxDropped { .. }))
        .count();
    assert_eq!(dropped, 3);
}

#[test]
fn byte_at_a_time_delivery_gives_the_same_state_as_whole_frames() {
    let mut whole = Bench::new();
    let mut bytes = Frame::Sensor(report([10, 20, 0, 0], 5))
        .encode(&p())
        .unwrap();
    bytes.extend([0xAA, 0x00, 0x55]);
    bytes.extend(
        Frame::Sensor(report([30, 50, 0, 0], 20_005))
            .encode(&p())
            .unwrap(),
    );
    whole.bytes(&bytes);
    let mut split = Bench::new();
    for byte in &bytes {
        split.bytes(std::slice::from_ref(byte));
    }
    assert_eq!(whole.state(), split.state());
    assert_eq!(split.state().link.rx_frames, 2);
}

#[test]
fn a_command_frame_from_the_chassis_side_is_a_loopback_not_feedback() {
    let mut b = Bench::new();
    for _ in 0..10 {
        b.bytes(&hex("AA 55 02 01 01 02"));
        b.run_for(ms(20));
    }
    let s = b.state();
    assert_eq!((s.link.rx_frames, s.link.rx_unknown_id), (0, 10));
    assert!(
        s.has_link_flag(LinkFlags::CHASSIS_SILENT),
        "an echo does not keep the link alive"
    );
}

#[test]
fn silence_sets_the_flag_and_the_first_report_after_it_re_enables_power() {
    let mut b = Bench::new();
    b.set(twist(0.5, 0.0, 0.0));
    b.reports(5, [0; 4], [10, 10, 0, 0]);
    let last_report = b.now - ms(20);
    b.run_until(last_report + ms(100));
    assert!(
        !b.state().has_link_flag(LinkFlags::CHASSIS_SILENT),
        "100 ms is in time"
    );
    b.run_for(ms(1));
    assert!(b.state().has_link_flag(LinkFlags::CHASSIS_SILENT));
    assert_eq!(b.notices(Level::Warn).len(), 1);
    b.run_for(ms(400));
    assert_eq!(b.powers().len(), 1);

    let before = b.sent.len();
    let back = b.now;
    b.reports(2, [0; 4], [10, 10, 0, 0]);
    assert!(!b.state().has_link_flag(LinkFlags::CHASSIS_SILENT));
    let new: Vec<_> = b.sent[before..]
        .iter()
        .filter(|(t, _)| *t == back)
        .map(|(_, f)| *f)
        .collect();
    assert!(matches!(new[0], Frame::Power(p) if p.enable), "{new:?}");
    assert!(
        matches!(new[1], Frame::Velocity(v) if v.linear_x_mps == 0.5),
        "{new:?}"
    );
    assert_eq!(
        b.notices(Level::Info),
        vec!["chassis is talking again".to_string()]
    );
    // Nothing is bridged across the gap: the counters restarted at 0 but the counts carry on.
    assert_eq!(b.state().motors[0].position_counts, 40 + 10);
}

#[test]
fn an_encoder_jump_is_taken_as_a_reboot_and_the_counts_stay_continuous() {
    let mut b = Bench::new();
    b.set(twist(1.0, 0.0, 0.0));
    b.reports(10, [20_000, 20_000, 0, 0], [250, 250, 0, 0]);
    assert_eq!(b.state().motors[0].position_counts, 22_250);
    let before = b.sent.len();
    // The board restarted between two reports: its counters read 0 again.
    b.reports(3, [0, 0, 0, 0], [250, 250, 0, 0]);
    let new: Vec<_> = b.sent[before..].iter().map(|(_, f)| *f).collect();
    assert!(matches!(new[0], Frame::Power(p) if p.enable), "{new:?}");
    assert!(
        matches!(new[1], Frame::Velocity(v) if v.linear_x_mps == 1.0),
        "{new:?}"
    );
    assert_eq!(b.state().motors[0].position_counts, 22_250 + 500);
    let m = p().metres_per_count();
    assert!(close(b.state().odometry.left_distance_m, 2_750.0 * m, 1e-9));
    assert!(
        b.notices(Level::Warn)[0].contains("jumped"),
        "{:?}",
        b.events
    );
}

#[test]
fn the_lift_and_servos_are_restored_after_a_reboot() {
    let mut b = Bench::new();
    b.control(Command::Lift {
        enable: true,
        position_pct: 40.0,
    });
    b.control(Command::Servos {
        pan_rad: 0.5,
        tilt_rad: 0.1,
    });
    b.reports(3, [0; 4], [0; 4]);
    b.run_for(ms(500));
    let before = b.sent.len();
    b.reports(1, [0; 4], [0; 4]);
    let names: Vec<_> = b.sent[before..]
        .iter()
        .map(|(_, f)| frame_name(f))
        .collect();
    assert_eq!(names, vec!["power", "lift", "servos", "velocity"]);
}

#[test]
fn while_the_bus_is_down_nothing_is_sent_and_control_is_retaken_when_it_returns() {
    let mut b = Bench::new();
    b.set(twist(0.3, 0.0, 0.0));
    b.run_for(ms(100));
    b.bytes(&[0xAA, 0x55, 0x47, 0x10]);
    b.d.set_bus_down(b.now, true);
    assert!(b.state().has_link_flag(LinkFlags::BUS_DOWN));
    assert_eq!(b.d.poll_timeout(), None);
    let before = b.sent.len();
    b.run_for(ms(1000));
    b.set(twist(0.6, 0.0, 0.0));
    assert_eq!(b.sent.len(), before);

    b.d.set_bus_down(b.now, false);
    b.drain();
    let back = b.now;
    let s = b.state();
    assert!(!s.has_link_flag(LinkFlags::BUS_DOWN));
    assert_eq!(s.link.bus_reconnects, 1);
    assert_eq!(s.link.rx_bytes_discarded, 4, "the partial frame is dropped");
    let new: Vec<_> = b.sent[before..].iter().map(|(t, f)| (*t, *f)).collect();
    assert!(
        matches!(new[0], (t, Frame::Power(p)) if p.enable && t == back),
        "{new:?}"
    );
    assert!(
        matches!(new[1], (t, Frame::Velocity(v)) if v.linear_x_mps == 0.6f32 as f64 && t == back),
        "{new:?}"
    );
    b.run_for(ms(250));
    let times: Vec<_> = b
        .velocities()
        .iter()
        .map(|(t, _)| *t)
        .filter(|t| *t > back)
        .collect();
    assert_eq!(
        times,
        vec![back + ms(125), back + ms(250)],
        "the grid restarts"
    );
}

#[test]
fn shutdown_sends_zero_at_once_even_when_the_window_is_full() {
    let mut b = Bench::new();
    b.stop_and_go(200);
    b.set(twist(0.7, 0.0, 0.0));
    b.run_for(ms(1));
    let before = b.velocities().len();
    b.d.shutdown(b.now);
    b.drain();
    assert_eq!(b.velocities().len(), before + 1);
    assert_eq!(
        *b.velocities().last().unwrap(),
        (b.now, VelocityCommand::default())
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn arbitrary_bytes_never_panic_and_every_candidate_is_counted(reads in arbitrary_reads()) {
        let mut b = Bench::new();
        for piece in &reads {
            b.bytes(piece);
            b.run_for(ms(3));
        }
        let link = b.state().link;
        prop_assert_eq!(link.rx_bytes_discarded, b.d.parser.bytes_discarded());
        prop_assert_eq!(link.rx_bad_checksum + link.rx_decode_errors, b.d.parser.errors());
        prop_assert_eq!(link.rx_frames + link.rx_unknown_id, b.d.parser.frames());
    }
}

#[test]
fn on_a_steady_heartbeat_one_change_a_second_goes_out_at_once() {
    let mut b = Bench::new();
    b.run_for(ms(5010));
    for k in 0..5u64 {
        let before = b.velocities().len();
        b.set(twist(0.25 + 0.25 * (k % 2) as f32, 0.0, 0.0));
        assert_eq!(b.velocities().len(), before + 1, "change {k} waited");
        b.run_for(ms(1100));
    }
}

#[test]
fn heartbeats_sent_a_little_late_still_leave_room_for_one_change_a_second() {
    let mut b = Bench::new();
    // The service wakes up 300 µs after each deadline.
    let late = Duration::from_micros(300);
    let step = |b: &mut Bench, until: Timestamp| {
        while let Some(next) = b.d.poll_timeout().filter(|&t| t + late <= until) {
            b.now = next + late;
            b.d.handle_timeout(b.now);
            b.drain();
        }
        b.now = until;
    };
    step(&mut b, T0 + ms(5010));
    for k in 0..5u64 {
        let before = b.velocities().len();
        b.set(twist(0.25 + 0.25 * (k % 2) as f32, 0.0, 0.0));
        assert_eq!(b.velocities().len(), before + 1, "change {k} waited");
        let until = b.now + ms(1100);
        step(&mut b, until);
    }
    let times: Vec<_> = b.velocities().iter().map(|(t, _)| *t).collect();
    assert!(max_per_second(&times) <= MAX_VELOCITY_FRAMES_PER_S);
}
