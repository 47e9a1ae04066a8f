//! The port builders both sides use: the owner of a service creates it with the contract's
//! limits, every other process opens it.

use std::fmt::Debug;

use chassis_interfaces::ControlResponse;
use iceoryx2::port::client::Client;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::{Notifier, NotifierCreateError};
use iceoryx2::port::publisher::{Publisher, PublisherCreateError};
use iceoryx2::port::server::Server;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::builder::event::EventOpenError;
use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenError;
use iceoryx2::service::builder::request_response::RequestResponseOpenError;
use iceoryx2::service::port_factory::server::ServerCreateError;
use iceoryx2::service::port_factory::{event, publish_subscribe, request_response};

use crate::limits::{EventLimits, PubSub, RequestResponse};
use crate::names::iceoryx_name;
use crate::{IpcError, reply_name};

/// Creates an iceoryx2 node (named `name`, when given) with `config`.
pub fn node(
    name: Option<&str>,
    config: &Config,
    signals: SignalHandlingMode,
) -> Result<Node<ipc::Service>, IpcError> {
    let mut builder = NodeBuilder::new()
        .config(config)
        .signal_handling_mode(signals);
    if let Some(name) = name {
        let node_name: NodeName = name.try_into().map_err(|e| IpcError::ServiceName {
            name: name.to_string(),
            error: Box::new(e),
        })?;
        builder = builder.name(&node_name);
    }
    builder
        .create::<ipc::Service>()
        .map_err(|e| match crate::foreign_folder() {
            Some((folder, owner)) => IpcError::ForeignFolder {
                folder: folder.display().to_string(),
                owner,
            },
            None => IpcError::Node(Box::new(e)),
        })
}

/// A listener of the event service `events` (called `name` in errors).
fn listener(
    events: &event::PortFactory<ipc::Service>,
    name: &str,
) -> Result<Listener<ipc::Service>, IpcError> {
    events
        .listener_builder()
        .create()
        .map_err(IpcError::port(name, "listener"))
}

/// A notifier of the event service `events` (called `name` in errors).
fn notifier(
    events: &event::PortFactory<ipc::Service>,
    name: &str,
) -> Result<Notifier<ipc::Service>, IpcError> {
    events
        .notifier_builder()
        .create()
        .map_err(IpcError::port(name, "notifier"))
}

/// A publish-subscribe service and the event service of the same name.
#[derive(Debug)]
pub struct Topic<T: Debug + ZeroCopySend + 'static> {
    name: String,
    data: publish_subscribe::PortFactory<ipc::Service, T, ()>,
    events: event::PortFactory<ipc::Service>,
}

/// A publisher and the notifier that wakes its readers.
#[derive(Debug)]
pub struct Writer<T: Debug + ZeroCopySend + 'static> {
    pub publisher: Publisher<ipc::Service, T, ()>,
    pub notifier: Notifier<ipc::Service>,
}

/// A subscriber and the listener its publisher wakes.
#[derive(Debug)]
pub struct Reader<T: Debug + ZeroCopySend + 'static> {
    pub subscriber: Subscriber<ipc::Service, T, ()>,
    pub listener: Listener<ipc::Service>,
}

fn create_event(
    node: &Node<ipc::Service>,
    name: &str,
    limits: &EventLimits,
) -> Result<event::PortFactory<ipc::Service>, IpcError> {
    node.service_builder(&iceoryx_name(name)?)
        .event()
        .max_nodes(limits.max_nodes)
        .max_notifiers(limits.max_notifiers)
        .max_listeners(limits.max_listeners)
        .open_or_create()
        .map_err(IpcError::service(name, "creating the event service"))
}

fn open_event(
    node: &Node<ipc::Service>,
    name: &str,
) -> Result<event::PortFactory<ipc::Service>, IpcError> {
    node.service_builder(&iceoryx_name(name)?)
        .event()
        .open()
        .map_err(IpcError::opening(name, "opening the event service", |e| {
            matches!(e, EventOpenError::DoesNotExist)
        }))
}

impl<T: Debug + ZeroCopySend + 'static> PubSub<T> {
    /// Creates the service `name` with these limits, or opens it when it exists (left by a
    /// process that died, or made by another owner with the same limits): the owner's side.
    pub fn create(&self, node: &Node<ipc::Service>, name: &str) -> Result<Topic<T>, IpcError> {
        let limits = &self.limits;
        let data = node
            .service_builder(&iceoryx_name(name)?)
            .publish_subscribe::<T>()
            .history_size(limits.history_size)
            .subscriber_max_buffer_size(limits.subscriber_max_buffer_size)
            .max_publishers(limits.max_publishers)
            .max_subscribers(limits.max_subscribers)
            .max_nodes(limits.max_nodes)
            .enable_safe_overflow(limits.safe_overflow)
            .open_or_create()
            .map_err(IpcError::service(name, "creating the service"))?;
        let events = create_event(node, name, &limits.event)?;
        Ok(Topic {
            name: name.to_string(),
            data,
            events,
        })
    }

    /// Opens the service `name`, made by its owner: [`IpcError::NotFound`] when the owner has not
    /// made it (is not running).
    pub fn open(&self, node: &Node<ipc::Service>, name: &str) -> Result<Topic<T>, IpcError> {
        let data = self.open_data(node, name)?;
        let events = open_event(node, name)?;
        Ok(Topic {
            name: name.to_string(),
            data,
            events,
        })
    }

    /// How many publishers the service `name` has now ([`IpcError::NotFound`]: none made it).
    pub fn publishers(&self, node: &Node<ipc::Service>, name: &str) -> Result<usize, IpcError> {
        Ok(self
            .open_data(node, name)?
            .dynamic_config()
            .number_of_publishers())
    }

    fn open_data(
        &self,
        node: &Node<ipc::Service>,
        name: &str,
    ) -> Result<publish_subscribe::PortFactory<ipc::Service, T, ()>, IpcError> {
        node.service_builder(&iceoryx_name(name)?)
            .publish_subscribe::<T>()
            .open()
            .map_err(IpcError::opening(name, "opening the service", |e| {
                matches!(e, PublishSubscribeOpenError::DoesNotExist)
            }))
    }
}

impl<T: Debug + ZeroCopySend + 'static> Topic<T> {
    pub fn name(&self) -> &str {
        &self.name
    }

    /// How many publishers the service has now.
    pub fn publishers(&self) -> usize {
        self.data.dynamic_config().number_of_publishers()
    }

    /// The largest buffer a subscriber may ask for, as the service's creator set it.
    pub fn subscriber_max_buffer_size(&self) -> usize {
        self.data.static_config().subscriber_max_buffer_size()
    }

    /// The service's publisher and its notifier: [`IpcError::Taken`] when another process holds
    /// the one publisher (or notifier) the service admits.
    pub fn publisher(&self) -> Result<Writer<T>, IpcError> {
        let publisher = self
            .data
            .publisher_builder()
            .create()
            .map_err(|e| match e {
                PublisherCreateError::ExceedsMaxSupportedPublishers => self.taken("publisher"),
                other => IpcError::port(&self.name, "publisher")(other),
            })?;
        let notifier = self
            .events
            .notifier_builder()
            .create()
            .map_err(|e| match e {
                NotifierCreateError::ExceedsMaxSupportedNotifiers => self.taken("notifier"),
                other => IpcError::port(&self.name, "notifier")(other),
            })?;
        Ok(Writer {
            publisher,
            notifier,
        })
    }

    /// A subscriber buffering `buffer` samples (at most
    /// [`Topic::subscriber_max_buffer_size`]) and a listener.
    pub fn subscriber(&self, buffer: usize) -> Result<Reader<T>, IpcError> {
        let subscriber = self
            .data
            .subscriber_builder()
            .buffer_size(buffer)
            .create()
            .map_err(IpcError::port(&self.name, "subscriber"))?;
        let listener = listener(&self.events, &self.name)?;
        Ok(Reader {
            subscriber,
            listener,
        })
    }

    /// A listener alone (a second reader of the same subscriber's events).
    pub fn listener(&self) -> Result<Listener<ipc::Service>, IpcError> {
        listener(&self.events, &self.name)
    }

    fn taken(&self, port: &'static str) -> IpcError {
        IpcError::Taken {
            service: self.name.clone(),
            port,
        }
    }
}

/// A request-response service answered with `ControlResponse`, and its two event services:
/// `<name>` (clients → server) and `<name>/reply` (server → clients).
#[derive(Debug)]
pub struct Exchange<Req: Debug + ZeroCopySend + 'static> {
    name: String,
    data: request_response::PortFactory<ipc::Service, Req, (), ControlResponse, ()>,
    requests: event::PortFactory<ipc::Service>,
    replies: event::PortFactory<ipc::Service>,
}

/// The server of an [`Exchange`], the listener its clients notify, and the notifier that tells
/// them an answer is ready.
#[derive(Debug)]
pub struct ServerPorts<Req: Debug + ZeroCopySend + 'static> {
    pub server: Server<ipc::Service, Req, (), ControlResponse, ()>,
    pub requests: Listener<ipc::Service>,
    pub replies: Notifier<ipc::Service>,
}

/// A client of an [`Exchange`], the notifier that wakes the server, and the listener the server
/// notifies when an answer is ready.
#[derive(Debug)]
pub struct ClientPorts<Req: Debug + ZeroCopySend + 'static> {
    pub client: Client<ipc::Service, Req, (), ControlResponse, ()>,
    pub requests: Notifier<ipc::Service>,
    pub replies: Listener<ipc::Service>,
}

impl<Req: Debug + ZeroCopySend + 'static> RequestResponse<Req> {
    /// Creates the service `name` and its events with these limits, or opens them when they
    /// exist: the server's side.
    pub fn create(&self, node: &Node<ipc::Service>, name: &str) -> Result<Exchange<Req>, IpcError> {
        let limits = &self.limits;
        let data = node
            .service_builder(&iceoryx_name(name)?)
            .request_response::<Req, ControlResponse>()
            .max_servers(limits.max_servers)
            .max_clients(limits.max_clients)
            .max_active_requests_per_client(limits.max_active_requests_per_client)
            .max_response_buffer_size(limits.max_response_buffer_size)
            .max_nodes(limits.max_nodes)
            .enable_safe_overflow_for_requests(limits.safe_overflow_for_requests)
            .enable_safe_overflow_for_responses(limits.safe_overflow_for_responses)
            .open_or_create()
            .map_err(IpcError::service(name, "creating the service"))?;
        let requests = create_event(node, name, &limits.request_event)?;
        let replies = create_event(node, &reply_name(name), &limits.reply_event)?;
        Ok(Exchange {
            name: name.to_string(),
            data,
            requests,
            replies,
        })
    }

    /// Opens the service `name` and its events, made by the server: [`IpcError::NotFound`] when
    /// the server has not made them (is not running).
    pub fn open(&self, node: &Node<ipc::Service>, name: &str) -> Result<Exchange<Req>, IpcError> {
        let data = node
            .service_builder(&iceoryx_name(name)?)
            .request_response::<Req, ControlResponse>()
            .open()
            .map_err(IpcError::opening(name, "opening the service", |e| {
                matches!(e, RequestResponseOpenError::DoesNotExist)
            }))?;
        let requests = open_event(node, name)?;
        let replies = open_event(node, &reply_name(name))?;
        Ok(Exchange {
            name: name.to_string(),
            data,
            requests,
            replies,
        })
    }
}

impl<Req: Debug + ZeroCopySend + 'static> Exchange<Req> {
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The one server: [`IpcError::Taken`] when another process already answers.
    pub fn server(&self) -> Result<ServerPorts<Req>, IpcError> {
        let server = self.data.server_builder().create().map_err(|e| match e {
            ServerCreateError::ExceedsMaxSupportedServers => IpcError::Taken {
                service: self.name.clone(),
                port: "server",
            },
            other => IpcError::port(&self.name, "server")(other),
        })?;
        let requests = listener(&self.requests, &self.name)?;
        let replies = notifier(&self.replies, &reply_name(&self.name))?;
        Ok(ServerPorts {
            server,
            requests,
            replies,
        })
    }

    /// A client, with its notifier and its listener.
    pub fn client(&self) -> Result<ClientPorts<Req>, IpcError> {
        let client = self
            .data
            .client_builder()
            .create()
            .map_err(IpcError::port(&self.name, "client"))?;
        let requests = notifier(&self.requests, &self.name)?;
        let replies = listener(&self.replies, &reply_name(&self.name))?;
        Ok(ClientPorts {
            client,
            requests,
            replies,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{CONTROL, STATE, ServiceKind, config, service_name};

    /// Removes the iceoryx2 files of a test's own prefix once its node is gone (declare it
    /// before the node: it is dropped after it).
    struct Scratch(String);

    impl Drop for Scratch {
        fn drop(&mut self) {
            for (path, e) in crate::remove_ipc_files(&self.0) {
                eprintln!("cannot remove {}: {e}", path.display());
            }
        }
    }

    fn test_node(test: &str) -> (Scratch, Node<ipc::Service>) {
        let prefix = format!("chassis_ipc_{test}_{}_", std::process::id());
        let node = node(
            None,
            &config(Some(&prefix)).unwrap(),
            SignalHandlingMode::Disabled,
        )
        .unwrap();
        (Scratch(prefix), node)
    }

    #[test]
    fn a_reader_started_before_the_owner_finds_nothing_and_creates_nothing() {
        let (_scratch, node) = test_node("before");
        let name = service_name("early", ServiceKind::State);
        let err = STATE.open(&node, &name).unwrap_err();
        assert!(matches!(err, IpcError::NotFound { .. }), "{err}");
        assert_eq!(err.to_string(), "no service chassis/early/state");
        assert!(matches!(
            STATE.publishers(&node, &name),
            Err(IpcError::NotFound { .. })
        ));
        let control = service_name("early", ServiceKind::Control);
        assert!(matches!(
            CONTROL.open(&node, &control),
            Err(IpcError::NotFound { .. })
        ));
    }

    #[test]
    fn the_owner_fixes_the_limits_and_holds_the_one_publisher_and_server() {
        let (_scratch, node) = test_node("owner");
        let name = service_name("owned", ServiceKind::State);
        let owned = STATE.create(&node, &name).unwrap();
        let _writer = owned.publisher().unwrap();
        let opened = STATE.open(&node, &name).unwrap();
        assert_eq!(opened.publishers(), 1);
        assert_eq!(
            opened.subscriber_max_buffer_size(),
            STATE.limits.subscriber_max_buffer_size
        );
        let err = opened.publisher().unwrap_err();
        assert!(
            matches!(
                err,
                IpcError::Taken {
                    port: "publisher",
                    ..
                }
            ),
            "{err}"
        );
        let reader = opened
            .subscriber(STATE.limits.subscriber_max_buffer_size)
            .unwrap();
        drop(reader);

        let control = service_name("owned", ServiceKind::Control);
        let _server = CONTROL.create(&node, &control).unwrap().server().unwrap();
        let exchange = CONTROL.open(&node, &control).unwrap();
        let _client = exchange.client().unwrap();
        let err = exchange.server().unwrap_err();
        assert!(
            matches!(err, IpcError::Taken { port: "server", .. }),
            "{err}"
        );
    }
}
