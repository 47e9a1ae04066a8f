//! Service names: everything a robot offers lives under `chassis/<name>/`.

/// The services of one robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ServiceKind<'a> {
    /// `ChassisState`, publish-subscribe with history 1, plus its event.
    State,
    /// `BusFrame` tap of both directions.
    Frames,
    /// `MuxStatus`.
    Mux,
    /// `ControlRequest` → `ControlResponse`, request-response.
    Control,
    /// `SimRequest` → `ControlResponse`: fault injection into a simulated chassis.
    Sim,
    /// `VelocityRequest` from one configured source.
    Cmd(&'a str),
}

/// The iceoryx2 service name of `kind` for the robot called `robot`, e.g. `chassis/titan/state`
/// or `chassis/titan/cmd/teleop`. Each publish-subscribe service has an event service of the same
/// name that wakes its readers.
pub fn service_name(robot: &str, kind: ServiceKind<'_>) -> String {
    match kind {
        ServiceKind::State => format!("chassis/{robot}/state"),
        ServiceKind::Frames => format!("chassis/{robot}/frames"),
        ServiceKind::Mux => format!("chassis/{robot}/mux"),
        ServiceKind::Control => format!("chassis/{robot}/control"),
        ServiceKind::Sim => format!("chassis/{robot}/sim"),
        ServiceKind::Cmd(source) => format!("chassis/{robot}/cmd/{source}"),
    }
}

/// Robot and source names: 1 to 16 characters of `a-z`, `0-9`, `-`, `_` (they become service
/// names and fixed-length fields).
pub fn valid_robot_name(name: &str) -> bool {
    (1..=crate::NAME_LEN).contains(&name.len())
        && name
            .bytes()
            .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'-' || b == b'_')
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
    }

    #[test]
    fn robot_names_are_checked() {
        assert!(valid_robot_name("scout-mini"));
        assert!(valid_robot_name("bot_2"));
        assert!(!valid_robot_name(""));
        assert!(!valid_robot_name("Titan"));
        assert!(!valid_robot_name("a/b"));
        assert!(!valid_robot_name("seventeen-chars-x"));
    }
}
