//! Protocol-V2 scenarios: the driver against the simulated chassis on simulated time, for each
//! kinematic kind (BUNKER differential, SCOUT MINI omni, HUNTER Ackermann, RANGER MINI
//! four-wheel steering), wired back to back by [`Pair`].

use std::time::Duration;

use chassis_interfaces::{ControlMode, FaultFlags, LinkFlags, Velocity};

use super::{Frame, V2Driver, V2Model, V2Profile, V2Sim, decode, id};
use crate::Direction;
use crate::command::Command;
use crate::driver::{Driver, DriverConfig};
use crate::firmware::{Firmware, Injection};
use crate::pair::Pair;
use crate::time::Timestamp;

type V2Pair = Pair<V2Driver, V2Sim>;

const T0: Timestamp = Timestamp::from_millis(1_000);

fn ms(v: u64) -> Duration {
    Duration::from_millis(v)
}

fn twist(vx: f64, vy: f64, w: f64) -> Velocity {
    Velocity::new(vx as f32, vy as f32, w as f32).unwrap()
}

fn pair(model: V2Model) -> V2Pair {
    let profile = V2Profile::for_model(model);
    let driver = V2Driver::new(profile.clone(), DriverConfig::default(), T0);
    let sim = V2Sim::new(profile, T0);
    let mut p = Pair::new(driver, sim, T0);
    p.record = true;
    p
}

/// The frames the driver sent, decoded.
fn sent(p: &V2Pair) -> Vec<(Timestamp, Frame)> {
    p.log()
        .iter()
        .filter(|r| r.direction == Direction::ToChassis)
        .filter_map(|r| {
            let frame = r.item.as_can()?;
            Some((r.at, decode(frame, p.driver.profile()).ok()?))
        })
        .collect()
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

/// The kinds, with a twist each can follow exactly: differential (BUNKER), omni (SCOUT MINI
/// mecanum), Ackermann (HUNTER) and the three motion modes of four-wheel steering (RANGER MINI
/// dual Ackermann, crab, spin).
const KINDS: [(V2Model, f64, f64, f64); 6] = [
    (V2Model::Bunker, 0.5, 0.0, 0.3),
    (V2Model::ScoutMiniOmni, 0.4, 0.2, 0.3),
    (V2Model::Hunter, 0.8, 0.0, 0.4),
    (V2Model::RangerMini, 0.6, 0.0, 0.3),
    (V2Model::RangerMini, 0.3, 0.3, 0.0),
    (V2Model::RangerMini, 0.0, 0.0, 0.8),
];

/// The speed a kind has while following its twist (crab: along the wheels).
fn follows(p: &V2Pair, (vx, vy, w): (f64, f64, f64)) -> bool {
    let t = p.firmware.truth();
    close(t.linear_mps, vx, 1e-3)
        && close(t.lateral_mps, vy, 1e-3)
        && close(t.angular_radps, w, 1e-3)
}

/// Standing: no body speed at all.
fn standing(p: &V2Pair) -> bool {
    let t = p.firmware.truth();
    close(t.linear_mps, 0.0, 0.01)
        && close(t.lateral_mps, 0.0, 0.01)
        && close(t.angular_radps, 0.0, 0.01)
}

#[test]
fn power_up_enable_drive_stop_for_every_kinematic_kind() {
    for (model, vx, vy, w) in KINDS {
        let mut p = pair(model);
        // Standby at power-up; the driver's 0x421 puts the chassis in CAN command mode at once.
        assert_eq!(sent(&p).len(), 0);
        p.run_for(ms(150));
        assert_eq!(
            p.firmware.truth().control_mode,
            ControlMode::COMMAND,
            "{model:?}"
        );
        assert_ne!(p.driver.state().link_flags & LinkFlags::COMMAND_MODE, 0);
        p.set_command(twist(vx, vy, w));
        p.run_for(ms(3000));
        let t = p.firmware.truth();
        assert!(close(t.linear_mps, vx, 1e-3), "{model:?}: {t:?}");
        assert!(close(t.lateral_mps, vy, 1e-3), "{model:?}: {t:?}");
        assert!(close(t.angular_radps, w, 1e-3), "{model:?}: {t:?}");
        let s = p.driver.state();
        assert!(close(s.motion.linear_mps.into(), vx, 2e-3), "{model:?}");
        assert!(close(s.motion.angular_radps.into(), w, 2e-3), "{model:?}");
        assert_eq!(s.command.clamp_flags, 0, "{model:?}");
        // The driver's integrated pose follows the chassis' true one.
        assert!(
            close(s.odometry.x_m, t.x_m, 0.05) && close(s.odometry.y_m, t.y_m, 0.05),
            "{model:?}: {} {} vs {} {}",
            s.odometry.x_m,
            s.odometry.y_m,
            t.x_m,
            t.y_m
        );
        p.set_command(Velocity::ZERO);
        p.run_for(ms(2000));
        assert!(close(p.firmware.truth().linear_mps, 0.0, 1e-3), "{model:?}");
        // Only V2 command ids ever went out, and 0x111 at the heartbeat period.
        let frames = sent(&p);
        assert!(
            frames
                .iter()
                .all(|(_, f)| f.direction() == Direction::ToChassis)
        );
        let heartbeats: Vec<Timestamp> = frames
            .iter()
            .filter(|(_, f)| f.id() == id::MOTION_COMMAND)
            .map(|(t, _)| *t)
            .collect();
        assert!(
            heartbeats.len() >= 5000 / 20 - 2,
            "{model:?}: {}",
            heartbeats.len()
        );
        assert!(
            heartbeats
                .windows(2)
                .all(|w| w[1].saturating_since(w[0]) <= ms(20)),
            "{model:?}"
        );
    }
}

#[test]
fn ranger_sends_its_motion_mode_before_the_motion_that_needs_it() {
    let mut p = pair(V2Model::RangerMini);
    p.run_for(ms(100));
    p.clear_log();
    p.set_command(twist(0.0, 0.0, 1.0));
    p.run_for(ms(1500));
    let frames = sent(&p);
    let first_mode = frames
        .iter()
        .position(|(_, f)| matches!(f, Frame::MotionModeCommand(m) if m.mode == 2));
    let first_spin = frames
        .iter()
        .position(|(_, f)| matches!(f, Frame::MotionCommand(m) if m.angular_radps != 0.0));
    assert!(
        first_mode.is_some() && first_mode < first_spin,
        "{frames:?}"
    );
    assert!(close(p.firmware.truth().angular_radps, 1.0, 1e-3));
    assert!(close(p.firmware.truth().linear_mps, 0.0, 1e-9));
    // Then sideways: crab mode.
    p.set_command(twist(0.0, 0.3, 0.0));
    p.run_for(ms(1500));
    let t = p.firmware.truth();
    assert!(
        close(t.lateral_mps, 0.3, 1e-3) && close(t.angular_radps, 0.0, 1e-9),
        "{t:?}"
    );
}

#[test]
fn heartbeat_gap_stops_the_chassis_and_the_next_command_resumes() {
    for (model, vx, vy, w) in KINDS {
        let mut p = pair(model);
        p.run_for(ms(100));
        p.set_command(twist(vx, vy, w));
        p.run_for(ms(1500));
        assert!(
            follows(&p, (vx, vy, w)),
            "{model:?}: {:?}",
            p.firmware.truth()
        );
        p.cut = true;
        p.run_for(ms(1500));
        let t = p.firmware.truth();
        assert!(standing(&p), "{model:?}: {t:?}");
        assert_ne!(t.fault_flags & FaultFlags::HEARTBEAT_LOST, 0, "{model:?}");
        assert_ne!(
            p.driver.state().link_flags & LinkFlags::CHASSIS_SILENT,
            0,
            "{model:?}"
        );
        p.cut = false;
        p.run_for(ms(2000));
        let t = p.firmware.truth();
        assert!(follows(&p, (vx, vy, w)), "{model:?}: {t:?}");
        assert_eq!(t.fault_flags & FaultFlags::HEARTBEAT_LOST, 0, "{model:?}");
    }
}

#[test]
fn reboot_mid_drive_is_back_in_can_mode_within_100_ms_of_its_first_report() {
    for (model, vx, vy, w) in KINDS {
        let mut p = pair(model);
        p.run_for(ms(100));
        p.set_command(twist(vx, vy, w));
        p.run_for(ms(1000));
        assert!(p.inject(Injection::Reboot));
        assert_eq!(p.firmware.truth().control_mode, ControlMode::STANDBY);
        // Boot silence 300 ms; the first 0x211 after it (≤ 100 ms period) triggers 0x421.
        let back = p.run_until_true(ms(1000), |p| {
            p.firmware.truth().control_mode == ControlMode::COMMAND
        });
        assert!(back.is_some(), "{model:?}");
        assert_eq!(p.firmware.truth().boots, 2);
        // It follows the mux's current output again (§8 item 4: same rule as the TITAN).
        p.run_for(ms(3000));
        assert!(
            follows(&p, (vx, vy, w)),
            "{model:?}: {:?}",
            p.firmware.truth()
        );
    }
    // The timing on a robot reporting every 20 ms: CAN mode back within 100 ms of the boot end.
    let mut p = pair(V2Model::RangerMini);
    p.run_for(ms(100));
    let reboot_at = p.now();
    assert!(p.inject(Injection::Reboot));
    let back = p
        .run_until_true(ms(1000), |p| {
            p.firmware.truth().control_mode == ControlMode::COMMAND
        })
        .expect("back in CAN mode");
    let boot_end = reboot_at + V2Sim::DEFAULT_BOOT_TIME;
    assert!(back.saturating_since(boot_end) <= ms(100), "{back:?}");
}

/// [`Injection::Silence`] stops everything the chassis sends, feedback and replies alike, for
/// its length; then the feedback resumes on its own.
#[test]
fn an_injected_silence_silences_the_chassis_for_its_length() {
    for (model, ..) in KINDS {
        let mut p = pair(model);
        p.run_for(ms(500));
        assert!(p.inject(Injection::Silence(ms(1000))));
        p.clear_log();
        p.run_for(ms(990));
        let from_chassis = |p: &V2Pair| {
            p.log()
                .iter()
                .filter(|r| r.direction == Direction::FromChassis)
                .count()
        };
        assert_eq!(from_chassis(&p), 0, "{model:?}");
        p.run_for(ms(200));
        assert!(from_chassis(&p) > 0, "{model:?}");
    }
}

#[test]
fn rc_takeover_is_reported_never_fought_and_the_hand_back_is_taken_over() {
    for (model, vx, vy, w) in KINDS {
        let mut p = pair(model);
        p.run_for(ms(100));
        p.set_command(twist(vx, vy, w));
        p.run_for(ms(1500));
        assert!(p.inject(Injection::RcTakeover(true)));
        p.run_for(ms(200));
        p.clear_log();
        p.run_for(ms(1000));
        assert_ne!(
            p.driver.state().link_flags & LinkFlags::RC_AUTHORITY,
            0,
            "{model:?}"
        );
        assert_eq!(
            p.firmware.truth().control_mode,
            ControlMode::REMOTE,
            "{model:?}"
        );
        assert!(standing(&p), "{model:?}: {:?}", p.firmware.truth());
        assert!(
            !sent(&p).iter().any(|(_, f)| f.id() == id::MODE),
            "{model:?}: 0x421 sent while the RC holds authority"
        );
        assert!(p.inject(Injection::RcTakeover(false)));
        let back = p.run_until_true(ms(1000), |p| {
            p.firmware.truth().control_mode == ControlMode::COMMAND
        });
        assert!(back.is_some(), "{model:?}");
        p.run_for(ms(2000));
        assert!(
            follows(&p, (vx, vy, w)),
            "{model:?}: {:?}",
            p.firmware.truth()
        );
    }
}

/// The driver reports the chassis' E-stop while it is pressed, and nothing else: the rule after
/// its release (motion only from a zero) is the service's, for every stop (chassisd's engine
/// scenario `a_chassis_estop_holds_zero_and_its_release_waits_for_a_zero`).
#[test]
fn the_estop_switch_is_reported_while_pressed_and_the_driver_keeps_no_rule_of_its_own() {
    for (model, vx, vy, w) in KINDS {
        let mut p = pair(model);
        p.run_for(ms(100));
        p.set_command(twist(vx, vy, w));
        p.run_for(ms(1500));
        assert!(p.inject(Injection::EStop(true)));
        p.run_for(ms(1000));
        assert!(standing(&p), "{model:?}: {:?}", p.firmware.truth());
        assert_ne!(
            p.driver.state().system.fault_flags & FaultFlags::EMERGENCY_STOP,
            0,
            "{model:?}"
        );
        assert!(p.inject(Injection::EStop(false)));
        p.set_command(twist(vx, vy, w));
        p.run_for(ms(2000));
        assert_eq!(
            p.driver.state().system.fault_flags & FaultFlags::EMERGENCY_STOP,
            0,
            "{model:?}"
        );
        assert!(
            follows(&p, (vx, vy, w)),
            "{model:?}: {:?}",
            p.firmware.truth()
        );
    }
}

#[test]
fn limits_are_applied_by_the_driver_before_the_wire() {
    for (model, vx, vy, w) in [
        (V2Model::Bunker, 5.0, 0.0, 3.0),
        (V2Model::ScoutMini, 5.0, 0.0, 5.0),
        (V2Model::ScoutMiniOmni, 5.0, 5.0, 0.0),
        (V2Model::Hunter, 5.0, 0.0, 5.0),
        (V2Model::RangerMini, 5.0, 0.0, 0.0),
        (V2Model::RangerMini, 0.0, 0.0, 9.0),
    ] {
        let mut p = pair(model);
        p.run_for(ms(100));
        p.set_command(twist(vx, vy, w));
        p.run_for(ms(2000));
        let profile = p.driver.profile().clone();
        let t = p.firmware.truth();
        assert_ne!(p.driver.state().command.clamp_flags, 0, "{model:?}");
        if vx != 0.0 {
            assert!(
                close(t.linear_mps, profile.max_linear_mps, 1e-3),
                "{model:?}: {t:?}"
            );
        }
        if vy != 0.0 {
            assert!(
                close(t.lateral_mps, profile.max_lateral_mps, 1e-3),
                "{model:?}: {t:?}"
            );
        }
        if vx == 0.0 && vy == 0.0 {
            assert!(
                close(t.angular_radps, profile.max_angular_radps, 1e-3),
                "{model:?}: {t:?}"
            );
        }
        assert_eq!(p.firmware.commands_clamped(), 0, "{model:?}");
    }
}

#[test]
fn hunter_releases_its_brake_before_motion_and_engages_it_on_shutdown() {
    let mut p = pair(V2Model::Hunter);
    p.run_for(ms(100));
    assert!(p.firmware.truth().brake_engaged);
    p.set_command(twist(0.5, 0.0, 0.0));
    p.run_for(ms(1000));
    assert!(!p.firmware.truth().brake_engaged);
    let frames = sent(&p);
    let release = frames
        .iter()
        .position(|(_, f)| matches!(f, Frame::ParkingBrake(b) if !b.engage));
    let motion = frames
        .iter()
        .position(|(_, f)| matches!(f, Frame::MotionCommand(m) if m.linear_mps != 0.0));
    assert!(release.is_some() && release < motion);
    p.driver.shutdown(p.now());
    p.run_for(ms(500));
    assert!(p.firmware.truth().brake_engaged);
    // Robots without a brake never see 0x131.
    let mut b = pair(V2Model::Bunker);
    b.run_for(ms(100));
    b.set_command(twist(0.5, 0.0, 0.0));
    b.run_for(ms(500));
    b.driver.shutdown(b.now());
    b.run_for(ms(100));
    assert!(!sent(&b).iter().any(|(_, f)| f.id() == id::PARKING_BRAKE));
}

#[test]
fn lights_are_refreshed_while_overridden_and_handed_back_once() {
    let mut p = pair(V2Model::Scout);
    p.run_for(ms(100));
    let outcome = p.control(&Command::Lights {
        enable: true,
        mode: 1,
        brightness_pct: 0,
    });
    assert_eq!(outcome.status(), chassis_interfaces::ControlStatus::OK);
    p.clear_log();
    p.run_for(ms(1000));
    let lights = sent(&p)
        .iter()
        .filter(|(_, f)| f.id() == id::LIGHT_COMMAND)
        .count();
    assert!((4..=6).contains(&lights), "{lights}");
    assert!(p.firmware.lights().enabled);
    p.control(&Command::Lights {
        enable: false,
        mode: 0,
        brightness_pct: 0,
    });
    p.run_for(ms(100));
    assert!(!p.firmware.lights().enabled);
    p.clear_log();
    p.run_for(ms(1000));
    assert!(!sent(&p).iter().any(|(_, f)| f.id() == id::LIGHT_COMMAND));
}

#[test]
fn hunter_steering_zero_is_acknowledged() {
    let mut p = pair(V2Model::Hunter);
    p.run_for(ms(100));
    let outcome = p.control(&Command::SteeringZero);
    assert!(matches!(outcome, crate::driver::ControlOutcome::Pending(_)));
    p.run_for(ms(100));
    assert_eq!(p.driver.state().system.steering_zero_done, 1);
    assert_eq!(
        p.driver.state().link_flags & LinkFlags::STEERING_ZERO_PENDING,
        0
    );
}

#[test]
fn the_version_is_asked_once_in_can_mode_and_its_answer_logged() {
    let mut p = pair(V2Model::Scout);
    p.run_for(ms(2000));
    let asked: Vec<u16> = sent(&p)
        .iter()
        .map(|(_, f)| f.id())
        .filter(|id| matches!(*id, 0x411 | 0x4A1))
        .collect();
    // The simulated chassis answers 0x411 with 0x41A: no 0x4A1 fallback.
    assert_eq!(asked, [0x411]);
    let notices = crate::pair::notices(&p.take_events());
    assert!(
        notices
            .iter()
            .any(|(_, m)| m.contains("controller hw 1.0 sw 2.0")),
        "{notices:?}"
    );
    // With `sdk` the 0x4A1 text is asked for instead, and logged.
    let profile = V2Profile {
        version_query: super::profile::VersionQuery::Sdk,
        ..V2Profile::for_model(V2Model::Bunker)
    };
    let driver = V2Driver::new(profile.clone(), DriverConfig::default(), T0);
    let mut p = Pair::new(driver, V2Sim::new(profile, T0), T0);
    p.run_for(ms(500));
    let notices = crate::pair::notices(&p.take_events());
    assert!(
        notices
            .iter()
            .any(|(_, m)| m.starts_with("chassis version text: AgileX")),
        "{notices:?}"
    );
}
