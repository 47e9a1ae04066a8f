//! `chassis-bench`: end-to-end latency of chassisd's real paths against raw-transport baselines,
//! measured in one run so every figure is a ratio that holds on any machine.
//!
//! Four stages, typed data between them:
//! * **measure** ([`run`]: its steps, each planning the rows it measures; `paths.rs`,
//!   `baseline.rs`, `control_loop.rs`, the bridges' scripts) → a [`Report`];
//! * **samples** (`--samples FILE`, [`Report::samples`]): every row's histogram and typed
//!   identity, every split, the run's conditions, as JSON lines;
//! * **verdict** (`verdict.rs`): the targets of `targets.toml`, judged by one comparator;
//! * **render** (`render.rs`, the words in `performance.md`; the table and plot in `report.rs`),
//!   from the samples and the verdict alone: `chassis-bench render SAMPLES` gives the same bytes.
//!
//! `--attach NAME` (or `--bus BUS`, chassisd started on it) measures a user's own robot instead
//! of the simulator: its state and control-loop rows by reading only, the rows that send
//! velocity with `--wheels-off-ground` alone.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use chassis_client::Robot;
use chassis_protocols::RobotKind;
use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};

mod baseline;
mod control_loop;
mod dds_echo;
mod fleet;
mod parts;
mod paths;
mod placement;
mod provenance;
mod python;
mod render;
mod report;
mod stalls;
mod stats;
mod verdict;
mod zenoh;

use baseline::{Load, Rounds, Transport};
use paths::{BusKind, LoopMode, ServiceConfig, Started};
use placement::Placement;
use report::{Leg, PathKind, Planned, Report, Row, path_rows, row_key};
use stats::Latencies;

#[derive(Debug, Parser)]
#[command(
    name = "chassis-bench",
    version,
    about = "Latency of chassisd's command, state, preemption and fan-out paths beside raw \
             iceoryx2, Unix-socket and UDP baselines, in one run"
)]
struct Cli {
    #[command(subcommand)]
    role: Option<RoleCmd>,
    #[command(flatten)]
    run: RunArgs,
}

#[derive(Debug, Subcommand)]
enum RoleCmd {
    /// The table, the document and the plots of a run again, from its samples alone (what
    /// `--samples` wrote): the same samples give the same bytes.
    Render(RenderArgs),
    /// One operator mirroring 1, 5, 10, 20 simulated robots over Zenoh (root): its CPU and
    /// memory, each robot's state latency; `--doc` writes the `## Fleet` section.
    Fleet(fleet::FleetArgs),
    /// (internal) the far end of a measurement.
    #[command(hide = true)]
    Role {
        #[command(subcommand)]
        role: Role,
    },
}

#[derive(Debug, Subcommand)]
enum Role {
    Pong(baseline::PongArgs),
    Feed(baseline::PongArgs),
    Subscribe(paths::SubscribeArgs),
    DdsEcho(dds_echo::EchoArgs),
    /// Publish stamped samples on a bare Zenoh session configured as chassis-zenoh's.
    ZenohPub(zenoh::RawArgs),
    /// Receive them and write their latencies.
    ZenohSub(zenoh::RawArgs),
}

#[derive(Debug, Args)]
struct RunArgs {
    /// A short run: fewer samples, the TITAN on the simulated bus only.
    #[arg(long)]
    quick: bool,
    /// The CI's check of the benchmark itself: a quick run without the throughput replay that
    /// fails (exit 1) when a row it plans is missing or brings less than 90 % of the samples
    /// it asked for (none, for a row measured for a time), when a row is flagged
    /// inconsistent beyond the noise of a debug build's 100 samples (a row below the sum of the
    /// hops it contains, or less than a fifth below its own baseline, is reported, not failed
    /// on), when a baseline a row names was not measured or two rows share a name. Never on a
    /// target: the figures of a shared machine are what they are.
    #[arg(long)]
    smoke: bool,
    /// Write the run's samples (JSON lines: every row with its histogram and typed identity,
    /// every split, the run's conditions), from which `chassis-bench render` renders it again.
    #[arg(long)]
    samples: Option<PathBuf>,
    /// Write latency CDFs of every path as SVG.
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Write the performance document (markdown, e.g. docs/PERFORMANCE.md) from this run.
    #[arg(long)]
    doc: Option<PathBuf>,
    /// Write files (--samples, --plot, --doc) from a tree with uncommitted changes; they then say
    /// DIRTY. Without it such a run is refused: figures written down must belong to a commit.
    #[arg(long)]
    allow_dirty: bool,
    /// Robots for the service paths (full run).
    #[arg(long, value_delimiter = ',', default_values_t = ["titan".to_string(), "scout-mini".to_string(), "xbot".to_string()])]
    robots: Vec<String>,
    /// Skip parts: baselines, paths, loops, fanout, cost, throughput, zenoh.
    #[arg(long, value_delimiter = ',')]
    skip: Vec<String>,
    /// Measure the chassisd already running for robot NAME (under `$CHASSIS_IPC_PREFIX`), not the
    /// simulator: its state rows and the control loops' rows, reading only; the rows that send
    /// velocity with --wheels-off-ground alone.
    #[arg(long, value_name = "NAME", conflicts_with = "bus")]
    attach: Option<String>,
    /// Start chassisd for the first of --robots on this bus (as chassisd takes it: `can:can0`,
    /// `slcan:/dev/ttyACM0`) instead of the simulator, and measure it as --attach does.
    #[arg(long, value_name = "BUS")]
    bus: Option<String>,
    /// With --attach or --bus, measure the rows that send velocity too (the command rows, the
    /// control loops' command → frame): the robot will drive, its wheels must be off the ground.
    #[arg(long)]
    wheels_off_ground: bool,
    /// Scratch directory for logs and sockets, kept afterwards (default: a new one under /tmp,
    /// removed at the end)
    #[arg(long)]
    dir: Option<PathBuf>,
}

#[derive(Debug, Args)]
struct RenderArgs {
    /// The samples file a run wrote (`--samples`).
    samples: PathBuf,
    /// Write latency CDFs of every path as SVG.
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Write the performance document (markdown).
    #[arg(long)]
    doc: Option<PathBuf>,
}

/// Writes the plot and the document of `report` ([`fleet::document`]).
fn render(report: &Report, doc: Option<&Path>, plot: Option<&Path>) -> anyhow::Result<()> {
    if let Some(path) = plot {
        report.plot(path)?;
    }
    if let Some(path) = doc {
        let text = fleet::document(report, std::fs::read_to_string(path).ok().as_deref())?;
        std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// The sizes of a run.
struct Plan {
    baseline_rounds: u64,
    /// Bursts of 200 ms a stall row spins on each CPU.
    stall_bursts: u64,
    paced_rounds: u64,
    commands: u64,
    xbot_commands: u64,
    states: u64,
    preemptions: u64,
    fanout: Vec<usize>,
    fanout_seconds: f64,
    cost_seconds: f64,
    /// How long each control loop runs.
    loop_seconds: f64,
    /// Simulated seconds of the recorded bus the throughput run replays.
    replay_seconds: u64,
}

impl Plan {
    /// A smoke run's (enough samples for every row to exist and its p99 to be shown, no more),
    /// a quick run's or a full run's.
    fn new(smoke: bool, quick: bool) -> Self {
        let size = usize::from(!smoke) + usize::from(!smoke && !quick);
        let n = |sizes: [u64; 3]| sizes[size];
        let s = |seconds: [f64; 3]| seconds[size];
        Self {
            baseline_rounds: n([500, 2000, 20_000]),
            stall_bursts: n([2, 10, 25]),
            paced_rounds: n([100, 500, 2500]),
            commands: n([100, 300, 3000]),
            xbot_commands: n([0, 0, 40]),
            states: n([300, 1000, 10_000]),
            preemptions: n([100, 100, 300]),
            fanout: [vec![2], vec![1, 4], vec![1, 4, 16]][size].clone(),
            fanout_seconds: s([1.0, 1.5, 5.0]),
            cost_seconds: s([1.0, 1.5, 5.0]),
            loop_seconds: s([1.0, 10.0, 150.0]),
            replay_seconds: n([300, 300, 1500]),
        }
    }
}

/// One service configuration to measure.
struct PathRun {
    robot: RobotKind,
    bus: BusKind,
    mode: LoopMode,
    placement: Placement,
}

fn path_runs(quick: bool, robots: &[RobotKind]) -> Vec<PathRun> {
    let run = |robot, bus, mode, placement| PathRun {
        robot,
        bus,
        mode,
        placement,
    };
    // The loops and placements compared on one robot and bus: the TITAN on the simulator.
    let titan_sim = |mode, placement| run(RobotKind::Titan, BusKind::Sim, mode, placement);
    // The service's own pass is held to its target on the simulated and the slcan-pty bus, in
    // both loops.
    let titan_pty = |mode| run(RobotKind::Titan, BusKind::Pty, mode, Placement::CrossCpu);
    if quick {
        return vec![
            titan_sim(LoopMode::Event, Placement::SameCpu),
            titan_sim(LoopMode::Event, Placement::CrossCpu),
            titan_sim(LoopMode::Spin, Placement::CrossCpu),
            titan_pty(LoopMode::Event),
            titan_pty(LoopMode::Spin),
        ];
    }
    let mut runs = vec![
        titan_sim(LoopMode::Event, Placement::SameCpu),
        titan_sim(LoopMode::Spin, Placement::CrossCpu),
        titan_sim(LoopMode::Hybrid, Placement::CrossCpu),
    ];
    for &robot in robots {
        for bus in [BusKind::Sim, BusKind::Pty] {
            runs.push(run(robot, bus, LoopMode::Event, Placement::CrossCpu));
        }
    }
    if robots.contains(&RobotKind::Titan) {
        runs.push(titan_pty(LoopMode::Spin));
    }
    runs
}

/// The raw DDS hops the ROS 2 rows contain (Cyclone DDS is the peer, RustDDS the bridge's).
const DDS_IN: &str = "DDS Cyclone DDS → RustDDS";
const DDS_OUT: &str = "DDS RustDDS → Cyclone DDS";
/// The ROS 2 bridge's rows, after their run's name.
const CMD_VEL: &str = "cmd_vel → frame";
const ODOM: &str = "frame read → odom";

/// The TITAN on the simulated bus with the event loop: the fan-out's service, and the runs the
/// Python client and the ROS 2 bridge are measured beside (same service, same placement as the
/// Rust client's rows).
const TITAN_SIM: (RobotKind, BusKind, LoopMode) = (RobotKind::Titan, BusKind::Sim, LoopMode::Event);

fn bus_label(robot: RobotKind, bus: BusKind) -> String {
    let bus = match (bus, robot.is_can()) {
        (BusKind::Sim, _) => "sim",
        (BusKind::Pty, true) => "slcan pty",
        (BusKind::Pty, false) => "serial pty",
    };
    format!("{robot} {bus}")
}

/// A path's row and its in-service row at `(mode, at)`, as [`path_rows`] names them.
fn plan_path(path: PathKind, what: &str, (mode, at): (&str, &str), asked: u64) -> [Planned; 2] {
    let inside = format!("{what}: {path}");
    [(path, what), (PathKind::InService, &*inside)]
        .map(|(path, what)| Planned::new(row_key(path, what, mode, at), asked))
}

/// The placement of a row whose ends no one pinned.
pub const UNPINNED: &str = "unpinned";

fn baseline_key(what: &str, placement: &str) -> String {
    row_key(PathKind::Baseline, what, "-", placement)
}

struct Ctx {
    plan: Plan,
    prefix: String,
    dir: PathBuf,
    python: Option<PathBuf>,
    ros2: Option<PathBuf>,
    bar: ProgressBar,
}

impl Ctx {
    /// Starts chassisd for `run` in the benchmark's configuration, unpinned, without a trace.
    fn start(&self, run: (RobotKind, BusKind, LoopMode)) -> anyhow::Result<Started> {
        let (prefix, dir) = (&self.prefix, &self.dir);
        paths::start(run, None, ServiceConfig::Bench, false, prefix, dir)
    }
}

/// A part of a run: the rows it plans, declared beside the code that measures them.
trait Step {
    /// Every row the step measures, named as it names them, with the samples it asks for: a
    /// smoke run fails when one of them did not come, or brought too few.
    fn planned(&self, _: &Ctx) -> Vec<Planned> {
        Vec::new()
    }

    fn measure(&self, ctx: &Ctx, report: &mut Report) -> anyhow::Result<()>;
}

fn run(args: &RunArgs) -> anyhow::Result<Report> {
    let plan = Plan::new(args.smoke, args.quick);
    // The smoke run checks rows: the bus-load cost and the replay make none.
    let skip = |part: &str| {
        args.skip.iter().any(|s| s == part) || (args.smoke && matches!(part, "cost" | "throughput"))
    };
    let dir = match &args.dir {
        Some(d) => d.clone(),
        None => std::env::temp_dir().join(format!("chassis-bench-{}", std::process::id())),
    };
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let robots = (args.robots.iter())
        .map(|r| r.parse::<RobotKind>().map_err(anyhow::Error::msg))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let strict = args.samples.is_some() || args.plot.is_some() || args.doc.is_some();
    let provenance = provenance::Provenance::begin(strict, args.allow_dirty)?;
    let mut report = Report {
        machine: report::Machine::probe(),
        provenance,
        ..Report::default()
    };
    if report.machine.cpus < 2 {
        let note = "one CPU only: cross-CPU runs share it";
        report.notes.push(note.into());
    }
    let prefix = format!("cb{}_", std::process::id());
    // A chassisd started on the user's bus stops at the end of the run.
    let (steps, _service) = match (&args.attach, &args.bus) {
        (None, None) => (steps(args, &robots, &plan, skip), None),
        (attach, bus) => {
            let kind = robots.first().copied().unwrap_or(RobotKind::Titan);
            let (attached, service) = Attached::new(args, attach, bus, kind, (&prefix, &dir))?;
            (vec![Box::new(attached) as Box<dyn Step>], service)
        }
    };
    let bar = ProgressBar::new(steps.len() as u64);
    bar.set_style(
        ProgressStyle::with_template("{elapsed:>4} [{bar:30}] {pos}/{len} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    let ctx = Ctx {
        plan,
        prefix,
        dir,
        python: python::interpreter("python"),
        ros2: python::interpreter("ros2"),
        bar,
    };
    for (missing, what, name) in [
        (ctx.python.is_none(), "the Python client", "python"),
        (ctx.ros2.is_none(), "the ROS 2 bridge", "ros2"),
    ] {
        if missing && !skip("paths") && args.attach.is_none() && args.bus.is_none() {
            report.notes.push(format!(
                "{what} was not measured: target/{name}-venv is missing \
                 (scripts/{name}-tests makes it)"
            ));
        }
    }
    // All of them before any is measured: a step that fails to bring a row is caught too.
    report.expected = steps.iter().flat_map(|s| s.planned(&ctx)).collect();
    for step in &steps {
        step.measure(&ctx, &mut report)?;
        ctx.bar.inc(1);
    }
    ctx.bar.finish_and_clear();
    report.compute_ratios();
    report.provenance.end()?;
    // A directory named on the command line keeps its logs.
    if args.dir.is_none() {
        let _ = std::fs::remove_dir_all(&ctx.dir);
    }
    Ok(report)
}

/// The steps of a run, in the order it measures them.
fn steps(
    args: &RunArgs,
    robots: &[RobotKind],
    plan: &Plan,
    skip: impl Fn(&str) -> bool,
) -> Vec<Box<dyn Step>> {
    fn boxed<S: Step + 'static>(steps: impl IntoIterator<Item = S>) -> Vec<Box<dyn Step>> {
        steps.into_iter().map(|s| Box::new(s) as _).collect()
    }
    let mut runs = path_runs(args.quick || args.smoke, robots);
    if args.smoke {
        // The event loop only: a busy-polling loop on a shared 2-core machine measures the
        // machine's other work (a smoke run is about rows, not figures).
        runs.retain(|r| r.mode == LoopMode::Event);
    }
    let hybrid = runs.iter().any(|r| r.mode == LoopMode::Hybrid);
    let mut baselines = boxed(Baseline::all(hybrid));
    baselines.extend(boxed((0..placement::cpu_count()).map(Stalls)));
    let mut paths = boxed(runs);
    paths.extend(boxed([DefaultConfig]));
    paths.extend(boxed([Unrecorded]));
    [
        ("baselines", baselines),
        ("paths", paths),
        ("loops", boxed([Loops(control_loop::plan(args.smoke))])),
        ("fanout", boxed(plan.fanout.iter().copied().map(FanOut))),
        ("zenoh", boxed([Zenoh])),
        ("cost", boxed([Cost])),
        ("throughput", boxed([Throughput])),
    ]
    .into_iter()
    .filter(|(part, _)| !skip(part))
    .flat_map(|(_, steps)| steps)
    .collect()
}

/// A raw transport's round trips: back to back (each transport at its best), or paced like the
/// command path: what a request after a pause meets, the service paths' reference.
#[derive(Clone, Copy)]
struct Baseline(Transport, Placement, Option<Duration>);

impl Baseline {
    fn all(hybrid: bool) -> Vec<Self> {
        use Transport::{IceoryxEvent, IceoryxHybrid, IceoryxSpin, Udp, Uds};
        let paced = Some(paths::off_grid(paths::COMMAND_INTERVAL));
        let (same, cross) = (Placement::SameCpu, Placement::CrossCpu);
        let mut all: Vec<Self> = [IceoryxEvent, Uds, Udp].map(|t| Self(t, same, None)).into();
        all.extend([IceoryxEvent, IceoryxSpin, Uds, Udp].map(|t| Self(t, cross, None)));
        let paced_runs = [
            (IceoryxEvent, same),
            (IceoryxEvent, cross),
            (IceoryxSpin, cross),
        ];
        all.extend(paced_runs.map(|(t, at)| Self(t, at, paced)));
        // The poll-then-block loop's own back-to-back hop, a context row beside the hybrid runs.
        if hybrid {
            all.push(Self(IceoryxHybrid, cross, None));
        }
        all
    }

    fn what(&self) -> String {
        match self.2 {
            Some(_) => format!("{} {}", self.0.label(), report::PACED),
            None => self.0.label().to_string(),
        }
    }
}

impl Step for Baseline {
    fn planned(&self, ctx: &Ctx) -> Vec<Planned> {
        // Back to back, both hops of a round count; paced, the ping's alone.
        let (paced, back_to_back) = (ctx.plan.paced_rounds, 2 * ctx.plan.baseline_rounds);
        let asked = self.2.map_or(back_to_back, |_| paced);
        let key = baseline_key(&self.what(), self.1.label());
        vec![Planned::new(key, asked)]
    }

    fn measure(&self, ctx: &Ctx, report: &mut Report) -> anyhow::Result<()> {
        let (what, Self(transport, placement, pace)) = (self.what(), *self);
        let at = placement.label();
        ctx.bar.set_message(format!("baseline {what} ({at})"));
        let (rounds, shape, conditions) = match pace {
            Some(p) => {
                let text = paths::period_text(p);
                let conditions = format!("one ping every {text}, receiver otherwise idle (cold)");
                (ctx.plan.paced_rounds, Rounds::Paced(p), conditions)
            }
            None => {
                let conditions = "back to back (warm)".into();
                (ctx.plan.baseline_rounds, Rounds::BackToBack, conditions)
            }
        };
        let (prefix, dir) = (&ctx.prefix, &ctx.dir);
        let l = baseline::run(
            transport,
            placement.cpus(),
            rounds,
            shape,
            None,
            prefix,
            dir,
        )?;
        (report.rows).push(Row::hop("", what, at, l.all_pings(), conditions));
        Ok(())
    }
}

/// How often CPU `.0` stalls a thread that never blocks.
struct Stalls(usize);

impl Step for Stalls {
    fn planned(&self, _: &Ctx) -> Vec<Planned> {
        let key = baseline_key(report::STALLS, &format!("CPU {}", self.0));
        vec![Planned::new(key, None)]
    }

    fn measure(&self, ctx: &Ctx, report: &mut Report) -> anyhow::Result<()> {
        let cpu = self.0;
        ctx.bar.set_message(format!("stalls on CPU {cpu}"));
        let stalls = stalls::measure(cpu, ctx.plan.stall_bursts, paths::REALTIME_PRIORITY)?;
        report.stalls.push(report::StallRates {
            cpu,
            over_20_us: stalls.per_second(20),
            over_100_us: stalls.per_second(100),
        });
        let (at, conditions) = (format!("CPU {cpu}"), stalls.conditions(cpu));
        let mut row = Row::hop("", report::STALLS.into(), &at, stalls.gaps, conditions);
        row.leg = Leg::Stalls;
        report.rows.push(row);
        Ok(())
    }
}

/// What a run's service measured, with the Python client and the ROS 2 bridge beside it.
struct ServiceRun {
    command: Option<paths::CommandFigures>,
    state: paths::StateRecorder,
    preempt: (Latencies, u64),
    python: Option<python::PythonFigures>,
    ros2: Option<python::Ros2Figures>,
    feed_per_s: f64,
    realtime: Option<u8>,
    passes: Vec<paths::PassStamps>,
}

impl PathRun {
    fn label(&self) -> String {
        bus_label(self.robot, self.bus)
    }

    /// (commands, preemptions, the interval between commands).
    fn sizes(&self, plan: &Plan) -> (u64, u64, Duration) {
        if self.robot == RobotKind::Xbot {
            // The XBot's manual caps the command rate below 10 Hz: a change goes out at once
            // only while the last second holds a free slot.
            let interval = paths::XBOT_COMMAND_INTERVAL;
            (plan.xbot_commands, plan.preemptions / 15, interval)
        } else {
            (plan.commands, plan.preemptions, paths::COMMAND_INTERVAL)
        }
    }

    fn key(&self, path: PathKind, what: &str) -> String {
        row_key(path, what, self.mode.arg(), self.placement.label())
    }

    fn plan(&self, path: PathKind, what: &str, asked: u64) -> Planned {
        Planned::new(self.key(path, what), asked)
    }

    fn plan_path(&self, path: PathKind, what: &str, asked: u64) -> [Planned; 2] {
        plan_path(path, what, (self.mode.arg(), self.placement.label()), asked)
    }

    /// `<run>: <what>`: the Python client's and the ROS 2 bridge's rows.
    fn of(&self, what: &str) -> String {
        format!("{}: {what}", self.label())
    }

    /// The raw DDS hop `dds`, named after this run: a full run measures the bridge beside more
    /// than one.
    fn beside(&self, dds: &str) -> String {
        format!("{dds}, beside {}", self.label())
    }

    /// The baselines loaded as this run's service was: paced, the feed's own hops, published,
    /// after a wake-up ping.
    fn loaded(&self) -> [String; 4] {
        let t = Transport::like(self.mode).label();
        let whats = [
            "paced",
            "at the feedback rate",
            "published",
            "after a wake-up ping",
        ];
        whats.map(|what| format!("{t} {what}, loaded as {}", self.label()))
    }

    fn reference(&self, what: &str) -> Option<String> {
        Some(format!("{what}, {}", self.placement.label()))
    }

    /// This run's rows, at its mode and placement; its baselines', at its placement.
    fn row(&self, path: PathKind, leg: Leg, what: String, l: Latencies, missed: u64) -> Row {
        let (mode, placement) = (self.mode.arg(), self.placement.label());
        Row::new(path, leg, &self.label(), what, mode, placement, l, missed)
    }

    fn hop_row(&self, what: String, l: Latencies, conditions: String) -> Row {
        Row::hop(&self.label(), what, self.placement.label(), l, conditions)
    }

    /// Starts chassisd for this run, configured as `config` says, on the service's CPU.
    fn start(&self, ctx: &Ctx, config: ServiceConfig, trace: bool) -> anyhow::Result<Started> {
        let (run, cpu) = ((self.robot, self.bus, self.mode), self.placement.cpus().1);
        paths::start(run, cpu, config, trace, &ctx.prefix, &ctx.dir)
    }

    /// The command path (when the run sends commands) and the state path of `robot`, each
    /// from a teleop source of its own.
    fn command_and_state(
        &self,
        ctx: &Ctx,
        robot: &mut Robot,
    ) -> anyhow::Result<(Option<paths::CommandFigures>, paths::StateRecorder)> {
        let (count, _, interval) = self.sizes(&ctx.plan);
        let spin = self.mode == LoopMode::Spin;
        let mut command = None;
        if count > 0 {
            let (t, exact) = (&mut robot.source("teleop")?, paths::Reach::Exact);
            let (kind, sizes) = ((self.robot, spin), (count, interval));
            command = Some(paths::command_path(robot, kind, t, sizes, exact)?);
        }
        let (mut state, mut teleop) = (paths::StateRecorder::default(), robot.source("teleop")?);
        let sizes = (ctx.plan.states, spin);
        paths::state_path(robot, Some(&mut teleop), &mut state, sizes, |_, _| {})?;
        Ok((command, state))
    }

    /// Starts the service and measures its paths, the scripts' beside them.
    fn service(&self, ctx: &Ctx, report: &mut Report) -> anyhow::Result<ServiceRun> {
        let (label, mode) = (self.label(), self.mode.arg());
        let title = format!("{label}, {mode} loop, {}", self.placement.label());
        ctx.bar.set_message(title.clone());
        let (service, mut robot) = self.start(ctx, ServiceConfig::BenchRealtime, true)?;
        let spin = self.mode == LoopMode::Spin;
        let (count, preemptions, interval) = self.sizes(&ctx.plan);
        let feedback = paths::FeedbackRate::start(&mut robot)?;
        let result = paths::pinned(self.placement.cpus().0, || -> anyhow::Result<_> {
            let (command, state) = self.command_and_state(ctx, &mut robot)?;
            let preempt = paths::preemption(&mut robot, self.robot, preemptions, interval, spin)?;
            // The Python client and the ROS 2 bridge beside the Rust one.
            let (mut python, mut ros2) = (None, None);
            let beside = (self.robot, self.bus, self.mode) == TITAN_SIM;
            if beside && (ctx.python.is_some() || ctx.ros2.is_some()) {
                let run = python::ScriptRun {
                    name: robot.name(),
                    prefix: &ctx.prefix,
                    chassis_cli: &paths::sibling("chassis")?,
                    dir: &ctx.dir,
                    states: ctx.plan.states,
                    commands: count,
                    interval,
                };
                if let Some(interpreter) = &ctx.python {
                    python = Some(python::run(interpreter, &run)?);
                }
                if let Some(interpreter) = &ctx.ros2 {
                    ros2 = Some(python::run_ros2(interpreter, &run)?);
                }
            }
            Ok((command, state, preempt, python, ros2))
        })??;
        let (command, state, preempt, python, ros2) = result;
        let feed_per_s = feedback.per_second(&mut robot)?;
        drop(robot);
        let scheduling = service.scheduling;
        if scheduling.fifo().is_some() {
            // Real-time mode locks every page the process maps.
            let rss = paths::rss_mib(service.pid)?;
            report.realtime_rss_mib = Some(report.realtime_rss_mib.map_or(rss, |m| m.max(rss)));
        }
        report.scheduling.push((title, scheduling));
        let passes = service.stop()?;
        Ok(ServiceRun {
            command,
            state,
            preempt,
            python,
            ros2,
            feed_per_s,
            realtime: scheduling.fifo(),
            passes,
        })
    }

    /// The baselines of this run's rows: their receiver lives like the service's loop did —
    /// woken by another process at the chassis' feedback rate, its own tick, the same placement
    /// and the same way of waiting.
    fn baselines(&self, ctx: &Ctx, run: &ServiceRun, rows: &mut Vec<Row>) -> anyhow::Result<()> {
        let (label, transport) = (self.label(), Transport::like(self.mode));
        let (feed_per_s, states) = (run.feed_per_s, run.state.latencies.count());
        let (_, _, interval) = self.sizes(&ctx.plan);
        let tick = self.robot.entry().defaults().heartbeat_period();
        let (realtime, published) = (run.realtime, false);
        let load = Load {
            feed_per_s,
            tick,
            realtime,
            published,
        };
        // The feed runs where chassisd put its simulated chassis (`baseline::feed_cpu`).
        let (feed_where, fifo) = match run.realtime {
            Some(_) => ("on the receiver's CPU", load.fifo_text()),
            None => ("on the other CPU", String::new()),
        };
        let conditions = format!(
            "receiver woken {feed_per_s:.0}/s by another process {feed_where}, as by the \
             simulated chassis (the feedback rate measured in the {label} run), and by its \
             own {} ms tick{fifo}",
            tick.as_millis()
        );
        let [paced, feed_what, published, warm] = self.loaded();
        let measure = |what: String, rounds, shape, load| {
            ctx.bar.set_message(format!("baseline as {label}: {what}"));
            let (cpus, prefix, dir) = (self.placement.cpus(), &ctx.prefix, &ctx.dir);
            baseline::run(transport, cpus, rounds, shape, Some(load), prefix, dir)
        };
        // The rounds of `period` in which the feed brings `more` times `wanted` samples.
        let rounds_for = |wanted: u64, period: Duration, more: f64| {
            (more * wanted as f64 / (feed_per_s * period.as_secs_f64()).max(1e-9)).ceil() as u64
        };
        // As many samples as the rows each part divides: the command row's pings, the state
        // row's feed hops (the run lasts until the feed made that many). A tenth more: the
        // feed starts after the receiver and keeps its own pace.
        let pings_wanted =
            (run.command.as_ref()).map_or(ctx.plan.paced_rounds, |c| c.latencies.count());
        let rounds = pings_wanted.max(rounds_for(states, interval, 1.1)) + 1;
        let pace = paths::off_grid(interval);
        let woken = format!("{} woken {feed_per_s:.0}/s", transport.label());
        let measured = measure(woken, rounds, Rounds::Paced(pace), load)?;
        let pings = baseline::last_of(&measured.pings, pings_wanted);
        let text = format!(
            "one ping every {}, the last {pings_wanted} of {rounds}; {conditions}",
            paths::period_text(pace)
        );
        rows.push(self.hop_row(paced, pings, text));
        if let Some(feed) = measured.feed {
            // As many hops as the state row has samples: the last ones, the receiver warm.
            let hops = baseline::last_of(&feed, states);
            let text = format!(
                "the feed's own hops: {feed_per_s:.0}/s, the last {states} of {}; {conditions}",
                feed.len()
            );
            rows.push(self.hop_row(feed_what, hops, text));
        }
        // The state row's hop, in a run of its own: its client sends a request every
        // STATE_REQUEST_INTERVAL, not one every command period (pings every 4 ms would keep
        // the reader's CPU awake, and its wake-up cheaper than the state path's). A quarter
        // more: the receiver publishes once per wake-up, which may take more than one feed
        // sample.
        let state_rounds = rounds_for(states, paths::STATE_REQUEST_INTERVAL, 1.25) + 1;
        let shape = Rounds::Paced(paths::STATE_REQUEST_INTERVAL);
        let what = format!("{} published, loaded", transport.label());
        let state_load = Load {
            published: true,
            ..load
        };
        // From the receiver, which lives as the loop does, to a reader that lives as the client
        // does.
        if let Some(hops) = measure(what, state_rounds, shape, state_load)?.published {
            let reader = match self.placement {
                Placement::SameCpu => "on the receiver's CPU",
                Placement::CrossCpu => "on the other CPU",
            };
            let waiting = match self.mode {
                LoopMode::Spin => "polling",
                LoopMode::Event | LoopMode::Hybrid => "blocked on its listener between drains",
            };
            let text = format!(
                "one sample published by the receiver each time it took the feed's samples, \
                 as chassisd publishes its state after each feedback frame that changed it, \
                 read at normal scheduling {reader}, {waiting}, as the client reads the \
                 state, while the ping side sends one ping every {} ms as the state path's \
                 client sends a request: the last {states} of {}; {conditions}",
                paths::STATE_REQUEST_INTERVAL.as_millis(),
                hops.len()
            );
            rows.push(self.hop_row(published, baseline::last_of(&hops, states), text));
        }
        // The preemption's stop follows a teleop request at once, while the loop is waking
        // for it: its baseline is a ping right after a lead ping, loaded as the service was,
        // with as many samples.
        let warm_rounds = run.preempt.0.count().max(1);
        let what = format!("{} after a wake-up ping, loaded", transport.label());
        let warm_measured = measure(what, warm_rounds, Rounds::AfterWakeUp, load)?;
        let text = format!(
            "{warm_rounds} pings, each sent right after a lead ping that wakes the receiver \
             (only the second ping's hop counts), back to back after a warm-up; {conditions}"
        );
        rows.push(self.hop_row(warm, warm_measured.all_pings(), text));
        Ok(())
    }

    /// Where the time of this run's paths goes.
    fn parts(&self, run: &ServiceRun, out: &mut Vec<report::Parts>) {
        let label = self.label();
        let mut push = |path: &str, of, split| {
            out.push(report::Parts {
                path: path.into(),
                of,
                run: label.clone(),
                what: label.clone(),
                mode: self.mode.arg().into(),
                placement: self.placement.label().into(),
                split,
            })
        };
        let passes = &run.passes;
        if let Some(figures) = &run.command {
            let split = parts::command(&figures.samples, passes, self.mode == LoopMode::Spin);
            push("command", (PathKind::Command, Leg::Command), split);
        }
        let split = parts::state(&run.state.samples, passes);
        push("state", (PathKind::State, Leg::State), split);
        if let Some(dds) = &run.ros2 {
            let split = parts::odom(&dds.odom_pairs, &dds.odom_trace, passes);
            let of = (PathKind::Ros2, Leg::Odom);
            push("ros2: frame read → odom", of, split);
        }
        if let Some(py) = &run.python {
            let split = parts::python_state(&py.state_stamps, passes);
            push(report::PYTHON_PARTS, (PathKind::Python, Leg::State), split);
        }
    }

    /// The ROS 2 bridge's rows, and the raw DDS hops they contain.
    fn ros2_rows(&self, dds: python::Ros2Figures, interval: Duration, rows: &mut Vec<Row>) {
        let conditions = |pace: String, carried: &str| {
            format!(
                "one message every {pace} after 200 uncounted, {carried}, measured by the ROS 2 \
                 run's own script, same run"
            )
        };
        let (dds_in, dds_out) = (self.beside(DDS_IN), self.beside(DDS_OUT));
        let pace_in = format!("{} (the cmd_vel path's)", paths::period_text(interval));
        let carried_in = "a TwistStamped read with the bridge's cmd_vel QoS";
        rows.push(self.hop_row(dds_in.clone(), dds.raw_in, conditions(pace_in, carried_in)));
        let pace_out = format!(
            "{} (the period of the odoms the path counted, 1.7 % more)",
            paths::period_text(dds.raw_out_period)
        );
        let carried_out = "an Odometry written as the bridge writes odom (its writer QoS)";
        let conditions_out = conditions(pace_out, carried_out);
        rows.push(self.hop_row(dds_out.clone(), dds.raw_out, conditions_out));
        let (label, at) = (self.label(), self.placement.label());
        let (what, l) = (self.of(CMD_VEL), dds.command);
        let mut command = self.row(PathKind::Ros2, Leg::CmdVel, what, l, dds.missed);
        command.baseline = self.reference(&dds_in);
        // The DDS hop in, then the service's command path.
        let path = self.key(PathKind::Command, &label);
        command.contains = vec![baseline_key(&dds_in, at), path];
        rows.push(command);
        let mut state = self.row(PathKind::Ros2, Leg::Odom, self.of(ODOM), dds.state, 0);
        state.baseline = self.reference(&dds_out);
        // The service's state path, then the DDS hop out.
        let path = self.key(PathKind::State, &label);
        state.contains = vec![path, baseline_key(&dds_out, at)];
        rows.push(state);
    }
}

impl Step for PathRun {
    fn planned(&self, ctx: &Ctx) -> Vec<Planned> {
        let (plan, label, placement) = (&ctx.plan, self.label(), self.placement.label());
        let (commands, preemptions, _) = self.sizes(plan);
        // A matched baseline has as many samples as the row it divides.
        let paced = plan.paced_rounds;
        let pings = if commands > 0 { commands } else { paced };
        let asked = [pings, plan.states, plan.states, preemptions];
        let mut rows: Vec<Planned> = (self.loaded().iter().zip(asked))
            .map(|(what, asked)| Planned::new(baseline_key(what, placement), asked))
            .collect();
        if commands > 0 {
            rows.extend(self.plan_path(PathKind::Command, &label, commands));
        }
        rows.extend(self.plan_path(PathKind::State, &label, plan.states));
        rows.push(self.plan(PathKind::Preemption, &label, preemptions));
        if (self.robot, self.bus, self.mode) != TITAN_SIM {
            return rows;
        }
        if ctx.python.is_some() {
            for (what, asked) in [("state", plan.states), ("command", commands)] {
                rows.push(self.plan(PathKind::Python, &self.of(what), asked));
            }
        }
        if ctx.ros2.is_some() {
            for (what, dds, asked) in [(CMD_VEL, DDS_IN, commands), (ODOM, DDS_OUT, plan.states)] {
                rows.push(self.plan(PathKind::Ros2, &self.of(what), asked));
                let hop = baseline_key(&self.beside(dds), placement);
                rows.push(Planned::new(hop, asked));
            }
        }
        rows
    }

    fn measure(&self, ctx: &Ctx, report: &mut Report) -> anyhow::Result<()> {
        let run = self.service(ctx, report)?;
        let rows = &mut report.rows;
        self.baselines(ctx, &run, rows)?;
        self.parts(&run, &mut report.parts);
        if let Some(dds) = run.ros2 {
            self.ros2_rows(dds, self.sizes(&ctx.plan).2, rows);
        }
        if let Some(py) = run.python {
            let mut state = self.row(PathKind::Python, Leg::State, self.of("state"), py.state, 0);
            state.dropped = py.dropped;
            rows.push(state);
            let what = self.of("command");
            rows.push(self.row(PathKind::Python, Leg::Command, what, py.command, py.missed));
        }
        let (label, [paced, _, published, warm]) = (self.label(), self.loaded());
        if let Some(figures) = run.command {
            let (l, missed) = (figures.latencies, figures.missed);
            let row = self.row(PathKind::Command, Leg::Command, label.clone(), l, missed);
            rows.extend(path_rows(row, self.reference(&paced), figures.in_service));
        }
        let (state, leg) = (run.state, Leg::State);
        let mut row = self.row(PathKind::State, leg, label.clone(), state.latencies, 0);
        row.dropped = state.dropped;
        rows.extend(path_rows(row, self.reference(&published), state.in_service));
        let (preempt, missed) = run.preempt;
        let mut row = self.row(PathKind::Preemption, Leg::Stop, label, preempt, missed);
        // The stop follows a teleop request at once: the loop is awake, as in a
        // back-to-back ping-pong.
        row.baseline = self.reference(&warm);
        rows.push(row);
        Ok(())
    }
}

/// chassisd as it ships beside the benchmark's configuration: the TITAN on the simulated bus,
/// event loop, cross CPU, against the same matched baseline as that run's row.
struct DefaultConfig;

const DEFAULT_CONFIG: PathRun = PathRun {
    robot: RobotKind::Titan,
    bus: BusKind::Sim,
    mode: LoopMode::Event,
    placement: Placement::CrossCpu,
};

impl Step for DefaultConfig {
    fn planned(&self, ctx: &Ctx) -> Vec<Planned> {
        let (what, commands) = (report::DEFAULT_CONFIG_ROW, ctx.plan.commands);
        let rows = DEFAULT_CONFIG.plan_path(PathKind::Command, what, commands);
        rows.into()
    }

    fn measure(&self, ctx: &Ctx, report: &mut Report) -> anyhow::Result<()> {
        let run = DEFAULT_CONFIG;
        let message = "titan sim in chassisd's default configuration";
        ctx.bar.set_message(message);
        let (service, mut robot) = run.start(ctx, ServiceConfig::Default, false)?;
        let figures = paths::pinned(run.placement.cpus().0, || -> anyhow::Result<_> {
            let sizes = (ctx.plan.commands, paths::COMMAND_INTERVAL);
            let (t, toward) = (&mut robot.source("teleop")?, paths::Reach::Toward);
            paths::command_path(&mut robot, (run.robot, false), t, sizes, toward)
        })??;
        drop(robot);
        drop(service);
        let (l, missed) = (figures.latencies, figures.missed);
        let what = report::DEFAULT_CONFIG_ROW.to_string();
        let row = run.row(PathKind::Command, Leg::FirstFrameToward, what, l, missed);
        let [paced, ..] = run.loaded();
        let rows = path_rows(row, run.reference(&paced), figures.in_service);
        report.rows.extend(rows);
        Ok(())
    }
}

/// The command and the state of the TITAN on the simulated bus, event loop, cross CPU, as the
/// table's run of it but with the black box off: what recording costs them, each row beside the
/// recording run's and against the same matched baselines.
struct Unrecorded;

impl Step for Unrecorded {
    fn planned(&self, ctx: &Ctx) -> Vec<Planned> {
        let (what, plan) = (report::UNRECORDED_ROW, &ctx.plan);
        let run = DEFAULT_CONFIG;
        let mut rows = Vec::from(run.plan_path(PathKind::Command, what, plan.commands));
        rows.extend(run.plan_path(PathKind::State, what, plan.states));
        rows
    }

    fn measure(&self, ctx: &Ctx, report: &mut Report) -> anyhow::Result<()> {
        let run = DEFAULT_CONFIG;
        ctx.bar.set_message(report::UNRECORDED_ROW);
        // Traced as the recording run is: the same work in the loop but the recording.
        let config = ServiceConfig::BenchRealtimeUnrecorded;
        let (service, mut robot) = run.start(ctx, config, true)?;
        let cpu = run.placement.cpus().0;
        let measured = paths::pinned(cpu, || run.command_and_state(ctx, &mut robot))??;
        drop(robot);
        drop(service);
        let (what, [paced, _, published, _]) = (report::UNRECORDED_ROW.to_string(), run.loaded());
        let (command, state) = measured;
        if let Some(command) = command {
            let (l, missed) = (command.latencies, command.missed);
            let row = run.row(PathKind::Command, Leg::Command, what.clone(), l, missed);
            let reference = run.reference(&paced);
            report
                .rows
                .extend(path_rows(row, reference, command.in_service));
        }
        let mut row = run.row(PathKind::State, Leg::State, what, state.latencies, 0);
        row.dropped = state.dropped;
        report
            .rows
            .extend(path_rows(row, run.reference(&published), state.in_service));
        Ok(())
    }
}

/// The rows of a control loop of `period` over `run` (robot and bus) at `at` with chassisd's
/// loop `mode`, lasting `seconds`: the period → frame row (a command the next period's
/// superseded is what the row measures, not a loss), the state's age, the raw loop's hop (cross
/// CPU).
fn loop_rows(
    run: &str,
    at: &str,
    (period, mode): (Duration, LoopMode),
    seconds: f64,
) -> [Planned; 3] {
    let periods = Some(control_loop::periods(period, seconds));
    let [frame, age, hop] = control_loop::row_names(run, period, Transport::like(mode));
    [
        Planned::new(row_key(PathKind::Loop, &frame, mode.arg(), at), None),
        Planned::new(row_key(PathKind::Loop, &age, mode.arg(), at), periods),
        Planned::new(baseline_key(&hop, Placement::CrossCpu.label()), periods),
    ]
}

/// The control loops of [`control_loop::plan`].
struct Loops(Vec<(Duration, LoopMode)>);

impl Step for Loops {
    fn planned(&self, ctx: &Ctx) -> Vec<Planned> {
        let (run, at) = (
            bus_label(RobotKind::Titan, BusKind::Sim),
            Placement::CrossCpu.label(),
        );
        let seconds = ctx.plan.loop_seconds;
        (self.0.iter())
            .flat_map(|&(period, mode)| loop_rows(&run, at, (period, mode), seconds))
            .collect()
    }

    fn measure(&self, ctx: &Ctx, report: &mut Report) -> anyhow::Result<()> {
        ctx.bar.set_message("control loops at 1 kHz and 100 Hz");
        let seconds = ctx.plan.loop_seconds;
        control_loop::run(&self.0, seconds, &ctx.prefix, &ctx.dir, report)
    }
}

/// A chassisd the run did not start as one of its configurations: the user's robot
/// (`--attach NAME`), or chassisd started on the user's bus (`--bus`), at its own loop and
/// configuration, unpinned. Its state path and the control loops (event-driven, as a client
/// waits) read it; the rows that send velocity are measured with `--wheels-off-ground` only,
/// and listed as withheld otherwise.
struct Attached {
    name: String,
    /// The IPC prefix it serves under (none: `$CHASSIS_IPC_PREFIX`).
    prefix: Option<String>,
    kind: RobotKind,
    /// Robot and bus: `titan can:can0`, `titan attached as base`.
    run: String,
    drive: bool,
    loops: Vec<Duration>,
}

/// An attached run's rows' loop and placement: the client waits for events, unpinned.
const ATTACHED: (&str, &str) = ("event", UNPINNED);

impl Attached {
    /// The chassisd of `--attach` (its robot read from its description), or chassisd started
    /// for `kind` on `--bus` (returned, stopped on drop).
    fn new(
        args: &RunArgs,
        attach: &Option<String>,
        bus: &Option<String>,
        kind: RobotKind,
        (prefix, dir): (&str, &Path),
    ) -> anyhow::Result<(Self, Option<Started>)> {
        let loops = control_loop::plan(args.smoke).into_iter();
        let loops = loops
            .filter(|l| l.1 == LoopMode::Event)
            .map(|l| l.0)
            .collect();
        let (name, prefix, kind, run, started) = match bus {
            Some(bus) => {
                let name = format!("bn{}", placement::unique());
                let children = paths::Children::default();
                let started = paths::launch((kind, &name, bus), &[], &[], children, prefix, dir)?;
                let run = format!("{kind} {bus}");
                (name, Some(prefix.to_string()), kind, run, Some(started))
            }
            None => {
                let name = attach.clone().unwrap_or_default();
                let robot = Robot::connect(&name).with_context(|| format!("attaching to {name}"));
                let described = robot?.description(Duration::from_secs(5))?;
                let kind: RobotKind = described.kind_name().parse().map_err(anyhow::Error::msg)?;
                let run = format!("{kind} attached as {name}");
                (name, None, kind, run, None)
            }
        };
        let drive = args.wheels_off_ground;
        let attached = Self {
            name,
            prefix,
            kind,
            run,
            drive,
            loops,
        };
        Ok((attached, started))
    }

    fn loop_rows(&self, ctx: &Ctx) -> impl Iterator<Item = [Planned; 3]> {
        let (run, seconds) = (&self.run, ctx.plan.loop_seconds);
        (self.loops.iter()).map(move |&p| loop_rows(run, UNPINNED, (p, LoopMode::Event), seconds))
    }

    /// The rows that send velocity: the command path and its in-service row, the loops' period
    /// → frame.
    fn sending(&self, ctx: &Ctx) -> Vec<Planned> {
        let commands = ctx.plan.commands;
        let mut rows: Vec<Planned> =
            plan_path(PathKind::Command, &self.run, ATTACHED, commands).into();
        rows.extend(self.loop_rows(ctx).map(|[frame, ..]| frame));
        rows
    }

    fn row(&self, path: PathKind, leg: Leg, l: Latencies, missed: u64) -> Row {
        let run = &self.run;
        let (mode, at) = ATTACHED;
        Row::new(path, leg, run, run.clone(), mode, at, l, missed)
    }
}

impl Step for Attached {
    fn planned(&self, ctx: &Ctx) -> Vec<Planned> {
        let states = ctx.plan.states;
        let mut rows: Vec<Planned> = plan_path(PathKind::State, &self.run, ATTACHED, states).into();
        // The raw loop runs beside a chassisd it does not control, which may take its receiver's
        // CPU long enough to lose pings: shown as missed, not failed on.
        let hop = |hop: Planned| Planned { asked: None, ..hop };
        rows.extend(
            self.loop_rows(ctx)
                .flat_map(|[_, age, raw]| [age, hop(raw)]),
        );
        if self.drive {
            rows.extend(self.sending(ctx));
        }
        rows
    }

    fn measure(&self, ctx: &Ctx, report: &mut Report) -> anyhow::Result<()> {
        ctx.bar.set_message(self.run.clone());
        let connect = || Robot::connect_with_prefix(&self.name, self.prefix.as_deref()).ok();
        let mut robot = paths::wait_until(&format!("no chassisd for {}", self.name), 5, connect)?;
        if !self.drive {
            let withheld = self.sending(ctx).into_iter();
            report
                .withheld
                .extend(withheld.map(|p| (p.key, report::Withheld::WheelsOnGround)));
        }
        let mut teleop = self.drive.then(|| robot.source("teleop")).transpose()?;
        let mut state = paths::StateRecorder::default();
        let sizes = (ctx.plan.states, false);
        paths::state_path(&robot, teleop.as_mut(), &mut state, sizes, |_, _| {})?;
        let mut row = self.row(PathKind::State, Leg::State, state.latencies, 0);
        row.dropped = state.dropped;
        report.rows.extend(path_rows(row, None, state.in_service));
        if let Some(teleop) = teleop.as_mut() {
            // The robot's own configuration may ramp a change: the first frame toward it.
            let (kind, sizes) = (
                (self.kind, false),
                (ctx.plan.commands, paths::COMMAND_INTERVAL),
            );
            let reach = paths::Reach::Toward;
            let figures = paths::command_path(&mut robot, kind, teleop, sizes, reach)?;
            let (l, missed) = (figures.latencies, figures.missed);
            let row = self.row(PathKind::Command, Leg::FirstFrameToward, l, missed);
            report.rows.extend(path_rows(row, None, figures.in_service));
        }
        drop(teleop);
        let over = control_loop::Over {
            run: self.run.clone(),
            kind: self.kind,
            mode: LoopMode::Event,
            placement: None,
            realtime: None,
        };
        for &period in &self.loops {
            let measured = over.measure(&mut robot, period, ctx.plan.loop_seconds, self.drive)?;
            over.record(measured, period, (&ctx.prefix, &ctx.dir), report)?;
        }
        Ok(())
    }
}

/// The TITAN's state on the simulated bus in `.0` subscriber processes.
struct FanOut(usize);

impl FanOut {
    fn what(&self) -> String {
        format!("titan sim → {} processes", self.0)
    }
}

impl Step for FanOut {
    fn planned(&self, _: &Ctx) -> Vec<Planned> {
        let key = row_key(PathKind::FanOut, &self.what(), "event", UNPINNED);
        vec![Planned::new(key, None)]
    }

    fn measure(&self, ctx: &Ctx, report: &mut Report) -> anyhow::Result<()> {
        let n = self.0;
        ctx.bar
            .set_message(format!("fan-out to {n} subscriber processes"));
        let (service, mut robot) = ctx.start(TITAN_SIM)?;
        let seconds = ctx.plan.fanout_seconds;
        let l = paths::fan_out(&mut robot, &service.name, &ctx.prefix, n, seconds)?;
        let run = bus_label(RobotKind::Titan, BusKind::Sim);
        let (path, leg, what) = (PathKind::FanOut, Leg::FanOut, self.what());
        (report.rows).push(Row::new(path, leg, &run, what, "event", UNPINNED, l, 0));
        Ok(())
    }
}

/// chassis-zenoh between two network namespaces, beside bare Zenoh hops.
struct Zenoh;

impl Step for Zenoh {
    fn planned(&self, ctx: &Ctx) -> Vec<Planned> {
        if !zenoh::possible() {
            return Vec::new();
        }
        let (commands, states, at) = (ctx.plan.commands, ctx.plan.states, zenoh::PLACEMENT);
        let zenoh = |what| row_key(PathKind::Zenoh, what, "event", at);
        vec![
            Planned::new(baseline_key(zenoh::RAW_COMMAND, at), commands),
            Planned::new(baseline_key(zenoh::RAW_STATE, at), states),
            Planned::new(zenoh(zenoh::COMMAND), commands),
            Planned::new(zenoh(zenoh::STATE), states),
            Planned::new(zenoh(zenoh::BRIDGE), states),
        ]
    }

    fn measure(&self, ctx: &Ctx, report: &mut Report) -> anyhow::Result<()> {
        if !zenoh::possible() {
            let note = "chassis-zenoh was not measured: its network namespaces need root";
            report.notes.push(note.into());
            return Ok(());
        }
        ctx.bar
            .set_message("chassis-zenoh between two network namespaces");
        let (commands, states) = (ctx.plan.commands, ctx.plan.states);
        zenoh::run(&ctx.prefix, &ctx.dir, commands, states, report)
    }
}

/// The service's cost at full load of a bus.
struct Cost;

impl Step for Cost {
    fn measure(&self, ctx: &Ctx, report: &mut Report) -> anyhow::Result<()> {
        // The simulated bus reads up to 256 frames per system call; an slcan adapter on a pty is
        // read as a byte stream, as a USB adapter on a robot is: the target is judged on the
        // worse of the two.
        for (bus, label) in [(BusKind::Sim, "sim"), (BusKind::Pty, "slcan-pty")] {
            let message = format!("service cost at 100 % load of the {label} bus");
            ctx.bar.set_message(message);
            let (service, mut robot) = ctx.start((RobotKind::Titan, bus, LoopMode::Event))?;
            for bitrate in [500_000, 1_000_000] {
                let seconds = ctx.plan.cost_seconds;
                let ring = ctx
                    .dir
                    .join(format!("state/chassisd/{}/blackbox", service.name));
                let service = (service.pid, ring.as_path());
                let cost = paths::cost_at(&mut robot, label, service, bitrate, seconds)?;
                report.cost.push(cost);
            }
        }
        Ok(())
    }
}

/// A recorded bus replayed at full speed.
struct Throughput;

impl Step for Throughput {
    fn measure(&self, ctx: &Ctx, report: &mut Report) -> anyhow::Result<()> {
        ctx.bar
            .set_message("replaying a recorded bus at full speed");
        let file = ctx.dir.join("titan.log");
        let frames = paths::record_titan(&file, ctx.plan.replay_seconds)?;
        for recorder in [true, false] {
            for _ in 0..report::REPLAYS {
                let replay = paths::replay(&file, frames, recorder, &ctx.prefix, &ctx.dir)?;
                report.throughput.push(replay);
            }
        }
        Ok(())
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.role {
        Some(RoleCmd::Role { role }) => match role {
            Role::Pong(args) => baseline::pong(&args),
            Role::Feed(args) => baseline::feed(&args),
            Role::Subscribe(args) => paths::subscribe(&args),
            Role::DdsEcho(args) => dds_echo::run(&args),
            Role::ZenohPub(args) => zenoh::publish(&args),
            Role::ZenohSub(args) => zenoh::subscribe(&args),
        },
        Some(RoleCmd::Render(args)) => std::fs::read_to_string(&args.samples)
            .with_context(|| format!("reading {}", args.samples.display()))
            .and_then(|text| Report::from_samples(&text))
            .and_then(|report| {
                print!("{}", report.table());
                render(&report, args.doc.as_deref(), args.plot.as_deref())
            }),
        Some(RoleCmd::Fleet(args)) => {
            fleet::run(&args).and_then(|report| fleet::write(&report, &args))
        }
        None => run(&cli.run).and_then(|report| write(&cli.run, &report)),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("chassis-bench: {err:#}");
            ExitCode::FAILURE
        }
    }
}

/// Prints a run's table, writes its files, and judges a smoke run.
fn write(args: &RunArgs, report: &Report) -> anyhow::Result<()> {
    print!("{}", report.table());
    for (key, why) in &report.withheld {
        println!("not measured: {key}: {why:?}");
    }
    let samples = report.samples()?;
    if let Some(path) = &args.samples {
        std::fs::write(path, &samples).with_context(|| format!("writing {}", path.display()))?;
    }
    // Rendered from the samples alone, as `render` renders them.
    let (doc, plot) = (args.doc.as_deref(), args.plot.as_deref());
    if doc.is_some() || plot.is_some() {
        render(&Report::from_samples(&samples)?, doc, plot)?;
    }
    if !args.smoke {
        return Ok(());
    }
    let warnings = report.smoke_warnings();
    let failures = report.smoke_failures(&report.expected);
    for line in warnings.iter().chain(&failures) {
        eprintln!("smoke: {line}");
    }
    let planned = report.expected.len();
    if !failures.is_empty() {
        let failed = failures.len();
        anyhow::bail!("the smoke run failed: {failed} failure(s), {planned} rows planned");
    }
    eprintln!(
        "smoke: all {planned} planned rows measured, none flagged beyond the smoke run's noise \
         ({} within it, above)",
        warnings.len()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A new empty directory of the test's own (`tag`) under the system's temporary directory.
    pub(crate) fn scratch(tag: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("chassis-bench-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    fn planned(
        quick: bool,
        robots: &[RobotKind],
    ) -> Vec<(RobotKind, BusKind, LoopMode, Placement)> {
        path_runs(quick, robots)
            .into_iter()
            .map(|r| (r.robot, r.bus, r.mode, r.placement))
            .collect()
    }

    #[test]
    fn the_quick_plan_compares_the_titans_loops_and_placements_on_the_simulator_and_a_pty() {
        use {BusKind::*, LoopMode::*, Placement::*, RobotKind::Titan};
        assert_eq!(
            planned(true, &[RobotKind::Xbot]),
            [
                (Titan, Sim, Event, SameCpu),
                (Titan, Sim, Event, CrossCpu),
                (Titan, Sim, Spin, CrossCpu),
                (Titan, Pty, Event, CrossCpu),
                (Titan, Pty, Spin, CrossCpu)
            ]
        );
    }

    #[test]
    fn the_full_plan_adds_every_robot_on_the_simulator_and_a_pty() {
        use {BusKind::*, LoopMode::*, Placement::*, RobotKind::*};
        assert_eq!(
            planned(false, &[Titan, Xbot]),
            [
                (Titan, Sim, Event, SameCpu),
                (Titan, Sim, Spin, CrossCpu),
                (Titan, Sim, Hybrid, CrossCpu),
                (Titan, Sim, Event, CrossCpu),
                (Titan, Pty, Event, CrossCpu),
                (Xbot, Sim, Event, CrossCpu),
                (Xbot, Pty, Event, CrossCpu),
                (Titan, Pty, Spin, CrossCpu)
            ]
        );
    }

    #[test]
    fn the_quick_plan_plans_every_row_of_the_committed_document_and_no_other() {
        use std::collections::BTreeSet;
        let args = Cli::parse_from(["chassis-bench", "--quick"]).run;
        let plan = Plan::new(false, true);
        let steps = steps(&args, &[RobotKind::Titan], &plan, |_| false);
        let ctx = Ctx {
            plan,
            prefix: String::new(),
            dir: PathBuf::new(),
            python: Some(PathBuf::from("python")),
            ros2: Some(PathBuf::from("python")),
            bar: ProgressBar::hidden(),
        };
        let planned: BTreeSet<String> = steps
            .iter()
            .flat_map(|s| s.planned(&ctx))
            .map(|p| p.key)
            .collect();
        let root = concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/bench.jsonl");
        let samples = std::fs::read_to_string(root).unwrap();
        let measured: BTreeSet<String> = Report::from_samples(&samples)
            .unwrap()
            .rows
            .iter()
            .map(Row::key)
            .collect();
        assert_eq!(
            planned.symmetric_difference(&measured).collect::<Vec<_>>(),
            Vec::<&String>::new(),
            "planned by --quick but not in docs/bench.jsonl, or the other way round"
        );
    }
}
