//! Latency histograms (HDR, nanoseconds) and their summaries.

use hdrhistogram::Histogram;
use hdrhistogram::serialization::{Deserializer, Serializer, V2Serializer};
use serde::{Deserialize, Serialize};

/// One-way latencies of one path, ns; in a samples file, a [`Stored`].
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(into = "Stored", try_from = "Stored")]
pub struct Latencies {
    histogram: Histogram<u64>,
    /// Samples outside the histogram's range (negative or above 60 s): counted, not recorded.
    pub out_of_range: u64,
}

impl Default for Latencies {
    /// 1 ns to 60 s with 3 significant digits (bounds the histogram always takes).
    fn default() -> Self {
        let histogram = Histogram::new_with_bounds(1, 60_000_000_000, 3);
        let histogram = histogram.unwrap_or_else(|_| std::process::abort());
        Self {
            histogram,
            out_of_range: 0,
        }
    }
}

impl Latencies {
    pub fn new() -> Self {
        Self::default()
    }

    /// Records `later − earlier` (both `CLOCK_MONOTONIC` ns).
    pub fn record_between(&mut self, earlier: u64, later: u64) {
        match later.checked_sub(earlier) {
            Some(ns) => self.record(ns),
            None => self.out_of_range += 1,
        }
    }

    pub fn record(&mut self, ns: u64) {
        if self.histogram.record(ns.max(1)).is_err() {
            self.out_of_range += 1;
        }
    }

    pub fn count(&self) -> u64 {
        self.histogram.len()
    }

    /// How many latencies recorded are longer than `ns` (to the histogram's 3 significant
    /// digits).
    pub fn count_above(&self, ns: u64) -> u64 {
        let h = &self.histogram;
        match ns < h.max() {
            true => h.count_between(ns + 1, h.max()),
            false => 0,
        }
    }

    pub fn merge(&mut self, other: &Latencies) {
        let _ = self.histogram.add(&other.histogram);
        self.out_of_range += other.out_of_range;
    }

    pub fn summary(&self) -> Summary {
        let h = &self.histogram;
        let us = |ns: u64| ns as f64 / 1000.0;
        let q = |q: f64| us(h.value_at_quantile(q));
        Summary {
            count: h.len(),
            mean_us: h.mean() / 1000.0,
            p50_us: q(0.50),
            p90_us: q(0.90),
            p99_us: q(0.99),
            p999_us: q(0.999),
            max_us: us(h.max()),
            out_of_range: self.out_of_range,
        }
    }

    /// (latency µs, cumulative fraction) points of the distribution, for plots.
    pub fn cdf(&self) -> Vec<(f64, f64)> {
        let h = &self.histogram;
        let total = h.len().max(1) as f64;
        let points = h.iter_recorded().scan(0, |seen, v| {
            *seen += v.count_since_last_iteration();
            let us = h.highest_equivalent(v.value_iterated_to()) as f64 / 1000.0;
            Some((us, *seen as f64 / total))
        });
        points.collect()
    }
}

/// How [`Latencies`] is written in a samples file: the histogram in HdrHistogram's V2 format
/// as hex, and the count out of its range.
#[derive(Serialize, Deserialize)]
struct Stored {
    v2_hex: String,
    out_of_range: u64,
}

impl From<Latencies> for Stored {
    fn from(l: Latencies) -> Self {
        let mut bytes = Vec::new();
        let _ = V2Serializer::new().serialize(&l.histogram, &mut bytes);
        let (v2_hex, out_of_range) = (hex::encode(bytes), l.out_of_range);
        Stored {
            v2_hex,
            out_of_range,
        }
    }
}

impl TryFrom<Stored> for Latencies {
    type Error = &'static str;

    fn try_from(stored: Stored) -> Result<Self, Self::Error> {
        let bytes = hex::decode(&stored.v2_hex).map_err(|_| "a histogram that is not hex")?;
        let histogram = Deserializer::new().deserialize(&mut &bytes[..]);
        let histogram = histogram.map_err(|_| "a histogram that is not HdrHistogram V2")?;
        Ok(Self {
            histogram,
            out_of_range: stored.out_of_range,
        })
    }
}

/// Percentiles of one path, µs.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
pub struct Summary {
    pub count: u64,
    pub mean_us: f64,
    pub p50_us: f64,
    pub p90_us: f64,
    pub p99_us: f64,
    pub p999_us: f64,
    pub max_us: f64,
    pub out_of_range: u64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn latencies_longer_than_a_bound_are_counted() {
        let mut l = Latencies::new();
        for ns in [5_000, 25_000, 150_000] {
            l.record(ns);
        }
        assert_eq!(l.count_above(20_000), 2);
        assert_eq!(l.count_above(100_000), 1);
        assert_eq!(l.count_above(200_000), 0);
    }

    #[test]
    fn percentiles_of_a_known_distribution() {
        let mut l = Latencies::new();
        for us in 1..=1000u64 {
            l.record(us * 1000);
        }
        let s = l.summary();
        assert_eq!(s.count, 1000);
        assert!((s.p50_us - 500.0).abs() < 1.0, "{s:?}");
        assert!((s.p99_us - 990.0).abs() < 1.5, "{s:?}");
        assert!((s.max_us - 1000.0).abs() < 1.0, "{s:?}");
    }

    #[test]
    fn histograms_survive_serialization_and_merge() {
        let mut a = Latencies::new();
        a.record(5_000);
        let json = serde_json::to_string(&a).unwrap();
        let mut b: Latencies = serde_json::from_str(&json).unwrap();
        b.record(7_000);
        assert_eq!(b.count(), 2);
        a.merge(&b);
        assert_eq!(a.count(), 3);
    }

    #[test]
    fn a_clock_going_backwards_is_counted_not_recorded() {
        let mut l = Latencies::new();
        l.record_between(10, 5);
        assert_eq!((l.count(), l.out_of_range), (0, 1));
        let cdf = {
            l.record_between(5, 10);
            l.cdf()
        };
        assert_eq!(cdf.last().map(|p| p.1), Some(1.0));
    }
}
