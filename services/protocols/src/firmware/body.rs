//! What every simulated chassis has alike, whatever its robot: the outbox and the storms
//! injected into it, the boot, the battery and its charge, the physics clock and the true pose, a
//! runaway speed loop, a gain between command and wheels, lost motor drivers, and the counts of what it received.
//!
//! Each simulated firmware embeds one [`SimBody`] and hands it every [`Injection`] first
//! ([`SimBody::inject`]); what only one robot has (its RC authority, bumper, E-stop switch,
//! range sensors, what a reboot resets) comes back to the robot ([`Applied::Robot`]).

use std::time::Duration;

use super::{
    BatteryModel, Flood, InjectedCounts, Injection, Outbox, Pose, SimTruth, Substeps, gain,
    motor_index, runaway_speed, state_of_charge, substeps,
};
use crate::Direction;
use crate::can::CanFrame;
use crate::driver::{Rx, WireItem};
use crate::time::{Timestamp, earliest};

/// CAN id of the frames that carry injected garbage on every simulated CAN chassis (0x7F0, an id
/// no simulated robot uses).
pub(crate) const GARBAGE_ID: u16 = 0x7F0;

/// What a simulated chassis puts on the wire: CAN frames, or chunks of a serial byte stream.
pub(crate) trait Item: Sized {
    /// [`Injection::Garbage`] as this wire carries it, each item with the faults it counts.
    fn garbage(bytes: Vec<u8>) -> Vec<(Self, InjectedCounts)>;

    fn into_wire(self) -> WireItem;
}

impl Item for CanFrame {
    /// The bytes, 8 at a time, as frames with [`GARBAGE_ID`].
    fn garbage(bytes: Vec<u8>) -> Vec<(Self, InjectedCounts)> {
        bytes
            .chunks(8)
            .filter_map(|chunk| CanFrame::new(u32::from(GARBAGE_ID), chunk).ok())
            .map(|frame| {
                let len = frame.data().len();
                (frame, InjectedCounts::garbage(len))
            })
            .collect()
    }

    fn into_wire(self) -> WireItem {
        WireItem::Can(self)
    }
}

impl Item for Vec<u8> {
    /// The bytes as they are, in one write (line noise); nothing for no bytes.
    fn garbage(bytes: Vec<u8>) -> Vec<(Self, InjectedCounts)> {
        if bytes.is_empty() {
            return Vec::new();
        }
        let counts = InjectedCounts::garbage(bytes.len());
        vec![(bytes, counts)]
    }

    fn into_wire(self) -> WireItem {
        WireItem::Bytes(self)
    }
}

/// What one robot's simulated chassis is, in the terms every chassis shares: which of the shared
/// injections it takes, how long it boots, its battery and what its electronics draw.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SimBodySpec {
    /// Motor drivers [`Injection::MotorDriverLoss`] may take away, numbered from 1 (0: none).
    pub(crate) motors: usize,
    /// Most extra frames a second [`Injection::Flood`] adds (0: the robot takes no flood).
    pub(crate) max_flood_per_s: u32,
    /// The robot's frames carry a checksum that [`Injection::BadChecksums`] corrupts.
    pub(crate) checksums: bool,
    /// Silence after a reboot.
    pub(crate) boot_time: Duration,
    /// One battery pack.
    pub(crate) battery: BatteryModel,
    /// What the electronics draw, A: the battery current before the physics first runs.
    pub(crate) idle_current_a: f64,
}

/// What [`SimBody::inject`] made of an injection.
#[derive(Debug, Clone, PartialEq)]
#[must_use]
pub(crate) enum Applied {
    /// Taken; it changed a condition the robot's rules watch (a motor driver, the battery).
    Condition,
    /// Taken; nothing more to do.
    Done,
    /// The robot has no such thing, or the value is out of range: the injection is refused.
    Refused,
    /// Not one the chassis handles alike: the robot's own to apply.
    Robot(Injection),
}

/// What a simulated chassis made of what it received, counted for the observer
/// ([`SimTruth`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct Received {
    /// Command frames obeyed ([`SimTruth::commands_received`]).
    pub(crate) commands: u64,
    /// Valid command frames not obeyed ([`SimTruth::commands_ignored`]).
    pub(crate) ignored: u64,
    /// Frames dropped for a bad checksum ([`SimTruth::bad_checksums_received`]).
    pub(crate) bad_checksums: u64,
    /// Frames that do not decode, or came on the other medium ([`SimTruth::decode_errors`]).
    pub(crate) decode_errors: u64,
    /// Valid frames only a chassis sends, from another node ([`SimTruth::frames_ignored`]).
    pub(crate) not_for_it: u64,
}

/// The part of a simulated chassis every robot shares. Silence, floods, pending corruptions, a
/// runaway and lost motor drivers are test conditions: they survive a reboot; the pose and the
/// battery are physical and survive it too; the counts are the observer's and keep counting.
#[derive(Debug, Clone)]
pub(crate) struct SimBody<T> {
    /// What the chassis has for transmission, with the silence window and the injected faults
    /// that left.
    pub(crate) outbox: Outbox<T>,
    /// State of charge, %: set by [`Injection::Battery`], drained by the robot's physics
    /// ([`SimBody::draw`]).
    pub(crate) soc_pct: f64,
    /// The current drawn from the battery now, A (positive = discharging).
    pub(crate) pack_current_a: f64,
    /// The true pose, in the frame the chassis started in, as the robot's physics moves it.
    pub(crate) pose: Pose,
    /// [`Injection::Runaway`]: the forward speed the chassis drives at whatever it is told.
    pub(crate) runaway_mps: Option<f64>,
    /// [`Injection::Gain`]: the multiple of the command the wheels turn at (1: they obey).
    pub(crate) gain: f64,
    /// [`Injection::MotorDriverLoss`]: motor drivers 1-4 that do not answer.
    pub(crate) motor_lost: [bool; 4],
    /// Boots since the observer started counting ([`crate::SimTruth::boots`]).
    pub(crate) boots: u32,
    /// What it made of what it received.
    pub(crate) received: Received,
    /// How far the physics has been integrated.
    last_update: Timestamp,
    /// Batteries fitted side by side.
    packs: u8,
    boot_time: Duration,
    booting_until: Option<Timestamp>,
    flood: Option<Flood>,
    /// Frames still to be sent with a corrupted checksum.
    corrupt_next: u32,
    spec: SimBodySpec,
}

impl<T: Item> SimBody<T> {
    /// A chassis booted at `now`, standing at the origin with one full battery, nothing
    /// injected, nothing received.
    pub(crate) fn new(spec: SimBodySpec, now: Timestamp) -> Self {
        Self {
            outbox: Outbox::new(),
            soc_pct: 100.0,
            pack_current_a: spec.idle_current_a,
            pose: Pose::default(),
            runaway_mps: None,
            gain: 1.0,
            motor_lost: [false; 4],
            boots: 0,
            received: Received::default(),
            last_update: now,
            packs: 1,
            boot_time: spec.boot_time,
            booting_until: None,
            flood: None,
            corrupt_next: 0,
            spec,
        }
    }

    /// Applies what every chassis handles alike: motor driver loss, battery state of charge,
    /// runaway, silence, garbage, bad checksums and floods. Anything else comes back as
    /// [`Applied::Robot`].
    pub(crate) fn inject(&mut self, now: Timestamp, injection: Injection) -> Applied {
        match injection {
            Injection::MotorDriverLoss { motor, lost } => {
                let Some(index) = motor_index(motor, self.spec.motors.min(4)) else {
                    return Applied::Refused;
                };
                self.motor_lost[index] = lost;
                Applied::Condition
            }
            Injection::Battery { soc_pct } => {
                let Some(soc_pct) = state_of_charge(soc_pct) else {
                    return Applied::Refused;
                };
                self.soc_pct = soc_pct;
                Applied::Condition
            }
            Injection::Runaway(speed) => {
                let Some(speed) = runaway_speed(speed) else {
                    return Applied::Refused;
                };
                self.runaway_mps = speed;
                Applied::Done
            }
            Injection::Gain(g) => {
                let Some(g) = gain(g) else {
                    return Applied::Refused;
                };
                self.gain = g.unwrap_or(1.0);
                Applied::Done
            }
            Injection::Silence(duration) => {
                self.outbox.silence(now, duration);
                Applied::Done
            }
            // Another node's noise, or the line's: on the wire at once, even while silent.
            Injection::Garbage(bytes) => {
                for (item, counts) in T::garbage(bytes) {
                    self.outbox.push_injected(item, counts);
                }
                Applied::Done
            }
            // Injections add up: one that comes before the last one's frames have all gone out
            // takes nothing away from it.
            Injection::BadChecksums(n) if self.spec.checksums => {
                self.corrupt_next = self.corrupt_next.saturating_add(n);
                Applied::Done
            }
            Injection::Flood { frames_per_s } if self.spec.max_flood_per_s > 0 => {
                self.flood = Flood::new(now, frames_per_s, self.spec.max_flood_per_s);
                Applied::Done
            }
            Injection::BadChecksums(_) | Injection::Flood { .. } => Applied::Refused,
            other => Applied::Robot(other),
        }
    }

    /// The next item the chassis sends.
    pub(crate) fn poll_transmit(&mut self) -> Option<WireItem> {
        self.outbox.pop().map(Item::into_wire)
    }
}

impl SimBody<CanFrame> {
    /// A command frame a simulated CAN chassis received, decoded by `decode`. Serial bytes (the
    /// wrong medium) and frames that do not decode count as decode errors; a valid frame that
    /// `direction` says only a chassis sends (another node's feedback) counts as not for it.
    pub(crate) fn command<F, E>(
        &mut self,
        rx: Rx<'_>,
        decode: impl FnOnce(&CanFrame) -> Result<F, E>,
        direction: impl FnOnce(&F) -> Direction,
    ) -> Option<F> {
        let decoded = match rx {
            Rx::Can(frame) => decode(frame).ok(),
            Rx::Bytes(_) => None,
        };
        let Some(frame) = decoded else {
            self.received.decode_errors += 1;
            return None;
        };
        if direction(&frame) == Direction::FromChassis {
            self.received.not_for_it += 1;
            return None;
        }
        Some(frame)
    }
}

impl<T> SimBody<T> {
    /// Starts a reboot at `now`: counted, and what is queued is dropped. True when the boot is
    /// over at once (no boot time).
    pub(crate) fn reboot(&mut self, now: Timestamp) -> bool {
        self.boots = self.boots.saturating_add(1);
        self.outbox.clear();
        if self.boot_time.is_zero() {
            self.booting_until = None;
            true
        } else {
            self.booting_until = Some(now + self.boot_time);
            false
        }
    }

    /// The truth every chassis knows alike: the pose, the charge, the boots, what it received
    /// and the injected faults that left; the robot fills in the rest (its speeds, mode, brake
    /// and faults) over it.
    pub(crate) fn truth(&self) -> SimTruth {
        SimTruth {
            x_m: self.pose.x_m,
            y_m: self.pose.y_m,
            yaw_rad: self.pose.yaw_rad,
            soc_pct: self.soc_pct,
            commands_received: self.received.commands,
            commands_ignored: self.received.ignored,
            frames_ignored: self.received.not_for_it,
            bad_checksums_received: self.received.bad_checksums,
            decode_errors: self.received.decode_errors,
            boots: self.boots,
            injected: self.outbox.injected(),
            ..SimTruth::default()
        }
    }

    /// The integration steps of the physics up to `now`, s ([`substeps`]).
    pub(crate) fn substeps(&mut self, now: Timestamp) -> Substeps {
        substeps(&mut self.last_update, now)
    }

    /// How far the physics has been integrated: the chassis' latest time.
    pub(crate) fn last_update(&self) -> Timestamp {
        self.last_update
    }

    /// Draws `current_a` from the battery for `dt` seconds (one step of the robot's physics).
    pub(crate) fn draw(&mut self, current_a: f64, dt: f64) {
        self.pack_current_a = current_a;
        self.soc_pct = self
            .spec
            .battery
            .drain(self.soc_pct, current_a, dt, f64::from(self.packs));
    }

    /// The battery's voltage under the current drawn now, V.
    pub(crate) fn battery_voltage_v(&self) -> f64 {
        self.spec
            .battery
            .voltage_v(self.soc_pct, self.pack_current_a)
    }

    /// Batteries fitted side by side (their capacities add up).
    pub(crate) fn set_packs(&mut self, packs: u8) {
        self.packs = packs;
    }

    /// Silence after a reboot.
    pub(crate) fn set_boot_time(&mut self, boot_time: Duration) {
        self.boot_time = boot_time;
    }

    /// True while the chassis boots after a reboot.
    pub(crate) fn is_booting(&self) -> bool {
        self.booting_until.is_some()
    }

    /// Ends a boot that is over by `now`, and forgets a silence that has ended: the time the
    /// boot ended, if it ended now.
    pub(crate) fn expire(&mut self, now: Timestamp) -> Option<Timestamp> {
        self.outbox.expire(now);
        let ended = self.booting_until.filter(|t| now >= *t)?;
        self.booting_until = None;
        Some(ended)
    }

    /// True while nothing may be sent: booting, or an injected silence.
    pub(crate) fn is_quiet(&self, now: Timestamp) -> bool {
        self.is_booting() || self.outbox.silent_until().is_some_and(|t| now < t)
    }

    /// True when the next frame sent must carry a corrupted checksum ([`Injection::BadChecksums`]);
    /// it counts as one of them.
    pub(crate) fn take_corruption(&mut self) -> bool {
        let corrupt = self.corrupt_next > 0;
        self.corrupt_next = self.corrupt_next.saturating_sub(1);
        corrupt
    }

    /// When a flood frame is due at `now`: serves it and says whether it is a copy of motor 1's
    /// feedback (`true`: every second one, while motor driver 1 answers) or of the motion
    /// feedback.
    pub(crate) fn flood_due(&mut self, now: Timestamp) -> Option<bool> {
        let second = self.flood.as_mut().and_then(|flood| flood.due(now))?;
        Some(second && !self.motor_lost[0])
    }

    /// The chassis' own deadlines: the end of a boot, of a silence, the next flood frame.
    pub(crate) fn poll_timeout(&self) -> Option<Timestamp> {
        [
            self.booting_until,
            self.outbox.silent_until(),
            self.flood.map(|f| f.next()),
        ]
        .into_iter()
        .fold(None, earliest)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::firmware::MAX_RUNAWAY_MPS;

    const T0: Timestamp = Timestamp::from_millis(1_000);

    const fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    const BATTERY: BatteryModel = BatteryModel {
        capacity_ah: 10.0,
        full_v: 25.0,
        empty_v: 20.0,
        resistance_ohm: 0.1,
    };

    const CAN: SimBodySpec = SimBodySpec {
        motors: 4,
        max_flood_per_s: 1000,
        checksums: false,
        boot_time: ms(300),
        battery: BATTERY,
        idle_current_a: 1.0,
    };

    const SERIAL: SimBodySpec = SimBodySpec {
        motors: 2,
        max_flood_per_s: 100,
        checksums: true,
        ..CAN
    };

    fn can() -> SimBody<CanFrame> {
        SimBody::new(CAN, T0)
    }

    fn serial() -> SimBody<Vec<u8>> {
        SimBody::new(SERIAL, T0)
    }

    fn sent<T: Item>(body: &mut SimBody<T>) -> Vec<WireItem> {
        std::iter::from_fn(|| body.poll_transmit()).collect()
    }

    #[test]
    fn garbage_goes_out_as_frames_of_8_bytes_on_can_and_as_is_on_a_serial_line() {
        let mut c = can();
        assert_eq!(
            c.inject(T0, Injection::Garbage((0u8..20).collect())),
            Applied::Done
        );
        let frames = sent(&mut c);
        let lens: Vec<usize> = frames
            .iter()
            .map(|f| f.as_can().map_or(0, |f| f.data().len()))
            .collect();
        assert_eq!(lens, [8, 8, 4]);
        assert!(
            frames
                .iter()
                .all(|f| f.as_can().is_some_and(|f| f.id() == u32::from(GARBAGE_ID)))
        );
        let injected = c.outbox.injected();
        assert_eq!((injected.garbage_frames, injected.garbage_bytes), (3, 20));

        let mut s = serial();
        assert_eq!(
            s.inject(T0, Injection::Garbage(vec![1, 2, 3])),
            Applied::Done
        );
        assert_eq!(s.inject(T0, Injection::Garbage(Vec::new())), Applied::Done);
        assert_eq!(sent(&mut s), [WireItem::Bytes(vec![1, 2, 3])]);
        let injected = s.outbox.injected();
        assert_eq!((injected.garbage_frames, injected.garbage_bytes), (1, 3));
    }

    #[test]
    fn garbage_goes_out_even_while_silent_but_nothing_else_may() {
        let mut c = can();
        assert_eq!(c.inject(T0, Injection::Silence(ms(100))), Applied::Done);
        assert!(c.is_quiet(T0 + ms(99)));
        assert!(!c.is_quiet(T0 + ms(100)));
        assert_eq!(c.inject(T0, Injection::Garbage(vec![0xFF])), Applied::Done);
        assert_eq!(sent(&mut c).len(), 1);
        assert_eq!(c.poll_timeout(), Some(T0 + ms(100)));
        assert_eq!(c.expire(T0 + ms(100)), None);
        assert_eq!(c.poll_timeout(), None);
    }

    #[test]
    fn what_a_robot_lacks_or_a_value_out_of_range_is_refused() {
        let mut c = can();
        assert_eq!(c.inject(T0, Injection::BadChecksums(3)), Applied::Refused);
        assert!(!c.take_corruption());
        let mut s = serial();
        for motor in [0, 3, 5] {
            let loss = Injection::MotorDriverLoss { motor, lost: true };
            assert_eq!(s.inject(T0, loss), Applied::Refused, "motor {motor}");
        }
        assert_eq!(s.motor_lost, [false; 4]);
        let soc = Injection::Battery { soc_pct: f64::NAN };
        assert_eq!(s.inject(T0, soc), Applied::Refused);
        let runaway = Injection::Runaway(Some(MAX_RUNAWAY_MPS + 1.0));
        assert_eq!(s.inject(T0, runaway), Applied::Refused);
        let mut none = SimBody::<CanFrame>::new(
            SimBodySpec {
                motors: 0,
                max_flood_per_s: 0,
                ..CAN
            },
            T0,
        );
        let flood = Injection::Flood { frames_per_s: 10 };
        assert_eq!(none.inject(T0, flood), Applied::Refused);
        let loss = Injection::MotorDriverLoss {
            motor: 1,
            lost: true,
        };
        assert_eq!(none.inject(T0, loss), Applied::Refused);
    }

    #[test]
    fn conditions_come_back_for_the_rules_and_the_robots_own_injections_come_back_whole() {
        let mut s = serial();
        let loss = Injection::MotorDriverLoss {
            motor: 2,
            lost: true,
        };
        assert_eq!(s.inject(T0, loss), Applied::Condition);
        assert_eq!(s.motor_lost, [false, true, false, false]);
        let soc = Injection::Battery { soc_pct: 150.0 };
        assert_eq!(s.inject(T0, soc), Applied::Condition);
        assert_eq!(s.soc_pct, 100.0);
        assert_eq!(s.inject(T0, Injection::Runaway(Some(-2.0))), Applied::Done);
        assert_eq!(s.runaway_mps, Some(-2.0));
        assert_eq!(s.inject(T0, Injection::Runaway(None)), Applied::Done);
        assert_eq!(s.runaway_mps, None);
        for own in [
            Injection::Reboot,
            Injection::RcTakeover(true),
            Injection::Bumper(true),
            Injection::EStop(true),
            Injection::ObstacleAhead(Some(1.0)),
        ] {
            assert_eq!(s.inject(T0, own.clone()), Applied::Robot(own));
        }
    }

    #[test]
    fn bad_checksum_injections_add_up_frame_by_frame() {
        let mut s = serial();
        assert_eq!(s.inject(T0, Injection::BadChecksums(2)), Applied::Done);
        assert!(s.take_corruption());
        assert_eq!(s.inject(T0, Injection::BadChecksums(2)), Applied::Done);
        let taken: Vec<bool> = (0..5).map(|_| s.take_corruption()).collect();
        assert_eq!(taken, [true, true, true, false, false]);
    }

    #[test]
    fn a_flood_is_capped_at_what_the_robot_carries_and_zero_stops_it() {
        let mut s = serial();
        let flood = Injection::Flood {
            frames_per_s: 1_000_000,
        };
        assert_eq!(s.inject(T0, flood), Applied::Done);
        // 100 a second at the most: one every 10 ms, alternating kinds.
        assert_eq!(s.poll_timeout(), Some(T0 + ms(10)));
        assert_eq!(s.flood_due(T0 + ms(9)), None);
        assert_eq!(s.flood_due(T0 + ms(10)), Some(false));
        assert_eq!(s.flood_due(T0 + ms(20)), Some(true));
        let stop = Injection::Flood { frames_per_s: 0 };
        assert_eq!(s.inject(T0 + ms(20), stop), Applied::Done);
        assert_eq!(s.flood_due(T0 + ms(30)), None);
        assert_eq!(s.poll_timeout(), None);
    }

    #[test]
    fn a_reboot_counts_drops_the_queue_and_ends_after_the_boot_time_or_at_once() {
        let mut c = can();
        assert_eq!(c.inject(T0, Injection::Garbage(vec![1])), Applied::Done);
        assert!(!c.reboot(T0));
        assert_eq!(c.boots, 1);
        assert!(c.is_booting() && c.is_quiet(T0));
        assert!(sent(&mut c).is_empty(), "the queue is dropped");
        assert_eq!(c.poll_timeout(), Some(T0 + ms(300)));
        assert_eq!(c.expire(T0 + ms(299)), None);
        assert_eq!(c.expire(T0 + ms(301)), Some(T0 + ms(300)));
        assert!(!c.is_booting());

        c.set_boot_time(Duration::ZERO);
        assert!(c.reboot(T0 + ms(400)), "no boot time: booted at once");
        assert_eq!(c.boots, 2);
        assert!(!c.is_booting());
    }

    #[test]
    fn the_battery_drains_by_the_current_drawn_and_two_packs_last_twice_as_long() {
        let mut one = can();
        assert_eq!(one.battery_voltage_v(), 25.0 - 0.1 * 1.0, "idle current");
        // 10 A for an hour from 10 Ah: empty.
        for _ in 0..3600 {
            one.draw(10.0, 1.0);
        }
        assert!(one.soc_pct.abs() < 1e-9, "{}", one.soc_pct);
        assert!((one.battery_voltage_v() - (20.0 - 0.1 * 10.0)).abs() < 1e-9);
        let mut two = can();
        two.set_packs(2);
        for _ in 0..3600 {
            two.draw(10.0, 1.0);
        }
        assert!((two.soc_pct - 50.0).abs() < 1e-9, "{}", two.soc_pct);
    }

    #[test]
    fn a_flood_copies_the_motion_feedback_in_place_of_a_lost_motor_1s() {
        let mut c = can();
        let flood = Injection::Flood { frames_per_s: 1000 };
        assert_eq!(c.inject(T0, flood), Applied::Done);
        let kinds = |c: &mut SimBody<CanFrame>, from: u64| {
            (from..from + 4)
                .map(|t| c.flood_due(T0 + ms(t)))
                .collect::<Vec<_>>()
        };
        assert_eq!(
            kinds(&mut c, 1),
            [Some(false), Some(true), Some(false), Some(true)]
        );
        let loss = Injection::MotorDriverLoss {
            motor: 1,
            lost: true,
        };
        assert_eq!(c.inject(T0, loss), Applied::Condition);
        assert_eq!(kinds(&mut c, 5), [Some(false); 4]);
    }

    #[test]
    fn a_command_is_decoded_and_what_is_none_is_counted() {
        let mut c = can();
        let decode = |f: &CanFrame| match f.id() {
            0x100 => Ok(Direction::ToChassis),
            0x200 => Ok(Direction::FromChassis),
            _ => Err(()),
        };
        let frame = |id| CanFrame::new(id, &[0]).unwrap();
        let command = c.command(Rx::Can(&frame(0x100)), decode, |d| *d);
        assert_eq!(command, Some(Direction::ToChassis));
        assert_eq!(c.command(Rx::Can(&frame(0x200)), decode, |d| *d), None);
        assert_eq!(c.command(Rx::Can(&frame(0x300)), decode, |d| *d), None);
        assert_eq!(c.command(Rx::Bytes(&[0xAA]), decode, |d| *d), None);
        assert_eq!(
            (c.received.not_for_it, c.received.decode_errors),
            (1, 2),
            "another node's feedback, an unknown frame and serial bytes"
        );
        let truth = c.truth();
        assert_eq!((truth.decode_errors, truth.commands_received), (2, 0));
    }

    #[test]
    fn silence_floods_and_corruptions_survive_a_reboot() {
        let mut s = serial();
        assert_eq!(s.inject(T0, Injection::Silence(ms(1000))), Applied::Done);
        assert_eq!(s.inject(T0, Injection::BadChecksums(1)), Applied::Done);
        let flood = Injection::Flood { frames_per_s: 10 };
        assert_eq!(s.inject(T0, flood), Applied::Done);
        assert!(!s.reboot(T0));
        assert_eq!(s.expire(T0 + ms(300)), Some(T0 + ms(300)));
        assert!(s.is_quiet(T0 + ms(300)), "still silenced");
        assert_eq!(s.flood_due(T0 + ms(100)), Some(false));
        assert!(s.take_corruption());
    }
}
