//! The real-time side: every latched contact goes out as one iceoryx2 sample.

use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;

use hal::{ContactSample, SampleSink, SinkError};

use super::{
    create_node, notifier, open_contact_service, open_event_service, IpcError, ServiceNames, Svc,
    CONTACT_MAX_LOANS,
};

/// Counters of a [`ContactPublisher`] (read them outside the real-time thread).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PublisherStats {
    /// Samples handed to iceoryx2.
    pub published: u64,
    /// Samples that could not be loaned or sent (returned as [`SinkError`]).
    pub failed: u64,
    /// Samples sent while no subscriber was connected (nobody received them).
    pub unreceived: u64,
    /// Samples sent whose wake-up event could not be sent (the estimator sees the
    /// sample at its next periodic wake-up instead).
    pub notify_failed: u64,
}

/// Publishes [`ContactSample`]s on `<prefix>/contacts` and wakes the estimator through
/// `<prefix>/contacts/event`.
///
/// `publish` does, per sample: `Publisher::loan_uninit`, `SampleMutUninit::write_payload`,
/// `SampleMut::send`, `Notifier::notify`. No lock is taken that another thread of this
/// process holds (the port mutexes of `ipc_threadsafe` are only ever locked by the owner
/// thread) and nothing blocks (safe overflow: a full subscriber buffer loses its oldest
/// sample).
///
/// Allocation, read from the iceoryx2 0.10 sources:
/// - `loan_uninit` allocates once on the heap per sample: `SampleMutUninit::new` wraps
///   the chunk in `ChunkMutSharedState::new`, which is `ArcSyncPolicy::new` = `Arc::new`
///   (+ a non-shared pthread mutex) for `ipc_threadsafe` (`Rc::new` for `ipc`); it is
///   freed again at `send`. iceoryx2 0.10 has no loan variant without it (`send_copy`,
///   `loan`, `loan_slice_uninit` all go through `SampleMutUninit::new`).
/// - `send` and `notify` do not allocate in the steady state. They do when the set of
///   subscribers/listeners changed since the previous call: `send` then opens the new
///   zero-copy connection (`format!` of its name, shared-memory open), `notify`
///   rebuilds its listener list (a `Vec`). Call [`ContactPublisher::update_connections`]
///   outside the hot path (e.g. when a run starts) to take that cost there.
/// - Error paths log through iceoryx2's logger, which formats.
pub struct ContactPublisher {
    // Field order = drop order: ports before the node.
    publisher: Publisher<Svc, ContactSample, ()>,
    notifier: Notifier<Svc>,
    stats: PublisherStats,
    names: ServiceNames,
    _node: Node<Svc>,
}

impl ContactPublisher {
    /// Opens (or creates) the contact services under `prefix` and creates the ports.
    /// All allocation happens here.
    pub fn new(prefix: &str) -> Result<Self, IpcError> {
        let names = ServiceNames::new(prefix)?;
        let node = create_node("probebridge-contacts")?;
        let service = open_contact_service(&node, &names)?;
        let publisher = service
            .publisher_builder()
            .max_loaned_samples(CONTACT_MAX_LOANS)
            .create()
            .map_err(|e| IpcError::iox("create contact publisher", e))?;
        let notifier = notifier(&open_event_service(&node, &names.contacts_event)?)?;
        Ok(Self {
            publisher,
            notifier,
            stats: PublisherStats::default(),
            names,
            _node: node,
        })
    }

    pub fn names(&self) -> &ServiceNames {
        &self.names
    }

    pub fn stats(&self) -> PublisherStats {
        self.stats
    }

    /// Connects to subscribers and listeners that appeared since the last call or
    /// publish. Allocates if there are new ones; call it outside the real-time path.
    pub fn update_connections(&self) -> Result<(), IpcError> {
        self.publisher
            .update_connections()
            .map_err(|e| IpcError::iox("update publisher connections", e))?;
        self.notifier
            .update_connections()
            .map_err(|e| IpcError::iox("update notifier connections", e))
    }

    /// Publishes one sample; returns how many subscribers received it.
    pub fn send(&mut self, sample: &ContactSample) -> Result<usize, SinkError> {
        let receivers = match self.publisher.loan_uninit() {
            Ok(slot) => match slot.write_payload(*sample).send() {
                Ok(n) => n,
                Err(_) => {
                    self.stats.failed += 1;
                    return Err(SinkError);
                }
            },
            Err(_) => {
                self.stats.failed += 1;
                return Err(SinkError);
            }
        };
        self.stats.published += 1;
        if receivers == 0 {
            self.stats.unreceived += 1;
        }
        if self.notifier.notify().is_err() {
            self.stats.notify_failed += 1;
        }
        Ok(receivers)
    }
}

impl SampleSink for ContactPublisher {
    fn publish(&mut self, sample: &ContactSample) -> Result<(), SinkError> {
        self.send(sample).map(|_| ())
    }
}

impl core::fmt::Debug for ContactPublisher {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("ContactPublisher")
            .field("service", &self.names.contacts)
            .field("stats", &self.stats)
            .finish()
    }
}
