//! The Foxglove side: the WebSocket server, its channels, and its callbacks, which run on the
//! server's own threads and turn into [`Inbox`] messages for the loop of the robot they address
//! (iceoryx2 ports are not `Send`: only that loop touches them). Nothing here talks to a robot.

use std::sync::Arc;
use std::sync::mpsc::Sender;
use std::time::Duration;

use anyhow::Context as _;
use chassis_client::foxglove::schema_of;
use chassis_client::{ChassisState, MuxStatus, SafetyStatus, ValidRequest};
use chassis_foxglove_messages::{self as messages, ServiceAction, TwistError, response_schema};
use foxglove::messages::{FrameTransforms, LocationFix, Log, PoseInFrame, SceneUpdate};
use foxglove::websocket::service::{Handler, Request, Responder, Service, ServiceSchema};
use foxglove::websocket::{Capability, Client, ClientChannel, ServerListener, Status};
use foxglove::{Channel, Context, RawChannel, Schema, WebSocketServer, WebSocketServerHandle};
use serde_json::Value;

use crate::convert::{frames_schema, mux_json, safety_json};
use crate::naming::Naming;

/// The channels the bridge logs one robot to.
#[derive(Debug)]
pub struct Channels {
    pub tf: Channel<FrameTransforms>,
    pub pose: Channel<PoseInFrame>,
    pub scene: Channel<SceneUpdate>,
    pub gps: Channel<LocationFix>,
    pub log: Channel<Log>,
    pub state: Arc<RawChannel>,
    pub mux: Arc<RawChannel>,
    pub safety: Arc<RawChannel>,
    pub frames: Arc<RawChannel>,
}

impl Channels {
    /// Creates the channels of the robot `naming` names in `ctx`: Foxglove's well-known
    /// messages, and JSON channels whose schemas name every field of the IPC types.
    pub fn new(ctx: &Arc<Context>, naming: &Naming) -> anyhow::Result<Self> {
        let json_channel = |topic: &str, schema_name: &str, schema: Value| {
            let topic = naming.topic(topic);
            ctx.channel_builder(&topic)
                .message_encoding("json")
                .schema(Schema::new(
                    schema_name,
                    "jsonschema",
                    schema.to_string().into_bytes(),
                ))
                .build_raw()
                .with_context(|| format!("creating {topic}"))
        };
        let state_value = serde_json::to_value(ChassisState::default())?;
        let mux_value = mux_json(&MuxStatus::default())?;
        let safety_value = safety_json(&SafetyStatus::default())?;
        Ok(Self {
            tf: ctx.channel_builder(naming.topic("/tf")).build(),
            pose: ctx.channel_builder(naming.topic("/pose")).build(),
            scene: ctx.channel_builder(naming.topic("/scene")).build(),
            gps: ctx.channel_builder(naming.topic("/gps")).build(),
            log: ctx.channel_builder(naming.topic("/log")).build(),
            state: json_channel("/state", "chassis.ChassisState", schema_of(&state_value))?,
            mux: json_channel("/mux", "chassis.MuxStatus", schema_of(&mux_value))?,
            safety: json_channel("/safety", "chassis.SafetyStatus", schema_of(&safety_value))?,
            frames: json_channel("/frames", "chassis.Frames", frames_schema())?,
        })
    }
}

/// One robot's loop, as the server reaches it.
#[derive(Debug, Clone)]
pub struct Route {
    pub naming: Naming,
    pub inbox: Sender<Inbox>,
}

/// What the bridge is told.
#[derive(Debug, Clone)]
pub struct Config {
    /// chassisd's robot names (`chassis/<name>/…`): one, or several each under its own prefix.
    pub names: Vec<String>,
    /// Address and TCP port of the WebSocket server (port 0: any free port).
    pub bind: String,
    pub port: u16,
    /// Shortest time between two published state samples.
    pub state_period: Duration,
    /// Take client channels (the Teleop panel) as the `foxglove` source and offer every
    /// service; off: only `/estop`.
    pub drive: bool,
}

/// Starts the WebSocket server of `ctx` on `config.bind:config.port`: each robot's services and
/// client publishing (the Teleop panel) unless `config.drive` is off, when only its `/estop` is
/// offered. A client message or service call goes to the loop of the robot it addresses.
pub fn start(
    ctx: &Arc<Context>,
    config: &Config,
    routes: &[Route],
) -> anyhow::Result<WebSocketServerHandle> {
    let actions: Vec<ServiceAction> = if config.drive {
        ServiceAction::ALL.to_vec()
    } else {
        vec![ServiceAction::Estop]
    };
    let mut capabilities = vec![Capability::Services];
    if config.drive {
        capabilities.push(Capability::ClientPublish);
    }
    WebSocketServer::new()
        .context(ctx)
        .name(format!("chassis-foxglove {}", config.names.join(",")))
        .bind(config.bind.clone(), config.port)
        .capabilities(capabilities)
        .supported_encodings(["json"])
        .listener(Arc::new(Listener {
            routes: routes.to_vec(),
        }))
        .services(routes.iter().flat_map(|route| {
            actions
                .iter()
                .map(|&a| service(a, &route.naming, route.inbox.clone()))
        }))
        .start_blocking()
        .with_context(|| format!("serving on {}:{}", config.bind, config.port))
}

/// What the server's callbacks ask of the robot loop.
#[derive(Debug)]
pub enum Inbox {
    /// A velocity from a client's Twist channel, parsed.
    Twist(ValidRequest),
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

/// The server's listener: client publishes become [`Inbox`] messages for the robot whose
/// prefix their topic carries (any topic, when the bridge serves one robot).
#[derive(Debug)]
pub struct Listener {
    pub routes: Vec<Route>,
}

impl Listener {
    fn route(&self, topic: &str) -> Option<&Route> {
        self.routes.iter().find(|r| r.naming.owns(topic))
    }

    /// Why a client's topic reaches no robot.
    fn unrouted(&self, topic: &str) -> String {
        let prefixes: Vec<String> = self.routes.iter().map(|r| r.naming.topic("/…")).collect();
        format!(
            "{topic} names no robot this bridge serves (velocities go to {}): its messages are ignored",
            prefixes.join(", ")
        )
    }
}

impl ServerListener for Listener {
    fn on_client_advertise(&self, client: Client, channel: &ClientChannel) {
        match check_twist_channel(channel) {
            Ok(()) if self.route(&channel.topic).is_none() => {
                client.send_status(Status::warning(self.unrouted(&channel.topic)));
            }
            Ok(()) => tracing::info!(topic = channel.topic, "a client publishes velocities"),
            Err(e) => {
                tracing::debug!(error = %e, "client channel refused");
                client.send_status(Status::warning(format!("{e}: its messages are ignored")));
            }
        }
    }

    fn on_client_unadvertise(&self, _client: Client, channel: &ClientChannel) {
        if check_twist_channel(channel).is_ok()
            && let Some(route) = self.route(&channel.topic)
            && route.inbox.send(Inbox::TwistEnded).is_err()
        {
            tracing::debug!("the robot loop has ended");
        }
    }

    fn on_message_data(&self, client: Client, channel: &ClientChannel, payload: &[u8]) {
        let request = check_twist_channel(channel)
            .and_then(|()| messages::twist_request(&channel.topic, payload));
        match request {
            Ok(request) => match self.route(&channel.topic) {
                Some(route) => {
                    if route.inbox.send(Inbox::Twist(request)).is_err() {
                        tracing::debug!("the robot loop has ended");
                    }
                }
                None => tracing::debug!(topic = channel.topic, "a velocity for no robot"),
            },
            Err(e) => {
                tracing::debug!(error = %e, "client message ignored");
                client.send_status(Status::warning(e.to_string()));
            }
        }
    }
}

/// The service advertised to clients for `action` on the robot `naming` names, handing its
/// calls to that robot's loop.
pub fn service(action: ServiceAction, naming: &Naming, inbox: Sender<Inbox>) -> Service {
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
    Service::builder(naming.topic(action.name()), schema).handler(CallHandler { action, inbox })
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
