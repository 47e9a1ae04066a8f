//! The Foxglove side: the WebSocket server's callbacks, which run on its own threads, turn
//! into [`Inbox`] messages for the robot loop (iceoryx2 ports are not `Send`: only that loop
//! touches them). Nothing here talks to the robot.

use std::sync::mpsc::Sender;

use chassis_client::VelocityRequest;
use foxglove::Schema;
use foxglove::websocket::service::{Handler, Request, Responder, Service, ServiceSchema};
use foxglove::websocket::{Client, ClientChannel, ServerListener, Status};
use serde::Deserialize;
use serde_json::{Value, json};

/// Schema names of the velocity messages taken from clients: ROS 1 and ROS 2 spellings, as
/// Foxglove's Teleop panel advertises them.
pub const TWIST_SCHEMAS: [&str; 2] = ["geometry_msgs/Twist", "geometry_msgs/msg/Twist"];

/// What the server's callbacks ask of the robot loop.
#[derive(Debug)]
pub enum Inbox {
    /// A velocity from a client's Twist channel.
    Twist(VelocityRequest),
    /// The client stopped publishing its Twist channel (unadvertised or disconnected).
    TwistEnded,
    /// A service call, answered through the responder once chassisd answered.
    Call {
        action: ServiceAction,
        payload: Vec<u8>,
        responder: Responder,
    },
}

/// A `geometry_msgs/Twist` as JSON.
#[derive(Debug, Default, Deserialize, PartialEq)]
pub struct Twist {
    #[serde(default)]
    pub linear: Vector,
    #[serde(default)]
    pub angular: Vector,
}

#[derive(Debug, Default, Deserialize, PartialEq)]
pub struct Vector {
    #[serde(default)]
    pub x: f64,
    #[serde(default)]
    pub y: f64,
    #[serde(default)]
    pub z: f64,
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
}

/// Checks a client channel carries Twists as JSON.
pub fn check_twist_channel(channel: &ClientChannel) -> Result<(), TwistError> {
    if !TWIST_SCHEMAS.contains(&channel.schema_name.as_str()) {
        return Err(TwistError::Schema {
            topic: channel.topic.clone(),
            schema: channel.schema_name.clone(),
        });
    }
    if channel.encoding != "json" {
        return Err(TwistError::Encoding {
            topic: channel.topic.clone(),
            encoding: channel.encoding.clone(),
        });
    }
    Ok(())
}

/// The velocity request a Twist asks for: `linear.x`, `linear.y` (omni robots), `angular.z`.
pub fn twist_request(topic: &str, payload: &[u8]) -> Result<VelocityRequest, TwistError> {
    let twist: Twist = serde_json::from_slice(payload).map_err(|source| TwistError::Json {
        topic: topic.into(),
        source,
    })?;
    Ok(VelocityRequest {
        linear_y_mps: twist.linear.y as f32,
        ..VelocityRequest::twist(twist.linear.x as f32, twist.angular.z as f32)
    })
}

/// The server's listener: client publishes become [`Inbox`] messages.
#[derive(Debug)]
pub struct Listener {
    pub inbox: Sender<Inbox>,
}

impl ServerListener for Listener {
    fn on_client_advertise(&self, client: Client, channel: &ClientChannel) {
        match check_twist_channel(channel) {
            Ok(()) => tracing::info!(topic = channel.topic, "a client publishes velocities"),
            Err(e) => {
                tracing::debug!(error = %e, "client channel refused");
                client.send_status(Status::warning(format!("{e}: its messages are ignored")));
            }
        }
    }

    fn on_client_unadvertise(&self, _client: Client, channel: &ClientChannel) {
        if check_twist_channel(channel).is_ok() && self.inbox.send(Inbox::TwistEnded).is_err() {
            tracing::debug!("the robot loop has ended");
        }
    }

    fn on_message_data(&self, client: Client, channel: &ClientChannel, payload: &[u8]) {
        let request =
            check_twist_channel(channel).and_then(|()| twist_request(&channel.topic, payload));
        match request {
            Ok(request) => {
                if self.inbox.send(Inbox::Twist(request)).is_err() {
                    tracing::debug!("the robot loop has ended");
                }
            }
            Err(e) => {
                tracing::debug!(error = %e, "client message ignored");
                client.send_status(Status::warning(e.to_string()));
            }
        }
    }
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

    /// The service's name.
    pub fn name(self) -> &'static str {
        match self {
            ServiceAction::Estop => "/estop",
            ServiceAction::EstopRelease => "/estop_release",
            ServiceAction::ClearFaults => "/clear_faults",
            ServiceAction::Mode => "/mode",
            ServiceAction::Brake => "/brake",
            ServiceAction::Lights => "/lights",
            ServiceAction::OffRoad => "/off_road",
            ServiceAction::Lift => "/lift",
            ServiceAction::Servos => "/servos",
            ServiceAction::Power => "/power",
            ServiceAction::SteeringZero => "/steering_zero",
            ServiceAction::Silent => "/silent",
        }
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

    /// The service advertised to clients, handing its calls to the robot loop.
    pub fn service(self, inbox: Sender<Inbox>) -> Service {
        let schema_name = format!("chassis{}", self.name().replace('/', "."));
        let json_schema = |name: String, value: &Value| {
            Schema::new(name, "jsonschema", value.to_string().into_bytes())
        };
        let schema = ServiceSchema::new(schema_name.clone())
            .with_request(
                "json",
                json_schema(format!("{schema_name}.Request"), &self.request_schema()),
            )
            .with_response(
                "json",
                json_schema(format!("{schema_name}.Response"), &response_schema()),
            );
        Service::builder(self.name(), schema).handler(CallHandler {
            action: self,
            inbox,
        })
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

struct CallHandler {
    action: ServiceAction,
    inbox: Sender<Inbox>,
}

impl Handler for CallHandler {
    fn call(&self, request: Request, responder: Responder) {
        let call = Inbox::Call {
            action: self.action,
            payload: request.into_payload().to_vec(),
            responder,
        };
        if let Err(std::sync::mpsc::SendError(Inbox::Call { responder, .. })) =
            self.inbox.send(call)
        {
            responder.respond_err("the bridge is shutting down".into());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use foxglove::websocket::ClientChannelId;

    fn channel(schema: &str, encoding: &str) -> ClientChannel {
        ClientChannel {
            id: ClientChannelId::new(1),
            topic: "/cmd_vel".into(),
            encoding: encoding.into(),
            schema_name: schema.into(),
            schema_encoding: None,
            schema: None,
        }
    }

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

    #[test]
    fn only_json_twist_channels_are_velocities() {
        assert!(check_twist_channel(&channel("geometry_msgs/Twist", "json")).is_ok());
        assert!(check_twist_channel(&channel("geometry_msgs/msg/Twist", "json")).is_ok());
        assert!(matches!(
            check_twist_channel(&channel("geometry_msgs/Twist", "cdr")),
            Err(TwistError::Encoding { .. })
        ));
        assert!(matches!(
            check_twist_channel(&channel("std_msgs/String", "json")),
            Err(TwistError::Schema { .. })
        ));
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
