//! The harness of the multi-process tests: start the real binaries, talk to them with
//! `chassis-client`, and clean up whatever happens.
//!
//! Every [`Env`] has its own iceoryx2 file prefix, so tests run in parallel without seeing each
//! other, and its own scratch directory for logs and pty links. When a test fails, the logs of
//! every process it started are printed.
//!
//! This crate only serves tests: a failed expectation here is a failed test, so it may panic,
//! and it waits on the wall clock.
#![allow(clippy::panic, clippy::disallowed_methods)]

use std::fs::File;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::OnceLock;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

pub use chassis_client::*;
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

static NEXT: AtomicU32 = AtomicU32::new(0);

/// The directory holding the workspace's binaries (`target/debug` or `target/release`), built
/// once per test process if they are missing.
pub fn bin_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        // target/<profile>/deps/<test-binary>
        let exe = std::env::current_exe().unwrap_or_default();
        let dir = exe
            .parent()
            .and_then(Path::parent)
            .map(Path::to_path_buf)
            .unwrap_or_default();
        let wanted = [
            "chassisd",
            "chassis",
            "chassis-safety",
            "chassis-teleop",
            "chassis-planner",
        ];
        if wanted.iter().any(|b| !dir.join(b).exists()) {
            let release = dir.ends_with("release");
            let mut cargo = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
            cargo.args(["build", "--workspace", "--bins"]);
            if release {
                cargo.arg("--release");
            }
            let status = cargo.status();
            assert!(
                status.is_ok_and(|s| s.success()),
                "the tests need the binaries: run `cargo build --workspace --bins` first"
            );
        }
        dir
    })
}

/// The path of the workspace binary `name`.
pub fn bin(name: &str) -> PathBuf {
    let path = bin_dir().join(name);
    assert!(
        path.exists(),
        "{} is missing: run `cargo build --workspace --bins`",
        path.display()
    );
    path
}

/// A process started by a test.
#[derive(Debug)]
pub struct Proc {
    pub name: String,
    pub child: Child,
    pub log: PathBuf,
}

impl Proc {
    pub fn pid(&self) -> Pid {
        Pid::from_raw(i32::try_from(self.child.id()).unwrap_or(0))
    }

    /// Sends `signal` (SIGKILL to crash it, SIGTERM / SIGINT to stop it).
    pub fn signal(&self, signal: Signal) {
        let _ = kill(self.pid(), signal);
    }

    /// Waits at most `timeout` for the process to end; returns its exit code (None: still running
    /// or killed by a signal).
    pub fn wait_exit(&mut self, timeout: Duration) -> Option<i32> {
        let end = Instant::now() + timeout;
        while Instant::now() < end {
            if let Ok(Some(status)) = self.child.try_wait() {
                return status.code();
            }
            pause(Duration::from_millis(20));
        }
        None
    }

    pub fn is_running(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }

    pub fn log_text(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }
}

/// Waits without spinning (tests only; the production code never sleeps).
#[allow(clippy::disallowed_methods)]
pub fn pause(d: Duration) {
    std::thread::sleep(d);
}

/// One test's world: its prefix, its scratch directory, its processes.
#[derive(Debug)]
pub struct Env {
    pub prefix: String,
    pub dir: PathBuf,
    procs: Vec<Proc>,
}

impl Env {
    pub fn new(test: &str) -> Self {
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let prefix = format!("ct{}_{n}_", std::process::id());
        let dir = std::env::temp_dir()
            .join("chassis-tests")
            .join(format!("{test}-{}-{n}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("creating {}: {e}", dir.display()));
        Self {
            prefix,
            dir,
            procs: Vec::new(),
        }
    }

    fn command(&self, binary: &str, args: &[&str]) -> Command {
        let mut cmd = Command::new(bin(binary));
        cmd.args(args)
            .env(IPC_PREFIX_ENV, &self.prefix)
            .env(
                "RUST_LOG",
                std::env::var("RUST_LOG").unwrap_or_else(|_| "info".into()),
            )
            .stdin(Stdio::null());
        cmd
    }

    /// Starts `binary args…` in the background; stdout and stderr go to `<dir>/<label>.log`.
    pub fn spawn(&mut self, label: &str, binary: &str, args: &[&str]) -> usize {
        let log = self.dir.join(format!("{label}.log"));
        let file = File::create(&log).unwrap_or_else(|e| panic!("{}: {e}", log.display()));
        let err = file
            .try_clone()
            .unwrap_or_else(|e| panic!("{}: {e}", log.display()));
        let child = self
            .command(binary, args)
            .stdout(file)
            .stderr(err)
            .spawn()
            .unwrap_or_else(|e| panic!("starting {binary}: {e}"));
        self.procs.push(Proc {
            name: label.to_string(),
            child,
            log,
        });
        self.procs.len() - 1
    }

    /// Starts `chassisd args…`.
    pub fn chassisd(&mut self, label: &str, args: &[&str]) -> usize {
        self.spawn(label, "chassisd", args)
    }

    /// Runs `chassis args…` to completion.
    pub fn chassis(&self, args: &[&str]) -> Output {
        self.command("chassis", args)
            .output()
            .unwrap_or_else(|e| panic!("running chassis: {e}"))
    }

    pub fn proc(&mut self, index: usize) -> &mut Proc {
        &mut self.procs[index]
    }

    /// Connects to `name`, retrying until the service is up — its first state sample is out,
    /// which it publishes once every port exists (at most `timeout`).
    pub fn robot(&self, name: &str, timeout: Duration) -> Robot {
        let end = Instant::now() + timeout;
        loop {
            match Robot::connect_with_prefix(name, Some(&self.prefix)) {
                Ok(mut robot) => {
                    if robot
                        .wait_state(Duration::from_millis(200))
                        .ok()
                        .flatten()
                        .is_some()
                    {
                        return robot;
                    }
                    assert!(
                        Instant::now() < end,
                        "chassis/{name} published no state\n{}",
                        self.logs()
                    );
                }
                Err(err) if Instant::now() >= end => {
                    panic!(
                        "chassis/{name} did not come up within {timeout:?}: {err}\n{}",
                        self.logs()
                    )
                }
                Err(_) => pause(Duration::from_millis(50)),
            }
        }
    }

    /// Every log written so far.
    pub fn logs(&self) -> String {
        let mut out = String::new();
        for p in &self.procs {
            out.push_str(&format!(
                "----- {} ({}) -----\n{}\n",
                p.name,
                p.log.display(),
                p.log_text()
            ));
        }
        out
    }
}

impl Drop for Env {
    fn drop(&mut self) {
        for p in &mut self.procs {
            if matches!(p.child.try_wait(), Ok(None)) {
                let _ = kill(p.pid(), Signal::SIGTERM);
            }
        }
        for p in &mut self.procs {
            if p.wait_exit(Duration::from_secs(3)).is_none() && p.is_running() {
                let _ = p.child.kill();
                let _ = p.child.wait();
            }
        }
        if std::thread::panicking() {
            eprintln!("{}", self.logs());
        }
        // Shared-memory files of this test's prefix.
        for dir in [
            "/dev/shm",
            "/tmp/iceoryx2",
            "/tmp/iceoryx2/services",
            "/tmp/iceoryx2/nodes",
        ] {
            if let Ok(entries) = std::fs::read_dir(dir) {
                for entry in entries.flatten() {
                    if entry
                        .file_name()
                        .to_string_lossy()
                        .starts_with(&self.prefix)
                    {
                        let path = entry.path();
                        if path.is_dir() {
                            let _ = std::fs::remove_dir_all(path);
                        } else {
                            let _ = std::fs::remove_file(path);
                        }
                    }
                }
            }
        }
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}

/// Polls `condition` every 10 ms until it holds or `timeout` passes; returns the time it took.
pub fn wait_for(timeout: Duration, mut condition: impl FnMut() -> bool) -> Option<Duration> {
    let start = Instant::now();
    loop {
        if condition() {
            return Some(start.elapsed());
        }
        if start.elapsed() >= timeout {
            return None;
        }
        pause(Duration::from_millis(10));
    }
}

/// Reads states for `duration` and returns the largest |linear speed| seen.
pub fn max_speed(robot: &mut Robot, duration: Duration) -> f32 {
    let end = Instant::now() + duration;
    let mut max = 0.0f32;
    while Instant::now() < end {
        if let Ok(Some(state)) = robot.wait_state(Duration::from_millis(50)) {
            max = max.max(state.motion.linear_mps.abs());
        }
    }
    max
}

/// The current state (waits up to a second for one).
pub fn state(robot: &mut Robot) -> ChassisState {
    robot
        .wait_state(Duration::from_secs(1))
        .ok()
        .flatten()
        .or_else(|| robot.latest_state().ok().flatten())
        .unwrap_or_else(|| panic!("no state from chassis/{}", robot.name()))
}

/// The latest mux status (waits up to a second).
pub fn mux(robot: &mut Robot) -> MuxStatus {
    robot
        .wait_mux(Duration::from_secs(1))
        .ok()
        .flatten()
        .unwrap_or_else(|| panic!("no mux status from chassis/{}", robot.name()))
}
