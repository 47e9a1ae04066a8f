//! The service's rules as scenarios: the engine, the TITAN driver (SCOUT MINI and XBot where
//! said) and the simulated chassis, on simulated time (see [`super::rig`]).
//!
//! Every rig starts at [`T0`] with the loop's 20 ms tick and the driver's heartbeat both anchored
//! there, so the instants below are exact. The safety monitor (the required source) sends a
//! heartbeat every 50 ms unless a scenario says otherwise, and the mux does not smooth unless a
//! scenario says so: a frame's speed is then the request's.

use std::time::Duration;

use chassis_interfaces::{
    ControlKind, ControlMode, ControlRequest, ControlStatus, ControllerState, DriveState,
    LinkFlags, LockStatus, Stop, StopCategory, VelocityRequest, ZeroReason,
};
use chassis_protocols::{Injection, Protocol, RobotKind, Timestamp, WireItem, titan};
use chassisd_config::mux::MuxConfig;

use super::rig::{LATENCY, Rig, T0};
use super::{Device, HeldLock, ListenerChange, Wake, WakeBudget};
use zerocopy::IntoBytes;

fn ms(v: u64) -> Duration {
    Duration::from_millis(v)
}

fn at(offset_ms: u64) -> Timestamp {
    T0 + ms(offset_ms)
}

/// The default sources and lock, without acceleration smoothing.
fn unsmoothed() -> MuxConfig {
    let mut mux = MuxConfig::default();
    mux.limits.linear_accel_mps2 = 0.0;
    mux.limits.angular_accel_radps2 = 0.0;
    mux
}

/// A TITAN rig whose safety monitor beats every 50 ms for `seconds`, run 200 ms: the chassis is
/// in CAN command mode and nothing asks for motion.
fn ready_for(robot: RobotKind, mux: MuxConfig, seconds: u64) -> Rig {
    let mut rig = Rig::with(robot, mux, |_| {});
    rig.publish_every(
        "safety",
        VelocityRequest::heartbeat(),
        ms(50),
        T0 + Duration::from_secs(seconds),
    );
    rig.run_until(at(200));
    rig
}

fn ready() -> Rig {
    ready_for(RobotKind::Titan, unsmoothed(), 60)
}

fn twist(v: f32) -> VelocityRequest {
    VelocityRequest::twist(v, 0.0)
}

/// The speed of the first motion frame the engine hands out at `t` (rounded to the wire's mm/s).
fn first_motion_polled(rig: &mut Rig, t: Timestamp) -> Option<f64> {
    while let Some(item) = rig.engine.poll_transmit(t) {
        if let Some(v) = rig.commanded_speed(&item) {
            return Some((v * 1000.0).round() / 1000.0);
        }
    }
    None
}

/// `request` as a client sends it at `t`.
fn stamped(request: VelocityRequest, t: Timestamp) -> VelocityRequest {
    VelocityRequest {
        stamp_ns: t.as_nanos(),
        ..request
    }
}

/// The speed of the last motion frame written at or before `t`.
fn speed_at(rig: &Rig, t: Timestamp) -> f64 {
    rig.motion()
        .into_iter()
        .take_while(|&(when, _)| when <= t)
        .last()
        .map_or(0.0, |(_, v)| v)
}

fn control(kind: u8) -> ControlRequest {
    ControlRequest::new(kind)
}

#[test]
fn a_request_is_on_the_wire_the_instant_it_is_read() {
    let mut rig = ready();
    let t = at(207);
    rig.request_at(t, "teleop", twist(0.5));
    rig.run_until(at(260));
    assert_eq!(rig.first_motion(at(200), |v| v > 0.0), Some(t));
    assert!((speed_at(&rig, t) - 0.5).abs() < 1e-3);
}

#[test]
fn the_heartbeat_repeats_the_command_on_its_20_ms_grid() {
    let mut rig = ready();
    rig.request_at(at(207), "teleop", twist(0.5));
    rig.publish_every("teleop", twist(0.5), ms(100), at(600));
    rig.run_until(at(400));
    let times: Vec<Timestamp> = rig
        .motion()
        .into_iter()
        .filter(|&(when, v)| when > at(207) && v > 0.0)
        .map(|(when, _)| when)
        .collect();
    // The grid of the driver's heartbeat (anchored at T0), whatever the request times.
    assert_eq!(times[..5], [at(220), at(240), at(260), at(280), at(300)]);
}

#[test]
fn a_command_is_decided_before_the_bus_is_drained() {
    let mut rig = ready();
    let t = at(231);
    let titan_profile = chassis_protocols::titan::TitanProfile::default();
    let feedback = WireItem::Can(
        titan::Frame::MotionFeedback(titan::MotionFeedback::default())
            .encode(&titan_profile)
            .unwrap(),
    );
    // A request and a feedback frame are read at the same instant, in the shell's order or not:
    // the driver has the new command before it sees the frame.
    rig.engine.begin_pass(t, Wake::default());
    rig.engine
        .handle_request(t, rig.source("teleop"), &stamped(twist(0.7), t))
        .unwrap();
    rig.engine.handle_rx(t, feedback.as_rx());
    assert!((rig.engine.mux().output().linear_x_mps() - 0.7).abs() < 1e-6);
    assert_eq!(rig.engine.mux().status().stamp_ns, t.as_nanos());
    assert_eq!(first_motion_polled(&mut rig, t), Some(0.7));
}

#[test]
fn a_request_that_arrives_during_a_pass_is_decided_again() {
    let mut rig = ready();
    let t = at(231);
    let teleop = rig.source("teleop");
    rig.engine.begin_pass(t, Wake::default());
    rig.engine
        .handle_request(t, teleop, &stamped(twist(0.5), t))
        .unwrap();
    assert_eq!(first_motion_polled(&mut rig, t), Some(0.5));
    while rig.engine.poll_transmit(t).is_some() {}
    // Another request, read later in the same pass: a stop goes out at once.
    let later = t + Duration::from_micros(40);
    rig.engine
        .handle_request(later, teleop, &stamped(twist(0.0), later))
        .unwrap();
    assert_eq!(first_motion_polled(&mut rig, later), Some(0.0));
}

#[test]
fn a_request_that_lands_while_its_listener_is_acknowledged_is_sent_in_the_same_pass() {
    let mut rig = ready();
    let t = at(231);
    rig.request_at(t, "teleop", twist(0.5));
    // Published after the pass read teleop, before it consumed teleop's notification: its
    // notification is consumed with the first, and only the read after it finds the request.
    rig.request_meanwhile(t, "teleop", twist(0.0));
    rig.run_until(at(240));
    let sent: Vec<f64> = rig
        .motion()
        .into_iter()
        .filter(|&(when, _)| when == t)
        .map(|(_, v)| v)
        .collect();
    assert_eq!(sent, [0.5, 0.0]);
    assert_eq!(
        rig.world.passes.iter().filter(|&&p| p == t).count(),
        1,
        "decided and sent by the pass that acknowledged it, not a later one"
    );
}

#[test]
fn a_changed_command_waits_for_the_drivers_minimum_interval_but_a_stop_does_not() {
    let mut rig = ready();
    rig.request_at(at(207), "teleop", twist(0.5));
    rig.request_at(at(207) + Duration::from_micros(500), "teleop", twist(0.6));
    rig.request_at(at(208), "teleop", twist(0.0));
    rig.run_until(at(215));
    let motion = rig.motion();
    let after: Vec<(Timestamp, f64)> = motion.into_iter().filter(|&(t, _)| t >= at(207)).collect();
    assert_eq!(after[0].0, at(207));
    // 0.6 would be due 2 ms after the 0.5 frame; the stop at 208 replaces it and is not delayed.
    assert_eq!(after[1].0, at(208));
    assert_eq!(after[1].1, 0.0);
    assert_eq!(after.len(), 2, "{after:?}");
}

#[test]
fn a_dead_source_motion_ends_exactly_at_its_timeout() {
    let mut rig = ready();
    let last = at(307);
    rig.request_at(at(207), "teleop", twist(0.5));
    rig.request_at(last, "teleop", twist(0.5));
    rig.run_until(at(1200));
    let stop = rig.first_motion(last, |v| v == 0.0);
    assert_eq!(stop, Some(last + ms(300)), "teleop's timeout is 300 ms");
    assert_eq!(
        speed_at(&rig, last + ms(300) - Duration::from_nanos(1)),
        0.5
    );
    assert!(
        rig.motion()
            .iter()
            .all(|&(t, v)| t < last + ms(300) || v == 0.0)
    );
    assert_eq!(rig.mux().zero_reason, ZeroReason::NO_ACTIVE_SOURCE);
}

#[test]
fn the_planner_times_out_at_its_own_500_ms() {
    let mut rig = ready();
    rig.request_at(at(213), "planner", twist(0.3));
    rig.run_until(at(1000));
    assert_eq!(rig.first_motion(at(214), |v| v == 0.0), Some(at(713)));
}

#[test]
fn a_higher_priority_source_preempts_and_hands_back_at_its_timeout() {
    let mut rig = ready();
    rig.publish_every("planner", twist(0.3), ms(40), at(2000));
    rig.request_at(at(405), "teleop", twist(0.8));
    rig.request_at(at(505), "teleop", twist(0.8));
    rig.run_until(at(1000));
    // The heartbeat went out at 200: a changed command waits the driver's 2 ms minimum interval.
    assert_eq!(
        rig.first_motion(at(200), |v| (v - 0.3).abs() < 1e-3),
        Some(at(202))
    );
    assert_eq!(
        rig.first_motion(at(201), |v| (v - 0.8).abs() < 1e-3),
        Some(at(405))
    );
    assert_eq!(
        rig.first_motion(at(406), |v| (v - 0.3).abs() < 1e-3),
        Some(at(805)),
        "handed back when teleop's last request is 300 ms old"
    );
}

#[test]
fn nothing_moves_before_the_safety_monitor_speaks() {
    let mut rig = Rig::with(RobotKind::Titan, unsmoothed(), |_| {});
    rig.publish_every("teleop", twist(0.5), ms(50), at(1000));
    rig.request_at(at(600), "safety", VelocityRequest::heartbeat());
    rig.run_until(at(650));
    assert_eq!(rig.first_motion(T0, |v| v != 0.0), Some(at(600)));
    assert!(
        rig.world
            .muxes
            .iter()
            .any(|m| m.zero_reason == ZeroReason::REQUIRED_SOURCE_STALE)
    );
}

#[test]
fn the_required_source_going_silent_stops_the_robot_at_its_timeout() {
    let mut rig = Rig::with(RobotKind::Titan, unsmoothed(), |_| {});
    rig.publish_every("safety", VelocityRequest::heartbeat(), ms(50), at(550));
    rig.publish_every("teleop", twist(0.5), ms(50), at(2000));
    rig.run_until(at(1000));
    // The last heartbeat came at 500: stale at 700, whatever teleop asks.
    assert_eq!(rig.first_motion(at(500), |v| v == 0.0), Some(at(700)));
    assert!(rig.motion().iter().all(|&(t, v)| t < at(700) || v == 0.0));
    let stale = rig
        .world
        .muxes
        .iter()
        .find(|m| {
            m.zero_reason == ZeroReason::REQUIRED_SOURCE_STALE && m.stamp_ns >= at(500).as_nanos()
        })
        .expect("the mux says why");
    assert_eq!(
        stale.stamp_ns,
        at(700).as_nanos(),
        "published the instant it changed"
    );
}

#[test]
fn an_operator_lock_blocks_every_lower_source_until_released() {
    let mut rig = ready();
    rig.publish_every("teleop", twist(0.5), ms(50), at(3000));
    let engage = rig.control_at(
        at(433),
        control(ControlKind::LOCK_ENGAGE).with_name("estop"),
    );
    let release = rig.control_at(
        at(1233),
        control(ControlKind::LOCK_RELEASE).with_name("estop"),
    );
    rig.run_until(at(1290));
    // A release never starts motion: teleop still asks for 0.5 m/s, so the mux waits for its
    // zero.
    assert_eq!(rig.mux().zero_reason, ZeroReason::AWAITING_ZERO);
    // Teleop lets go between two of its requests (every 50 ms from 200 ms): the next one drives.
    rig.request_at(at(1310), "teleop", twist(0.0));
    rig.run_until(at(1400));
    assert_eq!(rig.first_motion(at(201), |v| v == 0.0), Some(at(433)));
    assert!(
        rig.motion()
            .iter()
            .all(|&(t, v)| !(at(433)..at(1350)).contains(&t) || v == 0.0)
    );
    assert_eq!(rig.first_motion(at(434), |v| v > 0.0), Some(at(1350)));
    let (engaged, when) = rig.response(engage).unwrap();
    assert!(engaged.is_ok(), "{}", engaged.message());
    assert_eq!(when, at(433));
    assert_eq!(
        rig.response(release).unwrap().0.message(),
        WAITING_FOR_TELEOP
    );
}

/// What the operator's release answers while teleop asks for motion.
const WAITING_FOR_TELEOP: &str =
    "estop released; nothing moves until teleop asks for zero (a release never starts motion)";

#[test]
fn a_lock_held_by_a_source_survives_its_holder_going_silent() {
    let mut mux = unsmoothed().without_required_sources();
    mux.sources[0].required = false;
    let mut rig = Rig::with(RobotKind::Titan, mux, |_| {});
    rig.run_until(at(200));
    rig.request_at(
        at(210),
        "safety",
        VelocityRequest {
            lock_engage: 1,
            ..twist(0.0)
        },
    );
    rig.publish_every("teleop", twist(0.5), ms(50), at(3000));
    rig.run_until(at(2000));
    assert!(rig.motion().iter().all(|&(t, v)| t < at(210) || v == 0.0));
    let lock = rig.mux().locks()[0];
    assert_eq!(
        (lock.held, lock.holder),
        (1, 0),
        "held by the safety source"
    );
    assert_eq!(rig.mux().zero_reason, ZeroReason::LOCKED);
    let release = rig.control_at(
        at(2005),
        control(ControlKind::LOCK_RELEASE).with_name("estop"),
    );
    rig.request_at(at(2025), "teleop", twist(0.0));
    rig.run_until(at(2100));
    assert!(rig.response(release).unwrap().0.is_ok());
    assert_eq!(rig.first_motion(at(2000), |v| v > 0.0), Some(at(2050)));
    assert_eq!(rig.mux().locks()[0].holder, LockStatus::HOLDER_NONE);
}

#[test]
fn a_request_naming_an_unknown_lock_is_rejected_and_the_previous_one_stands() {
    let mut rig = ready();
    rig.request_at(at(207), "teleop", twist(0.5));
    rig.request_at(
        at(227),
        "teleop",
        VelocityRequest {
            lock_engage: 1 << 3,
            ..twist(0.9)
        },
    );
    rig.request_at(at(247), "teleop", twist(f32::NAN));
    rig.run_until(at(300));
    assert!(rig.motion().iter().all(|&(t, v)| t < at(207) || v == 0.5));
    let status = rig.engine.mux().status();
    assert_eq!(status.rejected_requests, 2);
    assert_eq!(status.sources()[rig.source("teleop")].rejected, 2);
}

/// What a source's process wrote into shared memory is parsed once, here: a NaN, an infinity
/// or a negative envelope never reaches the mux or the driver. Each is counted against its
/// source, and the source's previous request stands.
#[test]
fn non_finite_requests_are_rejected_counted_and_the_previous_one_stands() {
    let mut rig = ready();
    rig.request_at(at(207), "teleop", twist(0.5));
    for (t, bad) in [
        (217, f32::NAN),
        (227, f32::INFINITY),
        (237, f32::NEG_INFINITY),
    ] {
        rig.request_at(at(t), "teleop", twist(bad));
    }
    let lateral = VelocityRequest {
        linear_y_mps: f32::NAN,
        ..twist(0.5)
    };
    rig.request_at(at(247), "teleop", lateral);
    rig.request_at(
        at(257),
        "safety",
        VelocityRequest::limit(-1.0, 1.0, 1.0, 1.0),
    );
    rig.request_at(
        at(267),
        "safety",
        VelocityRequest::limit(1.0, 1.0, -0.5, 1.0),
    );
    rig.run_until(at(300));
    assert!(rig.motion().iter().all(|&(t, v)| t < at(207) || v == 0.5));
    assert!(
        rig.motion().iter().any(|&(t, _)| t > at(280)),
        "the heartbeat kept the valid request on the wire"
    );
    let status = rig.engine.mux().status();
    assert_eq!(status.rejected_requests, 6);
    assert_eq!(status.sources()[rig.source("teleop")].rejected, 4);
    assert_eq!(status.sources()[rig.source("safety")].rejected, 2);
}

#[test]
fn an_unknown_lock_name_is_answered_invalid_at_once() {
    let mut rig = ready();
    let ticket = rig.control_at(at(255), control(ControlKind::LOCK_ENGAGE).with_name("dock"));
    rig.run_until(at(300));
    let (answer, when) = rig.response(ticket).unwrap();
    assert_eq!(answer.status, ControlStatus::INVALID);
    assert_eq!(
        answer.message(),
        "no lock called 'dock' (configured: estop)"
    );
    assert_eq!(when, at(255));
}

#[test]
fn a_keep_is_answered_and_handed_to_the_black_box_only_while_it_records() {
    let mut rig = ready();
    let ticket = rig.control_at(at(255), control(ControlKind::KEEP));
    rig.run_until(at(300));
    let (answer, _) = rig.response(ticket).unwrap();
    assert_eq!(
        answer.status,
        ControlStatus::UNSUPPORTED,
        "{}",
        answer.message()
    );
    assert!(!rig.engine.take_keep());

    let mut rig = Rig::with(RobotKind::Titan, unsmoothed(), |c| c.recording = true);
    rig.run_until(at(200));
    let ticket = rig.control_at(at(255), control(ControlKind::KEEP));
    rig.run_until(at(300));
    let (answer, when) = rig.response(ticket).unwrap();
    assert!(answer.is_ok(), "{}", answer.message());
    assert_eq!(when, at(255));
    assert!(rig.engine.take_keep());
    assert!(!rig.engine.take_keep(), "a keep is handed over once");
}

#[test]
fn a_control_request_waiting_for_the_chassis_is_answered_when_it_answers() {
    let mut rig = ready();
    let ticket = rig.control_at(at(255), control(ControlKind::STEERING_ZERO));
    rig.run_until(at(400));
    let (answer, when) = rig.response(ticket).unwrap();
    assert!(answer.is_ok(), "{}", answer.message());
    // 0x431 out at 255, the chassis acknowledges 50 ms after it arrived, 0x43A back.
    assert_eq!(
        when,
        at(255) + LATENCY + titan::TitanSim::DEFAULT_STEERING_ZERO_DELAY + LATENCY
    );
}

#[test]
fn shutdown_commands_zero_and_refuses_the_requests_still_waiting() {
    let mut rig = ready();
    rig.request_at(at(255), "teleop", twist(0.5));
    let ticket = rig.control_at(at(255), control(ControlKind::STEERING_ZERO));
    rig.run_until(at(260));
    assert!(rig.response(ticket).is_none(), "waiting for the chassis");
    assert_eq!(speed_at(&rig, at(260)), 0.5);
    let states = rig.world.states.len();
    rig.stop();
    assert_eq!(rig.motion().last(), Some(&(at(260), 0.0)), "zero, at once");
    let (answer, when) = rig.response(ticket).unwrap();
    assert_eq!((answer.status, when), (ControlStatus::REFUSED, at(260)));
    assert_eq!(
        rig.world.states.len(),
        states + 1,
        "the last state is published"
    );
}

#[test]
fn the_state_is_published_on_change_and_refreshed_on_the_tick() {
    let mut rig = ready();
    rig.run_until(at(1000));
    // Every feedback frame that changes the state is published the instant it is read.
    let changes = rig
        .world
        .states
        .iter()
        .filter(|s| (at(400).as_nanos()..at(1000).as_nanos()).contains(&s.stamp_ns))
        .count();
    assert!(changes > 0);
    // A silent chassis: the state is still refreshed on the tick, every 100 ms.
    rig.inject(Injection::Silence(ms(500)));
    let silent_from = rig.now();
    let before = rig.world.states.len();
    rig.run_until(at(1400));
    let refreshed: Vec<u64> = rig.world.states[before..].iter().map(|s| s.seq).collect();
    assert!(!refreshed.is_empty());
    let stamps: Vec<Timestamp> = rig
        .world
        .passes
        .iter()
        .copied()
        .filter(|&t| t > silent_from)
        .collect();
    assert!(!stamps.is_empty());
    let published_at: Vec<Timestamp> = rig.world.states[before..]
        .iter()
        .filter_map(|s| rig_publication_time(&rig, s.seq))
        .collect();
    for pair in published_at.windows(2) {
        assert!(
            pair[1].saturating_since(pair[0]) <= ms(100),
            "{published_at:?}"
        );
    }
    assert!(rig.state().link_flags & LinkFlags::CHASSIS_SILENT != 0);
}

/// When the state numbered `seq` was published (the rig keeps the instants of its passes; a
/// refreshed state carries its frames' stamps, not the publication's).
fn rig_publication_time(rig: &Rig, seq: u64) -> Option<Timestamp> {
    rig.world
        .state_times
        .iter()
        .find(|(s, _)| *s == seq)
        .map(|(_, t)| *t)
}

#[test]
fn the_mux_status_is_published_on_change_and_every_100_ms() {
    let mut rig = ready();
    rig.run_until(at(800));
    let before = rig.world.muxes.len();
    let quiet: Vec<u64> = rig.world.muxes[..before]
        .windows(2)
        .filter(|w| w[0].stamp_ns >= at(300).as_nanos())
        .map(|w| w[1].stamp_ns - w[0].stamp_ns)
        .collect();
    assert!(
        quiet.iter().all(|&gap| gap == ms(100).as_nanos() as u64),
        "{quiet:?}"
    );
    rig.request_at(at(813), "teleop", twist(0.4));
    rig.run_until(at(830));
    assert!(
        rig.world.muxes[before..]
            .iter()
            .any(|m| m.stamp_ns == at(813).as_nanos() && m.active().is_some()),
        "a change is published at once"
    );
}

#[test]
fn a_lost_bus_is_reopened_with_doubling_backoff_and_nothing_is_written_meanwhile() {
    let mut rig = ready();
    rig.publish_every("teleop", twist(0.5), ms(50), at(10_000));
    rig.run_until(at(305));
    rig.cut_bus();
    rig.run_until(at(4000));
    let lost_at = rig
        .world
        .passes
        .iter()
        .copied()
        .find(|&t| t >= at(305))
        .unwrap();
    let attempts: Vec<Timestamp> = rig.world.opens.iter().map(|(t, _)| *t).collect();
    let gaps: Vec<u64> = std::iter::once(lost_at)
        .chain(attempts.iter().copied())
        .collect::<Vec<_>>()
        .windows(2)
        .map(|w| w[1].saturating_since(w[0]).as_millis() as u64)
        .collect();
    assert_eq!(gaps[..5], [100, 200, 400, 800, 1600]);
    assert!(gaps[5..].iter().all(|&g| g == 2000), "{gaps:?}");
    assert!(rig.world.wire.iter().all(|s| s.at <= lost_at));
    assert!(rig.state().link_flags & LinkFlags::BUS_DOWN != 0);
    // Back: the next attempt opens it and the robot is driven again.
    rig.restore_bus();
    // Attempts at +100, +300, +700, +1500, +3100, +5100 ms: the first after the restore at
    // +4695 ms opens it.
    let next_attempt = lost_at + ms(100 + 200 + 400 + 800 + 1600 + 2000);
    rig.run_until(next_attempt + ms(300));
    assert_eq!(rig.world.opens.last().map(|(t, _)| *t), Some(next_attempt));
    assert_eq!(
        rig.world.wire.iter().find(|s| s.at > lost_at).map(|s| s.at),
        Some(next_attempt)
    );
    // Teleop kept asking through the loss: the bus coming back starts nothing until teleop asks
    // for zero (motion starts only from a zero).
    assert_eq!(rig.first_motion(next_attempt, |v| v > 0.0), None);
    assert_waits_for_zero(&rig, "teleop", BUS_AND_HEARTBEAT);
    let zero_at = rig.now();
    rig.request("teleop", twist(0.0));
    rig.run_for(ms(200));
    assert!(rig.first_motion(zero_at, |v| v > 0.0).is_some());
    // A second loss starts from the first backoff again.
    rig.cut_bus();
    let second_loss = rig.now();
    rig.run_for(ms(150));
    let retry = rig.world.opens.last().map(|(t, _)| *t).unwrap();
    assert!(retry > second_loss && retry.saturating_since(second_loss) <= ms(100));
}

/// The first published state with `flag` set at or after `since`, and when it was published.
fn published_with(rig: &Rig, flag: u32, set: bool, since: Timestamp) -> Option<Timestamp> {
    rig.world
        .states
        .iter()
        .filter(|s| s.has_link_flag(flag) == set)
        .filter_map(|s| rig_publication_time(rig, s.seq))
        .find(|&t| t >= since)
}

/// The latest mux status says the robot stands waiting for `source`'s zero since one of
/// `stops` ended.
fn assert_waits_for_zero(rig: &Rig, source: &str, stops: &[u8]) {
    let m = rig.mux();
    assert_eq!(m.zero_reason, ZeroReason::AWAITING_ZERO, "{}", m.why());
    assert_eq!(m.awaiting().map(|s| s.name()), Some(source));
    assert!(stops.contains(&m.stop), "{}", m.why());
}

/// A TITAN that lost the heartbeat reports a body exception until it hears it again: when the
/// bus comes back, the last stop to end is either.
const BUS_AND_HEARTBEAT: &[u8] = &[Stop::BUS, Stop::CHASSIS_FAULT];

#[test]
fn a_bus_off_is_published_at_once_and_a_restart_waits_for_a_zero_to_drive_again() {
    let mut rig = ready();
    rig.publish_every("teleop", twist(0.5), ms(50), at(10_000));
    rig.run_until(at(500));
    assert!(rig.first_motion(at(200), |v| v > 0.0).is_some());
    rig.bus_off();
    let off = rig.now();
    rig.run_until(at(1500));
    // Published in the pass that read the report, one wire latency later.
    assert_eq!(
        published_with(&rig, LinkFlags::CAN_BUS_OFF, true, off),
        Some(off + LATENCY)
    );
    let s = *rig.state();
    assert!(s.has_link_flag(LinkFlags::CAN_BUS_OFF), "{s:?}");
    assert!(s.has_link_flag(LinkFlags::CHASSIS_SILENT));
    assert_eq!(
        (
            s.link.can_state,
            s.link.can_bus_off,
            s.link.can_error_frames
        ),
        (ControllerState::BUS_OFF, 1, 1)
    );
    // A bus-off controller sends nothing: the driver's frames were refused.
    assert!(rig.world.wire.iter().all(|w| w.at <= off + LATENCY));

    rig.restart_controller(true);
    let restarted = rig.now();
    rig.run_until(at(2500));
    assert_eq!(
        published_with(&rig, LinkFlags::CAN_BUS_OFF, false, restarted),
        Some(restarted + LATENCY)
    );
    let s = *rig.state();
    assert_eq!(
        s.link_flags & (LinkFlags::CAN_BUS_OFF | LinkFlags::CHASSIS_SILENT),
        0
    );
    assert_eq!(
        (s.link.can_state, s.link.can_bus_off, s.link.can_restarts),
        (ControllerState::ERROR_ACTIVE, 1, 1)
    );
    assert_eq!(rig.first_motion(restarted, |v| v > 0.0), None);
    assert_waits_for_zero(&rig, "teleop", BUS_AND_HEARTBEAT);
    let zero_at = rig.now();
    rig.request("teleop", twist(0.0));
    rig.run_for(ms(200));
    assert!(rig.first_motion(zero_at, |v| v > 0.0).is_some());
}

#[test]
fn frames_arriving_after_an_unreported_restart_clear_the_bus_off() {
    let mut rig = ready();
    rig.run_until(at(300));
    rig.bus_off();
    rig.run_until(at(800));
    assert!(rig.state().has_link_flag(LinkFlags::CAN_BUS_OFF));
    rig.restart_controller(false);
    let restarted = rig.now();
    let first_frame = rig.next_frame_arrival();
    rig.run_until(at(1300));
    assert_eq!(
        published_with(&rig, LinkFlags::CAN_BUS_OFF, false, restarted),
        Some(first_frame)
    );
    let s = rig.state();
    assert_eq!(s.link.can_state, ControllerState::UNKNOWN);
    assert_eq!((s.link.can_bus_off, s.link.can_restarts), (1, 0));
}

#[test]
fn an_error_passive_controller_is_flagged_and_its_bus_errors_counted() {
    let mut rig = ready();
    rig.run_until(at(300));
    let report = |state, counters| chassis_bus::can_controller::ControllerReport {
        state,
        counters: Some(counters),
        bus_error: true,
        from_frame: true,
        ..Default::default()
    };
    rig.controller_reports(report(ControllerState::ERROR_WARNING, (96, 0)));
    rig.controller_reports(report(ControllerState::ERROR_PASSIVE, (128, 0)));
    rig.run_until(at(400));
    let s = *rig.state();
    assert!(s.has_link_flag(LinkFlags::CAN_ERROR_PASSIVE));
    assert_eq!(
        (
            s.link.can_error_passive,
            s.link.can_bus_errors,
            s.link.can_tx_error_count
        ),
        (1, 2, 128)
    );
    rig.controller_reports(report(ControllerState::ERROR_ACTIVE, (20, 0)));
    rig.run_until(at(500));
    assert_eq!(rig.state().link_flags & LinkFlags::CAN_ERROR_PASSIVE, 0);
    assert_eq!(rig.state().link.can_error_passive, 1);
}

#[test]
fn a_flooding_source_is_read_on_the_tick_only_and_keeps_its_place() {
    let mut rig = ready();
    rig.publish_every("teleop", twist(0.5), Duration::from_micros(200), at(600));
    rig.run_until(at(600));
    let teleop = rig.source("teleop");
    let detached: Vec<Timestamp> = rig
        .world
        .listener_changes
        .iter()
        .filter(|(_, c)| *c == ListenerChange::Detach(teleop))
        .map(|(t, _)| *t)
        .collect();
    let attached: Vec<Timestamp> = rig
        .world
        .listener_changes
        .iter()
        .filter(|(_, c)| *c == ListenerChange::Attach(teleop))
        .map(|(t, _)| *t)
        .collect();
    // The 21st wake-up of the tick that began at 200 (one every 200 µs) detaches it …
    assert_eq!(
        detached[0],
        at(200) + Duration::from_micros(200 * u64::from(WakeBudget::PER_TICK))
    );
    // … and the tick at 220 attaches it again.
    assert_eq!(attached[0], at(220));
    assert_eq!(detached.len(), attached.len());
    // Its requests still win: the robot drives.
    assert!((speed_at(&rig, at(590)) - 0.5).abs() < 1e-3);
}

#[test]
fn the_safety_source_is_never_detached() {
    let mut rig = ready();
    rig.publish_every(
        "safety",
        VelocityRequest::heartbeat(),
        Duration::from_micros(100),
        at(400),
    );
    rig.run_until(at(400));
    let safety = rig.source("safety");
    assert!(
        rig.world
            .listener_changes
            .iter()
            .all(|(_, c)| *c != ListenerChange::Detach(safety))
    );
}

#[test]
fn ordinary_feedback_is_read_the_moment_it_arrives() {
    let mut rig = ready();
    rig.run_until(at(2000));
    assert_eq!(rig.world.worst_rx_wait, Duration::ZERO);
}

#[test]
fn a_saturated_bus_is_read_once_per_moderation_interval_and_loses_nothing() {
    let mut rig = ready();
    rig.inject(Injection::Flood { frames_per_s: 4000 });
    rig.run_until(at(1200));
    let reads_before = rig.world.bus_reads;
    let read_frames = rig.world.frames_read;
    rig.run_until(at(2200));
    let reads = rig.world.bus_reads - reads_before;
    // One read per 4 ms and one per 20 ms tick at most, instead of one per frame (≈ 4,500).
    assert!(reads <= 250 + 50 + 5, "{reads} reads in one second");
    assert!(
        rig.world.worst_rx_wait <= Duration::from_micros(4000),
        "{:?}",
        rig.world.worst_rx_wait
    );
    assert!(rig.world.frames_read - read_frames > 4000);
    assert_eq!(rig.frames_lost(), 0);
}

#[test]
fn acceleration_smoothing_ramps_but_a_timeout_cuts_at_once() {
    let mut rig = ready_for(RobotKind::Titan, MuxConfig::default(), 60);
    rig.request_at(at(220), "teleop", twist(1.0));
    rig.publish_every("teleop", twist(1.0), ms(50), at(1020));
    rig.run_until(at(1500));
    // 2 m/s² from the decision before the request (at most one 20 ms tick earlier): 1 m/s is
    // reached 0.5 s later.
    let first = speed_at(&rig, at(220));
    assert!(first > 0.0 && first <= 0.04 + 1e-3, "{first}");
    assert!((speed_at(&rig, at(420)) - 0.4).abs() <= 0.04 + 1e-3);
    assert!(speed_at(&rig, at(699)) < 1.0);
    assert!((speed_at(&rig, at(720)) - 1.0).abs() < 1e-3);
    // The last request at 1000: at 1300 the output is zero at once, not ramped down.
    assert_eq!(rig.first_motion(at(1001), |v| v < 0.99), Some(at(1300)));
    assert_eq!(speed_at(&rig, at(1300)), 0.0);
}

#[test]
fn the_gps_receiver_is_opened_at_start_and_retried_every_second() {
    let mut rig = Rig::with(RobotKind::Xbot, unsmoothed(), |c| c.gps = true);
    rig.run_until(at(3500));
    let gps: Vec<Timestamp> = rig
        .world
        .opens
        .iter()
        .filter(|(_, d)| *d == Device::Gps)
        .map(|(t, _)| *t)
        .collect();
    assert_eq!(gps, [T0, at(1000), at(2000), at(3000)]);
    assert!(rig.state().link_flags & LinkFlags::GPS_DOWN != 0);
}

/// A GGA sentence with a fix at 48.1173° N, 11.5167° E, eight satellites.
const GGA: &[u8] = b"$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47\r\n";

#[test]
fn a_gps_fix_is_read_in_the_pass_it_wakes_and_published_by_the_next_tick() {
    let mut rig = Rig::with(RobotKind::Xbot, unsmoothed(), |c| c.gps = true);
    rig.plug_gps();
    rig.gps_sends_at(at(507), GGA);
    rig.run_until(at(600));
    let gps: Vec<Timestamp> = rig
        .world
        .opens
        .iter()
        .filter(|(_, d)| *d == Device::Gps)
        .map(|(t, _)| *t)
        .collect();
    assert_eq!(gps, [T0], "opened at start");
    assert!(
        rig.world.passes.contains(&at(507)),
        "the receiver woke a pass"
    );
    let tapped: Vec<u64> = rig
        .world
        .frames
        .iter()
        .filter(|f| f.kind == chassis_interfaces::FrameKind::GPS)
        .map(|f| f.stamp_ns)
        .collect();
    assert_eq!(tapped.first(), Some(&at(507).as_nanos()), "{tapped:?}");
    let (seq, state) = rig
        .world
        .states
        .iter()
        .find(|s| s.gps.has_fix())
        .map(|s| (s.seq, *s))
        .expect("the fix is published");
    assert!((state.gps.latitude_deg - 48.1173).abs() < 1e-4);
    assert_eq!(state.gps.satellites, 8);
    assert_eq!(state.link_flags & LinkFlags::GPS_DOWN, 0);
    let published = rig_publication_time(&rig, seq).unwrap();
    assert!((at(507)..=at(520)).contains(&published), "{published:?}");
}

#[test]
fn a_gps_receiver_unplugged_is_closed_at_once_and_reopened_when_it_is_back() {
    let mut rig = Rig::with(RobotKind::Xbot, unsmoothed(), |c| c.gps = true);
    rig.plug_gps();
    rig.run_until(at(700));
    rig.unplug_gps();
    rig.run_until(at(2000));
    assert!(rig.state().link_flags & LinkFlags::GPS_DOWN != 0);
    rig.plug_gps();
    rig.run_until(at(3000));
    let gps: Vec<Timestamp> = rig
        .world
        .opens
        .iter()
        .filter(|(_, d)| *d == Device::Gps)
        .map(|(t, _)| *t)
        .collect();
    assert_eq!(
        gps,
        [T0, at(1700), at(2700)],
        "a second after the loss, then every second"
    );
    assert_eq!(rig.state().link_flags & LinkFlags::GPS_DOWN, 0);
}

#[test]
fn a_scout_mini_drives_and_stops_through_the_engine() {
    let mut rig = ready_for(RobotKind::ScoutMini, unsmoothed(), 60);
    rig.request_at(at(300), "teleop", twist(0.5));
    rig.run_until(at(1000));
    assert_eq!(rig.first_motion(at(300), |v| v > 0.4), Some(at(300)));
    assert_eq!(rig.first_motion(at(301), |v| v == 0.0), Some(at(600)));
}

#[test]
fn an_xbot_drives_and_stops_through_the_engine() {
    let mut rig = ready_for(RobotKind::Xbot, unsmoothed(), 60);
    rig.publish_every("teleop", twist(0.3), ms(50), at(1500));
    rig.run_until(at(1500));
    assert!(
        rig.world.firmware.truth().linear_mps > 0.2,
        "{:?}",
        rig.world.firmware.truth()
    );
    rig.run_until(at(3000));
    assert!(rig.world.firmware.truth().linear_mps.abs() < 1e-3);
    assert_eq!(rig.mux().zero_reason, ZeroReason::NO_ACTIVE_SOURCE);
}

#[test]
fn every_agilex_v2_robot_drives_and_stops_through_the_engine() {
    let v2_robots: Vec<RobotKind> = RobotKind::ALL
        .into_iter()
        .filter(|robot| robot.entry().defaults().protocol() == Some(Protocol::V2))
        .collect();
    assert_eq!(v2_robots.len(), 7, "{v2_robots:?}");
    for robot in v2_robots {
        let mut rig = ready_for(robot, unsmoothed(), 60);
        rig.publish_every("teleop", twist(0.3), ms(50), at(2000));
        rig.run_until(at(2000));
        assert!(
            (rig.world.firmware.truth().linear_mps - 0.3).abs() < 0.01,
            "{robot}: {:?}",
            rig.world.firmware.truth()
        );
        assert!(
            rig.state().link_flags & LinkFlags::COMMAND_MODE != 0,
            "{robot}"
        );
        rig.run_until(at(4000));
        assert!(
            rig.world.firmware.truth().linear_mps.abs() < 1e-3,
            "{robot}"
        );
        assert_eq!(rig.mux().zero_reason, ZeroReason::NO_ACTIVE_SOURCE);
        // The 0x111 heartbeat ran all along (every 20 ms for 3.8 s).
        assert!(rig.motion().len() > 150, "{robot}");
    }
}

/// The chassis' own E-stop switch (protocol V2): the engine holds zero while the chassis reports
/// it and, once released, waits for the zero of the source that kept asking — for every V2
/// robot, with no rule of the driver's own.
#[test]
fn a_chassis_estop_holds_zero_and_its_release_waits_for_a_zero() {
    for robot in RobotKind::ALL
        .into_iter()
        .filter(|robot| robot.entry().defaults().protocol() == Some(Protocol::V2))
    {
        let mut rig = ready_for(robot, unsmoothed(), 60);
        rig.publish_every("teleop", twist(0.3), ms(50), at(6000));
        rig.run_until(at(1500));
        assert!(
            (rig.world.firmware.truth().linear_mps - 0.3).abs() < 0.01,
            "{robot}"
        );
        assert!(rig.inject(Injection::EStop(true)), "{robot}");
        rig.run_until(at(2500));
        assert_eq!(rig.mux().zero_reason, ZeroReason::HELD, "{robot}");
        assert_eq!(rig.mux().stop, Stop::CHASSIS_ESTOP, "{robot}");
        assert!(rig.inject(Injection::EStop(false)), "{robot}");
        let released = rig.now();
        rig.run_until(at(3500));
        assert_eq!(rig.first_motion(released, |v| v != 0.0), None, "{robot}");
        assert!(
            rig.world.firmware.truth().linear_mps.abs() < 1e-3,
            "{robot}"
        );
        assert_waits_for_zero(&rig, "teleop", &[Stop::CHASSIS_ESTOP]);
        rig.request("teleop", twist(0.0));
        rig.run_until(at(5000));
        assert!(
            (rig.world.firmware.truth().linear_mps - 0.3).abs() < 0.01,
            "{robot}: {:?}",
            rig.world.firmware.truth()
        );
    }
}

/// A transmitter that takes the chassis over and hands it back, and a motor driver lost and
/// its fault cleared by the operator: each holds zero and its end waits for teleop's zero.
#[test]
fn remote_control_and_a_drive_fault_end_only_with_a_zero() {
    let mut rig = ready();
    rig.publish_every("teleop", twist(0.5), ms(50), at(20_000));
    rig.run_until(at(1000));
    assert!(rig.first_motion(at(200), |v| v > 0.4).is_some());
    assert!(rig.inject(Injection::RcTakeover(true)));
    rig.run_until(at(2000));
    assert_eq!(rig.mux().zero_reason, ZeroReason::HELD);
    assert_eq!(rig.mux().stop, Stop::REMOTE_CONTROL);
    assert!(rig.inject(Injection::RcTakeover(false)));
    let handed_back = rig.now();
    rig.run_until(at(3000));
    assert_eq!(rig.first_motion(handed_back, |v| v > 0.0), None);
    assert_waits_for_zero(&rig, "teleop", &[Stop::REMOTE_CONTROL]);
    rig.request("teleop", twist(0.0));
    rig.run_until(at(4000));
    assert!(rig.first_motion(at(3000), |v| v > 0.4).is_some());

    assert!(rig.inject(Injection::MotorDriverLoss {
        motor: 1,
        lost: true
    }));
    rig.run_until(at(5000));
    assert_eq!(rig.mux().zero_reason, ZeroReason::HELD);
    assert_eq!(rig.mux().stop, Stop::CHASSIS_FAULT);
    assert!(rig.inject(Injection::MotorDriverLoss {
        motor: 1,
        lost: false
    }));
    // 0x441 code 0x00: every latched fault whose cause is gone.
    rig.control_at(rig.now(), control(ControlKind::CLEAR_FAULTS));
    let cleared = rig.now();
    rig.run_until(at(6500));
    assert_eq!(
        rig.mux().zero_reason,
        ZeroReason::AWAITING_ZERO,
        "{}",
        rig.mux().why()
    );
    assert_eq!(rig.first_motion(cleared, |v| v > 0.0), None);
    assert_waits_for_zero(&rig, "teleop", &[Stop::CHASSIS_FAULT]);
    rig.request("teleop", twist(0.0));
    rig.run_until(at(7500));
    assert!(rig.first_motion(at(6500), |v| v > 0.4).is_some());
}

/// chassisd starting is a stop: a client that kept asking through the restart (it did not
/// connect anew, so its library sent nothing) is not obeyed until it asks for zero.
#[test]
fn a_client_that_kept_asking_through_a_restart_drives_only_after_its_zero() {
    let mut rig = Rig::unconnected(RobotKind::Titan, unsmoothed(), |_| {});
    rig.publish_every("safety", VelocityRequest::heartbeat(), ms(50), at(5000));
    rig.publish_every("teleop", twist(0.5), ms(50), at(5000));
    rig.run_until(at(1000));
    assert_eq!(rig.first_motion(T0, |v| v != 0.0), None);
    assert_waits_for_zero(&rig, "teleop", &[Stop::SERVICE_START]);
    rig.request("teleop", twist(0.0));
    rig.run_until(at(1500));
    assert!(rig.first_motion(at(1000), |v| v > 0.4).is_some());
}

#[test]
fn the_engine_waits_for_its_next_deadline() {
    let rig = ready();
    let t = rig.engine.poll_timeout();
    // Nothing but the tick and the heartbeat (both on the 20 ms grid) is pending.
    assert!(t > rig.now() && t <= rig.now() + ms(20), "{t:?}");
}

/// A fresh TITAN rig (a restarted service) whose safety monitor beats and whose teleop asks for
/// 0.5 m/s every 50 ms from the start; `before_first_pass` runs before anything is decided.
fn restarted(mux: MuxConfig, before_first_pass: impl FnOnce(&mut Rig)) -> Rig {
    let mut rig = Rig::with(RobotKind::Titan, mux, |_| {});
    before_first_pass(&mut rig);
    rig.publish_every("safety", VelocityRequest::heartbeat(), ms(50), at(5000));
    rig.publish_every("teleop", twist(0.5), ms(50), at(5000));
    rig
}

fn held(name: &str, holder: &str, since: Timestamp) -> HeldLock {
    HeldLock {
        name: name.into(),
        holder: holder.into(),
        since,
    }
}

#[test]
fn a_lock_restored_after_a_restart_holds_until_the_operator_releases_it() {
    let before = T0 - Duration::from_secs(30);
    let mut rig = restarted(unsmoothed(), |rig| {
        rig.engine
            .restore_locks(T0, &[held("estop", HeldLock::OPERATOR, before)]);
    });
    let release = rig.control_at(
        at(1500),
        control(ControlKind::LOCK_RELEASE).with_name("estop"),
    );
    rig.run_until(at(1400));
    assert!(
        rig.motion().iter().all(|&(_, v)| v == 0.0),
        "nothing moves while the restored e-stop is held"
    );
    let lock = rig.mux().locks()[0];
    assert_eq!((lock.held, lock.holder), (1, LockStatus::HOLDER_OPERATOR));
    assert_eq!(
        lock.since_ns,
        before.as_nanos(),
        "held since before the restart"
    );
    assert_eq!(rig.mux().zero_reason, ZeroReason::LOCKED);
    assert!(
        rig.world.kept_locks.is_empty(),
        "the file already holds what was restored"
    );
    rig.request_at(at(1525), "teleop", twist(0.0));
    rig.run_until(at(1600));
    assert_eq!(
        rig.response(release).unwrap().0.message(),
        WAITING_FOR_TELEOP
    );
    assert_eq!(rig.first_motion(at(0), |v| v > 0.0), Some(at(1550)));
    assert_eq!(
        rig.world.kept_locks,
        vec![(at(1500), vec![])],
        "release clears the file"
    );
}

#[test]
fn a_lock_restored_for_a_source_is_released_by_that_source() {
    let mut rig = restarted(unsmoothed(), |rig| {
        rig.engine.restore_locks(T0, &[held("estop", "safety", T0)]);
    });
    rig.run_until(at(500));
    assert!(rig.motion().iter().all(|&(_, v)| v == 0.0));
    assert_eq!(rig.mux().locks()[0].holder, 0, "the safety source holds it");
    rig.request_at(
        at(510),
        "safety",
        VelocityRequest {
            lock_release: 1,
            ..VelocityRequest::heartbeat()
        },
    );
    rig.request_at(at(525), "teleop", twist(0.0));
    rig.run_until(at(700));
    assert_eq!(rig.first_motion(at(0), |v| v > 0.0), Some(at(550)));
    assert_eq!(rig.world.kept_locks, vec![(at(510), vec![])]);
}

#[test]
fn an_unreadable_lock_file_starts_with_the_estop_held_and_rewrites_it() {
    let mut rig = restarted(unsmoothed(), |rig| {
        rig.engine
            .restore_failed(T0, &"the state file is not JSON (simulated)");
    });
    rig.run_until(at(1000));
    assert!(rig.motion().iter().all(|&(_, v)| v == 0.0));
    assert_eq!(rig.mux().zero_reason, ZeroReason::LOCKED);
    assert_eq!(
        rig.world.kept_locks,
        vec![(T0, vec![held("estop", HeldLock::OPERATOR, T0)])],
        "the held e-stop replaces the unreadable file at the first pass"
    );
    rig.control_at(
        at(1007),
        control(ControlKind::LOCK_RELEASE).with_name("estop"),
    );
    rig.request_at(at(1025), "teleop", twist(0.0));
    rig.run_until(at(1100));
    assert_eq!(rig.first_motion(at(0), |v| v > 0.0), Some(at(1050)));
}

#[test]
fn a_restored_lock_the_configuration_no_longer_has_holds_the_estop_instead() {
    let mut rig = restarted(unsmoothed(), |rig| {
        rig.engine
            .restore_locks(T0, &[held("dock", HeldLock::OPERATOR, T0)]);
    });
    rig.run_until(at(500));
    assert!(rig.motion().iter().all(|&(_, v)| v == 0.0));
    assert_eq!(rig.mux().locks()[0].holder, LockStatus::HOLDER_OPERATOR);
    assert_eq!(
        rig.world.kept_locks,
        vec![(T0, vec![held("estop", HeldLock::OPERATOR, T0)])]
    );
}

#[test]
fn every_engage_and_release_is_kept_at_once() {
    let mut rig = ready();
    rig.control_at(
        at(433),
        control(ControlKind::LOCK_ENGAGE).with_name("estop"),
    );
    rig.control_at(
        at(633),
        control(ControlKind::LOCK_ENGAGE).with_name("estop"),
    );
    rig.control_at(
        at(833),
        control(ControlKind::LOCK_RELEASE).with_name("estop"),
    );
    rig.run_until(at(1000));
    assert_eq!(
        rig.world.kept_locks,
        vec![
            (at(433), vec![held("estop", HeldLock::OPERATOR, at(433))]),
            (at(833), vec![]),
        ],
        "an engage of a held lock changes nothing to keep"
    );
}

#[test]
fn a_lock_engaged_in_a_pass_that_reads_frames_is_on_disk_before_anything_is_published() {
    let mut rig = ready();
    rig.publish_every("teleop", twist(0.5), ms(50), at(3000));
    rig.run_until(at(420));
    // The engage arrives with a frame of the chassis: one pass reads both, and publishes the
    // frame's state while the bus is drained, before its end.
    let t = rig.next_frame_arrival();
    let engage = rig.control_at(t, control(ControlKind::LOCK_ENGAGE).with_name("estop"));
    rig.run_until(t + ms(1));
    assert_eq!(
        rig.world.passes.iter().filter(|&&p| p == t).count(),
        1,
        "one pass"
    );
    assert!(
        rig.world.state_times.iter().any(|&(_, when)| when == t),
        "the pass published a state from the frame"
    );
    // (The rig checks at every pass that the locks are kept before its first publication.)
    assert_eq!(
        rig.world.kept_locks,
        vec![(t, vec![held("estop", HeldLock::OPERATOR, t)])]
    );
    assert_eq!(rig.response(engage).map(|(_, when)| when), Some(t));
    assert_eq!(rig.first_motion(t, |v| v == 0.0), Some(t));
}

#[test]
fn a_failed_write_of_the_locks_is_tried_again_every_second_without_holding_the_answer() {
    let mut rig = ready();
    rig.publish_every("teleop", twist(0.5), ms(50), at(3000));
    rig.break_disk();
    let engage = rig.control_at(
        at(433),
        control(ControlKind::LOCK_ENGAGE).with_name("estop"),
    );
    rig.run_until(at(2000));
    assert_eq!(rig.response(engage).map(|(_, when)| when), Some(at(433)));
    assert_eq!(rig.first_motion(at(433), |v| v == 0.0), Some(at(433)));
    let failures = rig.world.keep_failures.clone();
    assert_eq!(failures[0], at(433));
    // Once a second, at the first pass after (the tick at the latest).
    assert_eq!(failures.len(), 2, "{failures:?}");
    assert!((at(1433)..=at(1453)).contains(&failures[1]), "{failures:?}");
    assert!(rig.world.kept_locks.is_empty());
    rig.mend_disk();
    rig.run_until(at(3000));
    let (kept_at, kept) = rig.world.kept_locks[0].clone();
    assert!((at(2433)..=at(2453)).contains(&kept_at), "{kept_at:?}");
    assert_eq!(kept, vec![held("estop", HeldLock::OPERATOR, at(433))]);
    assert_eq!(rig.world.kept_locks.len(), 1, "kept once");
}

/// Simulated seconds of the long run.
const LONG_RUN_S: u64 = 1000;

/// A small deterministic generator (xorshift64*).
struct Dice(u64);

impl Dice {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }

    fn chance(&mut self, percent: u64) -> bool {
        self.below(100) < percent
    }
}

/// What a client said, as the rig's model keeps it: when it asked for motion and when for
/// nothing (a zero, a heartbeat), each list in time order.
#[derive(Debug, Default)]
struct Words {
    motion: Vec<Timestamp>,
    nothing: Vec<Timestamp>,
}

impl Words {
    fn said(&mut self, t: Timestamp, motion: bool) {
        if motion {
            self.motion.push(t);
        } else {
            self.nothing.push(t);
        }
    }

    fn last(list: &[Timestamp], until: Timestamp) -> Option<Timestamp> {
        list[..list.partition_point(|&x| x <= until)]
            .last()
            .copied()
    }

    /// Motion starts only from a zero: after a stop that ended at `ended`, this source may
    /// drive at `t` only if it has asked for nothing since its last motion before the end.
    fn may_drive(&self, ended: Timestamp, t: Timestamp) -> bool {
        Self::last(&self.nothing, t)
            .is_some_and(|zero| Self::last(&self.motion, ended).is_none_or(|m| zero > m))
    }

    /// Its last word at `ended` was motion (or it had not spoken): the stop made it wait.
    fn was_stopped(&self, ended: Timestamp) -> bool {
        Self::last(&self.motion, ended)
            .is_some_and(|m| Self::last(&self.nothing, ended).is_none_or(|z| m > z))
            || Self::last(&self.nothing, ended).is_none()
    }
}

/// The stops of the random run, as the clients and the world caused them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
enum Ended {
    Start,
    Release,
    SafetyBack,
    BusBack,
    RcHandBack,
}

/// The robot at T0 with clients that kept asking through a restart (none connects anew); for
/// 1,000 simulated seconds the safety monitor beats, dies for seconds at a time and latches the
/// e-stop, which the operator releases; teleop and the planner ask for random speeds (NaN among
/// them); the bus is cut and restored, the chassis rebooted and taken over by a transmitter.
/// Every frame written, and every millisecond between, is judged against a model of the rules
/// built from what the clients and the world did, not from the mux: the safety monitor fresh, a
/// source asking, the e-stop free, and motion only from a zero after every stop — the service's
/// start, a release, the safety monitor back, the bus back (the engine's reopen), a transmitter
/// switched off. The run counts the restarts from a zero it saw
/// after each kind of stop but the start (its own scenario:
/// `a_client_that_kept_asking_through_a_restart_drives_only_after_its_zero`).
#[test]
fn a_thousand_seconds_of_random_sources_locks_faults_and_bus_losses_keep_every_rule() {
    let mut rig = Rig::unconnected(RobotKind::Titan, MuxConfig::default(), |_| {});
    let mut dice = Dice(0x5EED_CAFE_F00D_D00D);
    let (safety, teleop, planner) = (
        rig.source("safety"),
        rig.source("teleop"),
        rig.source("planner"),
    );
    let timeouts = [ms(200), ms(300), ms(500)];
    // The last request of each source that asked for something (not a heartbeat), and of any
    // kind; what each source said.
    let mut asking: [Option<Timestamp>; 3] = [None; 3];
    let mut any: [Option<Timestamp>; 3] = [None; 3];
    let mut words: [Words; 3] = Default::default();
    // Every stop's end (or a time no later than it) and its kind, in time order.
    let mut ended: Vec<(Timestamp, Ended)> = vec![(T0, Ended::Start)];
    let mut restarts: std::collections::BTreeMap<Ended, std::collections::HashSet<(u64, usize)>> =
        Default::default();
    let mut held = false;
    // When the e-stop was engaged and released, as the clients did it.
    let mut locks: Vec<(Timestamp, Timestamp)> = Vec::new();
    let mut transmitter: Option<Timestamp> = None;
    let mut moving = 0u64;
    let mut steps = 0u64;
    let end = T0 + Duration::from_secs(LONG_RUN_S);
    let step = ms(10);
    let mut zero_checked = 0u64;
    let mut opens_seen = 0;
    // The speed the last motion frame commanded (`None` after the bus was cut).
    let mut wire: Option<f64> = None;
    while rig.now() < end {
        let now = rig.now();
        // Clients act at the start of each 10 ms step.
        let safety_alive = (now.as_nanos() / 7_000_000_000) % 5 != 4;
        if safety_alive && dice.chance(25) {
            let engage = !held && dice.chance(2);
            let request = if engage {
                VelocityRequest {
                    lock_engage: 1,
                    ..twist(0.0)
                }
            } else {
                VelocityRequest::heartbeat()
            };
            rig.request("safety", request);
            if engage {
                held = true;
                locks.push((now, end + ms(1)));
            }
            // Back after a silence the tick surely saw (a stale check falls every 20 ms).
            if any[safety].is_some_and(|last| now.saturating_since(last) >= ms(240)) {
                ended.push((now, Ended::SafetyBack));
            }
            any[safety] = Some(now);
        }
        for (index, name, percent) in [(teleop, "teleop", 8), (planner, "planner", 12)] {
            if dice.chance(percent) {
                let v = (dice.below(21) as f32 - 10.0) / 10.0;
                let nan = dice.chance(10);
                rig.request(name, twist(if nan { f32::NAN } else { v }));
                if !nan {
                    asking[index] = Some(now);
                    any[index] = Some(now);
                    words[index].said(now, v != 0.0);
                }
            }
        }
        if held && dice.chance(1) {
            rig.control_at(now, control(ControlKind::LOCK_RELEASE).with_name("estop"));
            held = false;
            if let Some(last) = locks.last_mut() {
                last.1 = now;
            }
            ended.push((now, Ended::Release));
        }
        if dice.below(3000) == 0 {
            // Not a stop of the service's: the chassis comes back in standby and takes the
            // command again; the other rules hold through it.
            rig.inject(Injection::Reboot);
        }
        match transmitter {
            None if dice.below(5000) == 0 => {
                rig.inject(Injection::RcTakeover(true));
                transmitter = Some(now);
            }
            Some(on) if now.saturating_since(on) >= ms(500) && dice.chance(1) => {
                rig.inject(Injection::RcTakeover(false));
                transmitter = None;
                ended.push((now, Ended::RcHandBack));
            }
            _ => {}
        }
        if dice.below(4000) == 0 {
            rig.cut_bus();
            // What the chassis was last told no longer stands for the wire: it stops on its
            // own command timeout.
            wire = None;
        }
        if dice.below(300) == 0 {
            rig.restore_bus();
        }
        rig.run_for(step);
        steps += 1;
        // The engine reopening the bus ends its loss no later than then.
        for &(t, device) in &rig.world.opens[opens_seen..] {
            if device == Device::Bus {
                ended.push((t, Ended::BusBack));
            }
        }
        opens_seen = rig.world.opens.len();
        ended.sort_by_key(|&(t, _)| t);
        // The rules hold at every frame written and at every millisecond in between: the
        // command on the wire is the last frame's until the next one.
        let frames: Vec<(Timestamp, f64)> = rig.motion();
        let samples = (1..=10).map(|k| (now + ms(k), None));
        let mut events: Vec<(Timestamp, Option<f64>)> = frames
            .iter()
            .map(|&(t, v)| (t, Some(v)))
            .chain(samples)
            .collect();
        events.sort_by_key(|&(t, frame)| (t, frame.is_none()));
        for (t, frame) in events {
            if let Some(v) = frame {
                wire = Some(v);
                if v == 0.0 {
                    zero_checked += 1;
                } else {
                    moving += 1;
                }
            }
            let fresh = |s: usize, last: Option<Timestamp>| {
                last.is_some_and(|a| t.saturating_since(a) < timeouts[s])
            };
            let Some(v) = wire.filter(|&v| v != 0.0) else {
                continue;
            };
            assert!(
                fresh(safety, any[safety]),
                "motion {v} at {t:?} while the safety monitor is silent"
            );
            assert!(
                !locks.iter().any(|(from, to)| (*from..*to).contains(&t)),
                "motion {v} at {t:?} while the e-stop is held"
            );
            // The source that would win (teleop outranks the planner) asks, and has asked for
            // zero since its last motion before the latest stop ended.
            let winner = [teleop, planner].into_iter().find(|&s| fresh(s, asking[s]));
            let Some(winner) = winner else {
                panic!("motion {v} at {t:?} outlives every source");
            };
            let (stop_end, kind) = ended[..ended.partition_point(|&(e, _)| e <= t)]
                .last()
                .copied()
                .unwrap_or((T0, Ended::Start));
            assert!(
                words[winner].may_drive(stop_end, t),
                "motion {v} at {t:?} from source {winner} without a zero since {kind:?} ended \
                 at {stop_end:?}"
            );
            if words[winner].was_stopped(stop_end) {
                restarts
                    .entry(kind)
                    .or_default()
                    .insert((stop_end.as_nanos(), winner));
            }
        }
        rig.forget();
    }
    assert_eq!(steps, LONG_RUN_S * 100);
    assert!(moving > 10_000, "the robot drove ({moving} motion frames)");
    assert!(zero_checked > 10_000);
    assert!(rig.world.opens.len() > 5, "buses were lost and reopened");
    assert!(rig.state().seq > 100_000, "{} states", rig.state().seq);
    // Every kind of stop was followed by a restart from a zero, several times.
    let counts: Vec<(Ended, usize)> = restarts.iter().map(|(k, v)| (*k, v.len())).collect();
    for kind in [
        Ended::Release,
        Ended::SafetyBack,
        Ended::BusBack,
        Ended::RcHandBack,
    ] {
        let n = restarts.get(&kind).map_or(0, |r| r.len());
        assert!(n >= 3, "{n} restarts after {kind:?}: {counts:?}");
    }
}

// ----- Stop categories -----

/// The default sources and the e-stop, unsmoothed, the e-stop stopping with `category`.
fn estop_of_category(category: u8) -> MuxConfig {
    let mut mux = unsmoothed();
    mux.locks[0].category = Some(category);
    mux
}

/// An operator's engage of the e-stop asking for `category` (`None`: the lock's own).
fn estop(category: Option<u8>) -> ControlRequest {
    control(ControlKind::LOCK_ENGAGE)
        .with_name("estop")
        .with_arg(0, category.map_or(0, |c| c + 1))
}

/// Teleop drives `robot` at 1 m/s from 300 ms; at 1.5 s the operator's e-stop asks for
/// `asked` on a lock configured with `configured`; teleop keeps asking until 6 s.
fn stopped_at_speed(robot: RobotKind, configured: u8, asked: Option<u8>) -> Rig {
    let mut rig = ready_for(robot, estop_of_category(configured), 60);
    rig.publish_every("teleop", twist(1.0), ms(50), at(6000));
    rig.run_until(at(1500));
    assert!(rig.world.firmware.truth().linear_mps > 0.9, "at speed");
    let engage = rig.control_at(at(1500), estop(asked));
    rig.run_until(at(1501));
    let (answer, _) = rig.response(engage).expect("answered at once");
    assert_eq!(answer.status, ControlStatus::OK, "{}", answer.message());
    rig
}

/// The operator releases the e-stop at `t_ms`: the drive is enabled again and nothing moves
/// until teleop's zero; then teleop drives at `v` m/s again.
fn released_and_driven_again(rig: &mut Rig, t_ms: u64, v: f32) {
    rig.control_at(
        at(t_ms),
        control(ControlKind::LOCK_RELEASE).with_name("estop"),
    );
    rig.run_until(at(t_ms + 500));
    assert_eq!(rig.mux().drive, DriveState::ENABLED);
    assert_eq!(rig.first_motion(at(t_ms), |v| v > 0.0), None);
    rig.request_at(at(t_ms + 500), "teleop", twist(0.0));
    rig.publish_every("teleop", twist(v), ms(50), at(t_ms + 2000));
    rig.run_until(at(t_ms + 2000));
    let speed = rig.world.firmware.truth().linear_mps;
    assert!(speed > 0.8 * f64::from(v), "drives again: {speed} m/s");
}

#[test]
fn a_category_1_estop_brakes_to_a_standstill_then_cuts_the_drive_and_its_release_enables_it() {
    let mut rig = stopped_at_speed(RobotKind::Titan, StopCategory::BRAKE_THEN_CUT, None);
    assert_eq!(rig.first_motion(at(1500), |v| v == 0.0), Some(at(1500)));
    assert_eq!(rig.mux().drive, DriveState::BRAKING);
    assert_eq!(rig.mux().locks[0].category, StopCategory::BRAKE_THEN_CUT);
    // Braking under control: the chassis is still in command mode until it stands.
    rig.run_until(at(1700));
    assert!(rig.world.firmware.truth().linear_mps > 0.05);
    assert_eq!(rig.mux().drive, DriveState::BRAKING);
    assert_eq!(rig.state().system.control_mode, ControlMode::COMMAND);
    rig.run_until(at(4000));
    assert_eq!(rig.mux().drive, DriveState::CUT);
    assert_eq!(rig.state().system.control_mode, ControlMode::STANDBY);
    assert!(rig.world.firmware.truth().linear_mps.abs() < 1e-3);
    assert!(rig.mux().why().to_string().contains("drive cut"));
    // The release enables the drive, and starts nothing: teleop kept asking for motion.
    released_and_driven_again(&mut rig, 6500, 0.5);
    assert_eq!(rig.state().system.control_mode, ControlMode::COMMAND);
}

#[test]
fn a_category_0_estop_cuts_the_drive_at_once_and_stops_sooner_than_category_2() {
    let distance = |asked| {
        let mut rig = stopped_at_speed(RobotKind::Titan, StopCategory::HOLD, Some(asked));
        let x0 = rig.world.firmware.truth().x_m;
        let drive = rig.mux().drive;
        rig.run_until(at(4000));
        assert!(rig.world.firmware.truth().linear_mps.abs() < 1e-3);
        (
            drive,
            rig.world.firmware.truth().x_m - x0,
            rig.state().system.control_mode,
        )
    };
    let (drive, cut_m, mode) = distance(StopCategory::CUT);
    assert_eq!(drive, DriveState::CUT, "at once");
    assert_eq!(mode, ControlMode::STANDBY);
    let (drive, hold_m, mode) = distance(StopCategory::HOLD);
    assert_eq!(drive, DriveState::ENABLED);
    assert_eq!(mode, ControlMode::COMMAND);
    // The simulated TITAN stops a cut drive on its 0.1 s lag, a zero command on its 0.3 s one.
    assert!(cut_m < 0.6 * hold_m, "cut {cut_m:.3} m, held {hold_m:.3} m");
}

#[test]
fn an_xbot_category_1_stop_turns_its_drive_power_off_and_on_again() {
    let mut rig = ready_for(
        RobotKind::Xbot,
        estop_of_category(StopCategory::BRAKE_THEN_CUT),
        60,
    );
    rig.publish_every("teleop", twist(0.3), ms(50), at(3000));
    rig.run_until(at(1500));
    assert!(rig.world.firmware.truth().linear_mps > 0.2);
    rig.control_at(at(1500), estop(None));
    rig.run_until(at(3000));
    assert_eq!(rig.mux().drive, DriveState::CUT);
    assert!(rig.world.firmware.truth().linear_mps.abs() < 1e-3);
    // Power back on at the release; teleop's zero, then its motion, drives again.
    released_and_driven_again(&mut rig, 3000, 0.3);
}

#[test]
fn a_robot_that_cannot_cut_its_drive_holds_zero_and_says_so() {
    // A SCOUT MINI on protocol V1: its only other mode hands the chassis to the RC transmitter.
    let mut rig = stopped_at_speed(
        RobotKind::ScoutMini,
        StopCategory::HOLD,
        Some(StopCategory::CUT),
    );
    assert_eq!(rig.mux().drive, DriveState::CANNOT_CUT);
    rig.run_until(at(4000));
    assert!(rig.world.firmware.truth().linear_mps.abs() < 1e-3);
    assert!(
        rig.mux().why().to_string().contains("cannot cut its drive"),
        "{}",
        rig.mux().why()
    );
}

#[test]
fn a_controlled_stop_ramps_down_at_the_braking_figure_and_a_category_0_stop_does_not() {
    let braked = |asked: u8| {
        let mut mux = estop_of_category(StopCategory::BRAKE_THEN_CUT);
        mux.limits.braking_mps2 = 1.0;
        let mut rig = ready_for(RobotKind::Titan, mux, 60);
        rig.publish_every("teleop", twist(1.0), ms(50), at(6000));
        rig.run_until(at(1500));
        let x0 = rig.world.firmware.truth().x_m;
        rig.control_at(at(1500), estop(Some(asked)));
        rig.run_until(at(1800));
        let ramping = speed_at(&rig, at(1800));
        rig.run_until(at(5000));
        assert!(rig.world.firmware.truth().linear_mps.abs() < 1e-3);
        (
            ramping,
            rig.world.firmware.truth().x_m - x0,
            rig.mux().drive,
        )
    };
    // 1 m/s at 1 m/s²: the command is 0.7 m/s 0.3 s in, zero after 1 s; v²/2a = 0.5 m, and the
    // TITAN's 0.3 s lag on top.
    let (ramping, m, drive) = braked(StopCategory::BRAKE_THEN_CUT);
    assert!((0.65..=0.75).contains(&ramping), "{ramping} m/s");
    assert!((0.5..=0.5 + 0.4).contains(&m), "{m:.3} m");
    assert_eq!(drive, DriveState::CUT, "cut once stopped");
    let (ramping, m, drive) = braked(StopCategory::CUT);
    assert_eq!(ramping, 0.0);
    assert!(m < 0.2, "{m:.3} m");
    assert_eq!(drive, DriveState::CUT);
}

#[test]
fn a_cut_drive_whose_chassis_takes_commands_again_after_a_bus_outage_is_cut_again() {
    let mut rig = ready_for(RobotKind::Titan, estop_of_category(StopCategory::CUT), 60);
    rig.run_until(at(500));
    // The bus goes; the operator's e-stop cuts the drive meanwhile: the standby request is lost.
    rig.cut_bus();
    rig.control_at(at(600), estop(None));
    rig.run_until(at(1500));
    assert_eq!(rig.mux().drive, DriveState::CUT);
    // The chassis dropped to standby for the lost heartbeat; the first heartbeat after the bus
    // came back returns it to command mode by itself, and the engine cuts it again.
    rig.restore_bus();
    rig.run_until(at(4000));
    assert_eq!(rig.mux().drive, DriveState::CUT);
    assert_eq!(rig.state().system.control_mode, ControlMode::STANDBY);
}

/// On every robot: an engine restored from its snapshot between two passes ([`Engine::restore`],
/// as a replay of the black box goes on after its ring let go of the run's beginning) goes on as
/// the engine it was taken of, through an e-stop, its release, a zero, motion again and a bus
/// cut: the same items written at the same instants, the same mux decisions and states.
#[test]
fn an_engine_restored_from_its_snapshot_goes_on_as_the_one_it_was_taken_of() {
    for robot in RobotKind::ALL {
        let run = |restore: bool| {
            let mut rig = ready_for(robot, unsmoothed(), 60);
            rig.publish_every("teleop", twist(0.4), ms(50), at(1900));
            rig.publish_every("planner", twist(0.2), ms(40), at(6000));
            rig.control_at(
                at(1133),
                control(ControlKind::LOCK_ENGAGE).with_name("estop"),
            );
            rig.control_at(
                at(2233),
                control(ControlKind::LOCK_RELEASE).with_name("estop"),
            );
            rig.request_at(at(2310), "teleop", twist(0.0));
            rig.run_until(at(1000));
            if restore {
                let snapshot = rig.engine.snapshot().unwrap();
                let mut engine = ready_for(robot, unsmoothed(), 0).engine;
                engine.restore(&snapshot).unwrap();
                let again = engine.snapshot().unwrap();
                assert!(
                    again == snapshot,
                    "{robot}: the restored engine's snapshot differs"
                );
                rig.engine = engine;
            }
            let since = rig.world.wire.len();
            rig.run_until(at(3000));
            rig.cut_bus();
            rig.run_until(at(3500));
            rig.restore_bus();
            rig.run_until(at(5000));
            let muxes: Vec<Vec<u8>> = (rig.world.muxes.iter())
                .map(|m| m.as_bytes().to_vec())
                .collect();
            let states: Vec<Vec<u8>> = (rig.world.states.iter())
                .map(|s| s.as_bytes().to_vec())
                .collect();
            (rig.world.wire[since..].to_vec(), muxes, states)
        };
        let (kept, restored) = (run(false), run(true));
        assert!(kept.0.len() > 20, "{robot}: {} items written", kept.0.len());
        assert!(
            kept == restored,
            "{robot}: the restored engine went its own way"
        );
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(256))]

    /// A snapshot read from a damaged recording (any bytes changed) is refused, or the engine
    /// restored from it runs on: never a panic.
    #[test]
    fn a_damaged_snapshot_is_refused_or_runs_never_panics(
        robot in proptest::sample::select(RobotKind::ALL.to_vec()),
        damage in proptest::collection::vec((proptest::num::usize::ANY, proptest::num::u8::ANY), 1..8),
    ) {
        let mut rig = ready_for(robot, unsmoothed(), 60);
        rig.publish_every("teleop", twist(0.4), ms(50), at(2000));
        rig.run_until(at(1000));
        let mut snapshot = rig.engine.snapshot().unwrap();
        for (at, byte) in damage {
            let len = snapshot.len();
            snapshot[at % len] = byte;
        }
        // A rig of its own: its checks of the numbering start from what this engine publishes.
        let mut restored = Rig::with(robot, unsmoothed(), |_| {});
        if restored.engine.restore(&snapshot).is_ok() {
            restored.run_until(at(1500));
        }
    }
}
