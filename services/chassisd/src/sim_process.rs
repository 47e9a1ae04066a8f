//! `chassisd sim`: the simulated firmware as its own process on a real bus.
//!
//! The chassis side of a pty (`pty:LINK`, XBot), of an slcan adapter on a pty
//! (`slcan-pty:LINK`, CAN robots), of a serial port, or of a CAN interface. Faults are injected
//! through `chassis/<name>/sim`, as with the service's embedded simulator.
// `chassisd sim`'s loop owns the clock, as the service's shell does.
#![allow(clippy::disallowed_methods)]

use std::path::Path;
use std::time::Duration;

use chassis_bus::clock;
use chassis_bus::{Bus, BusError, BusSpec, serial, slcan, socketcan};
use chassis_interfaces::{ControlResponse, ControlStatus};
use chassis_ipc::{SIM, ServiceKind, service_name};
use chassis_protocols::slcan::ADAPTER_BAUD;
use chassis_protocols::{BoxedFirmware, Firmware, Timestamp};
use chassisd_config::Config;
use iceoryx2::prelude::*;
use iceoryx2::waitset::{
    WaitSetAttachmentError, WaitSetCreateError, WaitSetRunError, WaitSetRunResult,
};
use thiserror::Error;
use tracing::{error, info, warn};

use crate::ipc::{IpcError, iceoryx_config, open_desk};
use crate::setup::serial_baud;
use crate::sim::{SimHandle, carry_out};

/// Why the simulated chassis stopped (or never started).
#[derive(Debug, Error)]
pub enum SimProcessError {
    /// The bus could not be opened, or ended in a failure when stopping.
    #[error(transparent)]
    Bus(#[from] BusError),
    /// The simulator's thread could not be started.
    #[error(transparent)]
    Spawn(#[from] std::io::Error),
    /// The iceoryx2 setup (prefix, fault desk) failed.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// Another process answers this robot's fault injections.
    #[error("another simulated chassis already answers chassis/{name}/sim; pick another --name")]
    AlreadyServed { name: String },
    #[error("wait set: {0}")]
    WaitSetCreate(#[source] WaitSetCreateError),
    #[error("wait set: {0}")]
    WaitSetAttach(#[source] WaitSetAttachmentError),
    #[error("wait set: {0}")]
    WaitSetRun(#[source] WaitSetRunError),
    /// The simulator's thread ended without losing its bus.
    #[error("the simulated chassis stopped")]
    Stopped,
}

/// Opens the chassis side of `spec`.
pub fn open_chassis_side(spec: &BusSpec, config: &Config) -> Result<Bus, BusError> {
    let robot = config.robot;
    let wrong = |reason: String| BusError::Open {
        name: spec.to_string(),
        reason,
    };
    Ok(match spec {
        BusSpec::Sim => return Err(wrong("`chassisd sim` needs a real bus, not sim".into())),
        BusSpec::Can { iface } if robot.is_can() => {
            Bus::Can(Box::new(socketcan::SocketCan::open(iface)?))
        }
        BusSpec::SlcanPty { link } if robot.is_can() => Bus::Can(Box::new(
            slcan::SlcanAdapter::new(serial::PtyLink::create(Path::new(link))?.into_bus()),
        )),
        BusSpec::Slcan { path, baud: b } if robot.is_can() => Bus::Can(Box::new(
            slcan::SlcanAdapter::new(serial::SerialBus::open(path, b.unwrap_or(ADAPTER_BAUD))?),
        )),
        BusSpec::Pty { link } if !robot.is_can() => Bus::Bytes(Box::new(
            serial::PtyLink::create(Path::new(link))?.into_bus(),
        )),
        BusSpec::Serial { path, baud: b } if !robot.is_can() => Bus::Bytes(Box::new(
            serial::SerialBus::open(path, serial_baud(spec, *b, &config.profile)?)?,
        )),
        _ if robot.is_can() => {
            return Err(wrong(format!(
                "{robot} is a CAN robot: use can:IFACE, slcan:PATH or slcan-pty:LINK"
            )));
        }
        _ => {
            return Err(wrong(format!(
                "{robot} speaks RS232: use serial:PATH or pty:LINK"
            )));
        }
    })
}

/// The simulated chassis: running on its bus, or waiting for the bus to come back with the same
/// firmware, which keeps running meanwhile ([`run_unplugged`]).
enum Simulator {
    Running(SimHandle),
    Down {
        firmware: BoxedFirmware,
        retry_at: Timestamp,
        backoff: Duration,
    },
}

impl Simulator {
    /// How long the loop may wait: a firmware without its bus is still due at its deadlines.
    fn wait(&self) -> Duration {
        match self {
            Simulator::Running(_) => CHECK_EVERY,
            Simulator::Down { firmware, .. } => (firmware.poll_timeout())
                .map_or(CHECK_EVERY, |t| t.saturating_since(clock::now()))
                .min(CHECK_EVERY),
        }
    }
}

/// How often the loop looks at the simulator's bus at least.
const CHECK_EVERY: Duration = Duration::from_millis(100);
const FIRST_RETRY: Duration = Duration::from_millis(100);
const LAST_RETRY: Duration = Duration::from_secs(2);

/// A chassis whose cable is out keeps running, as a real one does: its deadlines pass at `now`
/// (the command timeout that stops it among them) and what it sends is lost. Frozen instead, it
/// would come back with the speed it had when the bus went, and drive on with nobody asking.
fn run_unplugged(firmware: &mut BoxedFirmware, now: Timestamp) {
    if firmware.poll_timeout().is_some_and(|t| t <= now) {
        firmware.handle_timeout(now);
    }
    while firmware.poll_transmit(now).is_some() {}
}

/// Runs the simulated chassis until SIGINT/SIGTERM. A lost bus is reopened with backoff.
pub fn run(config: &Config) -> Result<(), SimProcessError> {
    let bus = open_chassis_side(&config.bus, config)?;
    let sim_name = service_name(&config.name, ServiceKind::Sim);
    info!(
        robot = config.robot.name(),
        bus = bus.name(),
        "simulated chassis up (faults: {sim_name})"
    );
    let firmware = config.profile.firmware(clock::now());
    let mut simulator = Simulator::Running(SimHandle::spawn(firmware, bus)?);

    let node = chassis_ipc::node(
        None,
        &iceoryx_config()?,
        SignalHandlingMode::HandleTerminationRequests,
    )
    .map_err(IpcError::from)?;
    let desk = open_desk(&node, &SIM, &sim_name).map_err(|e| match e {
        IpcError::AlreadyServed { .. } => SimProcessError::AlreadyServed {
            name: config.name.clone(),
        },
        other => other.into(),
    })?;
    let waitset = WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
        .create::<ipc::Service>()
        .map_err(SimProcessError::WaitSetCreate)?;
    // Attached for as long as the loop runs.
    let _attached = waitset
        .attach_notification(&desk.listener)
        .map_err(SimProcessError::WaitSetAttach)?;
    let mut notify_failures: u64 = 0;
    loop {
        let result = waitset.wait_and_process_once_with_timeout(
            |_| CallbackProgression::Continue,
            simulator.wait(),
        );
        match result {
            Ok(WaitSetRunResult::TerminationRequest) => {
                info!("stopping the simulated chassis");
                return match simulator {
                    Simulator::Running(sim) => sim.stop().map_err(SimProcessError::from),
                    Simulator::Down { .. } => Ok(()),
                };
            }
            // A signal interrupted the wait: SIGTERM and SIGINT come back as a termination
            // request from the next wait; a SIGCONT after a stop or a debugger is no reason to
            // stop the chassis.
            Ok(WaitSetRunResult::Interrupt) => continue,
            Ok(_) => {}
            Err(e) => return Err(SimProcessError::WaitSetRun(e)),
        }
        simulator = keep_running(simulator, config)?;
        // The notifications only wake the wait set; every request is read below whether or not
        // they could be drained.
        desk.listener.try_wait(|_| {}).ok();
        while let Ok(Some(active)) = desk.server.receive() {
            let request = *active.payload();
            let running = match &simulator {
                Simulator::Running(sim) => Some(sim),
                Simulator::Down { .. } => None,
            };
            let (status, message) = carry_out(
                &request,
                running,
                (
                    ControlStatus::REFUSED,
                    "the simulated chassis has lost its bus",
                ),
            );
            info!(status = ControlStatus::name(status), "{message}");
            if let Err(e) = active.send_copy(ControlResponse::new(request.seq, status, &message)) {
                warn!("cannot answer: {e}");
            }
            // The answer is in place even when the wake-up fails: the asker finds it when it
            // looks again. Counted, and logged at the 1st, 2nd, 4th, … failure.
            if let Err(e) = desk.notifier.notify() {
                notify_failures += 1;
                if notify_failures.is_power_of_two() {
                    warn!(failures = notify_failures, "cannot wake the asker: {e}");
                }
            }
        }
    }
}

/// Notices a lost bus and reopens it with backoff, keeping the same firmware.
fn keep_running(simulator: Simulator, config: &Config) -> Result<Simulator, SimProcessError> {
    match simulator {
        Simulator::Running(sim) if !sim.is_running() => match sim.recover() {
            Some((firmware, err)) => {
                error!("the simulated chassis lost its bus ({err}); reopening it");
                Ok(Simulator::Down {
                    firmware,
                    retry_at: clock::now() + FIRST_RETRY,
                    backoff: FIRST_RETRY,
                })
            }
            None => Err(SimProcessError::Stopped),
        },
        Simulator::Down {
            mut firmware,
            retry_at,
            backoff,
        } => {
            let now = clock::now();
            run_unplugged(&mut firmware, now);
            if now < retry_at {
                return Ok(Simulator::Down {
                    firmware,
                    retry_at,
                    backoff,
                });
            }
            reopen(firmware, backoff, config)
        }
        other => Ok(other),
    }
}

/// Opens the bus again for `firmware`, or waits twice as long (at most [`LAST_RETRY`]) for the
/// next try.
fn reopen(
    firmware: BoxedFirmware,
    backoff: Duration,
    config: &Config,
) -> Result<Simulator, SimProcessError> {
    match open_chassis_side(&config.bus, config) {
        Ok(bus) => {
            info!(bus = bus.name(), "the simulated chassis has its bus back");
            Ok(Simulator::Running(SimHandle::spawn(firmware, bus)?))
        }
        Err(err) => {
            let backoff = (backoff * 2).min(LAST_RETRY);
            tracing::debug!("reopening the bus: {err}");
            Ok(Simulator::Down {
                firmware,
                retry_at: clock::now() + backoff,
                backoff,
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chassis_interfaces::Velocity;
    use chassis_protocols::RobotKind;

    #[test]
    fn a_chassis_whose_bus_is_out_keeps_running_and_its_command_timeout_stops_it() {
        let entry = RobotKind::Titan.entry();
        let mut pair = entry.simulated_pair(&entry.defaults(), Timestamp::ZERO);
        pair.run_for(Duration::from_millis(100));
        pair.set_command(Velocity::twist(0.3, 0.0).unwrap());
        pair.run_for(Duration::from_secs(2));
        let speed = pair.firmware.truth().linear_mps;
        assert!(speed > 0.25, "not driving before the bus went: {speed} m/s");
        // The bus is out for 3 s; the loop calls the firmware every 10 ms.
        let (mut now, end) = (pair.now(), pair.now() + Duration::from_secs(3));
        let mut firmware = pair.firmware;
        while now < end {
            now += Duration::from_millis(10);
            run_unplugged(&mut firmware, now);
        }
        let truth = firmware.truth();
        assert!(
            truth.linear_mps.abs() < 0.01,
            "still at {} m/s after 3 s without a command",
            truth.linear_mps
        );
    }
}
