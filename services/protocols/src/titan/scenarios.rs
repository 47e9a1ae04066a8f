//! TITAN scenarios: the driver against the simulated chassis, wired back to back by [`Pair`] on
//! simulated time.
//!
//! Every test starts both sides at [`T0`]; the driver's heartbeat grid and the chassis' 20 ms
//! feedback grid are both anchored there, and the wire's one-way latency is the `Pair` default
//! ([`LATENCY`], 250 µs), so every time below is exact and every run is deterministic. The tests
//! read what crossed the wire from the `Pair` log, what the driver believes from
//! [`Driver::state`] and what the chassis really does from [`Firmware::truth`].

use std::time::Duration;

use chassis_interfaces::{
    ClampFlags, ControlMode, ControlStatus, FaultClear, FaultFlags, LinkFlags, Velocity,
};

use super::{Frame, MotionCommand, TitanDriver, TitanSim, decode, id, mode};
use crate::Direction;
use crate::can::CanFrame;
use crate::command::Command;
use crate::driver::{ControlOutcome, Driver, DriverConfig, DriverEvent, Level, wrap_angle};
use crate::firmware::{Firmware, Injection, SimTruth};
use crate::pair::{Pair, notices};
use crate::time::Timestamp;
use crate::titan::TitanProfile;

type TitanPair = Pair<TitanDriver, TitanSim>;

/// Where both sides start.
const T0: Timestamp = Timestamp::from_millis(1_000);
/// The TITAN heartbeat period and the chassis' fast feedback period.
const PERIOD: Duration = Duration::from_millis(20);
/// One-way latency of the simulated wire (the `Pair` default).
const LATENCY: Duration = Duration::from_micros(250);

fn ms(v: u64) -> Duration {
    Duration::from_millis(v)
}

fn twist(linear_mps: f64, angular_radps: f64) -> Velocity {
    Velocity::twist(linear_mps as f32, angular_radps as f32).unwrap()
}

fn steer(linear_mps: f64, steer_rad: f64) -> Velocity {
    Velocity::steer(linear_mps as f32, steer_rad as f32).unwrap()
}

fn pair_with(config: DriverConfig) -> TitanPair {
    let profile = TitanProfile::default();
    let driver = TitanDriver::new(profile.clone(), config, T0);
    let sim = TitanSim::new(profile, T0);
    let mut pair = Pair::new(driver, sim, T0);
    pair.record = true;
    assert_eq!(pair.latency, LATENCY);
    pair
}

fn pair() -> TitanPair {
    pair_with(DriverConfig::default())
}

/// Powered up, 100 ms for the chassis to enter CAN command mode, then `command` for `settle`.
fn driving(command: Velocity, settle: Duration) -> TitanPair {
    let mut p = pair();
    p.run_for(ms(100));
    assert_eq!(p.firmware.truth().control_mode, ControlMode::COMMAND);
    p.set_command(command);
    p.run_for(settle);
    p
}

fn truth(p: &TitanPair) -> SimTruth {
    p.firmware.truth()
}

fn faults(p: &TitanPair) -> u64 {
    p.driver.state().system.fault_flags
}

fn has_link_flag(p: &TitanPair, flag: u32) -> bool {
    p.driver.state().has_link_flag(flag)
}

/// Every CAN frame with this id sent in `direction` at or after `since`, with its send time and
/// its index in the log.
fn frames(
    p: &TitanPair,
    direction: Direction,
    frame_id: u16,
    since: Timestamp,
) -> Vec<(usize, Timestamp, CanFrame)> {
    p.log()
        .iter()
        .enumerate()
        .filter(|(_, r)| r.direction == direction && r.at >= since)
        .filter_map(|(i, r)| r.item.as_can().map(|f| (i, r.at, *f)))
        .filter(|(_, _, f)| f.id() == u32::from(frame_id))
        .collect()
}

fn sent(p: &TitanPair, frame_id: u16, since: Timestamp) -> Vec<(usize, Timestamp, CanFrame)> {
    frames(p, Direction::ToChassis, frame_id, since)
}

/// The 0x111 frames the driver sent at or after `since`, decoded.
fn motion_sent(p: &TitanPair, since: Timestamp) -> Vec<(usize, Timestamp, MotionCommand)> {
    let profile = TitanProfile::default();
    sent(p, id::MOTION_COMMAND, since)
        .into_iter()
        .map(|(i, t, f)| match decode(&f, &profile) {
            Ok(Frame::MotionCommand(m)) => (i, t, m),
            other => panic!("0x111 did not decode as a motion command: {other:?}"),
        })
        .collect()
}

/// The 0x131 frames the driver sent at or after `since`: (index, time, engage).
fn brake_sent(p: &TitanPair, since: Timestamp) -> Vec<(usize, Timestamp, bool)> {
    sent(p, id::PARKING_BRAKE, since)
        .into_iter()
        .map(|(i, t, f)| {
            assert_eq!(f.len(), 1, "0x131 is one byte");
            match f.data()[0] {
                0x00 => (i, t, true),
                0x01 => (i, t, false),
                other => panic!("0x131 = {other:#04x}"),
            }
        })
        .collect()
}

/// The 0x211 modes the chassis sent at or after `since`: (time, wire mode).
fn modes_reported(p: &TitanPair, since: Timestamp) -> Vec<(Timestamp, u8)> {
    frames(p, Direction::FromChassis, id::SYSTEM_STATUS, since)
        .into_iter()
        .map(|(_, t, f)| (t, f.data()[1]))
        .collect()
}

/// Runs until just after the next feedback grid slot has reached the driver (slot + latency), so
/// the driver's state describes the chassis as it was [`LATENCY`] ago.
fn run_to_fresh_feedback(p: &mut TitanPair) {
    let since_start = p.now().saturating_since(T0 + LATENCY).as_nanos();
    let period = PERIOD.as_nanos();
    let k = u32::try_from(since_start / period + 1).unwrap();
    p.run_until(T0 + LATENCY + PERIOD * k);
}

/// Runs until the true speed is within `tolerance` of `target`; returns how long that took.
fn time_to_speed(p: &mut TitanPair, target: f64, tolerance: f64, limit: Duration) -> Duration {
    let start = p.now();
    let at = p
        .run_until_true(limit, |p| {
            (p.firmware.truth().linear_mps - target).abs() <= tolerance
        })
        .unwrap_or_else(|| {
            panic!(
                "true speed {:.4} m/s did not reach {target} ± {tolerance} within {limit:?}",
                p.firmware.truth().linear_mps
            )
        });
    at.saturating_since(start)
}

fn control_done(events: &[DriverEvent]) -> Vec<(u64, u8, String)> {
    events
        .iter()
        .filter_map(|e| match e {
            DriverEvent::ControlDone {
                token,
                status,
                message,
            } => Some((*token, *status, message.clone())),
            _ => None,
        })
        .collect()
}

// ---------------------------------------------------------------------------------------------
// 1. Power-up, drive, idle brake.

#[test]
fn power_up_takes_command_mode_releases_the_brake_once_drives_true_and_brakes_once_when_idle() {
    let mut p = pair();
    p.run_for(ms(100));

    // 0x421 = 0x01 is the very first frame on the wire, at start.
    let first = p
        .log()
        .iter()
        .find(|r| r.direction == Direction::ToChassis)
        .unwrap();
    let first_frame = first.item.as_can().unwrap();
    assert_eq!(first.at, T0);
    assert_eq!(
        (first_frame.id(), first_frame.data()),
        (u32::from(id::MODE), &[mode::CAN_COMMAND][..])
    );
    assert_eq!(sent(&p, id::MODE, T0).len(), 1, "one mode request");
    let t = truth(&p);
    assert_eq!(t.control_mode, ControlMode::COMMAND);
    assert!(t.brake_engaged, "no motion asked yet: the brake stays on");
    let state = p.driver.state();
    assert_eq!(state.system.parking_brake_engaged, 1);
    assert_eq!(state.system.control_mode, ControlMode::COMMAND);
    assert!(state.has_link_flag(LinkFlags::COMMAND_MODE));
    assert!(brake_sent(&p, T0).is_empty());
    assert!(
        motion_sent(&p, T0)
            .iter()
            .all(|(_, _, m)| *m == MotionCommand::default()),
        "zeros until there is a command"
    );

    // Drive (1.0 m/s, 0.3 rad/s) for 10 s. Like a planner, the caller sets the command every
    // 100 ms; during the first 5 s it alternates with 0.9 m/s (50 changes), then it holds.
    let drive_start = p.now();
    let mut changes = 0;
    let mut previous = Velocity::ZERO;
    for i in 0..100 {
        let command = if i < 50 && i % 2 == 1 {
            twist(0.9, 0.3)
        } else {
            twist(1.0, 0.3)
        };
        changes += usize::from(command != previous);
        previous = command;
        p.set_command(command);
        p.run_for(ms(100));
    }
    assert_eq!(changes, 51);

    // The brake was released exactly once, at the first motion, before the first non-zero 0x111.
    let brakes = brake_sent(&p, T0);
    assert_eq!(brakes.len(), 1, "one brake frame for the whole drive");
    let (release_index, release_at, engage) = brakes[0];
    assert!(!engage);
    let (motion_index, motion_at, first_motion) = motion_sent(&p, T0)
        .into_iter()
        .find(|(_, _, m)| m.linear_mps != 0.0)
        .unwrap();
    assert!(release_index < motion_index, "0x131=0x01 precedes motion");
    // The heartbeat went out at `drive_start` itself, so the change waits out the minimum
    // interval between motion frames (2 ms); the release goes with it.
    let min_interval = ms(DriverConfig::default().min_command_interval_ms);
    assert_eq!(release_at, drive_start + min_interval);
    assert_eq!(motion_at, drive_start + min_interval);
    assert_eq!(first_motion.linear_mps, 1.0);
    assert!(!truth(&p).brake_engaged);
    assert_eq!(p.driver.state().system.parking_brake_engaged, 0);

    // The driver's state agrees with the truth, read just after a feedback frame.
    run_to_fresh_feedback(&mut p);
    let t = truth(&p);
    let s = p.driver.state();
    let (front_m, rear_m) = p.firmware.odometers_m();
    let expected_steer = (0.4225f64 / (1.0 / 0.3 - 0.43)).atan();
    let speed_err = (f64::from(s.motion.linear_mps) - t.linear_mps).abs();
    let steer_err = (f64::from(s.motion.steer_rad) - t.steer_rad).abs();
    let yaw_rate_err = (f64::from(s.motion.angular_radps) - t.angular_radps).abs();
    let pos_err = (s.odometry.x_m - t.x_m).hypot(s.odometry.y_m - t.y_m);
    let yaw_err = wrap_angle(s.odometry.yaw_rad - t.yaw_rad).abs();
    let front_err = (s.odometry.front_distance_m - front_m).abs();
    let rear_err = (s.odometry.rear_distance_m - rear_m).abs();
    println!(
        "after 10 s: truth v={:.4} steer={:.4} pose=({:.3}, {:.3}, {:.4}) odo={front_m:.3}; \
         errors: v {speed_err:.2e} m/s, steer {steer_err:.2e} rad, yaw rate {yaw_rate_err:.2e} \
         rad/s, position {pos_err:.2e} m, yaw {yaw_err:.2e} rad, odometers {front_err:.2e} / \
         {rear_err:.2e} m",
        t.linear_mps, t.steer_rad, t.x_m, t.y_m, t.yaw_rad
    );
    assert!((t.linear_mps - 1.0).abs() < 1e-6, "settled at 1 m/s");
    assert!(
        (t.steer_rad - expected_steer).abs() < 0.0006,
        "{}",
        t.steer_rad
    );
    assert!(
        (t.angular_radps - 0.3).abs() < 0.002,
        "yaw rate {}",
        t.angular_radps
    );
    assert!(speed_err < 0.001, "speed error {speed_err}");
    assert!(steer_err < 0.001, "steering error {steer_err}");
    assert!(yaw_rate_err < 0.001, "yaw rate error {yaw_rate_err}");
    assert!(pos_err < 0.005, "position error {pos_err} m after ~9.5 m");
    assert!(yaw_err < 0.001, "yaw error {yaw_err} rad");
    assert!(front_err < 0.002 && rear_err < 0.002, "odometers");
    assert!(front_m > 9.0 && front_m < 10.0, "odometer {front_m}");

    // Stop: the zero goes out at once; the brake engages once, exactly 5 s later.
    p.set_command(Velocity::ZERO);
    let stop_at = p.now();
    let (_, zero_at, zero) = *motion_sent(&p, stop_at).first().unwrap();
    assert_eq!((zero_at, zero), (stop_at, MotionCommand::default()));
    let idle = ms(DriverConfig::default().brake_idle_engage_ms);
    p.run_until(stop_at + idle - ms(1));
    assert_eq!(
        brake_sent(&p, T0).len(),
        1,
        "no engagement before the idle time"
    );
    p.run_for(ms(20_000));
    let brakes = brake_sent(&p, T0);
    assert_eq!(brakes.len(), 2, "release + one engagement: {brakes:?}");
    assert_eq!((brakes[1].1, brakes[1].2), (stop_at + idle, true));
    assert!(truth(&p).brake_engaged);
    assert_eq!(truth(&p).linear_mps, 0.0);
    assert_eq!(p.driver.state().system.parking_brake_engaged, 1);
    assert_eq!(p.stalls, 0);
}

// ---------------------------------------------------------------------------------------------
// 2. Heartbeat.

#[test]
fn the_heartbeat_runs_every_20_ms_exactly_and_command_changes_go_out_at_once() {
    let config = DriverConfig {
        min_command_interval_ms: 10,
        ..DriverConfig::default()
    };
    let mut p = pair_with(config);

    // No command at all for 60 s: zeros on the 20 ms grid, nothing else.
    p.run_for(ms(60_000));
    let beats = motion_sent(&p, T0);
    assert_eq!(beats.len(), 3001, "T0, T0 + 20 ms, …, T0 + 60 s");
    for (k, (_, at, m)) in (0u32..).zip(&beats) {
        assert_eq!(*at, T0 + PERIOD * k, "heartbeat {k}");
        assert_eq!(*m, MotionCommand::default());
    }
    let t = truth(&p);
    assert_eq!(t.control_mode, ControlMode::COMMAND);
    assert_eq!(t.fault_flags & FaultFlags::HEARTBEAT_LOST, 0);
    assert_eq!(
        t.commands_received,
        3000 + 1,
        "the mode frame and every heartbeat but the last, still on the wire"
    );

    // Another 60 s with a command change every second, 13 ms after a grid slot: every grid slot
    // still carries a 0x111, and each change adds exactly one frame at the instant it was made.
    let phase = p.now();
    let mut changes = Vec::new();
    for k in 0..60u32 {
        p.run_until(phase + ms(1000) * k + ms(13));
        let v = f64::from(k % 5) * 0.25;
        p.set_command(twist(v, 0.0));
        changes.push((p.now(), v));
        p.run_until(phase + ms(1000) * (k + 1));
    }
    let frames = motion_sent(&p, phase + ms(1));
    let (on_grid, extra): (Vec<_>, Vec<_>) = frames
        .iter()
        .partition(|(_, at, _)| at.saturating_since(T0).as_nanos() % PERIOD.as_nanos() == 0);
    assert_eq!(on_grid.len(), 3000, "every slot of the grid, no gap");
    for (k, (_, at, _)) in (1u32..).zip(&on_grid) {
        assert_eq!(*at, phase + PERIOD * k);
    }
    // A change to the value already sent (k = 0 after the zeros) sends nothing extra.
    let expected: Vec<_> = changes
        .iter()
        .zip(std::iter::once(0.0).chain(changes.iter().map(|c| c.1)))
        .filter(|((_, v), previous)| v != previous)
        .map(|((at, v), _)| (*at, *v))
        .collect();
    let got: Vec<_> = extra.iter().map(|(_, at, m)| (*at, m.linear_mps)).collect();
    assert_eq!(got, expected);

    // The minimum spacing between motion frames (10 ms here), and a stop that ignores it. `base`
    // is a grid slot whose heartbeat (1.0 m/s, the last change above) has just gone out.
    let base = p.now();
    assert_eq!(base.saturating_since(T0).as_nanos() % PERIOD.as_nanos(), 0);
    let script = [
        (0, 0.0),  // a stop: at once, 0 ms after the heartbeat
        (5, 0.5),  // 5 ms after the last frame: held until +10
        (13, 0.6), // held until +23, but the +20 heartbeat carries it first
        (27, 0.7), // 7 ms after the heartbeat: held until +30
        (45, 0.8), // held until +50
        (52, 0.0), // 2 ms after the last frame, but a stop: at once
        (55, 0.4), // held until +62; the +60 heartbeat carries it
        (73, 0.3), // 13 ms after the last frame: at once
    ];
    for (offset, v) in script {
        p.run_until(base + ms(offset));
        p.set_command(twist(v, 0.0));
    }
    p.run_until(base + ms(100));
    let got: Vec<_> = motion_sent(&p, base)
        .iter()
        .map(|(_, at, m)| {
            (
                at.saturating_since(base).as_millis(),
                (m.linear_mps * 1000.0).round() as i32,
            )
        })
        .collect();
    assert_eq!(
        got,
        [
            (0, 1000), // the heartbeat
            (0, 0),
            (10, 500),
            (20, 600),
            (30, 700),
            (40, 700),
            (50, 800),
            (52, 0),
            (60, 400),
            (73, 300),
            (80, 300),
            (100, 300),
        ]
    );
    assert_eq!(p.stalls, 0);
}

// ---------------------------------------------------------------------------------------------
// 3. A heartbeat gap.

#[test]
fn a_600_ms_cable_cut_faults_the_chassis_to_standby_and_driving_resumes_when_it_is_back() {
    let mut p = driving(twist(1.0, 0.0), ms(3000));
    assert!((truth(&p).linear_mps - 1.0).abs() < 1e-3);
    p.take_events();

    let cut_at = p.now();
    p.cut = true;
    let last_heard = *motion_sent(&p, T0).last().map(|(_, at, _)| at).unwrap() + LATENCY;
    let silent_at = p
        .run_until_true(ms(600), |p| has_link_flag(p, LinkFlags::CHASSIS_SILENT))
        .unwrap();
    assert!(
        silent_at.saturating_since(cut_at) <= ms(121),
        "CHASSIS_SILENT {:?} after the cut",
        silent_at.saturating_since(cut_at)
    );
    let lost_at = p
        .run_until_true(ms(600), |p| {
            p.firmware.truth().fault_flags & FaultFlags::HEARTBEAT_LOST != 0
        })
        .unwrap();
    let gap = lost_at.saturating_since(last_heard);
    assert!(gap > ms(500) && gap <= ms(501), "fault after {gap:?}");
    assert_eq!(truth(&p).control_mode, ControlMode::STANDBY);

    p.run_until(cut_at + ms(600));
    assert!(
        has_link_flag(&p, LinkFlags::CHASSIS_SILENT),
        "silent for the whole cut"
    );
    assert!(truth(&p).linear_mps < 0.5, "standby stops the robot");
    p.cut = false;
    let uncut_at = p.now();

    // The driver sees the fault the chassis reports.
    let seen_at = p
        .run_until_true(ms(100), |p| faults(p) & FaultFlags::HEARTBEAT_LOST != 0)
        .unwrap();
    assert!(seen_at.saturating_since(uncut_at) <= ms(21));
    assert!(!has_link_flag(&p, LinkFlags::CHASSIS_SILENT));
    assert_eq!(p.driver.state().system.control_mode, ControlMode::STANDBY);

    // The fault clears and CAN command mode returns, by the heartbeat alone.
    let resumed_at = p
        .run_until_true(ms(100), |p| {
            let t = p.firmware.truth();
            t.control_mode == ControlMode::COMMAND
                && t.fault_flags & FaultFlags::HEARTBEAT_LOST == 0
        })
        .unwrap();
    let cleared_at = p
        .run_until_true(ms(100), |p| {
            faults(p) & FaultFlags::HEARTBEAT_LOST == 0
                && p.driver.state().system.control_mode == ControlMode::COMMAND
        })
        .unwrap();
    let back = time_to_speed(&mut p, 1.0, 0.01, ms(2000));
    let recovery = p.now().saturating_since(uncut_at);
    println!(
        "heartbeat gap: silent after {:?}, chassis fault {gap:?} after the last 0x111, seen by the \
         driver {:?} after the uncut, chassis back in command mode after {:?}, driver after {:?}, \
         1 m/s ± 0.01 again {:?} after the uncut",
        silent_at.saturating_since(cut_at),
        seen_at.saturating_since(uncut_at),
        resumed_at.saturating_since(uncut_at),
        cleared_at.saturating_since(uncut_at),
        recovery
    );
    assert!(back <= ms(2000));
    assert!(
        recovery < ms(2000),
        "back to the commanded speed in {recovery:?}"
    );

    let notices = notices(&p.take_events());
    assert!(
        notices
            .iter()
            .any(|(l, m)| *l == Level::Error && m.contains("set: heartbeat_lost")),
        "{notices:?}"
    );
    assert!(
        notices
            .iter()
            .any(|(_, m)| m.contains("cleared: heartbeat_lost")),
        "{notices:?}"
    );
    assert_eq!(p.stalls, 0);
}

// ---------------------------------------------------------------------------------------------
// 4. Chassis reboot (ugv_sdk #51).

#[test]
fn after_a_chassis_reboot_the_driver_takes_control_within_100_ms_and_the_same_command_moves_again()
{
    let mut p = driving(twist(1.0, 0.0), ms(3000));
    assert!((truth(&p).linear_mps - 1.0).abs() < 1e-3);
    let reboot_at = p.now();
    assert!(p.inject(Injection::Reboot));

    // The chassis boots silently; the driver notices.
    let silent_at = p
        .run_until_true(ms(300), |p| has_link_flag(p, LinkFlags::CHASSIS_SILENT))
        .unwrap();
    let command_at = p
        .run_until_true(ms(2000), |p| {
            p.firmware.truth().control_mode == ControlMode::COMMAND
        })
        .unwrap();
    let standby_at = modes_reported(&p, reboot_at)
        .into_iter()
        .find(|(_, m)| *m == mode::STANDBY)
        .map(|(at, _)| at)
        .unwrap();
    let regain = command_at.saturating_since(standby_at);
    assert!(
        regain <= ms(100),
        "command mode {regain:?} after the first standby 0x211"
    );
    assert_eq!(truth(&p).boots, 1);

    // The same command moves the robot again; nobody called set_command. The robot, still
    // coasting down, starts to accelerate only after the release has reached the chassis.
    let mut last_v = truth(&p).linear_mps;
    let accelerating_at = p
        .run_until_true(ms(1000), |p| {
            let v = p.firmware.truth().linear_mps;
            let rising = v > last_v;
            last_v = v;
            rising
        })
        .unwrap();
    let moving = time_to_speed(&mut p, 1.0, 0.01, ms(3000));
    let back_at = p.now();
    assert!(!truth(&p).brake_engaged);

    // One 0x421 after the boot, then (once the chassis reports command mode) one release, right
    // before a 0x111 that carries the same command.
    let modes = sent(&p, id::MODE, reboot_at);
    assert_eq!(modes.len(), 1, "{modes:?}");
    let (mode_index, mode_at, _) = modes[0];
    assert_eq!(
        mode_at,
        standby_at + LATENCY,
        "asked as soon as standby was heard"
    );
    let release = brake_sent(&p, reboot_at);
    assert_eq!(release.len(), 1, "{release:?}");
    let (release_index, release_at, engage) = release[0];
    assert!(!engage);
    assert!(mode_index < release_index, "0x421 before 0x131");
    let command_reported_at = modes_reported(&p, command_at)
        .into_iter()
        .find(|(_, m)| *m == mode::CAN_COMMAND)
        .map(|(at, _)| at)
        .unwrap();
    assert!(release_at > command_reported_at, "released in command mode");
    let (_, next_at, next_motion) = motion_sent(&p, release_at)
        .into_iter()
        .find(|(i, _, _)| *i > release_index)
        .unwrap();
    assert_eq!(next_at, release_at);
    assert_eq!(next_motion.linear_mps, 1.0, "the same command");
    assert!(
        accelerating_at >= release_at + LATENCY,
        "accelerating at {accelerating_at:?}, release arrived {:?}",
        release_at + LATENCY
    );
    println!(
        "reboot: silent flagged {:?} after the reboot, first standby 0x211 {:?} after it; \
         command mode {regain:?} after that report, brake released {:?} after it, accelerating \
         {:?} after it, 1 m/s ± 0.01 again {:?} after it",
        silent_at.saturating_since(reboot_at),
        standby_at.saturating_since(reboot_at),
        release_at.saturating_since(standby_at),
        accelerating_at.saturating_since(standby_at),
        back_at.saturating_since(standby_at),
    );
    assert!(moving <= ms(3000));
    assert_eq!(p.stalls, 0);
}

// ---------------------------------------------------------------------------------------------
// 5. RC takeover and hand-back.

#[test]
fn an_rc_takeover_is_reported_not_fought_and_control_returns_when_the_transmitter_is_off() {
    let mut p = driving(twist(1.0, 0.0), ms(3000));
    let rc_at = p.now();
    assert!(p.inject(Injection::RcTakeover(true)));
    let seen = p
        .run_until_true(ms(100), |p| has_link_flag(p, LinkFlags::RC_AUTHORITY))
        .unwrap();
    assert!(seen.saturating_since(rc_at) <= ms(21));
    assert_eq!(p.driver.state().system.control_mode, ControlMode::REMOTE);
    assert!(!has_link_flag(&p, LinkFlags::COMMAND_MODE));

    let window = p.now();
    p.run_for(ms(3000));
    let t = truth(&p);
    assert_eq!(t.control_mode, ControlMode::REMOTE);
    assert!(
        t.linear_mps.abs() < 1e-6,
        "sticks centred: {}",
        t.linear_mps
    );
    assert!(sent(&p, id::MODE, rc_at).is_empty(), "no 0x421 against RC");
    assert!(brake_sent(&p, rc_at).is_empty(), "no 0x131 against RC");
    let during = motion_sent(&p, window + Duration::from_nanos(1));
    assert_eq!(during.len(), 150, "the heartbeat keeps going");
    assert!(during.iter().all(|(_, _, m)| m.linear_mps == 1.0));
    assert_eq!(p.driver.state().rc.switch_b, 1, "SWB in the middle");
    assert!(p.driver.state().motion.linear_mps.abs() < 1e-3);

    // The transmitter is switched off: standby, and the driver takes command mode back.
    let off_at = p.now();
    assert!(p.inject(Injection::RcTakeover(false)));
    assert_eq!(truth(&p).control_mode, ControlMode::STANDBY);
    let back_at = p
        .run_until_true(ms(200), |p| {
            p.firmware.truth().control_mode == ControlMode::COMMAND
        })
        .unwrap();
    let moving = time_to_speed(&mut p, 1.0, 0.01, ms(3000));
    println!(
        "RC hand-back: command mode {:?} after the transmitter went off, 1 m/s ± 0.01 {:?} later",
        back_at.saturating_since(off_at),
        moving
    );
    assert!(back_at.saturating_since(off_at) <= ms(21));
    assert_eq!(sent(&p, id::MODE, off_at).len(), 1);
    assert!(!has_link_flag(&p, LinkFlags::RC_AUTHORITY));
    assert!(has_link_flag(&p, LinkFlags::COMMAND_MODE));
    assert_eq!(p.stalls, 0);
}

#[test]
fn a_brake_engaged_before_an_rc_session_is_not_released_behind_the_transmitters_back() {
    let mut p = driving(twist(1.0, 0.0), ms(2000));
    p.set_command(Velocity::ZERO);
    p.run_for(ms(6000));
    assert!(truth(&p).brake_engaged, "the idle brake engaged");
    assert_eq!(p.driver.state().system.parking_brake_engaged, 1);

    // The planner asks for motion while an RC transmitter holds authority: the chassis obeys
    // neither 0x421 nor 0x131 now, so the driver sends neither and does not pretend the brake
    // is released.
    let rc_at = p.now();
    assert!(p.inject(Injection::RcTakeover(true)));
    p.run_for(ms(100));
    p.set_command(twist(1.0, 0.0));
    p.run_for(ms(2000));
    assert!(has_link_flag(&p, LinkFlags::RC_AUTHORITY));
    assert!(sent(&p, id::MODE, rc_at).is_empty(), "no 0x421 against RC");
    assert!(
        brake_sent(&p, rc_at).is_empty(),
        "no 0x131 while RC holds authority: {:?}",
        brake_sent(&p, rc_at)
    );
    assert!(truth(&p).brake_engaged);
    assert_eq!(
        p.driver.state().system.parking_brake_engaged,
        1,
        "the driver's brake report agrees with the chassis"
    );
    assert_eq!(truth(&p).linear_mps, 0.0);

    // Hand-back: standby, 0x421, and only then the release, before the robot moves.
    let off_at = p.now();
    assert!(p.inject(Injection::RcTakeover(false)));
    let moving = time_to_speed(&mut p, 1.0, 0.01, ms(3000));
    let releases = brake_sent(&p, off_at);
    assert_eq!(releases.len(), 1, "{releases:?}");
    assert!(!releases[0].2);
    let (mode_index, _, _) = sent(&p, id::MODE, off_at)[0];
    assert!(mode_index < releases[0].0, "0x421 before 0x131");
    println!(
        "braked RC session: released {:?} after the hand-back, 1 m/s ± 0.01 {moving:?} after it",
        releases[0].1.saturating_since(off_at)
    );
    assert!(!truth(&p).brake_engaged);
    assert_eq!(p.driver.state().system.parking_brake_engaged, 0);
    assert_eq!(p.stalls, 0);
}

// ---------------------------------------------------------------------------------------------
// 6. Battery.

#[test]
fn a_low_battery_warns_an_empty_one_cuts_drive_and_clearing_after_a_recharge_drives_again() {
    let mut p = driving(twist(1.0, 0.0), ms(3000));
    p.take_events();

    // 12 %: a warning, and the robot keeps driving.
    assert!(p.inject(Injection::Battery { soc_pct: 12.0 }));
    let at = p.now();
    let warned = p
        .run_until_true(ms(600), |p| faults(p) & FaultFlags::BATTERY_LOW != 0)
        .unwrap();
    assert!(warned.saturating_since(at) <= ms(521), "BMS every 500 ms");
    assert_eq!(
        faults(&p) & !FaultFlags::WARNINGS,
        0,
        "only warnings: {:?}",
        FaultFlags::names(faults(&p))
    );
    let soc = p.driver.state().system.battery_soc_pct;
    assert!(
        soc == 11.0 || soc == 12.0,
        "SOC {soc} % (reported rounded down)"
    );
    p.run_for(ms(2000));
    assert!((truth(&p).linear_mps - 1.0).abs() < 1e-3, "still drives");
    assert_eq!(faults(&p), truth(&p).fault_flags);
    assert!((p.driver.state().motion.linear_mps - 1.0).abs() < 1e-3);
    let events = notices(&p.take_events());
    assert!(
        events
            .iter()
            .any(|(l, m)| *l == Level::Warn && m.contains("battery_low")),
        "{events:?}"
    );

    // 8 %: under-voltage, drive cut.
    assert!(p.inject(Injection::Battery { soc_pct: 8.0 }));
    let at = p.now();
    let cut = p
        .run_until_true(ms(100), |p| {
            faults(p) & FaultFlags::BATTERY_UNDER_VOLTAGE != 0
        })
        .unwrap();
    assert!(cut.saturating_since(at) <= ms(21));
    p.run_for(ms(2000));
    assert!(truth(&p).linear_mps.abs() < 1e-6, "drive cut");
    assert_eq!(
        faults(&p),
        FaultFlags::BATTERY_UNDER_VOLTAGE
            | FaultFlags::BODY_EXCEPTION
            | FaultFlags::BATTERY_LOW
            | FaultFlags::BMS_ALARM
    );
    assert_eq!(faults(&p), truth(&p).fault_flags);
    assert_eq!(p.driver.state().system.power_enabled, 0);
    let events = notices(&p.take_events());
    assert!(
        events
            .iter()
            .any(|(l, m)| *l == Level::Error && m.contains("battery_under_voltage")),
        "{events:?}"
    );

    // Recharged: power stays cut until the fault is cleared.
    assert!(p.inject(Injection::Battery { soc_pct: 50.0 }));
    p.run_for(ms(1000));
    assert!(truth(&p).linear_mps.abs() < 1e-6, "not restored by itself");
    assert_ne!(faults(&p) & FaultFlags::BATTERY_UNDER_VOLTAGE, 0);
    assert_eq!(faults(&p) & FaultFlags::BATTERY_LOW, 0, "SOC 50 %");
    let clear_at = p.now();
    let outcome = p.control(&Command::ClearFaults {
        which: FaultClear::BATTERY_UNDER_VOLTAGE,
    });
    assert!(matches!(outcome, ControlOutcome::Done(_)), "{outcome:?}");
    let clears = sent(&p, id::CLEAR_FAULT, clear_at);
    assert_eq!(clears.len(), 1);
    assert_eq!(clears[0].2.data(), [0x09]);
    let moving = time_to_speed(&mut p, 1.0, 0.01, ms(3000));
    println!("battery: 1 m/s ± 0.01 again {moving:?} after the clear");
    p.run_for(ms(500));
    assert_eq!(faults(&p), 0, "{:?}", FaultFlags::names(faults(&p)));
    assert_eq!(truth(&p).fault_flags, 0);
    assert_eq!(p.driver.state().system.power_enabled, 1);
    assert_eq!(p.stalls, 0);
}

// ---------------------------------------------------------------------------------------------
// 7. Limits.

#[test]
fn commands_beyond_the_limits_are_clamped_on_the_wire_and_flagged_in_the_echo() {
    let mut p = pair();
    p.run_for(ms(100));
    // Sets the command and returns the data of the 0x111 that carried it: the first one after
    // the call, within the 2 ms minimum interval (the change may follow a heartbeat at once).
    let command = |p: &mut TitanPair, twist: Velocity| {
        let at = p.now();
        let logged = p.log().len();
        p.set_command(twist);
        p.run_for(ms(5));
        let (_, sent_at, frame) = sent(p, id::MOTION_COMMAND, at)
            .into_iter()
            .find(|(i, _, _)| *i >= logged)
            .unwrap();
        assert!(
            sent_at <= at + ms(2),
            "sent {sent_at:?} for a change at {at:?}"
        );
        frame.data().to_vec()
    };

    assert_eq!(
        command(&mut p, twist(5.0, 0.0)),
        [0x0B, 0xB8, 0, 0, 0, 0, 0, 0],
        "3000 mm/s"
    );
    let echo = p.driver.state().command;
    assert_eq!((echo.linear_mps, echo.steer_rad), (3.0, 0.0));
    assert_eq!(echo.clamp_flags, ClampFlags::LINEAR_LIMIT);
    p.run_for(ms(3000));
    assert!((truth(&p).linear_mps - 3.0).abs() < 1e-3, "top speed");
    assert_eq!(
        p.firmware.commands_clamped(),
        0,
        "nothing out of range arrived"
    );

    assert_eq!(
        command(&mut p, twist(-5.0, 0.0)),
        [0xF4, 0x48, 0, 0, 0, 0, 0, 0],
        "-3000 mm/s"
    );
    assert_eq!(
        p.driver.state().command.clamp_flags,
        ClampFlags::LINEAR_LIMIT
    );

    assert_eq!(
        command(&mut p, steer(2.0, 0.2)),
        [0x05, 0xDC, 0, 0, 0, 0, 0x00, 0xC8],
        "1500 mm/s, 200 mrad"
    );
    let echo = p.driver.state().command;
    assert_eq!((echo.linear_mps, echo.steer_rad), (1.5, 0.2));
    assert_eq!(echo.clamp_flags, ClampFlags::LINEAR_LIMIT_STEERING);

    assert_eq!(
        command(&mut p, twist(0.0, 0.5)),
        [0, 0, 0, 0, 0, 0, 0x01, 0x6F],
        "v = 0, 367 mrad"
    );
    let echo = p.driver.state().command;
    assert_eq!((echo.linear_mps, echo.steer_rad), (0.0, 0.367));
    assert_ne!(
        echo.clamp_flags & ClampFlags::TURN_IN_PLACE_UNACHIEVABLE,
        0,
        "{:?}",
        ClampFlags::names(echo.clamp_flags)
    );
    p.run_for(ms(3000));
    let t = truth(&p);
    assert!(
        t.linear_mps.abs() < 1e-3,
        "stopped from 1.5 m/s: {}",
        t.linear_mps
    );
    assert!(
        (t.steer_rad - 0.367).abs() < 1e-9,
        "not dropped: the wheels turn ({})",
        t.steer_rad
    );

    let lateral = Velocity::new(0.5, 0.3, 0.0).unwrap();
    assert_eq!(
        command(&mut p, lateral),
        [0x01, 0xF4, 0, 0, 0, 0, 0, 0],
        "500 mm/s"
    );
    let echo = p.driver.state().command;
    assert_eq!((echo.linear_mps, echo.lateral_mps), (0.5, 0.0));
    assert_eq!(echo.clamp_flags, ClampFlags::LATERAL_UNSUPPORTED);
    assert_eq!(p.stalls, 0);
}

// ---------------------------------------------------------------------------------------------
// 8. Faults and control.

#[test]
fn a_lost_motor_driver_stops_the_robot_until_it_is_back_and_cleared() {
    let mut p = driving(twist(1.0, 0.0), ms(3000));
    let at = p.now();
    assert!(p.inject(Injection::MotorDriverLoss {
        motor: 2,
        lost: true
    }));
    let seen = p
        .run_until_true(ms(100), |p| faults(p) & FaultFlags::MOTOR_2_COMM_LOST != 0)
        .unwrap();
    assert!(seen.saturating_since(at) <= ms(21));
    p.run_for(ms(2000));
    assert!(truth(&p).linear_mps.abs() < 1e-6, "drive stops");
    assert_eq!(
        faults(&p),
        FaultFlags::MOTOR_2_COMM_LOST | FaultFlags::BODY_EXCEPTION
    );
    assert_eq!(faults(&p), truth(&p).fault_flags);
    assert!(p.driver.state().motion.linear_mps.abs() < 1e-3);
    assert!(
        frames(&p, Direction::FromChassis, id::MOTOR_FAST_1 + 1, at + ms(1)).is_empty(),
        "motor 2 is silent"
    );

    // Back, but latched until cleared.
    assert!(p.inject(Injection::MotorDriverLoss {
        motor: 2,
        lost: false
    }));
    p.run_for(ms(1000));
    assert!(truth(&p).linear_mps.abs() < 1e-6);
    assert_ne!(faults(&p) & FaultFlags::MOTOR_2_COMM_LOST, 0);
    let clear_at = p.now();
    let outcome = p.control(&Command::ClearFaults {
        which: FaultClear::MOTOR_2_COMM,
    });
    assert!(matches!(outcome, ControlOutcome::Done(_)), "{outcome:?}");
    assert_eq!(sent(&p, id::CLEAR_FAULT, clear_at)[0].2.data(), [0x02]);
    let moving = time_to_speed(&mut p, 1.0, 0.01, ms(3000));
    println!("motor driver 2: 1 m/s ± 0.01 again {moving:?} after the clear");
    assert_eq!(faults(&p), 0);
    assert_eq!(p.stalls, 0);
}

#[test]
fn a_pressed_bumper_is_reported_and_stops_the_robot_until_released() {
    let mut p = driving(twist(1.0, 0.0), ms(3000));
    let at = p.now();
    assert!(p.inject(Injection::Bumper(true)));
    let seen = p
        .run_until_true(ms(100), |p| faults(p) & FaultFlags::BUMPER != 0)
        .unwrap();
    assert!(seen.saturating_since(at) <= ms(21));
    let stopped = time_to_speed(&mut p, 0.0, 0.01, ms(1000));
    println!("bumper: below 0.01 m/s {stopped:?} after the press");
    assert!(stopped <= ms(500), "{stopped:?}");
    assert_eq!(faults(&p), FaultFlags::BUMPER | FaultFlags::BODY_EXCEPTION);
    assert_eq!(faults(&p), truth(&p).fault_flags);
    assert!(p.inject(Injection::Bumper(false)));
    time_to_speed(&mut p, 1.0, 0.01, ms(3000));
    assert_eq!(faults(&p), 0);
    assert_eq!(p.stalls, 0);
}

#[test]
fn off_road_mode_is_refused_while_moving_and_accepted_while_standing() {
    let mut p = driving(twist(1.0, 0.0), ms(3000));
    let at = p.now();
    let outcome = p.control(&Command::OffRoad { enter: true });
    let ControlOutcome::Refused(reason) = &outcome else {
        panic!("{outcome:?}");
    };
    assert!(
        reason.contains("standing still") && reason.contains("1.00 m/s"),
        "{reason}"
    );
    assert!(sent(&p, id::OFF_ROAD, at).is_empty());

    p.set_command(Velocity::ZERO);
    p.run_for(ms(3000));
    let at = p.now();
    let outcome = p.control(&Command::OffRoad { enter: true });
    assert!(matches!(outcome, ControlOutcome::Done(_)), "{outcome:?}");
    assert_eq!(sent(&p, id::OFF_ROAD, at)[0].2.data(), [0x01]);
    p.run_for(ms(20));
    assert!(p.firmware.off_road(), "the chassis switched");
    assert_eq!(p.driver.state().system.off_road, 1);
    assert_eq!(p.stalls, 0);
}

#[test]
fn steering_zero_completes_only_on_the_chassis_acknowledgement() {
    let mut p = pair();
    p.run_for(ms(100));
    p.take_events();
    let at = p.now();
    let outcome = p.control(&Command::SteeringZero);
    let ControlOutcome::Pending(token) = outcome else {
        panic!("{outcome:?}");
    };
    assert_eq!(sent(&p, id::STEERING_ZERO, at)[0].2.data(), [0xAA]);
    assert!(has_link_flag(&p, LinkFlags::STEERING_ZERO_PENDING));
    assert!(matches!(
        p.control(&Command::SteeringZero),
        ControlOutcome::Refused(_)
    ));

    p.run_for(ms(50));
    assert!(control_done(&p.take_events()).is_empty(), "no answer yet");
    let done_at = p
        .run_until_true(ms(100), |p| {
            !has_link_flag(p, LinkFlags::STEERING_ZERO_PENDING)
        })
        .unwrap();
    assert_eq!(
        done_at,
        at + ms(50) + LATENCY * 2,
        "0x43A 50 ms after 0x431"
    );
    assert_eq!(
        frames(&p, Direction::FromChassis, id::STEERING_ZERO_ACK, at)[0].1,
        at + LATENCY + ms(50)
    );
    let done = control_done(&p.take_events());
    assert_eq!(done.len(), 1);
    assert_eq!((done[0].0, done[0].1), (token, ControlStatus::OK));
    assert_eq!(p.driver.state().system.steering_zero_done, 1);
    assert_eq!(p.stalls, 0);
}

#[test]
fn steering_zero_times_out_when_the_chassis_is_silent() {
    let mut p = pair();
    p.run_for(ms(100));
    assert!(p.inject(Injection::Silence(ms(3000))));
    p.run_until_true(ms(200), |p| has_link_flag(p, LinkFlags::CHASSIS_SILENT))
        .unwrap();
    p.take_events();
    let at = p.now();
    let ControlOutcome::Pending(token) = p.control(&Command::SteeringZero) else {
        panic!("steering zero not pending");
    };
    let timeout = ms(DriverConfig::default().control_timeout_ms);
    p.run_until(at + timeout - Duration::from_nanos(1));
    assert!(control_done(&p.take_events()).is_empty());
    let done_at = p
        .run_until_true(ms(100), |p| {
            !has_link_flag(p, LinkFlags::STEERING_ZERO_PENDING)
        })
        .unwrap();
    assert_eq!(done_at, at + timeout);
    let done = control_done(&p.take_events());
    assert_eq!(done.len(), 1);
    assert_eq!((done[0].0, done[0].1), (token, ControlStatus::TIMEOUT));
    assert!(done[0].2.contains("0x43A"), "{}", done[0].2);
    // No late acknowledgement after the chassis talks again.
    p.run_for(ms(3000));
    assert!(!has_link_flag(&p, LinkFlags::CHASSIS_SILENT));
    assert!(control_done(&p.take_events()).is_empty());
    assert_eq!(p.driver.state().system.steering_zero_done, 0);
    assert_eq!(p.stalls, 0);
}

#[test]
fn in_silent_mode_the_chassis_is_flagged_silent_and_the_heartbeat_goes_on() {
    let mut p = pair();
    p.run_for(ms(100));
    let at = p.now();
    let outcome = p.control(&Command::Silent { enter: true });
    assert!(matches!(outcome, ControlOutcome::Done(_)), "{outcome:?}");
    assert_eq!(sent(&p, id::SILENT_MODE, at)[0].2.data(), [0x01]);
    assert!(has_link_flag(&p, LinkFlags::SILENT_MODE));
    let silent_at = p
        .run_until_true(ms(300), |p| has_link_flag(p, LinkFlags::CHASSIS_SILENT))
        .unwrap();
    assert!(silent_at.saturating_since(at) <= ms(121));
    p.run_until(at + ms(2000));
    assert!(
        p.log()
            .iter()
            .all(|r| r.direction == Direction::ToChassis || r.at <= at),
        "the chassis sent nothing"
    );
    let beats = motion_sent(&p, at + ms(1));
    assert_eq!(beats.len(), 100, "0x111 every 20 ms through 2 s");
    assert!(
        beats
            .windows(2)
            .all(|w| w[1].1.saturating_since(w[0].1) == PERIOD)
    );
    let t = truth(&p);
    assert_eq!(t.control_mode, ControlMode::COMMAND, "heartbeat honoured");
    assert_eq!(t.fault_flags & FaultFlags::HEARTBEAT_LOST, 0);

    let leave_at = p.now();
    assert!(matches!(
        p.control(&Command::Silent { enter: false }),
        ControlOutcome::Done(_)
    ));
    let back = p
        .run_until_true(ms(100), |p| !has_link_flag(p, LinkFlags::CHASSIS_SILENT))
        .unwrap();
    assert!(back.saturating_since(leave_at) <= ms(21));
    assert!(!has_link_flag(&p, LinkFlags::SILENT_MODE));
    assert_eq!(p.stalls, 0);
}

// ---------------------------------------------------------------------------------------------
// 9. Garbage and floods.

#[test]
fn garbage_frames_are_counted_as_unknown_ids_and_change_nothing_else() {
    let mut p = driving(twist(1.0, 0.2), ms(2000));
    // Between two feedback slots, after everything in flight has arrived.
    run_to_fresh_feedback(&mut p);
    p.run_for(ms(5));
    let before = *p.driver.state();
    p.take_events();
    assert!(p.inject(Injection::Garbage((0u8..24).collect())));
    p.run_for(ms(1));
    let after = *p.driver.state();
    assert_eq!(after.link.rx_unknown_id, before.link.rx_unknown_id + 3);
    let mut expected = before;
    expected.link.rx_unknown_id += 3;
    assert_eq!(after, expected, "nothing but the counter changed");
    let events = p.take_events();
    assert_eq!(events.len(), 3);
    assert!(
        events
            .iter()
            .all(|e| matches!(e, DriverEvent::RxDropped { reason } if reason.contains("7F0")))
    );

    // Garbage is not a sign of life.
    assert!(p.inject(Injection::Silence(ms(1000))));
    p.run_for(ms(300));
    assert!(has_link_flag(&p, LinkFlags::CHASSIS_SILENT));
    assert!(p.inject(Injection::Garbage(vec![0xFF; 64])));
    p.run_for(ms(5));
    assert!(has_link_flag(&p, LinkFlags::CHASSIS_SILENT));
    assert_eq!(
        p.driver.state().link.rx_unknown_id,
        before.link.rx_unknown_id + 11
    );
    assert_eq!(p.stalls, 0);
}

#[test]
fn a_10_s_flood_of_4000_frames_per_second_does_not_disturb_the_heartbeat() {
    let mut p = driving(twist(1.0, 0.3), ms(1000));
    let at = p.now();
    let rx_before = p.driver.state().link.rx_frames;
    assert!(p.inject(Injection::Flood { frames_per_s: 4000 }));
    p.run_for(ms(10_000));
    assert!(p.inject(Injection::Flood { frames_per_s: 0 }));
    let rx = p.driver.state().link.rx_frames - rx_before;
    let after = at + Duration::from_nanos(1);
    let flood = frames(&p, Direction::FromChassis, id::MOTION_FEEDBACK, after).len()
        + frames(&p, Direction::FromChassis, id::MOTOR_FAST_1, after).len()
        - 2 * 500;
    assert_eq!(flood, 40_000, "4000 extra frames per second");
    assert!(rx >= 40_000 + 500 * 9, "{rx} frames received");
    let beats = motion_sent(&p, after);
    assert_eq!(beats.len(), 500);
    assert!(
        beats
            .windows(2)
            .all(|w| w[1].1.saturating_since(w[0].1) == PERIOD),
        "every 0x111 interval is 20 ms"
    );
    assert_eq!(p.driver.state().link.rx_unknown_id, 0);
    assert_eq!(p.driver.state().link.rx_decode_errors, 0);
    let t = truth(&p);
    assert!((t.linear_mps - 1.0).abs() < 1e-6);
    assert!(!has_link_flag(&p, LinkFlags::CHASSIS_SILENT));
    let s = p.driver.state();
    let pos_err = (s.odometry.x_m - t.x_m).hypot(s.odometry.y_m - t.y_m);
    println!("flood: {rx} frames in 10 s, pose error {pos_err:.2e} m");
    assert!(pos_err < 0.05, "{pos_err}");
    assert_eq!(p.stalls, 0);
}

// ---------------------------------------------------------------------------------------------
// 10. A long run.

/// A deterministic pseudo-random sequence (64-bit LCG, Knuth's MMIX constants).
struct Lcg(u64);

impl Lcg {
    /// Uniform in [0, 1).
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[test]
fn three_thousand_simulated_seconds_of_driving_run_without_stalls_and_the_pose_tracks_the_truth() {
    let mut p = pair();
    p.record = false;
    p.run_for(ms(100));
    // Every second starts just after a feedback slot reached the driver, so the comparisons below
    // measure integration drift, not the up to 20 ms age of the last feedback.
    run_to_fresh_feedback(&mut p);
    let mut rng = Lcg(0x7174_414E);
    let mut max_pos_err = 0.0f64;
    let mut max_yaw_err = 0.0f64;
    let mut distance = 0.0;
    let mut last_odometer = 0.0;
    for second in 0..3000 {
        let command = if second % 17 == 16 {
            Velocity::ZERO
        } else {
            twist(rng.next() * 2.4 - 1.2, rng.next() * 1.0 - 0.5)
        };
        p.set_command(command);
        p.run_for(ms(1000));
        let t = truth(&p);
        let s = p.driver.state();
        max_pos_err = max_pos_err.max((s.odometry.x_m - t.x_m).hypot(s.odometry.y_m - t.y_m));
        max_yaw_err = max_yaw_err.max(wrap_angle(s.odometry.yaw_rad - t.yaw_rad).abs());
        let (odometer, _) = p.firmware.odometers_m();
        distance += (odometer - last_odometer).abs();
        last_odometer = odometer;
    }
    p.set_command(Velocity::ZERO);
    p.run_for(ms(2000));
    let t = truth(&p);
    let s = p.driver.state();
    let pos_err = (s.odometry.x_m - t.x_m).hypot(s.odometry.y_m - t.y_m);
    let yaw_err = wrap_angle(s.odometry.yaw_rad - t.yaw_rad).abs();
    println!(
        "long run: 3000 simulated s; {:.0} m \
         driven (Σ |Δ odometer| per second), final pose error {pos_err:.3e} m / {yaw_err:.3e} \
         rad, max {max_pos_err:.3e} m / {max_yaw_err:.3e} rad; {} frames received, SOC {:.1} %",
        distance, s.link.rx_frames, t.soc_pct
    );
    assert_eq!(p.stalls, 0);
    assert_eq!(t.fault_flags & !FaultFlags::WARNINGS, 0, "no fault");
    assert_eq!(s.link.rx_decode_errors + s.link.rx_unknown_id, 0);
    assert!(!has_link_flag(&p, LinkFlags::CHASSIS_SILENT));
    assert!(distance > 1000.0, "{distance} m");
    // Drift of the driver's dead reckoning against the true pose: both integrate the same speeds,
    // the driver from 20 ms samples quantised to 1 mm/s and 1 mrad.
    assert!(
        max_pos_err < 0.0005 * distance,
        "drift {max_pos_err} m over {distance} m"
    );
    assert!(max_yaw_err < 0.02, "yaw drift {max_yaw_err} rad");
}

// ---------------------------------------------------------------------------------------------
// 11. Shutdown.

#[test]
fn shutdown_sends_a_zero_command_and_then_engages_the_brake() {
    let mut p = driving(twist(1.0, 0.0), ms(3000));
    let at = p.now();
    let logged = p.log().len();
    p.driver.shutdown(at);
    p.run_for(Duration::ZERO);
    let after: Vec<_> = p.log()[logged..]
        .iter()
        .filter(|r| r.direction == Direction::ToChassis)
        .map(|r| (r.at, *r.item.as_can().unwrap()))
        .collect();
    assert!(after.len() >= 2, "{after:?}");
    assert_eq!(after[0].0, at);
    assert_eq!(
        (after[0].1.id(), after[0].1.data()),
        (u32::from(id::MOTION_COMMAND), &[0u8; 8][..]),
        "zero first"
    );
    assert_eq!(
        (after[1].1.id(), after[1].1.data()),
        (u32::from(id::PARKING_BRAKE), &[0x00][..]),
        "then the brake"
    );
    p.run_for(ms(1000));
    assert!(
        motion_sent(&p, at)
            .iter()
            .filter(|(i, _, _)| *i >= logged)
            .all(|(_, _, m)| *m == MotionCommand::default())
    );
    let t = truth(&p);
    assert!(t.brake_engaged);
    assert!(t.linear_mps.abs() < 1e-3, "{}", t.linear_mps);
    assert_eq!(brake_sent(&p, at).len(), 1);
    assert_eq!(p.stalls, 0);
}
