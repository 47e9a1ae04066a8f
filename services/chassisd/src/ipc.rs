//! The service's iceoryx2 ports, every service created with explicit limits.
//!
//! | service (`chassis/<name>/…`) | pattern | payload |
//! | --- | --- | --- |
//! | `state` | publish-subscribe, history 1, + event | `ChassisState` |
//! | `frames` | publish-subscribe + event | `BusFrame` (both directions) |
//! | `mux` | publish-subscribe, history 1, + event | `MuxStatus` |
//! | `cmd/<source>` | publish-subscribe + event, one publisher | `VelocityRequest` |
//! | `control` | request-response + event | `ControlRequest` → `ControlResponse` |
//! | `sim` | request-response + event (simulated bus only) | `SimRequest` → `ControlResponse` |
//!
//! Each publish-subscribe service has an event service of the same name: the publisher notifies
//! after sending, so readers wait on a listener instead of polling.

use chassis_interfaces::{
    BusFrame, ChassisState, ControlRequest, ControlResponse, MuxStatus, STATE_BUFFER, ServiceKind,
    SimRequest, VelocityRequest, service_name,
};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::server::Server;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use thiserror::Error;

/// Environment variable naming the iceoryx2 file prefix (default `iox2_`): processes with
/// different prefixes never see each other (used to isolate tests running in parallel).
pub const IPC_PREFIX_ENV: &str = "CHASSIS_IPC_PREFIX";

/// Most subscribers of `state` and `mux` (clients, dashboards, benchmark fan-out).
pub const MAX_READERS: usize = 40;
/// Most nodes (processes) attached to one service.
pub const MAX_NODES: usize = 64;
/// Largest buffer a `frames` subscriber may ask for (a recorder draining in bursts).
pub const FRAMES_BUFFER: usize = 2048;
/// Most subscribers of `frames`.
pub const MAX_FRAME_READERS: usize = 8;

// The readers of `state` and `frames` are woken once per read of the bus: a reader must find
// room for a whole read.
const _: () = assert!(STATE_BUFFER >= crate::bus::MAX_RX_BATCH);
const _: () = assert!(FRAMES_BUFFER >= crate::bus::MAX_RX_BATCH);

pub type StatePublisher = Publisher<ipc::Service, ChassisState, ()>;
pub type FramePublisher = Publisher<ipc::Service, BusFrame, ()>;
pub type MuxPublisher = Publisher<ipc::Service, MuxStatus, ()>;
pub type CmdSubscriber = Subscriber<ipc::Service, VelocityRequest, ()>;
pub type ControlServer = Server<ipc::Service, ControlRequest, (), ControlResponse, ()>;
pub type SimServer = Server<ipc::Service, SimRequest, (), ControlResponse, ()>;
/// A server answered with `ControlResponse`.
pub type Answering<Request> = Server<ipc::Service, Request, (), ControlResponse, ()>;

/// Why the service's ports could not be set up.
#[derive(Debug, Error)]
pub enum IpcError {
    #[error(
        "another chassisd already serves the robot called '{name}' ({service} has its publisher); \
         stop it first or pick another --name"
    )]
    AlreadyServed { name: String, service: String },
    #[error("iceoryx2: {what}: {reason}")]
    Setup { what: String, reason: String },
}

fn setup<E: std::fmt::Debug>(what: impl Into<String>) -> impl FnOnce(E) -> IpcError {
    let what = what.into();
    move |e| IpcError::Setup {
        what,
        reason: format!("{e:?}"),
    }
}

/// iceoryx2 configuration honouring [`IPC_PREFIX_ENV`].
pub fn iceoryx_config() -> Result<Config, IpcError> {
    let mut config = Config::default();
    if let Ok(prefix) = std::env::var(IPC_PREFIX_ENV) {
        config.global.prefix = FileName::new(prefix.as_bytes()).map_err(setup(format!(
            "{IPC_PREFIX_ENV}={prefix} is not a valid file name prefix"
        )))?;
    }
    Ok(config)
}

fn service(name: &str) -> Result<ServiceName, IpcError> {
    name.try_into()
        .map_err(setup(format!("service name {name}")))
}

/// A publisher with its paired notifier.
#[derive(Debug)]
pub struct Outlet<P> {
    pub publisher: P,
    pub notifier: Notifier<ipc::Service>,
}

/// A velocity source: its subscriber and the listener its client notifies.
#[derive(Debug)]
pub struct Inlet {
    pub name: String,
    pub subscriber: CmdSubscriber,
    pub listener: Listener<ipc::Service>,
}

/// A request-response server and the listener its clients notify.
#[derive(Debug)]
pub struct Desk<S> {
    pub server: S,
    pub listener: Listener<ipc::Service>,
    /// Notifies clients that a response is ready.
    pub notifier: Notifier<ipc::Service>,
}

/// Every port of one running service.
#[derive(Debug)]
pub struct Ports {
    pub node: Node<ipc::Service>,
    pub state: Outlet<StatePublisher>,
    pub frames: Outlet<FramePublisher>,
    pub mux: Outlet<MuxPublisher>,
    pub sources: Vec<Inlet>,
    pub control: Desk<ControlServer>,
    pub sim: Option<Desk<SimServer>>,
}

fn event_pair(
    node: &Node<ipc::Service>,
    name: &ServiceName,
    notifiers: usize,
    listeners: usize,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<ipc::Service>, IpcError> {
    node.service_builder(name)
        .event()
        .max_nodes(MAX_NODES)
        .max_notifiers(notifiers)
        .max_listeners(listeners)
        .open_or_create()
        .map_err(setup(format!("event service {name}")))
}

impl Ports {
    /// Creates (or re-opens, after a crash) every service of the robot `robot_name`, with one
    /// `cmd/<source>` per source. Fails with [`IpcError::AlreadyServed`] when another process
    /// already publishes its state.
    pub fn open(robot_name: &str, sources: &[String], with_sim: bool) -> Result<Self, IpcError> {
        let config = iceoryx_config()?;
        let node = NodeBuilder::new()
            .name(
                &format!("chassisd/{robot_name}")
                    .as_str()
                    .try_into()
                    .map_err(setup("node name"))?,
            )
            .config(&config)
            .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
            .create::<ipc::Service>()
            .map_err(setup("creating the node"))?;

        // Ownership first: the state service admits one publisher.
        let state_name = service_name(robot_name, ServiceKind::State);
        let state_service = node
            .service_builder(&service(&state_name)?)
            .publish_subscribe::<ChassisState>()
            .history_size(1)
            // A state stream (`Robot::state_stream`) buffers a whole read of the bus.
            // The publisher's data segment holds a sample for every buffer slot of every
            // possible reader: MAX_READERS × (STATE_BUFFER + 2 borrowed) + 1 history + 2 loaned
            // = 10323 samples of 876 bytes (824 + iceoryx2's header): 8.6 MiB of shared memory.
            // Freed samples are reused first, so only the pages of the samples in flight become
            // resident: those the readers' queues hold.
            .subscriber_max_buffer_size(STATE_BUFFER)
            .max_publishers(1)
            .max_subscribers(MAX_READERS)
            .max_nodes(MAX_NODES)
            .enable_safe_overflow(true)
            .open_or_create()
            .map_err(setup(format!("service {state_name}")))?;
        let state_publisher = match state_service.publisher_builder().create() {
            Ok(p) => p,
            Err(iceoryx2::port::publisher::PublisherCreateError::ExceedsMaxSupportedPublishers) => {
                return Err(IpcError::AlreadyServed {
                    name: robot_name.to_string(),
                    service: state_name,
                });
            }
            Err(e) => return Err(setup(format!("publisher of {state_name}"))(e)),
        };
        let state_notifier = event_pair(&node, &service(&state_name)?, 2, MAX_READERS)?
            .notifier_builder()
            .create()
            .map_err(setup("state notifier"))?;

        let frames_name = service_name(robot_name, ServiceKind::Frames);
        let frames_publisher = node
            .service_builder(&service(&frames_name)?)
            .publish_subscribe::<BusFrame>()
            .history_size(0)
            .subscriber_max_buffer_size(FRAMES_BUFFER)
            .max_publishers(1)
            .max_subscribers(MAX_FRAME_READERS)
            .max_nodes(MAX_NODES)
            .enable_safe_overflow(true)
            .open_or_create()
            .map_err(setup(format!("service {frames_name}")))?
            .publisher_builder()
            .create()
            .map_err(setup(format!("publisher of {frames_name}")))?;
        let frames_notifier = event_pair(&node, &service(&frames_name)?, 2, MAX_FRAME_READERS)?
            .notifier_builder()
            .create()
            .map_err(setup("frames notifier"))?;

        let mux_name = service_name(robot_name, ServiceKind::Mux);
        let mux_publisher = node
            .service_builder(&service(&mux_name)?)
            .publish_subscribe::<MuxStatus>()
            .history_size(1)
            .subscriber_max_buffer_size(16)
            .max_publishers(1)
            .max_subscribers(MAX_READERS)
            .max_nodes(MAX_NODES)
            .enable_safe_overflow(true)
            .open_or_create()
            .map_err(setup(format!("service {mux_name}")))?
            .publisher_builder()
            .create()
            .map_err(setup(format!("publisher of {mux_name}")))?;
        let mux_notifier = event_pair(&node, &service(&mux_name)?, 2, MAX_READERS)?
            .notifier_builder()
            .create()
            .map_err(setup("mux notifier"))?;

        let mut inlets = Vec::with_capacity(sources.len());
        for source in sources {
            let name = service_name(robot_name, ServiceKind::Cmd(source));
            let subscriber = node
                .service_builder(&service(&name)?)
                .publish_subscribe::<VelocityRequest>()
                .history_size(0)
                .subscriber_max_buffer_size(16)
                // One process per source: a second publisher is refused.
                .max_publishers(1)
                .max_subscribers(4)
                .max_nodes(MAX_NODES)
                .enable_safe_overflow(true)
                .open_or_create()
                .map_err(setup(format!("service {name}")))?
                .subscriber_builder()
                .buffer_size(16)
                .create()
                .map_err(setup(format!("subscriber of {name}")))?;
            let listener = event_pair(&node, &service(&name)?, 2, 2)?
                .listener_builder()
                .create()
                .map_err(setup(format!("listener of {name}")))?;
            inlets.push(Inlet {
                name: source.clone(),
                subscriber,
                listener,
            });
        }

        let control =
            open_desk::<ControlRequest>(&node, &service_name(robot_name, ServiceKind::Control))?;
        let sim = if with_sim {
            Some(open_desk::<SimRequest>(
                &node,
                &service_name(robot_name, ServiceKind::Sim),
            )?)
        } else {
            None
        };

        Ok(Self {
            node,
            state: Outlet {
                publisher: state_publisher,
                notifier: state_notifier,
            },
            frames: Outlet {
                publisher: frames_publisher,
                notifier: frames_notifier,
            },
            mux: Outlet {
                publisher: mux_publisher,
                notifier: mux_notifier,
            },
            sources: inlets,
            control,
            sim,
        })
    }
}

/// A request-response service answered with `ControlResponse`, plus its paired events:
/// `<name>` (clients → server: "a request is waiting") and `<name>/reply` (server → clients).
pub fn open_desk<Request>(
    node: &Node<ipc::Service>,
    name: &str,
) -> Result<Desk<Answering<Request>>, IpcError>
where
    Request: std::fmt::Debug + ZeroCopySend + Copy + 'static,
{
    let server = node
        .service_builder(&service(name)?)
        .request_response::<Request, ControlResponse>()
        .max_servers(1)
        .max_clients(16)
        .max_active_requests_per_client(4)
        .max_response_buffer_size(4)
        .max_nodes(MAX_NODES)
        .enable_safe_overflow_for_requests(true)
        .enable_safe_overflow_for_responses(true)
        .open_or_create()
        .map_err(setup(format!("service {name}")))?
        .server_builder()
        .create()
        .map_err(|e| match e {
            iceoryx2::service::port_factory::server::ServerCreateError::ExceedsMaxSupportedServers => {
                IpcError::AlreadyServed {
                    name: name.to_string(),
                    service: name.to_string(),
                }
            }
            other => setup(format!("server of {name}"))(other),
        })?;
    let listener = event_pair(node, &service(name)?, 16, 2)?
        .listener_builder()
        .create()
        .map_err(setup(format!("listener of {name}")))?;
    let reply_name = format!("{name}/reply");
    let notifier = event_pair(node, &service(&reply_name)?, 2, 16)?
        .notifier_builder()
        .create()
        .map_err(setup(format!("notifier of {reply_name}")))?;
    Ok(Desk {
        server,
        listener,
        notifier,
    })
}
