//! The SCOUT MINI driver alone: frames fed by hand, frames sent checked byte by byte, on
//! simulated time.

// 0.5235 and 0.7853 are the manual's full scales as printed, not approximations of π/6 and π/4.
#![allow(clippy::approx_constant)]

use std::time::Duration;

use chassis_interfaces::{
    ClampFlags, ControlMode, FaultClear, FaultFlags, Group, LightMode, LinkFlags, SystemState,
    Velocity,
};
use proptest::prelude::*;

use super::{V1Driver, normalize_faults};
use crate::agilex_v1::V1Profile;
use crate::agilex_v1::{
    Frame, Lights, MotionCommand, MotionFeedback, MotorFeedback, SystemStatus, body, checksum,
    fault, light_mode, mode,
};
use crate::can::CanFrame;
use crate::command::Command;
use crate::driver::{ControlOutcome, Driver, DriverConfig, DriverEvent, Level, Rx, WireItem};
use crate::kind::RobotKind;
use crate::time::Timestamp;

const T0: Timestamp = Timestamp::from_millis(1_000);

fn at(ms: u64) -> Timestamp {
    T0 + Duration::from_millis(ms)
}

fn at_us(us: u64) -> Timestamp {
    T0 + Duration::from_micros(us)
}

fn p() -> V1Profile {
    V1Profile::default()
}

fn driver() -> V1Driver {
    V1Driver::new(p(), DriverConfig::default(), T0)
}

fn twist(linear_x_mps: f32, angular_z_radps: f32) -> Velocity {
    Velocity::twist(linear_x_mps, angular_z_radps).unwrap()
}

fn can(text: &str) -> CanFrame {
    CanFrame::from_candump(text).unwrap()
}

/// Everything the driver wants to send at `now`.
fn drain(d: &mut V1Driver, now: Timestamp) -> Vec<CanFrame> {
    let mut out = Vec::new();
    while let Some(item) = d.poll_transmit(now) {
        let WireItem::Can(frame) = item else {
            panic!("SCOUT MINI sent serial bytes");
        };
        out.push(frame);
    }
    out
}

/// Runs the driver alone from its deadlines until `until`; returns what it sent, with times.
fn run(d: &mut V1Driver, until: Timestamp) -> Vec<(Timestamp, CanFrame)> {
    let mut sent = Vec::new();
    while let Some(t) = d.poll_timeout().filter(|t| *t <= until) {
        d.handle_timeout(t);
        for f in drain(d, t) {
            sent.push((t, f));
        }
        assert!(
            d.poll_timeout().is_none_or(|next| next > t),
            "stall at {t:?}"
        );
    }
    sent
}

/// The 0x130 payload (b0-b3) and count of a frame.
fn motion_bytes(f: &CanFrame) -> ([u8; 4], u8) {
    assert_eq!(f.id(), 0x130);
    let d = f.data();
    assert_eq!(d[7], checksum(0x130, &d[..7]), "checksum of {f}");
    ([d[0], d[1], d[2], d[3]], d[6])
}

/// A chassis frame with count `count`, as the chassis would send it.
fn chassis(frame: Frame, count: u8) -> CanFrame {
    frame.encode(count, &p()).unwrap()
}

fn feed(d: &mut V1Driver, now: Timestamp, frame: Frame) {
    let f = chassis(frame, 0);
    d.handle_rx(now, Rx::Can(&f));
}

fn status(mode: u8, word: u16) -> Frame {
    Frame::SystemStatus(SystemStatus {
        body_status: body::NORMAL,
        mode,
        battery_voltage_v: 26.4,
        vendor_fault_word: word,
    })
}

fn events(d: &mut V1Driver) -> Vec<DriverEvent> {
    std::iter::from_fn(|| d.poll_event()).collect()
}

fn notices(d: &mut V1Driver) -> Vec<(Level, String)> {
    events(d)
        .into_iter()
        .filter_map(|e| match e {
            DriverEvent::Notice { level, message } => Some((level, message)),
            _ => None,
        })
        .collect()
}

#[test]
fn the_first_heartbeat_is_the_manuals_command_mode_frame() {
    let mut d = driver();
    assert_eq!(d.robot(), RobotKind::ScoutMini);
    assert_eq!(d.state().robot, RobotKind::ScoutMini.id());
    assert_eq!(d.state().system.control_mode, ControlMode::UNKNOWN);
    assert!(d.wants_control());
    // The manual's third example, count 0.
    assert_eq!(drain(&mut d, T0), vec![can("130#010000000000003A")]);
    assert_eq!(d.poll_timeout(), Some(at(20)));
    assert!(drain(&mut d, at(19)).is_empty());
    assert_eq!(drain(&mut d, at(20)), vec![can("130#010000000000013B")]);
    assert_eq!(d.state().link.tx_frames, 2);

    // Without take_control the heartbeat says RC mode.
    let config = DriverConfig {
        take_control: false,
        ..DriverConfig::default()
    };
    let mut d = V1Driver::new(p(), config, T0);
    assert_eq!(drain(&mut d, T0), vec![can("130#0000000000000039")]);
}

#[test]
fn the_heartbeat_carries_explicit_zeros_every_20_ms_and_counts_every_frame() {
    let mut d = driver();
    let sent = run(&mut d, at(6000));
    assert_eq!(sent.len(), 301);
    for (i, (t, f)) in sent.iter().enumerate() {
        assert_eq!(*t, at(20 * i as u64));
        let (payload, count) = motion_bytes(f);
        assert_eq!(
            payload,
            [0x01, 0x00, 0x00, 0x00],
            "mode 0x01, explicit zeros"
        );
        assert_eq!(count, (i % 256) as u8, "+1 per frame, wrapping");
    }
}

#[test]
fn a_changed_command_goes_out_at_once_and_a_stop_is_never_delayed() {
    let mut d = driver();
    drain(&mut d, T0);
    d.set_command(at(5), &twist(0.5, 0.0));
    let sent = drain(&mut d, at(5));
    assert_eq!(sent, vec![can("130#01000A0000000145")]);
    assert_eq!(
        d.state().group_stamp_ns[Group::Command.index()],
        at(5).as_nanos()
    );
    assert_eq!(d.state().command.linear_mps, 0.5);

    // Faster than the 2 ms minimum interval: held back until it has passed.
    d.set_command(at(6), &twist(1.0, 0.0));
    assert!(drain(&mut d, at(6)).is_empty());
    assert_eq!(d.poll_timeout(), Some(at(7)));
    assert_eq!(motion_bytes(&drain(&mut d, at(7))[0]).0, [1, 0, 20, 0]);
    // A stop goes out at once, even right after another frame.
    d.set_command(at_us(7_500), &Velocity::ZERO);
    assert_eq!(
        motion_bytes(&drain(&mut d, at_us(7_500))[0]).0,
        [1, 0, 0, 0]
    );
    // The same command again changes nothing; the heartbeat keeps its grid.
    d.set_command(at(8), &Velocity::ZERO);
    assert!(drain(&mut d, at(8)).is_empty());
    assert_eq!(d.poll_timeout(), Some(at(20)));
}

#[test]
fn limits_and_quantisation_are_echoed_with_their_flags() {
    let mut d = driver();
    drain(&mut d, T0);
    let mut send = |now: u64, command: Velocity| {
        d.set_command(at(now), &command);
        let (payload, _) = motion_bytes(&drain(&mut d, at(now))[0]);
        (payload, d.state().command)
    };
    // 1.234 m/s is 24.68 % of 5 m/s: 25 % = 1.25 m/s.
    let (payload, echo) = send(10, twist(1.234, 0.0));
    assert_eq!(payload, [1, 0, 25, 0]);
    assert_eq!(
        (echo.linear_mps, echo.clamp_flags),
        (1.25, ClampFlags::QUANTISED)
    );
    let (payload, echo) = send(20, twist(9.0, 0.0));
    assert_eq!(payload, [1, 0, 100, 0]);
    assert_eq!(
        (echo.linear_mps, echo.clamp_flags),
        (5.0, ClampFlags::LINEAR_LIMIT)
    );
    let (payload, echo) = send(30, twist(-0.5, -1.0));
    assert_eq!(payload, [1, 0, 0xF6, 0x9C]);
    assert_eq!((echo.linear_mps, echo.angular_radps), (-0.5, -0.5235));
    assert_eq!(echo.clamp_flags, ClampFlags::ANGULAR_LIMIT);
    let (payload, echo) = send(40, Velocity::new(0.5, 0.3, 0.0).unwrap());
    assert_eq!(payload, [1, 0, 10, 0]);
    assert_eq!(
        (echo.lateral_mps, echo.clamp_flags),
        (0.0, ClampFlags::LATERAL_UNSUPPORTED)
    );
    // 0.5 rad/s: 95.5 % of the table's 0.5235 rad/s.
    let (payload, echo) = send(50, twist(0.0, 0.5));
    assert_eq!(payload, [1, 0, 0, 96]);
    assert!((echo.angular_radps - 0.502_56).abs() < 1e-5, "{echo:?}");
    assert_eq!(echo.clamp_flags, ClampFlags::QUANTISED);

    // The ⚠ full scale changes what is sent: 0.5 rad/s is 64 % of the example's 0.7853 rad/s.
    let example = V1Profile {
        angular_full_scale_rad_s: 0.7853,
        max_angular_rad_s: 0.7853,
        ..p()
    };
    let mut d = V1Driver::new(example, DriverConfig::default(), T0);
    drain(&mut d, T0);
    d.set_command(at(5), &twist(0.0, 0.5));
    assert_eq!(motion_bytes(&drain(&mut d, at(5))[0]).0, [1, 0, 0, 64]);
    assert!((d.state().command.angular_radps - 0.502_59).abs() < 1e-5);
    d.set_command(at(10), &twist(0.0, 0.7));
    assert_eq!(motion_bytes(&drain(&mut d, at(10))[0]).0, [1, 0, 0, 89]);
}

#[test]
fn a_steering_request_becomes_the_bicycle_yaw_rate() {
    let mut d = driver();
    drain(&mut d, T0);
    d.set_command(at(5), &Velocity::steer(0.5, 0.02).unwrap());
    // ω = 0.5 · tan(0.02) / 0.452 = 0.0221 rad/s = 4.2 % → 4 %.
    assert_eq!(motion_bytes(&drain(&mut d, at(5))[0]).0, [1, 0, 10, 4]);
    assert_eq!(
        d.state().command.steer_rad,
        0.0,
        "a skid steer has no steering"
    );
}

#[test]
fn feedback_fills_the_state_and_touches_its_groups() {
    let mut d = driver();
    let t = at(3);
    feed(&mut d, t, status(mode::CAN_COMMAND, fault::RC_DISCONNECTED));
    feed(
        &mut d,
        t,
        Frame::MotionFeedback(MotionFeedback {
            linear_mps: 0.512,
            angular_radps: -0.1,
        }),
    );
    for motor in 1..=4u8 {
        feed(
            &mut d,
            t,
            Frame::Motor(MotorFeedback {
                motor,
                current_a: 1.5 + f64::from(motor),
                rpm: -100.0 * f64::from(motor),
                driver_temp_c: 30.0 + f64::from(motor),
                motor_temp_c: -5.0,
            }),
        );
    }
    feed(
        &mut d,
        t,
        Frame::LightState(Lights {
            control_enabled: true,
            front_mode: light_mode::BREATHING,
            front_brightness_pct: 0,
        }),
    );
    let s = d.state();
    assert_eq!(s.link.rx_frames, 7);
    assert_eq!(s.stamp_ns, t.as_nanos());
    assert_eq!(s.system.control_mode, ControlMode::COMMAND);
    assert_eq!(s.system.battery_voltage_v, 26.4);
    assert_eq!(s.system.vendor_fault_word, 0x1000);
    assert_eq!(s.system.fault_flags, FaultFlags::RC_LINK_LOST);
    assert_eq!((s.system.body_status, s.system.power_enabled), (0, 1));
    assert_eq!(s.link_flags, LinkFlags::COMMAND_MODE);
    assert_eq!((s.motion.linear_mps, s.motion.angular_radps), (0.512, -0.1));
    for (i, m) in s.motors.iter().enumerate() {
        let n = i as f32 + 1.0;
        assert_eq!(
            (m.current_a, m.rpm, m.driver_temp_c, m.motor_temp_c),
            (1.5 + n, -100.0 * n, 30.0 + n, -5.0)
        );
    }
    assert_eq!(
        (
            s.lights.control_enabled,
            s.lights.front_mode,
            s.lights.front_brightness_pct
        ),
        (1, LightMode::BREATHING, 0)
    );
    for group in [
        Group::System,
        Group::Motion,
        Group::Pose,
        Group::MotorDrive,
        Group::MotorDriver,
        Group::Lights,
    ] {
        assert_eq!(s.age_ns(group, t.as_nanos()), Some(0), "{}", group.name());
    }
    assert!(!s.is_valid(Group::Command), "nothing sent yet");
    assert!(!s.is_valid(Group::Odometry) && !s.is_valid(Group::Body));
}

/// The 0x151 fault bits as the manual names them (spec/PROTOCOLS.md, "0x151 fault bits"), each
/// set alone in a raw frame, and the flag the manual's words name. The b4 bits are alarms the
/// chassis clears itself and drives on (warnings); the b5 failures and protections cut or limit
/// the drive until cleared (no warnings).
#[test]
fn each_fault_bit_the_manual_names_is_reported_as_its_flag() {
    let b4 = [
        // bit0 CAN command checksum error, bit1 drive over-temp alarm (55 °C), bit2 motor
        // over-current alarm (15 A rms), bit3 battery under-voltage alarm (22.5 V), bit4 RC
        // transmitter disconnected.
        FaultFlags::COMMAND_CHECKSUM,
        FaultFlags::OVER_TEMPERATURE_WARNING,
        FaultFlags::OVER_CURRENT_WARNING,
        FaultFlags::BATTERY_UNDER_VOLTAGE_WARNING,
        FaultFlags::RC_LINK_LOST,
    ];
    let b5 = [
        // bit0 battery under-voltage failure (22 V), bit1 battery over-voltage failure, bit2-5
        // motor 1-4 communication failure, bit6 drive over-temp protection (65 °C), bit7 motor
        // over-current protection (20 A rms).
        FaultFlags::BATTERY_UNDER_VOLTAGE,
        FaultFlags::BATTERY_OVER_VOLTAGE,
        FaultFlags::MOTOR_1_COMM_LOST,
        FaultFlags::MOTOR_2_COMM_LOST,
        FaultFlags::MOTOR_3_COMM_LOST,
        FaultFlags::MOTOR_4_COMM_LOST,
        FaultFlags::OVER_TEMPERATURE,
        FaultFlags::OVER_CURRENT,
    ];
    let mut d = driver();
    let mut every = 0;
    for (byte, flags) in [(4, &b4[..]), (5, &b5[..])] {
        for (bit, flag) in (0u8..).zip(flags.iter().copied()) {
            // Body normal, CAN command mode, 26.4 V, the one fault bit, count 0, checksum.
            let mut data = [0x00, 0x01, 0x01, 0x08, 0x00, 0x00, 0x00, 0x00];
            data[byte] = 1 << bit;
            data[7] = checksum(0x151, &data[..7]);
            d.handle_rx(at(1), Rx::Can(&CanFrame::new(0x151, &data).unwrap()));
            let reported = d.state().system.fault_flags;
            assert_eq!(reported, flag, "b{byte} bit{bit}");
            let warning = reported & FaultFlags::WARNINGS != 0;
            assert_eq!(warning, byte == 4, "b{byte} bit{bit}");
            every |= flag;
        }
    }
    // Undefined bits (b4 bits 5-7) map to nothing; the raw word keeps them.
    assert_eq!(normalize_faults(0xE000), 0);
    feed(&mut d, at(1), status(mode::CAN_COMMAND, 0xFFFF));
    let s = d.state().system;
    assert_eq!(s.vendor_fault_word, 0xFFFF);
    assert_eq!(s.fault_flags, every);
    assert_eq!(s.power_enabled, 0, "under-voltage failure: drive power cut");

    for (body_status, state, flag) in [
        (
            body::EMERGENCY_STOP,
            SystemState::BODY_EMERGENCY_STOP,
            FaultFlags::EMERGENCY_STOP,
        ),
        (
            body::EXCEPTION,
            SystemState::BODY_EXCEPTION,
            FaultFlags::BODY_EXCEPTION,
        ),
        (
            0x7F,
            SystemState::BODY_EXCEPTION,
            FaultFlags::BODY_EXCEPTION,
        ),
    ] {
        feed(
            &mut d,
            at(2),
            Frame::SystemStatus(SystemStatus {
                body_status,
                mode: mode::CAN_COMMAND,
                battery_voltage_v: 25.0,
                vendor_fault_word: 0,
            }),
        );
        let s = d.state().system;
        assert_eq!((s.body_status, s.fault_flags), (state, flag));
    }
}

#[test]
fn the_control_mode_is_normalized_and_rc_authority_is_reported_with_notices() {
    let mut d = driver();
    feed(&mut d, at(1), status(mode::CAN_COMMAND, 0));
    assert_eq!(d.state().link_flags, LinkFlags::COMMAND_MODE);
    assert_eq!(
        notices(&mut d),
        vec![(Level::Info, "chassis mode unknown -> command".to_string())]
    );

    feed(&mut d, at(2), status(mode::RC, 0));
    assert_eq!(d.state().system.control_mode, ControlMode::REMOTE);
    assert_eq!(d.state().link_flags, LinkFlags::RC_AUTHORITY);
    let n = notices(&mut d);
    assert_eq!(n.len(), 1);
    assert_eq!(n[0].0, Level::Warn);
    assert!(
        n[0].1.starts_with("chassis mode command -> remote"),
        "{n:?}"
    );
    assert!(n[0].1.contains("not fought"), "{n:?}");
    // Reported, not fought: the heartbeat keeps mode 0x01 and the current command.
    d.set_command(at(3), &twist(0.5, 0.0));
    assert_eq!(motion_bytes(&drain(&mut d, at(3))[0]).0, [1, 0, 10, 0]);

    feed(&mut d, at(4), status(mode::SERIAL, 0));
    assert_eq!(d.state().system.control_mode, ControlMode::SERIAL);
    assert_eq!(d.state().link_flags, 0);
    feed(&mut d, at(5), status(0x07, 0));
    assert_eq!(d.state().system.control_mode, ControlMode::UNKNOWN);
    assert_eq!(notices(&mut d).len(), 2);
    // The same mode again is no news.
    feed(&mut d, at(6), status(0x07, 0));
    assert!(notices(&mut d).is_empty());
}

#[test]
fn faults_set_and_cleared_are_notices_at_their_level() {
    let mut d = driver();
    feed(&mut d, at(1), status(mode::CAN_COMMAND, 0));
    notices(&mut d);
    feed(
        &mut d,
        at(2),
        status(
            mode::CAN_COMMAND,
            fault::RC_DISCONNECTED | fault::COMMAND_CHECKSUM,
        ),
    );
    assert_eq!(
        notices(&mut d),
        vec![(
            Level::Warn,
            "chassis faults set: rc_link_lost, command_checksum".to_string()
        )]
    );
    feed(
        &mut d,
        at(3),
        status(
            mode::CAN_COMMAND,
            fault::RC_DISCONNECTED | fault::DRIVE_OVER_TEMP_PROTECTION,
        ),
    );
    assert_eq!(
        notices(&mut d),
        vec![
            (
                Level::Error,
                "chassis faults set: over_temperature".to_string()
            ),
            (
                Level::Info,
                "chassis faults cleared: command_checksum".to_string()
            ),
        ]
    );
}

#[test]
fn a_bad_checksum_is_dropped_counted_and_changes_nothing() {
    let mut d = driver();
    let good = chassis(
        Frame::MotionFeedback(MotionFeedback {
            linear_mps: 1.0,
            angular_radps: 0.0,
        }),
        7,
    );
    let mut data = good.data().to_vec();
    data[7] = data[7].wrapping_add(1);
    let bad = CanFrame::new(0x131, &data).unwrap();
    d.handle_rx(at(1), Rx::Can(&bad));
    let s = d.state();
    assert_eq!((s.link.rx_bad_checksum, s.link.rx_frames), (1, 0));
    assert_eq!((s.valid_mask, s.stamp_ns), (0, 0));
    let e = events(&mut d);
    assert_eq!(e.len(), 1);
    let DriverEvent::RxDropped { reason } = &e[0] else {
        panic!("{e:?}")
    };
    assert!(reason.contains("bad checksum"), "{reason}");

    d.handle_rx(at(2), Rx::Can(&can("7F0#0102030405060708")));
    d.handle_rx(
        at(2),
        Rx::Can(&CanFrame::new_extended(0x131, good.data()).unwrap()),
    );
    d.handle_rx(
        at(2),
        Rx::Can(&CanFrame::new(0x131, &good.data()[..6]).unwrap()),
    );
    d.handle_rx(at(2), Rx::Bytes(&[0xAA, 0x55]));
    let s = d.state();
    assert_eq!(
        (
            s.link.rx_unknown_id,
            s.link.rx_decode_errors,
            s.link.rx_frames
        ),
        (2, 2, 0)
    );
    assert_eq!(events(&mut d).len(), 4);

    // Another node's command is a valid frame but no state.
    // None of them is a sign of life: the link turns silent on time.
    run(&mut d, at(100) + Duration::from_nanos(1));
    assert!(d.state().has_link_flag(LinkFlags::CHASSIS_SILENT));
    let command = chassis(Frame::MotionCommand(MotionCommand::drive(1.0, 0.0)), 0);
    d.handle_rx(at(103), Rx::Can(&command));
    assert_eq!(d.state().link.rx_frames, 1);
    assert_eq!(d.state().valid_mask & !Group::Command.bit(), 0);
    d.handle_rx(at(104), Rx::Can(&good));
    assert_eq!(d.state().motion.linear_mps, 1.0);
}

#[test]
fn the_pose_integrates_the_reported_speeds() {
    let mut d = driver();
    for k in 0..=50 {
        feed(
            &mut d,
            at(20 * k),
            Frame::MotionFeedback(MotionFeedback {
                linear_mps: 1.0,
                angular_radps: 0.0,
            }),
        );
    }
    let o = d.state().odometry;
    assert!((o.x_m - 1.0).abs() < 1e-9 && o.y_m.abs() < 1e-12, "{o:?}");
    // A quarter turn on the spot at 0.5 rad/s takes π s.
    let start = at(1000);
    let steps = 157;
    for k in 1..=steps {
        feed(
            &mut d,
            start + Duration::from_millis(20 * k),
            Frame::MotionFeedback(MotionFeedback {
                linear_mps: 0.0,
                angular_radps: 0.5,
            }),
        );
    }
    let o = d.state().odometry;
    assert!((o.yaw_rad - 0.5 * 3.14).abs() < 0.01, "{o:?}");
    // The first turning interval still averages in the last 1 m/s sample: +1 cm.
    assert!((o.x_m - 1.01).abs() < 1e-4, "{o:?}");
}

#[test]
fn clear_codes_ride_the_next_0x130s_one_each_keeping_the_motion() {
    let mut d = driver();
    drain(&mut d, T0);
    d.set_command(at(1), &twist(0.5, 0.0));
    drain(&mut d, at(1));
    let outcome = d.control(
        at(5),
        &Command::ClearFaults {
            which: FaultClear::ALL,
        },
    );
    assert_eq!(
        outcome,
        ControlOutcome::Done("clear-fault all sent (8 codes in 0x130 b1)".into())
    );
    assert_eq!(d.pending_clear_codes(), 8);
    let sent = {
        let mut v: Vec<(Timestamp, CanFrame)> = drain(&mut d, at(5))
            .into_iter()
            .map(|f| (at(5), f))
            .collect();
        v.extend(run(&mut d, at(20)));
        v
    };
    let got: Vec<(Timestamp, [u8; 4])> =
        sent.iter().map(|(t, f)| (*t, motion_bytes(f).0)).collect();
    let mut expected: Vec<(Timestamp, [u8; 4])> = (0..8u8)
        .map(|i| (at(5 + 2 * u64::from(i)), [1, i + 1, 10, 0]))
        .collect();
    expected.push((at(20), [1, 0, 10, 0]));
    assert_eq!(
        got, expected,
        "codes 1-8 back to back with the current motion"
    );
    assert_eq!(d.pending_clear_codes(), 0);

    let outcome = d.control(
        at(30),
        &Command::ClearFaults {
            which: FaultClear::OVER_TEMPERATURE,
        },
    );
    assert_eq!(
        outcome,
        ControlOutcome::Done("clear-fault over-temperature sent (1 code in 0x130 b1)".into())
    );
    assert_eq!(motion_bytes(&drain(&mut d, at(30))[0]).0, [1, 7, 10, 0]);
    let outcome = d.control(
        at(31),
        &Command::ClearFaults {
            which: FaultClear::RC_LINK,
        },
    );
    assert_eq!(
        outcome,
        ControlOutcome::Unsupported("scout-mini has no fault to clear called rc-link".into())
    );
    assert!(drain(&mut d, at(31)).is_empty());
}

#[test]
fn functions_the_scout_mini_lacks_are_unsupported_and_velocity_is_invalid() {
    let mut d = driver();
    drain(&mut d, T0);
    for (command, text) in [
        (
            Command::Brake { engage: true },
            "scout-mini has no parking brake",
        ),
        (
            Command::OffRoad { enter: true },
            "scout-mini has no off-road mode",
        ),
        (
            Command::Lift {
                enable: true,
                position_pct: 10.0,
            },
            "scout-mini has no lift",
        ),
        (
            Command::Servos {
                pan_rad: 0.0,
                tilt_rad: 0.0,
            },
            "scout-mini has no servos",
        ),
        (
            Command::Power { enable: false },
            "scout-mini has no drive power switch on the bus",
        ),
        (Command::SteeringZero, "scout-mini has no steering to zero"),
        (
            Command::Silent { enter: true },
            "scout-mini has no silent mode",
        ),
    ] {
        assert_eq!(
            d.control(at(1), &command),
            ControlOutcome::Unsupported(text.into())
        );
    }
    let velocity = Command::Velocity(twist(1.0, 0.0));
    assert!(matches!(
        d.control(at(1), &velocity),
        ControlOutcome::Invalid(_)
    ));
    assert!(drain(&mut d, at(1)).is_empty(), "nothing sent for them");
}

#[test]
fn lights_repeat_every_25_ms_while_enabled_and_the_release_until_acknowledged() {
    let mut d = driver();
    drain(&mut d, T0);
    assert!(
        run(&mut d, at(40)).iter().all(|(_, f)| f.id() == 0x130),
        "lights never asked for are never sent"
    );
    let outcome = d.control(
        at(43),
        &Command::Lights {
            enable: true,
            mode: LightMode::CUSTOM,
            brightness_pct: 40,
        },
    );
    assert_eq!(
        outcome,
        ControlOutcome::Done("light control on: front custom 40 %, repeated every 25 ms".into())
    );
    // 01+40+08+01+03+28 = 0x75; its own count from 0.
    assert_eq!(drain(&mut d, at(43)), vec![can("140#0103280000000075")]);
    let lights: Vec<(Timestamp, u8)> = run(&mut d, at(120))
        .into_iter()
        .filter(|(_, f)| f.id() == 0x140)
        .map(|(t, f)| (t, f.data()[6]))
        .collect();
    assert_eq!(lights, vec![(at(68), 1), (at(93), 2), (at(118), 3)]);
    feed(
        &mut d,
        at(120),
        Frame::LightState(Lights {
            control_enabled: true,
            front_mode: light_mode::CUSTOM_BRIGHTNESS,
            front_brightness_pct: 40,
        }),
    );

    // Release: enable 0x00 until 0x141 reports light control off.
    let outcome = d.control(
        at(125),
        &Command::Lights {
            enable: false,
            mode: 0,
            brightness_pct: 0,
        },
    );
    assert_eq!(
        outcome,
        ControlOutcome::Done("light handed back to the chassis".into())
    );
    assert_eq!(drain(&mut d, at(125)), vec![can("140#000000000000044D")]);
    let releases = run(&mut d, at(160))
        .into_iter()
        .filter(|(_, f)| f.id() == 0x140)
        .count();
    assert_eq!(releases, 1, "at 150 ms");
    feed(&mut d, at(160), Frame::LightState(Lights::default()));
    assert!(run(&mut d, at(400)).iter().all(|(_, f)| f.id() == 0x130));

    for (mode, brightness_pct) in [(7, 0), (LightMode::CUSTOM, 101)] {
        let outcome = d.control(
            at(400),
            &Command::Lights {
                enable: true,
                mode,
                brightness_pct,
            },
        );
        assert!(matches!(outcome, ControlOutcome::Invalid(_)), "{outcome:?}");
    }
    assert!(drain(&mut d, at(400)).is_empty());
}

#[test]
fn letting_go_sends_a_stop_in_command_mode_then_mode_0x00() {
    let mut d = driver();
    drain(&mut d, T0);
    feed(&mut d, at(1), status(mode::CAN_COMMAND, 0));
    d.set_command(at(2), &twist(0.5, 0.1));
    drain(&mut d, at(2));
    let outcome = d.control(
        at(5),
        &Command::Mode {
            take_control: false,
        },
    );
    assert!(matches!(outcome, ControlOutcome::Done(_)));
    assert!(!d.wants_control());
    assert_eq!(motion_bytes(&drain(&mut d, at(5))[0]).0, [1, 0, 0, 0]);
    assert_eq!(d.state().link_flags, 0, "the chassis no longer obeys us");
    let sent = run(&mut d, at(40));
    assert_eq!(sent.len(), 2);
    for (_, f) in &sent {
        assert_eq!(motion_bytes(f).0, [0, 0, 0, 0]);
    }
    let echo = d.state().command;
    assert_eq!((echo.linear_mps, echo.angular_radps), (0.0, 0.0));
    assert_eq!(
        echo.clamp_flags,
        ClampFlags::CHASSIS_NOT_READY | ClampFlags::QUANTISED,
        "zero sent; the request itself was quantised"
    );

    d.control(at(45), &Command::Mode { take_control: true });
    assert_eq!(motion_bytes(&drain(&mut d, at(45))[0]).0, [1, 0, 10, 19]);
    assert_eq!(d.state().command.clamp_flags, ClampFlags::QUANTISED);
    feed(&mut d, at(46), status(mode::CAN_COMMAND, 0));
    assert_eq!(d.state().link_flags, LinkFlags::COMMAND_MODE);
}

#[test]
fn shutdown_sends_a_zero_command_at_once() {
    let mut d = driver();
    drain(&mut d, T0);
    d.set_command(at(1), &twist(1.0, 0.0));
    drain(&mut d, at(1));
    d.shutdown(at(10));
    assert_eq!(motion_bytes(&drain(&mut d, at(10))[0]).0, [1, 0, 0, 0]);
    // Even when the command was already zero.
    d.shutdown(at(12));
    assert_eq!(drain(&mut d, at(12)).len(), 1);
    let sent = run(&mut d, at(100));
    assert!(sent.iter().all(|(_, f)| motion_bytes(f).0 == [1, 0, 0, 0]));
}

#[test]
fn while_the_bus_is_down_nothing_is_sent_and_control_is_refused() {
    let mut d = driver();
    drain(&mut d, T0);
    d.control(
        at(1),
        &Command::ClearFaults {
            which: FaultClear::ALL,
        },
    );
    d.set_bus_down(at(1), true);
    assert!(d.state().has_link_flag(LinkFlags::BUS_DOWN));
    assert!(drain(&mut d, at(1)).is_empty());
    assert_eq!(d.poll_timeout(), None);
    assert!(matches!(
        d.control(at(2), &Command::Mode { take_control: true }),
        ControlOutcome::Refused(_)
    ));
    assert_eq!(notices(&mut d)[0].0, Level::Error);

    d.set_bus_down(at(1005), false);
    assert!(!d.state().has_link_flag(LinkFlags::BUS_DOWN));
    assert_eq!(d.state().link.bus_reconnects, 1);
    assert_eq!(
        d.pending_clear_codes(),
        0,
        "requests from before are dropped"
    );
    let sent = drain(&mut d, at(1005));
    assert_eq!(sent.len(), 1);
    assert_eq!(motion_bytes(&sent[0]).0, [1, 0, 0, 0]);
    assert_eq!(
        d.poll_timeout(),
        Some(at(1025)),
        "a new grid from the return"
    );
}

fn arbitrary_frame() -> impl Strategy<Value = (bool, u32, Vec<u8>, bool)> {
    (
        any::<bool>(),
        prop_oneof![
            0u32..0x800,
            Just(0x151u32),
            Just(0x131),
            Just(0x141),
            0x200u32..0x204,
            Just(0x130),
            Just(0x140),
        ],
        proptest::collection::vec(any::<u8>(), 0..=8),
        any::<bool>(),
    )
}

proptest! {
    #[test]
    fn arbitrary_can_frames_never_panic_the_driver(
        frames in proptest::collection::vec(arbitrary_frame(), 1..80),
    ) {
        let mut d = driver();
        let mut now = T0;
        let mut decoded = 0u64;
        for (i, (extended, frame_id, mut data, fix_checksum)) in frames.into_iter().enumerate() {
            now += Duration::from_millis(3);
            if fix_checksum && data.len() == 8 && frame_id <= 0x7FF {
                data[7] = checksum(frame_id as u16, &data[..7]);
            }
            let frame = if extended {
                CanFrame::new_extended(frame_id, &data).unwrap()
            } else {
                CanFrame::new(frame_id, &data).unwrap()
            };
            d.handle_rx(now, Rx::Can(&frame));
            if d.poll_timeout().is_some_and(|t| t <= now) {
                d.handle_timeout(now);
            }
            while d.poll_transmit(now).is_some() {}
            while d.poll_event().is_some() {}
            let link = d.state().link;
            prop_assert_eq!(
                link.rx_frames + link.rx_bad_checksum + link.rx_decode_errors + link.rx_unknown_id,
                i as u64 + 1
            );
            decoded = link.rx_frames;
            prop_assert!(d.state().odometry.yaw_rad.abs() <= std::f64::consts::PI);
        }
        prop_assert!(decoded <= 80);
    }
}
