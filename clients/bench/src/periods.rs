//! The clock of a controller's loop: periods on absolute deadlines, and the periods it missed.

use std::time::Duration;

use chassis_client::now_ns;

/// A periodic loop on absolute deadlines, as a controller's: period `k` starts at
/// `start + k·period`; a late period runs at once (none is skipped), and a period whose work ends
/// after the next one was due is a deadline miss.
pub struct Periods {
    next: u64,
    period: u64,
    /// The counted periods that ended late.
    pub misses: u64,
}

impl Periods {
    pub fn new(period: Duration) -> Self {
        let period = u64::try_from(period.as_nanos())
            .unwrap_or(u64::MAX / 4)
            .max(1);
        Self {
            next: now_ns() + period,
            period,
            misses: 0,
        }
    }

    /// Sleeps until the next period is due; returns when it was due.
    pub fn next(&mut self) -> u64 {
        use nix::sys::time::TimeSpec;
        use nix::time::{ClockId, ClockNanosleepFlags, clock_nanosleep};
        let due = self.next;
        let deadline = TimeSpec::from_duration(Duration::from_nanos(due));
        let _ = clock_nanosleep(
            ClockId::CLOCK_MONOTONIC,
            ClockNanosleepFlags::TIMER_ABSTIME,
            &deadline,
        );
        self.next += self.period;
        due
    }

    /// Ends the period due at `due`: a miss, if `counted`, when it ends after the next one was
    /// due.
    pub fn end(&mut self, due: u64, counted: bool) {
        if counted && now_ns() > due + self.period {
            self.misses += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_period_that_ends_after_the_next_one_was_due_is_a_miss() {
        // Periods long enough that a loaded machine ends the first one in time.
        let mut periods = Periods::new(Duration::from_millis(50));
        let due = periods.next();
        periods.end(due, true);
        assert_eq!(periods.misses, 0);
        // Periods whose work lasted into the next one.
        let due = periods.next();
        periods.next();
        periods.end(due, false);
        assert_eq!(periods.misses, 0, "a warm-up period is not counted");
        let due = periods.next();
        periods.next();
        periods.end(due, true);
        assert_eq!(periods.misses, 1);
    }
}
