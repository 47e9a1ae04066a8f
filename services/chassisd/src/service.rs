//! The service's shell: the event loop around the [`Engine`].
//!
//! One thread owns the iceoryx2 ports, the bus and GPS descriptors, the simulated chassis and the
//! clock. An iceoryx2 `WaitSet` waits on the bus (through the receive-moderation gate), the GPS
//! port, the listeners of every source, of `control` and of `sim`, with a timeout at the engine's
//! next deadline. Each wake-up runs one pass: the engine's [`Engine::run_pass`], which owns the
//! order, on the shell's ports, devices and clock (`service/pass.rs`, the shell's
//! [`crate::engine::PassIo`]). Every decision is the engine's; this module only moves bytes,
//! reads the clock and keeps the wait set.
//! Single-threaded means decode, mux and transmit never lock each other and ports never cross
//! threads.
// The shell owns the clock: it stamps what it reads and writes, and hands the time to the engine.
#![allow(clippy::disallowed_methods)]

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use chassis_bus::clock;
use chassis_bus::{Bus, BusSpec};
use chassis_interfaces::{ControlRequest, ControlResponse};
use chassis_protocols::Timestamp;
use chassis_protocols::snapshot::SnapshotError;
use chassisd_config::mux::MuxConfigError;
use chassisd_config::{Config, LoopMode};
use iceoryx2::active_request::ActiveRequest;
use iceoryx2::prelude::*;
use iceoryx2::waitset::{
    WaitSetAttachmentError, WaitSetCreateError, WaitSetRunError, WaitSetRunResult,
};
use iceoryx2_bb_posix::file_descriptor::{FileDescriptor, FileDescriptorBased};
use iceoryx2_bb_posix::file_descriptor_set::SynchronousMultiplexing;
use nix::sys::signal::{SaFlags, SigAction, SigHandler, SigSet, Signal, sigaction};
use tracing::{info, info_span, warn};

use crate::blackbox::ring::{Bound, Tape};
use crate::blackbox::{self, Event, Taped};
use crate::engine::{Engine, EngineConfig, ListenerChange, PassIo, Ticket, Wake};
use crate::ipc::{IpcError, Ports};
use crate::lockfile::{Clocks, LockFile};
use crate::mux::Mux;
use crate::notify::Notifier;
use crate::realtime::{
    PinError, enter_realtime, is_fifo, pin_to_cpu, sim_cpus, spin_throttle_warning,
};
use crate::rx_moderation::RxGate;
use crate::setup::{Devices, Hardware, driver_for_config};
use crate::sim::SimHandle;
use stall::LoopStall;

mod pass;
mod stall;
pub(crate) mod trace;

/// Why the service stopped.
#[derive(Debug, thiserror::Error)]
pub enum ServiceError {
    #[error(transparent)]
    Ipc(#[from] IpcError),
    #[error("[mux]: {0}")]
    Mux(#[from] MuxConfigError),
    #[error(transparent)]
    Pin(#[from] PinError),
    #[error("bus gate: {0}")]
    Gate(#[from] nix::Error),
    #[error("iceoryx2 wait set: {0}")]
    WaitSetCreate(#[from] WaitSetCreateError),
    #[error("iceoryx2 wait set: {0}")]
    WaitSetAttach(#[from] WaitSetAttachmentError),
    #[error("iceoryx2 wait set: {0}")]
    WaitSetRun(#[from] WaitSetRunError),
}

/// A descriptor the wait set can watch (it does not own the descriptor).
#[derive(Debug)]
struct FdAttachment(FileDescriptor);

impl FdAttachment {
    fn new(raw: i32) -> Option<Self> {
        FileDescriptor::non_owning_new(raw).map(Self)
    }
}

impl FileDescriptorBased for FdAttachment {
    fn file_descriptor(&self) -> &FileDescriptor {
        &self.0
    }
}

impl SynchronousMultiplexing for FdAttachment {}

type PendingControl = ActiveRequest<ipc::Service, ControlRequest, (), ControlResponse, ()>;

/// How a pass ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Next {
    Continue,
    /// A descriptor was lost or (re)opened: rebuild the wait set.
    Rewire,
}

impl std::ops::BitOrAssign for Next {
    fn bitor_assign(&mut self, rhs: Self) {
        if rhs == Next::Rewire {
            *self = Next::Rewire;
        }
    }
}

/// The shell's belongings: ports, descriptors, the requests waiting for an answer.
struct Shell<D> {
    devices: D,
    bus: Option<Bus>,
    sim: Option<SimHandle>,
    gps: Option<Bus>,
    /// Buses (and GPS ports) that failed: their descriptors stay open until the wait set that
    /// watches them is gone.
    retired: Vec<Bus>,
    pending: HashMap<Ticket, PendingControl>,
    next_ticket: Ticket,
    /// A device was lost or (re)opened in this pass: the wait set must be rebuilt.
    next: Next,
    loop_mode: LoopMode,
    spin: Duration,
    /// When something last woke the loop (hybrid mode keeps polling for a while after it).
    last_activity: Timestamp,
    /// Where the held locks outlive the process.
    lock_file: LockFile,
    /// systemd's notification socket, when started by a `Type=notify` unit.
    notifier: Option<Notifier>,
    /// The test hook that stalls the loop (`stall.rs`); `None` unless a test armed it.
    loop_stall: Option<LoopStall>,
    /// The stamps inside each pass, when `CHASSIS_PASS_TRACE` asks for them.
    trace: Option<trace::PassTrace>,
    /// The black box, when it records.
    tape: Option<Tape>,
    /// Passes the black box dropped, as of the pass under way (published in the state).
    recorder_dropped: u64,
}

/// A call of the shell that runs on its ports and devices.
#[derive(Debug, Clone, Copy)]
enum Step {
    Start(Timestamp),
    Pass(Wake),
    Stop(Timestamp),
}

impl Step {
    fn run(self, engine: &mut Engine, io: &mut impl PassIo) {
        match self {
            Step::Start(now) => engine.start(io, now),
            Step::Pass(wake) => engine.run_pass(io, wake),
            Step::Stop(now) => engine.stop(io, now),
        }
    }

    fn event(self) -> Event {
        match self {
            Step::Start(now) => Event::Began {
                now: now.as_nanos(),
            },
            Step::Pass(wake) => blackbox::pass(wake),
            Step::Stop(now) => Event::Stop {
                now: now.as_nanos(),
            },
        }
    }
}

/// SIGUSR1 asked the black box to keep the window around now.
static KEEP_ASKED: AtomicBool = AtomicBool::new(false);

extern "C" fn keep_asked(_: libc::c_int) {
    KEEP_ASKED.store(true, Ordering::Relaxed);
}

/// The black box, recording into the state directory, with SIGUSR1 keeping its window.
fn black_box(config: &Config, now: Timestamp) -> Option<Tape> {
    if config.blackbox_mib == 0 {
        return None;
    }
    let text = config
        .to_toml()
        .map_err(|e| warn!("black box off: the configuration as text: {e}"))
        .ok()?;
    let bound = Bound {
        bytes: config.blackbox_mib << 20,
        age: Duration::from_secs_f64(config.blackbox_minutes * 60.0),
    };
    let mut tape = Tape::start(&config.state_dir, bound, config.blackbox_kept)
        .map_err(|e| warn!("black box off: {}: {e}", config.state_dir.display()))
        .ok()?;
    let action = SigAction::new(
        SigHandler::Handler(keep_asked),
        SaFlags::SA_RESTART,
        SigSet::empty(),
    );
    // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
    if let Err(e) = unsafe { sigaction(Signal::SIGUSR1, &action) } {
        warn!("black box: SIGUSR1 keeps nothing: {e}");
    }
    tape.events.push(Event::Start {
        version: env!("CARGO_PKG_VERSION").into(),
        config: text,
        now: now.as_nanos(),
        unix_ns: clock::unix_ns(),
    });
    info!(
        dir = %config.state_dir.join("blackbox").display(),
        mib = config.blackbox_mib,
        minutes = config.blackbox_minutes,
        "black box recording"
    );
    Some(tape)
}

/// Opens the service's ports. A predecessor killed while it was creating one of them leaves that
/// service hanging in creation until iceoryx2's creation timeout has passed: such a failure is
/// tried again for a few seconds before it is reported (another chassisd serving the robot is
/// reported at once).
fn open_ports(name: &str, sources: &[String], with_sim: bool) -> Result<Ports, IpcError> {
    const PATIENCE: Duration = Duration::from_secs(4);
    const PAUSE: Duration = Duration::from_millis(100);
    let deadline = clock::now() + PATIENCE;
    loop {
        crate::ipc::remove_unsized_segments();
        crate::ipc::remove_dead_nodes();
        match Ports::open(name, sources, with_sim) {
            Err(IpcError::Contract(err)) if clock::now() < deadline => {
                warn!("{err}; trying again");
                crate::ipc::remove_abandoned_creations();
                // The loop has not started: nothing else waits on this thread.
                #[allow(clippy::disallowed_methods)]
                std::thread::sleep(PAUSE);
            }
            result => return result,
        }
    }
}

/// Runs the service on the devices its configuration names until SIGINT or SIGTERM. Returns
/// after commanding zero.
pub fn run(config: Config) -> Result<(), ServiceError> {
    let devices = Hardware::new(&config);
    serve(config, devices)
}

/// Runs the service on `devices` until SIGINT or SIGTERM.
pub fn serve(config: Config, mut devices: impl Devices) -> Result<(), ServiceError> {
    let span = info_span!(
        "chassisd",
        robot = config.robot.name(),
        name = config.name.as_str()
    );
    let _guard = span.enter();
    if config.no_safety_monitor {
        warn!(
            "--no-safety-monitor: the robot moves without a safety monitor; no required source \
             guards it"
        );
    }
    if let Some(cpu) = config.cpu {
        pin_to_cpu(cpu)?;
        info!(cpu, "loop pinned");
    }
    if config.loop_mode != LoopMode::Event {
        info!(mode = ?config.loop_mode, spin_us = config.spin_us, "loop polls instead of blocking");
    }
    let sources: Vec<String> = config.mux.sources.iter().map(|s| s.name.clone()).collect();
    let ports = open_ports(&config.name, &sources, config.bus == BusSpec::Sim)?;
    let now = clock::now();
    let driver = driver_for_config(&config, now);
    let mut engine = Engine::new(
        EngineConfig::from_config(&config),
        driver,
        Mux::new(&config.mux)?,
        now,
    );
    let mut tape = black_box(&config, now);
    let mut note = |event: Event| {
        if let Some(tape) = &mut tape {
            tape.events.push(event);
        }
    };
    // The locks held before a restart hold again before anything is decided.
    let lock_file = LockFile::new(&config.state_dir, &config.name);
    match lock_file.load(clocks(now)) {
        Ok(held) => {
            note(blackbox::restored(&held));
            engine.restore_locks(now, &held);
        }
        Err(err) => {
            let aside = lock_file
                .set_aside()
                .map_or_else(String::new, |p| format!(" (set aside as {})", p.display()));
            let reason = format!("{err}{aside}");
            note(Event::RestoreFailed {
                reason: reason.clone(),
            });
            engine.restore_failed(now, &reason);
        }
    }
    let (bus, sim) = match devices.open_bus(now) {
        Ok((bus, sim)) => (Some(bus), sim),
        Err(err) => {
            note(Event::BusLost {
                now: now.as_nanos(),
                reason: err.to_string(),
            });
            engine.handle_bus_lost(now, &err);
            (None, None)
        }
    };
    info!(
        bus = config.bus.to_string(),
        sources = sources.join(","),
        "serving chassis/{}/",
        config.name
    );
    let mut shell = Shell {
        devices,
        bus,
        sim,
        gps: None,
        retired: Vec::new(),
        pending: HashMap::new(),
        next_ticket: 0,
        next: Next::Continue,
        loop_mode: config.loop_mode,
        spin: Duration::from_micros(config.spin_us),
        last_activity: now,
        lock_file,
        notifier: Notifier::from_env(),
        loop_stall: LoopStall::from_env(),
        trace: trace::PassTrace::from_env(),
        tape,
        recorder_dropped: 0,
    };
    shell.step(&ports, &mut engine, Step::Start(now));
    if let Some(notifier) = &mut shell.notifier {
        notifier.ready(&engine.mux_status());
        if let Some(every) = notifier.ping_every() {
            info!("systemd watchdog: pinging every {every:?}");
        }
    }
    // Threads started before this (the simulated chassis) keep normal scheduling.
    if let Some(priority) = config.realtime {
        realtime_mode(priority, config.loop_mode);
        // A loop that got SCHED_FIFO takes its simulated chassis onto its CPU (`sim_cpus`).
        if let Some(sim) = &shell.sim {
            sim.confine_to(&sim_cpus(&config, is_fifo()));
        }
    }
    shell.run(&ports, &mut engine)
}

impl<D: Devices> Shell<D> {
    /// The loop: one wait set per bus session (the bus descriptor changes when it is reopened).
    fn run(&mut self, ports: &Ports, engine: &mut Engine) -> Result<(), ServiceError> {
        let mut gate = RxGate::new()?;
        loop {
            // The previous session's wait set is gone: failed buses can close now, and the new
            // one watches the descriptors as they are.
            self.retired.clear();
            self.next = Next::Continue;
            let waitset = WaitSetBuilder::new()
                .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
                .create::<ipc::Service>()?;
            let gps_fd = self
                .gps
                .as_ref()
                .and_then(|b| FdAttachment::new(b.raw_fd()));
            // The bus is watched through the gate receive moderation closes while it pauses.
            gate.watch(self.bus.as_ref().map(Bus::raw_fd))?;
            let gate_fd = self
                .bus
                .as_ref()
                .and_then(|_| FdAttachment::new(gate.raw_fd()));
            let bus_guard = gate_fd
                .as_ref()
                .map(|fd| waitset.attach_notification(fd))
                .transpose()?;
            let gps_guard = gps_fd
                .as_ref()
                .map(|fd| waitset.attach_notification(fd))
                .transpose()?;
            let mut source_guards = ports
                .sources
                .iter()
                .map(|inlet| waitset.attach_notification(&inlet.listener).map(Some))
                .collect::<Result<Vec<_>, _>>()?;
            self.note(Event::ResetWakeups);
            engine.reset_wakeups();
            let control_guard = waitset.attach_notification(&ports.control.listener)?;
            let sim_guard = ports
                .sim
                .as_ref()
                .map(|desk| waitset.attach_notification(&desk.listener))
                .transpose()?;

            loop {
                let now = clock::now();
                if let Some(trace) = &mut self.trace {
                    trace.waiting_since = now.as_nanos();
                }
                let timeout = self.wait_time(engine, now);
                let mut wake = Wake {
                    polled: timeout.is_zero(),
                    ..Wake::default()
                };
                let result = waitset.wait_and_process_once_with_timeout(
                    |id| {
                        wake.bus |= bus_guard.as_ref().is_some_and(|g| id.has_event_from(g));
                        wake.gps |= gps_guard.as_ref().is_some_and(|g| id.has_event_from(g));
                        for (index, guard) in source_guards.iter().enumerate() {
                            if guard.as_ref().is_some_and(|g| id.has_event_from(g)) {
                                wake.sources |= 1 << index;
                            }
                        }
                        wake.control |= id.has_event_from(&control_guard);
                        wake.sim |= sim_guard.as_ref().is_some_and(|g| id.has_event_from(g));
                        CallbackProgression::Continue
                    },
                    timeout,
                )?;
                match result {
                    WaitSetRunResult::TerminationRequest => {
                        self.shutdown(ports, engine);
                        return Ok(());
                    }
                    // A signal interrupted the wait: SIGTERM / SIGINT are reported as a
                    // termination request by the next wait; anything else (a SIGCONT after a
                    // SIGSTOP, a debugger) is no reason to stop.
                    WaitSetRunResult::Interrupt => continue,
                    _ => {}
                }
                // A moderation pause that ended: read what queued meanwhile. Only the wait
                // watches the gate: it opens after the pass, if the read did not pause again
                // (while the bus stays saturated it stays closed, no system call per poll).
                if !gate.is_open() && !self.is_rx_paused(engine) {
                    wake.bus = true;
                }
                let next = self.pass(ports, engine, wake);
                if let Some(notifier) = &mut self.notifier {
                    notifier.pass(clock::now(), &engine.mux_status());
                }
                if let Some(stall) = &self.loop_stall {
                    stall.check();
                }
                if next == Next::Rewire {
                    break;
                }
                // Close the gate for a pause that began, open it when the pause is over.
                let paused = self.is_rx_paused(engine);
                if gate.is_open() == paused {
                    set_gate(&mut gate, !paused);
                }
                // A source that wakes the loop too often is read on the tick only, until the next.
                let now = clock::now();
                self.note(Event::Wakeups {
                    now: now.as_nanos(),
                    fired: wake.sources,
                });
                let asked = [
                    (KEEP_ASKED.swap(false, Ordering::Relaxed), "SIGUSR1"),
                    (engine.take_keep(), "chassis control keep"),
                ];
                for (_, why) in asked.into_iter().filter(|(asked, _)| *asked) {
                    if let Some(tape) = &mut self.tape {
                        tape.keep(why);
                    }
                }
                if let Some(tape) = &mut self.tape {
                    tape.send();
                }
                for change in engine.spend_wakeups(now, wake.sources) {
                    match change {
                        ListenerChange::Detach(index) => {
                            if let Some(guard) = source_guards.get_mut(index) {
                                guard.take();
                            }
                        }
                        ListenerChange::Attach(index) => {
                            if let (Some(guard), Some(inlet)) =
                                (source_guards.get_mut(index), ports.sources.get(index))
                            {
                                *guard = Some(waitset.attach_notification(&inlet.listener)?);
                            }
                        }
                    }
                }
                self.snapshot(engine);
            }
        }
    }

    /// Runs `step` on the shell's ports and devices, noted by the black box when it records.
    fn step(&mut self, ports: &Ports, engine: &mut Engine, step: Step) {
        let mut tape = self.tape.take();
        if let Some(tape) = &tape {
            self.recorder_dropped = tape.unrecorded();
        }
        let mut io = self.io(ports);
        match &mut tape {
            Some(tape) => {
                tape.events.push(step.event());
                let mut taped = Taped::new(&mut io, &mut tape.events, &mut tape.deferred);
                step.run(engine, &mut taped);
                taped.finish();
                tape.send();
            }
            None => step.run(engine, &mut io),
        }
        self.tape = tape;
    }

    /// The engine's state, between two passes, when the black box began a segment of its ring.
    fn snapshot(&mut self, engine: &Engine) {
        let Some(tape) = &mut self.tape else {
            return;
        };
        if !tape.snapshot_due() {
            return;
        }
        match engine.snapshot() {
            Ok(state) => tape.events.push(Event::Snapshot {
                state: blackbox::Bytes(state),
            }),
            Err(SnapshotError::Sending) => tape.snapshot_later(),
            Err(e) => warn!("black box: the engine's state is not kept: {e}"),
        }
    }

    fn note(&mut self, event: Event) {
        if let Some(tape) = &mut self.tape {
            tape.events.push(event);
        }
    }

    fn is_rx_paused(&mut self, engine: &mut Engine) -> bool {
        let now = clock::now();
        self.note(Event::RxPaused {
            now: now.as_nanos(),
        });
        engine.is_rx_paused(now)
    }

    /// How long the loop waits, by its mode: event-driven blocks until the engine's next
    /// deadline, spin never blocks, hybrid polls for `spin_us` after each activity and then
    /// blocks.
    fn wait_time(&self, engine: &Engine, now: Timestamp) -> Duration {
        let deadline = self
            .notifier
            .as_ref()
            .and_then(Notifier::deadline)
            .map_or(engine.poll_timeout(), |ping| {
                ping.min(engine.poll_timeout())
            });
        let until_deadline = deadline.saturating_since(now);
        match self.loop_mode {
            LoopMode::Event => until_deadline,
            LoopMode::Spin => Duration::ZERO,
            LoopMode::Hybrid if now.saturating_since(self.last_activity) < self.spin => {
                Duration::ZERO
            }
            LoopMode::Hybrid => until_deadline,
        }
    }

    fn shutdown(&mut self, ports: &Ports, engine: &mut Engine) {
        if let Some(notifier) = &mut self.notifier {
            notifier.stopping();
        }
        self.step(ports, engine, Step::Stop(clock::now()));
        if let Some(tape) = self.tape.take() {
            tape.finish();
        }
        if let Some(trace) = &self.trace {
            match trace.write_out() {
                Ok(()) => info!(file = %trace.path().display(), "pass trace written"),
                Err(e) => warn!(file = %trace.path().display(), "pass trace not written: {e}"),
            }
        }
    }
}

/// Real-time mode for the loop's thread; what the system refuses is a warning, and the loop
/// runs with normal scheduling.
fn realtime_mode(priority: u8, loop_mode: LoopMode) {
    let (granted, refusals) = enter_realtime(priority);
    for refusal in &refusals {
        warn!("--realtime: {refusal}");
    }
    if granted.fifo {
        info!(
            priority,
            memory_locked = granted.locked,
            "real-time mode: the loop runs at SCHED_FIFO"
        );
        if loop_mode == LoopMode::Spin {
            let read = |name| std::fs::read_to_string(format!("/proc/sys/kernel/{name}"));
            if let (Ok(runtime), Ok(period)) =
                (read("sched_rt_runtime_us"), read("sched_rt_period_us"))
                && let Some(warning) = spin_throttle_warning(&runtime, &period)
            {
                warn!("{warning}");
            }
        }
    } else {
        warn!("--realtime: the loop runs with normal scheduling");
    }
}

/// Both clocks at `now` (the wall clock read right after).
fn clocks(now: Timestamp) -> Clocks {
    Clocks {
        monotonic: now,
        unix_ns: clock::unix_ns(),
    }
}

fn set_gate(gate: &mut RxGate, open: bool) {
    if let Err(e) = gate.set_open(open) {
        warn!("bus gate: {e}");
    }
}
