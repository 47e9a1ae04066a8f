//! The Python client's and the ROS 2 bridge's paths (`clients/python/bench.py`,
//! `clients/ros2/bench.py`) on the same service as the Rust client's rows beside them, in the
//! same run and placement: a script inherits the pinned CPU of the thread that starts it. Its
//! raw latencies come back as files, one ns figure a line, so its rows are summarised exactly as
//! the Rust client's are.
//!
//! The ROS 2 script is a Cyclone DDS participant standing in for a ROS 2 node; it measures the
//! raw DDS hops between the same two implementations (Cyclone DDS ↔ the bridge's RustDDS) in the
//! same run. DDS discovery multicasts: it runs under `unshare --net` with only the loopback up,
//! so no discovery packet leaves the machine (iceoryx2 is shared memory and works across it).

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
    /// For each state latency, its stamps: `[frame read, handed to iceoryx2, the stream's wait
    /// returned, the sample in hand]` ([`crate::parts::python_state`]).
    pub state_stamps: Vec<[u64; 4]>,
}

/// What the ROS 2 bridge's run measured.
#[derive(Debug)]
pub struct Ros2Figures {
    /// `cmd_vel` written by the peer → the motion frame written to the bus.
    pub command: Latencies,
    /// Frame read by chassisd → the `odom` carrying its pose taken by the peer.
    pub state: Latencies,
    /// Raw DDS hop, peer (Cyclone DDS) → the bridge's DDS stack (RustDDS).
    pub raw_in: Latencies,
    /// Raw DDS hop, the bridge's DDS stack → the peer.
    pub raw_out: Latencies,
    /// The pace of `raw_out`'s pings: the odoms' own period, 1.7 % more.
    pub raw_out_period: Duration,
    /// `cmd_vel` messages whose frame did not appear.
    pub missed: u64,
    /// Each counted odom's `(frame read, taken by the peer)`.
    pub odom_pairs: Vec<(u64, u64)>,
    /// The bridge's odom trace (`[read, woke, write begun, written]` a line): with chassisd's
    /// pass trace, [`crate::parts::odom`] splits the state row.
    pub odom_trace: Vec<[u64; 4]>,
}

/// The repository the benchmark was built from.
fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The interpreter of the test environment `target/<name>-venv` (`scripts/python-tests` and
/// `scripts/ros2-tests` make them, with the `chassis` package installed), if there is one.
pub fn interpreter(name: &str) -> Option<PathBuf> {
    let python = repo().join(format!("target/{name}-venv/bin/python"));
    python.exists().then_some(python)
}

/// Lines of `N` numbers, ns, separated by spaces (a script's `*.ns`, `state.stamps`,
/// `state.pairs`, counts).
fn read_stamps<const N: usize>(file: &Path) -> anyhow::Result<Vec<[u64; N]>> {
    let text =
        std::fs::read_to_string(file).with_context(|| format!("reading {}", file.display()))?;
    text.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|line| {
            let stamps: Vec<u64> = line
                .split_whitespace()
                .map(str::parse)
                .collect::<Result<_, _>>()
                .with_context(|| format!("a number in '{line}' of {}", file.display()))?;
            <[u64; N]>::try_from(stamps)
                .map_err(|_| anyhow::anyhow!("'{line}' of {} is not {N} numbers", file.display()))
        })
        .collect()
}

fn read_latencies(file: &Path) -> anyhow::Result<Latencies> {
    let mut latencies = Latencies::new();
    for [ns] in read_stamps(file)? {
        latencies.record(ns);
    }
    Ok(latencies)
}

/// A count the script wrote, one number in a file.
fn read_count(file: &Path) -> anyhow::Result<u64> {
    let [[count]] = <[[u64; 1]; 1]>::try_from(read_stamps(file)?)
        .map_err(|_| anyhow::anyhow!("{} does not hold one count", file.display()))?;
    Ok(count)
}

/// What a benchmark script (the Python client's or the ROS 2 bridge's `bench.py`) runs against
/// and how much it measures: both take the same arguments for it.
#[derive(Debug)]
pub struct ScriptRun<'a> {
    /// The robot (a TITAN) served under `prefix`.
    pub name: &'a str,
    pub prefix: &'a str,
    /// The `chassis` CLI the script drives the robot with.
    pub chassis_cli: &'a Path,
    /// The run's directory: the script writes into `<its tag>-<name>` below it.
    pub dir: &'a Path,
    pub states: u64,
    pub commands: u64,
    pub interval: Duration,
}

impl ScriptRun<'_> {
    /// The directory of the script tagged `tag` (`python`, `ros2`).
    fn out(&self, tag: &str) -> PathBuf {
        self.dir.join(format!("{tag}-{}", self.name))
    }

    /// Appends the arguments every `bench.py` takes.
    fn args(&self, script: &mut Command) {
        script
            .args(["--name", self.name, "--robot", "titan"])
            .args(["--prefix", self.prefix])
            .arg("--chassis")
            .arg(self.chassis_cli)
            .args(["--state-samples", &self.states.to_string()])
            .args(["--commands", &self.commands.to_string()])
            .args(["--interval-ms", &self.interval.as_millis().to_string()]);
    }

    /// Runs the script `script`, tagged `tag`, with its arguments: it writes its figures into
    /// its directory (`--latencies-dir`) and its log into `bench.log` there; `what` names it in
    /// the errors. Its output is not read: the figures are in the files.
    fn script(&self, mut script: Command, tag: &str, what: &str) -> anyhow::Result<PathBuf> {
        let out = self.out(tag);
        self.args(&mut script);
        run_script(script, &out, what)?;
        Ok(out)
    }
}

fn run_script(mut script: Command, out: &Path, what: &str) -> anyhow::Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let log_path = out.join("bench.log");
    let log = std::fs::File::create(&log_path)
        .with_context(|| format!("creating {}", log_path.display()))?;
    let program = script.get_program().to_string_lossy().into_owned();
    let status = (script.arg("--latencies-dir").arg(out))
        .stdout(Stdio::null())
        .stderr(log)
        .status()
        .with_context(|| format!("starting {what} ({program})"))?;
    if !status.success() {
        bail!("{what} failed ({status}); see {}", log_path.display());
    }
    Ok(())
}

/// Runs the Python client's `bench.py` with the interpreter `python`.
pub fn run(python: &Path, run: &ScriptRun<'_>) -> anyhow::Result<PythonFigures> {
    let mut script = Command::new(python);
    script.arg(repo().join("clients/python/bench.py"));
    let out = run.script(script, "python", "the Python client's benchmark")?;
    Ok(PythonFigures {
        state: read_latencies(&out.join("state.ns"))?,
        command: read_latencies(&out.join("command.ns"))?,
        missed: read_count(&out.join("command.missed"))?,
        dropped: read_count(&out.join("state.dropped"))?,
        state_stamps: read_stamps(&out.join("state.stamps"))?,
    })
}

/// Runs the ROS 2 bridge's `bench.py` with the interpreter `python`, beside the bridge binary.
pub fn run_ros2(python: &Path, run: &ScriptRun<'_>) -> anyhow::Result<Ros2Figures> {
    let mut script = Command::new("unshare");
    script
        .args(["--net", "--", "sh", "-c"])
        .arg("ip link set lo up && ip link set lo multicast on && exec \"$@\"")
        .arg("ros2-bench")
        .arg(python)
        .arg(repo().join("clients/ros2/bench.py"))
        .arg("--bridge")
        .arg(crate::paths::sibling("chassis-ros2")?)
        .arg("--echo")
        .arg(std::env::current_exe().context("finding chassis-bench itself")?);
    let out = run.script(script, "ros2", "the ROS 2 bridge's benchmark")?;
    let file = |name: &str| out.join(name);
    Ok(Ros2Figures {
        command: read_latencies(&file("command.ns"))?,
        state: read_latencies(&file("state.ns"))?,
        raw_in: read_latencies(&file("raw-in.ns"))?,
        raw_out: read_latencies(&file("raw-out.ns"))?,
        raw_out_period: Duration::from_nanos(read_count(&file("raw-out.period_ns"))?),
        missed: read_count(&file("command.missed")).unwrap_or(0),
        odom_pairs: (read_stamps(&file("state.pairs"))?.into_iter())
            .map(|[read, taken]| (read, taken))
            .collect(),
        odom_trace: crate::parts::read_trace(&file("odom.trace"), chassis_ipc::Trace::Odom)?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tests::scratch;

    #[test]
    fn a_script_is_told_where_to_write_and_its_stderr_is_kept_in_the_log() {
        let out = scratch("script-ok").join("python-titan");
        let mut script = Command::new("sh");
        script.args([
            "-c",
            "echo \"$@\" >&2; echo 7 > \"$2/command.missed\"",
            "bench",
        ]);
        run_script(script, &out, "a stand-in benchmark").unwrap();
        let log = std::fs::read_to_string(out.join("bench.log")).unwrap();
        assert_eq!(log.trim(), format!("--latencies-dir {}", out.display()));
        assert_eq!(read_count(&out.join("command.missed")).unwrap(), 7);
        std::fs::remove_dir_all(out.parent().unwrap()).unwrap();
    }

    #[test]
    fn the_state_stamps_are_read_four_a_line_and_a_short_line_is_an_error() {
        let dir = scratch("script-stamps");
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("state.stamps");
        std::fs::write(&file, "1 2 3 4\n\n5 6 7 8\n").unwrap();
        assert_eq!(
            read_stamps::<4>(&file).unwrap(),
            [[1, 2, 3, 4], [5, 6, 7, 8]]
        );
        std::fs::write(&file, "1 2 3 4\n5 6 7\n").unwrap();
        let error = read_stamps::<4>(&file).unwrap_err().to_string();
        assert!(error.contains("'5 6 7'"), "{error}");
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn both_scripts_are_given_the_robot_the_cli_and_how_much_to_measure() {
        let run = ScriptRun {
            name: "titan-1",
            prefix: "bench_7",
            chassis_cli: Path::new("/bin/chassis"),
            dir: Path::new("/tmp/run"),
            states: 500,
            commands: 40,
            interval: Duration::from_millis(20),
        };
        let mut script = Command::new("python3");
        run.args(&mut script);
        let args: Vec<_> = script.get_args().map(|a| a.to_string_lossy()).collect();
        assert_eq!(
            args,
            [
                "--name",
                "titan-1",
                "--robot",
                "titan",
                "--prefix",
                "bench_7",
                "--chassis",
                "/bin/chassis",
                "--state-samples",
                "500",
                "--commands",
                "40",
                "--interval-ms",
                "20"
            ]
        );
        assert_eq!(run.out("ros2"), Path::new("/tmp/run/ros2-titan-1"));
    }

    #[test]
    fn a_failing_script_is_an_error_that_points_at_its_log() {
        let out = scratch("script-fails").join("ros2-titan");
        let mut script = Command::new("sh");
        script.args(["-c", "echo broken >&2; exit 3"]);
        let err = run_script(script, &out, "a stand-in benchmark").unwrap_err();
        let log = out.join("bench.log");
        assert_eq!(
            err.to_string(),
            format!(
                "a stand-in benchmark failed (exit status: 3); see {}",
                log.display()
            )
        );
        assert_eq!(std::fs::read_to_string(&log).unwrap(), "broken\n");
        let missing = Command::new("/nonexistent/python");
        let err = run_script(missing, &out, "a stand-in benchmark").unwrap_err();
        assert_eq!(
            err.to_string(),
            "starting a stand-in benchmark (/nonexistent/python)"
        );
        std::fs::remove_dir_all(out.parent().unwrap()).unwrap();
    }
}
