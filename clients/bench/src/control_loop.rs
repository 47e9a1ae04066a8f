//! The loop robot software runs against a chassis: a controller (a ros2_control hardware
//! interface, say) that on each period of its clock reads the newest state and writes a command,
//! here over the client library. How often it misses its period, how late each period's
//! command reaches the bus, and how old the state it reads is — beside the same loop over the
//! raw iceoryx2 hop ([`crate::baseline::Rounds::Loop`]).

use std::path::Path;
use std::time::Duration;

use chassis_client::{BusFrame, Robot, now_ns};
use chassis_protocols::RobotKind;

use crate::baseline::{self, Transport};
use crate::paths::{self, LoopMode, Motion, ServiceConfig, stamped};
use crate::placement::{Periods, Placement};
use crate::report::{Leg, LoopRun, PathKind, Report, Row};
use crate::stats::Latencies;

/// What one run of the loop measured.
#[derive(Debug)]
pub struct LoopFigures {
    pub periods: u64,
    /// Periods that ended after the next one was due.
    pub misses: u64,
    /// A loop that writes commands: each period's start → the frame carrying its command
    /// written, and the periods whose command no frame carried (the next period's reached the
    /// loop first).
    pub command: Option<(Latencies, u64)>,
    /// The newest state's frame read → the loop read it, each period.
    pub state_age: Latencies,
}

/// The speed period `k` commands: 0.05 to 1 m/s in steps of 0.05, exact on every wire (whole
/// mm/s, whole percent of 5 m/s), so that every command is a change and its frame tells which
/// period it carries.
fn speed(k: u64) -> f32 {
    (k % 20 + 1) as f32 / 20.0
}

/// Runs the loop for `periods` periods of `period` on `robot` (after a warm-up): each period, the
/// newest state read ([`Robot::latest_state`]) and, with `drive`, a command written on `teleop`,
/// the frame tap (a [`Motion`] of `kind`, polled with `spin`) drained without waiting.
pub fn measure(
    robot: &mut Robot,
    (kind, spin, drive): (RobotKind, bool, bool),
    period: Duration,
    periods: u64,
) -> anyhow::Result<LoopFigures> {
    let mut commands = None;
    if drive {
        let (mut motion, mut teleop) = (Motion::open(robot, kind, spin)?, robot.source("teleop")?);
        motion.warm_up(&mut teleop)?;
        commands = Some((motion, teleop));
    }
    // The motion frames written: their stamps and speeds.
    let mut frames: Vec<(u64, f64)> = Vec::new();
    let mut take = |motion: &mut Motion, wait: bool| {
        let decoder = &mut motion.decoder;
        let each = |f: &BusFrame| frames.extend(decoder.linear(f).map(|v| (f.stamp_ns, v)));
        match wait {
            true => motion.tap.wait(Duration::from_millis(10), each),
            false => motion.tap.drain(each),
        }
    };
    let mut sent: Vec<(u64, u64, f64)> = Vec::with_capacity(usize::try_from(periods)?);
    let mut state_age = Latencies::new();
    let mut clock = Periods::new(period);
    for k in 0..periods {
        let due = clock.next();
        if let Some(state) = robot.latest_state()? {
            state_age.record_between(state.stamp_ns, now_ns());
        }
        if let Some((motion, teleop)) = commands.as_mut() {
            let (speed, stamp) = (speed(k), now_ns());
            teleop.send(stamped(stamp, speed))?;
            take(motion, false)?;
            sent.push((due, stamp, f64::from(speed)));
        }
        clock.end(due, true);
    }
    let mut command = None;
    if let Some((mut motion, mut teleop)) = commands {
        // The last periods' frames.
        let until = now_ns() + 100_000_000;
        while now_ns() < until {
            take(&mut motion, true)?;
        }
        teleop.stop()?;
        command = Some(match_frames(&sent, &frames));
    }
    let misses = clock.misses;
    Ok(LoopFigures {
        periods,
        misses,
        command,
        state_age,
    })
}

/// Each period's command (its start, when it was sent, its speed) matched to the first frame
/// written after it that commands its speed, before a frame commands another period's; frames
/// repeating the previous command (the service's tick) are passed over.
fn match_frames(sent: &[(u64, u64, f64)], frames: &[(u64, f64)]) -> (Latencies, u64) {
    let same = |a: f64, b: f64| (a - b).abs() < 1e-6;
    let mut latencies = Latencies::new();
    let mut superseded = 0;
    let mut i = 0;
    for (k, &(due, stamp, speed)) in sent.iter().enumerate() {
        let previous = k.checked_sub(1).map(|p| sent[p].2);
        while frames.get(i).is_some_and(|&(at, v)| {
            at < stamp || previous.is_some_and(|p| same(v, p) && !same(v, speed))
        }) {
            i += 1;
        }
        match frames.get(i) {
            Some(&(at, v)) if same(v, speed) => {
                latencies.record_between(due, at);
                i += 1;
            }
            _ => superseded += 1,
        }
    }
    (latencies, superseded)
}

/// The loops a run measures: 1 kHz and, but in a smoke run, 100 Hz, over the TITAN on the
/// simulated bus, cross CPU, with chassisd's event loop and, but in a smoke run, its polling
/// loop (a smoke run checks the rows, and the 1 kHz event loop has every kind of them).
pub fn plan(smoke: bool) -> Vec<(Duration, LoopMode)> {
    let (ms, modes) = (Duration::from_millis, [LoopMode::Event, LoopMode::Spin]);
    let all = modes
        .into_iter()
        .flat_map(|mode| [(ms(1), mode), (ms(10), mode)]);
    all.take(if smoke { 1 } else { 4 }).collect()
}

/// `1 kHz`, `100 Hz`.
fn rate(period: Duration) -> String {
    let hz = 1.0 / period.as_secs_f64();
    if hz >= 1000.0 {
        format!("{} kHz", hz / 1000.0)
    } else {
        format!("{hz} Hz")
    }
}

/// The rows of a loop of `period` over `run` (robot and bus) whose raw hop is `transport`:
/// (its period → frame, its state's age, the raw loop's period → ping).
pub fn row_names(run: &str, period: Duration, transport: Transport) -> [String; 3] {
    let (rate, raw) = (rate(period), transport.label());
    [
        format!("{run}, a loop at {rate}: period → its command's frame"),
        format!("{run}, a loop at {rate}: the state's age when read"),
        format!("{raw}, a loop at {rate}: period → its ping received"),
    ]
}

/// How many periods of `period` a loop of `seconds` runs.
pub fn periods(period: Duration, seconds: f64) -> u64 {
    (seconds / period.as_secs_f64()).round() as u64
}

/// Runs each loop of `loops` for `seconds` over a chassisd of its own (the TITAN on the simulated
/// bus, the latency runs' configuration, cross CPU), then the same loop over the raw iceoryx2
/// hop that waits as chassisd's loop does, and adds their rows and figures to `report`.
pub fn run(
    loops: &[(Duration, LoopMode)],
    seconds: f64,
    prefix: &str,
    dir: &Path,
    report: &mut Report,
) -> anyhow::Result<()> {
    let (kind, placement) = (RobotKind::Titan, Placement::CrossCpu);
    for &(period, mode) in loops {
        let (spec, config) = (
            (kind, paths::BusKind::Sim, mode),
            ServiceConfig::BenchRealtime,
        );
        let cpu = placement.cpus().1;
        let (service, mut robot) = paths::start(spec, cpu, config, false, prefix, dir)?;
        let run = format!("{kind} sim");
        let realtime = service.scheduling.fifo();
        let over = Over {
            run,
            kind,
            mode,
            placement: Some(placement),
            realtime,
        };
        let measured = over.measure(&mut robot, period, seconds, true)?;
        // The raw loop runs alone.
        drop((robot, service));
        over.record(measured, period, (prefix, dir), report)?;
    }
    Ok(())
}

/// The chassisd a loop runs over: robot and bus (`run`), its loop `mode` and scheduling, where
/// the loop and chassisd are pinned (none: where the system puts them).
pub struct Over {
    pub run: String,
    pub kind: RobotKind,
    pub mode: LoopMode,
    pub placement: Option<Placement>,
    pub realtime: Option<u8>,
}

impl Over {
    pub fn at(&self) -> &'static str {
        self.placement.map_or(crate::UNPINNED, Placement::label)
    }

    /// Runs a loop of `period` over `robot` for `seconds`, writing commands with `drive`: what
    /// it measured and the chassis' feedback rate meanwhile.
    pub fn measure(
        &self,
        robot: &mut Robot,
        period: Duration,
        seconds: f64,
        drive: bool,
    ) -> anyhow::Result<(LoopFigures, f64)> {
        let cpu = self.placement.and_then(|p| p.cpus().0);
        let count = periods(period, seconds);
        let feedback = paths::FeedbackRate::start(robot)?;
        let how = (self.kind, self.mode == LoopMode::Spin, drive);
        let figures = paths::pinned(cpu, || measure(robot, how, period, count))??;
        Ok((figures, feedback.per_second(robot)?))
    }

    /// Adds the rows and figures of a loop of `period` to `report`, measuring the same loop over
    /// the raw iceoryx2 hop, its receiver living as chassisd's loop did: woken by another
    /// process at the chassis' feedback rate, by its own tick, scheduled alike.
    pub fn record(
        &self,
        (figures, feed_per_s): (LoopFigures, f64),
        period: Duration,
        (prefix, dir): (&str, &Path),
        report: &mut Report,
    ) -> anyhow::Result<()> {
        let (run, at, mode, count) = (&self.run, self.at(), self.mode.arg(), figures.periods);
        // The raw loop is the bench's own pair of processes: across two CPUs, as the service's
        // and the client's in a simulated run.
        let (cpus, raw_at) = (Placement::CrossCpu.cpus(), Placement::CrossCpu.label());
        let tick = self.kind.entry().defaults().heartbeat_period();
        let realtime = self.realtime;
        let load = baseline::Load {
            feed_per_s,
            tick,
            realtime,
            published: false,
        };
        let transport = Transport::like(self.mode);
        let shape = baseline::Rounds::Loop(period);
        let raw = baseline::run(transport, cpus, count, shape, Some(load), prefix, dir)?;
        let [frame, age, hop] = row_names(run, period, transport);
        let row =
            |leg, what, l, missed| Row::new(PathKind::Loop, leg, run, what, mode, at, l, missed);
        let superseded = figures.command.as_ref().map_or(0, |c| c.1);
        if let Some((l, superseded)) = figures.command {
            let mut frame_row = row(Leg::PeriodToFrame, frame, l, superseded);
            // Compared with the raw loop only where both ran alike: a chassisd the run did not
            // place (an attached robot's) is not.
            frame_row.baseline = self.placement.map(|_| format!("{hop}, {raw_at}"));
            report.rows.push(frame_row);
        }
        report
            .rows
            .push(row(Leg::StateAge, age, figures.state_age, 0));
        let fifo = load.fifo_text();
        let conditions = format!(
            "a loop on absolute deadlines sending one ping at the start of each period, \
             looking for the answers without waiting; the receiver woken {feed_per_s:.0}/s \
             by another process, as by the simulated chassis, and by its own {} ms \
             tick{fifo}; {count} periods after 200 of warm-up",
            tick.as_millis(),
        );
        let mut hop = Row::hop(run, hop, raw_at, raw.all_pings(), conditions);
        // The pings the receiver lost.
        hop.missed = count.saturating_sub(raw.pings.len() as u64);
        report.rows.push(hop);
        report.loops.push(LoopRun {
            run: run.clone(),
            rate: rate(period),
            mode: mode.into(),
            placement: at.into(),
            periods: figures.periods,
            misses: figures.misses,
            superseded,
            raw_transport: transport.label().into(),
            raw_periods: count,
            raw_misses: raw.missed_periods,
        });
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_periods_speeds_are_the_wires_exact_values() {
        let wire = [
            0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45, 0.5, 0.55, 0.6, 0.65, 0.7, 0.75, 0.8,
            0.85, 0.9, 0.95, 1.0f32,
        ];
        for k in 0..40 {
            assert_eq!(
                speed(k).to_bits(),
                wire[k as usize % 20].to_bits(),
                "period {k}"
            );
        }
    }

    #[test]
    fn each_period_is_matched_to_the_frame_of_its_command() {
        // Periods of 1 ms sent 10 µs after they started, speeds 0.05, 0.1, 0.15, 0.2.
        let sent: Vec<(u64, u64, f64)> = (0..4u64)
            .map(|k| (k * 1000, k * 1000 + 10, 0.05 * (k + 1) as f64))
            .collect();
        let frames = [
            (80, 0.05),
            // The tick repeats the first command before the second's frame.
            (1005, 0.05),
            (1090, 0.1),
            // The third period's command was superseded by the fourth's.
            (3200, 0.2),
            (3300, 0.2),
        ];
        let (latencies, superseded) = match_frames(&sent, &frames);
        assert_eq!((latencies.count(), superseded), (3, 1));
        let s = latencies.summary();
        assert_eq!((s.p50_us, s.max_us), (0.09, 0.2));
    }
}

#[cfg(test)]
mod periods_tests {
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
