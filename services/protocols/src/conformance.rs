//! The conformance suite of the protocol families: what every family's driver and simulated
//! firmware must do, checked the same way on every profile of every robot in the registry and
//! on the test-only [`crate::loopback`] family (house style, rule 3; the model is
//! `services/bus/src/conformance.rs`, which runs every bus backend).
//!
//! Each check takes the two sides of one profile ([`Sides`]: the family's driver and firmware,
//! wired back to back on simulated time by [`Pair`]) and returns what it saw instead of the
//! contract, as text; [`check`] runs them all and names the check and the profile of each
//! violation. The timing comes from the profile — its heartbeat period, the command timeout it
//! describes, its limits — never from a number of the suite's. What only one family does (its
//! wire layout, its ⚠ choices, faults only its robots have) stays in the family's own tests.
//!
//! | check | every family's driver and firmware |
//! | --- | --- |
//! | [`powers_up_and_takes_control`] | the driver, the firmware and the profile name one robot; within 1 s the driver hears the chassis without an error of any kind, and the chassis obeys it, standing |
//! | [`drives_forward_and_reports_it`] | 0.3 m/s forward moves the chassis forward at 0.3 m/s, and the driver reports the speed it has |
//! | [`a_zero_command_stops_it`] | zero stops the chassis, reported, and the heartbeat goes on |
//! | [`the_heartbeat_keeps_its_period`] | at a steady command the driver sends exactly every heartbeat period; a changed command goes out at once and leaves the grid where it was |
//! | [`silence_from_the_driver_stops_the_chassis_at_its_command_timeout`] | a cut cable: the chassis keeps the last command for its described timeout and stops after it, the driver flags the chassis silent; with the cable back it drives again |
//! | [`shutdown_stops_the_chassis_at_once`] | at once, not at the timeout, and it stays stopped |
//! | [`while_the_bus_is_down_nothing_is_sent`] | no frame, control refused, the chassis stops at its timeout; with the bus back it drives again |
//! | [`a_silenced_chassis_is_flagged_and_obeys_throughout`] | `Injection::Silence`: nothing from the chassis for its length; the driver keeps its heartbeat and turns the chassis silent and back with a warning and a notice; the chassis obeys throughout |
//! | [`garbage_is_counted_and_changes_nothing`] | `Injection::Garbage`: every byte leaves the chassis (its truth counts them), the driver counts what it cannot read and drives on |
//! | [`a_reboot_is_ridden_out`] | `Injection::Reboot`: counted, silent and deaf while booting; the chassis obeys again within 100 ms of its first frame after the boot, and drives |
//! | [`the_battery_it_reports_follows_the_charge`] | `Injection::Battery`: the charge is the one injected, what the driver reports of the battery follows it; a charge that is no number is refused |
//! | [`a_runaway_drives_past_the_limit_and_gives_control_back`] | `Injection::Runaway`: past the described limit whatever is commanded, the driver reports the speed measured; cleared, the chassis obeys again; a speed that is no number is refused |
//! | [`a_gain_turns_the_wheels_off_the_command`] | `Injection::Gain`: at 0 the chassis stands though commanded, at 0.5 it drives at half the command, at −1 against it, the driver reporting each; `None` obeys again; a gain that is no number is refused |
//! | [`injections_a_firmware_takes_do_what_they_say`] | those not every robot has, where a firmware takes them: a flood adds exactly the frames asked for, bad checksums spoil exactly the next frames and the driver counts each, an RC takeover, the E-stop switch and the bumper stop the chassis and the driver reports each, and it drives again after |
//! | [`what_is_no_command_is_counted_and_not_obeyed`] | the other medium is a decode error on both sides; the chassis' own frames echoed back to it are neither obeyed nor errors |
//! | [`every_frame_of_the_exchange_decodes`] | with the family's describer (`Family::codec`), naming the robot and the direction it was sent in |
//! | [`a_late_call_skips_missed_slots`] | a firmware called late sends one slot, not a burst, and keeps its grid |
//!
//! Two property tests feed arbitrary input — the family's own frames (recorded from its driver
//! and firmware) mutated, noise, the other medium — with arbitrary injections to every firmware
//! and driver: nothing panics or stalls, no value turns non-finite, no chassis drives or steers
//! past its limits unless a runaway is injected, and a CAN driver counts every item it is
//! handed. Two more tests break a side on purpose and see the suite fail.

use std::fmt;
use std::sync::LazyLock;
use std::time::Duration;

use chassis_interfaces::{
    ChassisState, ControlMode, FaultFlags, LinkFlags, RobotDescription, Velocity, WireProtocol,
};
use proptest::prelude::*;

use crate::Direction;
use crate::can::CanFrame;
use crate::command::Command;
use crate::description::describe;
use crate::driver::{BoxedDriver, Driver, DriverConfig, Level, WireItem};
use crate::family::Profile;
use crate::firmware::{BoxedFirmware, Firmware, Injection, MAX_RUNAWAY_MPS};
use crate::kind::RobotKind;
use crate::loopback::LoopbackProfile;
use crate::pair::{Pair, notices};
use crate::time::{Grid, Timestamp, earliest};

/// When both sides power up.
const START: Timestamp = Timestamp::from_millis(1_000);
/// The speed the suite drives at, m/s: within every robot's limits.
const SPEED_MPS: f64 = 0.3;
/// How close a speed is to the one commanded, or to standing, m/s.
const CLOSE_MPS: f64 = 0.01;

fn ms(v: u64) -> Duration {
    Duration::from_millis(v)
}

fn forward() -> Velocity {
    Velocity::twist(SPEED_MPS as f32, 0.0).unwrap()
}

/// The two sides of one profile the suite runs: its family's driver (default configuration) and
/// simulated firmware. A profile is its own sides; the suite's own tests put a broken stand-in
/// in place of one of them.
pub(crate) trait Sides {
    fn profile(&self) -> &Profile;

    fn new_driver(&self, now: Timestamp) -> BoxedDriver {
        self.profile().driver(&DriverConfig::default(), now)
    }

    fn new_firmware(&self, now: Timestamp) -> BoxedFirmware {
        self.profile().firmware(now)
    }
}

impl Sides for Profile {
    fn profile(&self) -> &Profile {
        self
    }
}

/// A broken promise of a family.
#[derive(Debug)]
pub(crate) struct Violation {
    /// The check, as named in this module.
    pub(crate) check: &'static str,
    /// The profile's robot, protocol and model.
    pub(crate) profile: String,
    /// What was expected and what happened instead.
    pub(crate) detail: String,
}

impl fmt::Display for Violation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}: {}", self.profile, self.check, self.detail)
    }
}

/// What a check found: nothing, or what it saw instead of the contract.
type Outcome = Result<(), String>;

/// Returns the formatted detail from the check when `condition` does not hold.
macro_rules! ensure {
    ($condition:expr, $($detail:tt)+) => {
        let holds: bool = $condition;
        if !holds {
            return Err(format!($($detail)+));
        }
    };
}

/// Runs every check on `sides`; each violation names its check and the profile.
pub(crate) fn check(sides: &dyn Sides) -> Result<(), Vec<Violation>> {
    let violations: Vec<Violation> = CHECKS
        .iter()
        .filter_map(|(name, check)| {
            check(sides).err().map(|detail| Violation {
                check: name,
                profile: profile_name(sides.profile()),
                detail,
            })
        })
        .collect();
    if violations.is_empty() {
        Ok(())
    } else {
        Err(violations)
    }
}

/// The robot, the protocol and the model of a profile (`scout-mini v1 (model scout-mini)`).
fn profile_name(profile: &Profile) -> String {
    let protocol = profile.protocol().map_or("own protocol", |p| p.name());
    let description = describe(profile);
    format!(
        "{} {protocol} (model {})",
        profile.robot(),
        description.model()
    )
}

// -------------------------------------------------------------------------------------------
// The pair and what to read of it.

type SimPair = Pair<BoxedDriver, BoxedFirmware>;

/// Both sides powered up at [`START`], recording every item on the wire.
fn pair(sides: &dyn Sides) -> SimPair {
    let mut pair = Pair::new(sides.new_driver(START), sides.new_firmware(START), START);
    pair.record = true;
    pair
}

/// Powered up for 1 s, then driving forward at [`SPEED_MPS`] for 3 s.
fn driving(sides: &dyn Sides) -> SimPair {
    let mut pair = pair(sides);
    pair.run_for(ms(1_000));
    pair.set_command(forward());
    pair.run_for(ms(3_000));
    pair
}

fn description(sides: &dyn Sides) -> RobotDescription {
    describe(sides.profile())
}

/// The chassis' command timeout, as the profile describes it.
fn command_timeout(sides: &dyn Sides) -> Duration {
    ms(description(sides).command_timeout_ms.into())
}

/// The simulated chassis' forward speed, m/s.
fn true_speed(pair: &SimPair) -> f64 {
    pair.firmware.truth().linear_mps
}

/// The forward speed the driver reports, m/s.
fn reported_speed(pair: &SimPair) -> f64 {
    f64::from(pair.driver.state().motion.linear_mps)
}

fn moving_forward(pair: &SimPair) -> bool {
    (true_speed(pair) - SPEED_MPS).abs() < CLOSE_MPS
}

fn standing(pair: &SimPair) -> bool {
    true_speed(pair).abs() < CLOSE_MPS / 2.0
}

fn silent(state: &ChassisState) -> bool {
    state.link_flags & LinkFlags::CHASSIS_SILENT != 0
}

/// Received items the driver dropped: bad checksums, undecodable, unknown ids, discarded bytes.
fn rx_errors(state: &ChassisState) -> u64 {
    let link = &state.link;
    link.rx_bad_checksum + link.rx_decode_errors + link.rx_unknown_id + link.rx_bytes_discarded
}

/// When the items sent in `direction` strictly after `since` went out.
fn sent_after(pair: &SimPair, direction: Direction, since: Timestamp) -> Vec<Timestamp> {
    pair.log()
        .iter()
        .filter(|r| r.direction == direction && r.at > since)
        .map(|r| r.at)
        .collect()
}

/// An item of the medium the firmware does not speak.
fn other_medium(pair: &SimPair) -> WireItem {
    let can = pair
        .log()
        .iter()
        .any(|r| matches!(r.item, WireItem::Can(_)));
    if can {
        WireItem::Bytes(vec![0xAA, 0x55, 0x01, 0x02])
    } else {
        WireItem::Can(CanFrame::new(0x111, &[0; 8]).unwrap())
    }
}

// -------------------------------------------------------------------------------------------
// The checks.

/// The driver, the firmware and the profile name one robot; within 1 s of power-up the driver
/// hears the chassis without an error of any kind, and the chassis obeys it, standing.
pub(crate) fn powers_up_and_takes_control(sides: &dyn Sides) -> Outcome {
    let mut pair = pair(sides);
    let kind = sides.profile().robot();
    let (driver, firmware) = (pair.driver.robot(), pair.firmware.robot());
    ensure!(
        driver == kind && firmware == kind,
        "the driver drives a {driver} and the firmware is a {firmware}, the profile's a {kind}"
    );
    ensure!(
        pair.driver.state().robot == kind.id(),
        "the state names robot {}, not {}",
        pair.driver.state().robot,
        kind.id()
    );
    pair.run_for(ms(1_000));
    let state = pair.driver.state();
    let truth = pair.firmware.truth();
    ensure!(state.link.rx_frames > 0, "the driver heard nothing in 1 s");
    ensure!(
        rx_errors(state) == 0,
        "the driver could not read {} items: {:?}",
        rx_errors(state),
        state.link
    );
    ensure!(!silent(state), "the driver flags the chassis silent");
    ensure!(
        truth.decode_errors == 0 && truth.bad_checksums_received == 0,
        "the chassis could not read the driver: {truth:?}"
    );
    ensure!(
        truth.control_mode == ControlMode::COMMAND,
        "after 1 s the chassis is in control mode {}, not {} (command)",
        truth.control_mode,
        ControlMode::COMMAND
    );
    ensure!(
        truth.linear_mps == 0.0 && truth.x_m == 0.0 && truth.yaw_rad == 0.0,
        "the chassis moved without a command: {truth:?}"
    );
    Ok(())
}

/// A driver restored from its snapshot ([`Driver::restore`]) goes on as the driver it was taken
/// of: through a stop, a turn, and the wire cut and back, the same items at the same instants,
/// and the same state. (The simulation is deterministic: the two pairs are the same run.)
pub(crate) fn a_restored_driver_goes_on_as_the_one_it_was_taken_of(sides: &dyn Sides) -> Outcome {
    let (mut kept, mut restored) = (driving(sides), driving(sides));
    let snapshot = restored.driver.snapshot().map_err(|e| e.to_string())?;
    let mut driver = sides.new_driver(START);
    driver.restore(&snapshot).map_err(|e| e.to_string())?;
    ensure!(
        driver.snapshot().ok().as_ref() == Some(&snapshot),
        "the restored driver's snapshot is not the one it was restored from"
    );
    restored.driver = driver;
    let since = kept.now();
    for pair in [&mut kept, &mut restored] {
        pair.set_command(Velocity::ZERO);
        pair.run_for(ms(500));
        pair.set_command(Velocity::twist(0.2, 0.3).unwrap_or(Velocity::ZERO));
        pair.run_for(ms(500));
        pair.cut = true;
        pair.run_for(ms(300));
        pair.cut = false;
        pair.run_for(ms(1_000));
    }
    let after = |pair: &SimPair| -> Vec<(Timestamp, bool, WireItem, bool)> {
        (pair.log().iter())
            .filter(|r| r.at >= since)
            .map(|r| {
                (
                    r.at,
                    r.direction == Direction::ToChassis,
                    r.item.clone(),
                    r.lost,
                )
            })
            .collect()
    };
    let (theirs, ours) = (after(&kept), after(&restored));
    let first = theirs.iter().zip(&ours).position(|(a, b)| a != b);
    ensure!(
        theirs.len() == ours.len() && first.is_none(),
        "the restored driver's exchange differs from the one it was taken of ({} items against \
         {}), first at {first:?}: {:?} against {:?}",
        ours.len(),
        theirs.len(),
        first.and_then(|i| ours.get(i)),
        first.and_then(|i| theirs.get(i))
    );
    ensure!(
        zerocopy::IntoBytes::as_bytes(kept.driver.state())
            == zerocopy::IntoBytes::as_bytes(restored.driver.state()),
        "the restored driver's state differs from the one it was taken of"
    );
    Ok(())
}

/// 0.3 m/s forward moves the chassis forward at 0.3 m/s, and the driver reports it.
pub(crate) fn drives_forward_and_reports_it(sides: &dyn Sides) -> Outcome {
    let pair = driving(sides);
    let truth = pair.firmware.truth();
    ensure!(
        moving_forward(&pair),
        "3 s after asking for {SPEED_MPS} m/s the chassis drives at {:.4} m/s",
        truth.linear_mps
    );
    ensure!(
        truth.x_m > 0.6 && truth.y_m.abs() < 0.01 && truth.yaw_rad.abs() < 0.01,
        "3 s forward took the chassis to {truth:?}"
    );
    let reported = reported_speed(&pair);
    ensure!(
        (reported - truth.linear_mps).abs() < CLOSE_MPS,
        "the driver reports {reported:.4} m/s, the chassis drives at {:.4}",
        truth.linear_mps
    );
    Ok(())
}

/// Zero stops the chassis within 3 s, the driver reports it standing, and the heartbeat goes on
/// carrying the zero.
pub(crate) fn a_zero_command_stops_it(sides: &dyn Sides) -> Outcome {
    let mut pair = driving(sides);
    pair.set_command(Velocity::ZERO);
    let stopped = pair.run_until_true(ms(3_000), |p| {
        standing(p) && reported_speed(p).abs() < CLOSE_MPS
    });
    ensure!(
        stopped.is_some(),
        "3 s after zero the chassis drives at {:.4} m/s, the driver reports {:.4}",
        true_speed(&pair),
        reported_speed(&pair)
    );
    let since = pair.now();
    let period = sides.profile().heartbeat_period();
    pair.run_for(ms(1_000));
    let sent = sent_after(&pair, Direction::ToChassis, since).len();
    let beats = (ms(1_000).as_nanos() / period.as_nanos()) as usize;
    ensure!(
        sent >= beats,
        "standing, the driver sent {sent} frames in 1 s, not a heartbeat every {period:?}"
    );
    ensure!(
        standing(&pair),
        "the chassis moved again: {:.4} m/s",
        true_speed(&pair)
    );
    Ok(())
}

/// At a steady command the driver sends exactly every heartbeat period (other frames may share
/// a heartbeat's instant); a changed command goes out at once, between two heartbeats, and the
/// heartbeats after it stay on their grid.
pub(crate) fn the_heartbeat_keeps_its_period(sides: &dyn Sides) -> Outcome {
    let period = sides.profile().heartbeat_period();
    let mut pair = driving(sides);
    let since = pair.now();
    pair.run_for(ms(5_000));
    let mut instants = sent_after(&pair, Direction::ToChassis, since);
    instants.dedup();
    let beats = (ms(5_000).as_nanos() / period.as_nanos()) as usize;
    ensure!(
        instants.len() + 1 >= beats,
        "{} sends in 5 s, a heartbeat every {period:?} is {beats}",
        instants.len()
    );
    for sends in instants.windows(2) {
        let gap = sends[1].saturating_since(sends[0]);
        ensure!(
            gap == period,
            "{gap:?} between two sends at a steady command, the heartbeat is {period:?}"
        );
    }
    let Some(&last) = instants.last() else {
        return Err("no heartbeat at all".into());
    };
    let change = last + period + period / 2;
    pair.run_until(change);
    pair.set_command(Velocity::twist(0.2, 0.0).unwrap());
    ensure!(
        pair.log()
            .iter()
            .any(|r| r.direction == Direction::ToChassis && r.at == change),
        "a changed command half a period after a heartbeat did not go out at once"
    );
    pair.run_for(period * 3);
    let mut after = sent_after(&pair, Direction::ToChassis, change);
    after.dedup();
    let grid: Vec<Timestamp> = (2..=4).map(|k| last + period * k).collect();
    ensure!(
        after == grid,
        "after the change the driver sent at {:?} ms after the last heartbeat, not on its grid",
        after
            .iter()
            .map(|t| t.saturating_since(last).as_millis())
            .collect::<Vec<_>>()
    );
    Ok(())
}

/// A cut cable: the chassis keeps the last command it heard for its described command timeout,
/// stops after it, and the driver flags it silent; with the cable back it drives again.
pub(crate) fn silence_from_the_driver_stops_the_chassis_at_its_command_timeout(
    sides: &dyn Sides,
) -> Outcome {
    let timeout = command_timeout(sides);
    let mut pair = driving(sides);
    pair.cut = true;
    let cut = pair.now();
    let Some(last) = pair
        .log()
        .iter()
        .filter(|r| r.direction == Direction::ToChassis && !r.lost)
        .map(|r| r.at)
        .max()
    else {
        return Err("the driver never sent".into());
    };
    // The last frame arrived one latency after it was sent; the timeout counts from there.
    let due = last + pair.latency + timeout;
    let slowed = pair.run_until_true(timeout + ms(1_000), |p| true_speed(p) < 0.95 * SPEED_MPS);
    let Some(slowed) = slowed else {
        return Err(format!(
            "{:?} after the cable was cut the chassis still drives at {:.4} m/s (timeout {timeout:?})",
            timeout + ms(1_000),
            true_speed(&pair)
        ));
    };
    ensure!(
        slowed >= due,
        "the chassis slowed {:?} after the last command arrived, before its {timeout:?} timeout",
        slowed.saturating_since(last + pair.latency)
    );
    ensure!(
        slowed <= due + ms(100),
        "the chassis slowed {:?} after its {timeout:?} timeout, not at it",
        slowed.saturating_since(due)
    );
    pair.run_for(ms(3_000));
    ensure!(
        standing(&pair),
        "without commands the chassis drives at {:.4} m/s",
        true_speed(&pair)
    );
    ensure!(
        silent(pair.driver.state()),
        "{:?} after the cut the driver does not flag the chassis silent",
        pair.now().saturating_since(cut)
    );
    pair.cut = false;
    let back = pair.run_until_true(ms(3_000), |p| {
        moving_forward(p) && !silent(p.driver.state())
    });
    ensure!(
        back.is_some(),
        "3 s after the cable is back the chassis drives at {:.4} m/s, silent flagged: {}",
        true_speed(&pair),
        silent(pair.driver.state())
    );
    Ok(())
}

/// Shutdown stops the chassis at once — well before its command timeout — and it stays stopped.
pub(crate) fn shutdown_stops_the_chassis_at_once(sides: &dyn Sides) -> Outcome {
    let mut pair = driving(sides);
    let at = pair.now();
    pair.driver.shutdown(at);
    let slowed = pair.run_until_true(ms(100), |p| true_speed(p) < 0.95 * SPEED_MPS);
    ensure!(
        slowed.is_some(),
        "100 ms after shutdown the chassis still drives at {:.4} m/s (its timeout is {:?})",
        true_speed(&pair),
        command_timeout(sides)
    );
    pair.run_for(ms(3_000));
    ensure!(
        standing(&pair),
        "3 s after shutdown the chassis drives at {:.4} m/s",
        true_speed(&pair)
    );
    pair.run_for(ms(2_000));
    ensure!(
        standing(&pair),
        "after shutdown the chassis moved again: {:.4} m/s",
        true_speed(&pair)
    );
    Ok(())
}

/// While the bus is down the driver sends nothing and refuses control requests, and the
/// chassis stops at its timeout; with the bus back the chassis drives again.
pub(crate) fn while_the_bus_is_down_nothing_is_sent(sides: &dyn Sides) -> Outcome {
    let timeout = command_timeout(sides);
    let mut pair = driving(sides);
    let down = pair.now();
    pair.driver.set_bus_down(down, true);
    ensure!(
        pair.driver.state().link_flags & LinkFlags::BUS_DOWN != 0,
        "the bus is down and the state does not say so"
    );
    let outcome = pair.control(&Command::Mode { take_control: true });
    ensure!(
        matches!(outcome, crate::ControlOutcome::Refused(_)),
        "with the bus down a control request was answered {outcome:?}"
    );
    pair.run_for(timeout + ms(2_000));
    let sent = sent_after(&pair, Direction::ToChassis, down).len();
    ensure!(sent == 0, "{sent} frames sent while the bus was down");
    ensure!(
        standing(&pair),
        "with the bus down past its timeout the chassis drives at {:.4} m/s",
        true_speed(&pair)
    );
    let up = pair.now();
    pair.driver.set_bus_down(up, false);
    ensure!(
        pair.driver.state().link_flags & LinkFlags::BUS_DOWN == 0,
        "the bus is back and the state still says it is down"
    );
    let back = pair.run_until_true(ms(3_000), moving_forward);
    ensure!(
        back.is_some(),
        "3 s after the bus came back the chassis drives at {:.4} m/s",
        true_speed(&pair)
    );
    Ok(())
}

/// `Injection::Silence`: nothing comes from the chassis for its length, the driver turns it
/// silent with a warning and back with a notice when it talks again, and the chassis obeys
/// throughout.
pub(crate) fn a_silenced_chassis_is_flagged_and_obeys_throughout(sides: &dyn Sides) -> Outcome {
    let length = ms(500);
    let mut pair = driving(sides);
    pair.take_events();
    ensure!(
        pair.inject(Injection::Silence(length)),
        "the silence was refused"
    );
    let at = pair.now();
    pair.run_until(at + length - ms(1));
    let heard = sent_after(&pair, Direction::FromChassis, at).len();
    ensure!(heard == 0, "{heard} items came from a silenced chassis");
    ensure!(
        silent(pair.driver.state()),
        "the driver did not flag the silence"
    );
    ensure!(
        moving_forward(&pair),
        "silenced, the chassis drives at {:.4} m/s: it must obey throughout",
        true_speed(&pair)
    );
    let period = sides.profile().heartbeat_period();
    let beats = (length.as_nanos() / period.as_nanos()) as usize;
    let sent = sent_after(&pair, Direction::ToChassis, at).len();
    ensure!(
        sent + 1 >= beats,
        "the driver sent {sent} frames to a silent chassis in {length:?}: its heartbeat stopped"
    );
    let quiet = pair.now();
    let talking = pair.run_until_true(ms(200), |p| {
        !sent_after(p, Direction::FromChassis, quiet).is_empty() && !silent(p.driver.state())
    });
    ensure!(
        talking.is_some(),
        "200 ms after the silence the chassis is not heard, or still flagged silent"
    );
    let levels: Vec<Level> = notices(&pair.take_events())
        .into_iter()
        .map(|(level, _)| level)
        .collect();
    let warned = levels.iter().position(|l| *l == Level::Warn);
    let cleared = levels.iter().rposition(|l| *l == Level::Info);
    ensure!(
        matches!((warned, cleared), (Some(w), Some(c)) if w < c),
        "the driver's notices were {levels:?}: a warning when it turned silent, then a notice"
    );
    Ok(())
}

/// `Injection::Garbage`: every byte leaves the chassis and its truth counts them; the driver
/// counts what it cannot read and drives on.
pub(crate) fn garbage_is_counted_and_changes_nothing(sides: &dyn Sides) -> Outcome {
    let mut pair = driving(sides);
    let before = rx_errors(pair.driver.state());
    ensure!(
        pair.inject(Injection::Garbage((0u8..20).collect())),
        "garbage was refused"
    );
    pair.run_for(ms(1_000));
    let injected = pair.firmware.truth().injected;
    ensure!(
        injected.garbage_bytes == 20 && injected.garbage_frames > 0,
        "20 bytes of garbage went out as {injected:?}"
    );
    let after = rx_errors(pair.driver.state());
    ensure!(after > before, "the driver counted none of the garbage");
    ensure!(
        moving_forward(&pair) && !silent(pair.driver.state()),
        "after the garbage the chassis drives at {:.4} m/s, silent flagged: {}",
        true_speed(&pair),
        silent(pair.driver.state())
    );
    ensure!(
        (reported_speed(&pair) - true_speed(&pair)).abs() < CLOSE_MPS,
        "after the garbage the driver reports {:.4} m/s",
        reported_speed(&pair)
    );
    Ok(())
}

/// `Injection::Reboot`: counted; the chassis is silent and deaf while it boots; it obeys again
/// within 100 ms of its first frame after the boot, and drives at the command it had.
pub(crate) fn a_reboot_is_ridden_out(sides: &dyn Sides) -> Outcome {
    let mut pair = driving(sides);
    let before = pair.firmware.truth();
    let received = before.commands_received;
    ensure!(pair.inject(Injection::Reboot), "the reboot was refused");
    let at = pair.now();
    let boots = pair.firmware.truth().boots - before.boots;
    ensure!(boots == 1, "{boots} boots counted for one reboot");
    let mut obeyed_booting = received;
    let talking = pair.run_until_true(ms(2_000), |p| {
        if !sent_after(p, Direction::FromChassis, at).is_empty() {
            return true;
        }
        obeyed_booting = p.firmware.truth().commands_received;
        false
    });
    let Some(talking) = talking else {
        return Err("2 s after a reboot the chassis has not talked again".into());
    };
    ensure!(
        talking > at,
        "the chassis sent at once after a reboot: no boot"
    );
    ensure!(
        obeyed_booting == received,
        "the chassis obeyed {} commands while it booted",
        obeyed_booting - received
    );
    let obeying = pair.run_until_true(ms(100), |p| {
        p.firmware.truth().control_mode == ControlMode::COMMAND
    });
    ensure!(
        obeying.is_some(),
        "100 ms after the chassis talked again it is in control mode {}, not command",
        pair.firmware.truth().control_mode
    );
    let moving = pair.run_until_true(ms(3_000), moving_forward);
    ensure!(
        moving.is_some(),
        "3 s after the reboot the chassis drives at {:.4} m/s",
        true_speed(&pair)
    );
    Ok(())
}

/// `Injection::Battery`: the chassis' charge is the one injected and what the driver reports of
/// the battery — its voltage, its charge where the chassis reports one — follows; a charge that
/// is no number is refused and changes nothing.
pub(crate) fn the_battery_it_reports_follows_the_charge(sides: &dyn Sides) -> Outcome {
    let mut pair = pair(sides);
    pair.run_for(ms(1_000));
    let before = pair.driver.state().system;
    ensure!(
        before.battery_voltage_v > 0.0 || before.battery_soc_pct > 0.0,
        "the driver reports no battery: {before:?}"
    );
    let soc = pair.firmware.truth().soc_pct;
    ensure!(
        !pair.inject(Injection::Battery { soc_pct: f64::NAN }),
        "a charge of NaN was taken"
    );
    ensure!(
        pair.firmware.truth().soc_pct == soc,
        "a refused charge changed the charge"
    );
    ensure!(
        pair.inject(Injection::Battery { soc_pct: 40.0 }),
        "a charge of 40 % was refused"
    );
    let truth = pair.firmware.truth().soc_pct;
    ensure!(truth == 40.0, "injected 40 %, the chassis has {truth} %");
    pair.run_for(ms(1_500));
    let after = pair.driver.state().system;
    if before.battery_voltage_v > 0.0 {
        ensure!(
            after.battery_voltage_v < before.battery_voltage_v - 0.5,
            "from 100 % to 40 % the reported voltage went from {} V to {} V",
            before.battery_voltage_v,
            after.battery_voltage_v
        );
    }
    if before.battery_soc_pct > 0.0 {
        ensure!(
            (after.battery_soc_pct - 40.0).abs() <= 1.0,
            "at 40 % the driver reports {} %",
            after.battery_soc_pct
        );
    }
    Ok(())
}

/// `Injection::Runaway` (the speed loop fails, the robot rolls downhill): the chassis drives
/// past its described limit whatever it is commanded, the driver reports the speed measured;
/// cleared, the chassis obeys again. What the safety monitor's speed rule is tested with.
pub(crate) fn a_runaway_drives_past_the_limit_and_gives_control_back(sides: &dyn Sides) -> Outcome {
    let limit = description(sides).robot_limits.forward_mps;
    let mut pair = pair(sides);
    pair.run_for(ms(2_000));
    let runaway = limit + 0.5;
    ensure!(
        pair.inject(Injection::Runaway(Some(runaway))),
        "the runaway was refused"
    );
    pair.set_command(Velocity::ZERO);
    pair.run_for(ms(3_000));
    let (truth, measured) = (true_speed(&pair), reported_speed(&pair));
    ensure!(
        truth > limit + 0.4 && measured > limit + 0.4,
        "limit {limit} m/s, runaway {runaway}: true {truth:.3}, measured {measured:.3}"
    );
    ensure!(
        pair.inject(Injection::Runaway(None)),
        "clearing the runaway was refused"
    );
    pair.run_for(ms(3_000));
    let measured = reported_speed(&pair);
    ensure!(
        measured.abs() < 0.05 && standing(&pair),
        "3 s after the runaway was cleared the chassis drives at {:.3} m/s, measured {measured:.3}",
        true_speed(&pair)
    );
    ensure!(
        !pair.inject(Injection::Runaway(Some(f64::NAN))),
        "a runaway at NaN m/s was taken"
    );
    Ok(())
}

/// `Injection::Gain` (a chassis that ignores its command, slips, or is wired backwards): the
/// wheels turn at the gain times the command, the driver reporting what they do; `None` obeys
/// again. What the safety monitor's direction and following rules are tested with.
pub(crate) fn a_gain_turns_the_wheels_off_the_command(sides: &dyn Sides) -> Outcome {
    let mut pair = driving(sides);
    for gain in [0.0, 0.5, -1.0] {
        ensure!(
            pair.inject(Injection::Gain(Some(gain))),
            "gain {gain} refused"
        );
        pair.run_for(ms(3_000));
        let (truth, measured) = (true_speed(&pair), reported_speed(&pair));
        let want = gain * SPEED_MPS;
        ensure!(
            (truth - want).abs() < 0.02 && (measured - want).abs() < 0.02,
            "gain {gain}: {want} m/s wanted, true {truth:.3}, measured {measured:.3}"
        );
    }
    ensure!(
        pair.inject(Injection::Gain(None)),
        "clearing the gain was refused"
    );
    pair.run_for(ms(3_000));
    ensure!(
        moving_forward(&pair),
        "3 s after the gain was cleared the chassis drives at {:.3} m/s",
        true_speed(&pair)
    );
    ensure!(
        !pair.inject(Injection::Gain(Some(f64::NAN))),
        "a gain that is no number was taken"
    );
    Ok(())
}

/// An injection that stops the chassis, the one that ends it, and how the driver reports it.
type Stop = (Injection, Injection, fn(&ChassisState) -> bool);

/// The injections not every robot has, where a firmware takes them: a flood adds exactly the
/// frames asked for and stops at 0; bad checksums spoil exactly the next frames and the driver
/// counts each one; an RC takeover, the E-stop switch and the bumper stop the chassis and the
/// driver reports each, and the chassis drives again after.
pub(crate) fn injections_a_firmware_takes_do_what_they_say(sides: &dyn Sides) -> Outcome {
    let mut pair = pair(sides);
    pair.run_for(ms(1_000));
    let count = |p: &mut SimPair| {
        let since = p.now();
        p.run_for(ms(1_000));
        sent_after(p, Direction::FromChassis, since).len()
    };
    let normal = count(&mut pair);
    if pair.inject(Injection::Flood { frames_per_s: 100 }) {
        let flooded = count(&mut pair);
        ensure!(
            flooded == normal + 100,
            "a flood of 100 a second: {flooded} items in a second, {normal} without it"
        );
        let flood = pair.firmware.truth().injected.flood_frames;
        ensure!(
            flood == 100,
            "the truth counts {flood} flood frames, 100 were sent"
        );
        ensure!(
            pair.inject(Injection::Flood { frames_per_s: 0 }),
            "stopping the flood was refused"
        );
        let after = count(&mut pair);
        ensure!(
            after == normal,
            "{after} items a second after the flood, {normal} before"
        );
    }

    let bad_before = pair.driver.state().link.rx_bad_checksum;
    if pair.inject(Injection::BadChecksums(5)) {
        pair.run_for(ms(1_000));
        let spoiled = pair.firmware.truth().injected.bad_checksum_frames;
        ensure!(spoiled == 5, "5 bad checksums asked, {spoiled} sent");
        let counted = pair.driver.state().link.rx_bad_checksum - bad_before;
        ensure!(
            counted == 5,
            "5 frames with a bad checksum, the driver counted {counted}"
        );
    }

    let mut pair = driving(sides);
    let stops: [Stop; 3] = [
        (
            Injection::RcTakeover(true),
            Injection::RcTakeover(false),
            |s| {
                s.system.control_mode == ControlMode::REMOTE
                    && s.link_flags & LinkFlags::RC_AUTHORITY != 0
            },
        ),
        (Injection::EStop(true), Injection::EStop(false), |s| {
            s.system.fault_flags & FaultFlags::EMERGENCY_STOP != 0
        }),
        (Injection::Bumper(true), Injection::Bumper(false), |s| {
            s.system.fault_flags & FaultFlags::BUMPER != 0
        }),
    ];
    for (on, off, reported) in stops {
        let name = on.name();
        if !pair.inject(on) {
            continue;
        }
        let stopped = pair.run_until_true(ms(3_000), |p| standing(p) && reported(p.driver.state()));
        ensure!(
            stopped.is_some(),
            "{name}: the chassis drives at {:.4} m/s, the driver reports {:?}",
            true_speed(&pair),
            pair.driver.state().system
        );
        ensure!(pair.inject(off), "{name}: ending it was refused");
        let again = pair.run_until_true(ms(3_000), |p| {
            moving_forward(p) && !reported(p.driver.state())
        });
        ensure!(
            again.is_some(),
            "{name}: 3 s after it ended the chassis drives at {:.4} m/s",
            true_speed(&pair)
        );
    }
    Ok(())
}

/// The other medium (serial bytes on a CAN bus, a CAN frame on a serial line) is a decode error
/// on both sides; the chassis' own frames echoed back to it are neither obeyed nor errors.
pub(crate) fn what_is_no_command_is_counted_and_not_obeyed(sides: &dyn Sides) -> Outcome {
    let mut pair = pair(sides);
    pair.run_for(ms(1_000));
    let now = pair.now();
    let wrong = other_medium(&pair);
    let before = pair.firmware.truth();
    pair.firmware.handle_rx(now, wrong.as_rx());
    let after = pair.firmware.truth();
    ensure!(
        after.decode_errors == before.decode_errors + 1
            && after.commands_received == before.commands_received,
        "the chassis took {wrong:?}: {before:?} then {after:?}"
    );
    let errors = pair.driver.state().link.rx_decode_errors;
    pair.driver.handle_rx(now, wrong.as_rx());
    ensure!(
        pair.driver.state().link.rx_decode_errors == errors + 1,
        "the driver did not count {wrong:?} as a decode error"
    );
    let own: Vec<WireItem> = pair
        .log()
        .iter()
        .filter(|r| r.direction == Direction::FromChassis && r.at + ms(100) > now)
        .map(|r| r.item.clone())
        .collect();
    ensure!(!own.is_empty(), "the chassis sent nothing in 100 ms");
    let before = pair.firmware.truth();
    for item in &own {
        pair.firmware.handle_rx(now, item.as_rx());
    }
    let after = pair.firmware.truth();
    ensure!(
        after.commands_received == before.commands_received
            && after.decode_errors == before.decode_errors
            && after.bad_checksums_received == before.bad_checksums_received,
        "its own {} frames echoed back: {before:?} then {after:?}",
        own.len()
    );
    Ok(())
}

/// Every frame of a drive — power-up, forward, a turn, a stop — decodes with the family's
/// describer in both directions, and its JSON names the robot and the direction it was sent in.
pub(crate) fn every_frame_of_the_exchange_decodes(sides: &dyn Sides) -> Outcome {
    let profile = sides.profile();
    let mut pair = driving(sides);
    pair.set_command(Velocity::twist(0.2, 0.1).unwrap());
    pair.run_for(ms(1_000));
    pair.set_command(Velocity::ZERO);
    pair.run_for(ms(1_000));
    let name = profile.robot().name();
    let mut codecs = [profile.codec(), profile.codec()];
    let mut decoded = [0usize; 2];
    for record in pair.log() {
        let side = usize::from(record.direction == Direction::FromChassis);
        let codec = &mut codecs[side];
        let jsons = match &record.item {
            WireItem::Can(frame) => vec![
                codec
                    .decode_can(frame)
                    .map_err(|e| format!("{:?} {frame}: {e}", record.direction))?,
            ],
            WireItem::Bytes(bytes) => codec
                .push_serial(bytes)
                .into_iter()
                .collect::<Result<Vec<_>, _>>()
                .map_err(|e| format!("{:?} {bytes:02X?}: {e}", record.direction))?,
        };
        let direction = serde_json::to_value(record.direction).unwrap();
        for json in jsons {
            ensure!(
                json["robot"] == name,
                "a frame of {name}'s exchange reads {json:?}"
            );
            ensure!(
                json["direction"] == direction,
                "sent {direction}, described {json:?}"
            );
            decoded[side] += 1;
        }
    }
    ensure!(
        decoded.iter().all(|n| *n > 10),
        "only {} frames to the chassis and {} from it described",
        decoded[0],
        decoded[1]
    );
    Ok(())
}

/// A firmware called once at power-up and next 1.234 s later sends at most what it sends at one
/// instant when called on time — one slot of each period, no burst of the missed ones — and
/// asks next for the first instant of its grid after the late call.
pub(crate) fn a_late_call_skips_missed_slots(sides: &dyn Sides) -> Outcome {
    let late = START + ms(1_234);
    let mut on_time = sides.new_firmware(START);
    let drain = |f: &mut BoxedFirmware, now| std::iter::from_fn(|| f.poll_transmit(now)).count();
    on_time.handle_timeout(START);
    let mut most = drain(&mut on_time, START);
    let mut grid = Vec::new();
    while let Some(t) = on_time.poll_timeout().filter(|t| *t <= late + ms(1_000)) {
        on_time.handle_timeout(t);
        most = most.max(drain(&mut on_time, t));
        grid.push(t);
    }
    let mut called_late = sides.new_firmware(START);
    let (burst, next) = crate::sim_bench::late_call(&mut called_late, START, late);
    ensure!(burst > 0, "called late, the firmware sent nothing");
    ensure!(
        burst <= most,
        "called 1.234 s late the firmware sent {burst} items at once; on time never more than {most}"
    );
    let expected = grid.iter().copied().find(|t| *t > late);
    ensure!(
        next == expected,
        "after the late call it asks for {:?}, its grid's next instant is {:?}",
        next.map(|t| t.saturating_since(START)),
        expected.map(|t| t.saturating_since(START))
    );
    Ok(())
}

// -------------------------------------------------------------------------------------------
// Every profile, and the suite's own tests.

/// Every profile of every robot in the registry (each protocol a robot speaks), and the
/// loopback family's.
fn every_profile() -> Vec<Profile> {
    RobotKind::ALL
        .into_iter()
        .flat_map(|kind| kind.entry().profiles())
        .chain([Profile::from(LoopbackProfile::default())])
        .collect()
}

/// Runs `check` on every profile; the failures of all, each with its profile.
fn everywhere(name: &str, check: fn(&dyn Sides) -> Outcome) {
    let failures: Vec<String> = every_profile()
        .iter()
        .filter_map(|p| check(p).err().map(|e| format!("{}: {e}", profile_name(p))))
        .collect();
    assert!(failures.is_empty(), "{name}:\n{}", failures.join("\n"));
}

/// Every check, by name, and one test a check running it on every profile.
macro_rules! checks {
    ($($check:ident),+ $(,)?) => {
        /// Every check, by name.
        pub(crate) const CHECKS: &[(&str, fn(&dyn Sides) -> Outcome)] =
            &[$((stringify!($check), $check)),+];

        mod every_family {
            $(
                #[test]
                fn $check() {
                    super::everywhere(stringify!($check), super::$check);
                }
            )+
        }
    };
}

checks!(
    powers_up_and_takes_control,
    drives_forward_and_reports_it,
    a_zero_command_stops_it,
    the_heartbeat_keeps_its_period,
    silence_from_the_driver_stops_the_chassis_at_its_command_timeout,
    shutdown_stops_the_chassis_at_once,
    while_the_bus_is_down_nothing_is_sent,
    a_silenced_chassis_is_flagged_and_obeys_throughout,
    garbage_is_counted_and_changes_nothing,
    a_reboot_is_ridden_out,
    the_battery_it_reports_follows_the_charge,
    a_runaway_drives_past_the_limit_and_gives_control_back,
    a_gain_turns_the_wheels_off_the_command,
    injections_a_firmware_takes_do_what_they_say,
    what_is_no_command_is_counted_and_not_obeyed,
    every_frame_of_the_exchange_decodes,
    a_late_call_skips_missed_slots,
    a_restored_driver_goes_on_as_the_one_it_was_taken_of,
);

/// A robot that may speak V1 or V2 with its listening driver ([`crate::agilex_v2::AutoDriver`]).
struct Detecting(Profile);

impl Sides for Detecting {
    fn profile(&self) -> &Profile {
        &self.0
    }

    fn new_driver(&self, now: Timestamp) -> BoxedDriver {
        let entry = self.0.robot().entry();
        entry.driver(&self.0, true, &DriverConfig::default(), now)
    }
}

#[test]
fn a_restored_listening_driver_goes_on_as_the_one_it_was_taken_of() {
    let detecting: Vec<Profile> = (RobotKind::ALL.into_iter())
        .filter(|kind| kind.entry().detects_protocol())
        .flat_map(|kind| kind.entry().profiles())
        .collect();
    assert!(detecting.len() >= 2, "{detecting:?}");
    for profile in detecting {
        let sides = Detecting(profile);
        let mut pair = pair(&sides);
        pair.run_for(ms(1_000));
        assert!(
            pair.driver.state().system.wire_protocol != WireProtocol::DETECTING,
            "{}: not detected in 1 s",
            profile_name(&sides.0)
        );
        if let Err(e) = a_restored_driver_goes_on_as_the_one_it_was_taken_of(&sides) {
            panic!("{}: {e}", profile_name(&sides.0));
        }
    }
}

#[test]
fn the_suite_runs_on_each_protocol_of_each_robot_and_on_the_loopback() {
    let profiles = every_profile();
    for kind in RobotKind::ALL {
        let protocols: Vec<_> = profiles
            .iter()
            .filter(|p| p.robot() == kind && p.get::<LoopbackProfile>().is_none())
            .map(|p| p.protocol())
            .collect();
        let registry: Vec<_> = kind.entry().profiles().map(|p| p.protocol()).collect();
        assert_eq!(protocols, registry, "{kind}");
    }
    assert!(
        profiles
            .iter()
            .any(|p| p.get::<LoopbackProfile>().is_some())
    );
}

/// A stand-in firmware: the profile's own, hearing the last item it received again every
/// 20 ms — a chassis without a command timeout.
struct Stubborn {
    inner: BoxedFirmware,
    last: Option<WireItem>,
    again: Grid,
}

impl Firmware for Stubborn {
    fn robot(&self) -> RobotKind {
        self.inner.robot()
    }
    fn handle_rx(&mut self, now: Timestamp, rx: crate::Rx<'_>) {
        self.last = Some(match rx {
            crate::Rx::Can(frame) => WireItem::Can(*frame),
            crate::Rx::Bytes(bytes) => WireItem::Bytes(bytes.to_vec()),
        });
        self.inner.handle_rx(now, rx);
    }
    fn handle_timeout(&mut self, now: Timestamp) {
        if self.again.serve_due(now)
            && let Some(last) = &self.last
        {
            self.inner.handle_rx(now, last.as_rx());
        }
        self.inner.handle_timeout(now);
    }
    fn poll_transmit(&mut self, now: Timestamp) -> Option<WireItem> {
        self.inner.poll_transmit(now)
    }
    fn poll_timeout(&self) -> Option<Timestamp> {
        earliest(self.inner.poll_timeout(), Some(self.again.next()))
    }
    fn inject(&mut self, now: Timestamp, injection: Injection) -> bool {
        self.inner.inject(now, injection)
    }
    fn truth(&self) -> crate::SimTruth {
        self.inner.truth()
    }
}

/// A stand-in driver: the profile's own, losing every fifth frame it sends.
struct Forgetful {
    inner: BoxedDriver,
    sent: u64,
}

impl Driver for Forgetful {
    fn robot(&self) -> RobotKind {
        self.inner.robot()
    }
    fn handle_rx(&mut self, now: Timestamp, rx: crate::Rx<'_>) {
        self.inner.handle_rx(now, rx);
    }
    fn set_command(&mut self, now: Timestamp, command: &Velocity) {
        self.inner.set_command(now, command);
    }
    fn control(&mut self, now: Timestamp, command: &Command) -> crate::ControlOutcome {
        self.inner.control(now, command)
    }
    fn handle_timeout(&mut self, now: Timestamp) {
        self.inner.handle_timeout(now);
    }
    fn poll_transmit(&mut self, now: Timestamp) -> Option<WireItem> {
        loop {
            let item = self.inner.poll_transmit(now)?;
            self.sent += 1;
            if !self.sent.is_multiple_of(5) {
                return Some(item);
            }
        }
    }
    fn poll_timeout(&self) -> Option<Timestamp> {
        self.inner.poll_timeout()
    }
    fn poll_event(&mut self) -> Option<crate::DriverEvent> {
        self.inner.poll_event()
    }
    fn state(&self) -> &ChassisState {
        self.inner.state()
    }
    fn set_bus_down(&mut self, now: Timestamp, down: bool) {
        self.inner.set_bus_down(now, down);
    }
    fn shutdown(&mut self, now: Timestamp) {
        self.inner.shutdown(now);
    }
    fn snapshot(&self) -> Result<Vec<u8>, crate::snapshot::SnapshotError> {
        self.inner.snapshot()
    }
    fn restore(&mut self, snapshot: &[u8]) -> Result<(), crate::snapshot::SnapshotError> {
        self.inner.restore(snapshot)
    }
}

/// A profile with one side replaced.
struct Broken {
    profile: Profile,
    stubborn_firmware: bool,
}

impl Sides for Broken {
    fn profile(&self) -> &Profile {
        &self.profile
    }

    fn new_driver(&self, now: Timestamp) -> BoxedDriver {
        let inner = self.profile.driver(&DriverConfig::default(), now);
        if self.stubborn_firmware {
            inner
        } else {
            Box::new(Forgetful { inner, sent: 0 })
        }
    }

    fn new_firmware(&self, now: Timestamp) -> BoxedFirmware {
        let inner = self.profile.firmware(now);
        if self.stubborn_firmware {
            Box::new(Stubborn {
                inner,
                last: None,
                again: Grid::new(ms(20), now),
            })
        } else {
            inner
        }
    }
}

/// The names of the checks `sides` fails.
fn failed(sides: &dyn Sides) -> Vec<&'static str> {
    match check(sides) {
        Ok(()) => Vec::new(),
        Err(violations) => violations.iter().map(|v| v.check).collect(),
    }
}

#[test]
fn a_firmware_without_a_command_timeout_fails_the_suite() {
    for profile in [
        RobotKind::Titan.entry().defaults(),
        LoopbackProfile::default().into(),
    ] {
        let broken = Broken {
            profile,
            stubborn_firmware: true,
        };
        let failed = failed(&broken);
        assert!(
            failed.contains(&"silence_from_the_driver_stops_the_chassis_at_its_command_timeout")
                && failed.contains(&"while_the_bus_is_down_nothing_is_sent"),
            "{}: {failed:?}",
            profile_name(&broken.profile)
        );
    }
}

#[test]
fn a_driver_that_loses_frames_fails_the_suite() {
    for profile in [
        RobotKind::Xbot.entry().defaults(),
        LoopbackProfile::default().into(),
    ] {
        let broken = Broken {
            profile,
            stubborn_firmware: false,
        };
        let failed = failed(&broken);
        assert!(
            failed.contains(&"the_heartbeat_keeps_its_period"),
            "{}: {failed:?}",
            profile_name(&broken.profile)
        );
    }
}

// -------------------------------------------------------------------------------------------
// Arbitrary input.

/// A profile with the frames its driver and its firmware sent during a drive with every control
/// request: the seeds the property tests mutate.
struct Seeds {
    profile: Profile,
    to_chassis: Vec<WireItem>,
    from_chassis: Vec<WireItem>,
}

static SEEDS: LazyLock<Vec<Seeds>> = LazyLock::new(|| {
    every_profile()
        .into_iter()
        .map(|profile| {
            let mut pair = pair(&profile);
            pair.run_for(ms(500));
            for command in [
                Command::Brake { engage: false },
                Command::ClearFaults { which: 0 },
                Command::Lights {
                    enable: true,
                    mode: 3,
                    brightness_pct: 50,
                },
                Command::Power { enable: true },
                Command::Lift {
                    enable: true,
                    position_pct: 50.0,
                },
                Command::Servos {
                    pan_rad: 0.2,
                    tilt_rad: -0.1,
                },
                Command::SteeringZero,
            ] {
                pair.control(&command);
            }
            for velocity in [
                forward(),
                Velocity::twist(-0.5, 0.4).unwrap(),
                Velocity::ZERO,
            ] {
                pair.set_command(velocity);
                pair.run_for(ms(500));
            }
            let items = |direction| {
                pair.log()
                    .iter()
                    .filter(|r| r.direction == direction)
                    .map(|r| r.item.clone())
                    .collect()
            };
            Seeds {
                to_chassis: items(Direction::ToChassis),
                from_chassis: items(Direction::FromChassis),
                profile,
            }
        })
        .collect()
});

/// One arbitrary input: a kind, an index, a byte position, a byte, bytes, and the gap before it.
type Input = (u8, usize, usize, u8, Vec<u8>, u64);

fn arbitrary_input() -> impl Strategy<Value = Input> {
    (
        0u8..10,
        any::<usize>(),
        any::<usize>(),
        any::<u8>(),
        proptest::collection::vec(any::<u8>(), 0..=12),
        0u64..300,
    )
}

/// The item an input makes of `seeds`: a seed as it is (kinds 0-2), with one byte changed
/// (3-5), noise (6-7), or the other medium (8); `None` for an injection (9).
fn item(seeds: &[WireItem], (kind, index, position, byte, bytes, _): &Input) -> Option<WireItem> {
    let seed = seeds.get(index % seeds.len().max(1)).cloned();
    let can = matches!(seed, Some(WireItem::Can(_)));
    match kind {
        0..=2 => seed,
        3..=5 => seed.map(|item| match item {
            WireItem::Can(frame) => {
                let mut data = frame.data().to_vec();
                let at = position % data.len().max(1);
                if let Some(b) = data.get_mut(at) {
                    *b ^= byte | 1;
                }
                WireItem::Can(CanFrame::new(frame.id(), &data).unwrap_or(frame))
            }
            WireItem::Bytes(mut data) => {
                let at = position % data.len().max(1);
                if let Some(b) = data.get_mut(at) {
                    *b ^= byte | 1;
                }
                WireItem::Bytes(data)
            }
        }),
        6 | 7 if can => {
            let data = &bytes[..bytes.len().min(8)];
            let id = (*index % 0x800) as u32;
            Some(WireItem::Can(if *kind == 6 {
                CanFrame::new(id, data).unwrap()
            } else {
                CanFrame::new_extended(id, data).unwrap()
            }))
        }
        6 | 7 => Some(WireItem::Bytes(bytes.clone())),
        8 if can => Some(WireItem::Bytes(bytes.clone())),
        8 => Some(WireItem::Can(CanFrame::new(0x111, &[0; 8]).unwrap())),
        _ => None,
    }
}

/// The injection an input of kind 9 makes.
fn injection((_, index, position, byte, bytes, _): &Input) -> Injection {
    let value = f64::from(*byte);
    match index % 14 {
        0 => Injection::MotorDriverLoss {
            motor: *byte % 6,
            lost: position % 2 == 0,
        },
        1 => Injection::Battery {
            soc_pct: value - 20.0,
        },
        2 => Injection::Bumper(position % 2 == 0),
        3 => Injection::RcTakeover(position % 2 == 0),
        4 => Injection::Reboot,
        5 => Injection::Silence(ms(u64::from(*byte))),
        6 => Injection::Garbage(bytes.clone()),
        7 => Injection::BadChecksums(u32::from(*byte % 20)),
        8 => Injection::ObstacleAhead((position % 2 == 0).then_some(value / 100.0)),
        9 => Injection::ObstacleBehind((position % 2 == 0).then_some(value / 100.0)),
        10 => Injection::Flood {
            frames_per_s: u32::from(*byte) * 4,
        },
        11 => Injection::EStop(position % 2 == 0),
        12 => Injection::Runaway((position % 3 != 0).then_some(value / 20.0 - 6.0)),
        _ => Injection::Gain((position % 3 != 0).then_some(value / 50.0 - 2.5)),
    }
}

proptest! {
    /// Arbitrary input and injections never panic or stall a firmware: every deadline it asks
    /// for lies ahead, its truth stays finite with a charge of 0-100 %, and it never drives
    /// past the robot's speed limit unless a runaway was injected, nor steers past its steering
    /// limit.
    #[test]
    fn arbitrary_input_never_panics_or_stalls_a_firmware(
        which in any::<prop::sample::Index>(),
        inputs in proptest::collection::vec(arbitrary_input(), 1..60),
    ) {
        let seeds = which.get(&SEEDS);
        let limits = describe(&seeds.profile).robot_limits;
        let limit = limits.forward_mps.max(limits.reverse_mps);
        // A robot that does not steer describes no steering limit.
        let steer_limit = if limits.steer_rad.is_finite() { limits.steer_rad } else { f64::INFINITY };
        let mut firmware = seeds.profile.firmware(START);
        let mut now = START;
        let mut ran_away = false;
        let mut largest_gain: f64 = 1.0;
        for input in &inputs {
            let arrival = now + ms(input.5);
            while let Some(t) = firmware.poll_timeout().filter(|t| *t <= arrival) {
                prop_assert!(t >= now, "a deadline in the past");
                now = t;
                firmware.handle_timeout(now);
                while firmware.poll_transmit(now).is_some() {}
                prop_assert!(firmware.poll_timeout().is_some_and(|next| next > now), "a stall");
            }
            now = arrival;
            match item(&seeds.to_chassis, input) {
                Some(item) => firmware.handle_rx(now, item.as_rx()),
                None => {
                    let injection = injection(input);
                    let runaway = matches!(injection, Injection::Runaway(Some(_)));
                    // A gain above 1 drives past the limit as far as it multiplies the command.
                    let gain = match injection {
                        Injection::Gain(Some(g)) => g.abs(),
                        _ => 1.0,
                    };
                    if firmware.inject(now, injection) {
                        ran_away |= runaway;
                        largest_gain = largest_gain.max(gain);
                    }
                }
            }
            if firmware.poll_timeout().is_some_and(|t| t <= now) {
                firmware.handle_timeout(now);
            }
            prop_assert!(firmware.poll_timeout().is_some_and(|next| next > now), "a stall");
            while firmware.poll_transmit(now).is_some() {}
            let truth = firmware.truth();
            let values = [truth.linear_mps, truth.lateral_mps, truth.angular_radps, truth.x_m, truth.y_m, truth.yaw_rad];
            prop_assert!(values.iter().all(|v| v.is_finite()), "{truth:?}");
            prop_assert!((0.0..=100.0).contains(&truth.soc_pct), "{truth:?}");
            let bound = if ran_away { MAX_RUNAWAY_MPS } else { limit * largest_gain };
            prop_assert!(truth.linear_mps.abs() <= bound + 1e-9, "{} m/s, limit {bound}", truth.linear_mps);
            prop_assert!(truth.steer_rad.abs() <= steer_limit + 1e-9, "{} rad, limit {steer_limit}", truth.steer_rad);
        }
    }

    /// Arbitrary input never panics or stalls a driver: once served, its next deadline lies
    /// ahead, what it reports stays finite, and a CAN driver counts every item it is handed, as a
    /// frame or as one kind of error.
    #[test]
    fn arbitrary_input_never_panics_or_stalls_a_driver(
        which in any::<prop::sample::Index>(),
        inputs in proptest::collection::vec(arbitrary_input(), 1..60),
    ) {
        let seeds = which.get(&SEEDS);
        let serial = matches!(seeds.from_chassis.first(), Some(WireItem::Bytes(_)));
        let mut driver = seeds.profile.driver(&DriverConfig::default(), START);
        let mut now = START;
        for input in &inputs {
            let arrival = now + ms(input.5);
            while let Some(t) = driver.poll_timeout().filter(|t| *t <= arrival) {
                // A frame due at once may name a deadline already past (as `Pair` takes it).
                now = now.max(t);
                driver.handle_timeout(now);
                while driver.poll_transmit(now).is_some() {}
                prop_assert!(driver.poll_timeout().is_some_and(|next| next > now), "a stall");
            }
            now = arrival;
            let Some(item) = item(&seeds.from_chassis, input) else {
                driver.set_command(now, &Velocity::twist(f32::from(input.3) / 100.0 - 1.0, 0.3).unwrap());
                // A changed command is due at once: its owner sends it.
                while driver.poll_transmit(now).is_some() {}
                continue;
            };
            let counted = |s: &ChassisState| s.link.rx_frames + rx_errors(s) - s.link.rx_bytes_discarded;
            let before = counted(driver.state());
            driver.handle_rx(now, item.as_rx());
            // A serial driver's stream may hold a frame over until its next bytes.
            if !serial || matches!(item, WireItem::Can(_)) {
                prop_assert_eq!(counted(driver.state()), before + 1, "{:?} counted as nothing or twice", item);
            }
            while driver.poll_transmit(now).is_some() {}
            let state = driver.state();
            let values = [state.motion.linear_mps, state.motion.angular_radps, state.odometry.x_m as f32, state.odometry.y_m as f32];
            prop_assert!(values.iter().all(|v| v.is_finite()), "{:?} {:?}", state.motion, state.odometry);
        }
    }
}
