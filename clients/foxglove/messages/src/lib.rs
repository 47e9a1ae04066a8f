//! What a Foxglove WebSocket client may send `chassis-foxglove`, decoded and checked.
//!
//! The `foxglove` crate's server reads the WebSocket protocol itself (its JSON and binary
//! opcodes) and hands the bridge two kinds of client bytes, both untrusted:
//!
//! * the message data of a channel the client advertised ([`twist_request`]): on a
//!   `geometry_msgs/Twist` channel in `json` ([`check_twist_channel`]) — the Teleop panel's, or
//!   any client's — a Twist is parsed into a [`ValidRequest`] of the `foxglove` source; anything
//!   that is not a Twist, or that asks for a NaN or an infinity, is refused here and never
//!   reaches the mux;
//! * the request of a service call ([`control_request`]): JSON fields with defaults (`{}` or
//!   nothing is a request), each service ([`ServiceAction`]) becoming exactly its control
//!   request — only `/estop` and `/estop_release` touch a lock, and only the `estop` lock.
//!
//! The bridge advertises `clientPublish` and `services` only: parameters, assets and the
//! connection graph are refused by the server before any byte reaches this crate.
//!
//! Nothing here opens a socket or an IPC port, so the fuzz target `foxglove_client` builds this
//! crate without the WebSocket and iceoryx2 stacks.

use chassis_interfaces::{
    ControlKind, ControlRequest, ControlResponse, ControlStatus, FaultClear, InvalidVelocity,
    LightMode, ValidRequest, VelocityRequest,
};
use chassis_protocols::{Command, command_to_request};
use serde::de::{self, MapAccess, Visitor};
use serde::{Deserialize, Deserializer};
use serde_json::{Value, json};

/// Schema names of the velocity messages taken from clients: ROS 1 and ROS 2 spellings, as
/// Foxglove's Teleop panel advertises them.
pub const TWIST_SCHEMAS: [&str; 2] = ["geometry_msgs/Twist", "geometry_msgs/msg/Twist"];

/// A `geometry_msgs/Twist` as JSON: objects only (serde's derived structs would also read an
/// array by position), a missing part is zero, and a field a Twist does not have or a field
/// given twice refuses the message (a `TwistStamped` sent on a Twist channel would otherwise
/// be a silent zero), as does every byte that is not JSON.
#[derive(Debug, Default, PartialEq)]
pub struct Twist {
    pub linear: Vector,
    pub angular: Vector,
}

#[derive(Debug, Default, PartialEq)]
pub struct Vector {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

/// Reads a JSON object whose keys are among `names`, each at most once.
struct Object<T, const N: usize> {
    what: &'static str,
    names: &'static [&'static str; N],
    _t: std::marker::PhantomData<fn() -> T>,
}

impl<'de, T: Deserialize<'de>, const N: usize> Visitor<'de> for Object<T, N> {
    type Value = [Option<T>; N];

    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        write!(f, "{} (an object of {})", self.what, self.names.join(", "))
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
        let mut values: [Option<T>; N] = std::array::from_fn(|_| None);
        while let Some(key) = map.next_key::<String>()? {
            let Some(i) = self.names.iter().position(|n| *n == key) else {
                return Err(de::Error::unknown_field(&key, self.names));
            };
            if values[i].is_some() {
                return Err(de::Error::duplicate_field(self.names[i]));
            }
            values[i] = Some(map.next_value()?);
        }
        Ok(values)
    }
}

fn object<'de, D: Deserializer<'de>, T: Deserialize<'de>, const N: usize>(
    deserializer: D,
    what: &'static str,
    names: &'static [&'static str; N],
) -> Result<[Option<T>; N], D::Error> {
    deserializer.deserialize_map(Object {
        what,
        names,
        _t: std::marker::PhantomData,
    })
}

impl<'de> Deserialize<'de> for Twist {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let [linear, angular] = object(deserializer, "a Twist", &["linear", "angular"])?;
        Ok(Twist {
            linear: linear.unwrap_or_default(),
            angular: angular.unwrap_or_default(),
        })
    }
}

impl<'de> Deserialize<'de> for Vector {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let [x, y, z] = object(deserializer, "a Vector3", &["x", "y", "z"])?;
        Ok(Vector {
            x: x.unwrap_or_default(),
            y: y.unwrap_or_default(),
            z: z.unwrap_or_default(),
        })
    }
}

/// Why a client message is not a velocity.
#[derive(Debug, thiserror::Error)]
pub enum TwistError {
    #[error("topic {topic}: schema '{schema}' is not geometry_msgs/Twist")]
    Schema { topic: String, schema: String },
    #[error("topic {topic}: encoding '{encoding}' is not json")]
    Encoding { topic: String, encoding: String },
    #[error("topic {topic}: not a Twist: {source}")]
    Json {
        topic: String,
        source: serde_json::Error,
    },
    #[error("topic {topic}: the Twist is no velocity: {source}")]
    NonFinite {
        topic: String,
        source: InvalidVelocity,
    },
}

/// Checks a client channel carries Twists as JSON.
pub fn check_twist_channel(
    topic: &str,
    schema_name: &str,
    encoding: &str,
) -> Result<(), TwistError> {
    if !TWIST_SCHEMAS.contains(&schema_name) {
        return Err(TwistError::Schema {
            topic: topic.into(),
            schema: schema_name.into(),
        });
    }
    if encoding != "json" {
        return Err(TwistError::Encoding {
            topic: topic.into(),
            encoding: encoding.into(),
        });
    }
    Ok(())
}

/// The velocity request a Twist asks for, parsed: `linear.x`, `linear.y` (omni robots),
/// `angular.z`, as `f32`. A value that is not finite there (JSON has no NaN, but 1e39 is no
/// `f32`) is refused. What is finite but absurd is the mux's to refuse and count.
pub fn twist_request(topic: &str, payload: &[u8]) -> Result<ValidRequest, TwistError> {
    let twist: Twist = serde_json::from_slice(payload).map_err(|source| TwistError::Json {
        topic: topic.into(),
        source,
    })?;
    ValidRequest::try_from(VelocityRequest {
        linear_y_mps: twist.linear.y as f32,
        ..VelocityRequest::twist(twist.linear.x as f32, twist.angular.z as f32)
    })
    .map_err(|source| TwistError::NonFinite {
        topic: topic.into(),
        source,
    })
}

/// A service the bridge offers: the e-stop lock, and the chassis functions of `chassis
/// control`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ServiceAction {
    Estop,
    EstopRelease,
    ClearFaults,
    Mode,
    Brake,
    Lights,
    OffRoad,
    Lift,
    Servos,
    Power,
    SteeringZero,
    Silent,
}

impl ServiceAction {
    pub const ALL: [ServiceAction; 12] = [
        ServiceAction::Estop,
        ServiceAction::EstopRelease,
        ServiceAction::ClearFaults,
        ServiceAction::Mode,
        ServiceAction::Brake,
        ServiceAction::Lights,
        ServiceAction::OffRoad,
        ServiceAction::Lift,
        ServiceAction::Servos,
        ServiceAction::Power,
        ServiceAction::SteeringZero,
        ServiceAction::Silent,
    ];

    /// Each action's service name and the [`ControlKind`] of the request a call becomes, in the
    /// order the actions are declared.
    const SERVICES: [(&'static str, u8); 12] = [
        ("/estop", ControlKind::LOCK_ENGAGE),
        ("/estop_release", ControlKind::LOCK_RELEASE),
        ("/clear_faults", ControlKind::CLEAR_FAULTS),
        ("/mode", ControlKind::MODE),
        ("/brake", ControlKind::BRAKE),
        ("/lights", ControlKind::LIGHTS),
        ("/off_road", ControlKind::OFF_ROAD),
        ("/lift", ControlKind::LIFT),
        ("/servos", ControlKind::SERVOS),
        ("/power", ControlKind::POWER),
        ("/steering_zero", ControlKind::STEERING_ZERO),
        ("/silent", ControlKind::SILENT),
    ];

    /// The service's name.
    pub fn name(self) -> &'static str {
        Self::SERVICES[self as usize].0
    }

    /// The [`ControlKind`] of the request a call becomes.
    pub fn kind(self) -> u8 {
        Self::SERVICES[self as usize].1
    }

    /// The JSON Schema of the request's fields (every field has a default: `{}` is a request).
    pub fn request_schema(self) -> Value {
        let boolean = |name: &str, default: bool, what: &str| json!({name: {"type": "boolean", "default": default, "description": what}});
        let properties = match self {
            ServiceAction::Estop | ServiceAction::EstopRelease | ServiceAction::SteeringZero => {
                json!({})
            }
            ServiceAction::ClearFaults => json!({"which": {
                "type": "string", "default": "all",
                "description": "all, motor-1..motor-4, battery-under-voltage, battery-over-voltage, rc-link, front-steering-encoder, rear-steering-encoder, over-current, over-temperature"
            }}),
            ServiceAction::Mode => boolean(
                "take_control",
                true,
                "true: command mode (obey this computer); false: standby",
            ),
            ServiceAction::Brake => boolean("engage", true, "engage the parking brake"),
            ServiceAction::Lights => json!({
                "mode": {"type": "string", "enum": ["off", "on", "breathing", "custom", "auto"], "default": "on"},
                "brightness_pct": {"type": "integer", "minimum": 0, "maximum": 100, "default": 100}
            }),
            ServiceAction::OffRoad | ServiceAction::Silent => {
                boolean("enter", true, "enter (true) or leave (false)")
            }
            ServiceAction::Lift => json!({
                "position_pct": {"type": "number", "minimum": 0, "maximum": 100, "default": 0},
                "disable": {"type": "boolean", "default": false}
            }),
            ServiceAction::Servos => json!({
                "pan_deg": {"type": "number", "minimum": -90, "maximum": 90, "default": 0},
                "tilt_deg": {"type": "number", "minimum": -90, "maximum": 90, "default": 0}
            }),
            ServiceAction::Power => boolean("enable", true, "drive power on (true) or off"),
        };
        json!({"type": "object", "properties": properties})
    }
}

/// The JSON Schema of every service's answer: chassisd's `ControlResponse`.
pub fn response_schema() -> Value {
    json!({"type": "object", "properties": {
        "ok": {"type": "boolean"},
        "status": {"type": "string", "description": "ok, refused, unsupported, invalid, timeout"},
        "message": {"type": "string"}
    }})
}

/// chassisd's answer as the service's JSON response.
pub fn response_json(response: &ControlResponse) -> Value {
    json!({
        "ok": response.is_ok(),
        "status": ControlStatus::name(response.status),
        "message": response.message(),
    })
}

/// Why a service request is not a control request.
#[derive(Debug, thiserror::Error)]
pub enum CallError {
    #[error("request is not text: {0}")]
    Utf8(#[from] std::str::Utf8Error),
    #[error("request is not JSON of the service's schema: {0}")]
    Json(#[from] serde_json::Error),
    #[error("unknown fault '{0}'")]
    UnknownFault(String),
    #[error("unknown light mode '{0}' (off, on, breathing, custom, auto)")]
    LightMode(String),
    #[error("{0} is out of range")]
    Range(&'static str),
}

#[derive(Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct Fields {
    which: String,
    take_control: bool,
    engage: bool,
    enter: bool,
    enable: bool,
    mode: String,
    brightness_pct: u8,
    position_pct: f64,
    disable: bool,
    pan_deg: f64,
    tilt_deg: f64,
}

impl Default for Fields {
    fn default() -> Self {
        Self {
            which: "all".into(),
            take_control: true,
            engage: true,
            enter: true,
            enable: true,
            mode: "on".into(),
            brightness_pct: 100,
            position_pct: 0.0,
            disable: false,
            pan_deg: 0.0,
            tilt_deg: 0.0,
        }
    }
}

/// The control request a service call asks for. An empty payload is `{}`: every default;
/// bytes that are not text are refused, never taken for nothing.
pub fn control_request(action: ServiceAction, payload: &[u8]) -> Result<ControlRequest, CallError> {
    // JSON's whitespace only (no form feed).
    let text = std::str::from_utf8(payload)?.trim_matches([' ', '\t', '\n', '\r']);
    let f: Fields = if text.is_empty() {
        Fields::default()
    } else if text.starts_with('{') {
        serde_json::from_str(text)?
    } else {
        // Fields are flat: only the top level could be an array read by position.
        return Err(CallError::Json(de::Error::invalid_type(
            de::Unexpected::Other("a JSON value that is not an object"),
            &"an object of the service's fields",
        )));
    };
    let command = match action {
        ServiceAction::Estop => {
            return Ok(ControlRequest::new(ControlKind::LOCK_ENGAGE).with_name("estop"));
        }
        ServiceAction::EstopRelease => {
            return Ok(ControlRequest::new(ControlKind::LOCK_RELEASE).with_name("estop"));
        }
        ServiceAction::ClearFaults => Command::ClearFaults {
            which: FaultClear::from_name(&f.which).ok_or(CallError::UnknownFault(f.which))?,
        },
        ServiceAction::Mode => Command::Mode {
            take_control: f.take_control,
        },
        ServiceAction::Brake => Command::Brake { engage: f.engage },
        ServiceAction::Lights => {
            if f.brightness_pct > 100 {
                return Err(CallError::Range("brightness_pct"));
            }
            let (enable, mode) = match f.mode.as_str() {
                "off" => (true, LightMode::OFF),
                "on" => (true, LightMode::ON),
                "breathing" => (true, LightMode::BREATHING),
                "custom" => (true, LightMode::CUSTOM),
                "auto" => (false, LightMode::OFF),
                _ => return Err(CallError::LightMode(f.mode)),
            };
            Command::Lights {
                enable,
                mode,
                brightness_pct: f.brightness_pct,
            }
        }
        ServiceAction::OffRoad => Command::OffRoad { enter: f.enter },
        ServiceAction::Lift => {
            if !(0.0..=100.0).contains(&f.position_pct) {
                return Err(CallError::Range("position_pct"));
            }
            Command::Lift {
                enable: !f.disable,
                position_pct: f.position_pct,
            }
        }
        ServiceAction::Servos => {
            if !(-90.0..=90.0).contains(&f.pan_deg) || !(-90.0..=90.0).contains(&f.tilt_deg) {
                return Err(CallError::Range("pan_deg / tilt_deg"));
            }
            Command::Servos {
                pan_rad: f.pan_deg.to_radians(),
                tilt_rad: f.tilt_deg.to_radians(),
            }
        }
        ServiceAction::Power => Command::Power { enable: f.enable },
        ServiceAction::SteeringZero => Command::SteeringZero,
        ServiceAction::Silent => Command::Silent { enter: f.enter },
    };
    command_to_request(&command).ok_or(CallError::Range("command"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_teleop_twist_becomes_a_velocity_request() {
        let payload = br#"{"linear":{"x":0.4,"y":0.1,"z":0},"angular":{"x":0,"y":0,"z":-0.5}}"#;
        let r = twist_request("/cmd_vel", payload).unwrap();
        assert_eq!(
            (r.linear_x_mps, r.linear_y_mps, r.angular_z_radps),
            (0.4, 0.1, -0.5)
        );
        assert!(!r.is_heartbeat());
        // Missing parts are zero.
        let r = twist_request("/cmd_vel", br#"{"linear":{"x":0.2}}"#).unwrap();
        assert_eq!((r.linear_x_mps, r.angular_z_radps), (0.2, 0.0));
        assert!(twist_request("/cmd_vel", b"[1,2]").is_err());
    }

    /// Asserts that `result`, what reading `payload` gave, is an error `expected` accepts.
    #[track_caller]
    fn assert_refused<T: std::fmt::Debug, E: std::fmt::Debug>(
        payload: &[u8],
        result: Result<T, E>,
        expected: fn(&E) -> bool,
    ) {
        assert!(
            matches!(&result, Err(e) if expected(e)),
            "{}: {result:?}",
            String::from_utf8_lossy(payload)
        );
    }

    #[test]
    fn a_twist_beyond_f32_is_refused_not_sent_as_infinity() {
        for payload in [
            &br#"{"linear":{"x":1e39}}"#[..],
            br#"{"linear":{"y":-1e300}}"#,
            br#"{"angular":{"z":3.5e38}}"#,
        ] {
            assert_refused(payload, twist_request("/cmd_vel", payload), |e| {
                matches!(e, TwistError::NonFinite { .. })
            });
        }
        // Beyond f64 is no JSON number serde takes; NaN is no JSON at all.
        assert!(twist_request("/cmd_vel", br#"{"linear":{"x":1e400}}"#).is_err());
        assert!(twist_request("/cmd_vel", br#"{"linear":{"x":NaN}}"#).is_err());
        // The largest f32 is finite: the mux refuses it as absurd, and counts it.
        assert!(twist_request("/cmd_vel", br#"{"linear":{"x":3.4e38}}"#).is_ok());
    }

    /// Found by fuzzing (`foxglove_client`): bytes that are not JSON (not UTF-8, inside a field
    /// a Twist does not have) were taken as a zero Twist.
    #[test]
    fn a_twist_message_that_is_not_json_or_has_other_fields_is_refused() {
        for payload in [
            &b"{\"liangular\":{\"\xb5\":0,\"y\":0,\"z\":0}}"[..],
            b"{\"linear\":{\"x\":0.5},\"note\":\"\xff\"}",
            // A TwistStamped on a Twist channel would be a silent zero.
            br#"{"header":{"frame_id":"base_link"},"twist":{"linear":{"x":0.5}}}"#,
            br#"{"linear":{"x":0.5,"w":1}}"#,
            br#"{"linear":{"x":0.5},"linear":{"x":5}}"#,
        ] {
            assert_refused(payload, twist_request("/cmd_vel", payload), |e| {
                matches!(e, TwistError::Json { .. })
            });
        }
    }

    /// Found by fuzzing (`foxglove_client`): serde's derived structs also read a JSON array,
    /// by position — `[]` was a zero Twist or every default of a service, `[{"x":1}]` a speed.
    #[test]
    fn a_json_array_is_no_twist_and_no_service_request() {
        for payload in [&b"[]"[..], br#"[{"x":1}]"#, br#"{"linear":[1,0,0]}"#] {
            assert_refused(payload, twist_request("/cmd_vel", payload), |e| {
                matches!(e, TwistError::Json { .. })
            });
        }
        // Nor is a form feed JSON's whitespace (found by fuzzing too).
        for payload in [&b"[]"[..], br#"["all"]"#, b" [ ] ", b"\x0c{}", b"{}\x0c"] {
            assert_refused(
                payload,
                control_request(ServiceAction::Silent, payload),
                |e| matches!(e, CallError::Json(_)),
            );
        }
    }

    #[test]
    fn only_json_twist_channels_are_velocities() {
        assert!(check_twist_channel("/cmd_vel", "geometry_msgs/Twist", "json").is_ok());
        assert!(check_twist_channel("/cmd_vel", "geometry_msgs/msg/Twist", "json").is_ok());
        assert!(matches!(
            check_twist_channel("/cmd_vel", "geometry_msgs/Twist", "cdr"),
            Err(TwistError::Encoding { .. })
        ));
        assert!(matches!(
            check_twist_channel("/cmd_vel", "std_msgs/String", "json"),
            Err(TwistError::Schema { .. })
        ));
    }

    #[test]
    fn the_estop_services_engage_and_release_the_estop_lock() {
        let r = control_request(ServiceAction::Estop, b"").unwrap();
        assert_eq!((r.kind, r.name()), (ControlKind::LOCK_ENGAGE, "estop"));
        let r = control_request(ServiceAction::EstopRelease, b"{}").unwrap();
        assert_eq!((r.kind, r.name()), (ControlKind::LOCK_RELEASE, "estop"));
    }

    #[test]
    fn service_requests_become_the_control_requests_of_chassis_control() {
        let r = control_request(ServiceAction::ClearFaults, br#"{"which":"all"}"#).unwrap();
        assert_eq!(r.kind, ControlKind::CLEAR_FAULTS);
        let r = control_request(ServiceAction::Mode, br#"{"take_control":false}"#).unwrap();
        assert_eq!(r.kind, ControlKind::MODE);
        assert!(control_request(ServiceAction::ClearFaults, br#"{"which":"nope"}"#).is_err());
        assert!(control_request(ServiceAction::Lift, br#"{"position_pct":120}"#).is_err());
        assert!(control_request(ServiceAction::Brake, br#"{"bogus":1}"#).is_err());
        for action in ServiceAction::ALL {
            let r = control_request(action, b"{}").unwrap();
            assert_eq!(r.kind, action.kind(), "{action:?}");
        }
    }

    /// Found by fuzzing (`foxglove_client`): a request that was not UTF-8 was read as nothing,
    /// so every default — a `/mode` call asking for standby took control.
    #[test]
    fn a_service_request_that_is_not_utf8_is_refused_not_taken_for_the_defaults() {
        for payload in [
            &b"{\"ta\xbb\xbbk$_control\":false}"[..],
            b"{\"take_control\":false}\xff",
            b"\xff",
        ] {
            assert_refused(
                payload,
                control_request(ServiceAction::Mode, payload),
                |e| matches!(e, CallError::Utf8(_)),
            );
        }
        // Nothing at all is every default.
        for payload in [&b""[..], b"  \n"] {
            let r = control_request(ServiceAction::Mode, payload).unwrap();
            assert_eq!(r.arg[0], chassis_interfaces::ControlMode::COMMAND);
        }
    }

    #[test]
    fn every_service_has_a_distinct_name_and_an_object_schema() {
        let mut names: Vec<_> = ServiceAction::ALL.iter().map(|a| a.name()).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), ServiceAction::ALL.len());
        for a in ServiceAction::ALL {
            assert_eq!(a.request_schema()["type"], "object", "{a:?}");
        }
    }
}
