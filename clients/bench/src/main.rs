//! `chassis-bench`: end-to-end latency of chassisd's real paths against raw-transport baselines,
//! measured in one run so every figure is a ratio that holds on any machine.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use chassis_protocols::RobotKind;
use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};

mod baseline;
mod control_loop;
mod dds_echo;
mod fanout;
mod fleet;
mod parts;
mod paths;
mod periods;
mod placement;
mod provenance;
mod python;
mod render;
mod report;
mod ros2;
mod stalls;
mod stats;
mod throughput;
mod verdict;
mod zenoh;
mod zenoh_raw;

use baseline::{Load, Transport};
use paths::{BusKind, LoopMode};
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
    Feed(baseline::FeedArgs),
    Subscribe(fanout::SubscribeArgs),
    DdsEcho(dds_echo::EchoArgs),
    /// Publish stamped samples on a bare Zenoh session configured as chassis-zenoh's.
    ZenohPub(zenoh_raw::RawArgs),
    /// Receive them and write their latencies.
    ZenohSub(zenoh_raw::RawArgs),
    /// Write the candump log the throughput run replays (for profiling the service by hand).
    RecordTitan {
        #[arg(long)]
        out: PathBuf,
        /// Simulated seconds (about 650 frames each).
        #[arg(long, default_value_t = 1500)]
        seconds: u64,
    },
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
fn render(
    report: &Report,
    doc: Option<&std::path::Path>,
    plot: Option<&std::path::Path>,
) -> anyhow::Result<()> {
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
    stall_bursts: u32,
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
}

impl Plan {
    /// The smoke run's: enough samples for every row to exist and its p99 to be shown, no more.
    fn smoke() -> Self {
        Self {
            baseline_rounds: 500,
            stall_bursts: 2,
            paced_rounds: 100,
            commands: 100,
            xbot_commands: 0,
            states: 300,
            preemptions: 100,
            fanout: vec![2],
            fanout_seconds: 1.0,
            cost_seconds: 1.0,
            loop_seconds: 1.0,
        }
    }

    fn new(quick: bool) -> Self {
        if quick {
            Self {
                baseline_rounds: 2000,
                stall_bursts: 10,
                paced_rounds: 500,
                commands: 300,
                xbot_commands: 0,
                states: 1000,
                preemptions: 100,
                fanout: vec![1, 4],
                fanout_seconds: 1.5,
                cost_seconds: 1.5,
                loop_seconds: 10.0,
            }
        } else {
            Self {
                baseline_rounds: 20_000,
                stall_bursts: 25,
                paced_rounds: 2500,
                commands: 3000,
                xbot_commands: 40,
                states: 10_000,
                preemptions: 300,
                fanout: vec![1, 4, 16],
                fanout_seconds: 5.0,
                cost_seconds: 5.0,
                loop_seconds: 150.0,
            }
        }
    }
}

/// The placement column of CPU `cpu`'s stall row.
fn stall_placement(cpu: usize) -> String {
    format!("CPU {cpu}")
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

/// The baseline transport that waits like a service loop in `mode`.
/// The raw DDS hops the ROS 2 rows contain (Cyclone DDS is the peer, RustDDS the bridge's).
const DDS_IN: &str = "DDS Cyclone DDS → RustDDS";
const DDS_OUT: &str = "DDS RustDDS → Cyclone DDS";

/// The runs (robot, bus, loop) the Python client and the ROS 2 bridge are measured beside: same
/// service, same placement as the Rust client's rows.
const SCRIPTS_BESIDE: (RobotKind, BusKind, LoopMode) =
    (RobotKind::Titan, BusKind::Sim, LoopMode::Event);

fn transport_of(mode: LoopMode) -> Transport {
    match mode {
        LoopMode::Event => Transport::IceoryxEvent,
        LoopMode::Spin => Transport::IceoryxSpin,
        LoopMode::Hybrid => Transport::IceoryxHybrid,
    }
}

/// The period of `robot`'s heartbeat: the service's tick on that robot (the registry's, of its
/// default profile).
fn tick_of(robot: RobotKind) -> Duration {
    robot.entry().defaults().heartbeat_period()
}

fn bus_label(robot: RobotKind, bus: BusKind) -> String {
    let bus = match (bus, robot.is_can()) {
        (BusKind::Sim, _) => "sim",
        (BusKind::Pty, true) => "slcan pty",
        (BusKind::Pty, false) => "serial pty",
    };
    format!("{robot} {bus}")
}

fn run(args: &RunArgs) -> anyhow::Result<Report> {
    let quick = args.quick || args.smoke;
    let plan = if args.smoke {
        Plan::smoke()
    } else {
        Plan::new(quick)
    };
    // The smoke run checks rows: the bus-load cost and the replay make none.
    let skip = |part: &str| {
        args.skip.iter().any(|s| s == part) || (args.smoke && matches!(part, "cost" | "throughput"))
    };
    let dir = match &args.dir {
        Some(d) => d.clone(),
        None => std::env::temp_dir().join(format!("chassis-bench-{}", std::process::id())),
    };
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let prefix = format!("cb{}_", std::process::id());
    let robots: Vec<RobotKind> = args
        .robots
        .iter()
        .map(|r| r.parse::<RobotKind>().map_err(anyhow::Error::msg))
        .collect::<anyhow::Result<_>>()?;
    let strict = args.samples.is_some() || args.plot.is_some() || args.doc.is_some();
    let provenance = provenance::Provenance::begin(strict, args.allow_dirty)?;
    let mut report = Report {
        machine: report::Machine::probe(),
        provenance,
        ..Report::default()
    };
    if report.machine.cpus < 2 {
        report
            .notes
            .push("one CPU only: cross-CPU runs share it".into());
    }

    // Back to back (each transport at its best), then paced like the command path: what a
    // request after a pause meets, the service paths' reference.
    let paced = Some(paths::off_grid(paths::COMMAND_INTERVAL));
    let mut baselines: Vec<(Transport, Placement, Option<Duration>)> =
        [Placement::SameCpu, Placement::CrossCpu]
            .into_iter()
            .flat_map(|p| {
                let mut t = vec![
                    (Transport::IceoryxEvent, p, None),
                    (Transport::Uds, p, None),
                    (Transport::Udp, p, None),
                ];
                if p == Placement::CrossCpu {
                    t.insert(1, (Transport::IceoryxSpin, p, None));
                }
                t
            })
            .collect();
    baselines.extend([
        (Transport::IceoryxEvent, Placement::SameCpu, paced),
        (Transport::IceoryxEvent, Placement::CrossCpu, paced),
        (Transport::IceoryxSpin, Placement::CrossCpu, paced),
    ]);
    let mut runs = path_runs(quick, &robots);
    if args.smoke {
        // The event loop only: a busy-polling loop on a shared 2-core machine measures the
        // machine's other work (a smoke run is about rows, not figures).
        runs.retain(|r| r.mode == LoopMode::Event);
    }
    // The poll-then-block loop's own back-to-back hop, a context row beside the hybrid runs.
    if runs.iter().any(|r| r.mode == LoopMode::Hybrid) {
        baselines.push((Transport::IceoryxHybrid, Placement::CrossCpu, None));
    }
    // Every row this run plans, named as the code below names them, with the samples it asks
    // for: a smoke run fails when one of them did not come, or brought too few.
    let python = python::interpreter();
    let ros2 = ros2::interpreter();
    let mut expected: Vec<Planned> = Vec::new();
    let mut plan_row =
        |path: PathKind, what: &str, mode: &str, placement: &str, asked: Option<u64>| {
            expected.push(Planned::new(row_key(path, what, mode, placement), asked));
        };
    if !skip("baselines") {
        for (transport, placement, pace) in &baselines {
            // Back to back, both hops of a round count; paced, the ping's alone.
            let (what, asked) = match pace {
                Some(_) => (
                    format!("{} {}", transport.label(), report::PACED),
                    plan.paced_rounds,
                ),
                None => (transport.label().to_string(), 2 * plan.baseline_rounds),
            };
            plan_row(
                PathKind::Baseline,
                &what,
                "-",
                placement.label(),
                Some(asked),
            );
        }
        for cpu in 0..placement::cpu_count() {
            plan_row(
                PathKind::Baseline,
                report::STALLS,
                "-",
                &stall_placement(cpu),
                None,
            );
        }
    }
    if !skip("paths") {
        for r in &runs {
            let label = bus_label(r.robot, r.bus);
            let (mode, placement) = (r.mode.arg(), r.placement.label());
            let t = transport_of(r.mode).label();
            let (commands, preemptions) = if r.robot == RobotKind::Xbot {
                (plan.xbot_commands, plan.preemptions / 15)
            } else {
                (plan.commands, plan.preemptions)
            };
            // A matched baseline has as many samples as the row it divides.
            let pings = if commands > 0 {
                commands
            } else {
                plan.paced_rounds
            };
            for (what, asked) in [
                (format!("{t} paced, loaded as {label}"), pings),
                (
                    format!("{t} at the feedback rate, loaded as {label}"),
                    plan.states,
                ),
                (format!("{t} published, loaded as {label}"), plan.states),
                (
                    format!("{t} after a wake-up ping, loaded as {label}"),
                    preemptions,
                ),
            ] {
                plan_row(PathKind::Baseline, &what, "-", placement, Some(asked));
            }
            if commands > 0 {
                plan_row(PathKind::Command, &label, mode, placement, Some(commands));
                let what = format!("{label}: command");
                plan_row(PathKind::InService, &what, mode, placement, Some(commands));
            }
            plan_row(PathKind::State, &label, mode, placement, Some(plan.states));
            let what = format!("{label}: state");
            plan_row(
                PathKind::InService,
                &what,
                mode,
                placement,
                Some(plan.states),
            );
            plan_row(
                PathKind::Preemption,
                &label,
                mode,
                placement,
                Some(preemptions),
            );
            if (r.robot, r.bus, r.mode) == SCRIPTS_BESIDE {
                if python.is_some() {
                    for (p, asked) in [("state", plan.states), ("command", commands)] {
                        let what = format!("{label}: {p}");
                        plan_row(PathKind::Python, &what, mode, placement, Some(asked));
                    }
                }
                if ros2.is_some() {
                    for (what, dds, asked) in [
                        ("cmd_vel → frame", DDS_IN, commands),
                        ("frame read → odom", DDS_OUT, plan.states),
                    ] {
                        let what = format!("{label}: {what}");
                        plan_row(PathKind::Ros2, &what, mode, placement, Some(asked));
                        let hop = format!("{dds}, beside {label}");
                        plan_row(PathKind::Baseline, &hop, "-", placement, Some(asked));
                    }
                }
            }
        }
        let cross = Placement::CrossCpu.label();
        let asked = Some(plan.commands);
        plan_row(
            PathKind::Command,
            report::DEFAULT_CONFIG_ROW,
            "event",
            cross,
            asked,
        );
        let what = format!("{}: command", report::DEFAULT_CONFIG_ROW);
        plan_row(PathKind::InService, &what, "event", cross, asked);
    }
    let loops = control_loop::plan(args.smoke);
    if !skip("loops") {
        let cross = Placement::CrossCpu.label();
        for &(period, mode) in &loops {
            let periods = Some(control_loop::periods(period, plan.loop_seconds));
            let run = bus_label(RobotKind::Titan, BusKind::Sim);
            let [frame, age, hop] = control_loop::row_names(&run, period, transport_of(mode));
            // A command the next period's superseded is what the row measures, not a loss.
            plan_row(PathKind::Loop, &frame, mode.arg(), cross, None);
            plan_row(PathKind::Loop, &age, mode.arg(), cross, periods);
            plan_row(PathKind::Baseline, &hop, "-", cross, periods);
        }
    }
    if !skip("fanout") {
        for n in &plan.fanout {
            let what = format!("titan sim → {n} processes");
            plan_row(PathKind::FanOut, &what, "event", "unpinned", None);
        }
    }
    if !skip("zenoh") && zenoh::possible() {
        let placement = "2 netns, veth";
        for (what, asked) in [
            (zenoh::RAW_COMMAND, plan.commands),
            (zenoh::RAW_STATE, plan.states),
        ] {
            plan_row(PathKind::Baseline, what, "-", placement, Some(asked));
        }
        for (what, asked) in [
            (zenoh::COMMAND, plan.commands),
            (zenoh::STATE, plan.states),
            (zenoh::BRIDGE, plan.states),
        ] {
            plan_row(PathKind::Zenoh, what, "event", placement, Some(asked));
        }
    }
    report.expected = expected;

    let steps = (if skip("baselines") {
        0
    } else {
        baselines.len() + placement::cpu_count()
    }) + (if skip("paths") { 0 } else { runs.len() + 1 })
        + (if skip("fanout") { 0 } else { plan.fanout.len() })
        + usize::from(!skip("loops"))
        + usize::from(!skip("cost"))
        + usize::from(!skip("zenoh"))
        + usize::from(!skip("throughput"));
    let bar = ProgressBar::new(steps as u64);
    bar.set_style(
        ProgressStyle::with_template("{elapsed:>4} [{bar:30}] {pos}/{len} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );

    if !skip("baselines") {
        for (transport, placement, pace) in baselines {
            let what = match pace {
                Some(_) => format!("{} {}", transport.label(), report::PACED),
                None => transport.label().to_string(),
            };
            bar.set_message(format!("baseline {what} ({})", placement.label()));
            let rounds = if pace.is_some() {
                plan.paced_rounds
            } else {
                plan.baseline_rounds
            };
            let shape = pace.map_or(baseline::Rounds::BackToBack, baseline::Rounds::Paced);
            let l = baseline::run(transport, placement, rounds, shape, None, &prefix, &dir)?
                .all_pings();
            let mut r = Row::new(
                PathKind::Baseline,
                Leg::Hop,
                "",
                what,
                "-",
                placement.label(),
                l,
                0,
            );
            r.conditions = Some(match pace {
                Some(p) => format!(
                    "one ping every {}, receiver otherwise idle (cold)",
                    paths::period_text(p)
                ),
                None => "back to back (warm)".into(),
            });
            report.rows.push(r);
            bar.inc(1);
        }
        for cpu in 0..placement::cpu_count() {
            bar.set_message(format!("stalls on CPU {cpu}"));
            let stalls = stalls::measure(cpu, plan.stall_bursts, paths::REALTIME_PRIORITY)?;
            report.stalls.push(report::StallRates {
                cpu,
                over_20_us: stalls.per_second(20),
                over_100_us: stalls.per_second(100),
            });
            let conditions = stalls.conditions(cpu);
            let mut r = Row::new(
                PathKind::Baseline,
                Leg::Stalls,
                "",
                report::STALLS.into(),
                "-",
                &stall_placement(cpu),
                stalls.gaps,
                0,
            );
            r.conditions = Some(conditions);
            report.rows.push(r);
            bar.inc(1);
        }
    }

    if !skip("paths") {
        if python.is_none() {
            report.notes.push(
                "the Python client was not measured: target/python-venv is missing \
                 (scripts/python-tests makes it)"
                    .into(),
            );
        }
        if ros2.is_none() {
            report.notes.push(
                "the ROS 2 bridge was not measured: target/ros2-venv is missing \
                 (scripts/ros2-tests makes it)"
                    .into(),
            );
        }
        for r in &runs {
            let label = bus_label(r.robot, r.bus);
            bar.set_message(format!(
                "{label}, {} loop, {}",
                r.mode.arg(),
                r.placement.label()
            ));
            let (client_cpu, service_cpu) = r.placement.cpus();
            let (service, mut robot) = paths::start_configured(
                r.robot,
                r.bus,
                r.mode,
                service_cpu,
                paths::ServiceConfig::BenchRealtime,
                true,
                &prefix,
                &dir,
            )?;
            let spin = r.mode == LoopMode::Spin;
            let (count, interval) = if r.robot == RobotKind::Xbot {
                // The XBot's manual caps the command rate below 10 Hz: a change goes out at once
                // only while the last second holds a free slot.
                (plan.xbot_commands, paths::XBOT_COMMAND_INTERVAL)
            } else {
                (plan.commands, paths::COMMAND_INTERVAL)
            };
            let feedback = paths::FeedbackRate::start(&mut robot)?;
            let result = paths::pinned(client_cpu, || -> anyhow::Result<_> {
                let command = if count > 0 {
                    Some(paths::command_path(
                        &mut robot, r.robot, count, interval, spin,
                    )?)
                } else {
                    None
                };
                let state = paths::state_path(&mut robot, plan.states, spin)?;
                let preemptions = if r.robot == RobotKind::Xbot {
                    plan.preemptions / 15
                } else {
                    plan.preemptions
                };
                let preempt = paths::preemption(&mut robot, r.robot, preemptions, interval, spin)?;
                // The Python client and the ROS 2 bridge beside the Rust one.
                let (mut python_figures, mut ros2_figures) = (None, None);
                if (r.robot, r.bus, r.mode) == SCRIPTS_BESIDE
                    && (python.is_some() || ros2.is_some())
                {
                    let run = python::ScriptRun {
                        name: robot.name(),
                        prefix: &prefix,
                        chassis_cli: &paths::sibling("chassis")?,
                        dir: &dir,
                        states: plan.states,
                        commands: count,
                        interval,
                    };
                    if let Some(interpreter) = &python {
                        python_figures = Some(python::run(interpreter, &run)?);
                    }
                    if let Some(interpreter) = &ros2 {
                        let bridge = paths::sibling("chassis-ros2")?;
                        ros2_figures = Some(ros2::run(interpreter, &bridge, &run)?);
                    }
                }
                Ok((command, state, preempt, python_figures, ros2_figures))
            })??;
            let feed_per_s = feedback.per_second(&mut robot)?;
            drop(robot);
            let scheduling = service.scheduling;
            if scheduling.fifo().is_some() {
                // Real-time mode locks every page the process maps.
                let rss = paths::rss_mib(service.pid)?;
                report.realtime_rss_mib = Some(report.realtime_rss_mib.map_or(rss, |m| m.max(rss)));
            }
            report.scheduling.push((
                format!("{label}, {} loop, {}", r.mode.arg(), r.placement.label()),
                scheduling,
            ));
            let passes = service.stop()?;
            bar.inc(1);

            // The baseline of this run's command and state rows: its receiver lives like the
            // service's loop did — woken by another process at the chassis' feedback rate, its
            // own tick, the same placement and the same way of waiting.
            let transport = transport_of(r.mode);
            let tick = tick_of(r.robot);
            bar.set_message(format!(
                "baseline as {label}: {} woken {feed_per_s:.0}/s",
                transport.label()
            ));
            let (command, state, (preempt, preempt_missed), python, ros2) = result;
            // As many samples as the rows each part divides: the command row's pings, the state
            // row's feed hops (the run lasts until the feed made that many).
            let pings_wanted = command
                .as_ref()
                .map_or(plan.paced_rounds, |c| c.latencies.count());
            // A tenth more: the feed starts after the receiver and keeps its own pace.
            let feed_rounds = (1.1 * state.latencies.count() as f64
                / (feed_per_s * interval.as_secs_f64()).max(1e-9))
            .ceil() as u64;
            let rounds = pings_wanted.max(feed_rounds) + 1;
            let load = Load {
                feed_per_s,
                tick,
                realtime: scheduling.fifo(),
                published: false,
            };
            let measured = baseline::run(
                transport,
                r.placement,
                rounds,
                baseline::Rounds::Paced(paths::off_grid(interval)),
                Some(load),
                &prefix,
                &dir,
            )?;
            // The state row's hop, in a run of its own: its client sends a request every
            // STATE_REQUEST_INTERVAL, not one every command period (pings every 4 ms would keep
            // the reader's CPU awake, and its wake-up cheaper than the state path's).
            // A quarter more: the receiver publishes once per wake-up, which may take more than
            // one feed sample.
            let state_rounds = (1.25 * state.latencies.count() as f64
                / (feed_per_s * paths::STATE_REQUEST_INTERVAL.as_secs_f64()).max(1e-9))
            .ceil() as u64
                + 1;
            bar.set_message(format!(
                "baseline as {label}: {} published, loaded",
                transport.label()
            ));
            let state_measured = baseline::run(
                transport,
                r.placement,
                state_rounds,
                baseline::Rounds::Paced(paths::STATE_REQUEST_INTERVAL),
                Some(Load {
                    published: true,
                    ..load
                }),
                &prefix,
                &dir,
            )?;
            let placement = r.placement.label();
            // This run's rows, at its mode and placement; its baselines', at its placement.
            let run_row = |path, leg, what: String, latencies: Latencies, missed: u64| {
                Row::new(
                    path,
                    leg,
                    &label,
                    what,
                    r.mode.arg(),
                    placement,
                    latencies,
                    missed,
                )
            };
            let baseline_row = |what: String, latencies: Latencies| {
                Row::new(
                    PathKind::Baseline,
                    Leg::Hop,
                    &label,
                    what,
                    "-",
                    placement,
                    latencies,
                    0,
                )
            };
            // The feed runs where chassisd put its simulated chassis (`baseline::feed_cpu`).
            let (feed_where, fifo) = match scheduling.fifo() {
                Some(priority) => (
                    "on the receiver's CPU",
                    format!(", at SCHED_FIFO {priority} as the service's loop"),
                ),
                None => ("on the other CPU", String::new()),
            };
            let conditions = format!(
                "receiver woken {feed_per_s:.0}/s by another process {feed_where}, as by the \
                 simulated chassis (the feedback rate measured in the {label} run), and by its \
                 own {} ms tick{fifo}",
                tick.as_millis()
            );
            let paced_what = format!("{} paced, loaded as {label}", transport.label());
            let mut paced_row = baseline_row(
                paced_what.clone(),
                baseline::last_of(&measured.pings, pings_wanted),
            );
            paced_row.conditions = Some(format!(
                "one ping every {}, the last {pings_wanted} of {rounds}; {conditions}",
                paths::period_text(paths::off_grid(interval))
            ));
            report.rows.push(paced_row);
            let feed_what = format!(
                "{} at the feedback rate, loaded as {label}",
                transport.label()
            );
            if let Some(feed) = measured.feed {
                // As many hops as the state row has samples: the last ones, the receiver warm.
                let hops = baseline::last_of(&feed, state.latencies.count());
                let mut feed_row = baseline_row(feed_what.clone(), hops);
                feed_row.conditions = Some(format!(
                    "the feed's own hops: {feed_per_s:.0}/s, the last {} of {}; {conditions}",
                    state.latencies.count(),
                    feed.len()
                ));
                report.rows.push(feed_row);
            }
            // The state row's hop: from the receiver, which lives as the loop does, to a reader
            // that lives as the client does.
            let published_what = format!("{} published, loaded as {label}", transport.label());
            if let Some(published) = state_measured.published {
                let hops = baseline::last_of(&published, state.latencies.count());
                let mut published_row = baseline_row(published_what.clone(), hops);
                let reader = match r.placement {
                    Placement::SameCpu => "on the receiver's CPU",
                    Placement::CrossCpu => "on the other CPU",
                };
                let waiting = if r.mode == LoopMode::Spin {
                    "polling"
                } else {
                    "blocked on its listener between drains"
                };
                published_row.conditions = Some(format!(
                    "one sample published by the receiver each time it took the feed's samples, \
                     as chassisd publishes its state after each feedback frame that changed it, \
                     read at normal scheduling {reader}, {waiting}, as the client reads the \
                     state, while the ping side sends one ping every {} ms as the state path's \
                     client sends a request: the last {} of {}; {conditions}",
                    paths::STATE_REQUEST_INTERVAL.as_millis(),
                    state.latencies.count(),
                    published.len()
                ));
                report.rows.push(published_row);
            }
            let reference = |what: &str| Some(format!("{what}, {placement}"));
            // The preemption's stop follows a teleop request at once, while the loop is waking
            // for it: its baseline is a ping right after a lead ping, loaded as the service was,
            // with as many samples.
            bar.set_message(format!(
                "baseline as {label}: {} after a wake-up ping, loaded",
                transport.label()
            ));
            let warm_what = format!(
                "{} after a wake-up ping, loaded as {label}",
                transport.label()
            );
            let warm_rounds = preempt.count().max(1);
            let warm_measured = baseline::run(
                transport,
                r.placement,
                warm_rounds,
                baseline::Rounds::AfterWakeUp,
                Some(load),
                &prefix,
                &dir,
            )?;
            let mut warm_row = baseline_row(warm_what.clone(), warm_measured.all_pings());
            warm_row.conditions = Some(format!(
                "{warm_rounds} pings, each sent right after a lead ping that wakes the receiver \
                 (only the second ping's hop counts), back to back after a warm-up; {conditions}"
            ));
            report.rows.push(warm_row);
            let warm = reference(&warm_what);

            let mut odom_parts = None;
            if let Some(dds) = ros2 {
                odom_parts = Some(parts::odom(&dds.odom_pairs, &dds.odom_trace, &passes));
                let conditions = |pace: String, carried: &str| {
                    format!(
                        "one message every {pace} after 200 uncounted, {carried}, measured by \
                         the ROS 2 run's own script, same run"
                    )
                };
                // Named after this run: a full run measures the bridge beside more than one.
                let dds_in = format!("{DDS_IN}, beside {label}");
                let dds_out = format!("{DDS_OUT}, beside {label}");
                for (what, latencies, pace, carried) in [
                    (
                        &dds_in,
                        dds.raw_in,
                        format!("{} (the cmd_vel path's)", paths::period_text(interval)),
                        "a TwistStamped read with the bridge's cmd_vel QoS",
                    ),
                    (
                        &dds_out,
                        dds.raw_out,
                        format!(
                            "{} (the period of the odoms the path counted, 1.7 % more)",
                            paths::period_text(dds.raw_out_period)
                        ),
                        "an Odometry written as the bridge writes odom (its writer QoS)",
                    ),
                ] {
                    let mut r = baseline_row(what.clone(), latencies);
                    r.conditions = Some(conditions(pace, carried));
                    report.rows.push(r);
                }
                let mut command_row = run_row(
                    PathKind::Ros2,
                    Leg::CmdVel,
                    format!("{label}: cmd_vel → frame"),
                    dds.command,
                    dds.missed,
                );
                command_row.baseline = reference(&dds_in);
                // The DDS hop in, then the service's command path.
                command_row.contains = vec![
                    row_key(PathKind::Baseline, &dds_in, "-", placement),
                    row_key(PathKind::Command, &label, r.mode.arg(), placement),
                ];
                report.rows.push(command_row);
                let what = format!("{label}: frame read → odom");
                let mut state_row = run_row(PathKind::Ros2, Leg::Odom, what, dds.state, 0);
                state_row.baseline = reference(&dds_out);
                // The service's state path, then the DDS hop out.
                state_row.contains = vec![
                    row_key(PathKind::State, &label, r.mode.arg(), placement),
                    row_key(PathKind::Baseline, &dds_out, "-", placement),
                ];
                report.rows.push(state_row);
            }
            let python_parts = python
                .as_ref()
                .map(|py| parts::python_state(&py.state_stamps, &passes));
            if let Some(py) = python {
                let what = format!("{label}: state");
                let mut state_row = run_row(PathKind::Python, Leg::State, what, py.state, 0);
                state_row.dropped = py.dropped;
                report.rows.push(state_row);
                report.rows.push(run_row(
                    PathKind::Python,
                    Leg::Command,
                    format!("{label}: command"),
                    py.command,
                    py.missed,
                ));
            }
            let run_parts = |path: &str, of, split| report::Parts {
                path: path.into(),
                of,
                run: label.clone(),
                what: label.clone(),
                mode: r.mode.arg().into(),
                placement: placement.into(),
                split,
            };
            if let Some(figures) = &command {
                report.parts.push(run_parts(
                    "command",
                    (PathKind::Command, Leg::Command),
                    parts::command(&figures.samples, &passes, r.mode == LoopMode::Spin),
                ));
            }
            report.parts.push(run_parts(
                "state",
                (PathKind::State, Leg::State),
                parts::state(&state.samples, &passes),
            ));
            if let Some(odom) = odom_parts {
                report.parts.push(run_parts(
                    "ros2: frame read → odom",
                    (PathKind::Ros2, Leg::Odom),
                    odom,
                ));
            }
            if let Some(python) = python_parts {
                report.parts.push(run_parts(
                    report::PYTHON_PARTS,
                    (PathKind::Python, Leg::State),
                    python,
                ));
            }
            if let Some(figures) = command {
                let command_row = run_row(
                    PathKind::Command,
                    Leg::Command,
                    label.clone(),
                    figures.latencies,
                    figures.missed,
                );
                let baseline = reference(&paced_what);
                report
                    .rows
                    .extend(path_rows(command_row, baseline, figures.in_service));
            }
            let mut state_row = run_row(
                PathKind::State,
                Leg::State,
                label.clone(),
                state.latencies,
                0,
            );
            state_row.dropped = state.dropped;
            let baseline = reference(&published_what);
            report
                .rows
                .extend(path_rows(state_row, baseline, state.in_service));
            let mut preempt_row = run_row(
                PathKind::Preemption,
                Leg::Stop,
                label.clone(),
                preempt,
                preempt_missed,
            );
            // The stop follows a teleop request at once: the loop is awake, as in a
            // back-to-back ping-pong.
            preempt_row.baseline = warm;
            report.rows.push(preempt_row);
            bar.inc(1);
        }

        // chassisd as it ships beside the benchmark's configuration: the TITAN on the simulated
        // bus, event loop, cross CPU, against the same matched baseline as that run's row.
        bar.set_message("titan sim in chassisd's default configuration");
        let placement = Placement::CrossCpu;
        let (client_cpu, service_cpu) = placement.cpus();
        let (service, mut robot) = paths::start_configured(
            RobotKind::Titan,
            BusKind::Sim,
            LoopMode::Event,
            service_cpu,
            paths::ServiceConfig::Default,
            false,
            &prefix,
            &dir,
        )?;
        let figures = paths::pinned(client_cpu, || -> anyhow::Result<_> {
            let mut teleop = robot.source("teleop")?;
            paths::command_path_via(
                &mut robot,
                &mut teleop,
                RobotKind::Titan,
                plan.commands,
                paths::COMMAND_INTERVAL,
                false,
                paths::Reach::Toward,
            )
        })??;
        drop(robot);
        drop(service);
        let label = bus_label(RobotKind::Titan, BusKind::Sim);
        let mut default_row = Row::new(
            PathKind::Command,
            Leg::FirstFrameToward,
            &label,
            report::DEFAULT_CONFIG_ROW.to_string(),
            LoopMode::Event.arg(),
            placement.label(),
            figures.latencies,
            figures.missed,
        );
        default_row.baseline = Some(format!(
            "{} paced, loaded as {label}, {}",
            Transport::IceoryxEvent.label(),
            placement.label()
        ));
        report.rows.push(default_row);
        report.rows.push(Row::new(
            PathKind::InService,
            Leg::FirstFrameToward,
            &label,
            format!("{}: command", report::DEFAULT_CONFIG_ROW),
            LoopMode::Event.arg(),
            placement.label(),
            figures.in_service,
            0,
        ));
        bar.inc(1);
    }

    if !skip("loops") {
        bar.set_message("control loops at 1 kHz and 100 Hz");
        control_loop::run(
            &loops,
            plan.loop_seconds,
            transport_of,
            &prefix,
            &dir,
            &mut report,
        )?;
        bar.inc(1);
    }

    if !skip("fanout") {
        for &n in &plan.fanout {
            bar.set_message(format!("fan-out to {n} subscriber processes"));
            let (service, mut robot) = paths::start(
                RobotKind::Titan,
                BusKind::Sim,
                LoopMode::Event,
                None,
                &prefix,
                &dir,
            )?;
            let l = fanout::run(&mut robot, &service.name, &prefix, n, plan.fanout_seconds)?;
            report.rows.push(Row::new(
                PathKind::FanOut,
                Leg::FanOut,
                &bus_label(RobotKind::Titan, BusKind::Sim),
                format!("titan sim → {n} processes"),
                "event",
                "unpinned",
                l,
                0,
            ));
            bar.inc(1);
        }
    }

    if !skip("zenoh") {
        if zenoh::possible() {
            bar.set_message("chassis-zenoh between two network namespaces");
            let z = zenoh::run(
                &prefix,
                &dir,
                plan.commands,
                paths::COMMAND_INTERVAL,
                plan.states,
            )?;
            let placement = "2 netns, veth";
            // chassis-zenoh bridges the TITAN on the simulated bus.
            let run = bus_label(RobotKind::Titan, BusKind::Sim);
            let command_count = z.command.latencies.count();
            let state_count = z.state.count();
            for (what, count, hops, pace) in [
                (
                    zenoh::RAW_COMMAND,
                    command_count,
                    &z.raw_command,
                    format!(
                        "{} (the command path's)",
                        paths::period_text(paths::COMMAND_INTERVAL)
                    ),
                ),
                (
                    zenoh::RAW_STATE,
                    state_count,
                    &z.raw_state,
                    format!(
                        "{} (the period of the states the path counted, 1.7 % more)",
                        paths::period_text(z.state_period)
                    ),
                ),
            ] {
                let mut raw = Row::new(
                    PathKind::Baseline,
                    Leg::Hop,
                    &run,
                    what.into(),
                    "-",
                    placement,
                    baseline::last_of(hops, count),
                    0,
                );
                raw.conditions = Some(format!(
                    "one sample every {pace} from the robot's namespace to the operator's, bare \
                     sessions configured as chassis-zenoh's, same run, chassisd running, the \
                     bridges not; the last {count} of {} after a warm-up",
                    hops.len()
                ));
                report.rows.push(raw);
            }
            let reference = Some(format!("{}, {placement}", zenoh::RAW_COMMAND));
            let mut command = Row::new(
                PathKind::Zenoh,
                Leg::RemoteCommand,
                &run,
                zenoh::COMMAND.into(),
                "event",
                placement,
                z.command.latencies,
                z.command.missed,
            );
            command.baseline = reference.clone();
            report.rows.push(command);
            let reference = Some(format!("{}, {placement}", zenoh::RAW_STATE));
            let mut state = Row::new(
                PathKind::Zenoh,
                Leg::RemoteState,
                &run,
                zenoh::STATE.into(),
                "event",
                placement,
                z.state,
                0,
            );
            state.baseline = reference.clone();
            report.rows.push(state);
            let mut bridge = Row::new(
                PathKind::Zenoh,
                Leg::RemoteBridge,
                &run,
                zenoh::BRIDGE.into(),
                "event",
                placement,
                z.bridge,
                0,
            );
            bridge.baseline = reference;
            report.rows.push(bridge);
            report.parts.push(report::Parts {
                path: report::ZENOH_PARTS.into(),
                of: (PathKind::Zenoh, Leg::RemoteState),
                run,
                what: zenoh::STATE.into(),
                mode: "event".into(),
                placement: placement.into(),
                split: z.state_parts,
            });
        } else {
            report
                .notes
                .push("chassis-zenoh was not measured: its network namespaces need root".into());
        }
        bar.inc(1);
    }

    if !skip("cost") {
        // The simulated bus reads up to 256 frames per system call; an slcan adapter on a pty is
        // read as a byte stream, as a USB adapter on a robot is: the target is judged on the
        // worse of the two.
        for (bus, label) in [(BusKind::Sim, "sim"), (BusKind::Pty, "slcan-pty")] {
            bar.set_message(format!("service cost at 100 % load of the {label} bus"));
            let (service, mut robot) =
                paths::start(RobotKind::Titan, bus, LoopMode::Event, None, &prefix, &dir)?;
            for bitrate in [500_000, 1_000_000] {
                report.cost.push(paths::cost_at(
                    &mut robot,
                    label,
                    service.pid,
                    bitrate,
                    plan.cost_seconds,
                )?);
            }
            drop(service);
        }
        bar.inc(1);
    }
    if !skip("throughput") {
        bar.set_message("replaying a recorded bus at full speed");
        let file = dir.join("titan.log");
        let seconds = if quick { 300 } else { 1500 };
        let frames = throughput::record_titan(&file, seconds)?;
        for _ in 0..report::REPLAYS {
            report
                .throughput
                .push(throughput::replay(&file, frames, &prefix, &dir)?);
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    report.compute_ratios();
    report.provenance.end()?;
    // A directory named on the command line keeps its logs.
    if args.dir.is_none() {
        let _ = std::fs::remove_dir_all(&dir);
    }
    Ok(report)
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.role {
        Some(RoleCmd::Role {
            role: Role::Pong(args),
        }) => baseline::pong(&args),
        Some(RoleCmd::Role {
            role: Role::Subscribe(args),
        }) => fanout::subscribe(&args),
        Some(RoleCmd::Role {
            role: Role::Feed(args),
        }) => baseline::feed(&args),
        Some(RoleCmd::Role {
            role: Role::DdsEcho(args),
        }) => dds_echo::run(&args),
        Some(RoleCmd::Role {
            role: Role::ZenohPub(args),
        }) => {
            chassis_client::install_signal_handlers();
            zenoh_raw::publish(&args)
        }
        Some(RoleCmd::Role {
            role: Role::ZenohSub(args),
        }) => zenoh_raw::subscribe(&args),
        Some(RoleCmd::Role {
            role: Role::RecordTitan { out, seconds },
        }) => throughput::record_titan(&out, seconds).map(|frames| {
            eprintln!("{frames} frames written to {}", out.display());
        }),
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
        None => run(&cli.run).and_then(|report| {
            print!("{}", report.table());
            let samples = report.samples()?;
            if let Some(path) = &cli.run.samples {
                std::fs::write(path, &samples)
                    .with_context(|| format!("writing {}", path.display()))?;
            }
            // Rendered from the samples alone, as `render` renders them.
            let (doc, plot) = (cli.run.doc.as_deref(), cli.run.plot.as_deref());
            if doc.is_some() || plot.is_some() {
                render(&Report::from_samples(&samples)?, doc, plot)?;
            }
            if cli.run.smoke {
                for warning in report.smoke_warnings() {
                    eprintln!("smoke: {warning}");
                }
                let failures = report.smoke_failures(&report.expected);
                for failure in &failures {
                    eprintln!("smoke: {failure}");
                }
                if !failures.is_empty() {
                    anyhow::bail!(
                        "the smoke run failed: {} failure(s), {} rows planned",
                        failures.len(),
                        report.expected.len()
                    );
                }
                eprintln!(
                    "smoke: all {} planned rows measured, none flagged beyond the smoke run's \
                     noise ({} within it, above)",
                    report.expected.len(),
                    report.smoke_warnings().len()
                );
            }
            Ok(())
        }),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("chassis-bench: {err:#}");
            ExitCode::FAILURE
        }
    }
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
}
