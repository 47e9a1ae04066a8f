//! Whether a mirrored robot is still heard: its link judged on local arrival times, and its
//! last state published again, marked lost, while it is not.

use std::time::Duration;

use chassis_client::{ChassisState, LinkFlags};

/// A mirrored robot silent for this long is marked lost. chassisd refreshes its state at
/// least every 100 ms and the robot side forwards each refresh: five missed in a row.
pub const LOST_AFTER: Duration = Duration::from_millis(500);
/// While lost, the last state is published again this often (a reader that asks then gets an
/// answer, marked lost, rather than nothing).
const REPUBLISH_NS: u64 = 200_000_000;

/// The last state of a robot whose link is lost, marked so, to publish again.
#[derive(Debug, Clone, Copy)]
pub struct Lost {
    pub state: ChassisState,
    /// The first publication of this loss (log it), not a repetition.
    pub first: bool,
    pub why: &'static str,
}

/// Whether a mirrored robot is still heard, judged on local arrival times (the robot's stamps
/// are another clock): lost after [`LOST_AFTER`] of silence or when its liveliness token goes,
/// heard again with its next state. Time is a parameter.
#[derive(Debug, Clone)]
pub struct LinkWatch {
    lost_after_ns: u64,
    last_heard_ns: Option<u64>,
    last_state: Option<ChassisState>,
    lost_since_ns: Option<u64>,
    republished_ns: u64,
    why: &'static str,
}

impl LinkWatch {
    pub fn new(lost_after: Duration) -> Self {
        Self {
            lost_after_ns: u64::try_from(lost_after.as_nanos()).unwrap_or(u64::MAX),
            last_heard_ns: None,
            last_state: None,
            lost_since_ns: None,
            republished_ns: 0,
            why: "",
        }
    }

    /// A state sample arrived at `now`; true if the robot was lost until now.
    pub fn heard(&mut self, now_ns: u64, state: &ChassisState) -> bool {
        self.last_heard_ns = Some(now_ns);
        self.last_state = Some(*state);
        self.lost_since_ns.take().is_some()
    }

    /// The robot's liveliness token appeared (`true`) or went (`false`) at `now`.
    pub fn alive(&mut self, now_ns: u64, alive: bool) -> Option<Lost> {
        if alive || self.lost_since_ns.is_some() {
            return None;
        }
        self.lose(now_ns, "its liveliness token is gone")
    }

    /// At `now`: the state to publish again, marked lost, when the robot has been silent too
    /// long (first at the loss, then every 200 ms).
    pub fn poll(&mut self, now_ns: u64) -> Option<Lost> {
        if self.lost_since_ns.is_some() {
            if now_ns.saturating_sub(self.republished_ns) < REPUBLISH_NS {
                return None;
            }
            self.republished_ns = now_ns;
            return self.marked(false);
        }
        let heard = self.last_heard_ns?;
        if now_ns.saturating_sub(heard) <= self.lost_after_ns {
            return None;
        }
        self.lose(now_ns, "nothing heard for longer than the loss limit")
    }

    /// True while the robot is lost.
    #[cfg(test)]
    pub fn is_lost(&self) -> bool {
        self.lost_since_ns.is_some()
    }

    fn lose(&mut self, now_ns: u64, why: &'static str) -> Option<Lost> {
        self.lost_since_ns = Some(now_ns);
        self.republished_ns = now_ns;
        self.why = why;
        self.marked(true)
    }

    fn marked(&self, first: bool) -> Option<Lost> {
        let mut state = self.last_state?;
        state.link_flags |= LinkFlags::REMOTE_LOST;
        Some(Lost {
            state,
            first,
            why: self.why,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    fn state(seq: u64) -> ChassisState {
        ChassisState {
            seq,
            ..ChassisState::default()
        }
    }

    #[test]
    fn a_robot_silent_past_the_limit_is_lost_with_its_last_state_and_heard_again_after() {
        let mut link = LinkWatch::new(Duration::from_millis(500));
        assert!(link.poll(0).is_none(), "never heard: nothing to publish");
        assert!(!link.heard(1_000 * MS, &state(7)));
        assert!(link.poll(1_400 * MS).is_none());
        assert!(link.poll(1_500 * MS).is_none(), "at the limit: not yet");
        let lost = link.poll(1_501 * MS).expect("lost past the limit");
        assert!(lost.first && link.is_lost());
        assert_eq!(lost.state.seq, 7);
        assert_ne!(lost.state.link_flags & LinkFlags::REMOTE_LOST, 0);
        // Published again every 200 ms while lost, not on every poll.
        assert!(link.poll(1_600 * MS).is_none());
        let again = link.poll(1_701 * MS).expect("again after 200 ms");
        assert!(!again.first);
        assert!(link.heard(1_800 * MS, &state(8)), "heard again");
        assert!(!link.is_lost());
        assert!(link.poll(2_000 * MS).is_none());
    }

    #[test]
    fn a_robot_whose_token_goes_is_lost_at_once() {
        let mut link = LinkWatch::new(Duration::from_millis(500));
        link.heard(0, &state(1));
        assert!(link.alive(10 * MS, true).is_none());
        let lost = link.alive(20 * MS, false).expect("lost with its token");
        assert!(lost.first);
        assert!(link.alive(30 * MS, false).is_none(), "lost once, not twice");
    }
}
