//! An in-process CAN bus with the semantics of a real one: every frame sent by one
//! endpoint reaches every other endpoint, in the order sent; the sender does not
//! receive its own frames. Fixed-capacity queues, so sending and receiving allocate
//! nothing (the real-time loop runs over this bus in tests and benchmarks).

use super::{CanFrame, CanTransport, TransportError, TransportErrorKind};
use core::time::Duration;
use std::sync::{Arc, Condvar, Mutex};
use std::time::Instant;

/// Frames one endpoint can hold before the oldest unread are lost (reported as an
/// overrun, as a CAN controller reports its FIFO overflowing).
pub const QUEUE_CAPACITY: usize = 4096;

struct Queue {
    frames: heapless::Deque<CanFrame, QUEUE_CAPACITY>,
    overrun: bool,
}

struct Endpoint {
    id: usize,
    queue: Mutex<Queue>,
    ready: Condvar,
}

#[derive(Default)]
struct Shared {
    endpoints: Mutex<Vec<Arc<Endpoint>>>,
    next_id: Mutex<usize>,
}

/// The bus; clone it freely, all clones are the same bus.
#[derive(Clone, Default)]
pub struct InprocBus {
    shared: Arc<Shared>,
}

impl InprocBus {
    pub fn new() -> Self {
        Self::default()
    }

    /// Attaches a new node to the bus. It receives frames sent after this call.
    pub fn endpoint(&self) -> InprocEndpoint {
        let id = {
            let mut n = self
                .shared
                .next_id
                .lock()
                .unwrap_or_else(|e| e.into_inner());
            *n += 1;
            *n
        };
        let ep = Arc::new(Endpoint {
            id,
            queue: Mutex::new(Queue {
                frames: heapless::Deque::new(),
                overrun: false,
            }),
            ready: Condvar::new(),
        });
        self.shared
            .endpoints
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(ep.clone());
        InprocEndpoint {
            bus: self.shared.clone(),
            me: ep,
        }
    }
}

/// One node's attachment to an [`InprocBus`]. Dropping it detaches the node.
pub struct InprocEndpoint {
    bus: Arc<Shared>,
    me: Arc<Endpoint>,
}

impl Drop for InprocEndpoint {
    fn drop(&mut self) {
        let id = self.me.id;
        self.bus
            .endpoints
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .retain(|e| e.id != id);
    }
}

impl CanTransport for InprocEndpoint {
    fn transmit(&mut self, frame: &CanFrame) -> Result<(), TransportError> {
        let endpoints = self.bus.endpoints.lock().unwrap_or_else(|e| e.into_inner());
        for ep in endpoints.iter().filter(|e| e.id != self.me.id) {
            let mut q = ep.queue.lock().unwrap_or_else(|e| e.into_inner());
            if q.frames.is_full() {
                q.frames.pop_front();
                q.overrun = true;
            }
            // Cannot fail: room was made above.
            let _ = q.frames.push_back(*frame);
            drop(q);
            ep.ready.notify_one();
        }
        Ok(())
    }

    fn receive(&mut self, timeout: Duration) -> Result<Option<CanFrame>, TransportError> {
        let deadline = Instant::now() + timeout;
        let mut q = self.me.queue.lock().unwrap_or_else(|e| e.into_inner());
        loop {
            if q.overrun {
                q.overrun = false;
                return Err(TransportError::new(
                    TransportErrorKind::Overrun,
                    "in-process bus receive queue overflowed; frames were lost",
                ));
            }
            if let Some(f) = q.frames.pop_front() {
                return Ok(Some(f));
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            q = self
                .me
                .ready
                .wait_timeout(q, deadline - now)
                .unwrap_or_else(|e| e.into_inner())
                .0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_other_endpoint_receives_in_order_sender_does_not() {
        let bus = InprocBus::new();
        let mut a = bus.endpoint();
        let mut b = bus.endpoint();
        let mut c = bus.endpoint();
        for i in 0..5u8 {
            a.transmit(&CanFrame::new(0x100 + i as u16, &[i]).unwrap())
                .unwrap();
        }
        for rx in [&mut b, &mut c] {
            for i in 0..5u8 {
                let f = rx.receive(Duration::ZERO).unwrap().unwrap();
                assert_eq!(f.cob_id(), 0x100 + i as u16);
                assert_eq!(f.data(), &[i]);
            }
            assert!(rx.receive(Duration::ZERO).unwrap().is_none());
        }
        assert!(a.receive(Duration::ZERO).unwrap().is_none());
    }

    #[test]
    fn receive_wakes_on_frame_from_another_thread() {
        let bus = InprocBus::new();
        let mut a = bus.endpoint();
        let mut b = bus.endpoint();
        let t = std::thread::spawn(move || b.receive(Duration::from_secs(10)).unwrap());
        a.transmit(&CanFrame::new(0x80, &[]).unwrap()).unwrap();
        // The frame may be sent before the receiver waits: it is queued either way.
        assert_eq!(t.join().unwrap().unwrap().cob_id(), 0x80);
    }

    #[test]
    fn overflow_is_reported() {
        let bus = InprocBus::new();
        let mut a = bus.endpoint();
        let mut b = bus.endpoint();
        for _ in 0..QUEUE_CAPACITY + 1 {
            a.transmit(&CanFrame::new(0x1, &[]).unwrap()).unwrap();
        }
        let e = b.receive(Duration::ZERO).unwrap_err();
        assert_eq!(e.kind, TransportErrorKind::Overrun);
    }
}
