//! What the machine takes from a thread that never blocks: a thread pinned to one CPU reads
//! `CLOCK_MONOTONIC` in a loop and records every gap between two readings longer than
//! [`MIN_GAP_NS`] (an interrupt, the timer's tick, a virtual CPU the host did not run). Every
//! path and hop pays them too: a part of a path that takes 5 µs at the p50 and 150 µs at the p99
//! met one. The rows say how often and how long, on each CPU.

use std::time::Duration;

use chassis_client::now_ns;

use crate::placement;
use crate::stats::Latencies;

/// Shortest gap recorded: a loop of clock readings takes well under 100 ns a turn.
const MIN_GAP_NS: u64 = 1_000;

/// A burst of spinning, then a pause: a thread at SCHED_FIFO that never sleeps is stopped by
/// the kernel's real-time throttling (`kernel.sched_rt_runtime_us`, 950 ms of every second)
/// for the rest of each second, a gap that is the throttling's, not the machine's.
const BURST: Duration = Duration::from_millis(200);
const PAUSE: Duration = Duration::from_millis(100);

/// The gaps seen on one CPU.
#[derive(Debug)]
pub struct Stalls {
    /// Every gap longer than [`MIN_GAP_NS`], ns.
    pub gaps: Latencies,
    /// Time spent reading the clock.
    pub spinning: Duration,
    /// The SCHED_FIFO priority the thread ran at; `None`: normal scheduling (refused).
    pub fifo: Option<u8>,
}

impl Stalls {
    /// Gaps longer than `us` a second of spinning.
    pub fn per_second(&self, us: u64) -> f64 {
        self.gaps.count_above(us * 1000) as f64 / self.spinning.as_secs_f64().max(1e-9)
    }

    /// The row's conditions.
    pub fn conditions(&self, cpu: usize) -> String {
        let scheduling = match self.fifo {
            Some(p) => format!("at SCHED_FIFO {p} as the service's loop"),
            None => "at normal scheduling (SCHED_FIFO was refused)".into(),
        };
        format!(
            "a thread pinned to CPU {cpu} {scheduling} reading CLOCK_MONOTONIC in a loop for \
             {:.1} s (bursts of {} ms, under the kernel's real-time throttling), every gap \
             between two readings over {} µs: {:.1} a second over 20 µs, {:.1} over 50 µs, {:.2} \
             over 100 µs",
            self.spinning.as_secs_f64(),
            BURST.as_millis(),
            MIN_GAP_NS / 1000,
            self.per_second(20),
            self.per_second(50),
            self.per_second(100),
        )
    }
}

/// Spins `bursts` bursts on `cpu` in a thread of its own, at SCHED_FIFO `priority` when the
/// system grants it.
pub fn measure(cpu: usize, bursts: u64, priority: u8) -> anyhow::Result<Stalls> {
    let spin = move || {
        placement::pin_current_thread(cpu)?;
        let fifo = placement::set_fifo(priority).ok().map(|()| priority);
        let (mut gaps, mut spinning) = (Latencies::new(), Duration::ZERO);
        for _ in 0..bursts {
            let start = now_ns();
            let end = start + placement::nanos(BURST);
            let mut previous = start;
            while previous < end {
                let now = now_ns();
                let gap = now.saturating_sub(previous);
                if gap > MIN_GAP_NS {
                    gaps.record(gap);
                }
                previous = now;
            }
            spinning += Duration::from_nanos(previous - start);
            placement::pause(PAUSE);
        }
        Ok(Stalls {
            gaps,
            spinning,
            fifo,
        })
    };
    let thread = std::thread::spawn(spin).join();
    thread.map_err(|_| anyhow::anyhow!("the stall thread panicked"))?
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_short_spin_counts_its_gaps_and_their_rates() {
        let stalls = measure(0, 1, 80).unwrap();
        assert!(stalls.spinning >= BURST, "{stalls:?}");
        // Every gap over 20 µs is a gap recorded.
        assert!(
            stalls.gaps.count_above(20_000) <= stalls.gaps.count(),
            "{stalls:?}"
        );
        let text = stalls.conditions(0);
        assert!(text.starts_with("a thread pinned to CPU 0 at "), "{text}");
        assert!(text.contains("a second over 20 µs"), "{text}");
    }
}
