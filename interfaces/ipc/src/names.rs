//! Service names — everything a robot offers lives under `chassis/<robot>/` — and the iceoryx2
//! configuration every process of one system shares.

use iceoryx2::prelude::*;

use crate::IpcError;

/// Environment variable naming the iceoryx2 file prefix (default `iox2_`): processes with
/// different prefixes never see each other (tests running in parallel isolate themselves so).
pub const IPC_PREFIX_ENV: &str = "CHASSIS_IPC_PREFIX";

/// Test hook of chassisd, never for a robot: set at chassisd's start to a file path, the event
/// loop's thread alone stalls — as a hung loop would, while the process's other threads run on
/// — for the milliseconds written in that file whenever it appears (the loop removes it).
/// chassisd warns at start when it is set. The watchdog test uses it to show that the watchdog's
/// pings come from the loop itself.
pub const TEST_LOOP_STALL_ENV: &str = "CHASSISD_TEST_LOOP_STALL_FILE";

/// What [`reply_name`] appends to a request-response service's name.
pub const REPLY_SUFFIX: &str = "/reply";

/// The services of one robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ServiceKind<'a> {
    /// `ChassisState`, publish-subscribe with history 1, plus its event.
    State,
    /// `BusFrame` tap of both directions.
    Frames,
    /// `MuxStatus`.
    Mux,
    /// `RobotDescription` on `chassis/<robot>/robot`, publish-subscribe with history 1.
    Description,
    /// `ControlRequest` → `ControlResponse`, request-response.
    Control,
    /// `SimRequest` → `ControlResponse`: fault injection into a simulated chassis.
    Sim,
    /// `VelocityRequest` from one configured source.
    Cmd(&'a str),
    /// A client's own publication beside the robot's services (the safety monitor's
    /// `SafetyStatus` on `safety`), see [`crate::publication`].
    Publication(&'a str),
}

/// The iceoryx2 service name of `kind` for the robot called `robot`, e.g. `chassis/titan/state`
/// or `chassis/titan/cmd/teleop`. Each publish-subscribe service has an event service of the same
/// name that wakes its readers.
pub fn service_name(robot: &str, kind: ServiceKind<'_>) -> String {
    match kind {
        ServiceKind::State => format!("chassis/{robot}/state"),
        ServiceKind::Frames => format!("chassis/{robot}/frames"),
        ServiceKind::Mux => format!("chassis/{robot}/mux"),
        ServiceKind::Description => format!("chassis/{robot}/robot"),
        ServiceKind::Control => format!("chassis/{robot}/control"),
        ServiceKind::Sim => format!("chassis/{robot}/sim"),
        ServiceKind::Cmd(source) => format!("chassis/{robot}/cmd/{source}"),
        ServiceKind::Publication(suffix) => format!("chassis/{robot}/{suffix}"),
    }
}

/// The event service on which the server of the request-response service `service` tells its
/// clients that an answer is ready: `<service>/reply`.
pub fn reply_name(service: &str) -> String {
    format!("{service}{REPLY_SUFFIX}")
}

/// The iceoryx2 configuration: the default one, with the file prefix `prefix`, or else the one
/// in [`IPC_PREFIX_ENV`] when it is set.
pub fn config(prefix: Option<&str>) -> Result<Config, IpcError> {
    let mut config = Config::default();
    let prefix = prefix
        .map(str::to_string)
        .or_else(|| std::env::var(IPC_PREFIX_ENV).ok());
    if let Some(prefix) = prefix {
        config.global.prefix = FileName::new(prefix.as_bytes()).map_err(|e| IpcError::Prefix {
            prefix,
            error: Box::new(e),
        })?;
    }
    Ok(config)
}

/// The robots whose `state` service exists under `config` (this computer's iceoryx2 with one
/// file prefix), sorted by name: each `chassis/<robot>/state` publish-subscribe service, whether
/// chassisd or a mirror (`chassis-zenoh`) created it. A service outlives a killed owner until
/// the next cleanup, so a listed robot may have no publisher: open it to know.
pub fn robots(config: &Config) -> Result<Vec<String>, IpcError> {
    let mut names = Vec::new();
    ipc::Service::list(config, |service| {
        let details = &service.static_details;
        if matches!(
            details.messaging_pattern(),
            iceoryx2::service::static_config::messaging_pattern::MessagingPattern::PublishSubscribe(
                _
            )
        ) && let Some(robot) = robot_of_state(details.name().as_str())
        {
            names.push(robot.to_string());
        }
        CallbackProgression::Continue
    })
    .map_err(IpcError::service("chassis/*/state", "listing"))?;
    names.sort();
    names.dedup();
    Ok(names)
}

/// The robot a state service's name belongs to (`chassis/<robot>/state`).
fn robot_of_state(service: &str) -> Option<&str> {
    service
        .strip_prefix("chassis/")
        .and_then(|rest| rest.strip_suffix("/state"))
        .filter(|robot| !robot.is_empty() && !robot.contains('/'))
}

pub(crate) fn iceoryx_name(name: &str) -> Result<ServiceName, IpcError> {
    name.try_into().map_err(|e| IpcError::ServiceName {
        name: name.to_string(),
        error: Box::new(e),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn services_are_namespaced_by_robot_name() {
        assert_eq!(
            service_name("titan", ServiceKind::State),
            "chassis/titan/state"
        );
        assert_eq!(
            service_name("left", ServiceKind::Cmd("teleop")),
            "chassis/left/cmd/teleop"
        );
        assert_eq!(
            service_name("left", ServiceKind::Publication("safety")),
            "chassis/left/safety"
        );
        assert_eq!(
            reply_name(&service_name("titan", ServiceKind::Control)),
            "chassis/titan/control/reply"
        );
    }

    #[test]
    fn a_robot_is_named_by_its_state_service_only() {
        assert_eq!(robot_of_state("chassis/titan/state"), Some("titan"));
        assert_eq!(robot_of_state("chassis/titan/mux"), None);
        assert_eq!(robot_of_state("chassis/titan/cmd/state"), None);
        assert_eq!(robot_of_state("chassis//state"), None);
    }

    #[test]
    fn an_explicit_prefix_wins_and_a_bad_one_is_named() {
        let config = config(Some("chassis_test_")).unwrap();
        assert_eq!(config.global.prefix.as_bytes(), b"chassis_test_");
        let err = super::config(Some("a/b")).unwrap_err();
        assert!(matches!(err, IpcError::Prefix { .. }), "{err}");
        assert!(err.to_string().contains("a/b"), "{err}");
    }
}
