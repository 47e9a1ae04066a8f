//! [`Decimator`]: at most one sample per period, judged on the samples' own stamps — what a
//! bridge publishes of a stream faster than its other side wants (a browser keeps up with 50 Hz
//! of state, a JSON twin needs 10 Hz).
//!
//! ```
//! use std::time::Duration;
//! use chassis_client::Decimator;
//!
//! let mut d = Decimator::new(Duration::from_millis(20));
//! // A sample every 4 ms for 10 s: 50 a second pass.
//! let passed = (0..2500u64).filter(|i| d.pass(i * 4_000_000)).count();
//! assert!((500..=501).contains(&passed));
//! ```

use std::time::Duration;

/// Lets at most one sample per period through on average, judged on the samples' own stamps,
/// with a quarter period of slack for the jitter of whoever reads them (a sample 19.5 ms after
/// the last one of a 20 ms period passes; the next one is then due 40 ms after the first). A
/// period of zero lets every sample through.
#[derive(Debug, Clone, Copy)]
pub struct Decimator {
    period_ns: u64,
    next_ns: Option<u64>,
}

impl Decimator {
    /// One sample per `period`.
    pub fn new(period: Duration) -> Self {
        Self {
            period_ns: u64::try_from(period.as_nanos()).unwrap_or(u64::MAX),
            next_ns: None,
        }
    }

    /// `hz` samples per second; `hz` ≤ 0 (or not a number): every sample.
    pub fn per_second(hz: f64) -> Self {
        if hz > 0.0 && hz.is_finite() {
            Self::new(Duration::from_secs_f64(1.0 / hz))
        } else {
            Self::new(Duration::ZERO)
        }
    }

    /// True when the sample stamped `stamp_ns` is to be passed on.
    pub fn pass(&mut self, stamp_ns: u64) -> bool {
        if self.period_ns == 0 {
            return true;
        }
        let slack = self.period_ns / 4;
        if let Some(next) = self.next_ns
            && stamp_ns.saturating_add(slack) < next
        {
            return false;
        }
        let after_stamp = stamp_ns.saturating_add(self.period_ns - slack);
        self.next_ns = Some(self.next_ns.map_or(after_stamp, |next| {
            next.saturating_add(self.period_ns).max(after_stamp)
        }));
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn passed(period_ms: u64, samples: impl Iterator<Item = u64>) -> usize {
        let mut d = Decimator::new(Duration::from_millis(period_ms));
        samples.filter(|&t| d.pass(t)).count()
    }

    #[test]
    fn samples_are_decimated_to_the_period_on_average() {
        // A sample every 4 ms for 10 s: 50 Hz out.
        let n = passed(20, (0..2500).map(|i| i * 4_000_000));
        assert!((499..=501).contains(&n), "{n}");
        // Samples every 10 ms, read with ±1 ms of jitter: still every other one.
        let jitter = |i: u64| if i.is_multiple_of(2) { 0 } else { 1_000_000 };
        let n = passed(20, (0..1000).map(|i| i * 10_000_000 + jitter(i)));
        assert!((499..=501).contains(&n), "{n}");
        // A 20 ms source a little early now and then loses nothing.
        let n = passed(
            20,
            (0..500u64).map(|i| i * 20_000_000 - if i.is_multiple_of(3) { 0 } else { 400_000 }),
        );
        assert_eq!(n, 500);
        // Slower samples all pass.
        assert_eq!(passed(20, (0..100).map(|i| i * 50_000_000)), 100);
    }

    #[test]
    fn a_rate_in_hertz_passes_that_many_and_zero_passes_every_sample() {
        let mut ten = Decimator::per_second(10.0);
        let n = (0..100u64).filter(|i| ten.pass(i * 10_000_000)).count();
        assert!((10..=11).contains(&n), "{n}");
        for hz in [0.0, -1.0, f64::NAN] {
            let mut every = Decimator::per_second(hz);
            assert!((0..5).chain([3, 3, 0]).all(|t| every.pass(t)), "{hz}");
        }
    }
}
