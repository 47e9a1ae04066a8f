//! Time as a value: `CLOCK_MONOTONIC` nanoseconds, passed in by whoever owns the clock.

use std::ops::{Add, AddAssign, Sub};
use std::time::Duration;

use serde::{Deserialize, Serialize};

/// A point on the monotonic clock, ns. Drivers and firmware never read a clock: the event loop
/// (or a test) passes `now` in.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default, Serialize, Deserialize,
)]
pub struct Timestamp(u64);

impl Timestamp {
    pub const ZERO: Timestamp = Timestamp(0);

    pub const fn from_nanos(ns: u64) -> Self {
        Self(ns)
    }

    pub const fn from_millis(ms: u64) -> Self {
        Self(ms.saturating_mul(1_000_000))
    }

    pub const fn as_nanos(self) -> u64 {
        self.0
    }

    /// Time since `earlier`, zero if `earlier` is later.
    pub fn saturating_since(self, earlier: Timestamp) -> Duration {
        Duration::from_nanos(self.0.saturating_sub(earlier.0))
    }

    /// Seconds since `earlier` as `f64` (zero if `earlier` is later).
    pub fn secs_since(self, earlier: Timestamp) -> f64 {
        self.saturating_since(earlier).as_secs_f64()
    }
}

fn nanos(d: Duration) -> u64 {
    u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)
}

impl Add<Duration> for Timestamp {
    type Output = Timestamp;
    fn add(self, rhs: Duration) -> Timestamp {
        Timestamp(self.0.saturating_add(nanos(rhs)))
    }
}

impl AddAssign<Duration> for Timestamp {
    fn add_assign(&mut self, rhs: Duration) {
        *self = *self + rhs;
    }
}

impl Sub<Duration> for Timestamp {
    type Output = Timestamp;
    fn sub(self, rhs: Duration) -> Timestamp {
        Timestamp(self.0.saturating_sub(nanos(rhs)))
    }
}

/// A fixed grid of instants `start + k·period`: periodic work that never drifts. A late
/// service skips the missed slots instead of bunching them up.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Grid {
    period: Duration,
    next: Timestamp,
}

impl Grid {
    /// The first slot is at `start`.
    pub fn new(period: Duration, start: Timestamp) -> Self {
        Self {
            period: period.max(Duration::from_nanos(1)),
            next: start,
        }
    }

    /// True when the next slot has come.
    pub fn is_due(&self, now: Timestamp) -> bool {
        now >= self.next
    }

    /// The next slot.
    pub fn next(&self) -> Timestamp {
        self.next
    }

    pub fn period(&self) -> Duration {
        self.period
    }

    /// The slot at [`Grid::next`] was served at `now`: move to the first slot after `now`.
    pub fn served(&mut self, now: Timestamp) {
        self.next += self.period;
        if self.next <= now {
            let behind = now.saturating_since(self.next).as_nanos();
            let period = self.period.as_nanos().max(1);
            let skip = u32::try_from(behind / period + 1).unwrap_or(u32::MAX);
            self.next += self.period.saturating_mul(skip);
        }
    }

    /// Serves the slot when it has come at `now` ([`Grid::served`]); true when it had.
    pub fn serve_due(&mut self, now: Timestamp) -> bool {
        let due = self.is_due(now);
        if due {
            self.served(now);
        }
        due
    }

    /// Restart the grid at `start`.
    pub fn restart(&mut self, start: Timestamp) {
        self.next = start;
    }
}

/// The earlier of two optional deadlines.
pub fn earliest(a: Option<Timestamp>, b: Option<Timestamp>) -> Option<Timestamp> {
    match (a, b) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, None) => a,
        (None, b) => b,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arithmetic_saturates_instead_of_wrapping() {
        let t = Timestamp::from_millis(5);
        assert_eq!((t + Duration::from_millis(20)).as_nanos(), 25_000_000);
        assert_eq!(t - Duration::from_secs(1), Timestamp::ZERO);
        assert_eq!(Timestamp::ZERO.saturating_since(t), Duration::ZERO);
        assert_eq!(
            Timestamp::from_nanos(u64::MAX) + Duration::from_secs(1),
            Timestamp::from_nanos(u64::MAX)
        );
        assert!(
            (Timestamp::from_millis(1500).secs_since(Timestamp::from_millis(500)) - 1.0).abs()
                < 1e-12
        );
    }

    #[test]
    fn a_grid_never_drifts_and_skips_missed_slots() {
        let mut g = Grid::new(Duration::from_millis(20), Timestamp::from_millis(0));
        assert!(g.is_due(Timestamp::from_millis(0)));
        g.served(Timestamp::from_millis(3));
        assert_eq!(g.next(), Timestamp::from_millis(20));
        g.served(Timestamp::from_millis(75));
        assert_eq!(g.next(), Timestamp::from_millis(80));
        assert!(!g.is_due(Timestamp::from_millis(79)));
    }

    #[test]
    fn earliest_prefers_the_sooner_deadline() {
        let a = Some(Timestamp::from_millis(3));
        let b = Some(Timestamp::from_millis(2));
        assert_eq!(earliest(a, b), b);
        assert_eq!(earliest(a, None), a);
        assert_eq!(earliest(None, None), None);
    }
}
