//! Stamps for other protocols: every stamp in the system is `CLOCK_MONOTONIC`; ROS 2 and
//! Foxglove want Unix time. [`WallClock`] measures the system clock's offset from
//! `CLOCK_MONOTONIC` once and adds it to every stamp, so converted stamps keep the monotonic
//! clock's spacing; a later step of the system clock (NTP) does not move them until the process
//! measures again (a restart).
//!
//! ```
//! use chassis_client::WallClock;
//!
//! let clock = WallClock::with_offset(1_700_000_000_000_000_000);
//! assert_eq!(clock.wall_ns(5_000_000_123), 1_700_000_005_000_000_123);
//! assert_eq!(clock.monotonic_ns(1_700_000_005_000_000_123), 5_000_000_123);
//! ```

/// `CLOCK_MONOTONIC` → Unix time, with the offset measured once.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WallClock {
    offset_ns: i128,
}

impl WallClock {
    /// Reads both clocks once: the system clock between two readings of `CLOCK_MONOTONIC`,
    /// whose middle it is taken to be at.
    // The one reading of the system clock a process makes, at start.
    #[allow(clippy::disallowed_methods)]
    pub fn measure() -> Self {
        let before = i128::from(crate::now_ns());
        let wall = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| i128::try_from(d.as_nanos()).unwrap_or(i128::MAX));
        let after = i128::from(crate::now_ns());
        Self::with_offset(wall - (before + after) / 2)
    }

    /// A clock `offset_ns` ahead of `CLOCK_MONOTONIC` (0: stamps stay monotonic time).
    pub const fn with_offset(offset_ns: i128) -> Self {
        Self { offset_ns }
    }

    /// How far Unix time is ahead of `CLOCK_MONOTONIC`, ns.
    pub fn offset_ns(self) -> i128 {
        self.offset_ns
    }

    /// The Unix time of the monotonic instant `monotonic_ns`, ns (0 before the epoch).
    pub fn wall_ns(self, monotonic_ns: u64) -> u64 {
        let ns = i128::from(monotonic_ns) + self.offset_ns;
        u64::try_from(ns.max(0)).unwrap_or(u64::MAX)
    }

    /// The monotonic instant of the Unix time `wall_ns`, ns (0 before the monotonic clock's
    /// start).
    pub fn monotonic_ns(self, wall_ns: u64) -> u64 {
        let ns = i128::from(wall_ns) - self.offset_ns;
        u64::try_from(ns.max(0)).unwrap_or(u64::MAX)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stamps_are_monotonic_time_plus_the_measured_offset() {
        let clock = WallClock::with_offset(1_700_000_000_000_000_000);
        assert_eq!(clock.wall_ns(5_000_000_123), 1_700_000_005_000_000_123);
        assert_eq!(clock.monotonic_ns(1_700_000_005_000_000_123), 5_000_000_123);
        // Before either clock's start: clamped, never wrapped.
        assert_eq!(WallClock::with_offset(-10).wall_ns(5), 0);
        assert_eq!(clock.monotonic_ns(0), 0);
        assert_eq!(WallClock::with_offset(0).wall_ns(42), 42);
    }

    #[test]
    fn the_measured_offset_makes_now_the_system_clocks_now() {
        #[allow(clippy::disallowed_methods)]
        let wall = || {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .unwrap()
                .as_nanos() as i128
        };
        let clock = WallClock::measure();
        let converted = i128::from(clock.wall_ns(crate::now_ns()));
        assert!((converted - wall()).abs() < 50_000_000, "{converted}");
    }
}
