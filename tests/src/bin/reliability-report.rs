//! Renders docs/RELIABILITY.md from the figures the fault tests and the soak recorded.
//!
//! ```text
//! reliability-report begin DIR NAME COMMAND [--allow-dirty]
//!                           # DIR/NAME-run.json: date, commit, machine, /proc/stat now
//! reliability-report end DIR NAME   # adds the host's steal time since `begin`
//! reliability-report render DIR OUT # faults.jsonl + soak.jsonl → OUT (markdown)
//! ```
//!
//! A row passes only when its test passed: `render` reads each test's outcome from libtest's
//! output of the run, which the scripts keep beside the figures (`DIR/faults-tests.log`,
//! `DIR/soak-tests.log`). A row whose test failed, or whose outcome the log does not hold, is
//! FAIL whatever its figure says (the tests write a figure as passing only from their last
//! statement, `chassis_tests::Figures::finish`, and as failed when they panic).
//!
//! `begin` refuses a git tree with uncommitted changes: the figures must belong to a commit.
//! `--allow-dirty` lets a local run through; its section then says DIRTY. `scripts/reliability`
//! and `scripts/soak` call it; see their headers.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, bail};
use chassis_provenance::{CpuTimes, GitState, Steal, output};
use chassis_tests::{ExpectedRow, FAULT_ROWS, Figure, SOAK_ROWS, STATE_BUFFER, rerun_command};
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
    let git = GitState::read()
        .context("not a git checkout (or git is missing): the figures would belong to no commit")?;
    Ok((git.commit, git.changed))
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
        date: chassis_provenance::utc_date(),
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
    info.steal = Some(start.steal_until(&CpuTimes::read()?));
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

/// What libtest said of one test.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Outcome {
    Passed,
    Failed,
    Ignored,
    /// Not in the run's log: not run, or its test binary ended without a summary.
    Unknown,
}

/// Every test's outcome in the output of `cargo test` (stdout and stderr together), by
/// (suite, test): the suite is the integration test file, the one cargo names in its `Running
/// tests/SUITE.rs (…)` line or, in a binary of modules (`Running tests/system/main.rs`), the
/// first part of the test's path (`SUITE::test`). Read from what libtest prints whatever the capture mode:
/// `test NAME ... ok|FAILED|ignored` (with `--nocapture` the verdict may come lines later, after
/// the test's own output), the names under the second `failures:` heading, and the binary's
/// `test result:` line — a test named in a binary that never printed its result (it crashed) is
/// not known to have passed.
#[derive(Debug, Default)]
struct Outcomes(BTreeMap<(String, String), Outcome>);

impl Outcomes {
    fn parse(text: &str) -> Self {
        let mut outcomes = BTreeMap::new();
        // The binary's file, and whether its tests are named `SUITE::test`.
        let mut suite: Option<(String, bool)> = None;
        // Per binary: names started, verdicts on their line, the failures list, its summary.
        let mut started: Vec<String> = Vec::new();
        let mut verdicts: BTreeMap<String, Outcome> = BTreeMap::new();
        let mut failed: Vec<String> = Vec::new();
        let mut summary = false;
        let mut failures_headings = 0;
        let mut flush = |suite: &Option<(String, bool)>,
                         started: &mut Vec<String>,
                         verdicts: &mut BTreeMap<String, Outcome>,
                         failed: &mut Vec<String>,
                         summary: bool| {
            if let Some((file, modules)) = suite {
                for name in started.drain(..) {
                    let outcome = if failed.contains(&name) {
                        Outcome::Failed
                    } else {
                        match verdicts.get(&name) {
                            Some(v) => *v,
                            None if summary => Outcome::Passed,
                            None => Outcome::Unknown,
                        }
                    };
                    let key = match name.split_once("::") {
                        Some((module, test)) if *modules => (module.to_string(), test.to_string()),
                        _ => (file.clone(), name),
                    };
                    outcomes.insert(key, outcome);
                }
            }
            started.clear();
            verdicts.clear();
            failed.clear();
        };
        for line in text.lines() {
            let trimmed = line.trim();
            if let Some(rest) = trimmed.strip_prefix("Running ") {
                flush(&suite, &mut started, &mut verdicts, &mut failed, summary);
                summary = false;
                failures_headings = 0;
                suite = rest
                    .split_whitespace()
                    .next()
                    .and_then(|path| path.strip_prefix("tests/"))
                    .and_then(|file| file.strip_suffix(".rs"))
                    .map(|file| match file.strip_suffix("/main") {
                        Some(binary) => (binary.to_string(), true),
                        None => (file.to_string(), false),
                    });
                continue;
            }
            if trimmed.starts_with("test result:") {
                summary = true;
                continue;
            }
            if trimmed == "failures:" {
                failures_headings += 1;
                continue;
            }
            // The second `failures:` heading lists the failed tests, indented.
            if failures_headings >= 2
                && line.starts_with("    ")
                && !trimmed.is_empty()
                && !trimmed.contains(' ')
            {
                failed.push(trimmed.to_string());
                continue;
            }
            if let Some(start) = line.find("test ")
                && let Some((name, verdict)) = line[start + 5..].split_once(" ... ")
                && !name.is_empty()
                && !name.contains(' ')
            {
                started.push(name.to_string());
                let verdict = verdict.trim();
                let outcome = if verdict.starts_with("ok") {
                    Some(Outcome::Passed)
                } else if verdict.starts_with("FAILED") {
                    Some(Outcome::Failed)
                } else if verdict.starts_with("ignored") {
                    Some(Outcome::Ignored)
                } else {
                    None
                };
                if let Some(outcome) = outcome {
                    verdicts.insert(name.to_string(), outcome);
                }
            }
        }
        flush(&suite, &mut started, &mut verdicts, &mut failed, summary);
        Self(outcomes)
    }

    /// Reads `path` (missing: no outcome known).
    fn read(path: &Path) -> Self {
        std::fs::read_to_string(path)
            .map(|text| Self::parse(&text))
            .unwrap_or_default()
    }

    fn of(&self, suite: &str, test: &str) -> Outcome {
        self.0
            .get(&(suite.to_string(), test.to_string()))
            .copied()
            .unwrap_or(Outcome::Unknown)
    }
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
fault moments come from a printed seed (`CHASSIS_FAULT_SEED=N` repeats a run). A row passes
only if its figure is within its bounds and its test passed: a test writes its figures as
passing only from its last statement, after its last assert, and the report reads each test's
outcome from the run's libtest output.

";

const NOTES: &str = "\
## Notes on the figures

* **Time to stop** is measured from the `SIGKILL` to the first mux decision with a zero output
  (its stamp) and to the last TX frame asking for motion (the frame tap's stamp). A dead source
  never gets a grace period: its motion ends when its last request reaches its timeout, so both
  stay at or below the timeout. The robot standing still takes longer: that is the simulated
  chassis braking (a first-order lag), not the service.
* **Storms** are held against the sender's truth: the simulated chassis counts every garbage
  frame (byte) and every frame it corrupted as it hands it to the bus (`chassis sim truth
  --injected`). A row requires that something was asked for, that the chassis injected exactly
  that (once its last pending corruptions went out: the time after the storm is in the row,
  bounded by 1 s), and then — at a quiet moment, bracketed by an injected silence — that the
  bad items on the service's tap and its counters equal the injected count, with every good
  frame on the wire decoded. No difference is allowed.
* **Drove again** (after a restart, a hang-up) is a speed the chassis reported after the
  fault: a state sample whose motion group was stamped after the restart
  (`chassis_tests::drove_again_after`), never the last speed the state keeps from before it.
* **The rogue client** is one thread publishing as fast as it can, on a source below, equal to
  and above the one that drives. Below, it never wins; equal, the newer request wins (the mux's
  ages say which, in every sample); above, it wins, by design. In every case the monitor stays
  fresh, every request the rogue sent is read (the mux's last seq of its source is the rogue's
  last), the heartbeat keeps its grid and the service stays within half a core. The service's
  wake-up budget (`WakeBudget` in `services/chassisd/src/service.rs`) detaches a source's
  listener for the rest of a tick after its share of wake-ups; the source's requests are still
  read every tick. chassisd runs in real-time mode there, as `--realtime` runs it on a robot:
  with normal scheduling a loop that sleeps waits for the kernel behind a thread that never does
  (25-30 ms wake-ups on the 2-core machine of these figures).
* **Heartbeat jitter** is measured per slot of the 20 ms grid, from the start of a window to
  its end: the lateness of the first 0x111 of each slot, each slot served (a heartbeat less
  than a period late), no gap of two periods (40 ms), the end of the window included — a
  heartbeat that stops for good fails on its count and its last gap. The flood tests compare
  their window with a quiet window measured just before (both are in the row) and hold the
  bulk of the slots (90 %) within 2 ms. The soak holds every slot but one per mille served.
  Such a gap means the service's loop did not run for that long, and the state readers'
  longest wait for a sample shows the same stall. The TITAN itself stops only after 500 ms
  without a command.
* **The watchdog** is tested with the loop's thread alone stalled (a test hook of chassisd,
  armed only by `CHASSISD_TEST_LOOP_STALL_FILE`), its other threads running on: a ping from a
  timer beside the loop would not stop.
* **The held e-stop** is killed at measured moments after chassisd's answer: at once after the
  answer arrived, then one draw in each 6 ms of the 30 ms after the answer's stamp.
";

/// One rendered row: the expected row, its figure if one was recorded, its test's outcome.
struct Row<'a> {
    fault: &'a str,
    command: String,
    figure: Option<&'a Figure>,
    /// False for a recorded figure that is in no expected row.
    expected: bool,
    outcome: Outcome,
}

impl Row<'_> {
    /// Within its bounds: an expected row, its figure says so, and its test passed.
    fn pass(&self) -> bool {
        self.expected && self.outcome == Outcome::Passed && self.figure.is_some_and(|f| f.pass)
    }
}

/// The rows of a table: every expected row in its order, with the last figure recorded for it
/// (none: its test failed before measuring) and its test's outcome, then any recorded figure no
/// row expects.
fn rows<'a>(
    expected: &'a [ExpectedRow],
    figures: &'a [Figure],
    outcomes: &Outcomes,
) -> Vec<Row<'a>> {
    let mut rows: Vec<Row<'a>> = expected
        .iter()
        .map(|e| Row {
            fault: e.fault,
            command: e.command(),
            figure: figures.iter().rev().find(|f| e.matches(f)),
            expected: true,
            outcome: outcomes.of(e.suite, e.test),
        })
        .collect();
    for f in figures {
        if !expected.iter().any(|e| e.matches(f)) {
            rows.push(Row {
                fault: &f.fault,
                command: rerun_command(&f.suite, &f.test),
                figure: Some(f),
                expected: false,
                outcome: outcomes.of(&f.suite, &f.test),
            });
        }
    }
    rows
}

/// The verdict cell of a row.
fn result_cell(row: &Row) -> &'static str {
    match (row.expected, row.figure, row.outcome) {
        (false, _, _) => "**FAIL** (a figure no row of the report expects)",
        (true, None, _) => "**FAIL** (no figure: the test failed before recording it)",
        (true, Some(_), Outcome::Failed) => "**FAIL** (its test failed)",
        (true, Some(_), Outcome::Ignored) => "**FAIL** (its test was ignored)",
        (true, Some(_), Outcome::Unknown) => "**FAIL** (no outcome of its test in the run's log)",
        (true, Some(f), Outcome::Passed) => verdict(f.pass),
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
    let test_failed = rows
        .iter()
        .filter(|r| r.figure.is_some() && r.expected && r.outcome != Outcome::Passed)
        .count();
    if test_failed > 0 {
        text.push_str(&format!(
            " {test_failed} whose test did not pass (failed, or no outcome in the run's log)."
        ));
    }
    let failed = rows
        .iter()
        .filter(|r| r.figure.is_some() && r.outcome == Outcome::Passed && !r.pass())
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
    let fault_rows = rows(
        FAULT_ROWS,
        &faults,
        &Outcomes::read(&dir.join("faults-tests.log")),
    );
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
        soak_rows = rows(
            SOAK_ROWS,
            &soak,
            &Outcomes::read(&dir.join("soak-tests.log")),
        );
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
    use chassis_tests::OWN_BINARIES;

    /// The outcomes of a run in which every expected test passed.
    fn all_passed() -> Outcomes {
        Outcomes(
            FAULT_ROWS
                .iter()
                .chain(SOAK_ROWS)
                .map(|r| ((r.suite.to_string(), r.test.to_string()), Outcome::Passed))
                .collect(),
        )
    }

    /// Output of `cargo test … 2>&1` as the scripts keep it: three binaries, one with a failed
    /// test, one run with `--nocapture` (the verdict after the test's own output), one that
    /// crashed before its summary.
    const LOG: &str = "\
   Compiling chassis-tests v0.1.0 (/w/tests)
    Finished `test` profile [unoptimized + debuginfo] target(s) in 9.1s
     Running tests/faults_bus.rs (target/debug/deps/faults_bus-0a1b)

running 3 tests
test garbage_storms ... ok
test bad_checksum_storms ... FAILED
test slow_one ... ignored, needs a robot

failures:

---- bad_checksum_storms stdout ----
thread 'bad_checksum_storms' panicked at tests/tests/faults_bus.rs:1:1:
the sender's count

failures:
    bad_checksum_storms

test result: FAILED. 1 passed; 1 failed; 1 ignored; 0 measured; 0 filtered out; finished in 20.00s

     Running tests/soak.rs (target/release/deps/soak-9f)

running 1 test
test a_titan_soak ... 10 s: chassisd 29212 KiB, 146 fds
FIGURE [pass] heartbeat (0x111) jitter: 500 of 500 slots served
ok

test result: ok. 1 passed; 0 failed; 0 ignored; 0 measured; 0 filtered out; finished in 60.00s

     Running tests/system/main.rs (target/debug/deps/system-77)

running 3 tests
test service::a_stop ... ok
test systemd::ready_first ... ok
test systemd::the_watchdog_test ... 
error: test failed, to rerun pass `-p chassis-tests --test system`
";

    #[test]
    fn libtest_output_gives_each_tests_outcome() {
        let outcomes = Outcomes::parse(LOG);
        assert_eq!(outcomes.of("faults_bus", "garbage_storms"), Outcome::Passed);
        assert_eq!(
            outcomes.of("faults_bus", "bad_checksum_storms"),
            Outcome::Failed
        );
        assert_eq!(outcomes.of("faults_bus", "slow_one"), Outcome::Ignored);
        // The verdict came lines after the name, behind the test's output.
        assert_eq!(outcomes.of("soak", "a_titan_soak"), Outcome::Passed);
        // Its binary ended without a summary: the test that was running is not known to pass,
        // the one that said ok did.
        // In the binary of modules, the module is the suite.
        assert_eq!(outcomes.of("service", "a_stop"), Outcome::Passed);
        assert_eq!(outcomes.of("system", "service::a_stop"), Outcome::Unknown);
        assert_eq!(outcomes.of("systemd", "ready_first"), Outcome::Passed);
        assert_eq!(
            outcomes.of("systemd", "the_watchdog_test"),
            Outcome::Unknown
        );
        // Not run at all, or in another suite.
        assert_eq!(outcomes.of("faults_bus", "nothing"), Outcome::Unknown);
        assert_eq!(outcomes.of("soak", "garbage_storms"), Outcome::Unknown);
    }

    #[test]
    fn a_failed_tests_row_is_rendered_fail_though_its_figure_says_pass() {
        let figures: Vec<Figure> = FAULT_ROWS.iter().map(|r| figure_of(r, true)).collect();
        let mut outcomes = all_passed();
        let failed = &FAULT_ROWS[2];
        outcomes.0.insert(
            (failed.suite.to_string(), failed.test.to_string()),
            Outcome::Failed,
        );
        // And one whose outcome the log does not hold.
        let unknown = &FAULT_ROWS[4];
        outcomes
            .0
            .remove(&(unknown.suite.to_string(), unknown.test.to_string()));
        let rows = rows(FAULT_ROWS, &figures, &outcomes);
        assert!(rows[2].figure.is_some_and(|f| f.pass));
        assert!(!rows[2].pass());
        assert_eq!(result_cell(&rows[2]), "**FAIL** (its test failed)");
        assert!(!rows[4].pass());
        assert!(result_cell(&rows[4]).contains("no outcome"));
        assert_eq!(rows.iter().filter(|r| !r.pass()).count(), 2);
        let text = summary(&rows);
        assert!(
            text.starts_with(&format!(
                "{} of {} rows within their bounds. 2 whose test did not pass",
                FAULT_ROWS.len() - 2,
                FAULT_ROWS.len()
            )),
            "{text}"
        );
    }

    #[test]
    fn a_failed_test_renders_fail_in_the_document() {
        let dir = std::env::temp_dir().join(format!("reliability-render-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let figures: String = FAULT_ROWS
            .iter()
            .map(|r| serde_json::to_string(&figure_of(r, true)).unwrap() + "\n")
            .collect();
        std::fs::write(dir.join("faults.jsonl"), figures).unwrap();
        // libtest's output: every test passed but the first row's.
        let mut log = String::new();
        let mut suites: Vec<&str> = FAULT_ROWS.iter().map(|r| r.suite).collect();
        suites.dedup();
        for suite in suites {
            let (file, prefix) = if OWN_BINARIES.contains(&suite) {
                (suite.to_string(), String::new())
            } else {
                ("system/main".to_string(), format!("{suite}::"))
            };
            log.push_str(&format!(
                "     Running tests/{file}.rs (target/debug/deps/x)\n"
            ));
            for row in FAULT_ROWS.iter().filter(|r| r.suite == suite) {
                let verdict = if row == &FAULT_ROWS[0] {
                    "FAILED"
                } else {
                    "ok"
                };
                log.push_str(&format!("test {prefix}{} ... {verdict}\n", row.test));
            }
            log.push_str("test result: ok. 1 passed\n");
        }
        std::fs::write(dir.join("faults-tests.log"), log).unwrap();
        let out = dir.join("RELIABILITY.md");
        let failures = render(&dir, &out).unwrap();
        let text = std::fs::read_to_string(&out).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        // Every row of the first row's test fails with it (a test may record several rows).
        let of_first = FAULT_ROWS
            .iter()
            .filter(|r| r.test == FAULT_ROWS[0].test)
            .count();
        assert_eq!(failures, of_first);
        let line = text
            .lines()
            .find(|l| l.starts_with(&format!("| {} |", FAULT_ROWS[0].fault)))
            .unwrap();
        assert!(line.contains("**FAIL** (its test failed)"), "{line}");
        assert!(
            text.contains(&format!(
                "{} of {} rows within their bounds.",
                FAULT_ROWS.len() - of_first,
                FAULT_ROWS.len()
            )),
            "{text}"
        );
    }

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
        let rows = rows(FAULT_ROWS, &figures, &all_passed());
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
        let rows = rows(FAULT_ROWS, &figures, &all_passed());
        assert_eq!(rows.len(), FAULT_ROWS.len() + 1);
        assert!(!rows[0].pass());
        assert!(!rows[FAULT_ROWS.len()].pass());
        assert_eq!(rows.iter().filter(|r| !r.pass()).count(), 2);
    }
}
