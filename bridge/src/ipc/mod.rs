//! iceoryx2 services between the bridge (real-time loop) and the estimator process.
//!
//! All services hang off one prefix (default [`DEFAULT_PREFIX`]; tests use a unique one):
//!
//! | service | pattern | payload | who |
//! |---|---|---|---|
//! | `<prefix>/contacts` | publish-subscribe | [`hal::ContactSample`] | bridge publishes, estimator subscribes |
//! | `<prefix>/contacts/event` | event | - | bridge notifies after each sample |
//! | `<prefix>/requests` | request-response | [`EstimatorRequest`] -> [`EstimatorReply`] | bridge is client, estimator server |
//! | `<prefix>/requests/event` | event | - | client notifies after sending a request |
//! | `<prefix>/results/event` | event | - | estimator notifies after sending a reply |
//!
//! iceoryx2 0.10 has request-response; it has no built-in wake-up for servers or pending
//! responses, hence the two event services next to it. Every service is opened through
//! one function here ([`open_contact_service`] etc.) with the quality-of-service numbers
//! below, so `open_or_create` sees the same settings from every process.
//!
//! The real-time loop gets [`ContactPublisher`]: it publishes in the loop's thread (one
//! hop to the estimator) and allocates nothing there, on [`PooledSvc`].
//!
//! Everything else uses [`Svc`] = `ipc_threadsafe::Service`: [`hal::SampleSink`] must be
//! `Send` (the real-time loop owns it in its own thread), and the plain `ipc::Service`
//! ports are `!Send` (`Rc` inside). All flavours share the same shared-memory layout,
//! so a process using `ipc::Service` could still talk to these services.

mod client;
mod identify;
mod payload;
mod pooled_service;
mod process_watch;
mod publisher;
mod runtime_dir;
mod service_lock;
mod subscriber;

pub use client::{EstimatorChild, EstimatorClient};
pub use identify::{IdentifySessions, IpcEstimator, CHUNK, MAX_INPUT, MAX_SESSIONS};
pub use payload::{
    EstimatorReply, EstimatorRequest, ReplyStatus, RequestKind, SphereResult, REPLY_VALUES,
    REQUEST_MAX_RUNS, REQUEST_PARAMS,
};
pub use pooled_service::{PooledArc, PooledSvc};
pub use publisher::{ContactPublisher, PublisherStats};
pub use runtime_dir::{
    iceoryx_config, iceoryx_root_in, lock_dir, unit_runtime_dir, RUNTIME_DIRECTORY,
};
pub use service_lock::{ServiceLock, ServiceLockError, ServiceLockErrorKind};
pub use subscriber::ContactSubscriber;

use core::time::Duration;

use iceoryx2::node::NodeView;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::{event, publish_subscribe, request_response};
use iceoryx2::service::Service;

use hal::ContactSample;

/// The iceoryx2 service flavour of all probebridge ports (thread-safe: ports are `Send`).
pub type Svc = ipc_threadsafe::Service;

/// Prefix of the production services.
pub const DEFAULT_PREFIX: &str = "probebridge";

/// Longest wait for a started estimator process's first answer. Its first start on a
/// gateway reads its code from slow storage and creates its iceoryx2 resources; on a
/// loaded emulated VM (the vcan step) that has taken more than 10 s. Too short a wait
/// is not safe-side: 451 then computes in the bridge process instead.
pub const START_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(30);

/// Subscriber buffer of `<prefix>/contacts` (samples). A probing move yields one sample;
/// cycle 451 yields a few hundred per run. 1024 holds a whole burst even if the estimator
/// is busy fitting for a while; when it overflows, the oldest samples are overwritten
/// (safe overflow: the real-time publisher never blocks) and the estimator reports the
/// gap from `ContactSample::sequence`.
pub const CONTACT_BUFFER: usize = 1024;
/// History kept by the publisher for late subscribers: none. The estimator is started
/// and answers a ping before any run begins; replaying old samples into a restarted
/// estimator would mix runs.
pub const CONTACT_HISTORY: usize = 0;
/// Samples a subscriber may hold at once (we copy each sample out immediately).
pub const CONTACT_MAX_BORROWED: usize = 2;
/// The bridge's publisher plus one spare (simulator, replay tool).
pub const CONTACT_MAX_PUBLISHERS: usize = 2;
/// The estimator plus monitors (a `probebridge contacts` viewer, tests).
pub const CONTACT_MAX_SUBSCRIBERS: usize = 4;
/// Samples the publisher loans at a time (one, loaned when a probing move starts and
/// sent with its contact).
pub const CONTACT_MAX_LOANS: usize = 1;

/// One estimator per prefix: a second one fails to create its server.
pub const MAX_SERVERS: usize = 1;
pub const MAX_CLIENTS: usize = 8;
/// Requests one client may have in flight (the client waits for each reply).
pub const MAX_ACTIVE_REQUESTS_PER_CLIENT: usize = 2;
/// Replies per request (one).
pub const MAX_RESPONSE_BUFFER: usize = 2;
/// Notifiers/listeners per event service.
pub const MAX_EVENT_PORTS: usize = 16;

/// The names of all services under one prefix.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ServiceNames {
    pub prefix: String,
    pub contacts: String,
    pub contacts_event: String,
    pub requests: String,
    pub requests_event: String,
    pub results_event: String,
}

impl ServiceNames {
    pub fn new(prefix: &str) -> Result<Self, IpcError> {
        let prefix = prefix.trim_end_matches('/');
        if prefix.is_empty() {
            return Err(IpcError::BadPrefix(prefix.to_string()));
        }
        let names = Self {
            prefix: prefix.to_string(),
            contacts: format!("{prefix}/contacts"),
            contacts_event: format!("{prefix}/contacts/event"),
            requests: format!("{prefix}/requests"),
            requests_event: format!("{prefix}/requests/event"),
            results_event: format!("{prefix}/results/event"),
        };
        for n in names.all() {
            ServiceName::new(n).map_err(|_| IpcError::BadPrefix(prefix.to_string()))?;
        }
        Ok(names)
    }

    pub fn all(&self) -> [&str; 5] {
        [
            &self.contacts,
            &self.contacts_event,
            &self.requests,
            &self.requests_event,
            &self.results_event,
        ]
    }
}

/// Transport failures. Answers of the estimator (e.g. "unknown run") are not errors:
/// they come back as [`ReplyStatus`] inside the result.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum IpcError {
    #[error("invalid iceoryx2 service prefix {0:?}")]
    BadPrefix(String),
    #[error("iceoryx2: {op} failed: {detail}")]
    Iceoryx { op: &'static str, detail: String },
    #[error("no estimator is serving {0:?} (is the estimator process running?)")]
    NoEstimator(String),
    #[error("the estimator on {prefix:?} did not answer {what} within {after:?}")]
    Timeout {
        prefix: String,
        what: &'static str,
        after: Duration,
    },
    #[error("the estimator on {0:?} dropped the request without answering")]
    Dropped(String),
    #[error("the estimator replied with kind {got} to a request of kind {expected}")]
    WrongReply { expected: u32, got: u32 },
    #[error("estimator process: {0}")]
    Process(String),
    #[error("the estimator process (pid {pid}) serving {prefix:?} died while {what} was pending")]
    Died {
        prefix: String,
        pid: u32,
        what: &'static str,
    },
    #[error("estimator process: {0}")]
    Io(#[from] std::io::Error),
}

impl IpcError {
    pub(crate) fn iox(op: &'static str, e: impl core::fmt::Debug) -> Self {
        Self::Iceoryx {
            op,
            detail: format!("{e:?}"),
        }
    }
}

/// Creates a node, under the root of [`iceoryx_config`]. Signal handling is left to the
/// application: iceoryx2 would otherwise install SIGINT/SIGTERM handlers for the whole
/// process.
pub fn create_node<S: Service>(name: &str) -> Result<Node<S>, IpcError> {
    let name = NodeName::new(name).map_err(|e| IpcError::iox("node name", e))?;
    let config = iceoryx_config().map_err(|e| IpcError::iox("configuration", e))?;
    NodeBuilder::new()
        .name(&name)
        .config(config)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<S>()
        .map_err(|e| IpcError::iox("create node", e))
}

fn service_name(name: &str) -> Result<ServiceName, IpcError> {
    ServiceName::new(name).map_err(|e| IpcError::iox("service name", e))
}

pub type ContactService<S = Svc> = publish_subscribe::PortFactory<S, ContactSample, ()>;
pub type RequestService =
    request_response::PortFactory<Svc, EstimatorRequest, (), EstimatorReply, ()>;
pub type EventService<S = Svc> = event::PortFactory<S>;

/// `<prefix>/contacts` with the settings above.
pub fn open_contact_service<S: Service>(
    node: &Node<S>,
    names: &ServiceNames,
) -> Result<ContactService<S>, IpcError> {
    node.service_builder(&service_name(&names.contacts)?)
        .publish_subscribe::<ContactSample>()
        .enable_safe_overflow(true)
        .history_size(CONTACT_HISTORY)
        .subscriber_max_buffer_size(CONTACT_BUFFER)
        .subscriber_max_borrowed_samples(CONTACT_MAX_BORROWED)
        .max_publishers(CONTACT_MAX_PUBLISHERS)
        .max_subscribers(CONTACT_MAX_SUBSCRIBERS)
        .open_or_create()
        .map_err(|e| IpcError::iox("open or create the contacts service", e))
}

/// `<prefix>/requests` with the settings above.
pub fn open_request_service(
    node: &Node<Svc>,
    names: &ServiceNames,
) -> Result<RequestService, IpcError> {
    node.service_builder(&service_name(&names.requests)?)
        .request_response::<EstimatorRequest, EstimatorReply>()
        .enable_safe_overflow_for_requests(false)
        .enable_safe_overflow_for_responses(false)
        .enable_fire_and_forget_requests(false)
        .max_active_requests_per_client(MAX_ACTIVE_REQUESTS_PER_CLIENT)
        .max_loaned_requests(1)
        .max_response_buffer_size(MAX_RESPONSE_BUFFER)
        .max_servers(MAX_SERVERS)
        .max_clients(MAX_CLIENTS)
        .open_or_create()
        .map_err(|e| IpcError::iox("open or create the requests service", e))
}

/// One of the wake-up event services.
pub fn open_event_service<S: Service>(
    node: &Node<S>,
    name: &str,
) -> Result<EventService<S>, IpcError> {
    node.service_builder(&service_name(name)?)
        .event()
        .max_notifiers(MAX_EVENT_PORTS)
        .max_listeners(MAX_EVENT_PORTS)
        .open_or_create()
        .map_err(|e| IpcError::iox("open or create an event service", e))
}

pub(crate) fn notifier<S: Service>(service: &EventService<S>) -> Result<Notifier<S>, IpcError> {
    service
        .notifier_builder()
        .create()
        .map_err(|e| IpcError::iox("create notifier", e))
}

pub(crate) fn listener<S: Service>(service: &EventService<S>) -> Result<Listener<S>, IpcError> {
    service
        .listener_builder()
        .create()
        .map_err(|e| IpcError::iox("create listener", e))
}

/// What [`remove_stale_resources`] found and did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct CleanupReport {
    /// Nodes whose process is gone.
    pub dead_nodes: usize,
    /// Dead nodes whose resources were removed (by us or by a concurrent cleaner).
    pub cleaned: usize,
    /// Dead nodes we could not clean, with the reason.
    pub failed: Vec<String>,
    /// Nodes we may not inspect (other users) or in an undefined state.
    pub inaccessible: usize,
}

/// Removes the iceoryx2 resources (shared memory, ports in services) that processes
/// left behind when they died without dropping their nodes (crash, SIGKILL): lists all
/// nodes with `Node::list` and calls `DeadNodeView::blocking_remove_stale_resources` on
/// every dead one. Having nothing to clean is a success.
pub fn remove_stale_resources(timeout: Duration) -> Result<CleanupReport, IpcError> {
    let mut dead = Vec::new();
    let mut report = CleanupReport::default();
    let config = iceoryx_config().map_err(|e| IpcError::iox("configuration", e))?;
    Node::<Svc>::list(config, |state| {
        match state {
            NodeState::Dead(view) => dead.push(view),
            NodeState::Alive(_) => {}
            NodeState::Inaccessible(_) | NodeState::Undefined(_) => report.inaccessible += 1,
        }
        CallbackProgression::Continue
    })
    .map_err(|e| IpcError::iox("list nodes", e))?;
    report.dead_nodes = dead.len();
    for view in dead {
        let id = format!("{:?}", view.id());
        let process = view
            .details()
            .as_ref()
            .map(|d| format!(" (pid {:?}, {})", d.process_id(), d.name().as_str()))
            .unwrap_or_default();
        match view.blocking_remove_stale_resources(timeout) {
            Ok(()) => report.cleaned += 1,
            Err(e) => report.failed.push(format!("node {id}{process}: {e:?}")),
        }
    }
    Ok(report)
}
