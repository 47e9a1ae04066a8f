//! The simulated chassis at the far end of a bus: a robot's firmware driven by the real clock.
//!
//! [`SimHandle::spawn`] runs a firmware in its own thread on any [`Bus`]: the chassis side of a
//! socket pair for the service's default `sim` bus, or a pty, an slcan pty, a serial port or a
//! CAN interface for `chassisd sim`. Faults reach it through [`SimHandle::inject`].
// The simulator's runner drives its firmware by the clock: it is a loop that owns the clock.
#![allow(clippy::disallowed_methods)]

use std::os::fd::{AsFd, AsRawFd};
use std::os::unix::net::UnixDatagram;
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::Duration;

use chassis_bus::clock;
use chassis_bus::{Bus, BusError};
use chassis_interfaces::{ControlStatus, SimKind, SimRequest, SimTruthPage};
use chassis_protocols::RobotKind;
use chassis_protocols::{Firmware, Injection, SimTruth};
use nix::poll::{PollFd, PollFlags};
use nix::sys::time::TimeSpec;
use tracing::{debug, warn};

pub use chassis_protocols::BoxedFirmware;

/// Why a [`SimRequest`] asks for nothing the simulator can do.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BadSimRequest {
    #[error("{0} must be a finite, non-negative number")]
    NotFinite(&'static str),
    #[error("a runaway speed must be a number of at most {max} m/s either way")]
    BadRunaway { max: f64 },
    #[error("a gain must be a number of at most {max} either way")]
    BadGain { max: f64 },
    #[error("unknown simulator request kind {0}")]
    UnknownKind(u8),
}

/// Why an injection did not reach the simulated chassis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SimError {
    #[error("the simulated chassis has stopped")]
    Stopped,
    #[error("the simulated chassis did not answer")]
    NoAnswer,
}

/// Carries out `request` on the simulated chassis `sim`: the status and message to answer with.
/// Without a chassis the answer is `absent` (why there is none).
pub fn carry_out(
    request: &SimRequest,
    sim: Option<&SimHandle>,
    absent: (u8, &str),
) -> (u8, String) {
    if request.kind == SimKind::TRUTH {
        return match sim.map(SimHandle::truth) {
            None => (absent.0, absent.1.to_string()),
            Some(Ok(t)) => (ControlStatus::OK, truth_text(&t, request.index)),
            Some(Err(reason)) => (ControlStatus::REFUSED, reason.to_string()),
        };
    }
    match (injection_of(request), sim) {
        (Err(reason), _) => (ControlStatus::INVALID, reason.to_string()),
        (Ok(_), None) => (absent.0, absent.1.to_string()),
        (Ok(injection), Some(sim)) => {
            let name = injection.name();
            match sim.inject(injection) {
                Ok(true) => (ControlStatus::OK, format!("{name} injected")),
                Ok(false) => (
                    ControlStatus::UNSUPPORTED,
                    format!("the simulated {} has no {name}", sim.robot()),
                ),
                Err(reason) => (ControlStatus::REFUSED, reason.to_string()),
            }
        }
    }
}

/// The answer to [`SimKind::TRUTH`], page `page` ([`SimTruthPage`]; an unknown page is the
/// motion's). The injected page fits a `ControlResponse` for counters below 10^13 (a flood of
/// 100,000 frames/s needs three years to get there).
pub fn truth_text(t: &SimTruth, page: u8) -> String {
    if page == SimTruthPage::INJECTED {
        let i = t.injected;
        return format!(
            "garbage_frames={} garbage_bytes={} bad_checksums={} flood_frames={}",
            i.garbage_frames, i.garbage_bytes, i.bad_checksum_frames, i.flood_frames
        );
    }
    format!(
        "x_m={:.4} y_m={:.4} yaw_rad={:.4} linear_mps={:.4} angular_radps={:.4} commands={} \
         rejected={}",
        t.x_m,
        t.y_m,
        t.yaw_rad,
        t.linear_mps,
        t.angular_radps,
        t.commands_received,
        t.decode_errors + t.bad_checksums_received
    )
}

/// The injection a [`SimRequest`] asks for.
pub fn injection_of(request: &SimRequest) -> Result<Injection, BadSimRequest> {
    let value = request.value;
    let finite = |what: &'static str| {
        if value.is_finite() && value >= 0.0 {
            Ok(value)
        } else {
            Err(BadSimRequest::NotFinite(what))
        }
    };
    let on = request.flag != 0;
    Ok(match request.kind {
        SimKind::MOTOR_DRIVER_LOSS => Injection::MotorDriverLoss {
            motor: request.index,
            lost: on,
        },
        SimKind::BATTERY => Injection::Battery {
            soc_pct: finite("state of charge")?.min(100.0),
        },
        SimKind::BUMPER => Injection::Bumper(on),
        SimKind::RC_TAKEOVER => Injection::RcTakeover(on),
        SimKind::REBOOT => Injection::Reboot,
        SimKind::SILENCE => {
            Injection::Silence(Duration::from_secs_f64(finite("silence")?.min(3600.0)))
        }
        SimKind::GARBAGE => {
            // A fixed pseudo-random pattern: reproducible, and never a valid frame header run.
            let n = finite("garbage length")?.min(65_536.0) as usize;
            Injection::Garbage(
                (0..n)
                    .map(|i| (i as u8).wrapping_mul(37).wrapping_add(11))
                    .collect(),
            )
        }
        SimKind::BAD_CHECKSUMS => {
            Injection::BadChecksums(finite("frame count")?.min(f64::from(u32::MAX)) as u32)
        }
        SimKind::OBSTACLE_AHEAD => Injection::ObstacleAhead(on.then_some(finite("range")?)),
        SimKind::OBSTACLE_BEHIND => Injection::ObstacleBehind(on.then_some(finite("range")?)),
        SimKind::ESTOP_SWITCH => Injection::EStop(on),
        SimKind::RUNAWAY => {
            let max = chassis_protocols::firmware::MAX_RUNAWAY_MPS;
            if on && !(value.is_finite() && value.abs() <= max) {
                return Err(BadSimRequest::BadRunaway { max });
            }
            Injection::Runaway(on.then_some(value))
        }
        SimKind::GAIN => {
            let max = chassis_protocols::firmware::MAX_GAIN;
            if on && !(value.is_finite() && value.abs() <= max) {
                return Err(BadSimRequest::BadGain { max });
            }
            Injection::Gain(on.then_some(value))
        }
        SimKind::FLOOD => Injection::Flood {
            frames_per_s: finite("frame rate")?.min(1e6) as u32,
        },
        other => return Err(BadSimRequest::UnknownKind(other)),
    })
}

/// How the simulator's thread ended: the firmware comes back, with the bus error if the bus was
/// lost (the chassis keeps its state across a reconnection).
struct Ended {
    firmware: BoxedFirmware,
    lost: Option<BusError>,
}

enum SimCommand {
    Inject(Injection, mpsc::Sender<bool>),
    Truth(mpsc::Sender<SimTruth>),
    Stop,
}

/// A running simulated chassis.
#[derive(Debug)]
pub struct SimHandle {
    commands: mpsc::Sender<SimCommandBox>,
    doorbell: UnixDatagram,
    thread: Option<JoinHandle<Ended>>,
    /// The simulator thread's id, to place it on CPUs.
    tid: nix::unistd::Pid,
    robot: RobotKind,
}

/// `SimCommand` with a `Debug` face for the handle.
struct SimCommandBox(SimCommand);

impl std::fmt::Debug for SimCommandBox {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.0 {
            SimCommand::Inject(i, _) => write!(f, "Inject({})", i.name()),
            SimCommand::Truth(_) => f.write_str("Truth"),
            SimCommand::Stop => f.write_str("Stop"),
        }
    }
}

impl SimHandle {
    /// Runs `firmware` on `bus` in a new thread.
    pub fn spawn(firmware: BoxedFirmware, bus: Bus) -> std::io::Result<Self> {
        Self::spawn_on(firmware, bus, &[])
    }

    /// Like [`SimHandle::spawn`], with the thread confined to `cpus` (all CPUs when empty), so a
    /// pinned, spinning service loop does not starve its simulated chassis. The thread runs with
    /// normal scheduling whoever spawns it (a loop in real-time mode that reopens its bus).
    pub fn spawn_on(firmware: BoxedFirmware, bus: Bus, cpus: &[usize]) -> std::io::Result<Self> {
        let (doorbell, wake) = UnixDatagram::pair()?;
        doorbell.set_nonblocking(true)?;
        wake.set_nonblocking(true)?;
        let (commands, inbox) = mpsc::channel();
        let robot = firmware.robot();
        let (tell_tid, tid) = mpsc::sync_channel(1);
        let thread = std::thread::Builder::new()
            .name(format!("sim-{}", robot.name()))
            .spawn(move || {
                // The spawner waits for it; a spawner that is gone needs no answer.
                tell_tid.send(nix::unistd::gettid()).ok();
                normal_scheduling();
                let (mut firmware, mut bus) = (firmware, bus);
                let lost = drive(&mut firmware, &mut bus, &inbox, &wake).err();
                Ended { firmware, lost }
            })?;
        let tid = tid
            .recv()
            .map_err(|_| std::io::Error::other("the simulator thread ended at its start"))?;
        let handle = Self {
            commands,
            doorbell,
            thread: Some(thread),
            tid,
            robot,
        };
        // From here, not from the thread: a thread that confines itself can do so after its
        // spawner moved it (a loop that took it onto its CPU).
        if !cpus.is_empty() {
            handle.confine_to(cpus);
        }
        Ok(handle)
    }

    pub fn robot(&self) -> RobotKind {
        self.robot
    }

    /// Moves the simulator's thread onto `cpus` (all CPUs when empty).
    pub fn confine_to(&self, cpus: &[usize]) {
        if let Err(err) = crate::realtime::confine(self.tid, cpus) {
            warn!("simulated chassis: cannot move to CPUs {cpus:?}: {err}");
        }
    }

    /// Injects a fault; returns whether this robot has such a thing. Waits at most 200 ms for the
    /// simulator's answer.
    pub fn inject(&self, injection: Injection) -> Result<bool, SimError> {
        let (reply, answer) = mpsc::channel();
        self.ask(SimCommand::Inject(injection, reply), &answer)
    }

    /// What the simulated chassis really does. Waits at most 200 ms for the simulator.
    pub fn truth(&self) -> Result<SimTruth, SimError> {
        let (reply, answer) = mpsc::channel();
        self.ask(SimCommand::Truth(reply), &answer)
    }

    /// Sends `command` and waits at most 200 ms for its `answer`.
    fn ask<T>(&self, command: SimCommand, answer: &mpsc::Receiver<T>) -> Result<T, SimError> {
        self.commands
            .send(SimCommandBox(command))
            .map_err(|_| SimError::Stopped)?;
        // The doorbell only wakes the thread early: a full or closed socket means it is awake
        // already or has ended, and the answer (or its absence) below says which.
        self.doorbell.send(&[1]).ok();
        answer
            .recv_timeout(Duration::from_millis(200))
            .map_err(|_| SimError::NoAnswer)
    }

    /// True while the simulator thread runs.
    pub fn is_running(&self) -> bool {
        self.thread.as_ref().is_some_and(|t| !t.is_finished())
    }

    /// Stops the simulator and returns how it ended.
    pub fn stop(mut self) -> Result<(), BusError> {
        self.shutdown()
    }

    fn shutdown(&mut self) -> Result<(), BusError> {
        // Best effort: a thread that has ended already has dropped its inbox and its end of the
        // doorbell, and the join below reports how it ended either way.
        self.commands.send(SimCommandBox(SimCommand::Stop)).ok();
        self.doorbell.send(&[0]).ok();
        match self.thread.take().map(JoinHandle::join) {
            Some(Ok(Ended {
                lost: Some(err), ..
            })) => Err(err),
            Some(Ok(Ended { lost: None, .. })) | None => Ok(()),
            Some(Err(_)) => Err(BusError::Protocol {
                name: "sim".into(),
                reason: "the simulator thread panicked".into(),
            }),
        }
    }

    /// After the thread ended on a lost bus: the firmware, to run again on a reopened bus.
    pub fn recover(mut self) -> Option<(BoxedFirmware, BusError)> {
        if !self.thread.as_ref().is_some_and(|t| t.is_finished()) {
            return None;
        }
        match self.thread.take().map(JoinHandle::join) {
            Some(Ok(Ended {
                firmware,
                lost: Some(err),
            })) => Some((firmware, err)),
            _ => None,
        }
    }
}

impl Drop for SimHandle {
    fn drop(&mut self) {
        if self.thread.is_some()
            && let Err(err) = self.shutdown()
        {
            warn!("simulated chassis ended with: {err}");
        }
    }
}

/// The calling thread with normal scheduling (SCHED_OTHER), whatever it inherited.
fn normal_scheduling() {
    let param = libc::sched_param { sched_priority: 0 };
    // SAFETY: pid 0 is the calling thread; `param` is a valid sched_param for SCHED_OTHER.
    if unsafe { libc::sched_setscheduler(0, libc::SCHED_OTHER, &param) } != 0 {
        warn!(
            "simulated chassis: cannot take normal scheduling: {}",
            std::io::Error::last_os_error()
        );
    }
}

/// The simulator's event loop: bus readiness, injections and the firmware's own deadlines.
fn drive(
    firmware: &mut BoxedFirmware,
    bus: &mut Bus,
    inbox: &mpsc::Receiver<SimCommandBox>,
    wake: &UnixDatagram,
) -> Result<(), BusError> {
    let mut dropped: u64 = 0;
    loop {
        let now = clock::now();
        while let Ok(SimCommandBox(command)) = inbox.try_recv() {
            match command {
                SimCommand::Stop => return Ok(()),
                SimCommand::Inject(injection, reply) => {
                    debug!(injection = injection.name(), "injecting");
                    // The asker waits 200 ms at most: an answer nobody waits for any more is
                    // dropped on purpose (the injection took effect all the same).
                    reply.send(firmware.inject(now, injection)).ok();
                }
                // Likewise: an answer nobody waits for any more is dropped on purpose.
                SimCommand::Truth(reply) => {
                    reply.send(firmware.truth()).ok();
                }
            }
        }
        let mut scratch = [0u8; 64];
        while wake.recv(&mut scratch).is_ok() {}

        let received = bus.receive(|rx| firmware.handle_rx(clock::now(), rx));
        if let Err(err) = received {
            warn!("simulated chassis lost its bus: {err}");
            return Err(err);
        }
        let now = clock::now();
        if firmware.poll_timeout().is_some_and(|t| t <= now) {
            firmware.handle_timeout(now);
        }
        while let Some(item) = firmware.poll_transmit(now) {
            match bus.transmit(&item) {
                Ok(()) => {}
                Err(err) if err.is_disconnect() => {
                    warn!("simulated chassis lost its bus: {err}");
                    return Err(err);
                }
                Err(err) => {
                    dropped += 1;
                    if dropped.is_power_of_two() {
                        warn!(dropped, "simulated chassis dropped a frame: {err}");
                    }
                }
            }
        }
        if let Err(err) = bus.flush()
            && err.is_disconnect()
        {
            warn!("simulated chassis lost its bus: {err}");
            return Err(err);
        }

        let timeout = firmware
            .poll_timeout()
            .map(|t| t.saturating_since(clock::now()));
        wait(bus, wake, timeout);
    }
}

/// Waits until the bus or the doorbell is readable, or `timeout` passes.
fn wait(bus: &Bus, wake: &UnixDatagram, timeout: Option<Duration>) {
    // The bus descriptor stays open for the whole call: `bus` is borrowed.
    let bus_fd = unsafe { std::os::fd::BorrowedFd::borrow_raw(bus.raw_fd()) };
    let mut fds = [
        PollFd::new(bus_fd, PollFlags::POLLIN),
        PollFd::new(wake.as_fd(), PollFlags::POLLIN),
    ];
    let spec = timeout.map(TimeSpec::from_duration);
    if let Err(err) = nix::poll::ppoll(&mut fds, spec, None)
        && err != nix::errno::Errno::EINTR
    {
        warn!(fd = wake.as_raw_fd(), "simulator wait failed: {err}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chassis_bus::datagram::PairCan;

    /// Waits (test only) until `condition` holds, at most 5 s.
    #[allow(clippy::disallowed_methods)]
    fn eventually(mut condition: impl FnMut() -> bool) -> bool {
        for _ in 0..500 {
            if condition() {
                return true;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        false
    }

    #[test]
    fn a_simulator_that_loses_its_bus_hands_back_its_firmware_to_run_again() {
        let profile = chassis_protocols::RobotKind::Titan.entry().defaults();
        let firmware = profile.firmware(clock::now());
        let (service_end, chassis_end) = PairCan::pair("sim").unwrap();
        let sim = SimHandle::spawn(firmware, Bus::Can(Box::new(chassis_end))).unwrap();
        let mut service_end = Bus::Can(Box::new(service_end));
        assert!(
            eventually(|| service_end.receive(|_| {}).unwrap() > 0),
            "no feedback"
        );
        drop(service_end);
        assert!(eventually(|| !sim.is_running()), "the loss went unnoticed");
        let (firmware, err) = sim.recover().expect("the firmware comes back");
        assert!(err.is_disconnect(), "{err}");
        let (service_end, chassis_end) = PairCan::pair("sim").unwrap();
        let sim = SimHandle::spawn(firmware, Bus::Can(Box::new(chassis_end))).unwrap();
        let mut service_end = Bus::Can(Box::new(service_end));
        assert!(
            eventually(|| service_end.receive(|_| {}).unwrap() > 0),
            "no feedback after"
        );
        assert!(sim.stop().is_ok());
    }

    #[test]
    fn the_truth_answers_each_page_within_a_control_response() {
        let truth = SimTruth {
            injected: chassis_protocols::InjectedCounts {
                garbage_frames: 9_999_999_999_999,
                garbage_bytes: 9_999_999_999_999,
                bad_checksum_frames: 9_999_999_999_999,
                flood_frames: 9_999_999_999_999,
            },
            commands_received: 7,
            ..SimTruth::default()
        };
        let injected = truth_text(&truth, SimTruthPage::INJECTED);
        assert!(
            injected.len() <= chassis_interfaces::ControlResponse::MESSAGE_LEN,
            "{} bytes: {injected}",
            injected.len()
        );
        assert!(injected.starts_with("garbage_frames=9999999999999 garbage_bytes="));
        let motion = truth_text(&truth, SimTruthPage::MOTION);
        assert!(motion.starts_with("x_m=0.0000 ") && motion.contains(" commands=7 "));
    }

    #[test]
    fn every_sim_request_kind_maps_to_an_injection() {
        // The truth is a question, not an injection.
        for (kind, name) in SimKind::NAMES
            .into_iter()
            .filter(|(k, _)| *k != SimKind::TRUTH)
        {
            let request = SimRequest {
                kind,
                flag: 1,
                index: 1,
                value: 0.5,
                ..SimRequest::default()
            };
            let injection = injection_of(&request).unwrap();
            assert_eq!(injection.name(), name);
        }
        assert!(
            injection_of(&SimRequest {
                kind: 99,
                ..SimRequest::default()
            })
            .is_err()
        );
        let nan = SimRequest {
            kind: SimKind::BATTERY,
            value: f64::NAN,
            ..SimRequest::default()
        };
        assert!(injection_of(&nan).is_err());
        let reverse = SimRequest {
            kind: SimKind::RUNAWAY,
            flag: 1,
            value: -1.0,
            ..SimRequest::default()
        };
        assert_eq!(injection_of(&reverse), Ok(Injection::Runaway(Some(-1.0))));
        let absurd = SimRequest {
            value: 1e6,
            ..reverse
        };
        assert!(injection_of(&absurd).is_err());
        let clear = SimRequest { flag: 0, ..absurd };
        assert_eq!(injection_of(&clear), Ok(Injection::Runaway(None)));
        let backwards = SimRequest {
            kind: SimKind::GAIN,
            ..reverse
        };
        assert_eq!(injection_of(&backwards), Ok(Injection::Gain(Some(-1.0))));
        let too_much = SimRequest {
            value: 2.5,
            ..backwards
        };
        assert_eq!(
            injection_of(&too_much),
            Err(BadSimRequest::BadGain { max: 2.0 })
        );
        let clear = SimRequest {
            flag: 0,
            ..too_much
        };
        assert_eq!(injection_of(&clear), Ok(Injection::Gain(None)));
    }
}
