//! Anything a Foxglove WebSocket client may send chassis-foxglove once the server has read the
//! protocol's framing: a message on a channel the client advertised (any schema, any encoding)
//! or the request of a service call. No panic; a message becomes a velocity only on a JSON
//! Twist channel, carries finite numbers equal to the Twist's own (read here independently,
//! from a `serde_json::Value`) and never a flag, a lock or an envelope; a service call becomes
//! exactly its own control request — from nothing (every default) or a JSON object, never from
//! other bytes — which chassisd reads back as the same action, and only `/estop` and
//! `/estop_release` reach a lock — the `estop` lock.
#![no_main]

use chassis_foxglove_messages::{
    ServiceAction, TWIST_SCHEMAS, check_twist_channel, control_request, twist_request,
};
use chassis_interfaces::{ControlKind, VelocityRequest};
use chassis_protocols::{ControlAction, command_to_request, request_to_action};
use libfuzzer_sys::fuzz_target;
use serde_json::Value;

const SCHEMAS: [&str; 4] = [
    "geometry_msgs/Twist",
    "geometry_msgs/msg/Twist",
    "geometry_msgs/msg/TwistStamped",
    "std_msgs/String",
];

fn twist(schema: &str, encoding: &str, payload: &[u8]) {
    let Ok(request) = check_twist_channel("/cmd_vel", schema, encoding)
        .and_then(|()| twist_request("/cmd_vel", payload))
    else {
        return;
    };
    // Finite by its type: a ValidRequest.
    assert!(TWIST_SCHEMAS.contains(&schema) && encoding == "json");
    let value: Value = serde_json::from_slice(payload).expect("a Twist is JSON");
    let number = |part: &str, axis: &str| value[part][axis].as_f64().unwrap_or(0.0) as f32;
    let expected = VelocityRequest {
        linear_y_mps: number("linear", "y"),
        ..VelocityRequest::twist(number("linear", "x"), number("angular", "z"))
    };
    assert_eq!(*request, expected);
}

fn call(action: ServiceAction, payload: &[u8]) {
    let Ok(request) = control_request(action, payload) else {
        return;
    };
    assert_eq!(request.kind, action.kind(), "{action:?}");
    // Nothing (every default) or a JSON object: never bytes that are neither.
    let nothing = payload.iter().all(|b| b" \t\n\r".contains(b));
    assert!(
        nothing || serde_json::from_slice::<Value>(payload).is_ok_and(|v| v.is_object()),
        "{action:?} took {:?}",
        String::from_utf8_lossy(payload)
    );
    let read = request_to_action(&request)
        .unwrap_or_else(|e| panic!("{action:?}: chassisd refuses {request:?}: {e}"));
    match (action, read) {
        (ServiceAction::Estop, ControlAction::LockEngage(name, None))
        | (ServiceAction::EstopRelease, ControlAction::LockRelease(name)) => {
            assert_eq!(name, "estop");
        }
        (ServiceAction::Estop | ServiceAction::EstopRelease, other) => {
            panic!("{action:?} became {other:?}")
        }
        (_, ControlAction::Chassis(command)) => {
            assert!(
                ![ControlKind::LOCK_ENGAGE, ControlKind::LOCK_RELEASE].contains(&request.kind)
            );
            assert_eq!(command_to_request(&command), Some(request));
        }
        (_, other) => panic!("{action:?} became {other:?}"),
    }
}

fuzz_target!(|data: &[u8]| {
    let Some((&choice, payload)) = data.split_first() else {
        return;
    };
    if choice & 0x80 == 0 {
        let schema = SCHEMAS[usize::from(choice & 0x03)];
        let encoding = if choice & 0x04 == 0 { "json" } else { "cdr" };
        twist(schema, encoding, payload);
    } else {
        let action = ServiceAction::ALL[usize::from(choice & 0x7F) % ServiceAction::ALL.len()];
        call(action, payload);
    }
});
