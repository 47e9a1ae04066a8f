//! Where each microsecond goes: the command and state samples of a run split at the stamps
//! chassisd took inside the pass that served each (its pass trace, `CHASSIS_PASS_TRACE`). A
//! sample counts in every part or in none: one whose pass is not in the trace, or whose pass
//! did not take a stamp in between (a frame that was not the pass's first write), is left out,
//! and the parts say how many samples they hold.

use std::collections::HashMap;
use std::path::Path;

use anyhow::Context as _;
use serde::{Deserialize, Serialize};

use crate::stats::{Latencies, Summary};
use chassis_ipc::PassStamps;

/// Whose time a part is: what the targets can take out, and what bounds them on a machine.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Whose {
    /// The code this repository ships: chassisd's pass, a bridge's loop.
    Code,
    /// What that code calls or waits on: a wake-up, a system call, the transport, the peer.
    Outside,
}

/// One part of a path: from → to, whose time it is, its distribution.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Part {
    pub name: String,
    pub whose: Whose,
    pub summary: Summary,
}

/// The parts of one path, in the order a sample passes them, and each sample's parts of one
/// kind summed: a row's p99 is not the sum of its parts' p99s, and a few parts together can
/// miss a target that none of them misses alone.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Split {
    pub parts: Vec<Part>,
    /// Each sample's parts outside the code, together: what the sample would have taken had
    /// the code taken no time.
    pub outside: Summary,
    /// Each sample's parts of the code, together.
    pub code: Summary,
}

use Whose::{Code, Outside};

/// How many of a command split's parts, its last ([`command`]), lie within the in-service row
/// (request read → frame written): from the request read on.
pub const IN_SERVICE_COMMAND_PARTS: usize = 2;

/// Splits `names.len() + 1` stamps, each later than or at the one before, into the
/// distributions between consecutive stamps; a sample whose stamps are not in order is left out.
fn split(names: &[(&str, Whose)], samples: impl Iterator<Item = Vec<u64>>) -> Split {
    let mut parts: Vec<Latencies> = names.iter().map(|_| Latencies::new()).collect();
    let (mut outside, mut code) = (Latencies::new(), Latencies::new());
    for stamps in samples {
        let in_order = stamps.windows(2).all(|w| w[0] <= w[1]);
        if stamps.len() != names.len() + 1 || stamps.contains(&0) || !in_order {
            continue;
        }
        let (mut outside_ns, mut code_ns) = (0, 0);
        for ((part, w), &(_, whose)) in parts.iter_mut().zip(stamps.windows(2)).zip(names) {
            part.record_between(w[0], w[1]);
            match whose {
                Code => code_ns += w[1] - w[0],
                Outside => outside_ns += w[1] - w[0],
            }
        }
        outside.record(outside_ns);
        code.record(code_ns);
    }
    let parts = names.iter().zip(parts).map(|(&(name, whose), l)| Part {
        name: name.to_string(),
        whose,
        summary: l.summary(),
    });
    Split {
        parts: parts.collect(),
        outside: outside.summary(),
        code: code.summary(),
    }
}

/// Request created → the loop waiting again (the work of the passes under way when it was
/// created done) → the loop woke (a polling loop: its pass began) → the sources read → the first
/// write began → the frame written, for each `(request created, frame written)` sample whose
/// frame was its pass's first write. A boundary the request came after (the loop was waiting
/// already; a polling loop's pass was under way) is the request's creation: a part of 0.
pub fn command(samples: &[(u64, u64)], passes: &[PassStamps], polled: bool) -> Split {
    let traced = passes
        .iter()
        .filter(|p| p.written != 0 && p.waited_since != 0);
    let by_written: HashMap<u64, &PassStamps> = traced.map(|p| (p.written, p)).collect();
    let woke = match polled {
        true => "loop polling → pass began (the poll)",
        false => "loop waiting → loop woke (the wake-up)",
    };
    let read = match polled {
        true => "pass began → request read",
        false => "loop woke → request read",
    };
    let names = [
        (
            "request created → loop waiting (the passes under way)",
            Code,
        ),
        (woke, Outside),
        (read, Code),
        ("request read → write begun (mux, driver, encoding)", Code),
        (
            "write begun → frame written (the bus' write system call)",
            Outside,
        ),
    ];
    let stamps = samples.iter().filter_map(|&(created, written)| {
        let p = by_written.get(&written)?;
        let (waiting, woke) = (created.max(p.waited_since), created.max(p.woke));
        let (read, begun) = (p.requests_read, p.write_started);
        Some(vec![created, waiting, woke, read, begun, written])
    });
    split(&names, stamps)
}

/// The passes that handed a state and woke its readers, by the time they handed their first.
fn state_passes(passes: &[PassStamps]) -> Vec<&PassStamps> {
    let mut with_state: Vec<&PassStamps> = passes
        .iter()
        .filter(|p| p.state_handed != 0 && p.state_wake_begun != 0 && p.state_readers_woken != 0)
        .collect();
    with_state.sort_by_key(|p| p.state_handed);
    with_state
}

/// The last of `with_state` ([`state_passes`]) that handed a state at or before `handed`: the
/// sample's own pass when it was handed before that pass woke the readers (else its stamps are
/// out of order, and the split leaves it out).
fn pass_of<'a>(with_state: &[&'a PassStamps], handed: u64) -> Option<&'a PassStamps> {
    let after = with_state.partition_point(|p| p.state_handed <= handed);
    with_state.get(after.checked_sub(1)?).copied()
}

/// The notification of pass `p` as a reader that had its sample at `had` saw it: `[begun,
/// returned]`, each at most `had`. A reader that had the sample before the pass notified it (a
/// polling reader, or one awake already) spent nothing on the notification and a wake-up.
fn notification(p: &PassStamps, had: u64) -> [u64; 2] {
    [p.state_wake_begun.min(had), p.state_readers_woken.min(had)]
}

/// The parts of a state sample within chassisd's pass, up to its readers' notification.
const STATE_PASS: [(&str, Whose); 3] = [
    ("frame read → handed to iceoryx2 (decode, state)", Code),
    ("handed → notification begun (the rest of the pass)", Code),
    (
        "notification begun → returned (iceoryx2's notify: a system call a listener)",
        Outside,
    ),
];

/// Frame read → the sample handed to iceoryx2 → the state readers' notification begun at the
/// end of its pass → it returned → the reader has it, for each `(frame read, handed, received)`
/// sample handed within a pass of the trace (from the pass's first state handed to its readers
/// woken). A reader that had the sample before the pass notified it ([`notification`]): those
/// parts are 0, and the rest of the pass counts until the reader had it.
pub fn state(samples: &[(u64, u64, u64)], passes: &[PassStamps]) -> Split {
    let with_state = state_passes(passes);
    let mut names = STATE_PASS.to_vec();
    names.push((
        "notification returned → reader has it (its wake-up)",
        Outside,
    ));
    let stamps = samples.iter().filter_map(|&(read, handed, received)| {
        let [begun, woken] = notification(pass_of(&with_state, handed)?, received);
        Some(vec![read, handed, begun, woken, received])
    });
    split(&names, stamps)
}

/// The Python client's state samples as [`state`] splits the Rust client's, with the reader's
/// part in two: its wake-up (until the stream's listener returned), then the stream's reading
/// (iceoryx2's Python binding takes each sample, `ctypes` copies it out; the samples before it
/// in the same wake-up are read first). Each sample is `[frame read, handed, the stream's
/// wait returned, in hand]` (`bench.py`'s `state.stamps`). A sample whose notification came
/// while the stream was reading, or before it looked again, was read without a wake-up: that
/// part is 0 (and, as in [`state`], so are the notification's of one read before it).
pub fn python_state(samples: &[[u64; 4]], passes: &[PassStamps]) -> Split {
    let with_state = state_passes(passes);
    let mut names = STATE_PASS.to_vec();
    names.extend([
        (
            "notification returned → the stream's wait returned (its wake-up)",
            Outside,
        ),
        (
            "wait returned → sample in hand (the stream reads it and those before it, Python)",
            Code,
        ),
    ]);
    let stamps = samples
        .iter()
        .filter_map(|&[read, handed, returned, received]| {
            let [begun, woken] = notification(pass_of(&with_state, handed)?, received);
            let returned = returned.max(woken);
            Some(vec![read, handed, begun, woken, returned, received])
        });
    split(&names, stamps)
}

/// A bridge trace's lines by their first column (the frame's read time), the first line of each:
/// a later one carries the same frame again (a repeat, or a tick's refresh).
fn first_by_read(trace: &[[u64; 4]]) -> HashMap<u64, &[u64; 4]> {
    let mut by_read = HashMap::new();
    for t in trace {
        by_read.entry(t[0]).or_insert(t);
    }
    by_read
}

/// The parts of a bridge's sample from the frame's read until the bridge's loop woke with it
/// (`bridge`), then `rest`.
fn bridge_parts<'a>(bridge: &'a str, rest: &[(&'a str, Whose)]) -> Vec<(&'a str, Whose)> {
    let pass = "frame read → notification begun (chassisd: decode, state, the rest of the pass)";
    [&[(pass, Code), STATE_PASS[2], (bridge, Outside)], rest].concat()
}

/// `[frame read, notification begun, returned, bridge woke]` for a frame read at `read` that a
/// bridge's loop woke with at `woke`. The notification is the first of `with_state`
/// ([`state_passes`]) that began at or after the read: its own pass's, which publishes the
/// frame's state before it notifies (none: `None`). A bridge awake before the notification
/// (still at the samples before) spent nothing on it and on a wake-up, as a reader in [`state`].
fn to_bridge(with_state: &[&PassStamps], read: u64, woke: u64) -> Option<[u64; 4]> {
    let notifying = with_state.get(with_state.partition_point(|p| p.state_wake_begun < read))?;
    let [begun, woken] = notification(notifying, woke);
    Some([read, begun, woken, woke])
}

/// Frame read → chassisd's pass notified the state readers → the notification returned → the
/// bridge's state loop woke with the sample → the odom handed to RustDDS → the peer took it,
/// for each `(frame read, taken)` sample of the ROS 2 row whose odom is in the bridge's trace
/// (`[read, woke, write begun, written]` a line, joined on the frame's read time) and whose
/// frame is followed by a notification in chassisd's pass trace ([`to_bridge`]). The write's
/// return is not a boundary: on a shared CPU the peer often has the odom before the write
/// returns (RustDDS' sender and the peer ran in between).
pub fn odom(samples: &[(u64, u64)], trace: &[[u64; 4]], passes: &[PassStamps]) -> Split {
    let (by_read, with_state) = (first_by_read(trace), state_passes(passes));
    let names = bridge_parts(
        "notification returned → bridge woke (its wake-up)",
        &[
            ("bridge woke → odom handed to RustDDS (conversion)", Code),
            (
                "handed to RustDDS → taken by the peer (RustDDS' write and sender, UDP, Cyclone DDS)",
                Outside,
            ),
        ],
    );
    let stamps = samples.iter().filter_map(|&(read, taken)| {
        let t = by_read.get(&read)?;
        let mut stamps = to_bridge(&with_state, read, t[1])?.to_vec();
        stamps.extend([t[2], taken]);
        Some(stamps)
    });
    split(&names, stamps)
}

/// A bridge's trace of `format` ([`chassis_ipc::StampTrace`]).
pub fn read_trace<const N: usize>(
    path: &Path,
    format: chassis_ipc::Trace,
) -> anyhow::Result<Vec<[u64; N]>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    chassis_ipc::StampTrace::<N>::parse(&text, format)
        .with_context(|| format!("{}", path.display()))
}

/// Frame read → chassisd's pass notified the state readers → the notification returned → the
/// robot side's export loop woke with the sample → its put began → the operator side's Zenoh
/// callback had it → the mirror's loop took it → handed to iceoryx2 → the reader has it, for
/// each `(frame read, received)` sample of the Zenoh state row whose state is in both sides'
/// traces (chassis-zenoh's `CHASSIS_ZENOH_TRACE`, joined on the frame's read time: the robot
/// side's `[read, woke, put begun, put returned]`, the operator side's `[read, callback, taken,
/// handed]`) and whose frame is followed by a notification in chassisd's pass trace (as in
/// [`odom`]). The put's return is not a boundary, as the odom's write is not.
pub fn zenoh_state(
    samples: &[(u64, u64)],
    export: &[[u64; 4]],
    mirror: &[[u64; 4]],
    passes: &[PassStamps],
) -> Split {
    let (export, mirror) = (first_by_read(export), first_by_read(mirror));
    let with_state = state_passes(passes);
    let names = bridge_parts(
        "notification returned → export woke (its wake-up)",
        &[
            ("export woke → put begun (the newest of the wake-up)", Code),
            (
                "put begun → operator's callback (Zenoh: put, TCP over the veth, its runtime)",
                Outside,
            ),
            ("callback → mirror's loop took it (channel hand-off)", Code),
            ("taken → handed to iceoryx2 (decode, link watch)", Code),
            ("handed to iceoryx2 → reader has it (iceoryx2)", Outside),
        ],
    );
    let stamps = samples.iter().filter_map(|&(read, received)| {
        let (e, m) = (export.get(&read)?, mirror.get(&read)?);
        let mut stamps = to_bridge(&with_state, read, e[1])?.to_vec();
        stamps.extend([e[2], m[1], m[2], m[3], received]);
        Some(stamps)
    });
    split(&names, stamps)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each part's p50 in whole µs (the histogram keeps 3 significant digits) and its count.
    fn p50s(split: &Split) -> Vec<(u64, u64)> {
        split
            .parts
            .iter()
            .map(|p| (p.summary.p50_us as u64, p.summary.count))
            .collect()
    }

    /// A pass that handed its first state at `handed` and notified the state readers from
    /// `begun` to `woken`.
    fn notifying(handed: u64, begun: u64, woken: u64) -> PassStamps {
        PassStamps {
            state_handed: handed,
            state_wake_begun: begun,
            state_readers_woken: woken,
            ..PassStamps::default()
        }
    }

    /// A pass whose loop began waiting at 1.04 ms, woke at `woke` and read, encoded and wrote a
    /// request's frame by 1.06 ms.
    fn pass_woken_at(woke: u64) -> [PassStamps; 1] {
        [PassStamps {
            waited_since: 1_040_000,
            woke,
            requests_read: 1_052_000,
            write_started: 1_055_000,
            written: 1_060_000,
            ..PassStamps::default()
        }]
    }

    #[test]
    fn a_command_sample_is_split_at_its_passes_stamps_and_one_without_its_pass_is_left_out() {
        // Created at 1 ms: the loop was busy until 1.04 ms, woke at 1.05.
        let samples = [(1_000_000, 1_060_000), (2_000_000, 2_100_000)];
        let split = command(&samples, &pass_woken_at(1_050_000), false);
        assert_eq!(
            p50s(&split),
            vec![(40, 1), (10, 1), (2, 1), (3, 1), (5, 1)],
            "{split:?}"
        );
        assert_eq!(split.parts[0].whose, Whose::Code);
        assert_eq!(split.parts[1].whose, Whose::Outside);
        // Created while the loop waited: nothing of it was the loop's previous work.
        let split = command(&[(1_045_000, 1_060_000)], &pass_woken_at(1_050_000), false);
        assert_eq!(
            p50s(&split),
            vec![(0, 1), (5, 1), (2, 1), (3, 1), (5, 1)],
            "{split:?}"
        );
    }

    #[test]
    fn each_samples_parts_outside_the_code_and_in_it_are_summed_together() {
        // 10 µs of wake-up and 5 of write outside; 40 + 2 + 3 µs of the code.
        let [first] = pass_woken_at(1_050_000);
        // Woken 1 µs after the request, written 13 µs after its write began: 14 µs outside.
        let second = PassStamps {
            waited_since: 2_040_000,
            woke: 2_041_000,
            requests_read: 2_043_000,
            write_started: 2_044_000,
            written: 2_057_000,
            ..PassStamps::default()
        };
        let samples = [(1_000_000, 1_060_000), (2_040_000, 2_057_000)];
        let split = command(&samples, &[first, second], false);
        let max_us = |s: &Summary| s.max_us.round() as u64;
        // Alone, the wake-up's longest is 10 µs and the write's 13; no sample had both.
        assert_eq!(max_us(&split.parts[1].summary), 10, "{split:?}");
        assert_eq!(max_us(&split.parts[4].summary), 13, "{split:?}");
        assert_eq!(max_us(&split.outside), 15, "{split:?}");
        assert_eq!(max_us(&split.code), 45, "{split:?}");
        assert_eq!((split.outside.count, split.code.count), (2, 2));
        // A sample left out of the parts is left out of the sums.
        let split = command(&[(3_000_000, 3_100_000)], &[first], false);
        assert_eq!((split.outside.count, split.code.count), (0, 0));
    }

    #[test]
    fn the_in_service_row_holds_the_command_splits_parts_from_the_request_read_on() {
        for polled in [false, true] {
            let split = command(&[], &pass_woken_at(1_050_000), polled);
            let from = split.parts.len() - IN_SERVICE_COMMAND_PARTS;
            let within: Vec<&str> = split.parts[from..]
                .iter()
                .map(|p| p.name.as_str())
                .collect();
            assert_eq!(
                within,
                [
                    "request read → write begun (mux, driver, encoding)",
                    "write begun → frame written (the bus' write system call)"
                ],
                "polled: {polled}"
            );
        }
    }

    #[test]
    fn a_polling_loops_pass_under_way_before_the_request_counts_from_the_request() {
        // The pass began (1.049 ms) before the request (1.05 ms) and read it at 1.052.
        let split = command(&[(1_050_000, 1_060_000)], &pass_woken_at(1_049_000), true);
        assert_eq!(
            p50s(&split),
            vec![(0, 1), (0, 1), (2, 1), (3, 1), (5, 1)],
            "{split:?}"
        );
        // A pass without the loop's wait (the service's first) is left out.
        let mut first = pass_woken_at(1_049_000);
        first[0].waited_since = 0;
        let split = command(&[(1_050_000, 1_060_000)], &first, true);
        assert!(
            split.parts.iter().all(|p| p.summary.count == 0),
            "{split:?}"
        );
    }

    #[test]
    fn an_odom_sample_is_split_at_the_bridges_stamps_and_one_not_in_its_trace_is_left_out() {
        // The second line repeats the first's read time: a later odom, not the one taken.
        let trace = [
            [1_000_000, 1_070_000, 1_085_000, 1_600_000],
            [1_000_000, 9_000_000, 9_100_000, 9_200_000],
        ];
        // The frame's pass notified at 1.040-1.050 ms; a pass before it (notified at 0.9 ms)
        // is not the frame's.
        let passes = [
            notifying(880_000, 900_000, 910_000),
            notifying(1_010_000, 1_040_000, 1_050_000),
        ];
        let split = odom(
            &[(1_000_000, 1_500_000), (2_000_000, 2_600_000)],
            &trace,
            &passes,
        );
        // Taken before the write returned (1.6 ms): counted all the same.
        assert_eq!(
            p50s(&split),
            vec![(40, 1), (10, 1), (20, 1), (15, 1), (415, 1)],
            "{split:?}"
        );
    }

    #[test]
    fn an_odom_taken_by_a_bridge_awake_before_the_notification_spent_nothing_on_it() {
        let trace = [[1_000_000, 1_030_000, 1_045_000, 1_100_000]];
        let passes = [notifying(1_010_000, 1_040_000, 1_050_000)];
        let split = odom(&[(1_000_000, 1_500_000)], &trace, &passes);
        assert_eq!(
            p50s(&split),
            vec![(30, 1), (0, 1), (0, 1), (15, 1), (455, 1)],
            "{split:?}"
        );
        // A frame read after its pass handed its first state belongs to that pass all the same.
        let later = [[1_020_000, 1_060_000, 1_075_000, 1_100_000]];
        let split = odom(&[(1_020_000, 1_500_000)], &later, &passes);
        assert_eq!(
            p50s(&split),
            vec![(20, 1), (10, 1), (10, 1), (15, 1), (425, 1)],
            "{split:?}"
        );
        // No notification after the frame's read: left out.
        let split = odom(&[(1_000_000, 1_500_000)], &trace, &passes[..0]);
        assert!(
            split.parts.iter().all(|p| p.summary.count == 0),
            "{split:?}"
        );
    }

    #[test]
    fn a_state_sample_counts_within_its_pass_and_one_outside_every_pass_is_left_out() {
        let passes = [
            PassStamps {
                state_handed: 110,
                state_sent: 120,
                state_wake_begun: 140,
                state_readers_woken: 150,
                ..PassStamps::default()
            },
            notifying(300, 380, 400),
        ];
        // The pass's second sample (handed at 130) counts; one handed at 200 belongs to no pass.
        let split = state(
            &[(100, 130, 190), (180, 200, 290), (250, 300, 450)],
            &passes,
        );
        assert!(
            split.parts.iter().all(|p| p.summary.count == 2),
            "{split:?}"
        );
        // The rest of the pass (300 → 380) and the notification (380 → 400) apart.
        assert_eq!(split.parts[1].summary.max_us, 0.08, "{split:?}");
        assert_eq!(split.parts[2].summary.max_us, 0.02, "{split:?}");
        // A polling reader had the sample at 350, before the pass notified its readers (380):
        // no notification, no wake-up; the pass's rest until then.
        let split = state(&[(250, 300, 350)], &passes);
        let max_10ns: Vec<u64> = split
            .parts
            .iter()
            .map(|p| (p.summary.max_us * 1e2).round() as u64)
            .collect();
        assert_eq!(max_10ns, [5, 5, 0, 0], "{split:?}");
        assert!(
            split.parts.iter().all(|p| p.summary.count == 1),
            "{split:?}"
        );
    }

    #[test]
    fn a_python_state_sample_splits_the_readers_part_at_its_waits_return() {
        let passes = [notifying(110, 140, 150)];
        // Woken at 190; the second sample was read at once after the first, without a wake-up
        // of its own, its notification having come while the stream read (its wait returned
        // before the notification: a part of 0).
        let split = python_state(&[[100, 110, 190, 230], [105, 120, 145, 260]], &passes);
        let max_ns: Vec<u64> = split
            .parts
            .iter()
            .map(|p| (p.summary.max_us * 1e3).round() as u64)
            .collect();
        assert_eq!(max_ns, [15, 30, 10, 40, 110], "{split:?}");
        assert!(
            split.parts.iter().all(|p| p.summary.count == 2),
            "{split:?}"
        );
        assert_eq!(split.parts[3].whose, Whose::Outside);
        assert_eq!(split.parts[4].whose, Whose::Code);
        // Read at 135, before the pass notified its readers (140): the parts after it are 0
        // (recorded as 1 ns, the histogram's least value).
        let split = python_state(&[[105, 120, 125, 135]], &passes);
        let max_ns: Vec<u64> = split
            .parts
            .iter()
            .map(|p| (p.summary.max_us * 1e3).round() as u64)
            .collect();
        assert_eq!(max_ns, [15, 15, 1, 1, 1], "{split:?}");
        // A sample handed before every traced pass is left out.
        let split = python_state(&[[10, 20, 190, 230]], &passes);
        assert!(
            split.parts.iter().all(|p| p.summary.count == 0),
            "{split:?}"
        );
    }

    #[test]
    fn a_zenoh_state_is_split_at_both_sides_stamps_and_one_missing_from_a_side_is_left_out() {
        let export = [[1_000_000, 1_010_000, 1_012_000, 1_030_000]];
        let mirror = [
            [1_000_000, 1_020_000, 1_050_000, 1_051_000],
            [2_000_000, 2_020_000, 2_050_000, 2_051_000],
        ];
        // The frame's pass notified at 1.004-1.006 ms.
        let passes = [notifying(1_002_000, 1_004_000, 1_006_000)];
        let samples = [(1_000_000, 1_100_000), (2_000_000, 2_100_000)];
        let split = zenoh_state(&samples, &export, &mirror, &passes);
        assert_eq!(
            p50s(&split),
            vec![
                (4, 1),
                (2, 1),
                (4, 1),
                (2, 1),
                (8, 1),
                (30, 1),
                (1, 1),
                (49, 1)
            ],
            "{split:?}"
        );
        // Without a notification after the frame's read in chassisd's trace: left out.
        let split = zenoh_state(&samples, &export, &mirror, &[]);
        assert!(
            split.parts.iter().all(|p| p.summary.count == 0),
            "{split:?}"
        );
    }
}
