//! What every simulated chassis has alike, whatever its robot: the outbox and the storms
//! injected into it, the boot, the battery's charge, a runaway speed loop and lost motor drivers.
//!
//! Each simulated firmware embeds one [`Chassis`] and hands it every [`Injection`] first
//! ([`Chassis::inject`]); what only one robot has (its RC authority, bumper, E-stop switch,
//! range sensors, what a reboot resets) comes back to the robot ([`Applied::Robot`]).

use std::time::Duration;

use super::{
    Flood, InjectedCounts, Injection, Outbox, Pose, SimTruth, motor_index, runaway_speed,
    state_of_charge,
};
use crate::can::CanFrame;
use crate::driver::WireItem;
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

/// Which of the shared injections a robot has.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Injectable {
    /// Motor drivers [`Injection::MotorDriverLoss`] may take away, numbered from 1 (0: none).
    pub(crate) motors: usize,
    /// Most extra frames a second [`Injection::Flood`] adds (0: the robot takes no flood).
    pub(crate) max_flood_per_s: u32,
    /// The robot's frames carry a checksum that [`Injection::BadChecksums`] corrupts.
    pub(crate) checksums: bool,
}

/// What [`Chassis::inject`] made of an injection.
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

/// The part of a simulated chassis every robot shares. Silence, floods, pending corruptions, a
/// runaway and lost motor drivers are test conditions: they survive a reboot.
#[derive(Debug, Clone)]
pub(crate) struct Chassis<T> {
    /// What the chassis has for transmission, with the silence window and the injected faults
    /// that left.
    pub(crate) outbox: Outbox<T>,
    /// State of charge, %: set by [`Injection::Battery`], drained by the robot's physics.
    pub(crate) soc_pct: f64,
    /// [`Injection::Runaway`]: the forward speed the chassis drives at whatever it is told.
    pub(crate) runaway_mps: Option<f64>,
    /// [`Injection::MotorDriverLoss`]: motor drivers 1-4 that do not answer.
    pub(crate) motor_lost: [bool; 4],
    /// Boots since the observer started counting ([`crate::SimTruth::boots`]).
    pub(crate) boots: u32,
    boot_time: Duration,
    booting_until: Option<Timestamp>,
    flood: Option<Flood>,
    /// Frames still to be sent with a corrupted checksum.
    corrupt_next: u32,
    has: Injectable,
}

impl<T: Item> Chassis<T> {
    /// A booted chassis with a full battery, nothing injected; reboots take `boot_time`.
    pub(crate) fn new(has: Injectable, boot_time: Duration) -> Self {
        Self {
            outbox: Outbox::new(),
            soc_pct: 100.0,
            runaway_mps: None,
            motor_lost: [false; 4],
            boots: 0,
            boot_time,
            booting_until: None,
            flood: None,
            corrupt_next: 0,
            has,
        }
    }

    /// Applies what every chassis handles alike: motor driver loss, battery state of charge,
    /// runaway, silence, garbage, bad checksums and floods. Anything else comes back as
    /// [`Applied::Robot`].
    pub(crate) fn inject(&mut self, now: Timestamp, injection: Injection) -> Applied {
        match injection {
            Injection::MotorDriverLoss { motor, lost } => {
                let Some(index) = motor_index(motor, self.has.motors.min(4)) else {
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
            Injection::BadChecksums(n) if self.has.checksums => {
                self.corrupt_next = self.corrupt_next.saturating_add(n);
                Applied::Done
            }
            Injection::Flood { frames_per_s } if self.has.max_flood_per_s > 0 => {
                self.flood = Flood::new(now, frames_per_s, self.has.max_flood_per_s);
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

impl<T> Chassis<T> {
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

    /// The truth every chassis knows alike: the `pose` its robot integrated, the charge, the
    /// boots and the injected faults that left; the robot fills in the rest (its speeds, mode,
    /// brake, faults and counters) over it.
    pub(crate) fn truth(&self, pose: Pose) -> SimTruth {
        SimTruth {
            x_m: pose.x_m,
            y_m: pose.y_m,
            yaw_rad: pose.yaw_rad,
            soc_pct: self.soc_pct,
            boots: self.boots,
            injected: self.outbox.injected(),
            ..SimTruth::default()
        }
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
        self.is_booting() || self.outbox.is_silenced(now)
    }

    /// True when the next frame sent must carry a corrupted checksum ([`Injection::BadChecksums`]);
    /// it counts as one of them.
    pub(crate) fn take_corruption(&mut self) -> bool {
        let corrupt = self.corrupt_next > 0;
        self.corrupt_next = self.corrupt_next.saturating_sub(1);
        corrupt
    }

    /// When a flood frame is due at `now`: serves it and says whether it is the second kind.
    pub(crate) fn flood_due(&mut self, now: Timestamp) -> Option<bool> {
        self.flood.as_mut().and_then(|flood| flood.due(now))
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

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    const CAN: Injectable = Injectable {
        motors: 4,
        max_flood_per_s: 1000,
        checksums: false,
    };

    const SERIAL: Injectable = Injectable {
        motors: 2,
        max_flood_per_s: 100,
        checksums: true,
    };

    fn can() -> Chassis<CanFrame> {
        Chassis::new(CAN, ms(300))
    }

    fn serial() -> Chassis<Vec<u8>> {
        Chassis::new(SERIAL, ms(300))
    }

    fn sent<T: Item>(chassis: &mut Chassis<T>) -> Vec<WireItem> {
        std::iter::from_fn(|| chassis.poll_transmit()).collect()
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
        let mut none = Chassis::<CanFrame>::new(
            Injectable {
                motors: 0,
                max_flood_per_s: 0,
                checksums: false,
            },
            ms(300),
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
