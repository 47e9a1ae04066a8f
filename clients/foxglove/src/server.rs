//! The Foxglove side: the WebSocket server's callbacks, which run on its own threads, turn
//! into [`Inbox`] messages for the robot loop (iceoryx2 ports are not `Send`: only that loop
//! touches them). Nothing here talks to the robot.

use std::sync::mpsc::Sender;

use chassis_client::VelocityRequest;
use chassis_foxglove_messages::{self as messages, ServiceAction, TwistError, response_schema};
use foxglove::Schema;
use foxglove::websocket::service::{Handler, Request, Responder, Service, ServiceSchema};
use foxglove::websocket::{Client, ClientChannel, ServerListener, Status};
use serde_json::Value;

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

/// Checks a client channel carries Twists as JSON.
pub fn check_twist_channel(channel: &ClientChannel) -> Result<(), TwistError> {
    messages::check_twist_channel(&channel.topic, &channel.schema_name, &channel.encoding)
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
        let request = check_twist_channel(channel)
            .and_then(|()| messages::twist_request(&channel.topic, payload));
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

/// The service advertised to clients for `action`, handing its calls to the robot loop.
pub fn service(action: ServiceAction, inbox: Sender<Inbox>) -> Service {
    let schema_name = format!("chassis{}", action.name().replace('/', "."));
    let json_schema = |name: String, value: &Value| {
        Schema::new(name, "jsonschema", value.to_string().into_bytes())
    };
    let schema = ServiceSchema::new(schema_name.clone())
        .with_request(
            "json",
            json_schema(format!("{schema_name}.Request"), &action.request_schema()),
        )
        .with_response(
            "json",
            json_schema(format!("{schema_name}.Response"), &response_schema()),
        );
    Service::builder(action.name(), schema).handler(CallHandler { action, inbox })
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
}
