//! `chassis-bench fleet`: one operator, many simulated robots on this machine, in a network
//! namespace of its own (loopback only). Its method is the section it writes (`## Fleet`,
//! `clients/bench/fleet.md`) into `--doc FILE`, keeping the rest; the main run keeps the section.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use anyhow::{Context, bail};
use chassis_client::{ChassisState, Robot, now_ns};
use clap::Args;
use serde::Serialize;

use crate::paths::{self, Children, wait_until};
use crate::provenance::{CpuTimes, Provenance};
use crate::render::{fill, lines};
use crate::report::{Machine, Report};
use crate::zenoh::{Netns, ZENOH_LOG};

/// The heading of the section this writes.
pub const HEADING: &str = "## Fleet";
const BASE_PORT: u16 = 7600;
const KINDS: [&str; 3] = ["titan", "scout-mini", "hunter"];

#[derive(Debug, Args)]
pub struct FleetArgs {
    /// Fleet sizes to measure, ascending (robots are added, never restarted).
    #[arg(long, value_delimiter = ',', default_values_t = [1usize, 5, 10, 20])]
    pub sizes: Vec<usize>,
    /// Seconds measured at each size.
    #[arg(long, default_value_t = 10.0)]
    pub seconds: f64,
    /// Write the `## Fleet` section of this markdown document (e.g. docs/PERFORMANCE.md).
    #[arg(long)]
    pub doc: Option<PathBuf>,
    /// Write the figures as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write files from a tree with uncommitted changes (they then say DIRTY).
    #[arg(long)]
    pub allow_dirty: bool,
    /// Scratch directory for logs (default: a new one under /tmp, removed at the end).
    #[arg(long)]
    pub dir: Option<PathBuf>,
}

/// One robot's state path to the operator at one fleet size.
#[derive(Debug, Clone, Serialize)]
pub struct RobotFigures {
    pub name: String,
    pub kind: String,
    pub samples_per_s: f64,
    pub p50_ms: f64,
    pub p99_ms: f64,
    pub max_ms: f64,
}

/// One fleet size.
#[derive(Debug, Clone, Serialize)]
pub struct SizeFigures {
    pub robots: usize,
    pub operator_cpu_pct: f64,
    pub operator_rss_mib: f64,
    pub operator_peak_rss_mib: f64,
    pub operator_threads: u64,
    /// Every robot side together, % of one core.
    pub robot_sides_cpu_pct: f64,
    /// The whole machine's busy share over the window, % of all cores.
    pub machine_busy_pct: f64,
    pub samples_per_s: f64,
    /// The median of the robots' p50s, the worst p99 and the worst max.
    pub median_p50_ms: f64,
    pub worst_p99_ms: f64,
    pub worst_max_ms: f64,
    pub per_robot: Vec<RobotFigures>,
    /// Robots the operator did not show with fresh samples.
    pub missing: Vec<String>,
}

#[derive(Debug, Serialize)]
pub struct FleetReport {
    pub provenance: Provenance,
    /// `release build` or `debug build (…)`: the profile of the binaries measured.
    pub build: String,
    pub machine: Machine,
    pub seconds: f64,
    pub sizes: Vec<SizeFigures>,
}

/// User + system CPU time of a whole process, s.
fn process_cpu_s(pid: u32) -> anyhow::Result<f64> {
    paths::stat_cpu_seconds(&format!("/proc/{pid}/stat"))
}

/// A robot served under `prefix` whose state arrives.
fn serves(name: &str, prefix: &str) -> bool {
    let lost = chassis_client::LinkFlags::REMOTE_LOST;
    Robot::connect_with_prefix(name, Some(prefix)).is_ok_and(|mut r| {
        let state = r.wait_state(Duration::from_millis(300)).ok().flatten();
        state.is_some_and(|s: ChassisState| s.link_flags & lost == 0)
    })
}

/// Runs the fleet benchmark.
pub fn run(args: &FleetArgs) -> anyhow::Result<FleetReport> {
    if !crate::zenoh::possible() {
        bail!("the fleet benchmark needs root (a network namespace of its own)");
    }
    if args.sizes.is_empty() || args.sizes.windows(2).any(|w| w[0] >= w[1]) {
        bail!("--sizes must be ascending, e.g. 1,5,10,20");
    }
    if !(args.seconds.is_finite() && args.seconds >= 1.0) {
        bail!("--seconds must be at least 1");
    }
    let strict = args.doc.is_some() || args.json.is_some();
    let mut provenance = Provenance::begin(strict, args.allow_dirty)?;
    let scratch =
        || std::env::temp_dir().join(format!("chassis-bench-fleet-{}", std::process::id()));
    let dir = args.dir.clone().unwrap_or_else(scratch);
    std::fs::create_dir_all(&dir)?;
    let result = measure(args, &dir);
    match &result {
        Ok(_) if args.dir.is_none() => drop(std::fs::remove_dir_all(&dir)),
        _ => eprintln!("logs in {}", dir.display()),
    }
    let sizes = result?;
    provenance.end()?;
    // The binaries measured are built with chassis-bench, in its profile.
    let build = match cfg!(debug_assertions) {
        true => "**a debug build** (unoptimised: every figure is higher than a release build's)",
        false => "release build",
    };
    Ok(FleetReport {
        provenance,
        build: build.into(),
        machine: Machine::probe(),
        seconds: args.seconds,
        sizes,
    })
}

/// Each robot's state latency from `chassis fleet --once --json` (`json`) over `seconds`, and
/// the robots of `names` it had no sample of.
fn robot_figures(
    json: &[u8],
    names: &[(String, &str)],
    seconds: f64,
) -> anyhow::Result<(Vec<RobotFigures>, Vec<String>)> {
    let doc: serde_json::Value = serde_json::from_slice(json).context("chassis fleet --json")?;
    let rows = doc["robots"].as_array().context("no robots")?;
    let mut per_robot = Vec::new();
    let mut missing = Vec::new();
    for (name, kind) in names {
        let row = rows.iter().find(|r| r["name"] == name.as_str());
        match row.map(|r| &r["latency"]) {
            Some(l) if l["count"].as_u64().is_some_and(|c| c > 0) => per_robot.push(RobotFigures {
                name: name.clone(),
                kind: (*kind).to_string(),
                samples_per_s: l["count"].as_f64().unwrap_or(0.0) / seconds,
                p50_ms: l["p50_ms"].as_f64().unwrap_or(f64::NAN),
                p99_ms: l["p99_ms"].as_f64().unwrap_or(f64::NAN),
                max_ms: l["max_ms"].as_f64().unwrap_or(f64::NAN),
            }),
            _ => missing.push(name.clone()),
        }
    }
    Ok((per_robot, missing))
}

fn measure(args: &FleetArgs, dir: &Path) -> anyhow::Result<Vec<SizeFigures>> {
    let id = std::process::id() % 100_000;
    let netns = Netns::new(&[format!("cfb{id}")])?;
    let (prefix, operator_prefix) = (format!("cfb{id}_"), format!("cfb{id}_op_"));
    let chassisd = paths::sibling("chassisd")?;
    let (zenoh, chassis) = (paths::sibling("chassis-zenoh")?, paths::sibling("chassis")?);
    // The fleet's process `name`, logging to `<dir>/<name>.log` and `<name>-err.log`.
    let start = |command: &mut Command, prefix: &str, level: &str, name: &str| {
        paths::spawn_logged(command, (prefix, level), &dir.join(name), name)
    };
    // A command run in the robots' network namespace.
    let in_netns = |program: &Path| {
        let mut command = Command::new("ip");
        command.args(["netns", "exec", netns.robot()]).arg(program);
        command
    };
    let mut robots = Children::default();
    let mut robot_side_pids = Vec::new();
    let mut names: Vec<(String, &str)> = Vec::new();
    let mut figures = Vec::new();
    for &size in &args.sizes {
        while names.len() < size {
            let k = names.len();
            let (name, kind) = (format!("fb{k}"), KINDS[k % KINDS.len()]);
            let mut robot = Command::new(&chassisd);
            robot.args(["--robot", kind, "--name", &name, "--no-safety-monitor"]);
            robot.env("XDG_STATE_HOME", dir.join("state"));
            robots.push(start(
                &mut robot,
                &prefix,
                "warn",
                &format!("chassisd-{name}"),
            )?);
            wait_until(&format!("chassisd {name} serving"), 30, || {
                serves(&name, &prefix).then_some(())
            })?;
            let listen = format!("tcp/127.0.0.1:{}", BASE_PORT + k as u16);
            let mut side = in_netns(&zenoh);
            side.args(["--name", &name, "--listen", &listen]);
            let log = format!("zenoh-{name}");
            robot_side_pids.push(robots.push(start(&mut side, &prefix, ZENOH_LOG, &log)?));
            names.push((name, kind));
        }
        eprintln!("fleet of {size}: starting the operator");
        let mut operator = Children::default();
        let mut command = in_netns(&zenoh);
        for port in (0..size).map(|k| BASE_PORT + k as u16) {
            command.args(["--connect", &format!("tcp/127.0.0.1:{port}")]);
        }
        command.arg("--mirror-all");
        let log = format!("operator-{size}");
        let operator_pid = operator.push(start(&mut command, &operator_prefix, ZENOH_LOG, &log)?);
        for (name, _) in &names {
            wait_until(&format!("the operator mirroring {name}"), 60, || {
                serves(name, &operator_prefix).then_some(())
            })?;
        }
        crate::placement::pause(Duration::from_secs(2));
        let sides = || {
            robot_side_pids
                .iter()
                .map(|&p| process_cpu_s(p).unwrap_or(0.0))
                .sum()
        };
        let s = window(
            (&chassis, args.seconds),
            &operator_prefix,
            operator_pid,
            sides,
            &names,
        )?;
        let (cpu, rss) = (s.operator_cpu_pct, s.operator_rss_mib);
        let (rate, p50, p99) = (s.samples_per_s, s.median_p50_ms, s.worst_p99_ms);
        eprintln!(
            "fleet of {size}: operator {cpu:.1} % of a core, {rss:.1} MiB; {rate:.0} states/s; \
             p50 {p50:.2} ms, worst p99 {p99:.2} ms"
        );
        figures.push(s);
        drop(operator);
    }
    drop(robots);
    drop(netns);
    Ok(figures)
}

/// The figures of the fleet of `names` over `seconds` of `chassis` (`fleet`) at the operator's
/// iceoryx2 (`prefix`), `sides` the CPU time of every robot side, s.
fn window(
    (chassis, seconds): (&Path, f64),
    prefix: &str,
    operator_pid: u32,
    sides: impl Fn() -> f64,
    names: &[(String, &str)],
) -> anyhow::Result<SizeFigures> {
    let (machine0, cpu0, sides0) = (CpuTimes::read()?, process_cpu_s(operator_pid)?, sides());
    let start = now_ns();
    let out = Command::new(chassis)
        .args(["fleet", "--once", "--json", "--collect"])
        .arg(seconds.to_string())
        .env("CHASSIS_IPC_PREFIX", prefix)
        .output()
        .context("running chassis fleet")?;
    let elapsed = now_ns().saturating_sub(start) as f64 / 1e9;
    let (cpu1, sides1) = (process_cpu_s(operator_pid)?, sides());
    let (busy, total) = machine0.busy_since(&CpuTimes::read()?);
    if !out.status.success() {
        let stderr = String::from_utf8_lossy(&out.stderr);
        bail!("chassis fleet failed: {stderr}");
    }
    let (per_robot, missing) = robot_figures(&out.stdout, names, seconds)?;
    let mut p50s: Vec<f64> = per_robot.iter().map(|r| r.p50_ms).collect();
    p50s.sort_by(f64::total_cmp);
    let worst = |ms: fn(&RobotFigures) -> f64| per_robot.iter().map(ms).fold(0.0, f64::max);
    let status = |field| paths::status_field(operator_pid, field);
    Ok(SizeFigures {
        robots: names.len(),
        operator_cpu_pct: 100.0 * (cpu1 - cpu0) / elapsed,
        operator_rss_mib: status("VmRSS:")? / 1024.0,
        operator_peak_rss_mib: status("VmHWM:")? / 1024.0,
        operator_threads: status("Threads:")? as u64,
        robot_sides_cpu_pct: 100.0 * (sides1 - sides0) / elapsed,
        machine_busy_pct: 100.0 * busy as f64 / total.max(1) as f64,
        samples_per_s: per_robot.iter().map(|r| r.samples_per_s).sum(),
        median_p50_ms: p50s.get(p50s.len() / 2).copied().unwrap_or(f64::NAN),
        worst_p99_ms: worst(|r| r.p99_ms),
        worst_max_ms: worst(|r| r.max_ms),
        per_robot,
        missing,
    })
}

/// `text` without its `## Fleet` section, and that section: the document's last, where both
/// writers put it.
fn cut(text: &str) -> (&str, Option<&str>) {
    match text.find(&format!("\n{HEADING}")) {
        Some(i) => (&text[..i], Some(text[i + 1..].trim_end())),
        None => (text, None),
    }
}

/// `text` with its `## Fleet` section replaced by `section` (appended when it has none).
pub fn splice(text: &str, section: &str) -> String {
    format!("{}\n\n{}\n", cut(text).0.trim_end(), section.trim_end())
}

/// The performance document: `report`'s ([`crate::render::document`]), with the fleet section
/// of `existing` (the file as it is: `chassis-bench fleet` writes that section) kept.
pub fn document(report: &Report, existing: Option<&str>) -> anyhow::Result<String> {
    let text = crate::render::document(report)?;
    Ok(match existing.and_then(|e| cut(e).1) {
        Some(section) => splice(&text, section),
        None => text,
    })
}

impl FleetReport {
    /// The `## Fleet` section (`clients/bench/fleet.md`): method, figures, and the arithmetic
    /// for a larger fleet (`clients/bench/fleet-growth.md`) when it grew.
    pub fn markdown(&self) -> anyhow::Result<String> {
        let sizes = lines(&self.sizes, |s| {
            let (n, cpu, threads) = (s.robots, s.operator_cpu_pct, s.operator_threads);
            let (rss, peak) = (s.operator_rss_mib, s.operator_peak_rss_mib);
            let (rate, p50, p99) = (s.samples_per_s, s.median_p50_ms, s.worst_p99_ms);
            let (max, sides, busy) = (s.worst_max_ms, s.robot_sides_cpu_pct, s.machine_busy_pct);
            format!(
                "| {n} | {cpu:.1} | {rss:.1} ({peak:.1}) | {threads} | {rate:.0} | {p50:.2} | \
                 {p99:.2} | {max:.1} | {sides:.1} | {busy:.0} |"
            )
        });
        let missing = lines(self.sizes.iter().filter(|s| !s.missing.is_empty()), |s| {
            let (n, names) = (s.robots, s.missing.join(", "));
            format!(
                "* **{n} robots: no fresh samples from {names}** (counted as missing, not as fast)"
            )
        });
        let (Some(first), Some(last)) = (self.sizes.first(), self.sizes.last()) else {
            bail!("no fleet size measured");
        };
        let robots = lines(&last.per_robot, |r| {
            let (name, kind, rate) = (&r.name, &r.kind, r.samples_per_s);
            let (p50, p99, max) = (r.p50_ms, r.p99_ms, r.max_ms);
            format!("| {name} | {kind} | {rate:.0} | {p50:.2} | {p99:.2} | {max:.1} |")
        });
        let mut values = crate::render::provenance_values(&self.provenance, &self.machine);
        values.extend([
            ("build", self.build.clone()),
            ("seconds", format!("{:.0}", self.seconds)),
            ("sizes", sizes),
            ("missing", missing),
            ("largest", last.robots.to_string()),
            ("robots", robots),
            ("growth", growth(first, last)?),
        ]);
        fill(include_str!("../fleet.md"), &values)
    }
}

/// How the operator's cost grew from the `first` fleet size to the `last`, and what that makes
/// of 1,000 robots; nothing of a single size.
fn growth(first: &SizeFigures, last: &SizeFigures) -> anyhow::Result<String> {
    if last.robots <= first.robots {
        return Ok(String::new());
    }
    let added = (last.robots - first.robots) as f64;
    let cpu_per_robot = (last.operator_cpu_pct - first.operator_cpu_pct) / added;
    // The rate each robot sends when the machine keeps up: the smallest fleet's.
    let rate = first.samples_per_s / first.robots as f64;
    let last_rate = last.samples_per_s / last.robots as f64;
    let state_bytes = size_of::<ChassisState>() as f64;
    let (robots, busy) = (last.robots, last.machine_busy_pct);
    let kept_up = (last_rate < 0.8 * rate).then(|| {
        format!(
            " At {robots} robots this machine no longer kept up (busy {busy:.0} %): each robot's \
             states arrived at {last_rate:.0}/s, and the latency there is mostly time spent \
             waiting for a CPU; the operator's CPU per robot above is understated by as much."
        )
    });
    let mib_per_robot = (last.operator_rss_mib - first.operator_rss_mib) / added;
    let (kb_per_s, mb_per_s) = (rate * state_bytes / 1e3, 1000.0 * rate * state_bytes / 1e6);
    let values = [
        ("first", first.robots.to_string()),
        ("last", last.robots.to_string()),
        ("cpu_per_robot", format!("{cpu_per_robot:.2}")),
        ("mib_per_robot", format!("{mib_per_robot:.2}")),
        ("rate", format!("{rate:.0}")),
        ("kb_per_s", format!("{kb_per_s:.0}")),
        ("state_bytes", state_bytes.to_string()),
        ("kept_up", kept_up.unwrap_or_default()),
        ("mb_per_s", format!("{mb_per_s:.0}")),
        ("cores", format!("{:.0}", 10.0 * cpu_per_robot)),
    ];
    Ok(fill(include_str!("../fleet-growth.md"), &values)?
        .trim_end()
        .to_string())
}

/// Writes the report's files.
pub fn write(report: &FleetReport, args: &FleetArgs) -> anyhow::Result<()> {
    let markdown = report.markdown()?;
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_string_pretty(report)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if let Some(path) = &args.doc {
        let text = std::fs::read_to_string(path).unwrap_or_default();
        std::fs::write(path, splice(&text, &markdown))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    println!("{markdown}");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// docs/PERFORMANCE.md is its samples, docs/bench.jsonl, rendered: byte for byte (its fleet
    /// section is `chassis-bench fleet`'s, kept as the file has it).
    #[test]
    fn the_performance_document_is_its_samples_rendered() {
        let docs = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs");
        let samples = std::fs::read_to_string(docs.join("bench.jsonl")).unwrap();
        let doc = std::fs::read_to_string(docs.join("PERFORMANCE.md")).unwrap();
        let rendered = document(&Report::from_samples(&samples).unwrap(), Some(&doc)).unwrap();
        assert!(
            rendered == doc,
            "docs/PERFORMANCE.md is not docs/bench.jsonl rendered: measure again, or run \
             `chassis-bench render docs/bench.jsonl --doc docs/PERFORMANCE.md`"
        );
    }

    #[test]
    fn the_fleet_section_is_replaced_and_the_rest_kept() {
        let doc = "# Performance\n\nintro\n\n## The table\n\nrows\n";
        assert_eq!(cut(doc), (doc, None));
        let once = splice(doc, "## Fleet: x\n\nfigures 1\n");
        assert_eq!(once, format!("{doc}\n## Fleet: x\n\nfigures 1\n"));
        assert_eq!(cut(&once).1, Some("## Fleet: x\n\nfigures 1"));
        let twice = splice(&once, "## Fleet: y\n\nfigures 2");
        assert_eq!(twice, format!("{doc}\n## Fleet: y\n\nfigures 2\n"));
    }
}
