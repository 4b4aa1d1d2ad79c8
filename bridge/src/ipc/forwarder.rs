//! A [`SampleSink`] for the real-time thread that allocates nothing: it copies each
//! sample into a bounded queue and a forwarder thread publishes it with
//! [`ContactPublisher`] (which allocates once per sample inside iceoryx2 0.10's
//! `loan_uninit`, see there).

use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TrySendError};
use std::thread::JoinHandle;

use hal::{ContactSample, SampleSink, SinkError};

use super::{ContactPublisher, IpcError, PublisherStats};

/// Queue length between the real-time thread and the forwarder (samples).
pub const FORWARD_QUEUE: usize = 1024;

/// Hands samples to a forwarder thread through a preallocated queue.
///
/// `publish` is `SyncSender::try_send` on a bounded (array) channel: the slots are
/// allocated when the channel is created; sending writes a slot and wakes the forwarder
/// (futex), it does not allocate and does not block (a full queue is a [`SinkError`]).
/// The forwarder adds a thread hand-over (a few microseconds) before the iceoryx2 send.
pub struct ForwardingSink {
    tx: Option<SyncSender<ContactSample>>,
    forwarder: Option<JoinHandle<PublisherStats>>,
    /// Samples refused because the queue was full or the forwarder had stopped.
    pub refused: u64,
}

impl ForwardingSink {
    /// Creates the [`ContactPublisher`] on `prefix` and starts the forwarder thread.
    pub fn spawn(prefix: &str) -> Result<Self, IpcError> {
        Self::spawn_realtime(prefix, 0).map(|(sink, _)| sink)
    }

    /// As [`ForwardingSink::spawn`], the forwarder thread under SCHED_FIFO at
    /// `priority` (0: do not ask). The forwarder is on the hot path: left to the
    /// ordinary scheduler, its wake-up waits behind whatever else runs on a busy
    /// gateway. Returns whether SCHED_FIFO was granted.
    pub fn spawn_realtime(prefix: &str, priority: i32) -> Result<(Self, bool), IpcError> {
        let mut publisher = ContactPublisher::new(prefix)?;
        let (tx, rx) = sync_channel::<ContactSample>(FORWARD_QUEUE);
        let (got_tx, got_rx) = sync_channel::<bool>(1);
        let forwarder = std::thread::Builder::new()
            .name("pb-contact-fwd".into())
            .spawn(move || {
                let _ = got_tx.send(priority > 0 && hal::rt::set_fifo_priority(priority));
                forward(&mut publisher, rx)
            })?;
        let fifo = got_rx.recv().unwrap_or(false);
        Ok((
            Self {
                tx: Some(tx),
                forwarder: Some(forwarder),
                refused: 0,
            },
            fifo,
        ))
    }

    /// Stops the forwarder after it has published everything queued; returns its
    /// publisher's counters.
    pub fn finish(mut self) -> PublisherStats {
        self.stop()
    }

    fn stop(&mut self) -> PublisherStats {
        self.tx = None; // the forwarder's recv fails once the queue is empty
        self.forwarder
            .take()
            .and_then(|h| h.join().ok())
            .unwrap_or_default()
    }
}

fn forward(publisher: &mut ContactPublisher, rx: Receiver<ContactSample>) -> PublisherStats {
    while let Ok(sample) = rx.recv() {
        // Failures are counted in the publisher's stats.
        let _ = publisher.send(&sample);
    }
    publisher.stats()
}

impl SampleSink for ForwardingSink {
    fn publish(&mut self, sample: &ContactSample) -> Result<(), SinkError> {
        let Some(tx) = &self.tx else {
            self.refused += 1;
            return Err(SinkError);
        };
        match tx.try_send(*sample) {
            Ok(()) => Ok(()),
            Err(TrySendError::Full(_)) | Err(TrySendError::Disconnected(_)) => {
                self.refused += 1;
                Err(SinkError)
            }
        }
    }
}

impl Drop for ForwardingSink {
    fn drop(&mut self) {
        self.stop();
    }
}

impl core::fmt::Debug for ForwardingSink {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("ForwardingSink")
            .field("running", &self.tx.is_some())
            .field("refused", &self.refused)
            .finish()
    }
}
