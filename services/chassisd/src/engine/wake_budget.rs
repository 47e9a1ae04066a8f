//! Wake-ups per source and tick.
//!
//! A client publishing far faster than any controller needs (a runaway or rogue process, 100k
//! requests a second) would wake the loop from one notification to the next: a CPU hog that the
//! kernel then schedules in time slices, late for its deadlines (the heartbeat), with every core
//! it shares busy. Past [`WakeBudget::PER_TICK`] wake-ups in one tick the source's listener is
//! detached until the next tick: its requests are still read on every tick (its newest 16 wait in
//! its queue, and iceoryx2 coalesces its notifications), so it keeps its place in the mux, while
//! every other source still wakes the loop at once. Safety-priority sources are exempt: a stop
//! from the safety monitor never waits for a tick (the monitor holds its source alone: no rogue
//! process can publish on it).

use chassis_protocols::Timestamp;
use serde::{Deserialize, Serialize};

/// What the shell does with a source's listener.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ListenerChange {
    /// Over budget: stop waking the loop until the next tick.
    Detach(usize),
    /// A new tick: wake the loop again.
    Attach(usize),
}

/// Wake-ups counted per source in the current tick.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct WakeBudget {
    spent: Vec<u32>,
    /// One bit per detached source.
    detached: u32,
    /// One bit per source never detached.
    exempt: u32,
    /// The tick the counts belong to (its deadline).
    tick: Timestamp,
}

impl WakeBudget {
    /// 1 kHz at the 20 ms tick: more than any client needs.
    pub const PER_TICK: u32 = 20;

    /// `sources` sources, counting in the tick whose deadline is `tick`; `exempt` has one bit
    /// per source that is never detached.
    pub fn new(sources: usize, tick: Timestamp, exempt: u32) -> Self {
        Self {
            spent: vec![0; sources],
            detached: 0,
            exempt,
            tick,
        }
    }

    /// Every listener was attached again (a new wait set): counting starts over.
    pub fn reset(&mut self, tick: Timestamp) {
        self.spent.iter_mut().for_each(|n| *n = 0);
        self.detached = 0;
        self.tick = tick;
    }

    /// Counts the wake-ups of `fired` (one bit per source) in the tick whose deadline is `tick`;
    /// returns the listeners that must change: detached (over budget) or attached again (a new
    /// tick began).
    pub fn spend(&mut self, fired: u32, tick: Timestamp) -> Vec<ListenerChange> {
        let mut changes = Vec::new();
        if tick != self.tick {
            self.tick = tick;
            self.spent.iter_mut().for_each(|n| *n = 0);
            changes.extend(
                (0..self.spent.len())
                    .filter(|i| self.detached & (1 << i) != 0)
                    .map(ListenerChange::Attach),
            );
            self.detached = 0;
        }
        for (index, spent) in self.spent.iter_mut().enumerate() {
            if fired & !self.exempt & (1 << index) != 0 && self.detached & (1 << index) == 0 {
                *spent += 1;
                if *spent > Self::PER_TICK {
                    self.detached |= 1 << index;
                    changes.push(ListenerChange::Detach(index));
                }
            }
        }
        changes
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ListenerChange::{Attach, Detach};

    #[test]
    fn a_source_waking_the_loop_past_its_budget_is_detached_until_the_next_tick() {
        let tick = Timestamp::from_millis(20);
        let mut budget = WakeBudget::new(3, tick, 0);
        // Source 1 floods, source 0 wakes now and then.
        for _ in 0..WakeBudget::PER_TICK {
            assert!(budget.spend(0b010, tick).is_empty());
        }
        assert_eq!(budget.spend(0b011, tick), vec![Detach(1)], "over budget");
        assert!(
            budget.spend(0b001, tick).is_empty(),
            "the others are untouched"
        );
        assert!(
            budget.spend(0b010, tick).is_empty(),
            "detached: no longer counted"
        );
        // The next tick attaches it again, with a fresh budget.
        let next = Timestamp::from_millis(40);
        assert_eq!(budget.spend(0, next), vec![Attach(1)]);
        for _ in 0..WakeBudget::PER_TICK {
            assert!(budget.spend(0b010, next).is_empty());
        }
        assert_eq!(budget.spend(0b010, next), vec![Detach(1)]);
    }

    #[test]
    fn a_safety_source_is_never_detached() {
        let tick = Timestamp::from_millis(20);
        // Source 2 has safety priority.
        let mut budget = WakeBudget::new(3, tick, 0b100);
        for _ in 0..10 * WakeBudget::PER_TICK {
            assert!(budget.spend(0b100, tick).is_empty());
        }
        // The others still have their budget.
        for _ in 0..WakeBudget::PER_TICK {
            assert!(budget.spend(0b101, tick).is_empty());
        }
        assert_eq!(budget.spend(0b101, tick), vec![Detach(0)]);
    }

    #[test]
    fn a_reset_forgets_the_counts_and_the_detached() {
        let tick = Timestamp::from_millis(20);
        let mut budget = WakeBudget::new(1, tick, 0);
        for _ in 0..=WakeBudget::PER_TICK {
            budget.spend(0b1, tick);
        }
        budget.reset(tick);
        assert!(
            budget.spend(0, Timestamp::from_millis(40)).is_empty(),
            "nothing to attach again"
        );
    }
}
