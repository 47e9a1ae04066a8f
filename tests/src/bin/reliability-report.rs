//! Renders docs/RELIABILITY.md from the figures the fault tests and the soak recorded.
//!
//! ```text
//! reliability-report run-info DIR NAME COMMAND   # DIR/NAME-run.json: date, commit, machine
//! reliability-report render DIR OUT              # faults.jsonl + soak.jsonl → OUT (markdown)
//! ```
//!
//! `scripts/reliability` and `scripts/soak` call it; see their headers.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

use anyhow::{Context, bail};
use chassis_tests::{Figure, STATE_BUFFER};
use serde::{Deserialize, Serialize};

/// When, where and how a set of figures was measured.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
struct RunInfo {
    date: String,
    commit: String,
    machine: String,
    command: String,
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
        "{cpus} × {model}{memory}, Linux {}{virt}",
        output("uname", &["-r"])
    )
}

fn run_info(dir: &Path, name: &str, command: &str) -> anyhow::Result<()> {
    let commit = output("git", &["rev-parse", "--short", "HEAD"]);
    let dirty = !output("git", &["status", "--porcelain", "--untracked-files=no"]).is_empty();
    let info = RunInfo {
        date: output("date", &["-u", "+%Y-%m-%d %H:%M UTC"]),
        commit: if dirty {
            format!("{commit} (with uncommitted changes)")
        } else {
            commit
        },
        machine: machine(),
        command: command.to_string(),
    };
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let path = dir.join(format!("{name}-run.json"));
    std::fs::write(&path, serde_json::to_string_pretty(&info)? + "\n")
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
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
            out.push_str(&format!(
                "Measured {} on commit `{}`; machine: {}.\nReproduce: `{}`\n\n",
                info.date, info.commit, info.machine, info.command
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
* **The rogue client** is one thread publishing as fast as it can. Before the wake-up budget
  (`WakeBudget` in `services/chassisd/src/service.rs`) it kept the service's loop 97 % busy,
  which the kernel then scheduled in time slices: heartbeat periods of 3-29 ms appeared. The
  budget detaches a source's listener for the rest of a tick after 20 wake-ups; its requests are
  still read every tick.
* **Heartbeat jitter** on this machine is bounded by the kernel, not by the service: a plain
  sleep loop at normal priority on the same VM wakes up to 2-5 ms late now and then, with or
  without a CPU hog beside it, so the flood test compares its window with a quiet window
  measured just before, and holds the bulk of the periods (not every one) within 20 ± 2 ms.
  The soak is stricter: it fails on any 0x111 gap of two periods (40 ms) or more. Such a gap
  means the service's loop did not run for that long, and the state readers' longest wait for
  a sample shows the same stall. The TITAN itself stops only after 500 ms without a command.
";

fn render(dir: &Path, out_path: &Path) -> anyhow::Result<()> {
    let mut faults = read_figures(&dir.join("faults.jsonl"))?;
    if faults.is_empty() {
        bail!(
            "{} holds no figures: run scripts/reliability",
            dir.join("faults.jsonl").display()
        );
    }
    faults.sort_by(|a, b| (a.rank, &a.fault).cmp(&(b.rank, &b.fault)));
    let soak = read_figures(&dir.join("soak.jsonl"))?;
    let mut out = String::from(INTRO);

    out.push_str("## The fault matrix\n\n");
    provenance(&mut out, read_info(&dir.join("faults-run.json")).as_ref());
    let passed = faults.iter().filter(|f| f.pass).count();
    out.push_str(&format!(
        "{passed} of {} figures within their bounds.\n\n",
        faults.len()
    ));
    out.push_str(
        "| fault | how it is injected | what the system did | figure measured | result | \
         reproduce |\n| --- | --- | --- | --- | --- | --- |\n",
    );
    for f in &faults {
        out.push_str(&format!(
            "| {} | {} | {} | {} | {} | `cargo test -p chassis-tests --test {} {}` |\n",
            cell(&f.fault),
            cell(&f.injection),
            cell(&f.behaviour),
            cell(&f.figure),
            verdict(f.pass),
            f.suite,
            f.test
        ));
    }
    out.push('\n');

    out.push_str("## Soak\n\n");
    if soak.is_empty() {
        out.push_str("Not run yet: `scripts/soak 10` measures it (10 minutes).\n\n");
    } else {
        provenance(&mut out, read_info(&dir.join("soak-run.json")).as_ref());
        // One injection text for the whole soak.
        let mut runs: BTreeMap<&str, ()> = BTreeMap::new();
        for f in &soak {
            runs.insert(&f.injection, ());
        }
        for injection in runs.keys() {
            out.push_str(&format!("{injection}.\n\n"));
        }
        out.push_str("| measured | what it shows | figure | result |\n| --- | --- | --- | --- |\n");
        for f in &soak {
            out.push_str(&format!(
                "| {} | {} | {} | {} |\n",
                cell(&f.fault),
                cell(&f.behaviour),
                cell(&f.figure),
                verdict(f.pass)
            ));
        }
        out.push('\n');
        out.push_str(&format!(
            "What \"zero gaps\" is measured on: frames — `BusFrame::seq` numbers every frame \
             the service read or wrote, and two readers draining the tap from their own \
             threads (the soak's and `chassis record`'s, 2048 frames deep each) must see every \
             number. State — `ChassisState::seq` numbers every sample the service publishes (a \
             sample per frame that changes the state, in bursts of ≈ 18 while the saturated \
             bus is read once per 4 ms, and up to a whole read of 256 frames at once after the \
             service was held up); a failed publication is logged, and none may happen. \
             Two readers drain a state stream each (`Robot::state_stream`, {STATE_BUFFER} \
             samples deep): the soak's, from its own thread, must see every number published \
             from its start to the end of the run, with the longest wait for a sample \
             reported, and `chassis record`, which records every sample, must lose none; the \
             safety monitor's stale-state rule must never fire. A `Robot`'s own state reading is \
             latest-value (the newest samples, for control loops and displays), and `chassis \
             echo state` prints the newest sample per wake-up by design: neither is a gap \
             counter.\n\n"
        ));
    }
    out.push_str(NOTES);
    std::fs::write(out_path, out).with_context(|| format!("writing {}", out_path.display()))?;
    println!(
        "{}: {} fault figures ({passed} pass), {} soak figures",
        out_path.display(),
        faults.len(),
        soak.len()
    );
    Ok(())
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args
        .iter()
        .map(String::as_str)
        .collect::<Vec<_>>()
        .as_slice()
    {
        ["run-info", dir, name, command] => run_info(Path::new(dir), name, command),
        ["render", dir, out] => render(Path::new(dir), &PathBuf::from(out)),
        _ => {
            eprintln!(
                "usage: reliability-report run-info DIR NAME COMMAND\n       \
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
