//! `chassisd sim`: the simulated firmware as its own process on a real bus.
//!
//! The chassis side of a pty (`pty:LINK`, XBot), of an slcan adapter on a pty
//! (`slcan-pty:LINK`, CAN robots), of a serial port, or of a CAN interface. Faults are injected
//! through `chassis/<name>/sim`, as with the service's embedded simulator.

use std::path::Path;
use std::time::Duration;

use chassis_interfaces::{ControlResponse, ControlStatus};
use chassis_ipc::{SIM, ServiceKind, service_name};
use chassis_protocols::Profile;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use tracing::{error, info, warn};

use crate::bus::{Bus, BusError, BusSpec, serial, slcan, socketcan};
use crate::clock;
use crate::config::Config;
use crate::ipc::{IpcError, iceoryx_config, open_desk};
use crate::sim::{SimHandle, firmware_for, injection_of};

/// Opens the chassis side of `spec`.
pub fn open_chassis_side(spec: &BusSpec, config: &Config) -> Result<Bus, BusError> {
    let robot = config.robot;
    let baud = |b: Option<u32>| {
        b.unwrap_or(match &config.profile {
            Profile::Xbot(p) => p.baud,
            _ => 115_200,
        })
    };
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
            slcan::SlcanAdapter::new(serial::SerialBus::open(path, baud(*b))?),
        )),
        BusSpec::Pty { link } if !robot.is_can() => Bus::Bytes(Box::new(
            serial::PtyLink::create(Path::new(link))?.into_bus(),
        )),
        BusSpec::Serial { path, baud: b } if !robot.is_can() => {
            Bus::Bytes(Box::new(serial::SerialBus::open(path, baud(*b))?))
        }
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
/// firmware (a real chassis keeps running while its cable is out).
enum Chassis {
    Running(SimHandle),
    Down {
        firmware: crate::sim::BoxedFirmware,
        retry_at: chassis_protocols::Timestamp,
        backoff: Duration,
    },
}

const FIRST_RETRY: Duration = Duration::from_millis(100);
const LAST_RETRY: Duration = Duration::from_secs(2);

/// Runs the simulated chassis until SIGINT/SIGTERM. A lost bus is reopened with backoff.
pub fn run(config: &Config) -> Result<(), String> {
    let bus = open_chassis_side(&config.bus, config).map_err(|e| e.to_string())?;
    let sim_name = service_name(&config.name, ServiceKind::Sim);
    info!(
        robot = config.robot.name(),
        bus = bus.name(),
        "simulated chassis up (faults: {sim_name})"
    );
    let firmware = firmware_for(&config.profile, clock::now());
    let mut chassis = Chassis::Running(SimHandle::spawn(firmware, bus).map_err(|e| e.to_string())?);

    let node = chassis_ipc::node(
        None,
        &iceoryx_config().map_err(|e| e.to_string())?,
        SignalHandlingMode::HandleTerminationRequests,
    )
    .map_err(|e| e.to_string())?;
    let desk = open_desk(&node, &SIM, &sim_name).map_err(|e| match e {
        IpcError::AlreadyServed { .. } => {
            format!("another simulated chassis already answers {sim_name}; pick another --name")
        }
        other => other.to_string(),
    })?;
    let waitset = WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
        .create::<ipc::Service>()
        .map_err(|e| format!("wait set: {e}"))?;
    let guard = waitset
        .attach_notification(&desk.listener)
        .map_err(|e| format!("wait set: {e}"))?;
    loop {
        let result = waitset.wait_and_process_once_with_timeout(
            |_| CallbackProgression::Continue,
            Duration::from_millis(100),
        );
        let _ = &guard;
        match result {
            Ok(WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt) => {
                info!("stopping the simulated chassis");
                return match chassis {
                    Chassis::Running(sim) => sim.stop().map_err(|e| e.to_string()),
                    Chassis::Down { .. } => Ok(()),
                };
            }
            Ok(_) => {}
            Err(e) => return Err(format!("wait set: {e}")),
        }
        chassis = keep_running(chassis, config)?;
        if let Err(e) = desk.listener.try_wait(|_| {}) {
            warn!("taking the requests' notifications: {e}");
        }
        while let Ok(Some(active)) = desk.server.receive() {
            let request = *active.payload();
            let (status, message) = match (injection_of(&request), &chassis) {
                (Err(reason), _) => (ControlStatus::INVALID, reason),
                (Ok(_), Chassis::Down { .. }) => (
                    ControlStatus::REFUSED,
                    "the simulated chassis has lost its bus".to_string(),
                ),
                (Ok(injection), Chassis::Running(sim)) => {
                    let name = injection.name();
                    match sim.inject(injection) {
                        Ok(true) => (ControlStatus::OK, format!("{name} injected")),
                        Ok(false) => (
                            ControlStatus::UNSUPPORTED,
                            format!("the simulated {} has no {name}", sim.robot()),
                        ),
                        Err(reason) => (ControlStatus::REFUSED, reason),
                    }
                }
            };
            info!(status = ControlStatus::name(status), "{message}");
            if let Err(e) = active.send_copy(ControlResponse::new(request.seq, status, &message)) {
                warn!("cannot answer: {e}");
            }
            if let Err(e) = desk.notifier.notify() {
                warn!("cannot tell the client its answer is ready: {e}");
            }
        }
    }
}

/// Notices a lost bus and reopens it with backoff, keeping the same firmware.
fn keep_running(chassis: Chassis, config: &Config) -> Result<Chassis, String> {
    match chassis {
        Chassis::Running(sim) if !sim.is_running() => match sim.recover() {
            Some((firmware, err)) => {
                error!("the simulated chassis lost its bus ({err}); reopening it");
                Ok(Chassis::Down {
                    firmware,
                    retry_at: clock::now() + FIRST_RETRY,
                    backoff: FIRST_RETRY,
                })
            }
            None => Err("the simulated chassis stopped".into()),
        },
        Chassis::Down {
            firmware,
            retry_at,
            backoff,
        } if clock::now() >= retry_at => match open_chassis_side(&config.bus, config) {
            Ok(bus) => {
                info!(bus = bus.name(), "the simulated chassis has its bus back");
                Ok(Chassis::Running(
                    SimHandle::spawn(firmware, bus).map_err(|e| e.to_string())?,
                ))
            }
            Err(err) => {
                let backoff = (backoff * 2).min(LAST_RETRY);
                tracing::debug!("reopening the bus: {err}");
                Ok(Chassis::Down {
                    firmware,
                    retry_at: clock::now() + backoff,
                    backoff,
                })
            }
        },
        other => Ok(other),
    }
}
