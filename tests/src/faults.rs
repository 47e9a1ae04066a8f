//! What the fault tests (`faults_bus.rs`, `faults_processes.rs`, `faults_clients.rs`) share: the
//! machine lock that keeps timing measurements apart, the frame tap drained into memory, the
//! pump that keeps a client driving while a test waits, and the heartbeat's measures.

use std::sync::{RwLock, RwLockReadGuard, RwLockWriteGuard};
use std::time::{Duration, Instant};

use crate::{
    BusFrame, ChassisState, Figure, FrameDirection, FrameTap, MuxStatus, Robot, Source,
    SourceStatus, Spread, Tmux, VelocityRequest, drove_again_after,
};

/// How long a robot that must stand is watched, the fewest states it must report meanwhile,
/// and the speed below which it stands.
pub use crate::{MIN_STOOD_SAMPLES, STANDING_MPS, STOOD_FOR};

/// The tests that measure timing under load take this exclusively; the others share it, so the
/// heartbeat and the request accounting are measured without a second test beside them (within
/// one test binary: cargo runs the binaries one after another).
static MACHINE: RwLock<()> = RwLock::new(());

/// A share of the machine: other sharing tests run beside this one.
pub fn shared() -> RwLockReadGuard<'static, ()> {
    MACHINE.read().unwrap_or_else(|e| e.into_inner())
}

/// The machine alone: no other test of this binary runs meanwhile.
pub fn exclusive() -> RwLockWriteGuard<'static, ()> {
    MACHINE.write().unwrap_or_else(|e| e.into_inner())
}

pub use crate::name;

/// Nanoseconds as milliseconds.
/// The largest of `values`: NaN when there are none or one is NaN (`f64::max` would drop it),
/// so a row whose figure was not measured fails its bound instead of passing on nothing.
pub fn worst(values: &[f64]) -> f64 {
    if values.is_empty() || values.iter().any(|v| v.is_nan()) {
        return f64::NAN;
    }
    values.iter().copied().fold(f64::NEG_INFINITY, f64::max)
}

pub fn ms(ns: i128) -> f64 {
    ns as f64 / 1e6
}

/// The status of source `name` in `m`.
pub fn source_status<'m>(m: &'m MuxStatus, name: &str) -> &'m SourceStatus {
    m.sources()
        .iter()
        .find(|s| s.name() == name)
        .unwrap_or_else(|| panic!("no source {name}"))
}

/// One row of `faults.jsonl`: `fault` as `test` of test file `suite` injected it, what the
/// system did, the figure measured (in words, and its main number) and the test's verdict on it
/// (written as passing only if the test gets to its end: [`crate::Figures`]).
#[allow(clippy::too_many_arguments)]
pub fn fault_figure(
    suite: &str,
    test: &str,
    rank: u32,
    fault: &str,
    injection: &str,
    behaviour: &str,
    figure: String,
    value: f64,
    pass: bool,
) -> Figure {
    Figure {
        rank,
        fault: fault.into(),
        injection: injection.into(),
        behaviour: behaviour.into(),
        figure,
        value,
        pass,
        suite: suite.into(),
        test: test.into(),
    }
}

/// A TITAN 0x111 frame that asks for motion (its speed bytes are not zero).
pub fn is_titan_motion(f: &BusFrame) -> bool {
    f.direction == FrameDirection::TX && f.can_id == 0x111 && f.payload()[..2] != [0, 0]
}

/// The frame tap, drained into memory, with its sequence gaps counted.
pub struct Wire {
    tap: FrameTap,
    pub frames: Vec<BusFrame>,
    last_seq: u64,
    /// Frames the tap lost (sequence gaps) since it was opened.
    pub lost: u64,
}

impl std::fmt::Debug for Wire {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Wire")
            .field("frames", &self.frames.len())
            .field("last_seq", &self.last_seq)
            .field("lost", &self.lost)
            .finish()
    }
}

impl Wire {
    pub fn new(robot: &Robot) -> Self {
        Self {
            tap: robot
                .frames(2048)
                .unwrap_or_else(|e| panic!("frame tap: {e}")),
            frames: Vec::new(),
            last_seq: 0,
            lost: 0,
        }
    }

    /// Takes every frame the tap has.
    pub fn pump(&mut self) {
        let (frames, last_seq, lost) = (&mut self.frames, &mut self.last_seq, &mut self.lost);
        self.tap
            .drain(|f| {
                if *last_seq != 0 && f.seq > *last_seq + 1 {
                    *lost += f.seq - *last_seq - 1;
                }
                *last_seq = f.seq;
                frames.push(*f);
            })
            .unwrap_or_else(|e| panic!("frame tap: {e}"));
    }

    /// Forgets the frames read so far (the gap count stays).
    pub fn clear(&mut self) {
        self.pump();
        self.frames.clear();
    }

    /// The last frame that commanded motion, ns (`None`: the tap holds none, and a bound on
    /// it must fail rather than pass on nothing).
    pub fn last_motion_ns(&self) -> Option<u64> {
        self.frames
            .iter()
            .filter(|f| is_titan_motion(f))
            .map(|f| f.stamp_ns)
            .max()
    }

    /// How many frames that commanded motion the tap holds.
    pub fn motion_frames(&self) -> usize {
        self.frames.iter().filter(|f| is_titan_motion(f)).count()
    }

    /// The stamps of the TX 0x111 frames read, ns.
    pub fn heartbeats(&self) -> Vec<u64> {
        self.frames
            .iter()
            .filter(|f| f.direction == FrameDirection::TX && f.can_id == 0x111)
            .map(|f| f.stamp_ns)
            .collect()
    }
}

/// What a client test keeps doing while it waits: its own requests every 20 ms, keys into a
/// terminal, the tap drained.
#[allow(missing_debug_implementations)]
pub struct Pump<'a> {
    pub teleop: Option<(&'a mut Source, VelocityRequest)>,
    pub tmux: Option<&'a Tmux>,
    pub wire: &'a mut Wire,
    pub last: Instant,
}

impl<'a> Pump<'a> {
    /// Sends `request` on `source` every 20 ms (the first at once) while it waits.
    pub fn new(source: &'a mut Source, request: VelocityRequest, wire: &'a mut Wire) -> Self {
        Self {
            teleop: Some((source, request)),
            tmux: None,
            wire,
            last: Instant::now() - Duration::from_secs(1),
        }
    }

    /// Sends what is due, drains the tap.
    pub fn tick(&mut self) {
        if self.last.elapsed() >= Duration::from_millis(20) {
            if let Some((source, request)) = self.teleop.as_mut() {
                source
                    .send(*request)
                    .unwrap_or_else(|e| panic!("sending: {e}"));
            }
            if let Some(tmux) = self.tmux {
                // A terminal's auto-repeat of a held key.
                tmux.try_send("w");
            }
            self.last = Instant::now();
        }
        self.wire.pump();
    }

    /// Pumps for `d`.
    pub fn run(&mut self, robot: &mut Robot, d: Duration) {
        let end = Instant::now() + d;
        while Instant::now() < end {
            self.tick();
            let _ = robot.wait_mux(Duration::from_millis(5));
        }
    }

    /// Pumps until `condition` holds on the newest mux status and state (or `timeout`).
    pub fn until(
        &mut self,
        robot: &mut Robot,
        timeout: Duration,
        mut condition: impl FnMut(&MuxStatus, &ChassisState) -> bool,
    ) -> Option<Duration> {
        let start = Instant::now();
        while start.elapsed() < timeout {
            self.tick();
            let _ = robot.wait_mux(Duration::from_millis(5));
            if let (Ok(Some(m)), Ok(Some(s))) = (robot.latest_mux(), robot.latest_state())
                && condition(&m, &s)
            {
                return Some(start.elapsed());
            }
        }
        None
    }

    /// Pumps for `d` and reads every state the chassis reported meanwhile with a speed measured
    /// after `since_ns` ([`crate::stands`]).
    pub fn stands(&mut self, robot: &mut Robot, since_ns: u64, d: Duration) -> (usize, f64) {
        crate::stands(robot, since_ns, d, || self.tick())
    }

    /// [`drove_again_after`] `since_ns`, pumping meanwhile.
    pub fn drove_again(
        &mut self,
        robot: &mut Robot,
        since_ns: u64,
        timeout: Duration,
        condition: impl FnMut(&ChassisState) -> bool,
    ) -> Option<(ChassisState, Duration)> {
        drove_again_after(robot, since_ns, timeout, || self.tick(), condition)
    }
}

/// CPU time of process `pid` so far (user + system), clock ticks.
pub fn cpu_ticks(pid: i32) -> u64 {
    stat_ticks(&format!("/proc/{pid}/stat"))
}

/// CPU time of the main thread of process `pid` so far (chassisd's event loop), clock ticks.
pub fn main_thread_cpu_ticks(pid: i32) -> u64 {
    stat_ticks(&format!("/proc/{pid}/task/{pid}/stat"))
}

/// User + system time in a `stat` file of `/proc`, clock ticks.
fn stat_ticks(path: &str) -> u64 {
    let stat = std::fs::read_to_string(path).unwrap_or_default();
    // Fields after the command name (which may hold spaces): utime and stime are 14 and 15.
    let fields: Vec<&str> = stat
        .rsplit(')')
        .next()
        .unwrap_or("")
        .split_whitespace()
        .collect();
    let field = |i: usize| {
        fields
            .get(i)
            .and_then(|v| v.parse::<u64>().ok())
            .unwrap_or(0)
    };
    field(11) + field(12)
}

/// Clock ticks a second (`sysconf(_SC_CLK_TCK)`).
pub fn ticks_per_second() -> f64 {
    nix::unistd::sysconf(nix::unistd::SysconfVar::CLK_TCK)
        .ok()
        .flatten()
        .map_or(100.0, |t| t as f64)
}

/// The TITAN's heartbeat (0x111) period.
pub const HEARTBEAT_PERIOD: Duration = Duration::from_millis(20);

/// How far before the grid's estimated slot a frame may come and still serve that slot (with
/// lateness 0): the estimate is the frames' most common position within the period, and under
/// load the loop's typical lateness (which puts it there) varies by a millisecond or so, while
/// chassisd never sends a heartbeat before its slot.
pub const SLOT_EARLY: Duration = Duration::from_millis(2);

/// Lateness of each slot of the heartbeat's fixed grid between `start_ns` and `end_ns`, ms: how
/// long after the slot the first 0x111 from [`SLOT_EARLY`] before it on came (0 when before
/// it); a slot with none left before `end_ns` is late by the rest of the window: a heartbeat
/// that stopped is a growing lateness, not a shorter list. Command changes send extra 0x111
/// frames between slots; the grid's phase is the most common position of the frames within the
/// period, less the typical 0.2 ms of lateness.
pub fn slot_lateness(stamps: &[u64], start_ns: u64, end_ns: u64, period: Duration) -> Vec<f64> {
    let period = u64::try_from(period.as_nanos()).unwrap_or(u64::MAX).max(1);
    let mut sorted: Vec<u64> = stamps
        .iter()
        .copied()
        .filter(|t| (start_ns..=end_ns).contains(t))
        .collect();
    sorted.sort_unstable();
    let Some(phase) = grid_phase(&sorted, period) else {
        return Vec::new();
    };
    // The first slot after the window opened, then every slot with a full period left.
    let mut slot = phase + (start_ns.saturating_sub(phase) / period + 1) * period;
    let early = u64::try_from(SLOT_EARLY.as_nanos()).unwrap_or(0);
    let mut late = Vec::new();
    let mut i = 0;
    while slot + period <= end_ns {
        while i < sorted.len() && sorted[i] < slot.saturating_sub(early) {
            i += 1;
        }
        let next = sorted.get(i).copied().unwrap_or(end_ns);
        late.push(next.saturating_sub(slot) as f64 / 1e6);
        slot += period;
    }
    late
}

/// The grid of `sorted` stamps: a slot time (ns) on it, at or before the first stamp.
fn grid_phase(sorted: &[u64], period: u64) -> Option<u64> {
    const BIN: u64 = 50_000;
    let &first = sorted.first()?;
    // Phase: the 50 µs bin holding most frames.
    let mut bins = vec![0u32; usize::try_from(period / BIN).unwrap_or(1).max(1)];
    let last_bin = bins.len() - 1;
    for t in sorted {
        let bin = usize::try_from(((t - first) % period) / BIN).unwrap_or(last_bin);
        bins[bin.min(last_bin)] += 1;
    }
    // The first of the fullest bins.
    let best = bins
        .iter()
        .enumerate()
        .max_by_key(|(i, n)| (**n, std::cmp::Reverse(*i)))
        .map_or(0, |(i, _)| i as u64);
    // A slot's frame leaves a little after the slot: the bin holds the typical lateness.
    Some(
        (first + best * BIN)
            .saturating_sub(200_000)
            .saturating_sub(period),
    )
}

/// The heartbeat of a run held against its clock: one 0x111 per period from the start of the
/// window to its end, none missed, none missing at the end. Pure: fed the stamps a tap reader
/// saw, so its verdict is tested on made-up lists (`soak.rs` uses it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeartbeatCheck {
    /// Slots of the grid with a full period inside the window: the heartbeats expected.
    pub expected: u64,
    /// Slots whose heartbeat came before the next slot (less than a period late).
    pub served: u64,
    /// Slots that may go unserved: [`HeartbeatCheck::TOLERANCE_PER_MILLE`] of `expected`, at
    /// least 1.
    pub tolerance: u64,
    /// 0x111 frames in the window (command changes add frames between slots).
    pub frames: u64,
    /// Longest time without a 0x111, the window's start and end included, ms.
    pub longest_gap_ms: f64,
    /// From the last 0x111 to the end of the window, ms.
    pub gap_to_end_ms: f64,
    /// The bound of both gaps, ms: two periods (a gap that long is a missed heartbeat).
    pub gap_bound_ms: f64,
}

impl HeartbeatCheck {
    /// Slots per thousand that may be served a period late or more (the loop woke that late
    /// once: the gap bound still holds it to less than two periods).
    pub const TOLERANCE_PER_MILLE: u64 = 1;

    /// The check of `stamps` (0x111 stamps, ns, any order) over the window `start_ns..end_ns`.
    pub fn of(stamps: &[u64], start_ns: u64, end_ns: u64, period: Duration) -> Self {
        let mut inside: Vec<u64> = stamps
            .iter()
            .copied()
            .filter(|t| (start_ns..=end_ns).contains(t))
            .collect();
        inside.sort_unstable();
        let late = slot_lateness(&inside, start_ns, end_ns, period);
        let period_ms = period.as_secs_f64() * 1e3;
        let whole = end_ns.saturating_sub(start_ns);
        let per = u64::try_from(period.as_nanos()).unwrap_or(u64::MAX).max(1);
        // Without a frame there is no grid: every full period of the window is a slot missed.
        let expected = if inside.is_empty() {
            whole / per
        } else {
            late.len() as u64
        };
        let served = late.iter().filter(|l| **l < period_ms).count() as u64;
        let mut edges = Vec::with_capacity(inside.len() + 2);
        edges.push(start_ns);
        edges.extend(&inside);
        edges.push(end_ns);
        let longest = edges
            .windows(2)
            .map(|w| w[1].saturating_sub(w[0]))
            .max()
            .unwrap_or(whole);
        let gap_to_end = end_ns.saturating_sub(inside.last().copied().unwrap_or(start_ns));
        Self {
            expected,
            served,
            tolerance: (expected * Self::TOLERANCE_PER_MILLE / 1000).max(1),
            frames: inside.len() as u64,
            longest_gap_ms: longest as f64 / 1e6,
            gap_to_end_ms: gap_to_end as f64 / 1e6,
            gap_bound_ms: 2.0 * period_ms,
        }
    }

    /// Every slot served but the tolerance, no gap of two periods, the end included, and at
    /// least one heartbeat.
    pub fn pass(&self) -> bool {
        self.expected > 0
            && self.served > 0
            && self.served + self.tolerance >= self.expected
            && self.longest_gap_ms < self.gap_bound_ms
            && self.gap_to_end_ms < self.gap_bound_ms
    }
}

/// The spread of the 0x111 periods in `stamps`, and the share within ±2 ms of `period`, %.
pub fn heartbeat_spread(stamps: &[u64], period: Duration) -> (Spread, f64) {
    let period_ms = period.as_secs_f64() * 1e3;
    let mut sorted = stamps.to_vec();
    sorted.sort_unstable();
    let spread = Spread::of_gaps(&sorted);
    let within = sorted
        .windows(2)
        .filter(|w| ((w[1] - w[0]) as f64 / 1e6 - period_ms).abs() <= 2.0)
        .count();
    let share = 100.0 * within as f64 / sorted.len().saturating_sub(1).max(1) as f64;
    (spread, share)
}

#[cfg(test)]
mod tests {
    use super::*;

    const P: Duration = Duration::from_millis(20);
    const START: u64 = 1_000_000_000;
    /// One second of window.
    const END: u64 = START + 1_000_000_000;

    /// A heartbeat every 20 ms from `from` (ns after START) to `to`, 0.2 ms after each slot,
    /// `jitter` ns added to every odd one.
    fn beats(from: u64, to: u64, jitter: u64) -> Vec<u64> {
        (0..)
            .map(|k| START + 5_000_000 + 200_000 + k * 20_000_000)
            .take_while(|t| *t < START + to)
            .filter(|t| *t >= START + from)
            .enumerate()
            .map(|(i, t)| if i % 2 == 1 { t + jitter } else { t })
            .collect()
    }

    #[test]
    fn a_steady_heartbeat_over_the_whole_window_passes() {
        let check = HeartbeatCheck::of(&beats(0, 1_000_000_000, 3_000_000), START, END, P);
        assert!(check.pass(), "{check:?}");
        assert_eq!(check.expected, 49, "{check:?}");
        assert_eq!(check.served, check.expected);
        assert!(check.gap_to_end_ms < 20.0, "{check:?}");
    }

    #[test]
    fn no_heartbeat_at_all_fails() {
        let check = HeartbeatCheck::of(&[], START, END, P);
        assert!(!check.pass(), "{check:?}");
        assert_eq!((check.expected, check.served, check.frames), (50, 0, 0));
        assert_eq!(check.gap_to_end_ms, 1000.0);
    }

    #[test]
    fn a_heartbeat_that_stops_for_good_before_the_end_fails() {
        // Regular for 900 ms, then nothing for the last 100 ms: every gap between frames is
        // fine, only the gap to the end shows it.
        let check = HeartbeatCheck::of(&beats(0, 900_000_000, 0), START, END, P);
        assert!(!check.pass(), "{check:?}");
        assert!(check.gap_to_end_ms > 90.0, "{check:?}");
        assert!(check.served + check.tolerance < check.expected, "{check:?}");
    }

    #[test]
    fn a_heartbeat_that_starts_late_fails() {
        let check = HeartbeatCheck::of(&beats(100_000_000, 1_000_000_000, 0), START, END, P);
        assert!(!check.pass(), "{check:?}");
        assert!(check.longest_gap_ms > 100.0, "{check:?}");
    }

    #[test]
    fn one_missed_heartbeat_fails_and_extra_frames_elsewhere_do_not_make_up_for_it() {
        let mut stamps = beats(0, 1_000_000_000, 0);
        stamps.remove(20);
        // Command changes: extra frames in other slots.
        stamps.extend([START + 101_000_000, START + 333_000_000]);
        let check = HeartbeatCheck::of(&stamps, START, END, P);
        assert_eq!(check.frames, 51);
        assert_eq!((check.expected, check.served), (49, 48), "{check:?}");
        assert!(!check.pass(), "{check:?}");
        assert_eq!(check.longest_gap_ms, 40.0, "{check:?}");
    }

    #[test]
    fn a_command_frame_in_a_slot_whose_heartbeat_is_missing_serves_it() {
        // Any 0x111 resets the TITAN's command timeout: a command change 9 ms into the slot
        // is that slot's frame.
        let mut stamps = beats(0, 1_000_000_000, 0);
        let missing = stamps.remove(20);
        stamps.push(missing + 9_000_000);
        let check = HeartbeatCheck::of(&stamps, START, END, P);
        assert!(check.pass(), "{check:?}");
        assert_eq!(check.served, check.expected);
    }

    #[test]
    fn a_heartbeat_at_half_its_rate_fails_on_its_count() {
        // Every 39 ms: no gap reaches two periods, but half the slots go unserved.
        let stamps: Vec<u64> = (0..26)
            .map(|k| START + 1_000_000 + k * 39_000_000)
            .collect();
        let check = HeartbeatCheck::of(&stamps, START, END, P);
        assert!(check.longest_gap_ms < check.gap_bound_ms, "{check:?}");
        assert!(!check.pass(), "{check:?}");
        assert!(check.served < check.expected * 2 / 3, "{check:?}");
    }

    #[test]
    fn frames_outside_the_window_do_not_count() {
        let mut stamps = beats(0, 500_000_000, 0);
        // The same heartbeat, but measured before the window opened and after it closed.
        stamps.extend([START - 10_000_000, END + 10_000_000]);
        let check = HeartbeatCheck::of(&stamps, START, END, P);
        assert!(!check.pass(), "{check:?}");
        assert!(check.gap_to_end_ms > 490.0, "{check:?}");
    }

    #[test]
    fn a_heartbeat_whose_lateness_varies_under_load_is_served_every_slot() {
        // Most frames 1 ms after their slot, some 0.1 ms: the estimated phase (the common
        // position, less 0.2 ms) is after the early ones, which still serve their slots.
        let stamps: Vec<u64> = (0..50)
            .map(|k| {
                let late = if k % 4 == 3 { 100_000 } else { 1_000_000 };
                START + 5_000_000 + k * 20_000_000 + late
            })
            .collect();
        let check = HeartbeatCheck::of(&stamps, START, END, P);
        assert!(check.pass(), "{check:?}");
        assert_eq!(check.served, check.expected, "{check:?}");
        let late = slot_lateness(&stamps, START, END, P);
        assert!(late.iter().all(|l| *l < 1.0), "{late:?}");
    }

    #[test]
    fn slot_lateness_counts_a_stopped_heartbeat_as_late_to_the_end() {
        let late = slot_lateness(&beats(0, 500_000_000, 0), START, END, P);
        assert_eq!(late.len(), 49);
        assert!(late[..20].iter().all(|l| *l < 1.0), "{late:?}");
        assert!(late[30..].iter().all(|l| *l >= 20.0), "{late:?}");
    }
}
