//! Every limit of every service, and which payload each service carries.

use std::marker::PhantomData;

use chassis_interfaces::{
    BusFrame, ChassisState, ControlRequest, MuxStatus, RobotDescription, SimRequest,
    VelocityRequest,
};
use serde::Serialize;

/// Most processes attached to one service (publish-subscribe, request-response or event).
pub const MAX_NODES: usize = 64;
/// Most readers of `state`, `mux` and of a client's publication (clients, dashboards, benchmark
/// fan-out); each holds one subscriber and one listener.
pub const MAX_READERS: usize = 40;
/// Most `ChassisState` samples a subscriber of `chassis/<robot>/state` may buffer: the state
/// service's `subscriber_max_buffer_size`, and the most a client's state stream can ask for.
///
/// The service publishes one sample per bus frame that changes the state and wakes the readers
/// once per read of the bus. On a saturated bus it reads once per 4 ms: ≈ 18 samples per read at
/// 500 kbit/s, ≈ 36 at 1 Mbit/s (8-byte standard frames, 111 bits each). A read takes at most
/// 256 frames (`chassisd`'s `MAX_RX_BATCH`), the backlog of a service held up for ≈ 57 ms at
/// 500 kbit/s (≈ 28 ms at 1 Mbit/s): a reader needs room for one whole read before it is even
/// woken. 256 holds it; a reader woken at every read of a moderated 500 kbit/s bus may be ≈ 55 ms
/// late before it loses a sample.
pub const STATE_BUFFER: usize = 256;
/// Largest buffer a `frames` subscriber may ask for (a recorder draining in bursts).
pub const FRAMES_BUFFER: usize = 2048;
/// Most subscribers of `frames`.
pub const MAX_FRAME_READERS: usize = 8;
/// Most clients of `control` and of `sim` (every client process opens one).
pub const MAX_CLIENTS: usize = 16;
/// Notifiers of a publish-subscribe service's event: its publisher's, and room for the one of a
/// restarted publisher while iceoryx2 has not yet cleaned up after the dead one.
const PUBLISHER_NOTIFIERS: usize = 2;
/// Samples a subscriber of `mux` or of a source may buffer.
const STATUS_BUFFER: usize = 16;
/// Buffer of a client's publication: its readers want the latest sample.
const PUBLICATION_BUFFER: usize = 4;

/// Limits of an event service.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct EventLimits {
    pub max_notifiers: usize,
    pub max_listeners: usize,
    pub max_nodes: usize,
}

/// Limits of a publish-subscribe service, and of the event service of the same name that wakes
/// its readers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct PubSubLimits {
    /// Samples a new subscriber receives from before it connected.
    pub history_size: usize,
    pub subscriber_max_buffer_size: usize,
    pub max_publishers: usize,
    pub max_subscribers: usize,
    pub max_nodes: usize,
    /// A full subscriber buffer drops its oldest sample instead of blocking the publisher.
    pub safe_overflow: bool,
    #[serde(skip)]
    pub event: EventLimits,
}

impl PubSubLimits {
    /// One publisher to at most `readers` subscribers, each woken by its listener, with a
    /// buffer of `buffer` samples that drops its oldest when full; `history_size` samples for a
    /// late joiner.
    pub const fn broadcast(history_size: usize, buffer: usize, readers: usize) -> Self {
        Self {
            history_size,
            subscriber_max_buffer_size: buffer,
            max_publishers: 1,
            max_subscribers: readers,
            max_nodes: MAX_NODES,
            safe_overflow: true,
            event: EventLimits {
                max_notifiers: PUBLISHER_NOTIFIERS,
                max_listeners: readers,
                max_nodes: MAX_NODES,
            },
        }
    }
}

/// Limits of a request-response service and of its two event services.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct RequestResponseLimits {
    pub max_servers: usize,
    pub max_clients: usize,
    pub max_active_requests_per_client: usize,
    pub max_response_buffer_size: usize,
    pub max_nodes: usize,
    pub safe_overflow_for_requests: bool,
    pub safe_overflow_for_responses: bool,
    /// `<name>`: clients notify, the server listens.
    #[serde(skip)]
    pub request_event: EventLimits,
    /// `<name>/reply`: the server notifies, clients listen.
    #[serde(skip)]
    pub reply_event: EventLimits,
}

/// A publish-subscribe service carrying `T`, with its limits.
#[derive(Debug)]
pub struct PubSub<T> {
    pub limits: PubSubLimits,
    payload: PhantomData<fn() -> T>,
}

impl<T> PubSub<T> {
    pub const fn new(limits: PubSubLimits) -> Self {
        Self {
            limits,
            payload: PhantomData,
        }
    }
}

/// A request-response service asked with `Req` and answered with `ControlResponse`, with its
/// limits.
#[derive(Debug)]
pub struct RequestResponse<Req> {
    pub limits: RequestResponseLimits,
    request: PhantomData<fn() -> Req>,
}

impl<Req> RequestResponse<Req> {
    pub const fn new(limits: RequestResponseLimits) -> Self {
        Self {
            limits,
            request: PhantomData,
        }
    }
}

/// `chassis/<robot>/state`: one publisher (the ownership check: a second `chassisd` for the same
/// robot is refused), history 1 (a late joiner gets the latest state).
///
/// The publisher's data segment holds a sample for every buffer slot of every possible reader:
/// `MAX_READERS` × (`STATE_BUFFER` + 2 borrowed) + 1 history + 2 loaned = 10323 samples of
/// 956 bytes (904 + iceoryx2's header): 9.4 MiB of shared memory. Freed samples are reused first,
/// so only the pages of the samples in flight become resident: those the readers' queues hold.
pub const STATE: PubSub<ChassisState> =
    PubSub::new(PubSubLimits::broadcast(1, STATE_BUFFER, MAX_READERS));

/// `chassis/<robot>/frames`: every frame on the bus, both directions; no history.
pub const FRAMES: PubSub<BusFrame> =
    PubSub::new(PubSubLimits::broadcast(0, FRAMES_BUFFER, MAX_FRAME_READERS));

/// `chassis/<robot>/mux`: the mux's decisions, history 1.
pub const MUX: PubSub<MuxStatus> =
    PubSub::new(PubSubLimits::broadcast(1, STATUS_BUFFER, MAX_READERS));

/// `chassis/<robot>/robot`: the robot's description, history 1 (a client started an hour later
/// reads it at once). Published at start and when it changes (the protocol once detected).
pub const DESCRIPTION: PubSub<RobotDescription> =
    PubSub::new(PubSubLimits::broadcast(1, 2, MAX_READERS));

/// `chassis/<robot>/cmd/<source>`: one publisher (one process per source: a second one is
/// refused), read by `chassisd` with a buffer of `subscriber_max_buffer_size`.
pub const CMD: PubSub<VelocityRequest> = PubSub::new(PubSubLimits {
    history_size: 0,
    subscriber_max_buffer_size: STATUS_BUFFER,
    max_publishers: 1,
    max_subscribers: 4,
    max_nodes: MAX_NODES,
    safe_overflow: true,
    event: EventLimits {
        max_notifiers: PUBLISHER_NOTIFIERS,
        max_listeners: 2,
        max_nodes: MAX_NODES,
    },
});

const DESK: RequestResponseLimits = RequestResponseLimits {
    max_servers: 1,
    max_clients: MAX_CLIENTS,
    max_active_requests_per_client: 4,
    max_response_buffer_size: 4,
    max_nodes: MAX_NODES,
    safe_overflow_for_requests: true,
    safe_overflow_for_responses: true,
    request_event: EventLimits {
        max_notifiers: MAX_CLIENTS,
        max_listeners: 2,
        max_nodes: MAX_NODES,
    },
    reply_event: EventLimits {
        max_notifiers: 2,
        max_listeners: MAX_CLIENTS,
        max_nodes: MAX_NODES,
    },
};

/// `chassis/<robot>/control`: one server, `chassisd`.
pub const CONTROL: RequestResponse<ControlRequest> = RequestResponse::new(DESK);

/// `chassis/<robot>/sim`: one server, the simulated chassis (embedded in `chassisd`, or
/// `chassisd sim`).
pub const SIM: RequestResponse<SimRequest> = RequestResponse::new(DESK);

/// Limits of a client's own publication ([`publication`]).
pub const PUBLICATION: PubSubLimits = PubSubLimits::broadcast(1, PUBLICATION_BUFFER, MAX_READERS);

/// A client's own publish-subscribe service beside the robot's,
/// `chassis/<robot>/<suffix>` ([`crate::ServiceKind::Publication`]): history 1 (a late reader
/// gets the latest sample), one publisher, [`PUBLICATION`]'s limits.
pub const fn publication<T>() -> PubSub<T> {
    PubSub::new(PUBLICATION)
}
