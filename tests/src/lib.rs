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

pub mod faults;
pub mod netns;

use std::fs::File;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::OnceLock;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

pub use chassis_client::*;
pub use chassis_ipc::{ipc_files, remove_ipc_files};
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

    /// Stops the process (SIGSTOP, as Ctrl-Z) and continues it (SIGCONT, as `fg`) `times`
    /// times: 100 ms stopped, then 50 ms running.
    pub fn stop_and_continue(&self, times: usize) {
        for _ in 0..times {
            self.signal(Signal::SIGSTOP);
            pause(Duration::from_millis(100));
            self.signal(Signal::SIGCONT);
            pause(Duration::from_millis(50));
        }
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

    /// What the kernel says of the process, for a failure's log: running with each thread's
    /// wait channel (where a silent process is stuck), or how it ended (an empty log and a
    /// signal tell a crash from a hang).
    pub fn kernel_view(&self) -> String {
        let pid = self.child.id();
        let Ok(stat) = std::fs::read_to_string(format!("/proc/{pid}/stat")) else {
            return format!("pid {pid}: ended and reaped");
        };
        // The fields after the command name (which may hold spaces) in parentheses.
        let fields: Vec<&str> = stat
            .rsplit_once(')')
            .map_or("", |(_, rest)| rest)
            .split_whitespace()
            .collect();
        let state = fields.first().copied().unwrap_or("?");
        if state == "Z" {
            // The last field is the exit status as waitpid(2) reports it.
            let code: i32 = fields.last().and_then(|f| f.parse().ok()).unwrap_or(-1);
            return match (code & 0x7f, (code >> 8) & 0xff) {
                (0, status) => format!("pid {pid}: exited with status {status}"),
                (signal, _) => format!("pid {pid}: killed by signal {signal}"),
            };
        }
        let mut threads = Vec::new();
        if let Ok(tasks) = std::fs::read_dir(format!("/proc/{pid}/task")) {
            for task in tasks.flatten() {
                let path = task.path();
                let wchan = std::fs::read_to_string(path.join("wchan")).unwrap_or_default();
                let comm = std::fs::read_to_string(path.join("comm")).unwrap_or_default();
                threads.push(format!("{} in {}", comm.trim(), wchan.trim()));
            }
        }
        format!("pid {pid}: state {state}; threads: {}", threads.join(", "))
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
        self.command_of(&bin(binary), args)
    }

    /// `program args…` with this test's prefix, state directory and log level.
    fn command_of(&self, program: &Path, args: &[&str]) -> Command {
        let mut cmd = Command::new(program);
        cmd.args(args)
            .env(IPC_PREFIX_ENV, &self.prefix)
            // Held locks are kept per test (a restarted chassisd of the same test finds them).
            .env("XDG_STATE_HOME", self.state_home())
            .env_remove("STATE_DIRECTORY")
            .env(
                "RUST_LOG",
                std::env::var("RUST_LOG").unwrap_or_else(|_| "info".into()),
            )
            .stdin(Stdio::null());
        cmd
    }

    /// `$XDG_STATE_HOME` of every process of this test: chassisd keeps robot NAME's held locks
    /// in `chassisd/NAME/NAME.locks.json` under it.
    pub fn state_home(&self) -> PathBuf {
        self.dir.join("state")
    }

    /// Starts `binary args…` in the background; stdout and stderr go to `<dir>/<label>.log`.
    pub fn spawn(&mut self, label: &str, binary: &str, args: &[&str]) -> usize {
        self.spawn_program(label, &bin(binary), args, &[])
    }

    /// Starts any `program args…` (a wrapper such as `setpriv` in front of a workspace binary)
    /// in the background with `envs` added to its environment; logs as [`Env::spawn`].
    pub fn spawn_program(
        &mut self,
        label: &str,
        program: &Path,
        args: &[&str],
        envs: &[(&str, &str)],
    ) -> usize {
        let log = self.dir.join(format!("{label}.log"));
        let file = File::create(&log).unwrap_or_else(|e| panic!("{}: {e}", log.display()));
        let err = file
            .try_clone()
            .unwrap_or_else(|e| panic!("{}: {e}", log.display()));
        let child = self
            .command_of(program, args)
            .envs(envs.iter().copied())
            .stdout(file)
            .stderr(err)
            .spawn()
            .unwrap_or_else(|e| panic!("starting {}: {e}", program.display()));
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

    /// Starts chassisd (labelled `chassisd`) serving `robot` as chassis/`name`, with `extra`
    /// arguments after `--robot ROBOT --name NAME`.
    pub fn serve(&mut self, robot: &str, name: &str, extra: &[&str]) -> usize {
        self.serve_as("chassisd", (robot, name), extra)
    }

    /// [`Env::serve`] with the label `label` (a restarted service, a second one).
    pub fn serve_as(&mut self, label: &str, (robot, name): (&str, &str), extra: &[&str]) -> usize {
        let mut args = vec!["--robot", robot, "--name", name];
        args.extend_from_slice(extra);
        self.chassisd(label, &args)
    }

    /// A test's environment (`test` names it) with chassisd serving `robot` as chassis/NAME
    /// (`tag` and the pid) with `extra` arguments: the environment, NAME and the connection
    /// (up within `up`).
    pub fn serving(
        test: &str,
        (tag, robot): (&str, &str),
        extra: &[&str],
        up: Duration,
    ) -> (Self, String, Robot) {
        let mut env = Self::new(test);
        let n = name(tag);
        env.serve(robot, &n, extra);
        let connection = env.robot(&n, up);
        (env, n, connection)
    }

    /// Starts `chassisd sim` (labelled `label`) simulating `robot` as chassis/`name` on `bus`,
    /// with `extra` arguments after `sim --robot ROBOT`.
    pub fn sim(
        &mut self,
        label: &str,
        robot: &str,
        extra: &[&str],
        name: &str,
        bus: &str,
    ) -> usize {
        let mut args = vec!["sim", "--robot", robot];
        args.extend_from_slice(extra);
        args.extend_from_slice(&["--name", name, "--bus", bus]);
        self.chassisd(label, &args)
    }

    /// Starts `chassisd sim` (labelled `sim`) simulating `robot` as chassis/`name` at the far
    /// end of `line`, a pty it links at `link`, and waits for the link (at most `timeout`);
    /// returns the simulator's index and the `--bus` for chassisd's end.
    pub fn sim_on_pty(
        &mut self,
        robot: &str,
        extra: &[&str],
        name: &str,
        line: Line,
        link: &Path,
        timeout: Duration,
    ) -> (usize, String) {
        let sim = self.sim("sim", robot, extra, name, &line.sim_bus(link));
        self.wait_link(link, timeout);
        (sim, line.bus(link))
    }

    /// A simulated XBot board (`chassisd sim`, labelled `sim`) on a serial pty linked at `link`,
    /// and chassisd serving it as chassis/`name` with [`XBOT_PROFILE`] over the other end;
    /// returns the simulator's index and the connection (each up within `timeout`).
    pub fn xbot_over_pty(&mut self, name: &str, link: &Path, timeout: Duration) -> (usize, Robot) {
        let config = self.write("xbot.toml", XBOT_PROFILE);
        let extra = ["--config", config.as_str()];
        self.over_pty(("xbot", name), Line::Serial, link, &extra, timeout)
    }

    /// A simulated `robot` (`chassisd sim`, labelled `sim`) at the far end of `line`, a pty
    /// linked at `link`, and chassisd serving it as chassis/`name` without its safety monitor
    /// over the other end, with `extra` arguments; returns the simulator's index and the
    /// connection (each up within `timeout`).
    pub fn over_pty(
        &mut self,
        (robot, name): (&str, &str),
        line: Line,
        link: &Path,
        extra: &[&str],
        timeout: Duration,
    ) -> (usize, Robot) {
        let (sim, bus) = self.sim_on_pty(robot, &[], name, line, link, timeout);
        let mut args = vec!["--bus", bus.as_str(), "--no-safety-monitor"];
        args.extend_from_slice(extra);
        self.serve(robot, name, &args);
        (sim, self.robot(name, timeout))
    }

    /// Waits until `path` (the link to a simulator's pty) exists, at most `timeout`.
    pub fn wait_link(&self, path: &Path, timeout: Duration) {
        assert!(
            wait_for(timeout, || path.exists()).is_some(),
            "no link {}\n{}",
            path.display(),
            self.logs()
        );
    }

    /// Writes `text` to `file` in the test's directory (a configuration); returns its path as a
    /// program's argument.
    pub fn write(&self, file: &str, text: &str) -> String {
        let path = self.dir.join(file);
        std::fs::write(&path, text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        path.to_string_lossy().into_owned()
    }

    /// Starts `chassis pub velocity --name NAME args…` (labelled `label`) in the background.
    pub fn publish(&mut self, label: &str, name: &str, args: &[&str]) -> usize {
        let mut all = vec!["pub", "velocity", "--name", name];
        all.extend_from_slice(args);
        self.spawn(label, "chassis", &all)
    }

    /// Runs `chassis args…` to completion.
    pub fn chassis(&self, args: &[&str]) -> Output {
        self.run("chassis", args)
    }

    /// Runs `chassis args…` to completion, which must succeed; returns what it printed.
    pub fn chassis_ok(&self, args: &[&str]) -> String {
        let out = self.chassis(args);
        assert!(
            out.status.success(),
            "chassis {args:?}: {}\n{}",
            String::from_utf8_lossy(&out.stderr),
            self.logs()
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    }

    /// What a program that had to succeed printed; otherwise fails the test with `what` (what
    /// it did), its output and every log.
    pub fn succeeded(&self, what: &str, out: &Output) -> String {
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        assert!(
            out.status.success(),
            "{what}: {}\n{stdout}\n{}",
            String::from_utf8_lossy(&out.stderr),
            self.logs()
        );
        stdout
    }

    /// Runs the workspace binary `binary args…` to completion.
    pub fn run(&self, binary: &str, args: &[&str]) -> Output {
        self.command(binary, args)
            .output()
            .unwrap_or_else(|e| panic!("running {binary}: {e}"))
    }

    pub fn proc(&mut self, index: usize) -> &mut Proc {
        &mut self.procs[index]
    }

    /// The process started last with `label`.
    pub fn proc_labelled(&mut self, label: &str) -> &mut Proc {
        self.procs
            .iter_mut()
            .rev()
            .find(|p| p.name == label)
            .unwrap_or_else(|| panic!("no process labelled {label}"))
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
                "----- {} ({}; {}) -----\n{}\n",
                p.name,
                p.log.display(),
                p.kernel_view(),
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
        for (path, e) in remove_ipc_files(&self.prefix) {
            eprintln!("cannot remove {}: {e}", path.display());
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

/// The service's tick: the heartbeat grid and the period of its mux status, 20 ms.
pub const TICK: Duration = Duration::from_millis(20);

/// How late a mux decision a timing test observes may be, on top of the rule it checks: two
/// [`TICK`]s. The service decides at the dead source's expiry (`Mux::next_deadline` in chassisd),
/// but on a loaded machine its loop wakes late (one tick of allowance), and the test reads the
/// newest status, so a test thread that wakes late sees the decision in the status of a later
/// tick (the second). Measured on a 2-core machine shared with other builds (load average 4-6):
/// at most 15 ms past the rule in ten runs of the service suite.
pub const DECISION_ALLOWANCE: Duration = Duration::from_millis(2 * 20);

/// Calls `between` (the test's own sends) and reads the newest mux status until one stamped after
/// `since_ns` satisfies `condition`, for at most `timeout`. Returns that status's stamp minus
/// `since_ns`: when the service decided, not when the test happened to look.
///
/// [`MuxStatus`] samples are read newest-first, so a decision can be seen one status late
/// ([`DECISION_ALLOWANCE`]).
pub fn decided_after(
    robot: &mut Robot,
    since_ns: u64,
    timeout: Duration,
    mut between: impl FnMut(),
    mut condition: impl FnMut(&MuxStatus) -> bool,
) -> Option<Duration> {
    let end = Instant::now() + timeout;
    while Instant::now() < end {
        between();
        let _ = robot.wait_mux(Duration::from_millis(5));
        if let Ok(Some(m)) = robot.latest_mux()
            && m.stamp_ns > since_ns
            && condition(&m)
        {
            return Some(Duration::from_nanos(m.stamp_ns - since_ns));
        }
    }
    None
}

/// The `[profile]` a simulated XBot board needs over a real serial line: a real XBot's wheel
/// separation must be measured, and the board's is 0.45 m.
pub const XBOT_PROFILE: &str = "[profile]\nwheel_separation_m = 0.45\n";

/// A serial line through a pty between `chassisd sim` and chassisd.
#[derive(Clone, Copy, Debug)]
pub enum Line {
    /// A robot's own serial protocol (the XBot's).
    Serial,
    /// CAN through an slcan adapter.
    Slcan,
}

impl Line {
    /// `chassisd sim`'s `--bus`: it makes the pty and links it at `link`.
    pub fn sim_bus(self, link: &Path) -> String {
        match self {
            Self::Serial => format!("pty:{}", link.display()),
            Self::Slcan => format!("slcan-pty:{}", link.display()),
        }
    }

    /// chassisd's `--bus`: it opens the pty behind `link`.
    pub fn bus(self, link: &Path) -> String {
        match self {
            Self::Serial => format!("serial:{}", link.display()),
            Self::Slcan => format!("slcan:{}", link.display()),
        }
    }
}

/// How long a robot that must stand is watched, the fewest states it must report meanwhile,
/// and the speed below which it stands.
pub const STOOD_FOR: Duration = Duration::from_secs(1);
pub const MIN_STOOD_SAMPLES: usize = 20;
pub const STANDING_MPS: f64 = 0.01;

/// Reads every state the chassis reports for `d` (the last 4 at each read) whose speed the
/// chassis measured after `since_ns`, running `between` on every turn: how many, and the fastest
/// |speed| among them (NaN if one was not a number). A check that the robot stood asserts both:
/// states seen, none moving. The motion's own stamp decides, not the state's: after a lost bus
/// the state keeps the last speed measured until the chassis reports again, which says nothing
/// of now.
pub fn stands(
    robot: &mut Robot,
    since_ns: u64,
    d: Duration,
    mut between: impl FnMut(),
) -> (usize, f64) {
    let end = Instant::now() + d;
    let (mut samples, mut fastest) = (0usize, 0.0f64);
    while Instant::now() < end {
        between();
        let each = |s: &ChassisState| {
            if s.group_stamp_ns[Group::Motion as usize] > since_ns {
                samples += 1;
                let speed = f64::from(s.motion.linear_mps).abs();
                fastest = if speed.is_nan() || fastest.is_nan() {
                    f64::NAN
                } else {
                    fastest.max(speed)
                };
            }
        };
        // A state that cannot be read fails the test: it is no robot that stood.
        if let Err(e) = robot.wait_states(Duration::from_millis(5), each) {
            panic!("reading states: {e}");
        }
    }
    (samples, fastest)
}

/// The stops a bus outage ends with: the bus, and a fault the chassis reported meanwhile (a
/// TITAN that lost its heartbeat reports a body exception until it hears it again).
pub const BUS_AND_ITS_FAULT: &[u8] = &[Stop::BUS, Stop::CHASSIS_FAULT];

/// How a robot stood after a stop while its client kept asking for motion.
#[derive(Debug, Clone, Copy)]
pub struct StoodUntilZero {
    /// From `since` until the mux said it waits for the source's zero.
    pub waited: Duration,
    /// States read over [`STOOD_FOR`] after that, and the fastest of them, m/s.
    pub samples: usize,
    pub fastest_mps: f64,
}

impl StoodUntilZero {
    /// Enough states, none moving, none NaN.
    pub fn stood(&self) -> bool {
        self.samples >= MIN_STOOD_SAMPLES && self.fastest_mps < STANDING_MPS
    }
}

/// Motion starts only from a zero: after a stop that ends at or after `since_ns`, while `ask`
/// keeps asking for motion, waits (up to 15 s) until the mux says it waits for `source`'s zero
/// since one of `stops` (the last to end, where a fault the chassis reported for the outage
/// clears after the bus is back), then watches the robot for [`STOOD_FOR`]. `Err` names what
/// the mux said instead.
pub fn stands_until_zero(
    robot: &mut Robot,
    since_ns: u64,
    (source, stops): (&str, &[u8]),
    mut ask: impl FnMut(),
) -> Result<StoodUntilZero, String> {
    let start = Instant::now();
    let mut last = String::from("no mux status");
    let waiting = loop {
        if start.elapsed() > Duration::from_secs(15) {
            let names: Vec<&str> = stops.iter().map(|&s| Stop::name(s)).collect();
            return Err(format!(
                "the mux never waited for {source}'s zero since {}: {last}",
                names.join(" or ")
            ));
        }
        ask();
        if let Ok(Some(m)) = robot.wait_mux(Duration::from_millis(20)) {
            last = m.why().to_string();
            if m.stamp_ns > since_ns
                && m.zero_reason == ZeroReason::AWAITING_ZERO
                && stops.contains(&m.stop)
                && m.awaiting().is_some_and(|s| s.name() == source)
            {
                break start.elapsed();
            }
        }
    };
    let from = now_ns();
    let (samples, fastest_mps) = stands(robot, from, STOOD_FOR, ask);
    Ok(StoodUntilZero {
        waited: waiting,
        samples,
        fastest_mps,
    })
}

/// A hang-up of the pty line to a `chassisd sim` mid-drive, and the row of the reliability
/// report that says how it went.
#[derive(Debug)]
pub struct HangUp<'a> {
    pub rank: u32,
    pub fault: &'a str,
    pub injection: &'a str,
    /// What the figure says came back ("line", "adapter").
    pub end: &'a str,
    /// Above this speed (m/s) the robot drives again.
    pub above_mps: f32,
    /// The source the test drives as.
    pub source: &'a str,
    pub suite: &'a str,
    pub test: &'a str,
}

impl HangUp<'_> {
    /// SIGKILLs the simulator `sim` (it simulates `kind` as chassis/`name` at the far end of
    /// `line`, linked at `link`); the loss must be reported within 3 s. Then starts it again
    /// (labelled `sim2`): while `send(false)` keeps asking for motion, the bus coming back
    /// starts nothing — the robot stands and the mux waits for the source's zero — until
    /// `send(true)` asks for zero; then it waits up to 10 s for a speed above `above_mps`
    /// reported after that zero, with the bus up. Returns the figure (to be finished by the
    /// test once its asserts passed) and how long after the zero the robot drove again (`None`
    /// also when it did not stand first).
    pub fn run(
        &self,
        (env, robot): (&mut Env, &mut Robot),
        (sim, kind, name): (usize, &str, &str),
        (line, link): (Line, &Path),
        mut send: impl FnMut(bool),
    ) -> (Figures, Option<Duration>) {
        env.proc(sim).signal(Signal::SIGKILL);
        let killed = Instant::now();
        let lost = wait_for(Duration::from_secs(3), || {
            state(robot).link_flags & (LinkFlags::BUS_DOWN | LinkFlags::CHASSIS_SILENT) != 0
        });
        assert!(lost.is_some(), "the loss was not reported\n{}", env.logs());
        let down_for = killed.elapsed();
        let _ = std::fs::remove_file(link);
        let restarted = now_ns();
        env.sim("sim2", kind, &[], name, &line.sim_bus(link));
        let standing =
            stands_until_zero(robot, restarted, (self.source, BUS_AND_ITS_FAULT), || {
                send(false)
            });
        let stood = standing.as_ref().is_ok_and(StoodUntilZero::stood);
        send(true);
        let zero_sent = now_ns();
        // The state keeps the speed from before the hang-up: driving again is a speed the
        // chassis reported after the zero.
        let above = self.above_mps;
        let back = drove_again_after(
            robot,
            zero_sent,
            Duration::from_secs(10),
            || send(false),
            |s| s.link_flags & LinkFlags::BUS_DOWN == 0 && s.motion.linear_mps > above,
        )
        .map(|(_, after)| after)
        .filter(|_| stood);
        let ms = |d: Option<Duration>| d.map_or(f64::NAN, |d| d.as_secs_f64() * 1e3);
        let mut figures = Figures::faults();
        figures.add(Figure {
            rank: self.rank,
            fault: self.fault.into(),
            injection: self.injection.into(),
            behaviour: "the loss was reported (`bus_down` / `chassis_silent`) and the port \
                        reopened with backoff; motion starts only from a zero: the client kept \
                        asking on the same connection and the robot stood, its mux waiting for \
                        the client's zero since the bus came back, until it sent one; then it \
                        drove"
                .into(),
            figure: format!(
                "loss reported {:.0} ms after the hang-up; {}; driving again {:.0} ms after the \
                 zero (the motion stamp of the first sample above {} m/s; the {} restarted \
                 {:.0} ms after the hang-up)",
                ms(lost),
                match &standing {
                    Ok(s) => format!(
                        "after the {} came back the robot stood {} ms ({} states, fastest {:.3} \
                         m/s) waiting for {}'s zero",
                        self.end,
                        STOOD_FOR.as_millis(),
                        s.samples,
                        s.fastest_mps,
                        self.source
                    ),
                    Err(e) => e.clone(),
                },
                ms(back),
                self.above_mps,
                self.end,
                down_for.as_secs_f64() * 1e3
            ),
            value: ms(back),
            pass: back.is_some(),
            suite: self.suite.into(),
            test: self.test.into(),
        });
        (figures, back)
    }
}

/// What a program printed, standard output then standard error.
pub fn output_text(out: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// The line of `chassis doctor`'s `report` for check `key`, as `(verdict, line)`.
pub fn doctor_line<'a>(report: &'a str, key: &str) -> (&'a str, &'a str) {
    report
        .lines()
        .find_map(|l| {
            let mut words = l.split_whitespace();
            let verdict = words.next()?;
            (words.next()? == key).then_some((verdict, l))
        })
        .unwrap_or_else(|| panic!("no '{key}' line in\n{report}"))
}

/// Checks that `chassis doctor`'s `report` gives check `key` the verdict `verdict` on a line
/// that says `text`.
pub fn check_line(report: &str, key: &str, verdict: &str, text: &str) {
    let (got, line) = doctor_line(report, key);
    assert_eq!(got, verdict, "{report}");
    assert!(line.contains(text), "{report}");
}

/// Runs `check` (a `chassis doctor`) until it exits 0, at most `timeout`; returns how long that
/// took and the last report.
pub fn until_passes(
    timeout: Duration,
    mut check: impl FnMut() -> (Option<i32>, String),
) -> (Option<Duration>, String) {
    let mut report = String::new();
    let passed = wait_for(timeout, || {
        let (code, text) = check();
        report = text;
        code == Some(0)
    });
    (passed, report)
}

/// Runs `chassis doctor --robot ROBOT --name NAME --bus BUS --listen 1`; returns its exit code
/// and its report (printed too).
pub fn doctor_listening(env: &Env, robot: &str, name: &str, bus: &str) -> (Option<i32>, String) {
    let out = env.chassis(&[
        "doctor", "--robot", robot, "--name", name, "--bus", bus, "--listen", "1",
    ]);
    let text = output_text(&out);
    println!("{text}");
    (out.status.code(), text)
}

/// The Python of a virtualenv the test scripts prepare: `$ENV_VAR` if set, else
/// `target/VENV/bin/python`; it must run `import IMPORTS`, or the test fails saying what is
/// missing (`missing`) and how to prepare it (`hint`).
pub fn venv_python(
    env_var: &str,
    venv: &str,
    (imports, missing): (&str, &str),
    hint: &str,
) -> PathBuf {
    let python = std::env::var_os(env_var).map_or_else(
        || {
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../target")
                .join(venv)
                .join("bin/python")
        },
        PathBuf::from,
    );
    let ready = Command::new(&python)
        .args(["-c", &format!("import {imports}")])
        .status()
        .is_ok_and(|s| s.success());
    assert!(
        ready,
        "{} cannot import {missing}: {hint}",
        python.display()
    );
    python
}

/// A robot name unique to this test process: `tag` and the pid (names are at most 16
/// characters).
pub fn name(tag: &str) -> String {
    format!("{tag}{}", std::process::id() % 100_000)
}

/// Client `name`'s velocity source on `robot`.
pub fn source(robot: &mut Robot, name: &str) -> Source {
    robot
        .source(name)
        .unwrap_or_else(|e| panic!("source {name}: {e}"))
}

/// Sends `request` to the simulated chassis and checks it was accepted; returns the answer's
/// stamp (what it asked for happened just before it).
pub fn sim_ok(robot: &mut Robot, request: SimRequest) -> u64 {
    let answer = robot
        .sim(request, Duration::from_secs(3))
        .unwrap_or_else(|e| panic!("sim: {e}"));
    assert!(answer.is_ok(), "{}", answer.message());
    answer.stamp_ns
}

/// The timeout of source `name` as the running mux reports it.
pub fn source_timeout(m: &MuxStatus, name: &str) -> Duration {
    let source = m
        .sources()
        .iter()
        .find(|s| s.name() == name)
        .unwrap_or_else(|| panic!("the mux has no source {name}"));
    Duration::from_millis(u64::from(source.timeout_ms))
}

/// Reads states for `duration` and returns the largest |linear speed| seen.
pub fn max_speed(robot: &mut Robot, duration: Duration) -> f32 {
    max_speed_polling(robot, duration, Duration::from_millis(50))
}

/// [`max_speed`], waiting at most `poll` for each state sample.
pub fn max_speed_polling(robot: &mut Robot, duration: Duration, poll: Duration) -> f32 {
    let end = Instant::now() + duration;
    let mut max = 0.0f32;
    while Instant::now() < end {
        if let Ok(Some(state)) = robot.wait_state(poll) {
            max = max.max(state.motion.linear_mps.abs());
        }
    }
    max
}

/// Waits at most `timeout` until the robot moves slower than `below_mps` (either way); returns
/// how long that took.
pub fn comes_to_rest(robot: &mut Robot, timeout: Duration, below_mps: f32) -> Option<Duration> {
    wait_for(timeout, || state(robot).motion.linear_mps.abs() < below_mps)
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

/// The shell command that runs `chassis-teleop --name N` in a terminal under the test's prefix,
/// its log going to `log`.
pub fn teleop_command(env: &Env, n: &str, log: &Path) -> String {
    format!(
        "env {}={} RUST_LOG=info {} --name {n} 2>{}",
        IPC_PREFIX_ENV,
        quote(&env.prefix),
        quote(&bin("chassis-teleop").to_string_lossy()),
        quote(&log.to_string_lossy()),
    )
}

/// "Drove again" after a fault (a restart, a reconnection): waits at most `timeout` for a state
/// sample whose motion group (`ChassisState::group_stamp_ns[Group::Motion]`) was stamped after
/// `since_ns` — a speed the chassis reported after the fault, never the last one the state keeps
/// from before it — and that satisfies `condition` (a speed, a flag). `between` runs on every
/// turn (the test's own sends, a pumped tap). Returns that sample and how long after `since_ns`
/// its motion was stamped.
pub fn drove_again_after(
    robot: &mut Robot,
    since_ns: u64,
    timeout: Duration,
    mut between: impl FnMut(),
    mut condition: impl FnMut(&ChassisState) -> bool,
) -> Option<(ChassisState, Duration)> {
    let end = Instant::now() + timeout;
    while Instant::now() < end {
        between();
        if let Ok(Some(s)) = robot.wait_state(Duration::from_millis(10)) {
            let motion = s.group_stamp_ns[Group::Motion as usize];
            if motion > since_ns && condition(&s) {
                return Some((s, Duration::from_nanos(motion - since_ns)));
            }
        }
    }
    None
}

/// Asks the simulated chassis for 0.3 s of silence and waits until the service has handled
/// every frame read before it (frames in flight, then a state sample, out at least every
/// 100 ms) while `teleop` keeps sending `go` and `pump` drains the test's tap; returns that
/// state, the tap drained to the same point.
pub fn quiet_moment(
    robot: &mut Robot,
    teleop: &mut Source,
    go: VelocityRequest,
    mut pump: impl FnMut(),
) -> ChassisState {
    let silence = SimRequest {
        kind: SimKind::SILENCE,
        value: 0.3,
        ..SimRequest::default()
    };
    sim_ok(robot, silence);
    let end = Instant::now() + Duration::from_millis(200);
    while Instant::now() < end {
        teleop.send(go).unwrap_or_else(|e| panic!("teleop: {e}"));
        pump();
        pause(Duration::from_millis(20));
    }
    let s = state(robot);
    pump();
    s
}

/// What the simulated chassis (embedded or `chassisd sim`) really does: the `key=value` pairs of
/// its truth (`SimKind::TRUTH`: true pose and speeds, commands obeyed, frames rejected), read
/// by [`SimTruth::get`].
pub fn sim_truth(robot: &mut Robot) -> SimTruth {
    let request = SimRequest {
        kind: SimKind::TRUTH,
        ..SimRequest::default()
    };
    let answer = robot
        .sim(request, Duration::from_secs(2))
        .unwrap_or_else(|e| panic!("sim truth: {e}"));
    assert!(answer.is_ok(), "{}", answer.message());
    SimTruth(answer.message().to_string())
}

/// The faults the simulated chassis injected, as it counted them when each left it for the bus
/// (`SimTruthPage::INJECTED`: `garbage_frames`, `garbage_bytes`, `bad_checksums`,
/// `flood_frames`, since power-up), read by [`SimTruth::get`]: the sender's truth of a storm.
pub fn sim_injected(robot: &mut Robot) -> SimTruth {
    let request = SimRequest {
        kind: SimKind::TRUTH,
        index: SimTruthPage::INJECTED,
        ..SimRequest::default()
    };
    let answer = robot
        .sim(request, Duration::from_secs(2))
        .unwrap_or_else(|e| panic!("sim truth --injected: {e}"));
    assert!(answer.is_ok(), "{}", answer.message());
    SimTruth(answer.message().to_string())
}

/// The simulated chassis' answer to `SimKind::TRUTH`, one of its pages.
#[derive(Debug, Clone)]
pub struct SimTruth(String);

impl SimTruth {
    /// The value of `key` (panics when it is missing: the answer's format is the contract).
    pub fn get(&self, key: &str) -> f64 {
        self.value(key)
    }

    /// The value of counter `key`, exact (panics when it is missing).
    pub fn count(&self, key: &str) -> u64 {
        self.0
            .split_whitespace()
            .find_map(|kv| kv.strip_prefix(key)?.strip_prefix('='))
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("no count {key} in {:?}", self.0))
    }

    fn value(&self, key: &str) -> f64 {
        self.0
            .split_whitespace()
            .find_map(|kv| kv.strip_prefix(key)?.strip_prefix('='))
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("no {key} in {:?}", self.0))
    }
}

/// The latest mux status (waits up to a second).
pub fn mux(robot: &mut Robot) -> MuxStatus {
    robot
        .wait_mux(Duration::from_secs(1))
        .ok()
        .flatten()
        .unwrap_or_else(|| panic!("no mux status from chassis/{}", robot.name()))
}

// ----- Reliability figures (docs/RELIABILITY.md) -----

/// Environment variable naming the directory the fault tests record their figures in
/// (`faults.jsonl`, one [`Figure`] a line); unset, [`Figures`] only prints them.
pub const RELIABILITY_DIR_ENV: &str = "CHASSIS_RELIABILITY_DIR";

/// The test files that are test binaries of their own: the fault matrix (its machine lock,
/// [`faults::exclusive`], keeps timing measurements apart within one binary), the soak and the
/// VM tests. Every other file is a module of the `system` binary (`tests/tests/system/`).
pub const OWN_BINARIES: &[&str] = &[
    "faults_bus",
    "faults_clients",
    "faults_processes",
    "faults_chassis",
    "soak",
    "vcan",
    "sja1000",
];

/// The command that runs test `test` of test file `suite` alone.
pub fn rerun_command(suite: &str, test: &str) -> String {
    if OWN_BINARIES.contains(&suite) {
        format!("cargo test -p chassis-tests --test {suite} {test}")
    } else {
        format!("cargo test -p chassis-tests --test system {suite}::{test}")
    }
}

/// One row of the reliability table: a fault, how the test injected it, what the system did,
/// and the figure measured. `rank` groups the rows in the JSON lines (the table's order is
/// [`FAULT_ROWS`]'s); `suite` (the test file) and `test` name the test that reproduces it
/// ([`rerun_command`]).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Figure {
    pub rank: u32,
    pub fault: String,
    pub injection: String,
    pub behaviour: String,
    /// The figure in words, number and unit: `stopped 212 ms after the kill (timeout 300 ms)`.
    pub figure: String,
    /// The figure's main number (in the unit the text gives).
    pub value: f64,
    pub pass: bool,
    pub suite: String,
    pub test: String,
}

/// A row the reliability report expects: the test that records it and the fault it names. The
/// report is rendered from this list, not from the rows that happened to be recorded: a test
/// that failed before recording its figure shows as a failed row naming the test.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ExpectedRow {
    pub suite: &'static str,
    pub test: &'static str,
    pub fault: &'static str,
}

impl ExpectedRow {
    /// True when `figure` is this row's.
    pub fn matches(&self, figure: &Figure) -> bool {
        figure.suite == self.suite && figure.test == self.test && figure.fault == self.fault
    }

    /// The command that reproduces the row.
    pub fn command(&self) -> String {
        rerun_command(self.suite, self.test)
    }
}

/// Every row of the fault matrix (`faults.jsonl`), in the order of the table.
pub const FAULT_ROWS: &[ExpectedRow] = &[
    ExpectedRow {
        suite: "faults_processes",
        test: "sigkill_of_chassisd_at_random_moments_never_blocks_its_restart_and_clients_reconnect",
        fault: "SIGKILL of chassisd (simulated bus)",
    },
    ExpectedRow {
        suite: "faults_processes",
        test: "sigkill_of_chassisd_over_slcan_lets_the_titan_stop_on_its_own_heartbeat_timeout",
        fault: "SIGKILL of chassisd (slcan over a pty to `chassisd sim`)",
    },
    ExpectedRow {
        suite: "faults_processes",
        test: "sigkill_of_chassisd_sim_is_reported_as_a_lost_bus_and_survived",
        fault: "SIGKILL of `chassisd sim` (the XBot's serial link over a pty hangs up)",
    },
    ExpectedRow {
        suite: "faults_processes",
        test: "sigkill_of_the_safety_monitor_at_random_moments_stops_the_robot_within_its_timeout",
        fault: "SIGKILL of chassis-safety (the required source)",
    },
    ExpectedRow {
        suite: "faults_processes",
        test: "sigkill_of_the_planner_at_random_moments_ends_its_motion_with_its_timeout",
        fault: "SIGKILL of chassis-planner (figure-eights)",
    },
    ExpectedRow {
        suite: "faults_processes",
        test: "sigkill_of_chassis_pub_at_random_moments_ends_its_motion_with_its_timeout",
        fault: "SIGKILL of `chassis pub` (as teleop)",
    },
    ExpectedRow {
        suite: "faults_processes",
        test: "sigkill_of_chassis_teleop_in_a_terminal_ends_its_motion_with_its_timeout",
        fault: "SIGKILL of chassis-teleop (a key held in a terminal)",
    },
    ExpectedRow {
        suite: "service",
        test: "titan_drives_over_slcan_ptys_against_chassisd_sim_and_survives_a_hang_up",
        fault: "slcan adapter hang-up (TITAN over an slcan pty)",
    },
    ExpectedRow {
        suite: "serial",
        test: "xbot_drives_over_a_serial_pty_against_chassisd_sim_and_reconnects_after_a_hang_up",
        fault: "serial line hang-up (XBot over a pty)",
    },
    ExpectedRow {
        suite: "faults_bus",
        test: "garbage_frame_storms_on_the_titan_bus_are_counted_and_lose_no_good_frame",
        fault: "garbage CAN frames (id 0x7F0) on the TITAN's bus, 10 frames/s",
    },
    ExpectedRow {
        suite: "faults_bus",
        test: "garbage_frame_storms_on_the_titan_bus_are_counted_and_lose_no_good_frame",
        fault: "garbage CAN frames (id 0x7F0) on the TITAN's bus, 100 frames/s",
    },
    ExpectedRow {
        suite: "faults_bus",
        test: "garbage_frame_storms_on_the_titan_bus_are_counted_and_lose_no_good_frame",
        fault: "garbage CAN frames (id 0x7F0) on the TITAN's bus, 1000 frames/s",
    },
    ExpectedRow {
        suite: "faults_bus",
        test: "garbage_frame_storms_on_a_protocol_v2_bus_are_counted_and_lose_no_good_frame",
        fault: "garbage CAN frames (id 0x7F0) on the HUNTER's bus (protocol V2), 10 frames/s",
    },
    ExpectedRow {
        suite: "faults_bus",
        test: "garbage_frame_storms_on_a_protocol_v2_bus_are_counted_and_lose_no_good_frame",
        fault: "garbage CAN frames (id 0x7F0) on the HUNTER's bus (protocol V2), 100 frames/s",
    },
    ExpectedRow {
        suite: "faults_bus",
        test: "garbage_frame_storms_on_a_protocol_v2_bus_are_counted_and_lose_no_good_frame",
        fault: "garbage CAN frames (id 0x7F0) on the HUNTER's bus (protocol V2), 1000 frames/s",
    },
    ExpectedRow {
        suite: "faults_bus",
        test: "bad_checksum_storms_on_the_scout_mini_bus_are_counted_and_lose_no_good_frame",
        fault: "bad checksums on the SCOUT MINI's CAN frames, 10 frames/s",
    },
    ExpectedRow {
        suite: "faults_bus",
        test: "bad_checksum_storms_on_the_scout_mini_bus_are_counted_and_lose_no_good_frame",
        fault: "bad checksums on the SCOUT MINI's CAN frames, 100 frames/s",
    },
    ExpectedRow {
        suite: "faults_bus",
        test: "bad_checksum_storms_on_the_scout_mini_bus_are_counted_and_lose_no_good_frame",
        fault: "bad checksums on the SCOUT MINI's CAN frames, 250 frames/s",
    },
    ExpectedRow {
        suite: "faults_bus",
        test: "garbage_and_bad_checksum_storms_on_the_xbot_line_are_counted_and_lose_no_good_report",
        fault: "garbage bytes on the XBot's serial line, 100 bytes/s",
    },
    ExpectedRow {
        suite: "faults_bus",
        test: "garbage_and_bad_checksum_storms_on_the_xbot_line_are_counted_and_lose_no_good_report",
        fault: "garbage bytes on the XBot's serial line, 1000 bytes/s",
    },
    ExpectedRow {
        suite: "faults_bus",
        test: "garbage_and_bad_checksum_storms_on_the_xbot_line_are_counted_and_lose_no_good_report",
        fault: "garbage bytes on the XBot's serial line, 10000 bytes/s",
    },
    ExpectedRow {
        suite: "faults_bus",
        test: "garbage_and_bad_checksum_storms_on_the_xbot_line_are_counted_and_lose_no_good_report",
        fault: "bad checksums on the XBot's serial reports, 5 reports/s",
    },
    ExpectedRow {
        suite: "faults_bus",
        test: "garbage_and_bad_checksum_storms_on_the_xbot_line_are_counted_and_lose_no_good_report",
        fault: "bad checksums on the XBot's serial reports, 20 reports/s",
    },
    ExpectedRow {
        suite: "faults_clients",
        test: "a_rogue_client_flooding_requests_neither_wins_nor_shakes_the_heartbeat",
        fault: "a rogue client flooding the `planner` source (below teleop, which drives)",
    },
    ExpectedRow {
        suite: "faults_clients",
        test: "a_rogue_client_of_the_driving_priority_wins_only_with_the_newer_request",
        fault: "a rogue client flooding the `foxglove` source (teleop's priority; teleop drives)",
    },
    ExpectedRow {
        suite: "faults_clients",
        test: "a_rogue_client_above_the_driving_priority_wins_by_design_and_shakes_nothing",
        fault: "a rogue client flooding the `teleop` source (above the planner, which drives)",
    },
    ExpectedRow {
        suite: "faults_clients",
        test: "non_finite_and_absurd_requests_are_rejected_counted_and_logged_once_a_second",
        fault: "NaN, ±inf and absurd requests (1000 m/s, -100 rad/s, 3 rad steering)",
    },
    ExpectedRow {
        suite: "faults_clients",
        test: "a_second_publisher_on_the_safety_source_is_refused_and_the_monitor_unharmed",
        fault: "a second publisher on the `safety` source while chassis-safety holds it",
    },
    ExpectedRow {
        suite: "service",
        test: "a_second_chassisd_for_the_same_robot_is_refused_and_the_first_is_unharmed",
        fault: "a second chassisd for the same robot name",
    },
    ExpectedRow {
        suite: "latch",
        test: "an_estop_release_never_restarts_motion_by_itself",
        fault: "the e-stop released while teleop keeps asking for motion",
    },
    ExpectedRow {
        suite: "latch",
        test: "a_release_followed_by_a_silence_longer_than_the_timeout_still_waits_for_a_zero",
        fault: "the e-stop released, then teleop silent beyond its timeout and asking again",
    },
    ExpectedRow {
        suite: "service",
        test: "a_v2_chassis_estop_switch_stops_it_and_only_a_zero_command_lets_it_drive_again",
        fault: "the chassis' own E-stop switch (HUNTER 2.0, protocol V2) pressed and released",
    },
    ExpectedRow {
        suite: "latch",
        test: "an_answered_estop_is_held_after_a_kill_at_any_moment_after_the_answer",
        fault: "chassisd SIGKILLed with the e-stop held, and restarted",
    },
    ExpectedRow {
        suite: "systemd",
        test: "the_watchdog_pings_come_from_the_loop_and_stop_while_it_stalls",
        fault: "chassisd's event loop stalls (hung) under a systemd watchdog",
    },
    ExpectedRow {
        suite: "zenoh",
        test: "the_operator_reads_the_robots_description_and_a_release_through_the_mirror_starts_no_motion",
        fault: "the e-stop released through the Zenoh mirror while the operator asks for motion",
    },
    ExpectedRow {
        suite: "zenoh",
        test: "requests_buffered_through_an_outage_never_drive_when_the_link_comes_back",
        fault: "remote requests buffered through a Zenoh link outage",
    },
    ExpectedRow {
        suite: "ros2_reach",
        test: "a_dds_peer_on_the_robots_network_drives_only_when_the_discovery_range_allows_it",
        fault: "a DDS peer on the robot's network publishes cmd_vel",
    },
    ExpectedRow {
        suite: "faults_chassis",
        test: "a_chassis_running_away_from_its_command_is_latched",
        fault: "the chassis runs away: 1.2 m/s while commanded 0.5 m/s (TITAN)",
    },
    ExpectedRow {
        suite: "faults_chassis",
        test: "a_chassis_driving_against_its_command_is_latched",
        fault: "the chassis drives against its command (TITAN, wheels at −1 × the command)",
    },
    ExpectedRow {
        suite: "faults_chassis",
        test: "a_chassis_ignoring_its_command_is_stopped_and_the_cause_named",
        fault: "the chassis ignores its command and reports nothing (TITAN, wheels at 0 × the command)",
    },
    ExpectedRow {
        suite: "faults_chassis",
        test: "a_chassis_in_standby_is_stopped_and_the_cause_named",
        fault: "the chassis in standby while commanded: it answers and does not drive (TITAN)",
    },
    ExpectedRow {
        suite: "faults_chassis",
        test: "a_slipping_chassis_is_stopped_and_the_cause_named",
        fault: "the chassis slips: 10 % of the commanded speed (TITAN)",
    },
    ExpectedRow {
        suite: "faults_chassis",
        test: "a_motor_driver_lost_mid_motion_stops_the_chassis",
        fault: "a motor driver lost mid-motion (TITAN, driver 1)",
    },
    ExpectedRow {
        suite: "faults_chassis",
        test: "a_chassis_running_over_its_speed_limit_is_stopped",
        fault: "the chassis runs over a lowered speed limit: 0.3 m/s set, 1.6 × the command \
                measured (TITAN)",
    },
    ExpectedRow {
        suite: "faults_chassis",
        test: "a_chassis_turning_against_its_command_is_latched",
        fault: "the chassis turns against its command (SCOUT MINI turning on the spot, wheels \
                at −1 × the command)",
    },
    ExpectedRow {
        suite: "faults_chassis",
        test: "stop_distances",
        fault: "the operator's e-stop of each stop category from 1 m/s and from full speed (titan)",
    },
    ExpectedRow {
        suite: "faults_chassis",
        test: "stop_distances",
        fault: "the operator's e-stop of each stop category from 1 m/s and from full speed (scout-mini)",
    },
    ExpectedRow {
        suite: "faults_chassis",
        test: "stop_distances",
        fault: "the operator's e-stop of each stop category from 1 m/s and from full speed (xbot)",
    },
    ExpectedRow {
        suite: "faults_chassis",
        test: "stop_distances",
        fault: "the operator's e-stop of each stop category from 1 m/s and from full speed (scout)",
    },
    ExpectedRow {
        suite: "faults_chassis",
        test: "stop_distances",
        fault: "the operator's e-stop of each stop category from 1 m/s and from full speed (hunter)",
    },
    ExpectedRow {
        suite: "faults_chassis",
        test: "stop_distances",
        fault: "the operator's e-stop of each stop category from 1 m/s and from full speed (hunter-se)",
    },
    ExpectedRow {
        suite: "faults_chassis",
        test: "stop_distances",
        fault: "the operator's e-stop of each stop category from 1 m/s and from full speed (tracer)",
    },
    ExpectedRow {
        suite: "faults_chassis",
        test: "stop_distances",
        fault: "the operator's e-stop of each stop category from 1 m/s and from full speed (bunker)",
    },
    ExpectedRow {
        suite: "faults_chassis",
        test: "stop_distances",
        fault: "the operator's e-stop of each stop category from 1 m/s and from full speed (ranger-mini)",
    },
    ExpectedRow {
        suite: "faults_chassis",
        test: "stop_distances",
        fault: "the operator's e-stop of each stop category from 1 m/s and from full speed (tracer-mini)",
    },
];

/// Every row of the soak's table (`soak.jsonl`), in the order of the table.
pub const SOAK_ROWS: &[ExpectedRow] = &[
    ExpectedRow {
        suite: "soak",
        test: "a_titan_on_a_full_bus_with_every_client_runs_for_minutes_without_gaps_or_growth",
        fault: "frames: sequence gaps",
    },
    ExpectedRow {
        suite: "soak",
        test: "a_titan_on_a_full_bus_with_every_client_runs_for_minutes_without_gaps_or_growth",
        fault: "state: sequence gaps",
    },
    ExpectedRow {
        suite: "soak",
        test: "a_titan_on_a_full_bus_with_every_client_runs_for_minutes_without_gaps_or_growth",
        fault: "resident memory of chassisd",
    },
    ExpectedRow {
        suite: "soak",
        test: "a_titan_on_a_full_bus_with_every_client_runs_for_minutes_without_gaps_or_growth",
        fault: "open file descriptors of chassisd",
    },
    ExpectedRow {
        suite: "soak",
        test: "a_titan_on_a_full_bus_with_every_client_runs_for_minutes_without_gaps_or_growth",
        fault: "heartbeat (0x111) jitter",
    },
    ExpectedRow {
        suite: "soak",
        test: "a_titan_on_a_full_bus_with_every_client_runs_for_minutes_without_gaps_or_growth",
        fault: "safety and drive",
    },
];

/// The expected rows of the figures file `file` (`faults.jsonl` or `soak.jsonl`).
pub fn expected_rows(file: &str) -> &'static [ExpectedRow] {
    match file {
        "soak.jsonl" => SOAK_ROWS,
        _ => FAULT_ROWS,
    }
}

/// The figures of one test, written when the test ends: into
/// `$CHASSIS_RELIABILITY_DIR/faults.jsonl` ([`Figures::faults`]) or `soak.jsonl`
/// ([`Figures::soak`]), and printed; without the variable they are only printed.
///
/// A figure's `pass` is the test's verdict on it, but it is written as passing only when the
/// test got to its end: [`Figures::finish`] is the test's last statement, after its last
/// assert. A test that panics (a failed assert anywhere, before or after the figure was
/// measured) or never calls `finish` writes its figures with `pass: false` when they are
/// dropped. The report also reads each test's outcome from libtest's output
/// (`reliability-report`), so a row never shows pass for a failed test.
#[derive(Debug)]
#[must_use = "a test's figures are written by `finish`, its last statement"]
pub struct Figures {
    file: &'static str,
    rows: Vec<Figure>,
    finished: bool,
}

impl Figures {
    /// The figures of a fault test (`faults.jsonl`, rows of [`FAULT_ROWS`]).
    pub fn faults() -> Self {
        Self::new("faults.jsonl")
    }

    /// The figures of the soak (`soak.jsonl`, rows of [`SOAK_ROWS`]).
    pub fn soak() -> Self {
        Self::new("soak.jsonl")
    }

    fn new(file: &'static str) -> Self {
        Self {
            file,
            rows: Vec::new(),
            finished: false,
        }
    }

    /// Adds `row`, to be written when the test ends. It must be one of the report's rows.
    pub fn add(&mut self, row: Figure) {
        assert!(
            expected_rows(self.file).iter().any(|e| e.matches(&row)),
            "the figure of '{}' ({} {}) is not in the report's list of rows ({}): add it there",
            row.fault,
            row.suite,
            row.test,
            if self.file == "soak.jsonl" {
                "SOAK_ROWS"
            } else {
                "FAULT_ROWS"
            }
        );
        self.rows.push(row);
    }

    /// The test's last statement: every assert passed, so each figure is written with the
    /// test's own verdict on it.
    pub fn finish(mut self) {
        self.finished = true;
        let rows = std::mem::take(&mut self.rows);
        for row in &rows {
            if let Err(e) = write_figure(self.file, row) {
                panic!("recording a figure: {e}");
            }
        }
    }
}

impl Drop for Figures {
    /// The test did not get to `finish`: its figures are written as failed.
    fn drop(&mut self) {
        if self.finished {
            return;
        }
        for row in &self.rows {
            let failed = Figure {
                pass: false,
                ..row.clone()
            };
            if let Err(e) = write_figure(self.file, &failed) {
                eprintln!("recording a failed figure: {e}");
            }
        }
    }
}

/// Appends `row` to `$CHASSIS_RELIABILITY_DIR/<file>` and prints it.
fn write_figure(file: &str, row: &Figure) -> std::io::Result<()> {
    use std::io::Write;
    eprintln!(
        "FIGURE [{}] {}: {} — {}",
        if row.pass { "pass" } else { "FAIL" },
        row.fault,
        row.figure,
        row.behaviour
    );
    let Some(dir) = std::env::var_os(RELIABILITY_DIR_ENV) else {
        return Ok(());
    };
    let dir = PathBuf::from(dir);
    std::fs::create_dir_all(&dir)?;
    let path = dir.join(file);
    let line = serde_json::to_string(row)? + "\n";
    // One write of one line with O_APPEND: tests running in parallel never interleave.
    std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&path)
        .and_then(|mut f| f.write_all(line.as_bytes()))
        .map_err(|e| std::io::Error::new(e.kind(), format!("{}: {e}", path.display())))
}

/// A small seeded random number generator (SplitMix64): fault moments that a seed reproduces.
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    /// The seed from `CHASSIS_FAULT_SEED` if set, else from the clock; printed either way so a
    /// failing run can be repeated.
    pub fn from_env(what: &str) -> Self {
        let seed = std::env::var("CHASSIS_FAULT_SEED")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or_else(|| now_ns() ^ u64::from(std::process::id()).rotate_left(32));
        eprintln!("{what}: random fault moments with CHASSIS_FAULT_SEED={seed}");
        Self::new(seed)
    }

    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// A duration drawn uniformly from `[low, high)`.
    pub fn between(&mut self, low: Duration, high: Duration) -> Duration {
        let span = u64::try_from(high.saturating_sub(low).as_micros())
            .unwrap_or(u64::MAX)
            .max(1);
        low + Duration::from_micros(self.next_u64() % span)
    }
}

/// Summary of a set of intervals (heartbeat periods), ms.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Spread {
    pub count: usize,
    pub min_ms: f64,
    pub max_ms: f64,
    pub mean_ms: f64,
    pub p1_ms: f64,
    pub p50_ms: f64,
    pub p99_ms: f64,
}

impl Spread {
    /// The spread of the gaps between consecutive `stamps_ns` (sorted or not).
    pub fn of_gaps(stamps_ns: &[u64]) -> Self {
        let mut sorted = stamps_ns.to_vec();
        sorted.sort_unstable();
        let gaps: Vec<f64> = sorted
            .windows(2)
            .map(|w| (w[1] - w[0]) as f64 / 1e6)
            .collect();
        Self::of(&gaps)
    }

    /// The spread of `values_ms`.
    pub fn of(values_ms: &[f64]) -> Self {
        if values_ms.is_empty() {
            return Self::default();
        }
        let mut v = values_ms.to_vec();
        v.sort_by(f64::total_cmp);
        let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
        Self {
            count: v.len(),
            min_ms: v[0],
            max_ms: v[v.len() - 1],
            mean_ms: v.iter().sum::<f64>() / v.len() as f64,
            p1_ms: at(0.01),
            p50_ms: at(0.5),
            p99_ms: at(0.99),
        }
    }

    /// Largest deviation from `period_ms`, ms.
    pub fn worst_deviation_ms(&self, period_ms: f64) -> f64 {
        (self.max_ms - period_ms).max(period_ms - self.min_ms)
    }
}

/// Resident memory of process `pid`, KiB (`VmRSS` in `/proc/PID/status`).
pub fn rss_kib(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.split_whitespace().next())
        .and_then(|v| v.parse().ok())
}

/// Open file descriptors of process `pid` (entries of `/proc/PID/fd`).
pub fn open_fds(pid: u32) -> Option<usize> {
    std::fs::read_dir(format!("/proc/{pid}/fd"))
        .ok()
        .map(Iterator::count)
}

// ----- A program in a terminal (tmux) -----

/// True when `tmux` runs here (the terminal tests skip, saying so, without it).
pub fn tmux_available() -> bool {
    Command::new("tmux")
        .arg("-V")
        .output()
        .is_ok_and(|o| o.status.success())
}

/// A private tmux server (its own socket in the test's directory) running one program in a
/// detached 120×40 session, killed when dropped.
#[derive(Debug)]
pub struct Tmux {
    socket: PathBuf,
}

impl Tmux {
    /// Starts `command` (a shell command line) with the server's socket `dir/label.tmux`.
    pub fn start(dir: &Path, label: &str, command: &str) -> Self {
        let tmux = Self {
            socket: dir.join(format!("{label}.tmux")),
        };
        let out = tmux.run(&[
            "new-session",
            "-d",
            "-x",
            "120",
            "-y",
            "40",
            "-s",
            "ops",
            command,
        ]);
        assert!(
            out.status.success(),
            "tmux new-session: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        tmux
    }

    pub fn run(&self, args: &[&str]) -> Output {
        Command::new("tmux")
            .arg("-S")
            .arg(&self.socket)
            .args(args)
            .output()
            .unwrap_or_else(|e| panic!("running tmux: {e}"))
    }

    /// Types `key`; the session must still be there.
    pub fn send(&self, key: &str) {
        let out = self.run(&["send-keys", "-t", "ops", key]);
        assert!(
            out.status.success(),
            "tmux send-keys: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }

    /// Types `key` if the session is still there (its program may have been killed).
    pub fn try_send(&self, key: &str) -> bool {
        self.run(&["send-keys", "-t", "ops", key]).status.success()
    }

    /// The pane's process (the program itself when it was started with `exec`).
    pub fn pid(&self) -> Option<i32> {
        let out = self.run(&["list-panes", "-t", "ops", "-F", "#{pane_pid}"]);
        String::from_utf8_lossy(&out.stdout).trim().parse().ok()
    }

    pub fn screen(&self) -> String {
        String::from_utf8_lossy(&self.run(&["capture-pane", "-p", "-t", "ops"]).stdout).into_owned()
    }

    /// Waits until the screen contains `text`; returns the screen.
    pub fn wait_for_text(&self, text: &str, timeout: Duration) -> String {
        let mut screen = String::new();
        let found = wait_for(timeout, || {
            screen = self.screen();
            screen.contains(text)
        });
        assert!(found.is_some(), "'{text}' never appeared:\n{screen}");
        screen
    }
}

impl Drop for Tmux {
    fn drop(&mut self) {
        let _ = self.run(&["kill-server"]);
    }
}

/// `text` quoted for a POSIX shell command line.
pub fn quote(text: &str) -> String {
    format!("'{}'", text.replace('\'', r"'\''"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every row the report expects names a test that exists in its suite, and no row twice.
    #[test]
    fn every_expected_reliability_row_names_an_existing_test() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests");
        for (i, row) in FAULT_ROWS.iter().chain(SOAK_ROWS).enumerate() {
            let file = if OWN_BINARIES.contains(&row.suite) {
                format!("{}.rs", row.suite)
            } else {
                format!("system/{}.rs", row.suite)
            };
            let source = std::fs::read_to_string(dir.join(file))
                .unwrap_or_else(|e| panic!("{}: {e}", row.suite));
            assert!(
                source.contains(&format!("fn {}()", row.test)),
                "{} has no test {}",
                row.suite,
                row.test
            );
            let again = FAULT_ROWS
                .iter()
                .chain(SOAK_ROWS)
                .skip(i + 1)
                .any(|other| other == row);
            assert!(!again, "{row:?} listed twice");
        }
    }
}
