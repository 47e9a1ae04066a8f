//! The real paths through a running `chassisd`:
//!
//! * **command**: a `VelocityRequest` created in this process → the motion frame written to the
//!   bus by the service (the frame tap's TX stamp, taken right after the write);
//! * **state**: a frame read from the bus (the service stamps it right after the read) → the
//!   `ChassisState` it changed, received here;
//! * **preemption**: the `safety` source publishes a stop while `teleop` drives → the zero
//!   frame written.
//!
//! Every figure is one-way, from `CLOCK_MONOTONIC` stamps taken in two processes.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use anyhow::{Context, bail};
use chassis_client::{
    BusFrame, ChassisState, FrameDirection, FrameKind, IPC_PREFIX_ENV, Robot, STATE_BUFFER, Source,
    Ticker, Velocity, VelocityRequest, now_ns,
};
pub use chassis_ipc::PassStamps;
use chassis_protocols::driver::DriverConfig;
use chassis_protocols::frame_json::{BoxedCodec, FrameJson};
use chassis_protocols::pair::Pair;
use chassis_protocols::titan::{self, TitanProfile};
use chassis_protocols::{CanFrame, CandumpLine, Direction, RobotKind, Timestamp, WireItem};
use serde::Serialize;
use zerocopy::IntoBytes as _;

use crate::placement::{nanos, pause, pin_current_thread, unique, unpin_current_thread};
use crate::report::{Cost, Scheduling, Throughput};
use crate::stats::Latencies;

/// How long a hybrid receiver keeps polling after each activity: chassisd's `--spin-us` in the
/// benchmark's hybrid runs, and the poll-then-block baseline's window.
pub const HYBRID_SPIN: Duration = Duration::from_micros(200);

/// How the service's loop waits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum LoopMode {
    Event,
    Spin,
    Hybrid,
}

impl LoopMode {
    pub fn arg(self) -> &'static str {
        match self {
            LoopMode::Event => "event",
            LoopMode::Spin => "spin",
            LoopMode::Hybrid => "hybrid",
        }
    }
}

/// chassisd's real-time priority in the benchmark: the one `deploy/chassisd@.service` gives a
/// robot (`--realtime 80`).
pub const REALTIME_PRIORITY: u8 = 80;

/// Which bus the service uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum BusKind {
    /// The embedded simulator (a socket pair).
    Sim,
    /// `chassisd sim` on a pty: raw serial (XBot) or an slcan adapter (CAN robots).
    Pty,
}

/// The service under test, stopped on drop.
pub struct Service {
    pub name: String,
    children: Children,
    pub pid: u32,
    /// Where chassisd writes its pass trace as it stops, when asked for one.
    trace: Option<PathBuf>,
    /// How chassisd's loop is scheduled.
    pub scheduling: Scheduling,
}

impl Service {
    /// Stops the service and returns the passes of its trace (none when it kept no trace).
    pub fn stop(mut self) -> anyhow::Result<Vec<PassStamps>> {
        drop(std::mem::take(&mut self.children));
        let Some(path) = &self.trace else {
            return Ok(Vec::new());
        };
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("reading chassisd's pass trace {}", path.display()))?;
        PassStamps::parse(&text).with_context(|| format!("{}", path.display()))
    }
}

/// Processes stopped on drop, newest first: each asked to end (SIGTERM), then each waited for.
#[derive(Default)]
pub struct Children(pub Vec<Child>);

impl Children {
    /// Keeps `child`; its pid.
    pub fn push(&mut self, child: Child) -> u32 {
        let pid = child.id();
        self.0.push(child);
        pid
    }
}

impl Drop for Children {
    fn drop(&mut self) {
        use nix::sys::signal::{Signal, kill};
        for child in self.0.iter().rev() {
            if let Ok(pid) = i32::try_from(child.id()) {
                let _ = kill(nix::unistd::Pid::from_raw(pid), Signal::SIGTERM);
            }
        }
        for child in self.0.iter_mut().rev() {
            let _ = child.wait();
        }
    }
}

/// Where the workspace's binaries are (next to this one).
pub fn sibling(binary: &str) -> anyhow::Result<PathBuf> {
    let path = std::env::current_exe()?.with_file_name(binary);
    if !path.exists() {
        let path = path.display();
        bail!(
            "{path} not found next to chassis-bench: build the whole workspace (`cargo build --workspace`)"
        );
    }
    Ok(path)
}

/// The configuration of chassisd in the benchmark's runs, where it differs from the default:
/// no minimum spacing between command frames (default 2 ms), no idle brake (the TITAN's brake
/// engages after an idle time by default), no acceleration smoothing (by default the mux ramps a
/// change at 2 m/s² and its yaw-rate limit): a command's frame then carries the requested speed
/// itself, which the command path waits for. The document states it; a default-configuration
/// row is measured beside it.
pub const BENCH_CONFIG: &str = "[driver]\nmin_command_interval_ms = 0\nbrake_idle_engage_ms = 0\n\n\
                                [mux.limits]\nlinear_accel_mps2 = 0.0\nangular_accel_radps2 = 0.0\n";

/// Which configuration a run's chassisd has.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ServiceConfig {
    /// [`BENCH_CONFIG`], normal scheduling: the cost, memory, fan-out and Zenoh runs.
    Bench,
    /// [`BENCH_CONFIG`] in real-time mode where the loop blocks: the latency runs of the service
    /// paths.
    BenchRealtime,
    /// [`ServiceConfig::BenchRealtime`] with the black box off (`blackbox_mib = 0`): what its
    /// recording costs the paths.
    BenchRealtimeUnrecorded,
    /// chassisd's defaults.
    Default,
}

impl ServiceConfig {
    /// The SCHED_FIFO priority this configuration asks for with the loop `mode`, if any:
    /// [`REALTIME_PRIORITY`] for a loop that blocks, as a robot runs it; none for the polling
    /// loop, which at SCHED_FIFO holds its CPU and is stopped by the kernel's real-time
    /// throttling (`kernel.sched_rt_runtime_us`: 50 ms of every second by default) unless its
    /// CPU is isolated, which this machine's are not.
    pub fn realtime(self, mode: LoopMode) -> Option<u8> {
        let blocks = mode != LoopMode::Spin;
        let realtime = matches!(
            self,
            ServiceConfig::BenchRealtime | ServiceConfig::BenchRealtimeUnrecorded
        );
        (realtime && blocks).then_some(REALTIME_PRIORITY)
    }
}

/// The configuration file of a run: [`BENCH_CONFIG`], in real-time mode when the configuration
/// asks for it with this loop ([`ServiceConfig::realtime`]); empty for chassisd's defaults.
pub fn config_text(config: ServiceConfig, mode: LoopMode) -> String {
    let unrecorded = config == ServiceConfig::BenchRealtimeUnrecorded;
    match (config, config.realtime(mode)) {
        (ServiceConfig::Default, _) => String::new(),
        (_, Some(priority)) if unrecorded => {
            format!("[service]\nrealtime = {priority}\nblackbox_mib = 0\n\n{BENCH_CONFIG}")
        }
        (_, Some(priority)) => format!("[service]\nrealtime = {priority}\n\n{BENCH_CONFIG}"),
        (_, None) => BENCH_CONFIG.to_string(),
    }
}

/// The SCHED_FIFO priority of the first of `pid`'s threads that runs at SCHED_FIFO, if one does:
/// whether chassisd's loop got the real-time mode it asked for.
pub fn fifo_priority(pid: u32) -> Option<u8> {
    threads(pid).find_map(|(tid, _)| {
        let tid = libc::pid_t::try_from(tid).ok()?;
        // SAFETY: sched_getscheduler and sched_getparam take a thread id and, for the second,
        // a valid sched_param to fill; a thread that is gone makes them fail, not misbehave.
        unsafe {
            if libc::sched_getscheduler(tid) != libc::SCHED_FIFO {
                return None;
            }
            let mut param = libc::sched_param { sched_priority: 0 };
            if libc::sched_getparam(tid, &mut param) != 0 {
                return None;
            }
            u8::try_from(param.sched_priority).ok()
        }
    })
}

/// Starts `command` (chassisd, its simulator, chassis-zenoh) under the IPC prefix `prefix` at
/// the `RUST_LOG` level `level`, its stdout to `<log>.log`, its stderr to `<log>-err.log`.
pub(crate) fn spawn_logged(
    command: &mut Command,
    (prefix, level): (&str, &str),
    log: &Path,
    what: &str,
) -> anyhow::Result<Child> {
    let file = |suffix: &str| -> anyhow::Result<Stdio> {
        let path = PathBuf::from(format!("{}{suffix}.log", log.display()));
        let file =
            std::fs::File::create(&path).with_context(|| format!("creating {}", path.display()))?;
        Ok(Stdio::from(file))
    };
    command
        .env(IPC_PREFIX_ENV, prefix)
        .env("RUST_LOG", level)
        // The held locks and the black box of every robot of the run, in its scratch directory.
        .env("XDG_STATE_HOME", log.with_file_name("state"))
        .stdout(file("")?)
        .stderr(file("-err")?)
        .spawn()
        .with_context(|| format!("starting {what}"))
}

/// What `f` brings, once it brings something (at most `seconds` away); fails with `what`.
pub(crate) fn wait_until<T>(
    what: &str,
    seconds: u64,
    mut f: impl FnMut() -> Option<T>,
) -> anyhow::Result<T> {
    let deadline = now_ns() + seconds * 1_000_000_000;
    let mut ticker = Ticker::new(Duration::from_millis(50));
    loop {
        if let Some(v) = f() {
            return Ok(v);
        }
        if now_ns() > deadline {
            bail!("{what} within {seconds}s");
        }
        ticker.wait();
    }
}

/// A started service and a client of it.
pub type Started = (Service, Robot);

/// Starts `chassisd` (and, for a pty bus, `chassisd sim`) for `robot` on `bus` with the loop
/// `mode`, configured as `config` says, keeping its pass trace with `trace` ([`Service::stop`]
/// returns it), and waits until it publishes and the chassis is in command mode.
pub fn start(
    (robot, bus, mode): (RobotKind, BusKind, LoopMode),
    cpu: Option<usize>,
    config: ServiceConfig,
    trace: bool,
    prefix: &str,
    dir: &Path,
) -> anyhow::Result<Started> {
    let name = format!("bn{}", unique());
    let trace = trace.then(|| dir.join(format!("{name}-passes.txt")));
    let config_file = dir.join(format!("{name}.toml"));
    let mut text = config_text(config, mode);
    if robot == RobotKind::Xbot {
        // The benchmark's simulated board has a known wheel separation.
        text.push_str("\n[profile]\nwheel_separation_m = 0.45\n");
    }
    std::fs::write(&config_file, text)?;
    let mut children = Children::default();
    let bus_arg = match bus {
        BusKind::Sim => "sim".to_string(),
        BusKind::Pty => {
            let link = dir.join(format!("{name}-link")).display().to_string();
            let (sim_bus, service_bus) = match robot.is_can() {
                true => (format!("slcan-pty:{link}"), format!("slcan:{link}")),
                false => (format!("pty:{link}"), format!("serial:{link}")),
            };
            let mut sim = Command::new(sibling("chassisd")?);
            let args = format!("sim --robot {} --name {name} --bus", robot.name());
            sim.args(args.split(' ')).arg(&sim_bus);
            let log = dir.join(format!("{name}-sim"));
            let spawned = spawn_logged(&mut sim, (prefix, "warn"), &log, "chassisd sim")?;
            children.push(spawned);
            let linked = || Path::new(&link).exists().then_some(());
            wait_until("chassisd sim made no pty link", 10, linked)?;
            service_bus
        }
    };
    let mut args = vec!["--config".into(), config_file.display().to_string()];
    args.extend(["--loop".into(), mode.arg().into()]);
    if let Some(cpu) = cpu {
        args.extend(["--cpu".into(), cpu.to_string()]);
    }
    if mode == LoopMode::Hybrid {
        // The same window as the poll-then-block baseline's.
        args.extend(["--spin-us".into(), HYBRID_SPIN.as_micros().to_string()]);
    }
    let envs: Vec<_> = (trace.iter())
        .map(|path| (chassis_ipc::Trace::Pass.env(), path.clone()))
        .collect();
    let spec = (robot, name.as_str(), bus_arg.as_str());
    let (mut service, robot_conn) = launch(spec, &args, &envs, children, prefix, dir)?;
    service.trace = trace;
    // chassisd enters real-time mode before its loop's first wait, so by now.
    if config.realtime(mode).is_some() {
        let fifo = fifo_priority(service.pid);
        service.scheduling = fifo.map_or(Scheduling::Refused, Scheduling::Fifo);
    }
    Ok((service, robot_conn))
}

/// chassisd for `robot` as `name` on the bus `bus` (as its `--bus` takes it: `sim`, `can:can0`),
/// without its safety monitor: the bench's sources are its only ones.
fn chassisd(robot: &str, name: &str, bus: &str) -> anyhow::Result<Command> {
    let mut chassisd = Command::new(sibling("chassisd")?);
    chassisd.args(["--robot", robot, "--name", name, "--bus", bus]);
    chassisd.arg("--no-safety-monitor");
    Ok(chassisd)
}

/// Starts [`chassisd`] with `args` and `envs` besides, beside `children`; waits until it
/// publishes and the chassis is in command mode.
pub fn launch(
    (robot, name, bus): (RobotKind, &str, &str),
    args: &[String],
    envs: &[(&str, PathBuf)],
    mut children: Children,
    prefix: &str,
    dir: &Path,
) -> anyhow::Result<Started> {
    let mut service = chassisd(robot.name(), name, bus)?;
    service.args(args).envs(envs.iter().cloned());
    let log = dir.join(format!("{name}-chassisd"));
    let spawned = spawn_logged(&mut service, (prefix, "warn"), &log, "chassisd")?;
    let pid = children.push(spawned);
    let service = Service {
        name: name.into(),
        children,
        pid,
        trace: None,
        scheduling: Scheduling::Normal,
    };
    let up = format!(
        "chassisd for {robot} on {bus} did not come up (logs in {})",
        dir.display()
    );
    let mut robot_conn = wait_until(&up, 15, || {
        let mut r = Robot::connect_with_prefix(name, Some(prefix)).ok()?;
        r.wait_state(Duration::from_millis(200)).ok()??;
        Some(r)
    })?;
    // Let the chassis reach command mode.
    let ready_by = now_ns() + 5_000_000_000;
    while now_ns() < ready_by {
        if let Some(s) = robot_conn.wait_state(Duration::from_millis(100))?
            && s.system.control_mode == chassis_client::ControlMode::COMMAND
        {
            break;
        }
    }
    Ok((service, robot_conn))
}

/// The linear speed a transmitted motion frame commands, if the frame is one: the frame as the
/// robot's codec of the registry describes it (`Family::codec`, what `chassis decode`
/// prints), a serial robot's frames found in its byte stream.
pub(crate) struct MotionDecoder {
    codec: BoxedCodec,
    /// The speed of the last motion frame decoded.
    last: Option<f64>,
}

impl MotionDecoder {
    pub(crate) fn new(robot: RobotKind) -> Self {
        let codec = robot.entry().defaults().codec();
        Self { codec, last: None }
    }

    pub(crate) fn linear(&mut self, frame: &BusFrame) -> Option<f64> {
        if frame.direction != FrameDirection::TX {
            return None;
        }
        let decoded: Vec<FrameJson> = if frame.kind == FrameKind::CAN {
            let can = CanFrame::new(frame.can_id, frame.payload()).ok()?;
            vec![self.codec.decode_can(&can).ok()?]
        } else {
            self.codec
                .push_serial(frame.payload())
                .into_iter()
                .filter_map(Result::ok)
                .collect()
        };
        let speed = decoded.iter().rev().find_map(commanded_speed);
        self.last = speed.or(self.last);
        speed
    }
}

/// The forward speed a motion frame commands (`motion_command` of the CAN robots, `velocity` of
/// the serial ones), m/s.
fn commanded_speed(json: &FrameJson) -> Option<f64> {
    match json.get("frame")?.as_str()? {
        "motion_command" | "velocity" => ["linear_mps", "linear_x_mps"]
            .iter()
            .find_map(|key| json.get(*key)?.as_f64()),
        _ => None,
    }
}

/// The state `robot` publishes next (at most a second away).
fn state(robot: &mut Robot) -> anyhow::Result<ChassisState> {
    robot
        .wait_state(Duration::from_secs(1))?
        .context("no state")
}

/// The frames a second the service reads from the chassis over a stretch of a run: the rate at
/// which the chassis' feedback wakes the service's loop.
pub struct FeedbackRate {
    frames: u64,
    at: u64,
}

impl FeedbackRate {
    pub fn start(robot: &mut Robot) -> anyhow::Result<Self> {
        let (frames, at) = (state(robot)?.link.rx_frames, now_ns());
        Ok(Self { frames, at })
    }

    /// Frames read a second since [`FeedbackRate::start`].
    pub fn per_second(&self, robot: &mut Robot) -> anyhow::Result<f64> {
        let s = state(robot)?;
        let seconds = now_ns().saturating_sub(self.at) as f64 / 1e9;
        if seconds <= 0.0 || s.link.rx_frames <= self.frames {
            bail!("the chassis sent no feedback during the run");
        }
        Ok((s.link.rx_frames - self.frames) as f64 / seconds)
    }
}

/// The motion frames the service writes, as the frame tap shows them, decoded.
pub(crate) struct Motion {
    pub tap: chassis_client::FrameTap,
    pub decoder: MotionDecoder,
    /// The tap polled (a busy-polling run), not waited on.
    pub spin: bool,
}

/// A commanded speed that is `speed`.
fn at(speed: f64) -> impl Fn(f64) -> bool {
    move |v| (v - speed).abs() < 1e-6
}

/// A request for `speed` straight ahead, created at `stamp_ns`: a sample's start.
pub(crate) fn stamped(stamp_ns: u64, speed: f32) -> VelocityRequest {
    VelocityRequest {
        stamp_ns,
        ..VelocityRequest::twist(speed, 0.0)
    }
}

impl Motion {
    pub fn open(robot: &mut Robot, kind: RobotKind, spin: bool) -> anyhow::Result<Self> {
        let (tap, decoder) = (robot.frames(2048)?, MotionDecoder::new(kind));
        Ok(Self { tap, decoder, spin })
    }

    /// Drains the tap until a TX motion frame whose commanded speed `accept`s, stamped at or
    /// after `since`, appears; returns its stamp.
    fn wait(
        &mut self,
        accept: impl Fn(f64) -> bool,
        since: u64,
        timeout: Duration,
    ) -> anyhow::Result<Option<u64>> {
        let deadline = since + nanos(timeout);
        loop {
            let mut found = None;
            let decoder = &mut self.decoder;
            let each = |frame: &BusFrame| {
                if found.is_none()
                    && frame.stamp_ns >= since
                    && decoder.linear(frame).is_some_and(&accept)
                {
                    found = Some(frame.stamp_ns);
                }
            };
            if self.spin {
                self.tap.drain(each)?;
            } else {
                self.tap.wait(Duration::from_millis(5), each)?;
            }
            if found.is_some() || now_ns() > deadline {
                return Ok(found);
            }
        }
    }

    /// Drives at 0.25 m/s until a frame commands it (at most 3 s): the first motion releases
    /// TITAN's brake and waits for command mode (and, ramped, reaches the speed).
    pub(crate) fn warm_up(&mut self, teleop: &mut Source) -> anyhow::Result<()> {
        let warm_until = now_ns() + 3_000_000_000;
        let mut ticker = Ticker::new(COMMAND_INTERVAL);
        while now_ns() < warm_until {
            teleop.send(VelocityRequest::twist(0.25, 0.0))?;
            if self.wait(at(0.25), now_ns(), Duration::ZERO)?.is_some() {
                break;
            }
            ticker.wait();
        }
        Ok(())
    }
}

/// How often the command path sends a request (a 250 Hz controller), before [`off_grid`]; the
/// paced baselines use the same period.
pub const COMMAND_INTERVAL: Duration = Duration::from_millis(4);

/// The period the command path and its paced baselines keep: `interval` and 1.7 % more (4 ms:
/// 4.068 ms). A client's timer is not aligned to the chassis': at exactly 4 ms, on the clock the
/// simulated chassis keeps its 2 ms feedback and 20 ms tick on, a run's requests all fell at one
/// phase of the feedback (the pass traces `--dir` keeps, `bn*-passes.txt`, put every request of
/// a run about 0.55 ms after a feedback pass, another run's 0.7 ms), so a run, and its baseline,
/// measured one moment of the chassis' cycle only, drawn anew each run. 1.7 % more sweeps 300
/// requests across a whole 20 ms tick.
pub fn off_grid(interval: Duration) -> Duration {
    interval + interval * 17 / 1000
}

/// `period` in ms, to the µs when it is not whole.
pub fn period_text(period: Duration) -> String {
    let ms = period.as_secs_f64() * 1e3;
    if period.as_micros().is_multiple_of(1000) {
        format!("{ms:.0} ms")
    } else {
        format!("{ms:.3} ms")
    }
}

/// How often the state path's client sends a request, to keep the robot driving so that frames
/// keep changing the state; the state rows' baseline pings at the same period.
pub const STATE_REQUEST_INTERVAL: Duration = Duration::from_millis(50);

/// How often a request is repeated between two command-path samples further apart (the
/// `teleop` source's timeout is 300 ms).
const KEEP_ALIVE: Duration = Duration::from_millis(100);

/// The XBot's manual caps its velocity frames below 10 Hz; with the 8 Hz heartbeat the driver
/// sends one change a second at once (and keeps a slot for a stop), so the command path and the
/// preemption rounds measure one change per 1.1 s: faster, a change rides the next heartbeat
/// and the figure is the manual's rate bound, not the service's latency.
pub const XBOT_COMMAND_INTERVAL: Duration = Duration::from_millis(1100);

/// What the command path measured.
#[derive(Debug, Default)]
pub struct CommandFigures {
    /// Request created → its frame's write returned.
    pub latencies: Latencies,
    /// The service's own part: its loop woke for the request (the mux decision's stamp) → the
    /// frame's write returned.
    pub in_service: Latencies,
    /// Each sample's (request created, frame written) stamps, ns.
    pub samples: Vec<(u64, u64)>,
    /// Requests that produced no frame within the wait.
    pub missed: u64,
}

/// When the mux decided on request `seq` of source `index`: the stamp of the first published
/// decision that reports it (published in the same pass as the frame, before the frame is seen).
fn decision_stamp(robot: &mut Robot, index: usize, seq: u64) -> anyhow::Result<Option<u64>> {
    let mut found = None;
    robot.poll_mux(|m| {
        if found.is_none() && m.sources().get(index).is_some_and(|s| s.last_seq == seq) {
            found = Some(m.stamp_ns);
        }
    })?;
    Ok(found)
}

/// Which frame ends a command-path sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reach {
    /// The frame that commands the requested speed itself ([`BENCH_CONFIG`]: no ramp).
    Exact,
    /// The first frame that moves the commanded speed toward the request (the default
    /// configuration ramps a change over many frames).
    Toward,
}

/// Command-path latencies: `count` requests from `teleop`, a source opened anywhere (through a
/// bridge from another computer too), alternating between two speeds, one every `interval`;
/// the frames (a [`Motion`] of `kind`, polled with `spin`) and the mux are read from `robot`.
pub fn command_path(
    robot: &mut Robot,
    (kind, spin): (RobotKind, bool),
    teleop: &mut Source,
    (count, interval): (u64, Duration),
    reach: Reach,
) -> anyhow::Result<CommandFigures> {
    let motion = &mut Motion::open(robot, kind, spin)?;
    // A new reader gets the latest decision with the service's next publication (10 Hz).
    let source = teleop.name().to_string();
    let teleop_index = robot
        .wait_mux(Duration::from_secs(2))?
        .and_then(|m| m.sources().iter().position(|s| s.name() == source))
        .ok_or_else(|| anyhow::anyhow!("the mux reports no {source} source"))?;
    // Exact on every wire: whole mm/s, whole percent of 5 m/s, exact in f32.
    let speeds = [0.25, 0.5];
    motion.warm_up(teleop)?;
    let mut figures = CommandFigures::default();
    // Between two samples further apart than the source's timeout, the current request is
    // repeated as a controller would: the mux output stays, no frame is sent for it.
    let period = interval.min(KEEP_ALIVE);
    let periods = (interval.as_nanos() / period.as_nanos().max(1)).max(1);
    let mut ticker = Ticker::new(off_grid(period));
    let mut current = 0.25;
    for i in 0..count {
        for k in 1..=periods {
            ticker.wait();
            if k < periods {
                teleop.send(VelocityRequest::twist(current, 0.0))?;
            }
        }
        motion.tap.drain(|f| {
            motion.decoder.linear(f);
        })?;
        robot.poll_mux(|_| {})?;
        // The first sample differs from the warm-up's 0.25: every sample is a change.
        let speed = speeds[usize::from(i % 2 == 0)];
        current = speed as f32;
        let from = motion.decoder.last.unwrap_or(0.25);
        let accept = move |v: f64| match reach {
            Reach::Exact => at(speed)(v),
            Reach::Toward => {
                (v - from).abs() > 1e-9 && (v - from).signum() == (speed - from).signum()
            }
        };
        let stamp = now_ns();
        teleop.send(stamped(stamp, current))?;
        let Some(written) = motion.wait(accept, stamp, Duration::from_millis(500))? else {
            figures.missed += 1;
            continue;
        };
        figures.latencies.record_between(stamp, written);
        figures.samples.push((stamp, written));
        if let Some(decided) = decision_stamp(robot, teleop_index, teleop.last_seq())? {
            figures.in_service.record_between(decided, written);
        }
    }
    teleop.stop()?;
    Ok(figures)
}

/// Records state-path latencies from the samples a reader receives, by the rule every client
/// of the benchmark applies alike (the Rust rows here, `clients/python/bench.py`,
/// `clients/ros2/bench.py`): a sample counts when its stamp (the read time of the frame that
/// made it) is newer than every stamp received before it and it says something the sample
/// before it did not. A sample the service's tick merely refreshed is left out: it carries an
/// older frame's read time, or the read time of a frame that changed nothing but stamps and
/// counters (the service publishes such a frame only with its next tick, so its "latency"
/// would be the tick's wait); so is the first one (the newest sample published before the
/// reader opened). Gaps in `seq` are samples the reader lost: counted as dropped, never
/// silently.
#[derive(Debug, Default)]
pub struct StateRecorder {
    last_seq: Option<u64>,
    newest_stamp: Option<u64>,
    /// What the last sample said ([`StateRecorder::body`]).
    last_body: Option<ChassisState>,
    /// Gaps in `seq` are by design (behind a bridge that forwards the newest sample of each
    /// read of the bus), not samples lost: not counted as dropped.
    pub gaps_allowed: bool,
    pub latencies: Latencies,
    /// The service's own part: the frame read → the sample handed to iceoryx2.
    pub in_service: Latencies,
    /// Each recorded sample's (frame read, handed to iceoryx2, received) stamps, ns.
    pub samples: Vec<(u64, u64, u64)>,
    /// Samples published that this reader never received (gaps in `seq`).
    pub dropped: u64,
    /// Samples received whose stamp was not newer, or that said nothing new (tick refreshes):
    /// not recorded.
    pub refreshes: u64,
}

impl StateRecorder {
    /// A recorder of samples that may skip some (`gaps_allowed`).
    pub fn with_gaps() -> Self {
        Self {
            gaps_allowed: true,
            ..Self::default()
        }
    }

    /// What a sample says, without what every publication changes: its number, its stamps and
    /// the link's counters.
    fn body(state: &ChassisState) -> ChassisState {
        ChassisState {
            seq: 0,
            stamp_ns: 0,
            published_ns: 0,
            group_stamp_ns: Default::default(),
            link: Default::default(),
            ..*state
        }
    }

    pub fn sample(&mut self, state: &ChassisState, received: u64) {
        if let Some(last) = self.last_seq {
            if state.seq <= last {
                return;
            }
            if !self.gaps_allowed {
                self.dropped += state.seq - last - 1;
            }
        }
        self.last_seq = Some(state.seq);
        let body = Self::body(state);
        let said_nothing_new = self
            .last_body
            .replace(body)
            .is_some_and(|last| last.as_bytes() == body.as_bytes());
        let Some(newest) = self.newest_stamp else {
            self.newest_stamp = Some(state.stamp_ns);
            return;
        };
        if state.stamp_ns <= newest || said_nothing_new {
            self.newest_stamp = Some(newest.max(state.stamp_ns));
            self.refreshes += 1;
            return;
        }
        self.newest_stamp = Some(state.stamp_ns);
        self.latencies.record_between(state.stamp_ns, received);
        self.in_service
            .record_between(state.stamp_ns, state.published_ns);
        self.samples
            .push((state.stamp_ns, state.published_ns, received));
    }
}

/// State-path latencies while `driver`, if any, keeps the robot driving (so frames keep changing
/// the state; without one, what changes it is what the robot does anyway), read from `robot` as
/// a client that needs every sample reads them: a lossless [`chassis_client::StateStream`],
/// until `recorder` counted `samples` (at most 120 s); `counted` is given each sample that
/// counted and when it was received.
pub fn state_path(
    robot: &Robot,
    mut driver: Option<&mut Source>,
    recorder: &mut StateRecorder,
    (samples, spin): (u64, bool),
    mut counted: impl FnMut(&ChassisState, u64),
) -> anyhow::Result<()> {
    let stream = robot.state_stream(STATE_BUFFER)?;
    let mut last_request = 0u64;
    let deadline = now_ns() + 120_000_000_000;
    while recorder.latencies.count() < samples && now_ns() < deadline {
        if let Some(driver) = driver.as_mut()
            && Duration::from_nanos(now_ns().saturating_sub(last_request)) > STATE_REQUEST_INTERVAL
        {
            driver.send(VelocityRequest::twist(0.6, 0.3))?;
            last_request = now_ns();
        }
        let mut each = |s: &ChassisState| {
            let (received, before) = (now_ns(), recorder.latencies.count());
            recorder.sample(s, received);
            if recorder.latencies.count() > before {
                counted(s, received);
            }
        };
        if spin {
            stream.drain(&mut each)?;
        } else {
            stream.wait(Duration::from_millis(20), &mut each)?;
        }
    }
    driver.map(Source::stop).transpose()?;
    Ok(())
}

/// Preemption latencies: teleop drives; `safety` publishes a stop → the zero frame written.
/// One round per `interval` at most.
pub fn preemption(
    robot: &mut Robot,
    kind: RobotKind,
    count: u64,
    interval: Duration,
    spin: bool,
) -> anyhow::Result<(Latencies, u64)> {
    let mut motion = Motion::open(robot, kind, spin)?;
    let mut teleop = robot.source("teleop")?;
    let mut safety: Source = robot.source("safety")?;
    let (mut latencies, mut missed) = (Latencies::new(), 0);
    // Rounds and requests at a controller's pace: a client waking the service more than 1,000
    // times a second is read on the service's tick only (and a round takes well under 1 ms).
    let pace = COMMAND_INTERVAL.as_nanos() as u64;
    let mut ticker = Ticker::new(interval.max(COMMAND_INTERVAL));
    let mut sent = 0;
    for _ in 0..count {
        ticker.wait();
        // Drive: teleop wins.
        safety.heartbeat()?;
        let start = now_ns();
        let mut driving = false;
        while !driving && now_ns() - start < 2_000_000_000 {
            if now_ns() - sent >= pace {
                sent = now_ns();
                teleop.send(VelocityRequest::twist(0.5, 0.0))?;
                safety.heartbeat()?;
            }
            driving = (motion.wait(at(0.5), start, Duration::from_millis(20))?).is_some();
        }
        if !driving {
            missed += 1;
            continue;
        }
        // The stop follows a teleop request at once, as a ping follows its wake-up ping in the
        // row's baseline: nothing between the two sends (the frames before are skipped by their
        // stamps; draining them here first keeps the wait short).
        motion.tap.drain(|_| {})?;
        teleop.send(VelocityRequest::twist(0.5, 0.0))?;
        let stamp = now_ns();
        safety.send(stamped(stamp, 0.0))?;
        match motion.wait(at(0.0), stamp, Duration::from_millis(500))? {
            Some(written) => latencies.record_between(stamp, written),
            None => missed += 1,
        }
    }
    safety.heartbeat()?;
    teleop.stop()?;
    Ok((latencies, missed))
}

/// Runs `f` with the calling thread pinned to `cpu` (if any).
pub fn pinned<T>(cpu: Option<usize>, f: impl FnOnce() -> T) -> anyhow::Result<T> {
    if let Some(cpu) = cpu {
        pin_current_thread(cpu)?;
    }
    let out = f();
    unpin_current_thread();
    Ok(out)
}

/// CPU time one thread of a process has used, s: the scheduler's own account (ns precision)
/// where the kernel exposes it, else user + system time in clock ticks (10 ms).
pub fn cpu_seconds_of_thread(pid: u32, tid: u32) -> anyhow::Result<f64> {
    let task = format!("/proc/{pid}/task/{tid}");
    if let Ok(sched) = std::fs::read_to_string(format!("{task}/sched"))
        && let Some(ms) = sched
            .lines()
            .find_map(|l| l.strip_prefix("se.sum_exec_runtime"))
            .and_then(|l| l.split(':').nth(1))
            .and_then(|v| v.trim().parse::<f64>().ok())
    {
        return Ok(ms / 1000.0);
    }
    stat_cpu_seconds(&format!("{task}/stat"))
}

pub(crate) fn stat_cpu_seconds(path: &str) -> anyhow::Result<f64> {
    let stat = std::fs::read_to_string(path)?;
    // Fields after the command name (which may contain spaces) start after the last ')'.
    let (_, rest) = stat.rsplit_once(')').context("malformed stat")?;
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let utime: f64 = fields.get(11).context("no utime")?.parse()?;
    let stime: f64 = fields.get(12).context("no stime")?.parse()?;
    let ticks = nix::unistd::sysconf(nix::unistd::SysconfVar::CLK_TCK);
    let ticks = ticks.ok().flatten().unwrap_or(100) as f64;
    Ok((utime + stime) / ticks)
}

/// Resident memory of a process, MiB.
pub fn rss_mib(pid: u32) -> anyhow::Result<f64> {
    Ok(status_field(pid, "VmRSS:")? / 1024.0)
}

/// A field of `/proc/PID/status` (`VmRSS:`, `Threads:`…), its first number.
pub(crate) fn status_field(pid: u32, field: &str) -> anyhow::Result<f64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status"))?;
    status
        .lines()
        .find_map(|l| l.strip_prefix(field))
        .and_then(|v| v.split_whitespace().next())
        .with_context(|| format!("no {field}"))?
        .parse::<f64>()
        .context(field.to_string())
}

/// Loads the simulated bus to `bitrate`'s capacity (8-byte standard frames, no stuffing:
/// 111 bits each) with the simulator's flood, and measures the service for `seconds`.
pub fn cost_at(
    robot: &mut Robot,
    bus: &'static str,
    (pid, ring): (u32, &Path),
    bitrate: u32,
    seconds: f64,
) -> anyhow::Result<Cost> {
    let capacity = f64::from(bitrate) / 111.0;
    // The feedback the chassis sends anyway.
    let feedback = FeedbackRate::start(robot)?;
    pause(Duration::from_secs(1));
    let flood = (capacity - feedback.per_second(robot)?).max(0.0);
    robot.sim(chassis_client::flood_request(flood), Duration::from_secs(3))?;
    // Settle, then measure.
    robot.wait_state(Duration::from_millis(500))?;
    let start_frames = state(robot)?.link.rx_frames;
    // The service's loop thread (its main thread) only: the simulated chassis flooding the bus
    // runs in a thread of the same process and is not part of the service's cost.
    // The black box's writer (a thread of its own) is the service's cost too, counted apart.
    let recorder = thread_named(pid, "blackbox");
    let recorder_cpu = || recorder.map_or(Ok(0.0), |tid| cpu_seconds_of_thread(pid, tid));
    // What it writes: the ring's files (its segments and the run's header), kept windows aside.
    let ring_bytes = || -> u64 {
        let files = std::fs::read_dir(ring).into_iter().flatten().flatten();
        files
            .filter_map(|f| f.metadata().ok())
            .filter(|m| m.is_file())
            .map(|m| m.len())
            .sum()
    };
    // The loop thread's CPU time, the recorder's, the ring's bytes.
    let usage = || {
        anyhow::Ok((
            cpu_seconds_of_thread(pid, pid)?,
            recorder_cpu()?,
            ring_bytes(),
        ))
    };
    let before = usage()?;
    let start = now_ns();
    let end = start + (seconds * 1e9) as u64;
    while now_ns() < end {
        robot.wait_state(Duration::from_millis(100))?;
    }
    let elapsed = (now_ns() - start) as f64 / 1e9;
    let after = usage()?;
    let recorder_cpu_pct = 100.0 * (after.1 - before.1) / elapsed;
    let recorder_mb_per_min = after.2.saturating_sub(before.2) as f64 / 1e6 * 60.0 / elapsed;
    let frames = state(robot)?.link.rx_frames;
    let rss_mib = rss_mib(pid)?;
    robot.sim(chassis_client::flood_request(0.0), Duration::from_secs(3))?;
    Ok(Cost {
        bus: bus.into(),
        bitrate,
        frames_per_s: (frames - start_frames) as f64 / elapsed,
        cpu_pct: 100.0 * (after.0 - before.0) / elapsed,
        recorder_cpu_pct: recorder.map(|_| recorder_cpu_pct),
        recorder_mb_per_min: recorder.map(|_| recorder_mb_per_min),
        rss_mib,
    })
}

/// The threads of process `pid`: their ids and `/proc` directories.
fn threads(pid: u32) -> impl Iterator<Item = (u32, PathBuf)> {
    let dir = format!("/proc/{pid}/task");
    let tasks = std::fs::read_dir(dir).into_iter().flatten().flatten();
    tasks.filter_map(|t| Some((t.file_name().to_str()?.parse().ok()?, t.path())))
}

/// The thread of process `pid` named `name`, if it has one.
fn thread_named(pid: u32, name: &str) -> Option<u32> {
    threads(pid).find_map(|(tid, path)| {
        let comm = std::fs::read_to_string(path.join("comm")).ok()?;
        (comm.trim_end() == name).then_some(tid)
    })
}

/// Arguments of a subscriber process (a hidden role of this binary).
#[derive(Debug, Clone, clap::Args)]
pub struct SubscribeArgs {
    #[arg(long)]
    pub name: String,
    #[arg(long)]
    pub prefix: String,
    #[arg(long)]
    pub seconds: f64,
}

/// The subscriber role: records state latencies for `seconds`, then prints them on stdout (as a
/// samples file holds them).
pub fn subscribe(args: &SubscribeArgs) -> anyhow::Result<()> {
    let robot = Robot::connect_with_prefix(&args.name, Some(&args.prefix))?;
    // Every sample, as a client that needs them all reads them.
    let stream = robot.state_stream(STATE_BUFFER)?;
    let mut recorder = StateRecorder::default();
    let end = now_ns() + (args.seconds * 1e9) as u64;
    while now_ns() < end {
        stream.wait(Duration::from_millis(20), |s| recorder.sample(s, now_ns()))?;
    }
    println!("{}", serde_json::to_string(&recorder.latencies)?);
    Ok(())
}

/// State fan-out: the state path measured in `subscribers` subscriber processes at once for
/// `seconds` while this process drives the robot; their latencies merged.
pub fn fan_out(
    robot: &mut Robot,
    name: &str,
    prefix: &str,
    subscribers: usize,
    seconds: f64,
) -> anyhow::Result<Latencies> {
    let exe = std::env::current_exe()?;
    let args = format!("role subscribe --name {name} --prefix {prefix} --seconds {seconds}");
    let mut subscriber = Command::new(&exe);
    (subscriber.args(args.split(' '))).stdout(Stdio::piped());
    let children = (0..subscribers)
        .map(|_| subscriber.spawn().context("starting a subscriber"))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let mut teleop = robot.source("teleop")?;
    let end = now_ns() + ((seconds + 0.5) * 1e9) as u64;
    while now_ns() < end {
        teleop.send(VelocityRequest::twist(0.6, 0.3))?;
        robot.wait_state(Duration::from_millis(50))?;
    }
    teleop.stop()?;
    let mut merged = Latencies::new();
    for child in children {
        let out = child.wait_with_output()?;
        if !out.status.success() {
            bail!("a subscriber failed");
        }
        let latencies: Latencies =
            serde_json::from_slice(&out.stdout).context("a subscriber's histogram")?;
        merged.merge(&latencies);
    }
    Ok(merged)
}

/// Writes a candump log of a TITAN driving figure-eights for `seconds` of simulated time: what
/// its bus carries from the chassis (about 650 frames a second).
pub fn record_titan(path: &Path, seconds: u64) -> anyhow::Result<u64> {
    let profile = TitanProfile::default();
    let start = Timestamp::from_millis(1);
    let driver = titan::TitanDriver::new(profile.clone(), DriverConfig::default(), start);
    let firmware = titan::TitanSim::new(profile, start);
    let mut pair = Pair::new(driver, firmware, start);
    pair.record = true;
    let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
    let mut frames = 0u64;
    for second in 0..seconds {
        let turn = if second % 20 < 10 { 0.3 } else { -0.3 };
        pair.set_command(Velocity::twist(1.0, turn)?);
        pair.run_for(Duration::from_secs(1));
        for record in pair.log() {
            if let (Direction::FromChassis, WireItem::Can(frame)) = (record.direction, &record.item)
            {
                let line = CandumpLine {
                    time_s: record.at.as_nanos() as f64 / 1e9,
                    interface: "can0".into(),
                    frame: *frame,
                };
                writeln!(out, "{}", line.format())?;
                frames += 1;
            }
        }
        pair.clear_log();
    }
    out.flush()?;
    Ok(frames)
}

/// Throughput: `file` (of `frames` frames) replayed into the service as fast as it drains it —
/// read, decode, publish — its loop pinned to CPU 0 (the replay thread runs on the other).
/// `recorder`: with the black box recording (its ring of 64 MiB) or off.
pub fn replay(
    file: &Path,
    frames: u64,
    recorder: bool,
    prefix: &str,
    dir: &Path,
) -> anyhow::Result<Throughput> {
    let name = format!("tp{}", unique());
    let mut command = chassisd("titan", &name, &format!("replay:{}@max", file.display()))?;
    let mib = if recorder { 64 } else { 0 };
    let config = dir.join(format!("{name}.toml"));
    let state = dir.join(format!("{name}-state"));
    let text = format!(
        "[service]\nblackbox_mib = {mib}\nstate_dir = {:?}\n",
        state.display()
    );
    std::fs::write(&config, text).context("the replay's configuration")?;
    command.args(["--cpu", "0", "--config"]).arg(&config);
    let log = dir.join(&name);
    let (mut child, what) = (Children::default(), "chassisd on the replay bus");
    let pid = child.push(spawn_logged(&mut command, (prefix, "warn"), &log, what)?);
    let connect = || Robot::connect_with_prefix(&name, Some(prefix)).ok();
    let mut robot = wait_until(&format!("{what} did not come up"), 20, connect)?;
    // From the first frame counted to the last: the loop thread's CPU over that span.
    let mut first: Option<(u64, u64, f64)> = None;
    let mut last = (0u64, 0u64, 0.0f64);
    let end = now_ns() + 120_000_000_000;
    while now_ns() < end {
        if let Some(state) = robot.wait_state(Duration::from_millis(20))? {
            let cpu = cpu_seconds_of_thread(pid, pid)?;
            let sample = (now_ns(), state.link.rx_frames, cpu);
            if first.is_none() && state.link.rx_frames > 0 {
                first = Some(sample);
            }
            last = sample;
            if state.link.rx_frames >= frames {
                break;
            }
        }
    }
    drop(child);
    let (t0, f0, c0) = first.context("no frame was replayed")?;
    let seconds = (last.0 - t0) as f64 / 1e9;
    let counted = last.1 - f0;
    let cpu_seconds = last.2 - c0;
    Ok(Throughput {
        recorder,
        frames: counted,
        seconds,
        frames_per_s: counted as f64 / seconds.max(1e-9),
        service_cpu_pct: 100.0 * cpu_seconds / seconds.max(1e-9),
        frames_per_cpu_s: counted as f64 / cpu_seconds.max(1e-9),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use chassis_client::Velocity;
    use chassis_protocols::{Direction, Timestamp, WireItem};

    #[test]
    fn the_command_period_sweeps_the_chassis_feedback_and_tick() {
        let period = off_grid(COMMAND_INTERVAL);
        assert_eq!(period_text(period), "4.068 ms");
        assert_eq!(period_text(COMMAND_INTERVAL), "4 ms");
        // 300 requests drift through a whole 20 ms tick against a 2 ms feedback grid, and no
        // two requests in a row fall at one phase of it.
        let step = (period - COMMAND_INTERVAL).as_nanos();
        assert!(300 * step >= 20_000_000, "{period:?}");
        assert!(step > 0 && step < 2_000_000, "{period:?}");
    }

    /// The latency runs' file asks for real-time mode for a loop that blocks and not for the
    /// polling one; the other runs' never; chassisd's defaults are an empty file.
    #[test]
    fn a_loop_that_blocks_runs_in_realtime_mode_and_the_spin_loop_does_not() {
        for mode in [LoopMode::Event, LoopMode::Hybrid] {
            let text = config_text(ServiceConfig::BenchRealtime, mode);
            assert!(
                text.starts_with("[service]\nrealtime = 80\n") && text.ends_with(BENCH_CONFIG),
                "{mode:?}: {text}"
            );
            assert_eq!(config_text(ServiceConfig::Bench, mode), BENCH_CONFIG);
        }
        assert_eq!(
            config_text(ServiceConfig::BenchRealtime, LoopMode::Spin),
            BENCH_CONFIG
        );
        for mode in [LoopMode::Event, LoopMode::Spin] {
            assert_eq!(config_text(ServiceConfig::Default, mode), "");
        }
    }

    /// A thread of this process at SCHED_FIFO is found with its priority; none while every
    /// thread has normal scheduling. Where the system refuses SCHED_FIFO (no CAP_SYS_NICE), the
    /// thread stays normal and none is found.
    #[test]
    fn a_thread_at_sched_fifo_is_found_with_its_priority() {
        let pid = std::process::id();
        assert_eq!(fifo_priority(pid), None);
        let (entered, found) = std::thread::spawn(move || {
            let entered = crate::placement::enter_realtime(7).is_ok();
            (entered, fifo_priority(pid))
        })
        .join()
        .unwrap();
        assert_eq!(found, entered.then_some(7));
        // SAFETY: munlockall takes no arguments; the test's pages need not stay locked.
        unsafe { libc::munlockall() };
    }

    #[test]
    fn chassisd_is_started_under_its_prefix_with_both_outputs_logged() {
        let dir = crate::tests::scratch("spawn");
        let mut command = Command::new("sh");
        command.args(["-c", "echo \"$CHASSIS_IPC_PREFIX\"; echo \"$RUST_LOG\" >&2"]);
        let log = dir.join("bn1-chassisd");
        let level = ("bench_3", crate::zenoh::ZENOH_LOG);
        let mut child = spawn_logged(&mut command, level, &log, "a stand-in").unwrap();
        assert!(child.wait().unwrap().success());
        let read = |file: &str| std::fs::read_to_string(dir.join(file)).unwrap();
        assert_eq!(read("bn1-chassisd.log"), "bench_3\n");
        assert_eq!(read("bn1-chassisd-err.log"), "warn,zenoh=error\n");
        let mut missing = Command::new("/nonexistent/chassisd");
        let err = spawn_logged(&mut missing, level, &log, "chassisd sim").unwrap_err();
        assert_eq!(err.to_string(), "starting chassisd sim");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Every robot's driver asked for 0.3 m/s against its simulated firmware: the command path
    /// finds that speed in the motion frames it wrote, as the tap shows them (a serial robot's
    /// frames cut into chunks), by the robot's codec of the registry.
    #[test]
    fn every_robots_motion_frames_tell_the_speed_they_command() {
        for kind in RobotKind::ALL {
            let entry = kind.entry();
            let profile = entry.defaults();
            let mut pair = entry.simulated_pair(&profile, Timestamp::from_millis(1_000));
            pair.run_for(Duration::from_secs(2));
            pair.record = true;
            pair.set_command(Velocity::twist(0.3, 0.0).unwrap());
            pair.run_for(Duration::from_millis(500));
            let mut decoder = MotionDecoder::new(kind);
            let mut speeds = Vec::new();
            for record in pair.log() {
                let mut frame = BusFrame {
                    direction: match record.direction {
                        Direction::ToChassis => FrameDirection::TX,
                        Direction::FromChassis => FrameDirection::RX,
                    },
                    ..BusFrame::default()
                };
                let chunks: Vec<Vec<u8>> = match &record.item {
                    WireItem::Can(can) => {
                        frame.kind = FrameKind::CAN;
                        frame.can_id = can.id();
                        vec![can.data().to_vec()]
                    }
                    WireItem::Bytes(bytes) => {
                        frame.kind = FrameKind::SERIAL;
                        bytes.chunks(3).map(<[u8]>::to_vec).collect()
                    }
                };
                for chunk in chunks {
                    frame.set_payload(&chunk);
                    speeds.extend(decoder.linear(&frame));
                }
            }
            assert!(
                speeds.iter().any(|v| (v - 0.3).abs() < 1e-6),
                "{kind}: speeds on the wire {speeds:?}"
            );
        }
    }
}

#[cfg(test)]
mod state_recorder_tests {
    use super::*;

    /// A sample whose frame, read at `stamp_ns`, moved the robot there (each frame says
    /// something new).
    fn sample(seq: u64, stamp_ns: u64) -> ChassisState {
        let mut s = ChassisState {
            seq,
            stamp_ns,
            published_ns: stamp_ns + 10_000,
            ..ChassisState::default()
        };
        s.odometry.x_m = stamp_ns as f64 * 1e-9;
        s
    }

    #[test]
    fn the_state_rule_leaves_out_the_first_sample_and_tick_refreshes_and_counts_gaps() {
        let mut r = StateRecorder::default();
        // The sample published before the reader opened: only sets the stamp.
        r.sample(&sample(10, 1_000_000), 1_500_000);
        // A new frame: 50 µs.
        r.sample(&sample(11, 2_000_000), 2_050_000);
        // The tick's refresh of the same frame's state: left out.
        r.sample(&sample(12, 2_000_000), 3_000_000);
        // The same sample twice (a repeat): nothing.
        r.sample(&sample(12, 2_000_000), 3_000_000);
        // The tick's refresh after a frame that changed nothing but stamps and counters (read at
        // 2.5 ms, published with the tick at 22 ms): left out, not a 19.5 ms latency.
        let mut unchanged = sample(13, 2_500_000);
        unchanged.odometry = sample(0, 2_000_000).odometry;
        unchanged.link.rx_frames = 7;
        r.sample(&unchanged, 22_000_000);
        // Two samples lost, then a new frame: 20 µs.
        r.sample(&sample(16, 4_000_000), 4_020_000);
        assert_eq!(r.latencies.count(), 2);
        assert_eq!((r.refreshes, r.dropped), (2, 2));
        let s = r.latencies.summary();
        assert!((s.max_us - 50.0).abs() < 0.1, "{s:?}");
        assert_eq!(r.in_service.count(), 2);

        let mut bridged = StateRecorder::with_gaps();
        bridged.sample(&sample(1, 1_000), 2_000);
        bridged.sample(&sample(5, 9_000), 10_000);
        assert_eq!((bridged.latencies.count(), bridged.dropped), (1, 0));
    }
}
