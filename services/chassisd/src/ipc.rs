//! The service's iceoryx2 ports. Names, limits and the builders are the contract's
//! (`chassis-ipc`): this module creates every service of one robot with them and holds the ports,
//! and it cleans up what a killed predecessor left in iceoryx2's directories
//! ([`remove_unsized_segments`], [`remove_dead_nodes`], [`remove_abandoned_creations`]) so that
//! the ports can be created again.

use std::time::Duration;

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
use tracing::{debug, warn};

// The readers of `state` and `frames` are woken once per read of the bus: a reader must find
// room for a whole read.
const _: () = assert!(STATE.limits.subscriber_max_buffer_size >= chassis_bus::MAX_RX_BATCH);
const _: () = assert!(FRAMES.limits.subscriber_max_buffer_size >= chassis_bus::MAX_RX_BATCH);

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

        let name = |kind: ServiceKind<'_>| service_name(robot_name, kind);
        // Ownership first: the state service admits one publisher.
        let state_name = name(ServiceKind::State);
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
            .create(&node, &name(ServiceKind::Frames))?
            .publisher()?;
        let mux = MUX.create(&node, &name(ServiceKind::Mux))?.publisher()?;
        let description = DESCRIPTION
            .create(&node, &name(ServiceKind::Description))?
            .publisher()?;

        let mut inlets = Vec::with_capacity(sources.len());
        for source in sources {
            let Reader {
                subscriber,
                listener,
            } = CMD
                .create(&node, &name(ServiceKind::Cmd(source)))?
                .subscriber(CMD.limits.subscriber_max_buffer_size)?;
            inlets.push(Inlet {
                name: source.clone(),
                subscriber,
                listener,
            });
        }

        let control = open_desk(&node, &CONTROL, &name(ServiceKind::Control))?;
        let sim = with_sim
            .then(|| open_desk(&node, &SIM, &name(ServiceKind::Sim)))
            .transpose()?;

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

/// Removes what processes that died without cleaning up left behind (a service half created
/// included), so that a service they were creating can be created again.
pub fn remove_dead_nodes() {
    let Ok(config) = iceoryx_config() else {
        return;
    };
    let listed = Node::<ipc::Service>::list(&config, |state| {
        if let iceoryx2::node::NodeState::Dead(dead) = state
            && let Err(e) = dead.try_remove_stale_resources()
        {
            debug!("removing a dead node's resources: {e}");
        }
        CallbackProgression::Continue
    });
    if let Err(e) = listed {
        debug!("listing iceoryx2 nodes: {e}");
    }
}

/// How old a half-created service must be before it counts as abandoned: iceoryx2 gives up
/// opening one after its creation timeout (500 ms by default); nothing takes seconds to create.
pub const ABANDONED_AFTER: Duration = Duration::from_secs(2);

/// Removes the static files of services whose creator died before finishing them. iceoryx2
/// writes such a file owner-writable and makes it read-only once the service is complete; a
/// process killed in between leaves a file no cleanup of dead nodes removes (the service never
/// listed the node), and every later open or create fails with `HangsInCreation`. Only files of
/// this process' iceoryx2 prefix, still writable, and older than [`ABANDONED_AFTER`] go.
pub fn remove_abandoned_creations() {
    let Ok(config) = iceoryx_config() else {
        return;
    };
    let global = &config.global;
    let dir =
        std::path::Path::new(global.root_path().as_str()).join(global.service.directory.as_str());
    // Modification times are wall-clock times: the one reading of the system clock here.
    #[allow(clippy::disallowed_methods)]
    let now = std::time::SystemTime::now();
    for file in abandoned_creations(&dir, global.prefix.as_str(), now) {
        match std::fs::remove_file(dir.join(&file)) {
            Ok(()) => warn!(file, "removed a service its creator abandoned half created"),
            Err(e) => debug!(file, "removing an abandoned service file: {e}"),
        }
    }
}

/// The files in `dir` of the iceoryx2 `prefix` that are still writable (unfinished) and older
/// than [`ABANDONED_AFTER`] at `now`.
fn abandoned_creations(
    dir: &std::path::Path,
    prefix: &str,
    now: std::time::SystemTime,
) -> Vec<String> {
    use std::os::unix::fs::PermissionsExt;
    files_of_prefix(dir, prefix)
        .into_iter()
        .filter_map(|(file, meta)| {
            let writable = meta.permissions().mode() & 0o200 != 0;
            let age = now.duration_since(meta.modified().ok()?).ok()?;
            (writable && age >= ABANDONED_AFTER).then_some(file)
        })
        .collect()
}

/// The regular files in `dir` of the iceoryx2 `prefix`, with their metadata.
fn files_of_prefix(dir: &std::path::Path, prefix: &str) -> Vec<(String, std::fs::Metadata)> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    entries
        .flatten()
        .filter_map(|entry| {
            let file = entry.file_name().to_str()?.to_string();
            let meta = entry.metadata().ok()?;
            (file.starts_with(prefix) && meta.is_file()).then_some((file, meta))
        })
        .collect()
}

/// Where POSIX shared memory lives on Linux: iceoryx2's segments are files here.
const SHM_DIR: &str = "/dev/shm";

/// How long a shared-memory segment may stay empty before it counts as abandoned: its creator
/// sizes it right after making it, and iceoryx2 gives a whole creation 500 ms.
pub const UNSIZED_AFTER: Duration = Duration::from_millis(500);

/// Removes the shared-memory segments whose creator died between making them and sizing them
/// (a chassisd killed while it created its services). iceoryx2 0.10 retries opening an empty
/// segment without a timeout (`posix_shared_memory`'s open treats a zero-size mapping as "not
/// yet"), and removing a dead node opens every service it used: without this, a restart after
/// such a kill would hang in [`remove_dead_nodes`] for good, before it logs a line. A segment
/// younger than [`UNSIZED_AFTER`] may have a live creator about to size it: it is waited for,
/// at most that long, and removed only if it is still empty then.
pub fn remove_unsized_segments() {
    let Ok(config) = iceoryx_config() else {
        return;
    };
    let prefix = config.global.prefix.as_str();
    let dir = std::path::Path::new(SHM_DIR);
    const PAUSE: Duration = Duration::from_millis(50);
    let rounds = UNSIZED_AFTER.as_millis() / PAUSE.as_millis();
    for round in 0..=rounds {
        // Modification times are wall-clock times: the one reading of the system clock here.
        #[allow(clippy::disallowed_methods)]
        let now = std::time::SystemTime::now();
        let (old, young) = unsized_segments(dir, prefix, now);
        // In the last round, a segment seen empty all along is abandoned whatever its time says.
        let last = round == rounds;
        let abandoned = if last {
            [old, young.clone()].concat()
        } else {
            old
        };
        for file in abandoned {
            match std::fs::remove_file(dir.join(&file)) {
                Ok(()) => warn!(
                    file,
                    "removed a shared-memory segment its creator never sized"
                ),
                Err(e) => debug!(file, "removing an unsized segment: {e}"),
            }
        }
        if last || young.is_empty() {
            return;
        }
        // The ports are not open yet: nothing else waits on this thread.
        #[allow(clippy::disallowed_methods)]
        std::thread::sleep(PAUSE);
    }
}

/// The empty, uninitialised (not yet readable) segments of the iceoryx2 `prefix` in `dir`: those
/// older than [`UNSIZED_AFTER`] at `now`, and the younger ones.
fn unsized_segments(
    dir: &std::path::Path,
    prefix: &str,
    now: std::time::SystemTime,
) -> (Vec<String>, Vec<String>) {
    use std::os::unix::fs::PermissionsExt;
    let (mut old, mut young) = (Vec::new(), Vec::new());
    for (file, meta) in files_of_prefix(dir, prefix) {
        let unreadable = meta.permissions().mode() & 0o400 == 0;
        if meta.len() != 0 || !unreadable {
            continue;
        }
        let age = meta
            .modified()
            .ok()
            .and_then(|m| now.duration_since(m).ok())
            .unwrap_or(Duration::ZERO);
        if age >= UNSIZED_AFTER {
            old.push(file);
        } else {
            young.push(file);
        }
    }
    (old, young)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    #[test]
    // File modification times are wall-clock times: the test compares with the system clock.
    #[allow(clippy::disallowed_methods)]
    fn only_old_unfinished_files_of_the_prefix_are_abandoned() {
        let dir = std::env::temp_dir().join(format!("chassisd-abandoned-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let make = |name: &str, mode: u32| {
            let path = dir.join(name);
            std::fs::write(&path, b"x").unwrap();
            std::fs::set_permissions(&path, std::fs::Permissions::from_mode(mode)).unwrap();
        };
        make("px_half.service", 0o600);
        make("px_done.service", 0o400);
        make("other_half.service", 0o600);
        let later = std::time::SystemTime::now() + Duration::from_secs(3);
        assert_eq!(
            abandoned_creations(&dir, "px_", later),
            vec!["px_half.service"]
        );
        // Young enough to be a creation in progress.
        assert!(abandoned_creations(&dir, "px_", std::time::SystemTime::now()).is_empty());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    // File modification times are wall-clock times: the test compares with the system clock.
    #[allow(clippy::disallowed_methods)]
    fn only_empty_unreadable_segments_of_the_prefix_are_unsized() {
        let dir = std::env::temp_dir().join(format!("chassisd-unsized-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let make = |name: &str, bytes: &[u8], mode: u32| {
            let path = dir.join(name);
            std::fs::write(&path, bytes).unwrap();
            std::fs::set_permissions(&path, std::fs::Permissions::from_mode(mode)).unwrap();
        };
        make("px_empty.dynamic", b"", 0o200);
        make("px_sized.dynamic", b"x", 0o200);
        make("px_ready.dynamic", b"", 0o600);
        make("other_empty.dynamic", b"", 0o200);
        let later = std::time::SystemTime::now() + Duration::from_secs(1);
        let (old, young) = unsized_segments(&dir, "px_", later);
        assert_eq!((old, young), (vec!["px_empty.dynamic".to_string()], vec![]));
        let (old, young) = unsized_segments(&dir, "px_", std::time::SystemTime::now());
        assert_eq!((old, young), (vec![], vec!["px_empty.dynamic".to_string()]));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
