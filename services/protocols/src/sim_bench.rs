//! The bench of the simulated firmwares' own tests: one firmware alone on simulated time, fed by
//! hand, with an optional heartbeat from "the computer". The bench is written once here; each
//! robot's tests say what its firmware sends and hears ([`BenchFirmware`]) and add their own
//! helpers to `Bench<TheirSim>`.

use std::time::Duration;

use crate::can::CanFrame;
use crate::driver::WireItem;
use crate::firmware::{Firmware, Injection};
use crate::time::{Timestamp, earliest};

/// A firmware powered up at `start`, called once then with its output drained, and next only at
/// `late`: how many items it sends at `late`, and when it asks to be called after that.
pub(crate) fn late_call(
    firmware: &mut impl Firmware,
    start: Timestamp,
    late: Timestamp,
) -> (usize, Option<Timestamp>) {
    firmware.handle_timeout(start);
    while firmware.poll_transmit(start).is_some() {}
    firmware.handle_timeout(late);
    let mut burst = 0;
    while firmware.poll_transmit(late).is_some() {
        burst += 1;
    }
    (burst, firmware.poll_timeout())
}

/// What one robot's firmware puts on the wire: CAN frames or serial chunks.
pub(crate) trait Sent: Sized {
    fn from_wire(item: WireItem) -> Option<Self>;
}

impl Sent for CanFrame {
    fn from_wire(item: WireItem) -> Option<Self> {
        match item {
            WireItem::Can(frame) => Some(frame),
            WireItem::Bytes(_) => None,
        }
    }
}

impl Sent for Vec<u8> {
    fn from_wire(item: WireItem) -> Option<Self> {
        match item {
            WireItem::Bytes(bytes) => Some(bytes),
            WireItem::Can(_) => None,
        }
    }
}

/// A firmware as its bench drives it: what it sends, its profile, and its heartbeat command.
pub(crate) trait BenchFirmware: Firmware + Sized {
    type Item: Sent;
    type Command: Copy;
    type Profile: Clone;
    const HEARTBEAT_PERIOD: Duration;

    fn bench_profile(&self) -> &Self::Profile;

    /// What the computer sends at each heartbeat.
    fn send_heartbeat(bench: &mut Bench<Self>, command: Self::Command);
}

/// One firmware on simulated time, and everything it sent.
pub(crate) struct Bench<F: BenchFirmware> {
    pub(crate) sim: F,
    /// The profile the computer's side encodes and decodes with (the firmware's own).
    pub(crate) profile: F::Profile,
    pub(crate) now: Timestamp,
    /// Everything the chassis sent, with the time it was polled.
    pub(crate) sent: Vec<(Timestamp, F::Item)>,
    heartbeat: Option<F::Command>,
    next_heartbeat: Timestamp,
    /// When the computer last sent its heartbeat.
    pub(crate) last_heartbeat: Option<Timestamp>,
    /// The computer's rolling count, for robots whose commands carry one (SCOUT MINI).
    pub(crate) count: u8,
}

impl<F: BenchFirmware> Bench<F> {
    /// `sim` at `now`, with what it sent at once already drained.
    pub(crate) fn with(sim: F, now: Timestamp) -> Self {
        let mut bench = Self {
            profile: sim.bench_profile().clone(),
            sim,
            now,
            sent: Vec::new(),
            heartbeat: None,
            next_heartbeat: now,
            last_heartbeat: None,
            count: 0,
        };
        bench.drain();
        bench
    }

    pub(crate) fn inject(&mut self, injection: Injection) -> bool {
        let ok = self.sim.inject(self.now, injection);
        self.drain();
        ok
    }

    /// Sends `command` every heartbeat period from now on (`None` stops it).
    pub(crate) fn heartbeat(&mut self, command: Option<F::Command>) {
        if self.heartbeat.is_none() {
            self.next_heartbeat = self.now;
        }
        self.heartbeat = command;
    }

    pub(crate) fn drain(&mut self) {
        while let Some(item) = self.sim.poll_transmit(self.now) {
            let Some(item) = F::Item::from_wire(item) else {
                panic!("the firmware sent the other kind of bus item");
            };
            self.sent.push((self.now, item));
        }
    }

    /// Moves time from deadline to deadline for `duration`, sending the heartbeat when it is
    /// due; a firmware whose deadline does not move on is a stall.
    pub(crate) fn run_for(&mut self, duration: Duration) {
        let until = self.now + duration;
        loop {
            let heartbeat = self.heartbeat.map(|_| self.next_heartbeat);
            let next = earliest(self.sim.poll_timeout(), heartbeat).unwrap_or(until);
            assert!(
                next >= self.now,
                "deadline {next:?} before now {:?}",
                self.now
            );
            if next > until {
                self.now = until;
                break;
            }
            self.now = next;
            if let Some(command) = self.heartbeat
                && self.next_heartbeat <= next
            {
                F::send_heartbeat(self, command);
                self.last_heartbeat = Some(next);
                self.next_heartbeat += F::HEARTBEAT_PERIOD;
            }
            if self.sim.poll_timeout().is_some_and(|t| t <= next) {
                self.sim.handle_timeout(next);
                let after = self.sim.poll_timeout().unwrap();
                assert!(
                    after > next,
                    "stall: {after:?} after handle_timeout at {next:?}"
                );
            }
            self.drain();
        }
    }

    /// The simulated chassis' forward speed, m/s.
    pub(crate) fn v(&self) -> f64 {
        self.sim.truth().linear_mps
    }

    /// Items sent strictly after `since`.
    pub(crate) fn sent_since(&self, since: Timestamp) -> usize {
        self.sent.iter().filter(|(t, _)| *t > since).count()
    }
}
