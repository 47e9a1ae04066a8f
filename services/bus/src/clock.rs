//! The one clock of the process: `CLOCK_MONOTONIC`, system-wide, in nanoseconds.
//!
//! Only the loops that own the clock call [`now`] — chassisd's shell, the simulator's runner,
//! `chassisd sim`, the replay player and the conformance suite timing a real bus — each opting in
//! where `clippy.toml` forbids it elsewhere; everything else (the engine, the mux, the drivers)
//! takes time as a parameter. Every sample the service publishes carries this clock, so another
//! process on the machine computes one-way latency by reading the same clock.

use chassis_protocols::Timestamp;
use nix::time::{ClockId, clock_gettime};

/// The current `CLOCK_MONOTONIC` time.
pub fn now() -> Timestamp {
    // CLOCK_MONOTONIC cannot fail on Linux; a zero keeps the caller going if it ever did.
    clock_gettime(ClockId::CLOCK_MONOTONIC).map_or(Timestamp::ZERO, |t| {
        let ns = i128::from(t.tv_sec()) * 1_000_000_000 + i128::from(t.tv_nsec());
        Timestamp::from_nanos(u64::try_from(ns).unwrap_or(0))
    })
}

/// The wall clock (`CLOCK_REALTIME`), ns since the Unix epoch: only for what must outlive the
/// machine's monotonic clock (the held locks on disk).
pub fn unix_ns() -> u64 {
    clock_gettime(ClockId::CLOCK_REALTIME).map_or(0, |t| {
        let ns = i128::from(t.tv_sec()) * 1_000_000_000 + i128::from(t.tv_nsec());
        u64::try_from(ns).unwrap_or(0)
    })
}

#[cfg(test)]
#[allow(clippy::disallowed_methods)] // the clock's own test reads it
mod tests {
    #[test]
    fn the_clock_moves_forward() {
        let a = super::now();
        let b = super::now();
        assert!(a.as_nanos() > 0 && b >= a);
    }
}
