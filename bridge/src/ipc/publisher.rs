//! The real-time side: every latched contact goes out as one iceoryx2 sample, published
//! by the real-time thread itself (one hop: no forwarder thread between).

use core::mem::MaybeUninit;

use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::sample_mut_uninit::SampleMutUninit;

use hal::contact_sample::ProbeWindow;
use hal::{ContactSample, SampleSink, SinkError};

use super::{
    create_node, notifier, open_contact_service, open_event_service, IpcError, PooledSvc,
    ServiceNames, CONTACT_MAX_LOANS,
};

/// Counters of a [`ContactPublisher`] (read them outside the real-time thread).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PublisherStats {
    /// Samples handed to iceoryx2 (contacts and probing windows).
    pub published: u64,
    /// Samples that could not be loaned or sent (returned as [`SinkError`]).
    pub failed: u64,
    /// Samples sent while no subscriber was connected (nobody received them).
    pub unreceived: u64,
    /// Samples sent whose wake-up event could not be sent (the estimator sees the
    /// sample at its next periodic wake-up instead).
    pub notify_failed: u64,
    /// Contacts sent from a sample loaned before their probing move started.
    pub preloaned: u64,
}

type Loaned = SampleMutUninit<PooledSvc, MaybeUninit<ContactSample>, ()>;

/// Publishes [`ContactSample`]s on `<prefix>/contacts` and wakes the estimator through
/// `<prefix>/contacts/event`; the real-time loop's sink.
///
/// Per contact: the payload written into a sample loaned when the probing move started
/// ([`SampleSink::probing_move`]), `SampleMut::send`, `Notifier::notify`. No lock is
/// taken that another thread holds and nothing blocks (safe overflow: a full subscriber
/// buffer loses its oldest sample).
///
/// Allocation: none after the first sample. The ports are on [`PooledSvc`], whose
/// per-sample shared state comes from recycled blocks (see there for where iceoryx2
/// 0.10 allocates otherwise). `send` and `notify` allocate only when the set of
/// subscribers/listeners changed since the previous call (a new connection is opened):
/// [`ContactPublisher::update_connections`] takes that cost outside the hot path, and
/// so does every probing window. Error paths log through iceoryx2's logger, which
/// formats.
pub struct ContactPublisher {
    // Field order = drop order: the loaned sample and the ports before the node.
    loaned: Option<Loaned>,
    publisher: Publisher<PooledSvc, ContactSample, ()>,
    notifier: Notifier<PooledSvc>,
    stats: PublisherStats,
    names: ServiceNames,
    _node: Node<PooledSvc>,
}

impl ContactPublisher {
    /// Opens (or creates) the contact services under `prefix` and creates the ports.
    pub fn new(prefix: &str) -> Result<Self, IpcError> {
        let names = ServiceNames::new(prefix)?;
        let node = create_node::<PooledSvc>("probebridge-contacts")?;
        let service = open_contact_service(&node, &names)?;
        let publisher = service
            .publisher_builder()
            .max_loaned_samples(CONTACT_MAX_LOANS)
            .create()
            .map_err(|e| IpcError::iox("create contact publisher", e))?;
        let notifier = notifier(&open_event_service(&node, &names.contacts_event)?)?;
        Ok(Self {
            loaned: None,
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

    /// Loans the sample the next contact is written into, if none is loaned yet.
    pub fn preloan(&mut self) {
        if self.loaned.is_none() {
            self.loaned = self.publisher.loan_uninit().ok();
        }
    }

    /// Publishes one sample (from the loaned one, else a new loan); returns how many
    /// subscribers received it.
    pub fn send(&mut self, sample: &ContactSample) -> Result<usize, SinkError> {
        let slot = match self.loaned.take() {
            Some(slot) => Ok(slot),
            None => self.publisher.loan_uninit(),
        };
        let sent = match slot {
            Ok(slot) => {
                let mut sample = *sample;
                sample.publish_ns = hal::clock::monotonic_ns();
                slot.write_payload(sample).send().map_err(|_| SinkError)
            }
            Err(_) => Err(SinkError),
        };
        let Ok(receivers) = sent else {
            self.stats.failed += 1;
            return Err(SinkError);
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
        if self.loaned.is_some() {
            self.stats.preloaned += 1;
        }
        self.send(sample).map(|_| ())
    }

    /// Tells the estimator the window (it may poll for the contact until its end),
    /// then loans the contact's sample, so the contact only writes and sends.
    fn probing_move(&mut self, window: ProbeWindow) {
        let _ = self.send(&window.to_sample());
        self.preloan();
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
