//! A driver and a simulated firmware wired back to back on simulated time.
//!
//! The test harness of the scenario tests (the quinn-proto `Pair` idea): both sides are driven
//! from their own deadlines, frames cross the wire with a configurable latency, and the clock
//! jumps straight to the next deadline, so thousands of simulated seconds run in well under a
//! second of CPU. Everything is deterministic.

use std::collections::VecDeque;
use std::time::Duration;

use chassis_interfaces::Velocity;

use crate::Direction;
use crate::command::Command;
use crate::driver::{ControlOutcome, Driver, DriverEvent, Level, WireItem};
use crate::firmware::{Firmware, Injection};
use crate::time::{Timestamp, earliest};

/// One item that crossed the wire.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// When it was sent.
    pub at: Timestamp,
    pub direction: Direction,
    pub item: WireItem,
    /// Sent while the wire was cut: it never arrived.
    pub lost: bool,
}

/// A driver and a firmware connected by a simulated wire.
#[derive(Debug)]
pub struct Pair<D, F> {
    pub driver: D,
    pub firmware: F,
    now: Timestamp,
    /// One-way latency of the wire.
    pub latency: Duration,
    /// While true, everything sent in either direction is lost (a cut cable).
    pub cut: bool,
    /// While true, every item sent is kept in [`Pair::log`].
    pub record: bool,
    to_firmware: VecDeque<(Timestamp, WireItem)>,
    to_driver: VecDeque<(Timestamp, WireItem)>,
    log: Vec<Record>,
    events: Vec<DriverEvent>,
    /// Times a side kept asking for a deadline that had already passed (a bug in that side).
    pub stalls: u64,
}

impl<D: Driver, F: Firmware> Pair<D, F> {
    /// Both sides start at `start`.
    pub fn new(driver: D, firmware: F, start: Timestamp) -> Self {
        Self {
            driver,
            firmware,
            now: start,
            latency: Duration::from_micros(250),
            cut: false,
            record: false,
            to_firmware: VecDeque::new(),
            to_driver: VecDeque::new(),
            log: Vec::new(),
            events: Vec::new(),
            stalls: 0,
        }
    }

    pub fn now(&self) -> Timestamp {
        self.now
    }

    /// Runs both sides until `until`.
    pub fn run_until(&mut self, until: Timestamp) {
        self.run_until_true_at(until, |_| false);
        self.flush();
    }

    /// Steps until `condition` holds (checked after every step) or `until`. A side that keeps
    /// asking for a deadline in the past is counted in [`Pair::stalls`] and time moves on by 1 µs,
    /// so a buggy side cannot hang a test.
    fn run_until_true_at(
        &mut self,
        until: Timestamp,
        mut condition: impl FnMut(&Self) -> bool,
    ) -> Option<Timestamp> {
        self.flush();
        if condition(self) {
            return Some(self.now);
        }
        let mut same_instant = 0u32;
        while self.now < until {
            let before = self.now;
            self.step(until);
            self.flush();
            if condition(self) {
                return Some(self.now);
            }
            if self.now == before {
                same_instant += 1;
                if same_instant > 10_000 {
                    self.stalls += 1;
                    self.now += Duration::from_micros(1);
                    same_instant = 0;
                }
            } else {
                same_instant = 0;
            }
        }
        None
    }

    /// Runs both sides for `duration`.
    pub fn run_for(&mut self, duration: Duration) {
        let until = self.now + duration;
        self.run_until(until);
    }

    /// Runs until `condition` holds (checked after every step) or `limit` has passed. Returns the
    /// time the condition first held.
    pub fn run_until_true(
        &mut self,
        limit: Duration,
        condition: impl FnMut(&Self) -> bool,
    ) -> Option<Timestamp> {
        let until = self.now + limit;
        self.run_until_true_at(until, condition)
    }

    fn step(&mut self, until: Timestamp) {
        self.flush();
        let queued = earliest(
            self.to_firmware.front().map(|(t, _)| *t),
            self.to_driver.front().map(|(t, _)| *t),
        );
        let next = earliest(
            earliest(self.driver.poll_timeout(), self.firmware.poll_timeout()),
            queued,
        )
        .map_or(until, |t| t.min(until))
        .max(self.now);
        self.now = next;
        let now = self.now;
        while let Some((_, item)) = self.to_firmware.front().filter(|(t, _)| *t <= now) {
            let item = item.clone();
            self.to_firmware.pop_front();
            self.firmware.handle_rx(now, item.as_rx());
        }
        while let Some((_, item)) = self.to_driver.front().filter(|(t, _)| *t <= now) {
            let item = item.clone();
            self.to_driver.pop_front();
            self.driver.handle_rx(now, item.as_rx());
        }
        if self.driver.poll_timeout().is_some_and(|t| t <= now) {
            self.driver.handle_timeout(now);
        }
        if self.firmware.poll_timeout().is_some_and(|t| t <= now) {
            self.firmware.handle_timeout(now);
        }
        self.flush();
    }

    /// Moves everything both sides want to send onto the wire.
    fn flush(&mut self) {
        let now = self.now;
        while let Some(item) = self.driver.poll_transmit(now) {
            self.send(Direction::ToChassis, item);
        }
        while let Some(item) = self.firmware.poll_transmit(now) {
            self.send(Direction::FromChassis, item);
        }
        while let Some(event) = self.driver.poll_event() {
            self.events.push(event);
        }
    }

    fn send(&mut self, direction: Direction, item: WireItem) {
        if self.record {
            self.log.push(Record {
                at: self.now,
                direction,
                item: item.clone(),
                lost: self.cut,
            });
        }
        if self.cut {
            return;
        }
        let at = self.now + self.latency;
        match direction {
            Direction::ToChassis => self.to_firmware.push_back((at, item)),
            Direction::FromChassis => self.to_driver.push_back((at, item)),
        }
    }

    /// Gives the driver a new command.
    pub fn set_command(&mut self, command: Velocity) {
        let now = self.now;
        self.driver.set_command(now, &command);
        self.flush();
    }

    /// Asks the driver for a control action.
    pub fn control(&mut self, command: &Command) -> ControlOutcome {
        let now = self.now;
        let outcome = self.driver.control(now, command);
        self.flush();
        outcome
    }

    /// Injects a fault into the firmware. Returns whether the robot has such a thing.
    pub fn inject(&mut self, injection: Injection) -> bool {
        let now = self.now;
        let ok = self.firmware.inject(now, injection);
        self.flush();
        ok
    }

    /// Puts something on the wire towards the driver, as if the chassis had sent it.
    pub fn send_to_driver(&mut self, item: WireItem) {
        self.send(Direction::FromChassis, item);
    }

    /// Puts something on the wire towards the chassis, as if the driver had sent it (a rogue
    /// node, a corrupted frame).
    pub fn send_to_firmware(&mut self, item: WireItem) {
        self.send(Direction::ToChassis, item);
    }

    /// Everything recorded while [`Pair::record`] was on.
    pub fn log(&self) -> &[Record] {
        &self.log
    }

    pub fn clear_log(&mut self) {
        self.log.clear();
    }

    /// Driver events collected so far (and forgets them).
    pub fn take_events(&mut self) -> Vec<DriverEvent> {
        std::mem::take(&mut self.events)
    }
}

/// The notices among `events`, with their level.
pub fn notices(events: &[DriverEvent]) -> Vec<(Level, String)> {
    events
        .iter()
        .filter_map(|e| match e {
            DriverEvent::Notice { level, message } => Some((*level, message.clone())),
            _ => None,
        })
        .collect()
}
