//! The service's iceoryx2 ports. Names, limits and the builders are the contract's
//! (`chassis-ipc`): this module creates every service of one robot with them and holds the ports.

use chassis_interfaces::{
    BusFrame, ChassisState, ControlRequest, ControlResponse, MuxStatus, RobotDescription,
    SimRequest, VelocityRequest,
};
use chassis_ipc::{
    CMD, CONTROL, DESCRIPTION, FRAMES, MUX, Reader, RequestResponse, SIM, STATE, ServerPorts,
    ServiceKind, Writer, service_name,
};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::server::Server;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use thiserror::Error;

// The readers of `state` and `frames` are woken once per read of the bus: a reader must find
// room for a whole read.
const _: () = assert!(STATE.limits.subscriber_max_buffer_size >= crate::bus::MAX_RX_BATCH);
const _: () = assert!(FRAMES.limits.subscriber_max_buffer_size >= crate::bus::MAX_RX_BATCH);

pub type StatePublisher = Publisher<ipc::Service, ChassisState, ()>;
pub type FramePublisher = Publisher<ipc::Service, BusFrame, ()>;
pub type MuxPublisher = Publisher<ipc::Service, MuxStatus, ()>;
pub type DescriptionPublisher = Publisher<ipc::Service, RobotDescription, ()>;
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
    #[error(transparent)]
    Contract(#[from] chassis_ipc::IpcError),
}

/// iceoryx2 configuration honouring `CHASSIS_IPC_PREFIX` ([`chassis_ipc::IPC_PREFIX_ENV`]).
pub fn iceoryx_config() -> Result<Config, IpcError> {
    Ok(chassis_ipc::config(None)?)
}

/// A publisher with its paired notifier.
#[derive(Debug)]
pub struct Outlet<P> {
    pub publisher: P,
    pub notifier: Notifier<ipc::Service>,
}

impl<T: std::fmt::Debug + ZeroCopySend + 'static> From<Writer<T>>
    for Outlet<Publisher<ipc::Service, T, ()>>
{
    fn from(w: Writer<T>) -> Self {
        Self {
            publisher: w.publisher,
            notifier: w.notifier,
        }
    }
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
    pub description: Outlet<DescriptionPublisher>,
    pub sources: Vec<Inlet>,
    pub control: Desk<ControlServer>,
    pub sim: Option<Desk<SimServer>>,
}

impl Ports {
    /// Creates (or re-opens, after a crash) every service of the robot `robot_name`, with one
    /// `cmd/<source>` per source. Fails with [`IpcError::AlreadyServed`] when another process
    /// already publishes its state.
    pub fn open(robot_name: &str, sources: &[String], with_sim: bool) -> Result<Self, IpcError> {
        let node = chassis_ipc::node(
            Some(&format!("chassisd/{robot_name}")),
            &iceoryx_config()?,
            SignalHandlingMode::HandleTerminationRequests,
        )?;

        // Ownership first: the state service admits one publisher.
        let state_name = service_name(robot_name, ServiceKind::State);
        let state = match STATE.create(&node, &state_name)?.publisher() {
            Ok(writer) => writer,
            Err(chassis_ipc::IpcError::Taken { .. }) => {
                return Err(IpcError::AlreadyServed {
                    name: robot_name.to_string(),
                    service: state_name,
                });
            }
            Err(e) => return Err(e.into()),
        };
        let frames = FRAMES
            .create(&node, &service_name(robot_name, ServiceKind::Frames))?
            .publisher()?;
        let mux = MUX
            .create(&node, &service_name(robot_name, ServiceKind::Mux))?
            .publisher()?;
        let description = DESCRIPTION
            .create(&node, &service_name(robot_name, ServiceKind::Description))?
            .publisher()?;

        let mut inlets = Vec::with_capacity(sources.len());
        for source in sources {
            let Reader {
                subscriber,
                listener,
            } = CMD
                .create(&node, &service_name(robot_name, ServiceKind::Cmd(source)))?
                .subscriber(CMD.limits.subscriber_max_buffer_size)?;
            inlets.push(Inlet {
                name: source.clone(),
                subscriber,
                listener,
            });
        }

        let control = open_desk(
            &node,
            &CONTROL,
            &service_name(robot_name, ServiceKind::Control),
        )?;
        let sim = if with_sim {
            Some(open_desk(
                &node,
                &SIM,
                &service_name(robot_name, ServiceKind::Sim),
            )?)
        } else {
            None
        };

        Ok(Self {
            node,
            state: state.into(),
            frames: frames.into(),
            mux: mux.into(),
            description: description.into(),
            sources: inlets,
            control,
            sim,
        })
    }
}

/// The request-response service `name` of the contract's `spec`, answered with
/// `ControlResponse`, with its paired events: `<name>` (clients → server: "a request is
/// waiting") and its reply event (server → clients). Fails with [`IpcError::AlreadyServed`]
/// when another process already answers it.
pub fn open_desk<Request>(
    node: &Node<ipc::Service>,
    spec: &RequestResponse<Request>,
    name: &str,
) -> Result<Desk<Answering<Request>>, IpcError>
where
    Request: std::fmt::Debug + ZeroCopySend + Copy + 'static,
{
    let ServerPorts {
        server,
        requests,
        replies,
    } = spec.create(node, name)?.server().map_err(|e| match e {
        chassis_ipc::IpcError::Taken { .. } => IpcError::AlreadyServed {
            name: name.to_string(),
            service: name.to_string(),
        },
        other => other.into(),
    })?;
    Ok(Desk {
        server,
        listener: requests,
        notifier: replies,
    })
}
