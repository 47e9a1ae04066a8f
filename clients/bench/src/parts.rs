//! Where each microsecond goes: the command and state samples of a run split at the stamps
//! chassisd took inside the pass that served each (its pass trace, `CHASSIS_PASS_TRACE`). A
//! sample counts in every part or in none: one whose pass is not in the trace, or whose pass
//! did not take a stamp in between (the frame was not the pass's first write), is left out, and
//! the parts say how many samples they hold.

use std::collections::HashMap;

use crate::paths::PassStamps;
use crate::stats::{Latencies, Summary};

/// The parts of one path, in the order a sample passes them: (from → to, distribution).
pub type Split = Vec<(String, Summary)>;

/// Splits `parts.len()` stamps, each later than or at the one before, into the distributions
/// between consecutive stamps; a sample whose stamps are not in order is left out.
fn split(names: &[&str], samples: impl Iterator<Item = Vec<u64>>) -> Split {
    let mut parts: Vec<Latencies> = names.iter().map(|_| Latencies::new()).collect();
    for stamps in samples {
        if stamps.len() != names.len() + 1
            || stamps.contains(&0)
            || stamps.windows(2).any(|w| w[1] < w[0])
        {
            continue;
        }
        for (part, w) in parts.iter_mut().zip(stamps.windows(2)) {
            part.record_between(w[0], w[1]);
        }
    }
    names
        .iter()
        .zip(parts)
        .map(|(name, l)| ((*name).to_string(), l.summary()))
        .collect()
}

/// Request created → the loop woke → the sources read → the first write began → the frame
/// written, for each `(request created, frame written)` sample whose frame was its pass's first
/// write.
pub fn command(samples: &[(u64, u64)], passes: &[PassStamps]) -> Split {
    let by_written: HashMap<u64, &PassStamps> = passes
        .iter()
        .filter(|p| p.written != 0)
        .map(|p| (p.written, p))
        .collect();
    split(
        &[
            "request created → loop woke",
            "loop woke → request read",
            "request read → write begun (mux, driver, encoding)",
            "write begun → frame written",
        ],
        samples.iter().filter_map(|&(created, written)| {
            let p = by_written.get(&written)?;
            Some(vec![
                created,
                p.woke,
                p.requests_read,
                p.write_started,
                written,
            ])
        }),
    )
}

/// Frame read → the sample handed to iceoryx2 → its send returned → the state readers woken →
/// the reader has it, for each `(frame read, handed, received)` sample that was its pass's first
/// state.
pub fn state(samples: &[(u64, u64, u64)], passes: &[PassStamps]) -> Split {
    let by_handed: HashMap<u64, &PassStamps> = passes
        .iter()
        .filter(|p| p.state_handed != 0)
        .map(|p| (p.state_handed, p))
        .collect();
    split(
        &[
            "frame read → handed to iceoryx2 (decode, state)",
            "handed → sent",
            "sent → readers woken (the rest of the pass)",
            "readers woken → reader has it",
        ],
        samples.iter().filter_map(|&(read, handed, received)| {
            let p = by_handed.get(&handed)?;
            Some(vec![
                read,
                handed,
                p.state_sent,
                p.state_readers_woken,
                received,
            ])
        }),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_command_sample_is_split_at_its_passes_stamps_and_one_without_its_pass_is_left_out() {
        let passes = [PassStamps {
            woke: 1_050_000,
            requests_read: 1_052_000,
            write_started: 1_055_000,
            written: 1_060_000,
            ..PassStamps::default()
        }];
        let split = command(&[(1_000_000, 1_060_000), (2_000_000, 2_100_000)], &passes);
        // Whole µs (the histogram keeps 3 significant digits).
        let us: Vec<(u64, u64)> = split
            .iter()
            .map(|(_, s)| (s.p50_us as u64, s.count))
            .collect();
        assert_eq!(us, vec![(50, 1), (2, 1), (3, 1), (5, 1)], "{split:?}");
    }

    #[test]
    fn a_state_sample_whose_pass_took_no_stamp_in_between_is_left_out_of_every_part() {
        let passes = [
            PassStamps {
                state_handed: 110,
                state_sent: 120,
                state_readers_woken: 150,
                ..PassStamps::default()
            },
            PassStamps {
                state_handed: 210,
                ..PassStamps::default()
            },
        ];
        let split = state(&[(100, 110, 190), (200, 210, 290)], &passes);
        assert!(split.iter().all(|(_, s)| s.count == 1), "{split:?}");
    }
}
