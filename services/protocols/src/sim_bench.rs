//! The bench of the simulated firmwares' own tests: one firmware alone on simulated time, fed by
//! hand, with an optional heartbeat from "the computer". Each robot's tests keep their `Bench`
//! (its fields are what the tests read) and implement [`SimBench`] for it; the time-keeping is
//! written once here.

use std::time::Duration;

use crate::can::CanFrame;
use crate::driver::WireItem;
use crate::firmware::{Firmware, Injection};
use crate::time::{Timestamp, earliest};

/// What one robot's firmware puts on the wire: CAN frames or serial chunks.
pub(crate) trait Sent: Sized {
    fn from_transmit(item: WireItem) -> Option<Self>;
}

impl Sent for CanFrame {
    fn from_transmit(item: WireItem) -> Option<Self> {
        match item {
            WireItem::Can(frame) => Some(frame),
            WireItem::Bytes(_) => None,
        }
    }
}

impl Sent for Vec<u8> {
    fn from_transmit(item: WireItem) -> Option<Self> {
        match item {
            WireItem::Bytes(bytes) => Some(bytes),
            WireItem::Can(_) => None,
        }
    }
}

/// The bench's fields the shared methods work on.
pub(crate) struct Parts<'a, F, I, C> {
    pub(crate) sim: &'a mut F,
    pub(crate) now: &'a mut Timestamp,
    /// Everything the chassis sent, with the time it was polled.
    pub(crate) sent: &'a mut Vec<(Timestamp, I)>,
    pub(crate) heartbeat: &'a mut Option<C>,
    pub(crate) next_heartbeat: &'a mut Timestamp,
    pub(crate) last_heartbeat: &'a mut Option<Timestamp>,
}

/// A firmware on simulated time whose heartbeat command is `Command`.
pub(crate) trait SimBench {
    type Firmware: Firmware;
    type Item: Sent;
    type Command: Copy;
    const HEARTBEAT_PERIOD: Duration;

    fn parts(&mut self) -> Parts<'_, Self::Firmware, Self::Item, Self::Command>;

    /// Everything the chassis sent, with the time it was polled.
    fn sent(&self) -> &[(Timestamp, Self::Item)];

    /// What the computer sends at each heartbeat.
    fn send_heartbeat(&mut self, command: Self::Command);

    fn inject(&mut self, injection: Injection) -> bool {
        let p = self.parts();
        let ok = p.sim.inject(*p.now, injection);
        self.drain();
        ok
    }

    /// Sends `command` every heartbeat period from now on (`None` stops it).
    fn heartbeat(&mut self, command: Option<Self::Command>) {
        let p = self.parts();
        if p.heartbeat.is_none() {
            *p.next_heartbeat = *p.now;
        }
        *p.heartbeat = command;
    }

    fn drain(&mut self) {
        let p = self.parts();
        while let Some(item) = p.sim.poll_transmit(*p.now) {
            let Some(item) = Self::Item::from_transmit(item) else {
                panic!("the firmware sent the other kind of bus item");
            };
            p.sent.push((*p.now, item));
        }
    }

    /// Moves time from deadline to deadline for `duration`, sending the heartbeat when it is
    /// due; a firmware whose deadline does not move on is a stall.
    fn run_for(&mut self, duration: Duration) {
        let until = *self.parts().now + duration;
        loop {
            let p = self.parts();
            let heartbeat = p.heartbeat.map(|_| *p.next_heartbeat);
            let next = earliest(p.sim.poll_timeout(), heartbeat).unwrap_or(until);
            assert!(next >= *p.now, "deadline {next:?} before now {:?}", p.now);
            if next > until {
                *p.now = until;
                break;
            }
            *p.now = next;
            if let Some(command) = *p.heartbeat
                && *p.next_heartbeat <= next
            {
                self.send_heartbeat(command);
                let p = self.parts();
                *p.last_heartbeat = Some(next);
                *p.next_heartbeat += Self::HEARTBEAT_PERIOD;
            }
            let p = self.parts();
            if p.sim.poll_timeout().is_some_and(|t| t <= next) {
                p.sim.handle_timeout(next);
                let after = p.sim.poll_timeout().unwrap();
                assert!(
                    after > next,
                    "stall: {after:?} after handle_timeout at {next:?}"
                );
            }
            self.drain();
        }
    }

    /// Items sent strictly after `since`.
    fn sent_since(&self, since: Timestamp) -> usize {
        self.sent().iter().filter(|(t, _)| *t > since).count()
    }
}
