//! The Python client's paths (`clients/python/bench.py`) on the same service as the Rust client's
//! rows beside them, in the same run and placement: the process inherits the pinned CPU of the
//! thread that starts it. Its raw latencies come back as files, one ns figure a line, so its rows
//! are summarised exactly as the Rust client's are.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use anyhow::{Context, bail};

use crate::stats::Latencies;

/// What the Python client measured.
#[derive(Debug)]
pub struct PythonFigures {
    /// Frame read by chassisd → the Python process woke with the state.
    pub state: Latencies,
    /// Python request created → its frame's write returned.
    pub command: Latencies,
    /// Requests whose frame did not appear.
    pub missed: u64,
    /// State samples the Python reader never received (gaps in `seq`).
    pub dropped: u64,
}

/// The repository the benchmark was built from.
pub(crate) fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The interpreter of the Python package's test environment (`scripts/python-tests` makes it,
/// with the `chassis` package installed), if there is one.
pub fn interpreter() -> Option<PathBuf> {
    let python = repo().join("target/python-venv/bin/python");
    python.exists().then_some(python)
}

pub(crate) fn read_latencies(file: &Path) -> anyhow::Result<Latencies> {
    let mut latencies = Latencies::new();
    let text =
        std::fs::read_to_string(file).with_context(|| format!("reading {}", file.display()))?;
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        latencies.record(line.trim().parse().context("a latency in ns")?);
    }
    Ok(latencies)
}

/// Runs `bench.py` against the robot `name` (TITAN) served under `prefix`.
#[allow(clippy::too_many_arguments)]
pub fn run(
    python: &Path,
    name: &str,
    prefix: &str,
    chassis_cli: &Path,
    dir: &Path,
    states: u64,
    commands: u64,
    interval: Duration,
) -> anyhow::Result<PythonFigures> {
    let out = dir.join(format!("python-{name}"));
    std::fs::create_dir_all(&out)?;
    let log = std::fs::File::create(out.join("bench.log"))?;
    let status = Command::new(python)
        .arg(repo().join("clients/python/bench.py"))
        .args(["--name", name, "--robot", "titan", "--prefix", prefix])
        .args(["--state-samples", &states.to_string()])
        .args(["--commands", &commands.to_string()])
        .args(["--interval-ms", &interval.as_millis().to_string()])
        .arg("--chassis")
        .arg(chassis_cli)
        .arg("--latencies-dir")
        .arg(&out)
        .stdout(Stdio::null())
        .stderr(log)
        .status()
        .context("starting the Python client's benchmark")?;
    if !status.success() {
        bail!(
            "the Python client's benchmark failed ({status}); see {}",
            out.join("bench.log").display()
        );
    }
    Ok(PythonFigures {
        state: read_latencies(&out.join("state.ns"))?,
        command: read_latencies(&out.join("command.ns"))?,
        missed: read_count(&out.join("command.missed"))?,
        dropped: read_count(&out.join("state.dropped"))?,
    })
}

/// A count the script wrote, one number in a file.
pub(crate) fn read_count(file: &Path) -> anyhow::Result<u64> {
    let text =
        std::fs::read_to_string(file).with_context(|| format!("reading {}", file.display()))?;
    text.trim()
        .parse()
        .with_context(|| format!("a count in {}", file.display()))
}
