//! The receiving side of `<prefix>/contacts` (estimator, monitors, tests).

use core::cell::Cell;
use core::time::Duration;
use std::time::Instant;

use iceoryx2::port::listener::Listener;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;

use hal::contact_sample::ProbeWindow;
use hal::ContactSample;

use super::{
    create_node, listener, open_contact_service, open_event_service, IpcError, ServiceNames, Svc,
    CONTACT_BUFFER,
};

/// Subscribes to `<prefix>/contacts` and listens on `<prefix>/contacts/event`.
///
/// Probing windows ([`ProbeWindow`], announced on the same service) are not returned
/// as samples: the last one is kept until its contact arrives or it is taken
/// ([`ContactSubscriber::take_window`]).
pub struct ContactSubscriber {
    window: Cell<Option<ProbeWindow>>,
    // Field order = drop order: ports before the node.
    subscriber: Subscriber<Svc, ContactSample, ()>,
    listener: Listener<Svc>,
    names: ServiceNames,
    node: Node<Svc>,
}

impl ContactSubscriber {
    pub fn new(prefix: &str) -> Result<Self, IpcError> {
        Self::with_node(create_node("probebridge-contact-subscriber")?, prefix)
    }

    /// Creates the ports on an existing node (the estimator's).
    pub fn with_node(node: Node<Svc>, prefix: &str) -> Result<Self, IpcError> {
        let names = ServiceNames::new(prefix)?;
        let service = open_contact_service(&node, &names)?;
        let subscriber = service
            .subscriber_builder()
            .buffer_size(CONTACT_BUFFER)
            .create()
            .map_err(|e| IpcError::iox("create contact subscriber", e))?;
        let listener = listener(&open_event_service(&node, &names.contacts_event)?)?;
        Ok(Self {
            window: Cell::new(None),
            subscriber,
            listener,
            names,
            node,
        })
    }

    pub fn names(&self) -> &ServiceNames {
        &self.names
    }

    pub fn node(&self) -> &Node<Svc> {
        &self.node
    }

    /// The wake-up listener, to attach to a `WaitSet`.
    pub fn listener(&self) -> &Listener<Svc> {
        &self.listener
    }

    /// Takes one contact if there is one (does not wait). A window on the way is
    /// kept; a contact ends the window it belongs to.
    pub fn try_receive(&self) -> Result<Option<ContactSample>, IpcError> {
        loop {
            match self.subscriber.receive() {
                Ok(Some(sample)) => {
                    let s = *sample.payload();
                    if let Some(w) = ProbeWindow::of_sample(&s) {
                        self.window.set(Some(w));
                        continue;
                    }
                    self.window.set(None);
                    return Ok(Some(s));
                }
                Ok(None) => return Ok(None),
                Err(e) => return Err(IpcError::iox("receive contact sample", e)),
            }
        }
    }

    /// The probing window announced last whose contact has not come yet, once.
    pub fn take_window(&self) -> Option<ProbeWindow> {
        self.window.take()
    }

    /// Consumes pending wake-up events (call before draining with `try_receive`, so a
    /// notification that arrives afterwards wakes the next wait).
    pub fn clear_events(&self) -> Result<(), IpcError> {
        self.listener
            .try_wait(|_| {})
            .map(|_| ())
            .map_err(|e| IpcError::iox("read contact events", e))
    }

    /// Waits up to `timeout` for a sample, sleeping on the event (no busy polling).
    pub fn receive_timeout(&self, timeout: Duration) -> Result<Option<ContactSample>, IpcError> {
        let deadline = Instant::now() + timeout;
        loop {
            self.clear_events()?;
            if let Some(s) = self.try_receive()? {
                return Ok(Some(s));
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            self.listener
                .timed_wait(|_| {}, deadline - now)
                .map_err(|e| IpcError::iox("wait for contact events", e))?;
        }
    }
}
