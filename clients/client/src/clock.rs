//! Stamps for other protocols: every stamp in the system is `CLOCK_MONOTONIC`; ROS 2 and
//! Foxglove want Unix time. [`WallClock`] measures the system clock's offset from
//! `CLOCK_MONOTONIC` once and adds it to every stamp, so converted stamps keep the monotonic
//! clock's spacing; a later step of the system clock (NTP) does not move them until the process
//! measures again (a restart).
//!
//! [`PeerClock`] does the same for another computer's `CLOCK_MONOTONIC`, which cannot be read
//! here: it is measured by round trips (this side's send and receive times around the other's
//! reading, as NTP does), so that a stamp made there is known here to within half the fastest
//! recent round trip.
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

/// Round trips [`PeerClock`] keeps to choose from.
pub const PEER_CLOCK_SAMPLES: usize = 16;

/// Another computer's `CLOCK_MONOTONIC` as seen from here, from round trips: this side sends at
/// `sent_ns`, the other reads its clock (`peer_ns`) and answers, the answer arrives at
/// `received_ns`. The other's reading was made between the two, so it is taken to be at their
/// middle, give or take half the round trip. Of the last [`PEER_CLOCK_SAMPLES`] round trips the
/// fastest is used (a round trip slowed by a queue on either way says the least).
///
/// ```
/// use chassis_client::PeerClock;
///
/// let mut peer = PeerClock::default();
/// // Sent at 1.000 s here, read 5.000 s there, answered at 1.010 s here: 3.995 s ahead ± 5 ms.
/// peer.record(1_000_000_000, 5_000_000_000, 1_010_000_000);
/// assert_eq!(peer.local_ns(5_100_000_000), Some((1_105_000_000, 5_000_000)));
/// ```
#[derive(Debug, Clone, Default)]
pub struct PeerClock {
    /// (offset of the peer's clock from this one, ns; half the round trip, ns), newest last.
    samples: std::collections::VecDeque<(i128, u64)>,
}

impl PeerClock {
    /// Takes one round trip. One whose answer came before it was sent is ignored.
    pub fn record(&mut self, sent_ns: u64, peer_ns: u64, received_ns: u64) {
        let Some(rtt) = received_ns.checked_sub(sent_ns) else {
            return;
        };
        let middle = i128::from(sent_ns) + i128::from(rtt / 2);
        if self.samples.len() == PEER_CLOCK_SAMPLES {
            self.samples.pop_front();
        }
        self.samples
            .push_back((i128::from(peer_ns) - middle, rtt.div_ceil(2)));
    }

    /// The offset of the peer's clock from this one and its uncertainty (half the fastest
    /// round trip), ns; `None` before the first round trip.
    pub fn offset(&self) -> Option<(i128, u64)> {
        self.samples.iter().copied().min_by_key(|&(_, half)| half)
    }

    /// This computer's `CLOCK_MONOTONIC` at the instant the peer's clock read `peer_ns`, and the
    /// uncertainty of it, ns; `None` before the first round trip.
    pub fn local_ns(&self, peer_ns: u64) -> Option<(u64, u64)> {
        let (offset, uncertainty) = self.offset()?;
        let local = (i128::from(peer_ns) - offset).max(0);
        Some((u64::try_from(local).unwrap_or(u64::MAX), uncertainty))
    }

    /// How old, ns, a message stamped `peer_ns` by the peer is when it arrives here at `now_ns`,
    /// giving it the benefit of the doubt (the uncertainty is taken off); `None` before the
    /// first round trip. A stamp from the future is 0 old.
    pub fn age_ns(&self, peer_ns: u64, now_ns: u64) -> Option<u64> {
        let (local, uncertainty) = self.local_ns(peer_ns)?;
        Some(now_ns.saturating_sub(local).saturating_sub(uncertainty))
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

    #[test]
    fn the_peer_clock_is_read_from_the_fastest_round_trip() {
        let mut peer = PeerClock::default();
        assert_eq!(peer.offset(), None);
        assert_eq!(peer.age_ns(0, 0), None);
        // The peer's clock is 7 s ahead. A slow round trip (queued one way: 80 ms out, 2 ms
        // back) misjudges it by 39 ms, within its ±41 ms.
        peer.record(1_000_000_000, 8_080_000_000, 1_082_000_000);
        let (offset, half) = peer.offset().unwrap();
        assert_eq!((offset, half), (7_039_000_000, 41_000_000));
        // A fast one (1 ms each way) takes over.
        peer.record(2_000_000_000, 9_001_000_000, 2_002_000_000);
        assert_eq!(peer.offset(), Some((7_000_000_000, 1_000_000)));
        // A request stamped there at 10.0 s arrives here at 3.3 s: made at 3.0 s here, 299 ms
        // old at least.
        assert_eq!(
            peer.local_ns(10_000_000_000),
            Some((3_000_000_000, 1_000_000))
        );
        assert_eq!(
            peer.age_ns(10_000_000_000, 3_300_000_000),
            Some(299_000_000)
        );
        // From the future (clocks within the uncertainty): not old at all.
        assert_eq!(peer.age_ns(10_500_000_000, 3_300_000_000), Some(0));
        // An answer before its question is not a round trip.
        peer.record(5, 0, 4);
        assert_eq!(peer.offset(), Some((7_000_000_000, 1_000_000)));
        // Only the last PEER_CLOCK_SAMPLES count: the fast one ages out.
        for i in 0..PEER_CLOCK_SAMPLES as u64 {
            let t = 10_000_000_000 + i * 1_000_000_000;
            peer.record(t, t + 7_000_000_000 + 10_000_000, t + 20_000_000);
        }
        assert_eq!(peer.offset(), Some((7_000_000_000, 10_000_000)));
    }
}
