//! `chassis-ipc`: the iceoryx2 contract between `chassisd` and its clients, written once.
//!
//! | service (`chassis/<robot>/…`) | pattern | payload | created by |
//! | --- | --- | --- | --- |
//! | `state` | publish-subscribe, history 1, + event | `ChassisState` | `chassisd` |
//! | `frames` | publish-subscribe + event | `BusFrame` (both directions) | `chassisd` |
//! | `mux` | publish-subscribe, history 1, + event | `MuxStatus` | `chassisd` |
//! | `robot` | publish-subscribe, history 1, + event | `RobotDescription` | `chassisd` |
//! | `cmd/<source>` | publish-subscribe + event, one publisher | `VelocityRequest` | `chassisd` |
//! | `control` | request-response + 2 events | `ControlRequest` → `ControlResponse` | `chassisd` |
//! | `sim` | request-response + 2 events | `SimRequest` → `ControlResponse` | `chassisd` (simulated bus), `chassisd sim` |
//! | `<suffix>` | publish-subscribe, history 1, + event | any, e.g. `SafetyStatus` on `safety` | a client ([`publication`]) |
//!
//! Each publish-subscribe service has an event service of the same name: the publisher notifies
//! after sending, so readers wait on a listener instead of polling. A request-response service
//! has two: `<name>` (clients → server, "a request is waiting") and [`reply_name`]`(<name>)`
//! (server → clients, "an answer is ready").
//!
//! With iceoryx2 0.10 the process that creates a service fixes its limits, so the owner of each
//! service creates it with the limits here ([`PubSub::create`], [`RequestResponse::create`]),
//! and every other process only opens it ([`PubSub::open`], [`RequestResponse::open`]): a client
//! started before `chassisd` gets [`IpcError::NotFound`] instead of creating a service with
//! other limits. Safe overflow is on everywhere, so a reader killed mid-read never blocks a
//! publisher.
//!
//! [`contract::document`] describes all of it — services, limits, the prefix variable and the
//! layout of every payload — as JSON (`chassis interfaces --json`, committed as
//! `interfaces/contract.json`), the source of the mirrors in other languages.

pub mod contract;
mod error;
mod files;
mod limits;
mod names;
mod ports;
mod trace;

pub use error::IpcError;
pub use files::{foreign_folder, ipc_files, remove_ipc_files, user_name};
pub use limits::{
    CMD, CONTROL, DESCRIPTION, EventLimits, FRAMES, FRAMES_BUFFER, MAX_CLIENTS, MAX_FRAME_READERS,
    MAX_NODES, MAX_READERS, MUX, PUBLICATION, PubSub, PubSubLimits, RequestResponse,
    RequestResponseLimits, SIM, STATE, STATE_BUFFER, publication,
};
pub use names::{
    IPC_PREFIX_ENV, REPLY_SUFFIX, ServiceKind, TEST_LOOP_STALL_ENV, config, reply_name, robots,
    service_name,
};
pub use ports::{ClientPorts, Exchange, Reader, ServerPorts, Topic, Writer, node};
pub use trace::{PassStamps, StampTrace, Trace, TraceError};
