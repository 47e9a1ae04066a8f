//! The results: the samples of a run (JSON lines, [`Report::samples`]), and what is rendered
//! from them alone: a table on stdout, the performance document and CDF plots as SVG.

use std::path::Path;

use plotters::prelude::*;
use serde::{Deserialize, Serialize};

use crate::stats::{Latencies, Summary};

/// The `what` of the TITAN on the simulated bus with chassisd's defaults (no
/// [`crate::paths::BENCH_CONFIG`]): a sample ends at the first frame toward the request (the mux
/// ramps the change).
pub const DEFAULT_CONFIG_ROW: &str =
    "titan sim, chassisd's default configuration, request → first frame toward it";

/// The `what` of the command and state rows of the TITAN on the simulated bus with the black box
/// off, beside the same run's rows with it recording (as chassisd ships).
pub const UNRECORDED_ROW: &str = "titan sim, the black box off";

/// Which path a row measures, the table's first column.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PathKind {
    #[default]
    Baseline,
    Command,
    InService,
    State,
    Preemption,
    FanOut,
    Python,
    Ros2,
    Zenoh,
    Loop,
}

impl PathKind {
    /// The title of the kind's panel in the plot.
    fn panel(self) -> &'static str {
        match self {
            PathKind::Baseline => "raw transports (ping-pong, one way)",
            PathKind::Command => "command: request created → frame written",
            PathKind::State => "state: frame read → state received",
            PathKind::Preemption => "preemption: safety stop → zero frame written",
            PathKind::FanOut => "fan-out: state to 1, 4, 16 processes",
            PathKind::Python => "Python client: frame read → state in Python; request → frame",
            PathKind::InService => {
                "in-service: chassisd's own part (woke → frame written, frame read → state published)"
            }
            PathKind::Ros2 => "ROS 2 bridge: cmd_vel → frame; frame read → odom (Cyclone DDS peer)",
            PathKind::Zenoh | PathKind::Loop => "",
        }
    }
}

impl std::fmt::Display for PathKind {
    /// The kind's name in the samples (`in-service`), but `control loop` for [`PathKind::Loop`].
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PathKind::Loop => f.write_str("control loop"),
            kind => kind.serialize(f),
        }
    }
}

/// Where a row's samples start and end, as the targets and the splits find a row (its `what`
/// is only shown).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Leg {
    #[default]
    /// A raw transport's hop.
    Hop,
    /// Gaps in a running thread's clock readings ([`STALLS`]).
    Stalls,
    /// A request created → its frame written.
    Command,
    /// A request → the first frame toward it ([`DEFAULT_CONFIG_ROW`]).
    FirstFrameToward,
    /// A frame read → the state it changed in a reader.
    State,
    /// A safety stop → its zero frame.
    Stop,
    /// A state sample in several readers.
    FanOut,
    /// `cmd_vel` → its frame.
    CmdVel,
    /// A frame read → the `odom` carrying it.
    Odom,
    /// The operator's remote source → the robot's frame.
    RemoteCommand,
    /// The robot's frame read → the state in the operator's iceoryx2.
    RemoteState,
    /// The robot's state published → in the operator's iceoryx2.
    RemoteBridge,
    /// A control loop's period started → the frame of the command it wrote.
    PeriodToFrame,
    /// The frame read → a control loop read the state it made.
    StateAge,
}

/// One measured distribution.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Row {
    pub path: PathKind,
    pub leg: Leg,
    /// The service run it belongs to (`titan sim`); empty for a baseline of no run.
    pub run: String,
    /// What ran: the transport of a baseline, or robot and bus of a service path.
    pub what: String,
    /// Service loop mode (`event`, `spin`, `hybrid`), or `-` for baselines.
    pub mode: String,
    pub placement: String,
    pub summary: Summary,
    /// Requests that produced no frame within the wait (0 expected).
    pub missed: u64,
    /// Samples of a lossless stream the reader never received (gaps in `seq`; 0 expected).
    pub dropped: u64,
    /// The rows ([`row_key`]s) whose hops this row contains in turn: a DDS hop and a path for ROS 2.
    pub contains: Vec<String>,
    /// A baseline's conditions: how it was paced and what its receiver lived with.
    pub conditions: Option<String>,
    /// The baseline row this path row is compared with (`what, placement` of that row): for a
    /// command or state row, the baseline of the same run whose receiver lived like the
    /// service's loop; for a preemption row, a ping right after a wake-up ping.
    pub baseline: Option<String>,
    pub ratio_p50: Option<f64>,
    pub ratio_p99: Option<f64>,
    /// Why the row is below its baseline, or below the sum of the rows it contains: a path
    /// cannot be faster than a part of it, so they were not measured alike.
    pub inconsistent: Option<String>,
    /// Every flag is one a smoke run only reports: below the sum of the hops it contains (medians
    /// add only approximately), or below its baseline by at most [`SMOKE_BASELINE_TOLERANCE`].
    pub smoke_tolerated: bool,
    pub latencies: Latencies,
}

/// Everything one run measured.
#[derive(Debug, Default, Serialize, Deserialize)]
pub struct Report {
    pub provenance: crate::provenance::Provenance,
    pub machine: Machine,
    /// Each its own line of the samples file, as are `parts`.
    #[serde(skip)]
    pub rows: Vec<Row>,
    pub cost: Vec<Cost>,
    /// The replays, in the order they ran ([`REPLAYS`]).
    pub throughput: Vec<Throughput>,
    /// Where the time of the service paths goes, run by run.
    #[serde(skip)]
    pub parts: Vec<Parts>,
    pub notes: Vec<String>,
    /// What makes the rows unfit to compare (a named row not measured, two rows of one name): a
    /// smoke run fails on each; the document lists them with the notes.
    pub problems: Vec<String>,
    /// How chassisd's loop was scheduled in each latency run (the run's label).
    pub scheduling: Vec<(String, Scheduling)>,
    /// chassisd's largest resident memory in a latency run in real-time mode, MiB.
    pub realtime_rss_mib: Option<f64>,
    /// The rows the run planned, for the smoke check.
    #[serde(skip)]
    pub expected: Vec<Planned>,
    /// How often each CPU stalled a thread that never blocks ([`STALLS`] rows).
    pub stalls: Vec<StallRates>,
    #[serde(default)]
    pub loops: Vec<LoopRun>,
    /// Rows planned and not measured, and why (an attached robot's rows that send velocity).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub withheld: Vec<(String, Withheld)>,
}

/// One control loop's periods over chassisd (`mode`), and the same loop over the raw hop.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LoopRun {
    /// Robot and bus.
    pub run: String,
    /// `1 kHz`, `100 Hz`.
    pub rate: String,
    pub mode: String,
    pub placement: String,
    pub periods: u64,
    /// Periods that ended after the next one was due.
    pub misses: u64,
    /// Periods whose command no frame carried (the next period's reached chassisd first).
    pub superseded: u64,
    pub raw_transport: String,
    pub raw_periods: u64,
    pub raw_misses: u64,
}

impl LoopRun {
    pub(crate) fn per_million(misses: u64, periods: u64) -> f64 {
        1e6 * misses as f64 / periods.max(1) as f64
    }
}

/// One line of a samples file: the run (what it measured on, its costs, notes), a row with its
/// histogram, or a path's split; written from references, read back into boxes.
#[derive(Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
enum Line<R, W, S> {
    Run(R),
    Row(W),
    Split(S),
}

type ReadLine = Line<Box<Report>, Box<Row>, Box<Parts>>;

impl Report {
    /// The run's samples, one JSON line each: the run first, then its rows and splits in order.
    /// Everything the table, the document and the plots are rendered from.
    pub fn samples(&self) -> Result<String, serde_json::Error> {
        let lines = std::iter::once(Line::<_, &Row, &Parts>::Run(self))
            .chain(self.rows.iter().map(Line::Row))
            .chain(self.parts.iter().map(Line::Split));
        lines
            .map(|line| Ok(serde_json::to_string(&line)? + "\n"))
            .collect()
    }

    /// A run read back from its [`Report::samples`].
    pub fn from_samples(text: &str) -> anyhow::Result<Report> {
        let mut report: Option<Report> = None;
        for (n, line) in text.lines().enumerate().filter(|(_, l)| !l.is_empty()) {
            let n = n + 1;
            let read: ReadLine =
                serde_json::from_str(line).map_err(|e| anyhow::anyhow!("samples line {n}: {e}"))?;
            match (read, report.as_mut()) {
                (Line::Run(run), None) => report = Some(*run),
                (Line::Row(row), Some(r)) => r.rows.push(*row),
                (Line::Split(split), Some(r)) => r.parts.push(*split),
                _ => anyhow::bail!("samples line {n}: the run's line must come first, once"),
            }
        }
        report.ok_or_else(|| anyhow::anyhow!("no run in the samples"))
    }
}

/// A row a run plans: its [`row_key`] and how many samples it asks for, where the plan fixes
/// that (a row measured for a time, the fan-out's and the stalls', asks for none).
#[derive(Debug, Clone, PartialEq)]
pub struct Planned {
    pub key: String,
    pub asked: Option<u64>,
}

impl Planned {
    pub fn new(key: String, asked: impl Into<Option<u64>>) -> Self {
        let asked = asked.into();
        Self { key, asked }
    }
}

/// The share of the samples it asked for a row must bring for a smoke run to pass: a request
/// the service dropped, a state sample a reader lost, a hop that timed out all cost one, and a
/// path that loses more than a tenth is broken, whatever its latency.
pub const MIN_SHARE_OF_ASKED: f64 = 0.9;

/// The stall rows' name ([`crate::stalls`]).
pub const STALLS: &str = "stalls of a running thread (gaps in its clock readings)";

/// How often one CPU stalled a thread that never blocks, gaps a second.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct StallRates {
    pub cpu: usize,
    pub over_20_us: f64,
    pub over_100_us: f64,
}

/// The splits of the Zenoh and the Python client's state rows ([`Parts::path`]).
pub const ZENOH_PARTS: &str = "zenoh: frame read → operator's state";
pub const PYTHON_PARTS: &str = "python: state";

/// One path of one run split at the stamps the code takes: each part's distribution over the
/// same samples (a sample counts in every part or in none).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Parts {
    /// `command`, `state`, `ros2: frame read → odom`, [`ZENOH_PARTS`] or [`PYTHON_PARTS`], as
    /// the document shows it.
    pub path: String,
    /// The path and leg of the rows it splits (in-service rows are split with their path's).
    pub of: (PathKind, Leg),
    pub run: String,
    pub what: String,
    pub mode: String,
    pub placement: String,
    #[serde(flatten)]
    pub split: crate::parts::Split,
}

/// Replay of a recorded bus through decode + publish as fast as the service drains it.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct Throughput {
    /// The black box was recording.
    #[serde(default)]
    pub recorder: bool,
    pub frames: u64,
    pub seconds: f64,
    pub frames_per_s: f64,
    /// CPU use of the service's loop thread while replaying, % of one core.
    pub service_cpu_pct: f64,
    /// Frames per second of the loop thread's CPU time: what one core of the service reads,
    /// decodes and publishes, whether or not the replay's writer kept it busy.
    pub frames_per_cpu_s: f64,
}

/// How many times the recording is replayed, each into a fresh service.
pub const REPLAYS: usize = 3;

#[derive(Debug, Default, Serialize, Deserialize)]
pub struct Machine {
    pub cpus: usize,
    pub kernel: String,
    pub cpu_model: String,
}

impl Machine {
    pub fn probe() -> Self {
        let read = |path| std::fs::read_to_string(path).unwrap_or_default();
        let cpuinfo = read("/proc/cpuinfo");
        let model = (cpuinfo.lines()).find_map(|l| l.strip_prefix("model name")?.split(':').nth(1));
        Self {
            cpus: crate::placement::cpu_count(),
            kernel: read("/proc/sys/kernel/osrelease").trim().to_string(),
            cpu_model: model.unwrap_or("").trim().into(),
        }
    }
}

/// How a paced baseline is labelled: one ping per command period, the hop after the pause only.
pub const PACED: &str = "paced";

/// How far below the sum of the p50s of the hops it contains a row's p50 may be before it is
/// flagged: medians of independent hops add only approximately (on a loaded 2-core machine a
/// ROS 2 row came 1.5 % and 5.9 % below the sum in two runs; the bias this catches was 19 %).
pub const SUM_TOLERANCE: f64 = 0.10;

/// How far below its own baseline's p50 a row's p50 may be in a smoke run and only be reported
/// (the document's runs flag every crossing). A smoke run is a debug build of 100 samples a row,
/// and a cross-CPU path and its matched hop are mostly an idle CPU's wake-up, whose median moves
/// between identical runs: in six smoke runs of one commit on a 2-core machine the hop measured
/// 68.2 to 82.2 µs p50 and the command path's ratio to it 0.996 to 1.17 (a CI run: 0.886), while
/// rows 44 % below their hops, a round trip counted for each, still fail.
pub const SMOKE_BASELINE_TOLERANCE: f64 = 0.20;

/// Fewest samples whose 99th percentile is shown: below it, the p99 is nearly the maximum.
pub const MIN_FOR_P99: u64 = 100;
/// Fewest samples whose 99.9th percentile is shown.
pub const MIN_FOR_P999: u64 = 1000;

/// A row's name, unique in a run: `path what (loop, placement)`.
pub fn row_key(path: PathKind, what: &str, mode: &str, placement: &str) -> String {
    format!("{path} {what} ({mode}, {placement})")
}

/// A service path's row, compared with `baseline`, and its in-service row: the part of each of
/// its samples spent inside chassisd, named `<what>: <path>` (`titan sim: state`) at the same
/// mode and placement.
pub fn path_rows(row: Row, baseline: Option<String>, in_service: Latencies) -> [Row; 2] {
    let what = format!("{}: {}", row.what, row.path);
    let (run, mode, at, l) = (&row.run, &row.mode, &row.placement, in_service);
    let inside = Row::new(PathKind::InService, row.leg, run, what, mode, at, l, 0);
    [Row { baseline, ..row }, inside]
}

impl Row {
    /// A measured row with nothing beside it yet: no loss but `missed`, no baseline, no
    /// conditions.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        path: PathKind,
        leg: Leg,
        run: &str,
        what: String,
        mode: &str,
        placement: &str,
        latencies: Latencies,
        missed: u64,
    ) -> Self {
        Self {
            path,
            leg,
            run: run.into(),
            what,
            mode: mode.into(),
            placement: placement.into(),
            summary: latencies.summary(),
            missed,
            latencies,
            ..Self::default()
        }
    }

    /// A raw transport's hop measured under `conditions`.
    pub fn hop(run: &str, what: String, at: &str, l: Latencies, conditions: String) -> Self {
        let row = Self::new(PathKind::Baseline, Leg::Hop, run, what, "-", at, l, 0);
        let conditions = Some(conditions);
        Self { conditions, ..row }
    }

    /// [`row_key`] of this row.
    pub fn key(&self) -> String {
        row_key(self.path, &self.what, &self.mode, &self.placement)
    }

    /// The row's count with what it lost beside it: `1000`, `998 (2 dropped, 1 out of range)`.
    pub(crate) fn count_text(&self) -> String {
        let (count, out) = (self.summary.count, self.summary.out_of_range);
        let lost = [
            (self.missed, "missed"),
            (self.dropped, "dropped"),
            (out, "out of range"),
        ];
        let lost: Vec<String> = (lost.iter().filter(|(n, _)| *n > 0))
            .map(|(n, what)| format!("{n} {what}"))
            .collect();
        match lost.is_empty() {
            true => count.to_string(),
            false => format!("{count} ({})", lost.join(", ")),
        }
    }
}

impl Report {
    /// Fills in the ratios of every row that names its baseline (the p99 ratio only where both
    /// have [`MIN_FOR_P99`] samples), and flags a row whose p50 is below its baseline's or below
    /// the sum of the rows it contains; a named baseline or contained row that is missing, and
    /// two rows of the same name, are problems.
    pub fn compute_ratios(&mut self) {
        let mut named = std::collections::BTreeMap::<String, usize>::new();
        for r in &self.rows {
            *named.entry(r.key()).or_default() += 1;
        }
        let twice = named.into_iter().filter(|(_, n)| *n > 1);
        (self.problems)
            .extend(twice.map(|(key, n)| format!("two rows are named '{key}' ({n} of them)")));
        // Each row by its name as a baseline (`what, placement`; none but a baseline's) and its key.
        let all: Vec<(Option<String>, String, Summary)> = (self.rows.iter())
            .map(|r| {
                let as_baseline =
                    (r.path == PathKind::Baseline).then(|| format!("{}, {}", r.what, r.placement));
                (as_baseline, r.key(), r.summary)
            })
            .collect();
        let paths = self
            .rows
            .iter_mut()
            .filter(|r| r.path != PathKind::Baseline);
        for row in paths {
            let (s, key) = (row.summary, row.key());
            // Each flag, and whether a smoke run only reports it.
            let mut flags: Vec<(String, bool)> = Vec::new();
            if let Some(name) = &row.baseline {
                let named = all.iter().filter(|(b, ..)| b.as_ref() == Some(name));
                match named.map(|(.., s)| s).collect::<Vec<_>>()[..] {
                    [] => (self.problems)
                        .push(format!("{key}: its baseline '{name}' was not measured")),
                    [base] => {
                        row.ratio_p50 = (base.p50_us > 0.0).then(|| s.p50_us / base.p50_us);
                        let enough = base.count.min(s.count) >= MIN_FOR_P99;
                        row.ratio_p99 =
                            (base.p99_us > 0.0 && enough).then(|| s.p99_us / base.p99_us);
                        if s.count > 0 && s.p50_us < base.p50_us {
                            let (p50, base_p50) = (s.p50_us, base.p50_us);
                            let text = format!(
                                "p50 {p50:.1} µs is below the p50 {base_p50:.1} µs of the hop it \
                                 contains ({name}): the path and its baseline were not measured \
                                 under the same conditions"
                            );
                            flags.push((text, p50 >= base_p50 * (1.0 - SMOKE_BASELINE_TOLERANCE)));
                        }
                    }
                    _ => (self.problems)
                        .push(format!("{key}: more than one baseline is named '{name}'")),
                }
            }
            let measured = |k: &String| all.iter().find(|(_, n, s)| n == k && s.count > 0);
            let contained = row
                .contains
                .iter()
                .map(|k| measured(k).map(|(.., s)| s.p50_us));
            match contained.sum::<Option<f64>>() {
                _ if row.contains.is_empty() => {}
                None => self.problems.push(format!(
                    "{key}: a row it contains was not measured ({})",
                    row.contains.join(", ")
                )),
                Some(sum) if s.count > 0 && s.p50_us < sum * (1.0 - SUM_TOLERANCE) => {
                    let (p50, hops, pct) =
                        (s.p50_us, row.contains.join(" + "), SUM_TOLERANCE * 100.0);
                    let text = format!(
                        "p50 {p50:.1} µs is more than {pct:.0} % below {sum:.1} µs, the sum of the \
                         p50s of the hops it contains ({hops}): they were not measured under the \
                         same conditions"
                    );
                    flags.push((text, true));
                }
                Some(_) => {}
            }
            let (texts, near): (Vec<String>, Vec<bool>) = flags.into_iter().unzip();
            row.smoke_tolerated = !near.is_empty() && near.iter().all(|n| *n);
            row.inconsistent = (!texts.is_empty()).then(|| texts.join("; "));
        }
    }

    /// What makes a run fail its smoke check (`--smoke`): a row of `expected` missing, or
    /// bringing less than [`MIN_SHARE_OF_ASKED`] of the samples it asked for (none, where it
    /// asked for no number), any row more than [`SMOKE_BASELINE_TOLERANCE`] below its own
    /// baseline (a path faster than a hop it contains), and every [`Report::problems`]. Never a
    /// target: the figures of a loaded machine are what they are. A row flagged only within the
    /// smoke run's noise is a [`Report::smoke_warnings`] line instead (a release run's document
    /// still marks the row).
    pub fn smoke_failures(&self, expected: &[Planned]) -> Vec<String> {
        let mut failures = Vec::new();
        for Planned { key, asked } in expected {
            let Some(r) = self.rows.iter().find(|r| r.key() == *key) else {
                failures.push(format!("missing row: {key}"));
                continue;
            };
            let count = r.summary.count;
            match asked {
                None if count == 0 => failures.push(format!("no sample: {key}")),
                Some(asked) if (count as f64) < MIN_SHARE_OF_ASKED * *asked as f64 => {
                    let count = r.count_text();
                    failures.push(format!(
                        "too few samples: {key}: {count} of the {asked} asked for"
                    ))
                }
                _ => {}
            }
        }
        failures.extend(self.flagged(false).map(|f| format!("flagged row: {f}")));
        failures.extend(self.problems.iter().cloned());
        failures
    }

    /// The rows the smoke run reports without failing on them: flagged within its noise only.
    pub fn smoke_warnings(&self) -> Vec<String> {
        let warning = |f| format!("flagged within a smoke run's noise (not failing it): {f}");
        self.flagged(true).map(warning).collect()
    }

    /// "KEY: WHY" of each row flagged inconsistent whose flags a smoke run only reports, or not.
    fn flagged(&self, tolerated: bool) -> impl Iterator<Item = String> + '_ {
        let rows = self
            .rows
            .iter()
            .filter(move |r| r.smoke_tolerated == tolerated);
        rows.filter_map(|r| Some(format!("{}: {}", r.key(), r.inconsistent.as_deref()?)))
    }

    /// Latency CDFs of every row, log latency axis: one panel per kind of path, all on the same
    /// axes so panels compare.
    pub fn plot(&self, path: &Path) -> anyhow::Result<()> {
        use PathKind::*;
        let panels = [
            Baseline, Command, State, Preemption, FanOut, Python, InService, Ros2,
        ];
        let root = SVGBackend::new(path, (1600, 2000)).into_drawing_area();
        root.fill(&WHITE)?;
        let title = "one-way latency, CDF (log latency axis)";
        let root = root.titled(title, ("sans-serif", 26))?;
        let max_us = self.rows.iter().map(|r| r.summary.max_us);
        let max_us = max_us.fold(10.0f64, f64::max).min(1e6);
        for (area, kind) in root.split_evenly((4, 2)).iter().zip(panels) {
            // The stall rows are gaps in one thread, not a hop: the table gives them.
            let rows = self.rows.iter().filter(|r| r.path == kind);
            let rows: Vec<&Row> = rows.filter(|r| r.leg != Leg::Stalls).collect();
            if rows.is_empty() {
                continue;
            }
            let mut chart = ChartBuilder::on(area)
                .caption(kind.panel(), ("sans-serif", 18))
                .margin(12)
                .x_label_area_size(35)
                .y_label_area_size(45)
                .build_cartesian_2d((0.5f64..max_us * 1.2).log_scale(), 0.0f64..1.0)?;
            chart
                .configure_mesh()
                .x_desc("latency, µs")
                .y_desc("fraction of samples")
                .draw()?;
            for (i, row) in rows.iter().enumerate() {
                let color = Palette99::pick(i).to_rgba();
                let (what, placement) = (&row.what, &row.placement);
                let label = match row.mode.as_str() {
                    "-" => format!("{what}, {placement}"),
                    mode => format!("{what}, {mode}, {placement}"),
                };
                let line = LineSeries::new(row.latencies.cdf(), color.stroke_width(2));
                chart.draw_series(line)?.label(label).legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                });
            }
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::LowerRight)
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .label_font(("sans-serif", 12))
                .draw()?;
        }
        Ok(root.present()?)
    }

    /// The split of the rows `of` in `row`'s run, loop and placement, if it was split.
    pub(crate) fn split_of(&self, of: (PathKind, Leg), row: &Row) -> Option<&Parts> {
        let run =
            |p: &&Parts| (&p.run, &p.mode, &p.placement) == (&row.run, &row.mode, &row.placement);
        self.parts.iter().filter(run).find(|p| p.of == of)
    }
}

/// How a run's chassisd loop is scheduled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Scheduling {
    /// Normal scheduling, as asked.
    Normal,
    /// Real-time mode, granted: SCHED_FIFO at this priority.
    Fifo(u8),
    /// Real-time mode asked for and refused by the system: normal scheduling.
    Refused,
}

impl Scheduling {
    /// The SCHED_FIFO priority the loop runs at, if it does.
    pub fn fifo(self) -> Option<u8> {
        match self {
            Scheduling::Fifo(priority) => Some(priority),
            Scheduling::Normal | Scheduling::Refused => None,
        }
    }
}

/// CPU use and memory of the service at a given bus load.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Cost {
    /// The bus the service read: `sim` (a socket pair, up to 256 frames per read) or `slcan-pty`
    /// (`chassisd sim` behind an emulated slcan adapter on a pty: text lines, as a USB adapter).
    pub bus: String,
    pub bitrate: u32,
    pub frames_per_s: f64,
    /// The loop thread's CPU, % of one core.
    pub cpu_pct: f64,
    /// The black box writer's thread's CPU, % of one core (`None`: not recording).
    #[serde(default)]
    pub recorder_cpu_pct: Option<f64>,
    /// What the black box wrote to its ring, MB (10⁶ bytes) a minute.
    #[serde(default)]
    pub recorder_mb_per_min: Option<f64>,
    pub rss_mib: f64,
}
impl Cost {
    /// The service's CPU: its loop and its black box writer, % of one core.
    pub fn service_cpu_pct(&self) -> f64 {
        self.cpu_pct + self.recorder_cpu_pct.unwrap_or(0.0)
    }
}

/// Why a planned row was not measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Withheld {
    /// It sends velocity to a robot the run did not start for itself, and `--wheels-off-ground`
    /// was not given.
    WheelsOnGround,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::parts::Part;
    use crate::parts::Whose;
    use crate::render::{TOGETHER_CODE, TOGETHER_OUTSIDE, percentile};

    /// A target judged, as these tests read it: met (none: not measured), where the worst
    /// row's time goes, what bounds it.
    #[derive(Debug)]
    struct Judged {
        what: String,
        measured: String,
        met: Option<bool>,
        why: String,
        limit: String,
    }

    fn targets(report: &Report) -> Vec<Judged> {
        use crate::verdict::Outcome;
        crate::verdict::judge(report)
            .unwrap()
            .into_iter()
            .map(|v| {
                let (met, why, limit) = match v.outcome {
                    Outcome::Met => (Some(true), String::new(), String::new()),
                    Outcome::Missed { worst, bound } => (Some(false), worst, bound),
                    Outcome::NotMeasured => (None, String::new(), String::new()),
                    Outcome::Inconsistent { rows } => (
                        Some(false),
                        format!("flagged: {}", rows.join("; ")),
                        "the measurement, not the time".into(),
                    ),
                };
                Judged {
                    what: v.text,
                    measured: v.measured,
                    met,
                    why,
                    limit,
                }
            })
            .collect()
    }

    /// A row of `path` with `n` samples of `us` µs each.
    fn measured(path: &str, what: &str, mode: &str, us: u64, n: u64) -> Row {
        let mut latencies = Latencies::new();
        for _ in 0..n {
            latencies.record(us * 1000);
        }
        let (path, leg) = kind_of(path, what);
        let run = what.split(": ").next().unwrap_or_default();
        Row::new(path, leg, run, what.into(), mode, "cross CPU", latencies, 0)
    }

    /// The typed kind of a fixture's row, from the words its table shows.
    fn kind_of(path: &str, what: &str) -> (PathKind, Leg) {
        let leg = if what.ends_with("command") {
            Leg::Command
        } else if what.ends_with("odom") {
            Leg::Odom
        } else if what.ends_with("frame") {
            Leg::CmdVel
        } else {
            Leg::State
        };
        match path {
            "baseline" => (PathKind::Baseline, Leg::Hop),
            "command" => (PathKind::Command, Leg::Command),
            "state" => (PathKind::State, Leg::State),
            "preemption" => (PathKind::Preemption, Leg::Stop),
            "in-service" => (PathKind::InService, leg),
            "python" | "python: state" => (PathKind::Python, leg),
            "ros2" => (PathKind::Ros2, leg),
            other => panic!("no fixture row of path {other}"),
        }
    }

    /// The document says whether real-time mode was granted, naming the runs that were refused.
    #[test]
    fn the_runs_refused_realtime_mode_are_named() {
        use Scheduling;
        let mut report = Report {
            scheduling: vec![
                (
                    "titan sim, event loop, same CPU".into(),
                    Scheduling::Fifo(80),
                ),
                ("titan sim, spin loop, cross CPU".into(), Scheduling::Normal),
            ],
            ..Report::default()
        };
        assert_eq!(
            report.scheduling_text(),
            "Real-time mode was granted in each of the 1 runs that asked for it."
        );
        report.scheduling.push((
            "titan slcan pty, event loop, cross CPU".into(),
            Scheduling::Refused,
        ));
        let text = report.scheduling_text();
        assert!(
            text.contains("refused** (no CAP_SYS_NICE or RLIMIT_RTPRIO) in 1 of the 2 runs")
                && text.ends_with(": titan slcan pty, event loop, cross CPU."),
            "{text}"
        );
    }

    #[test]
    fn a_service_paths_rows_are_the_path_against_its_baseline_and_its_in_service_part() {
        let mut state = measured("state", "titan sim", "event", 60, 10);
        state.dropped = 2;
        let inside = measured("in-service", "-", "event", 20, 10).latencies;
        let [path, in_service] = path_rows(state, Some("iceoryx2 feed, cross CPU".into()), inside);
        assert_eq!(
            (
                row_key(path.path, &path.what, &path.mode, &path.placement),
                path.dropped
            ),
            ("state titan sim (event, cross CPU)".to_string(), 2)
        );
        assert_eq!(path.baseline.as_deref(), Some("iceoryx2 feed, cross CPU"));
        assert_eq!(path.summary.count, 10);
        assert_eq!(
            row_key(
                in_service.path,
                &in_service.what,
                &in_service.mode,
                &in_service.placement
            ),
            "in-service titan sim: state (event, cross CPU)"
        );
        assert_eq!((in_service.baseline, in_service.missed), (None, 0));
        assert_eq!(in_service.latencies.count(), 10);
        assert_eq!(in_service.summary.p50_us.round(), 20.0);
    }

    /// A ROS 2 row containing a DDS hop and the service's command path, and what the smoke
    /// check expects of the run.
    fn run_with_ros2_row(ros2_us: u64) -> (Report, Vec<Planned>) {
        let mut ros2 = measured("ros2", "cmd_vel → frame", "event", ros2_us, 200);
        ros2.baseline = Some("dds, cross CPU".into());
        ros2.contains = vec![
            row_key(PathKind::Baseline, "dds", "-", "cross CPU"),
            row_key(PathKind::Command, "titan sim", "event", "cross CPU"),
        ];
        compared(vec![
            measured("baseline", "dds", "-", 300, 200),
            measured("command", "titan sim", "event", 200, 200),
            ros2,
        ])
    }

    /// A report of `rows`, its ratios and flags computed, and the rows it planned: all of them.
    fn compared(rows: Vec<Row>) -> (Report, Vec<Planned>) {
        let expected = rows
            .iter()
            .map(|r| Planned::new(r.key(), r.summary.count))
            .collect();
        let mut report = Report {
            rows,
            ..Report::default()
        };
        report.compute_ratios();
        (report, expected)
    }

    #[test]
    fn a_run_with_every_planned_row_and_none_flagged_passes_the_smoke_check() {
        let (report, expected) = run_with_ros2_row(600);
        assert_eq!(report.smoke_failures(&expected), Vec::<String>::new());
        let ros2 = &report.rows[2];
        assert!(
            ros2.ratio_p50.is_some_and(|r| (r - 2.0).abs() < 0.01),
            "{ros2:?}"
        );
    }

    #[test]
    fn a_row_cheaper_than_the_hops_it_contains_is_flagged_and_warned_of_by_the_smoke_check() {
        // Above its DDS hop (300 µs), more than 10 % below the hop plus the command path
        // (500 µs).
        let (report, expected) = run_with_ros2_row(440);
        let ros2 = &report.rows[2];
        assert!(
            ros2.inconsistent
                .as_deref()
                .is_some_and(|f| f.contains("sum")),
            "{ros2:?}"
        );
        assert!(ros2.smoke_tolerated);
        assert_eq!(report.smoke_failures(&expected), Vec::<String>::new());
        let warnings = report.smoke_warnings();
        assert!(
            warnings.len() == 1 && warnings[0].contains("ros2"),
            "{warnings:?}"
        );
    }

    #[test]
    fn a_row_far_cheaper_than_its_own_baseline_fails_the_smoke_check() {
        // A third below its DDS hop (300 µs) alone.
        let (report, expected) = run_with_ros2_row(200);
        assert!(!report.rows[2].smoke_tolerated, "{:?}", report.rows[2]);
        let failures = report.smoke_failures(&expected);
        assert!(
            failures.iter().any(|f| f.starts_with("flagged row: ros2")),
            "{failures:?}"
        );
    }

    /// A command row and its matched hop, the row `path_us` and the hop `hop_us` at the p50.
    fn run_with_command_row(path_us: u64, hop_us: u64) -> (Report, Vec<Planned>) {
        let mut command = measured("command", "titan sim", "event", path_us, 100);
        command.baseline = Some("hop, cross CPU".into());
        compared(vec![measured("baseline", "hop", "-", hop_us, 100), command])
    }

    #[test]
    fn a_row_a_little_below_its_baseline_is_flagged_and_only_warned_of_by_the_smoke_check() {
        // 80.7 against 91.1 µs: a smoke run's cross-CPU command row on CI.
        let (report, expected) = run_with_command_row(81, 91);
        let command = &report.rows[1];
        assert!(
            command
                .inconsistent
                .as_deref()
                .is_some_and(|f| f.contains("of the hop it contains (hop, cross CPU)")),
            "{command:?}"
        );
        assert!(command.smoke_tolerated);
        assert_eq!(report.smoke_failures(&expected), Vec::<String>::new());
        assert_eq!(report.smoke_warnings().len(), 1);
    }

    #[test]
    fn a_row_more_than_the_tolerance_below_its_baseline_fails_the_smoke_check() {
        // 79 µs is 21 % below 100 µs: past the tolerance of 20 %.
        let (report, expected) = run_with_command_row(79, 100);
        assert!(!report.rows[1].smoke_tolerated, "{:?}", report.rows[1]);
        assert!(report.smoke_warnings().is_empty());
        let failures = report.smoke_failures(&expected);
        assert!(
            failures.len() == 1 && failures[0].starts_with("flagged row: command"),
            "{failures:?}"
        );
        // Within it, reported only.
        let (report, expected) = run_with_command_row(81, 100);
        assert!(report.rows[1].smoke_tolerated, "{:?}", report.rows[1]);
        assert!(report.smoke_failures(&expected).is_empty());
    }

    #[test]
    fn a_row_within_the_tolerance_of_the_sum_of_its_hops_is_not_flagged() {
        let (report, _) = run_with_ros2_row(460);
        assert_eq!(report.rows[2].inconsistent, None);
    }

    /// A replay whose service read, decoded and published `per_cpu_s` frames per second of
    /// its CPU, busy 80 % of the time.
    fn replay(per_cpu_s: f64) -> Throughput {
        Throughput {
            recorder: true,
            frames: 150_000,
            seconds: 150_000.0 / (0.8 * per_cpu_s),
            frames_per_s: 0.8 * per_cpu_s,
            service_cpu_pct: 80.0,
            frames_per_cpu_s: per_cpu_s,
        }
    }

    fn throughput_target(runs: &[f64]) -> Judged {
        let report = Report {
            throughput: runs.iter().map(|&r| replay(r)).collect(),
            ..Report::default()
        };
        targets(&report)
            .into_iter()
            .find(|t| t.what.starts_with("decode + publish"))
            .unwrap()
    }

    #[test]
    fn the_throughput_target_takes_the_median_replays_frames_per_cpu_second() {
        // Each run's wall-clock rate (80 % of it) is below the target; the median run's CPU
        // second is not.
        let t = throughput_target(&[900_000.0, 1_200_000.0, 1_100_000.0]);
        assert_eq!(t.met, Some(true));
        assert_eq!(
            t.measured,
            "1100000 frames per second of the service's CPU, the median of 3 replays with the \
             black box recording (900000, 1200000, 1100000)"
        );
        // Replays with the black box off are not the robot as shipped: not judged.
        let report = Report {
            throughput: vec![Throughput {
                recorder: false,
                ..replay(2_000_000.0)
            }],
            ..Report::default()
        };
        let judged = targets(&report);
        let t = judged
            .iter()
            .find(|t| t.what.starts_with("decode + publish"));
        assert_eq!(t.map(|t| t.met), Some(None));
        // One fast replay does not carry the target.
        let t = throughput_target(&[900_000.0, 1_200_000.0, 950_000.0]);
        assert_eq!(t.met, Some(false), "{}", t.measured);
        assert_eq!(throughput_target(&[]).measured, "not measured");
    }

    #[test]
    fn the_microseconds_table_gives_each_part_and_its_share_of_the_p50s() {
        let mut split = split_of(
            "command",
            "titan sim",
            "event",
            vec![
                part("woke", Whose::Outside, 30, 200),
                part("written", Whose::Code, 10, 200),
            ],
        );
        split.split.code = part("", Whose::Code, 12, 200).summary;
        split.split.outside = part("", Whose::Outside, 33, 200).summary;
        let report = Report {
            parts: vec![split],
            ..Report::default()
        };
        let md = crate::render::parts(&report);
        assert!(
            md.contains("| woke | outside | 200 | 30.0 | 30.0 | 75 % |"),
            "{md}"
        );
        assert!(
            md.contains("| written | the code | 200 | 10.0 | 10.0 | 25 % |"),
            "{md}"
        );
        // The sums of its samples' parts, without a share.
        assert!(
            md.contains(&format!(
                "| {TOGETHER_CODE} | the code | 200 | 12.0 | 12.0 |  |"
            )),
            "{md}"
        );
        assert!(
            md.contains(&format!(
                "| {TOGETHER_OUTSIDE} | outside | 200 | 33.0 | 33.0 |  |"
            )),
            "{md}"
        );
    }

    /// A part of a split: `n` samples of `us` µs each.
    fn part(name: &str, whose: Whose, us: u64, n: u64) -> Part {
        Part {
            name: name.into(),
            whose,
            summary: measured("command", "x", "event", us, n).summary,
        }
    }

    /// The split of the cross-CPU run of `path` on `what`, in loop `mode`.
    fn split_of(path: &str, what: &str, mode: &str, parts: Vec<Part>) -> Parts {
        Parts {
            path: path.into(),
            of: kind_of(path, path),
            run: what.into(),
            what: what.into(),
            mode: mode.into(),
            placement: "cross CPU".into(),
            split: crate::parts::Split {
                parts,
                ..Default::default()
            },
        }
    }

    /// The targets of a run whose cross-CPU state row (p99 `row_us` against its baseline's 100
    /// µs) splits into a decode of `decode_us` and a reader's wake-up of `wake_us`.
    fn state_target(row_us: u64, decode_us: u64, wake_us: u64) -> Judged {
        state_target_of(
            row_us,
            vec![
                part("frame read → handed", Whose::Code, decode_us, 200),
                part("woken → reader has it", Whose::Outside, wake_us, 200),
            ],
            None,
        )
    }

    /// The state target of a run whose cross-CPU state row (p99 `row_us` against its
    /// baseline's 100 µs) splits into `parts`, their samples' outside and code sums `sums`
    /// (p99s, µs; none: too few samples to say).
    fn state_target_of(row_us: u64, parts: Vec<Part>, sums: Option<(u64, u64)>) -> Judged {
        let mut state = measured("state", "titan sim", "event", row_us, 200);
        state.baseline = Some("hop, cross CPU".into());
        let (mut report, _) = compared(vec![measured("baseline", "hop", "-", 100, 200), state]);
        let mut split = split_of("state", "titan sim", "event", parts);
        if let Some((outside, code)) = sums {
            split.split.outside = part("", Whose::Outside, outside, 200).summary;
            split.split.code = part("", Whose::Code, code, 200).summary;
        }
        report.parts.push(split);
        targets(&report)
            .into_iter()
            .find(|t| t.what.starts_with("state p99"))
            .unwrap()
    }

    /// A state row of p99 300 µs (3 × its baseline's) whose decode takes 20 µs and whose
    /// notification and wake-up take 100 and 150 µs, each within 2 × the baseline's.
    fn three_parts() -> Vec<Part> {
        vec![
            part("frame read → handed", Whose::Code, 20, 200),
            part("notification begun → returned", Whose::Outside, 100, 200),
            part("returned → reader has it", Whose::Outside, 150, 200),
        ]
    }

    #[test]
    fn a_target_missed_by_the_parts_outside_the_code_together_is_out_of_reach_of_the_code() {
        // Together, sample by sample, 280 µs: 2.8 × the baseline's.
        let t = state_target_of(300, three_parts(), Some((280, 20)));
        assert_eq!(t.met, Some(false));
        assert!(
            t.limit.starts_with(
                "outside the code: its 2 parts outside it together (each sample's sum): p99 280."
            ) && t.limit.ends_with(
                "µs, 2.80 × the baseline's, beyond 2 × the baseline's (100.0 µs) whatever the \
                 code does; none alone (the largest, returned → reader has it: p99 150.0 µs, \
                 1.50 × the baseline's)"
            ),
            "{}",
            t.limit
        );
    }

    #[test]
    fn a_target_missed_while_the_parts_outside_stay_within_it_together_is_the_codes() {
        // Together 190 µs (the two parts' longest seldom in one sample); the code's, 110.
        let t = state_target_of(300, three_parts(), Some((190, 110)));
        assert_eq!(t.met, Some(false));
        assert!(
            t.limit.starts_with(
                "the code: the parts outside it stay within the target (together: p99 190."
            ) && t.limit.contains(
                "µs, 1.90 × the baseline's; the largest, returned → reader has it: p99 150.0 \
                 µs, 1.50 × the baseline's); the code's parts together have p99 110.0 µs (p50 \
                 110.0); the code's largest, frame read → handed, has p99 20.0 µs"
            ),
            "{}",
            t.limit
        );
        // Its slowest samples slow in both at once: the row's p99 beyond the sums' added.
        let t = state_target_of(400, three_parts(), Some((190, 110)));
        assert!(
            t.limit.contains("the row's p99 (400.")
                && t.limit
                    .contains("µs) is beyond the two sums' p99s added (300.")
                && t.limit.contains(
                    "µs): its slowest samples were slow in the code's parts and outside at once; \
                 the code's largest"
                ),
            "{}",
            t.limit
        );
    }

    #[test]
    fn a_target_missed_by_a_part_outside_the_code_alone_is_out_of_reach_of_the_code() {
        let t = state_target(300, 20, 280);
        assert_eq!(t.met, Some(false));
        assert!(
            t.why.contains("woken → reader has it, p99 280."),
            "{}",
            t.why
        );
        assert!(
            t.limit
                .starts_with("outside the code: woken → reader has it alone: p99 280.")
                && t.limit.contains(
                    "2.80 × the baseline's, beyond 2 × the baseline's (100.0 µs) whatever"
                ),
            "{}",
            t.limit
        );
    }

    #[test]
    fn a_target_missed_while_the_parts_outside_the_code_stay_within_it_is_the_codes() {
        let t = state_target(300, 150, 150);
        assert_eq!(t.met, Some(false));
        assert!(
            t.limit.starts_with("the code: the parts outside it stay within the target (the largest, woken → reader has it: p99 150.0 µs, 1.50 × the baseline's); the code's largest, frame read → handed, has p99 150.0 µs"),
            "{}",
            t.limit
        );
    }

    /// The Python target of a run whose Rust state row has p99 100 µs and whose Python state
    /// row (p99 `row_us`) splits into a wake-up of `wake_us` and the stream's reading of
    /// `read_us`.
    fn python_target(row_us: u64, wake_us: u64, read_us: u64) -> Judged {
        let mut report = Report {
            rows: vec![
                measured("state", "titan sim", "event", 100, 200),
                measured("python", "titan sim: state", "event", row_us, 200),
            ],
            ..Report::default()
        };
        report.parts.push(split_of(
            PYTHON_PARTS,
            "titan sim",
            "event",
            vec![
                part("returned → wait returned", Whose::Outside, wake_us, 200),
                part("wait returned → in hand", Whose::Code, read_us, 200),
            ],
        ));
        targets(&report)
            .into_iter()
            .find(|t| t.what.starts_with("Python state"))
            .unwrap()
    }

    #[test]
    fn the_python_target_names_what_bounds_it_from_the_python_split() {
        let t = python_target(150, 100, 50);
        assert_eq!(
            (t.met, t.why.as_str(), t.limit.as_str()),
            (Some(true), "", "")
        );
        let t = python_target(400, 250, 150);
        assert_eq!(t.met, Some(false));
        assert!(
            t.why.contains("returned → wait returned, p99 250."),
            "{}",
            t.why
        );
        assert!(
            t.limit
                .starts_with("outside the code: returned → wait returned alone: p99 250.")
                && t.limit
                    .contains("2.50 × the baseline's, beyond 2 × the baseline's (100.0 µs)"),
            "{}",
            t.limit
        );
        let t = python_target(400, 150, 250);
        assert!(
            t.limit
                .starts_with("the code: the parts outside it stay within the target")
                && t.limit.contains("wait returned → in hand, has p99 250."),
            "{}",
            t.limit
        );
    }

    #[test]
    fn a_target_missed_only_on_a_row_flagged_inconsistent_says_so_not_a_part() {
        // 90 µs against its hop's 100: within 2 × at the p99, flagged below its hop.
        let t = state_target(90, 20, 70);
        assert_eq!(t.met, Some(false));
        assert_eq!(t.why, "flagged: titan sim event cross CPU");
        assert!(
            t.limit.starts_with("the measurement, not the time"),
            "{}",
            t.limit
        );
    }

    #[test]
    fn a_target_finds_its_rows_by_their_kind_not_their_words() {
        let target = |rows: Vec<Row>| {
            let report = Report {
                rows,
                ..Report::default()
            };
            targets(&report).remove(0)
        };
        let fast = measured("in-service", "titan sim: command", "event", 3, 200);
        assert_eq!(target(vec![fast.clone()]).met, Some(true));
        // The default configuration's row reads like a command's but ends at the first frame
        // of a ramp: the target over the service's own pass leaves it out.
        let mut ramp = measured("in-service", "titan sim: command", "event", 900, 200);
        ramp.leg = Leg::FirstFrameToward;
        assert_eq!(target(vec![fast.clone(), ramp.clone()]).met, Some(true));
        // A row of the same kind counts, whatever it is called.
        ramp.leg = Leg::Command;
        ramp.what = "anything".into();
        assert_eq!(target(vec![fast, ramp]).met, Some(false));
    }

    #[test]
    fn an_in_service_target_missed_by_the_bus_write_alone_says_so() {
        let mut report = Report::default();
        report.rows.push(measured(
            "in-service",
            "titan slcan pty: command",
            "spin",
            30,
            200,
        ));
        report.parts.push(split_of(
            "command",
            "titan slcan pty",
            "spin",
            vec![
                // Before the row starts: left out of what bounds it.
                part(
                    "request created → request read (the poll)",
                    Whose::Outside,
                    900,
                    200,
                ),
                part("request read → write begun", Whose::Code, 2, 200),
                part("write begun → frame written", Whose::Outside, 26, 200),
            ],
        ));
        let t = targets(&report).remove(0);
        assert_eq!(t.met, Some(false));
        assert!(
            t.why.contains("write begun → frame written, p99 26.0"),
            "{}",
            t.why
        );
        assert!(
            t.limit.starts_with("outside the code: write begun → frame written alone: 26.0 / 26.0 µs (p50 / p99), beyond 5 / 15 µs"),
            "{}",
            t.limit
        );
    }

    #[test]
    fn the_targets_say_how_often_the_machine_stalls_a_running_thread() {
        let mut report = Report::default();
        assert_eq!(report.stalls_text(), "");
        report.stalls = vec![
            StallRates {
                cpu: 0,
                over_20_us: 300.0,
                over_100_us: 2.5,
            },
            StallRates {
                cpu: 1,
                over_20_us: 340.0,
                over_100_us: 0.5,
            },
        ];
        let text = report.stalls_text();
        assert!(
            text.contains(
                "more than 20 µs 300 to 340 times a second and more than 100 µs 0.50 to 2.50"
            ),
            "{text}"
        );
        assert!(
            text.contains("in about 3.0 to 3.4 % of its samples"),
            "{text}"
        );
        assert!(
            text.ends_with("so that its p99 carries one, whatever the code does."),
            "{text}"
        );
        // Rarer stalls say nothing of the p99.
        report.stalls[0].over_20_us = 50.0;
        assert!(
            crate::render::document(&report)
                .unwrap()
                .contains("0.5 to 3.4 % of its samples on each CPU it runs on.")
        );
    }

    #[test]
    fn a_missing_row_fails_the_smoke_check() {
        let (mut report, expected) = run_with_ros2_row(600);
        report.rows.remove(1);
        let failures = report.smoke_failures(&expected);
        assert!(
            failures.contains(&format!("missing row: {}", expected[1].key)),
            "{failures:?}"
        );
    }

    #[test]
    fn a_row_that_lost_more_than_a_tenth_of_what_it_asked_for_fails_the_smoke_check() {
        let (mut report, mut expected) = run_with_ros2_row(600);
        // The command row asked for 200 and brought 200; a run that asked for 230 got 87 %.
        expected[1].asked = Some(230);
        assert_eq!(
            report.smoke_failures(&expected),
            ["too few samples: command titan sim (event, cross CPU): 200 of the 230 asked for"]
        );
        // 222 asked: 200 is 90.1 %, within what a run may lose.
        expected[1].asked = Some(222);
        assert_eq!(report.smoke_failures(&expected), Vec::<String>::new());
        // A row that asked for no number fails only without a sample.
        expected[1].asked = None;
        report.rows[1] = measured("command", "titan sim", "event", 200, 0);
        assert_eq!(
            report.smoke_failures(&expected),
            ["no sample: command titan sim (event, cross CPU)"]
        );
    }

    #[test]
    fn two_rows_of_one_name_and_a_baseline_never_measured_fail_the_smoke_check() {
        let (mut report, expected) = run_with_ros2_row(600);
        report
            .rows
            .push(measured("command", "titan sim", "event", 200, 200));
        let mut orphan = measured("state", "titan sim", "event", 200, 200);
        orphan.baseline = Some("feed, cross CPU".into());
        report.rows.push(orphan);
        report.problems.clear();
        report.compute_ratios();
        let failures = report.smoke_failures(&expected);
        assert!(
            failures.iter().any(|f| f.starts_with("two rows")),
            "{failures:?}"
        );
        assert!(
            failures.iter().any(|f| f.contains("was not measured")),
            "{failures:?}"
        );
    }

    #[test]
    fn a_run_rendered_from_its_samples_is_the_run_rendered() {
        use Scheduling;
        let (mut report, _) = run_with_ros2_row(600);
        report.rows[1].latencies.record_between(5, 1);
        report.parts.push(split_of(
            "command",
            "titan sim",
            "event",
            vec![part("woke", Whose::Outside, 30, 200)],
        ));
        report.cost.push(Cost {
            bus: "sim".into(),
            bitrate: 500_000,
            frames_per_s: 4504.5,
            cpu_pct: 1.25,
            recorder_cpu_pct: Some(0.25),
            recorder_mb_per_min: Some(16.0),
            rss_mib: 7.1,
        });
        report.throughput.push(replay(1.5e6));
        report.scheduling = vec![(
            "titan sim, event loop, same CPU".into(),
            Scheduling::Refused,
        )];
        report.stalls.push(StallRates {
            cpu: 1,
            over_20_us: 340.0,
            over_100_us: 0.5,
        });
        report.notes.push("one CPU only".into());
        report
            .problems
            .push("two rows are named 'x' (2 of them)".into());
        report.realtime_rss_mib = Some(12.25);
        report.loops.push(loop_run(3, 1));

        let samples = report.samples().unwrap();
        let again = Report::from_samples(&samples).unwrap();
        assert_eq!(
            crate::render::document(&again).unwrap(),
            crate::render::document(&report).unwrap()
        );
        assert_eq!(again.table(), report.table());
        assert_eq!(again.samples().unwrap(), samples);
        assert_eq!(
            again.rows[1].latencies.cdf(),
            report.rows[1].latencies.cdf()
        );
        assert_eq!(again.rows[1].latencies.out_of_range, 1);
    }

    /// A 1 kHz loop of 100,000 periods beside a raw loop of as many.
    fn loop_run(misses: u64, raw_misses: u64) -> LoopRun {
        LoopRun {
            run: "titan sim".into(),
            rate: "1 kHz".into(),
            mode: "event".into(),
            placement: "cross CPU".into(),
            periods: 100_000,
            misses,
            superseded: 0,
            raw_transport: "iceoryx2 event".into(),
            raw_periods: 100_000,
            raw_misses,
        }
    }

    #[test]
    fn a_control_loop_may_miss_no_more_periods_than_the_raw_loop_beyond_the_counts_noise() {
        let target = |loops: Vec<LoopRun>| {
            let report = Report {
                loops,
                ..Report::default()
            };
            targets(&report)
                .into_iter()
                .find(|t| t.what.starts_with("a control loop"))
                .unwrap()
        };
        assert_eq!(target(vec![]).met, None);
        let t = target(vec![loop_run(2, 2)]);
        assert_eq!(
            (t.met, t.measured.as_str()),
            (Some(true), "1 kHz event: 20 vs 20 of a million")
        );
        // 3 of 5 misses in one of two loops of as many periods: half the time by chance.
        let t = target(vec![loop_run(2, 2), loop_run(3, 2)]);
        let measured = "1 kHz event: 20 vs 20 of a million; 1 kHz event: 30 vs 20 of a million \
                        (3 vs 2 misses, as many by chance: 50.0 %)";
        assert_eq!((t.met, t.measured.as_str()), (Some(true), measured));
        // All of 4 misses: 1 in 16 by chance; all of 5: 1 in 32, below the target's 5 %.
        assert_eq!(target(vec![loop_run(4, 0)]).met, Some(true));
        let t = target(vec![loop_run(5, 0)]);
        assert_eq!(t.met, Some(false));
        assert!(
            t.measured
                .ends_with("(5 vs 0 misses, as many by chance: 3.1 %)")
        );
        let t = target(vec![loop_run(42, 13)]);
        assert_eq!(t.met, Some(false));
        assert!(
            t.measured
                .ends_with("(42 vs 13 misses, as many by chance: < 0.1 %)")
        );
        let section = crate::render::loops(&Report {
            loops: vec![loop_run(3, 1)],
            ..Report::default()
        });
        assert!(
            section.contains(
                "| titan sim, 1 kHz | event | cross CPU | 100000 | 3 (30) | 1 of 100000 (10) | 0 |"
            ),
            "{section}"
        );
    }

    #[test]
    fn samples_without_their_run_first_are_refused() {
        let (report, _) = run_with_ros2_row(600);
        let samples = report.samples().unwrap();
        let (run, rows) = samples.split_once('\n').unwrap();
        let error = Report::from_samples(&format!("{rows}{run}\n")).unwrap_err();
        assert!(
            error
                .to_string()
                .contains("line 1: the run's line must come first"),
            "{error}"
        );
        assert!(Report::from_samples("{\"row\": 3}").is_err());
    }

    #[test]
    fn a_p99_of_fewer_than_100_samples_is_not_shown_nor_divided() {
        let mut few = measured("preemption", "titan sim", "event", 50, 40);
        few.baseline = Some("warm, cross CPU".into());
        let mut report = Report {
            rows: vec![measured("baseline", "warm", "-", 20, 200), few],
            ..Report::default()
        };
        report.compute_ratios();
        assert!(report.rows[1].ratio_p50.is_some() && report.rows[1].ratio_p99.is_none());
        assert_eq!(
            percentile(report.rows[1].summary.p99_us, 40, MIN_FOR_P99),
            "—"
        );
        assert!(
            report.table().contains("2.50, — | warm, cross CPU |"),
            "{}",
            report.table()
        );
    }
}
