//! The scripts CI runs, tested against stand-ins: `scripts/fuzz` must fail when a target crashes,
//! executes no input, cargo-fuzz fails, or a target's coverage stays below its floor (or it has
//! no floor, or no coverage figure), and pass only when every target ran inputs without a crash
//! and reached its floor.
//!
//! Each test copies the script and the committed floors into a scratch tree (`scripts/fuzz`,
//! `fuzz/coverage-floors.txt`, `fuzz/seeds/<target>/`) and puts a stand-in `cargo` first on
//! `PATH`: it logs its arguments, answers `cargo fuzz --version`, and plays a clean run (coverage
//! far above any floor), a crash, a run of zero inputs, a run without statistics, a build
//! failure, a fuzz body that returns before its decoder (the harness' few edges) or a run without
//! a `cov:` figure on the target it is told to.
// Test code: helpers outside #[test] functions may unwrap, panic and read the wall clock.
#![allow(clippy::unwrap_used, clippy::panic, clippy::disallowed_methods)]

use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The targets `scripts/fuzz` runs when it is given none: every target of `fuzz/Cargo.toml`.
const TARGETS: [&str; 10] = [
    "titan_decode",
    "agilex_v1_decode",
    "agilex_v2_decode",
    "xbot_stream",
    "nmea_stream",
    "candump_text",
    "slcan_stream",
    "zenoh_payload",
    "foxglove_client",
    "blackbox_reader",
];

/// Runs a program the test has just written. A child another test forks while the file is
/// open for writing holds it open until that child execs, and an exec meanwhile fails with
/// "text file busy" (ETXTBSY): the test's own race, not the program's, so it is retried.
fn exec_retrying(run: impl Fn() -> std::io::Result<Output>) -> Output {
    for _ in 0..100 {
        match run() {
            Err(e) if e.kind() == std::io::ErrorKind::ExecutableFileBusy => {
                std::thread::sleep(std::time::Duration::from_millis(20));
            }
            result => return result.unwrap(),
        }
    }
    run().unwrap()
}

/// The coverage (libFuzzer's `cov:`) the stand-in's clean run ends on: far above any floor.
const CLEAN_COVERAGE: u64 = 100_000;

/// The coverage the stand-in's early-return run ends on: libFuzzer's and the harness' own edges,
/// what the real titan_decode reached with `return;` at the top of its body.
const EARLY_RETURN_COVERAGE: u64 = 8;

const STAND_IN_CARGO: &str = r#"#!/bin/sh
# A stand-in for cargo: logs its arguments, plays what $FUZZ_PLAY asks on $FUZZ_TARGET.
echo "$*" >> "$FUZZ_CALLS"
if [ "$1 $2" = "fuzz --version" ]; then
    echo "cargo-fuzz 0.0.0 (stand-in)"
    exit 0
fi
clean() {
    # Coverage grows: the last status line's figure is the one that counts.
    printf '#2\tINITED cov: 40 ft: 41 corp: 1/2b exec/s: 0 rss: 30Mb\n'
    printf '#512\tpulse  cov: 900 ft: 1500 corp: 30/600b lim: 4 exec/s: 512 rss: 35Mb\n'
    printf '#1000\tDONE   cov: 100000 ft: 200000 corp: 50/1Kb lim: 4 exec/s: 1000 rss: 40Mb\n'
    echo "Done 1000 runs in 1 second(s)"
    echo "stat::number_of_executed_units: 1000"
}
# `cargo fuzz run [--sanitizer S] --fuzz-dir fuzz TARGET …`: the target follows the fuzz dir.
target=$(echo "$*" | sed -n 's/^fuzz run .*--fuzz-dir [^ ]* \([^ ]*\).*/\1/p')
if [ "$target" != "$FUZZ_TARGET" ]; then
    clean
    exit 0
fi
case "$FUZZ_PLAY" in
    crash|crash-exit-0)
        echo "==4242== ERROR: libFuzzer: deadly signal"
        echo "artifact_prefix='fuzz/artifacts/$target/'; Test unit written to fuzz/artifacts/$target/crash-0123"
        echo "SUMMARY: libFuzzer: deadly signal"
        if [ "$FUZZ_PLAY" = crash ]; then exit 77; fi
        exit 0
        ;;
    build-error)
        echo "error: could not compile \`chassis-fuzz\` (bin \"$target\") due to 1 previous error" >&2
        exit 101
        ;;
    zero)
        # libFuzzer given nothing to run (e.g. -runs=0 on an empty corpus) exits 0.
        echo "Done 0 runs in 0 second(s)"
        echo "stat::number_of_executed_units: 0"
        exit 0
        ;;
    no-stats)
        printf '#1000\tDONE   cov: 100000 ft: 200000 corp: 50/1Kb lim: 4 exec/s: 1000 rss: 40Mb\n'
        echo "Done 1000 runs in 1 second(s)"
        exit 0
        ;;
    early-return)
        # A fuzz body that returns before its decoder: many inputs, the harness' edges only.
        printf '#2\tINITED cov: 5 ft: 5 corp: 1/2b exec/s: 0 rss: 30Mb\n'
        printf '#1048576\tpulse  cov: 8 ft: 8 corp: 1/2b lim: 4 exec/s: 524288 rss: 31Mb\n'
        printf '#2000000\tDONE   cov: 8 ft: 8 corp: 1/2b lim: 4 exec/s: 1000000 rss: 31Mb\n'
        echo "Done 2000000 runs in 2 second(s)"
        echo "stat::number_of_executed_units: 2000000"
        exit 0
        ;;
    no-cov)
        echo "Done 1000 runs in 1 second(s)"
        echo "stat::number_of_executed_units: 1000"
        exit 0
        ;;
    *)
        clean
        exit 0
        ;;
esac
"#;

/// The committed floors: `target minimum_cov` per line, `#` comments and blank lines aside.
fn committed_floors() -> Vec<(String, String)> {
    std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/coverage-floors.txt"),
    )
    .unwrap()
    .lines()
    .map(|l| l.split('#').next().unwrap().trim())
    .filter(|l| !l.is_empty())
    .map(|l| {
        let mut words = l.split_whitespace();
        let target = words.next().unwrap().to_string();
        let floor = words.collect::<Vec<_>>().join(" ");
        (target, floor)
    })
    .collect()
}

/// The committed floor of one target.
fn committed_floor(target: &str) -> u64 {
    committed_floors()
        .into_iter()
        .find(|(t, _)| t == target)
        .map(|(_, floor)| floor.parse().unwrap())
        .unwrap_or_else(|| panic!("{target} has no committed coverage floor"))
}

/// A scratch copy of the script with a stand-in `cargo`.
struct Sandbox {
    root: PathBuf,
}

impl Sandbox {
    fn new(test: &str) -> Self {
        let root = std::env::temp_dir()
            .join("chassis-tests")
            .join(format!("scripts-{test}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let workspace = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        std::fs::create_dir_all(root.join("scripts")).unwrap();
        let script = root.join("scripts/fuzz");
        std::fs::copy(workspace.join("scripts/fuzz"), &script).unwrap();
        std::fs::create_dir_all(root.join("fuzz")).unwrap();
        std::fs::copy(
            workspace.join("fuzz/coverage-floors.txt"),
            root.join("fuzz/coverage-floors.txt"),
        )
        .unwrap();
        for target in TARGETS {
            let seeds = root.join("fuzz/seeds").join(target);
            std::fs::create_dir_all(&seeds).unwrap();
            std::fs::write(seeds.join("seed-0"), b"\x01\x02").unwrap();
        }
        let bin = root.join("bin");
        std::fs::create_dir_all(&bin).unwrap();
        let cargo = bin.join("cargo");
        std::fs::write(&cargo, STAND_IN_CARGO).unwrap();
        std::fs::set_permissions(&cargo, std::fs::Permissions::from_mode(0o755)).unwrap();
        // Once one exec of the stand-in succeeded, no child forked while it was being written
        // holds it open any more: the script's own exec of it cannot fail with ETXTBSY.
        exec_retrying(|| {
            Command::new(&cargo)
                .args(["fuzz", "--version"])
                .env("FUZZ_CALLS", "/dev/null")
                .output()
        });
        Self { root }
    }

    /// Runs `scripts/fuzz args…` with the stand-in playing `play` on `target`.
    fn fuzz(&self, args: &[&str], play: &str, target: &str) -> Output {
        let path = format!(
            "{}:{}",
            self.root.join("bin").display(),
            std::env::var("PATH").unwrap_or_default()
        );
        exec_retrying(|| {
            Command::new(self.root.join("scripts/fuzz"))
                .args(args)
                .env("PATH", &path)
                .env("FUZZ_CALLS", self.calls_path())
                .env("FUZZ_PLAY", play)
                .env("FUZZ_TARGET", target)
                .output()
        })
    }

    /// Rewrites the scratch floors file: the committed floors, `target`'s line replaced by
    /// `target floor` or, with `None`, dropped.
    fn set_floor(&self, target: &str, floor: Option<u64>) {
        let mut text = String::new();
        for (t, f) in committed_floors() {
            if t != target {
                text.push_str(&format!("{t} {f}\n"));
            }
        }
        if let Some(floor) = floor {
            text.push_str(&format!("{target} {floor}\n"));
        }
        std::fs::write(self.root.join("fuzz/coverage-floors.txt"), text).unwrap();
    }

    fn calls_path(&self) -> PathBuf {
        self.root.join("cargo-calls")
    }

    /// The `cargo fuzz run` invocations, one line each.
    fn runs(&self) -> Vec<String> {
        std::fs::read_to_string(self.calls_path())
            .unwrap_or_default()
            .lines()
            .filter(|l| l.starts_with("fuzz run"))
            .map(str::to_string)
            .collect()
    }
}

impl Drop for Sandbox {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.root);
        }
    }
}

fn text(output: &Output) -> (String, String) {
    (
        String::from_utf8_lossy(&output.stdout).into_owned(),
        String::from_utf8_lossy(&output.stderr).into_owned(),
    )
}

/// Asserts every default target was run once, bounded to `seconds`.
fn assert_every_target_ran(sandbox: &Sandbox, seconds: u32) {
    let runs = sandbox.runs();
    assert_eq!(runs.len(), TARGETS.len(), "{runs:?}");
    for target in TARGETS {
        assert!(
            runs.iter().any(|r| r.contains(&format!(" {target} "))
                && r.contains(&format!("-max_total_time={seconds}"))),
            "{target} was not fuzzed for {seconds} s: {runs:?}"
        );
    }
}

#[test]
fn fuzzing_passes_when_every_target_runs_without_a_crash() {
    let sandbox = Sandbox::new("clean");
    let output = sandbox.fuzz(&["3"], "clean", "");
    let (stdout, stderr) = text(&output);
    assert_eq!(output.status.code(), Some(0), "{stdout}\n{stderr}");
    assert!(
        stdout.contains(
            "no crash in 10 targets, each executed inputs and reached its coverage floor"
        ),
        "{stdout}\n{stderr}"
    );
    // Each target's executed count is shown, and its final coverage beside its floor.
    assert_eq!(
        stdout
            .matches("stat::number_of_executed_units: 1000")
            .count(),
        TARGETS.len(),
        "{stdout}"
    );
    for target in TARGETS {
        let line = format!(
            "coverage: {CLEAN_COVERAGE} (floor {})",
            committed_floor(target)
        );
        assert!(stdout.contains(&line), "{target}: no {line:?} in {stdout}");
    }
    assert_every_target_ran(&sandbox, 3);
}

#[test]
fn a_crashing_fuzz_target_fails_the_run_and_is_named() {
    let sandbox = Sandbox::new("crash");
    let output = sandbox.fuzz(&["2"], "crash", "agilex_v1_decode");
    let (stdout, stderr) = text(&output);
    assert_eq!(output.status.code(), Some(1), "{stdout}\n{stderr}");
    assert!(
        stderr.contains("agilex_v1_decode found a crash (exit 77"),
        "{stderr}"
    );
    assert!(
        stderr.contains("FAILED: 1 of 10 targets: agilex_v1_decode"),
        "{stderr}"
    );
    assert!(!stdout.contains("fuzzing done"), "{stdout}");
    // The other targets still ran: one run reports every crash.
    assert_every_target_ran(&sandbox, 2);
}

#[test]
fn a_crash_in_the_output_fails_the_run_even_with_exit_status_zero() {
    let sandbox = Sandbox::new("crash0");
    let output = sandbox.fuzz(&["1", "nmea_stream"], "crash-exit-0", "nmea_stream");
    let (stdout, stderr) = text(&output);
    assert_ne!(output.status.code(), Some(0), "{stdout}\n{stderr}");
    assert!(
        stderr.contains("nmea_stream found a crash (exit 0"),
        "{stderr}"
    );
    assert_eq!(sandbox.runs().len(), 1, "{:?}", sandbox.runs());
}

#[test]
fn cargo_fuzz_failing_without_a_crash_fails_the_run_with_its_error() {
    let sandbox = Sandbox::new("build");
    let output = sandbox.fuzz(&["1"], "build-error", "xbot_stream");
    let (stdout, stderr) = text(&output);
    assert_eq!(output.status.code(), Some(1), "{stdout}\n{stderr}");
    assert!(
        stderr.contains("cargo fuzz failed on xbot_stream (exit 101)"),
        "{stderr}"
    );
    assert!(stderr.contains("could not compile"), "{stderr}");
    assert!(
        stderr.contains("FAILED: 1 of 10 targets: xbot_stream"),
        "{stderr}"
    );
}

#[test]
fn a_target_that_executes_no_input_fails_the_run_and_is_named() {
    let sandbox = Sandbox::new("zero");
    let output = sandbox.fuzz(&["2"], "zero", "slcan_stream");
    let (stdout, stderr) = text(&output);
    assert_eq!(output.status.code(), Some(1), "{stdout}\n{stderr}");
    assert!(
        stderr.contains("slcan_stream executed no input (stat::number_of_executed_units: 0)"),
        "{stderr}"
    );
    assert!(
        stderr.contains("FAILED: 1 of 10 targets: slcan_stream"),
        "{stderr}"
    );
    assert!(!stdout.contains("fuzzing done"), "{stdout}");
    assert_every_target_ran(&sandbox, 2);
}

#[test]
fn a_run_that_reports_no_executed_count_fails_like_a_run_of_none() {
    let sandbox = Sandbox::new("nostats");
    let output = sandbox.fuzz(&["1", "zenoh_payload"], "no-stats", "zenoh_payload");
    let (stdout, stderr) = text(&output);
    assert_eq!(output.status.code(), Some(1), "{stdout}\n{stderr}");
    assert!(
        stderr
            .contains("zenoh_payload executed no input (stat::number_of_executed_units: missing)"),
        "{stderr}"
    );
}

#[test]
fn the_default_targets_are_every_target_of_the_fuzz_crate() {
    let manifest =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/Cargo.toml"))
            .unwrap();
    let mut defined: Vec<&str> = manifest
        .split("[[bin]]")
        .skip(1)
        .filter_map(|bin| {
            bin.lines()
                .find_map(|l| l.trim().strip_prefix("name = "))
                .map(|name| name.trim_matches('"'))
        })
        .collect();
    defined.sort_unstable();
    let mut listed = TARGETS.to_vec();
    listed.sort_unstable();
    assert_eq!(defined, listed);
    // And each has its seeds.
    for target in TARGETS {
        let seeds = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../fuzz/seeds")
            .join(target);
        let count = std::fs::read_dir(&seeds).map_or(0, |d| d.count());
        assert!(count > 0, "{target} has no seeds in {}", seeds.display());
    }
}

#[test]
fn a_target_below_its_coverage_floor_fails_the_run_and_is_named() {
    let sandbox = Sandbox::new("early");
    let output = sandbox.fuzz(&["2"], "early-return", "agilex_v2_decode");
    let (stdout, stderr) = text(&output);
    assert_eq!(output.status.code(), Some(1), "{stdout}\n{stderr}");
    let floor = committed_floor("agilex_v2_decode");
    assert!(
        stderr.contains(&format!(
            "agilex_v2_decode reached coverage {EARLY_RETURN_COVERAGE}, below its floor {floor} \
             (fuzz/coverage-floors.txt): does its fuzz body still reach its decoder?"
        )),
        "{stderr}"
    );
    assert!(
        stdout.contains(&format!(
            "coverage: {EARLY_RETURN_COVERAGE} (floor {floor})"
        )),
        "{stdout}"
    );
    assert!(
        stderr.contains("FAILED: 1 of 10 targets: agilex_v2_decode"),
        "{stderr}"
    );
    assert!(!stdout.contains("fuzzing done"), "{stdout}");
    // Executing inputs is not enough, and the other targets still ran.
    assert!(
        stdout.contains("stat::number_of_executed_units: 2000000"),
        "{stdout}"
    );
    assert_every_target_ran(&sandbox, 2);
}

#[test]
fn a_target_exactly_at_its_floor_passes_and_one_edge_short_fails() {
    let sandbox = Sandbox::new("boundary");
    sandbox.set_floor("titan_decode", Some(CLEAN_COVERAGE));
    let output = sandbox.fuzz(&["1", "titan_decode"], "clean", "titan_decode");
    let (stdout, stderr) = text(&output);
    assert_eq!(output.status.code(), Some(0), "{stdout}\n{stderr}");
    assert!(
        stdout.contains(&format!(
            "coverage: {CLEAN_COVERAGE} (floor {CLEAN_COVERAGE})"
        )),
        "{stdout}"
    );

    sandbox.set_floor("titan_decode", Some(CLEAN_COVERAGE + 1));
    let output = sandbox.fuzz(&["1", "titan_decode"], "clean", "titan_decode");
    let (stdout, stderr) = text(&output);
    assert_eq!(output.status.code(), Some(1), "{stdout}\n{stderr}");
    assert!(
        stderr.contains(&format!(
            "titan_decode reached coverage {CLEAN_COVERAGE}, below its floor {}",
            CLEAN_COVERAGE + 1
        )),
        "{stderr}"
    );
}

#[test]
fn a_target_without_a_coverage_floor_fails_the_run_and_is_named() {
    let sandbox = Sandbox::new("nofloor");
    sandbox.set_floor("candump_text", None);
    let output = sandbox.fuzz(&["1"], "clean", "");
    let (stdout, stderr) = text(&output);
    assert_eq!(output.status.code(), Some(1), "{stdout}\n{stderr}");
    assert!(
        stderr.contains("candump_text has no coverage floor in fuzz/coverage-floors.txt"),
        "{stderr}"
    );
    assert!(
        stderr.contains("FAILED: 1 of 10 targets: candump_text"),
        "{stderr}"
    );
    assert!(
        stdout.contains(&format!("coverage: {CLEAN_COVERAGE} (floor none)")),
        "{stdout}"
    );
    assert_every_target_ran(&sandbox, 1);
}

#[test]
fn a_floor_that_is_not_a_whole_number_fails_like_no_floor() {
    let sandbox = Sandbox::new("badfloor");
    std::fs::write(
        sandbox.root.join("fuzz/coverage-floors.txt"),
        "slcan_stream half\n",
    )
    .unwrap();
    let output = sandbox.fuzz(&["1", "slcan_stream"], "clean", "slcan_stream");
    let (stdout, stderr) = text(&output);
    assert_eq!(output.status.code(), Some(1), "{stdout}\n{stderr}");
    assert!(
        stderr.contains(
            "slcan_stream's coverage floor in fuzz/coverage-floors.txt is not a whole number above 0: 'half'"
        ),
        "{stderr}"
    );
}

#[test]
fn a_missing_floors_file_fails_before_any_target_runs() {
    let sandbox = Sandbox::new("nofloors");
    std::fs::remove_file(sandbox.root.join("fuzz/coverage-floors.txt")).unwrap();
    let output = sandbox.fuzz(&["1"], "clean", "");
    let (stdout, stderr) = text(&output);
    assert_eq!(output.status.code(), Some(1), "{stdout}\n{stderr}");
    assert!(
        stderr.contains("fuzz/coverage-floors.txt is missing"),
        "{stderr}"
    );
    assert!(sandbox.runs().is_empty(), "{:?}", sandbox.runs());
}

#[test]
fn a_run_that_reports_no_coverage_fails_the_run_and_is_named() {
    let sandbox = Sandbox::new("nocov");
    let output = sandbox.fuzz(&["1"], "no-cov", "foxglove_client");
    let (stdout, stderr) = text(&output);
    assert_eq!(output.status.code(), Some(1), "{stdout}\n{stderr}");
    assert!(
        stderr.contains("foxglove_client reported no coverage (no libFuzzer `cov:` line)"),
        "{stderr}"
    );
    assert!(stdout.contains("coverage: missing"), "{stdout}");
    assert!(
        stderr.contains("FAILED: 1 of 10 targets: foxglove_client"),
        "{stderr}"
    );
}

#[test]
fn every_fuzz_target_has_one_coverage_floor_above_zero() {
    let floors = committed_floors();
    for target in TARGETS {
        let lines: Vec<_> = floors.iter().filter(|(t, _)| t == target).collect();
        assert_eq!(lines.len(), 1, "{target}: {lines:?}");
        let floor: u64 = lines[0].1.parse().unwrap();
        assert!(floor > 0, "{target}: floor {floor}");
        // A floor the harness alone reaches would not catch a body that returns early.
        assert!(
            floor > EARLY_RETURN_COVERAGE * 2,
            "{target}: floor {floor} is within reach of an early return"
        );
    }
    // No floor names a target that does not exist.
    for (target, _) in &floors {
        assert!(
            TARGETS.contains(&target.as_str()),
            "unknown target {target}"
        );
    }
}
