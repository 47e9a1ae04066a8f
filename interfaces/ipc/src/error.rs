//! What can go wrong creating or opening the contract's services and ports.

use thiserror::Error;

use crate::IPC_PREFIX_ENV;

/// An iceoryx2 error, shown with its own `Display`.
type Cause = Box<dyn std::error::Error + Send + Sync>;

/// Why a service or a port of the contract could not be set up.
#[derive(Debug, Error)]
pub enum IpcError {
    /// The iceoryx2 file prefix is not a valid file name.
    #[error("{IPC_PREFIX_ENV}={prefix} is not a valid iceoryx2 file name prefix: {error}")]
    Prefix { prefix: String, error: Cause },
    /// A robot, source or suffix made a service name iceoryx2 refuses.
    #[error("'{name}' is not a valid iceoryx2 service name: {error}")]
    ServiceName { name: String, error: Cause },
    /// The iceoryx2 node could not be created.
    #[error("creating the iceoryx2 node: {0}")]
    Node(Cause),
    /// iceoryx2's folder belongs to another user (whose program ran first).
    #[error(
        "{folder} belongs to user {owner}, whose program made it first: iceoryx2 keeps every \
         other user out of it. Stop that user's programs and remove it (rm -rf /tmp/iceoryx2 \
         /dev/shm/iox2_*), or run every program of the robot as {owner}"
    )]
    ForeignFolder { folder: String, owner: String },
    /// Opening a service nobody has created (its owner is not running).
    #[error("no service {service}")]
    NotFound { service: String },
    /// A port the contract allows only one of (the publisher of `state` or of a source, the
    /// server of `control`) is held by another process.
    #[error("{service} already has its {port} (another process holds it)")]
    Taken { service: String, port: &'static str },
    /// Any other failure creating or opening a service.
    #[error("{what} {service}: {error}")]
    Service {
        service: String,
        what: &'static str,
        error: Cause,
    },
    /// Any other failure creating a port.
    #[error("creating the {port} of {service}: {error}")]
    Port {
        service: String,
        port: &'static str,
        error: Cause,
    },
}

impl IpcError {
    pub(crate) fn service<E: std::error::Error + Send + Sync + 'static>(
        service: &str,
        what: &'static str,
    ) -> impl FnOnce(E) -> Self {
        move |e| Self::Service {
            service: service.to_string(),
            what,
            error: Box::new(e),
        }
    }

    /// The error of opening `service`: [`IpcError::NotFound`] when `missing` says it does not
    /// exist, [`IpcError::Service`] otherwise.
    pub(crate) fn opening<E: std::error::Error + Send + Sync + 'static>(
        service: &str,
        what: &'static str,
        missing: fn(&E) -> bool,
    ) -> impl FnOnce(E) -> Self {
        move |e| {
            if missing(&e) {
                Self::NotFound {
                    service: service.to_string(),
                }
            } else {
                Self::service(service, what)(e)
            }
        }
    }

    pub(crate) fn port<E: std::error::Error + Send + Sync + 'static>(
        service: &str,
        port: &'static str,
    ) -> impl FnOnce(E) -> Self {
        move |e| Self::Port {
            service: service.to_string(),
            port,
            error: Box::new(e),
        }
    }
}
