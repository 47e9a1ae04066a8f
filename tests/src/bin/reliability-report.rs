//! Renders docs/RELIABILITY.md from the figures the fault tests and the soak recorded.
//!
//! ```text
//! reliability-report begin DIR NAME COMMAND [--allow-dirty]
//!                           # DIR/NAME-run.json: date, commit, machine, /proc/stat now
//! reliability-report end DIR NAME   # adds the host's steal time since `begin`
//! reliability-report render DIR OUT # faults.jsonl + soak.jsonl → OUT (markdown)
//! ```
//!
//! `begin` refuses a git tree with uncommitted changes: the figures must belong to a commit.
//! `--allow-dirty` lets a local run through; its section then says DIRTY. `scripts/reliability`
//! and `scripts/soak` call it; see their headers.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

use anyhow::{Context, bail};
use chassis_tests::{ExpectedRow, FAULT_ROWS, Figure, SOAK_ROWS, STATE_BUFFER};
use serde::{Deserialize, Serialize};

/// When, where and how a set of figures was measured.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
#[serde(default)]
struct RunInfo {
    date: String,
    commit: String,
    /// The tree had uncommitted changes (allowed with `--allow-dirty`).
    dirty: bool,
    machine: String,
    command: String,
    /// `/proc/stat`'s total CPU time and steal time at `begin`, clock ticks.
    cpu_start: Option<CpuTimes>,
    /// The host's steal time between `begin` and `end`.
    steal: Option<Steal>,
}

/// The first line of `/proc/stat`: CPU time of every CPU together, clock ticks.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
struct CpuTimes {
    total: u64,
    steal: u64,
}

impl CpuTimes {
    fn read() -> anyhow::Result<Self> {
        let stat = std::fs::read_to_string("/proc/stat").context("reading /proc/stat")?;
        let line = stat
            .lines()
            .find(|l| l.starts_with("cpu "))
            .context("/proc/stat has no cpu line")?;
        let fields: Vec<u64> = line
            .split_whitespace()
            .skip(1)
            .map(|v| v.parse().context("a field of /proc/stat's cpu line"))
            .collect::<anyhow::Result<_>>()?;
        // user nice system idle iowait irq softirq steal guest guest_nice; guest time is
        // already counted in user and nice.
        let steal = *fields.get(7).context("/proc/stat has no steal column")?;
        Ok(Self {
            total: fields.iter().take(8).sum(),
            steal,
        })
    }
}

/// Steal time over a run: time the host ran something else while this machine's CPUs wanted
/// to run.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
struct Steal {
    steal_s: f64,
    cpu_time_s: f64,
}

impl Steal {
    fn between(start: CpuTimes, end: CpuTimes) -> Self {
        let hz = ticks_per_second();
        Self {
            steal_s: end.steal.saturating_sub(start.steal) as f64 / hz,
            cpu_time_s: end.total.saturating_sub(start.total) as f64 / hz,
        }
    }

    fn text(&self) -> String {
        let share = if self.cpu_time_s > 0.0 {
            100.0 * self.steal_s / self.cpu_time_s
        } else {
            0.0
        };
        format!(
            "{:.2} s of {:.0} s of CPU time ({share:.2} %)",
            self.steal_s, self.cpu_time_s
        )
    }
}

fn ticks_per_second() -> f64 {
    nix::unistd::sysconf(nix::unistd::SysconfVar::CLK_TCK)
        .ok()
        .flatten()
        .map_or(100.0, |t| t as f64)
}

fn output(program: &str, args: &[&str]) -> String {
    Command::new(program)
        .args(args)
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_default()
}

fn machine() -> String {
    let cpus = std::thread::available_parallelism().map_or(0, |n| n.get());
    let model = std::fs::read_to_string("/proc/cpuinfo")
        .unwrap_or_default()
        .lines()
        .find_map(|l| l.strip_prefix("model name"))
        .map(|l| l.trim_start_matches([' ', '\t', ':']).to_string())
        .unwrap_or_else(|| "unknown CPU".into());
    let memory = std::fs::read_to_string("/proc/meminfo")
        .unwrap_or_default()
        .lines()
        .find_map(|l| l.strip_prefix("MemTotal:"))
        .and_then(|v| v.split_whitespace().next()?.parse::<u64>().ok())
        .map_or(String::new(), |kib| {
            format!(", {:.0} GiB", kib as f64 / 1024.0 / 1024.0)
        });
    let virt = output("systemd-detect-virt", &[]);
    let virt = if virt.is_empty() || virt == "none" {
        String::new()
    } else {
        format!(" (systemd-detect-virt: {virt})")
    };
    format!(
        "{model}, {cpus} cores{memory}, Linux {}{virt}",
        output("uname", &["-r"])
    )
}

/// The commit checked out, and the files changed since (tracked files only).
fn git_state() -> anyhow::Result<(String, Vec<String>)> {
    let commit = output("git", &["rev-parse", "--short", "HEAD"]);
    if commit.is_empty() {
        bail!("not a git checkout (or git is missing): the figures would belong to no commit");
    }
    let changed = output("git", &["status", "--porcelain", "--untracked-files=no"])
        .lines()
        .map(|l| l.trim().to_string())
        .collect();
    Ok((commit, changed))
}

fn info_path(dir: &Path, name: &str) -> PathBuf {
    dir.join(format!("{name}-run.json"))
}

fn write_info(path: &Path, info: &RunInfo) -> anyhow::Result<()> {
    std::fs::write(path, serde_json::to_string_pretty(info)? + "\n")
        .with_context(|| format!("writing {}", path.display()))
}

fn begin(dir: &Path, name: &str, command: &str, allow_dirty: bool) -> anyhow::Result<()> {
    let (commit, changed) = git_state()?;
    if !changed.is_empty() && !allow_dirty {
        bail!(
            "the git tree has uncommitted changes ({}): figures for the docs must come from a \
             commit. Commit them, or pass --allow-dirty for a local run (its section then says \
             DIRTY)",
            changed.join(", ")
        );
    }
    let info = RunInfo {
        date: output("date", &["-u", "+%Y-%m-%d %H:%M UTC"]),
        commit,
        dirty: !changed.is_empty(),
        machine: machine(),
        command: command.to_string(),
        cpu_start: Some(CpuTimes::read()?),
        steal: None,
    };
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    // The figures of an earlier run are not this run's.
    let _ = std::fs::remove_file(dir.join(format!("{name}.jsonl")));
    write_info(&info_path(dir, name), &info)
}

fn end(dir: &Path, name: &str) -> anyhow::Result<()> {
    let path = info_path(dir, name);
    let mut info = read_info(&path)
        .with_context(|| format!("{} is missing: `begin` did not run", path.display()))?;
    let start = info
        .cpu_start
        .with_context(|| format!("{} has no start figures", path.display()))?;
    info.steal = Some(Steal::between(start, CpuTimes::read()?));
    // The tree must still be the commit the run began on.
    let (commit, changed) = git_state()?;
    if commit != info.commit || !changed.is_empty() {
        info.dirty = true;
    }
    write_info(&path, &info)
}

fn read_figures(path: &Path) -> anyhow::Result<Vec<Figure>> {
    let Ok(text) = std::fs::read_to_string(path) else {
        return Ok(Vec::new());
    };
    text.lines()
        .filter(|l| !l.trim().is_empty())
        .enumerate()
        .map(|(i, l)| {
            serde_json::from_str(l).with_context(|| format!("{}:{}", path.display(), i + 1))
        })
        .collect()
}

fn read_info(path: &Path) -> Option<RunInfo> {
    serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()
}

/// Text safe inside a markdown table cell.
fn cell(text: &str) -> String {
    text.replace('|', "\\|").replace('\n', " ")
}

fn verdict(pass: bool) -> &'static str {
    if pass { "pass" } else { "**FAIL**" }
}

fn provenance(out: &mut String, info: Option<&RunInfo>) {
    match info {
        Some(info) => {
            let commit = if info.dirty {
                format!("`{}` — DIRTY: uncommitted changes", info.commit)
            } else {
                format!("`{}`", info.commit)
            };
            let steal = info.steal.as_ref().map_or_else(
                || "not measured (the run did not finish)".to_string(),
                Steal::text,
            );
            out.push_str(&format!(
                "Measured {} on commit {commit}; machine: {}; the host's steal time over the \
                 run: {steal}.\nReproduce: `{}`\n\n",
                info.date, info.machine, info.command
            ));
        }
        None => out.push_str("(no run information recorded)\n\n"),
    }
}

const INTRO: &str = "\
# Reliability under faults

Each row is a test with the real processes (`chassisd`, `chassisd sim`, `chassis-safety`,
`chassis-planner`, `chassis-teleop`, the `chassis` tool) that injects a fault, checks what the
system did and measures a figure. This file is generated from the figures of one run — do not
edit it by hand: `scripts/reliability` runs the fault tests and renders it, `scripts/soak`
adds the soak section. The fault tests are part of `cargo test` (and of `.ci/run`); random
fault moments come from a printed seed (`CHASSIS_FAULT_SEED=N` repeats a run).

";

const NOTES: &str = "\
## Notes on the figures

* **Time to stop** is measured from the `SIGKILL` to the first mux decision with a zero output
  (its stamp) and to the last TX frame asking for motion (the frame tap's stamp). A dead source
  never gets a grace period: its motion ends when its last request reaches its timeout, so both
  stay at or below the timeout. The robot standing still takes longer: that is the simulated
  chassis braking (a first-order lag), not the service.
* **Storms** are bracketed by a short injected silence of the chassis, so that the service's
  counters and the frames on the tap are compared at a quiet moment: the bad frames counted
  equal the bad frames on the wire, and every good frame on the wire was decoded.
* **The rogue client** is one thread publishing as fast as it can. The service's wake-up
  budget (`WakeBudget` in `services/chassisd/src/service.rs`) detaches a source's listener for
  the rest of a tick after its share of wake-ups; the source's requests are still read every
  tick. The row gives the share of a core the service used under the flood, as measured.
* **Heartbeat jitter** on a shared machine is bounded by the kernel as well as by the service,
  so the flood test compares its window with a quiet window measured just before (both are in
  the row), and holds the bulk of the periods (not every one) within 20 ± 2 ms. The soak is
  stricter: it fails on any 0x111 gap of two periods (40 ms) or more. Such a gap means the
  service's loop did not run for that long, and the state readers' longest wait for a sample
  shows the same stall. The TITAN itself stops only after 500 ms without a command.
";

/// One rendered row: the expected row and its figure, if one was recorded.
struct Row<'a> {
    fault: &'a str,
    command: String,
    figure: Option<&'a Figure>,
    /// False for a recorded figure that is in no expected row.
    expected: bool,
}

impl Row<'_> {
    fn pass(&self) -> bool {
        self.expected && self.figure.is_some_and(|f| f.pass)
    }
}

/// The rows of a table: every expected row in its order, with the last figure recorded for it
/// (none: its test failed before measuring), then any recorded figure no row expects.
fn rows<'a>(expected: &'a [ExpectedRow], figures: &'a [Figure]) -> Vec<Row<'a>> {
    let mut rows: Vec<Row<'a>> = expected
        .iter()
        .map(|e| Row {
            fault: e.fault,
            command: e.command(),
            figure: figures.iter().rev().find(|f| e.matches(f)),
            expected: true,
        })
        .collect();
    for f in figures {
        if !expected.iter().any(|e| e.matches(f)) {
            rows.push(Row {
                fault: &f.fault,
                command: format!("cargo test -p chassis-tests --test {} {}", f.suite, f.test),
                figure: Some(f),
                expected: false,
            });
        }
    }
    rows
}

/// The verdict cell of a row.
fn result_cell(row: &Row) -> &'static str {
    match (row.expected, row.figure) {
        (false, _) => "**FAIL** (a figure no row of the report expects)",
        (true, None) => "**FAIL** (no figure: the test failed before recording it)",
        (true, Some(f)) => verdict(f.pass),
    }
}

/// "N of M rows within their bounds", and the rows that are not.
fn summary(rows: &[Row]) -> String {
    let passed = rows.iter().filter(|r| r.pass()).count();
    let mut text = format!("{passed} of {} rows within their bounds.", rows.len());
    let missing: Vec<&str> = rows
        .iter()
        .filter(|r| r.figure.is_none())
        .map(|r| r.fault)
        .collect();
    if !missing.is_empty() {
        text.push_str(&format!(
            " No figure recorded for {} (their tests failed before measuring): {}.",
            missing.len(),
            missing.join("; ")
        ));
    }
    let failed = rows
        .iter()
        .filter(|r| r.figure.is_some() && !r.pass())
        .count();
    if failed > 0 {
        text.push_str(&format!(" {failed} recorded outside their bounds."));
    }
    text
}

/// Renders OUT; returns how many rows failed or are missing.
fn render(dir: &Path, out_path: &Path) -> anyhow::Result<usize> {
    let faults = read_figures(&dir.join("faults.jsonl"))?;
    let faults_info = read_info(&dir.join("faults-run.json"));
    if faults.is_empty() && faults_info.is_none() {
        bail!(
            "{} holds no figures and no run information: run scripts/reliability",
            dir.display()
        );
    }
    let soak = read_figures(&dir.join("soak.jsonl"))?;
    let soak_info = read_info(&dir.join("soak-run.json"));
    let mut out = String::from(INTRO);

    out.push_str("## The fault matrix\n\n");
    provenance(&mut out, faults_info.as_ref());
    let fault_rows = rows(FAULT_ROWS, &faults);
    out.push_str(&summary(&fault_rows));
    out.push_str("\n\n");
    out.push_str(
        "| fault | how it is injected | what the system did | figure measured | result | \
         reproduce |\n| --- | --- | --- | --- | --- | --- |\n",
    );
    for row in &fault_rows {
        let (injection, behaviour, figure) = match row.figure {
            Some(f) => (cell(&f.injection), cell(&f.behaviour), cell(&f.figure)),
            None => ("—".into(), "—".into(), "not measured".into()),
        };
        out.push_str(&format!(
            "| {} | {injection} | {behaviour} | {figure} | {} | `{}` |\n",
            cell(row.fault),
            result_cell(row),
            row.command
        ));
    }
    out.push('\n');
    let mut failures = fault_rows.iter().filter(|r| !r.pass()).count();

    out.push_str("## Soak\n\n");
    let mut soak_rows = Vec::new();
    if soak.is_empty() && soak_info.is_none() {
        out.push_str("Not run yet: `scripts/soak 10` measures it (10 minutes).\n\n");
    } else {
        provenance(&mut out, soak_info.as_ref());
        // One injection text for the whole soak.
        let mut runs: BTreeMap<&str, ()> = BTreeMap::new();
        for f in &soak {
            runs.insert(&f.injection, ());
        }
        for injection in runs.keys() {
            out.push_str(&format!("{injection}.\n\n"));
        }
        soak_rows = rows(SOAK_ROWS, &soak);
        out.push_str(&summary(&soak_rows));
        out.push_str("\n\n");
        out.push_str("| measured | what it shows | figure | result |\n| --- | --- | --- | --- |\n");
        for row in &soak_rows {
            let (behaviour, figure) = match row.figure {
                Some(f) => (cell(&f.behaviour), cell(&f.figure)),
                None => ("—".into(), "not measured".into()),
            };
            out.push_str(&format!(
                "| {} | {behaviour} | {figure} | {} |\n",
                cell(row.fault),
                result_cell(row)
            ));
        }
        out.push('\n');
        out.push_str(&format!(
            "What \"zero gaps\" is measured on: frames — `BusFrame::seq` numbers every frame \
             the service read or wrote, and two readers draining the tap from their own \
             threads (the soak's and `chassis record`'s) must see every number. State — \
             `ChassisState::seq` numbers every sample the service publishes (a sample per \
             frame that changes the state, so in bursts while a saturated bus is read); a \
             failed publication is logged, and none may happen. Two readers drain a state \
             stream each (`Robot::state_stream`, {STATE_BUFFER} samples deep): the soak's, \
             from its own thread, must see every number published from its start to the end \
             of the run, with the longest wait for a sample reported, and `chassis record`, \
             which records every sample, must lose none; the safety monitor's stale-state rule \
             must never fire. A `Robot`'s own state reading is latest-value (the newest \
             samples, for control loops and displays), and `chassis echo state` prints the \
             newest sample per wake-up by design: neither is a gap counter.\n\n"
        ));
        failures += soak_rows.iter().filter(|r| !r.pass()).count();
    }
    out.push_str(NOTES);
    std::fs::write(out_path, out).with_context(|| format!("writing {}", out_path.display()))?;
    println!(
        "{}\n  fault matrix: {}\n  soak: {}",
        out_path.display(),
        summary(&fault_rows),
        if soak_rows.is_empty() {
            "not run".to_string()
        } else {
            summary(&soak_rows)
        }
    );
    Ok(failures)
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args
        .iter()
        .map(String::as_str)
        .collect::<Vec<_>>()
        .as_slice()
    {
        ["begin", dir, name, command] => begin(Path::new(dir), name, command, false),
        ["begin", dir, name, command, "--allow-dirty"] => {
            begin(Path::new(dir), name, command, true)
        }
        ["end", dir, name] => end(Path::new(dir), name),
        ["render", dir, out] => match render(Path::new(dir), &PathBuf::from(out)) {
            Ok(0) => Ok(()),
            Ok(failures) => Err(anyhow::anyhow!(
                "{out} written with {failures} rows failed or not measured"
            )),
            Err(e) => Err(e),
        },
        _ => {
            eprintln!(
                "usage: reliability-report begin DIR NAME COMMAND [--allow-dirty]\n       \
                 reliability-report end DIR NAME\n       \
                 reliability-report render DIR OUT"
            );
            return ExitCode::from(2);
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("reliability-report: {err:#}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn figure_of(row: &ExpectedRow, pass: bool) -> Figure {
        Figure {
            rank: 0,
            fault: row.fault.into(),
            injection: "injected".into(),
            behaviour: "behaved".into(),
            figure: "1 ms".into(),
            value: 1.0,
            pass,
            suite: row.suite.into(),
            test: row.test.into(),
        }
    }

    #[test]
    fn a_row_whose_test_recorded_nothing_is_a_failed_row_naming_its_test() {
        // Every row recorded and passing but the second.
        let figures: Vec<Figure> = FAULT_ROWS
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != 1)
            .map(|(_, r)| figure_of(r, true))
            .collect();
        let rows = rows(FAULT_ROWS, &figures);
        assert_eq!(rows.len(), FAULT_ROWS.len());
        assert!(rows[1].figure.is_none() && !rows[1].pass());
        assert!(rows[1].command.contains(FAULT_ROWS[1].test));
        assert!(result_cell(&rows[1]).contains("FAIL"));
        let text = summary(&rows);
        assert!(
            text.starts_with(&format!(
                "{} of {} rows within their bounds.",
                FAULT_ROWS.len() - 1,
                FAULT_ROWS.len()
            )),
            "{text}"
        );
        assert!(text.contains(FAULT_ROWS[1].fault), "{text}");
    }

    #[test]
    fn a_failed_figure_and_a_figure_no_row_expects_fail_the_table() {
        let mut figures: Vec<Figure> = FAULT_ROWS.iter().map(|r| figure_of(r, true)).collect();
        figures[0].pass = false;
        let stray = ExpectedRow {
            suite: "faults",
            test: "no_such_test",
            fault: "a fault nobody expects",
        };
        figures.push(figure_of(&stray, true));
        let rows = rows(FAULT_ROWS, &figures);
        assert_eq!(rows.len(), FAULT_ROWS.len() + 1);
        assert!(!rows[0].pass());
        assert!(!rows[FAULT_ROWS.len()].pass());
        assert_eq!(rows.iter().filter(|r| !r.pass()).count(), 2);
    }
}
