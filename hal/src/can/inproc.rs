//! An in-process CAN bus with the semantics of a real one: every frame sent by one
//! endpoint reaches every other endpoint, in the order it had on the wire; the sender
//! does not receive its own frames. Fixed-capacity queues, so sending and receiving
//! allocate nothing (the real-time loop runs over this bus in tests and benchmarks).
//!
//! With wire time ([`InprocBus::with_wire_time`]) the bus has a bit rate: a frame
//! occupies the wire for its worst-case stuffed length, frames queued while the bus is
//! busy go out lowest CAN id first, and a frame is handed to the receivers when its
//! last bit would have arrived (see [`super::wire_time`]). On
//! [`WireClock::Monotonic`] receivers wait for that instant in real time; on
//! [`WireClock::Virtual`] (lockstep simulation) nothing waits: each frame carries its
//! arrival on the virtual clock ([`CanTransport::arrival_ns`]), a sender's frames
//! leave at its own virtual time, and frames are scheduled when a receiver asks for
//! them, so frames sent as one batch arbitrate together but a later batch does not
//! overtake an earlier one (that would take a bus loaded past its SYNC period).

use super::wire_time::Arbitration;
use super::{CanFrame, CanTransport, TransportError, TransportErrorKind};
use crate::clock::monotonic_ns;
use core::time::Duration;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};

/// Frames one endpoint can hold before the oldest unread are lost (reported as an
/// overrun, as a CAN controller reports its FIFO overflowing).
pub const QUEUE_CAPACITY: usize = 4096;

/// Frames that can wait for the wire at once (all senders); beyond that a send fails,
/// as a controller's full transmit queue does.
pub const PENDING_CAPACITY: usize = 1024;

/// The clock the wire time runs on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WireClock {
    /// CLOCK_MONOTONIC: a frame is received no earlier than its last bit arrives.
    Monotonic,
    /// A virtual clock (lockstep): frames are stamped with their arrival, nobody waits.
    Virtual,
}

type Queue = heapless::Deque<(CanFrame, u64), QUEUE_CAPACITY>;

struct Slot {
    id: usize,
    /// One endpoint standing for several devices: each node (the low 7 bits of the
    /// COB-ID of what it sends) has its own controller on the wire.
    per_node: bool,
    /// Received frames with their arrival time (0 without wire time).
    frames: Box<Queue>,
    overrun: bool,
    /// Virtual clock: this endpoint's now; what it sends is ready then.
    clock_ns: u64,
    ready: Arc<Condvar>,
}

struct BusState {
    slots: Vec<Slot>,
    next_id: usize,
    /// `None`: no wire time, frames are delivered as they are sent.
    wire: Option<Arbitration<PENDING_CAPACITY>>,
}

struct Shared {
    state: Mutex<BusState>,
    clock: WireClock,
}

/// The bus; clone it freely, all clones are the same bus.
#[derive(Clone)]
pub struct InprocBus {
    shared: Arc<Shared>,
}

impl Default for InprocBus {
    fn default() -> Self {
        Self::new()
    }
}

fn lock(shared: &Shared) -> MutexGuard<'_, BusState> {
    shared.state.lock().unwrap_or_else(|e| e.into_inner())
}

impl InprocBus {
    /// A bus with no wire time: a frame reaches the receivers as it is sent.
    pub fn new() -> Self {
        Self::build(None, WireClock::Monotonic)
    }

    /// A bus of `bitrate` bit/s (at least 1) whose wire time runs on `clock`.
    pub fn with_wire_time(bitrate: u32, clock: WireClock) -> Self {
        Self::build(Some(Arbitration::new(bitrate)), clock)
    }

    fn build(wire: Option<Arbitration<PENDING_CAPACITY>>, clock: WireClock) -> Self {
        Self {
            shared: Arc::new(Shared {
                state: Mutex::new(BusState {
                    slots: Vec::new(),
                    next_id: 0,
                    wire,
                }),
                clock,
            }),
        }
    }

    /// The bit rate and clock of the wire time, if the bus has one.
    pub fn wire_time(&self) -> Option<(u32, WireClock)> {
        let st = lock(&self.shared);
        st.wire.as_ref().map(|a| (a.bitrate(), self.shared.clock))
    }

    /// Attaches a new node to the bus. It receives frames sent after this call.
    pub fn endpoint(&self) -> InprocEndpoint {
        self.attach(false)
    }

    /// Attaches an endpoint that stands for several devices (the simulated drives):
    /// on the wire each node it sends for has its own controller, so their frames
    /// arbitrate by id as separate devices' would.
    pub fn endpoint_for_devices(&self) -> InprocEndpoint {
        self.attach(true)
    }

    fn attach(&self, per_node: bool) -> InprocEndpoint {
        let ready = Arc::new(Condvar::new());
        let mut st = lock(&self.shared);
        st.next_id += 1;
        let id = st.next_id;
        st.slots.push(Slot {
            id,
            per_node,
            frames: Box::new(heapless::Deque::new()),
            overrun: false,
            clock_ns: 0,
            ready: ready.clone(),
        });
        InprocEndpoint {
            bus: self.shared.clone(),
            id,
            ready,
            last_arrival_ns: None,
        }
    }
}

/// Hands `frame` (arrived at `arrival_ns`) to every endpoint but its sender's.
fn deliver(slots: &mut [Slot], sender: usize, frame: &CanFrame, arrival_ns: u64) {
    for s in slots.iter_mut().filter(|s| s.id != sender) {
        if s.frames.is_full() {
            s.frames.pop_front();
            s.overrun = true;
        }
        // Cannot fail: room was made above.
        let _ = s.frames.push_back((*frame, arrival_ns));
        s.ready.notify_one();
    }
}

/// Puts on the wire every frame whose start is at or before `horizon_ns`.
fn advance(st: &mut BusState, horizon_ns: u64) {
    let BusState { slots, wire, .. } = st;
    if let Some(wire) = wire {
        while let Some(w) = wire.next_until(horizon_ns) {
            deliver(slots, (w.sender >> 8) as usize, &w.frame, w.arrival_ns);
        }
    }
}

/// One node's attachment to an [`InprocBus`]. Dropping it detaches the node.
pub struct InprocEndpoint {
    bus: Arc<Shared>,
    id: usize,
    ready: Arc<Condvar>,
    last_arrival_ns: Option<u64>,
}

impl InprocEndpoint {
    fn slot<'a>(&self, st: &'a mut BusState) -> Option<&'a mut Slot> {
        st.slots.iter_mut().find(|s| s.id == self.id)
    }
}

impl Drop for InprocEndpoint {
    fn drop(&mut self) {
        let id = self.id;
        lock(&self.bus).slots.retain(|s| s.id != id);
    }
}

impl CanTransport for InprocEndpoint {
    fn transmit(&mut self, frame: &CanFrame) -> Result<(), TransportError> {
        self.transmit_all(core::slice::from_ref(frame))
    }

    /// The frames go onto the wire together: they arbitrate with each other and with
    /// whatever else is waiting.
    fn transmit_all(&mut self, frames: &[CanFrame]) -> Result<(), TransportError> {
        let clock = self.bus.clock;
        let mut st = lock(&self.bus);
        let (per_node, own_clock) = self
            .slot(&mut st)
            .map_or((false, 0), |s| (s.per_node, s.clock_ns));
        let BusState { slots, wire, .. } = &mut *st;
        let Some(arbitration) = wire else {
            for f in frames {
                deliver(slots, self.id, f, 0);
            }
            return Ok(());
        };
        let (ready, horizon) = match clock {
            WireClock::Monotonic => {
                let now = monotonic_ns();
                (now, now)
            }
            WireClock::Virtual => (own_clock, u64::MAX),
        };
        for f in frames {
            let controller = if per_node { f.cob_id() & 0x7F } else { 0xFF };
            let sender = ((self.id as u32) << 8) | controller as u32;
            arbitration.submit(sender, *f, ready).map_err(|_| {
                TransportError::new(
                    TransportErrorKind::Io,
                    "in-process bus: the transmit queue is full (the bus is overloaded)",
                )
            })?;
        }
        // In real time only what starts by now goes out; the rest waits for the bus
        // to free and is scheduled by whoever looks then.
        advance(&mut st, horizon);
        // Every receiver recomputes when its next frame can arrive.
        for s in st.slots.iter().filter(|s| s.id != self.id) {
            s.ready.notify_one();
        }
        Ok(())
    }

    fn receive(&mut self, timeout: Duration) -> Result<Option<CanFrame>, TransportError> {
        let clock = self.bus.clock;
        let deadline = monotonic_ns().saturating_add(timeout.as_nanos() as u64);
        let mut st = lock(&self.bus);
        loop {
            let now = monotonic_ns();
            let horizon = match clock {
                WireClock::Monotonic => now,
                WireClock::Virtual => u64::MAX,
            };
            advance(&mut st, horizon);
            let timed = st.wire.is_some();
            let next_start = st.wire.as_ref().and_then(|w| w.next_start_ns());
            let Some(slot) = self.slot(&mut st) else {
                return Err(TransportError::new(
                    TransportErrorKind::Closed,
                    "in-process bus endpoint detached",
                ));
            };
            if slot.overrun {
                slot.overrun = false;
                return Err(TransportError::new(
                    TransportErrorKind::Overrun,
                    "in-process bus receive queue overflowed; frames were lost",
                ));
            }
            let head = slot.frames.front().map(|&(_, at)| at);
            if head.is_some_and(|at| at <= horizon) {
                if let Some((f, arrival)) = slot.frames.pop_front() {
                    if timed {
                        slot.clock_ns = slot.clock_ns.max(arrival);
                        self.last_arrival_ns = Some(arrival);
                    }
                    return Ok(Some(f));
                }
            }
            if now >= deadline {
                return Ok(None);
            }
            // Wake when the next frame can arrive or be scheduled, a sender notifies,
            // or the timeout ends.
            let mut wake = deadline;
            if clock == WireClock::Monotonic {
                wake = wake.min(head.unwrap_or(u64::MAX));
                wake = wake.min(next_start.unwrap_or(u64::MAX));
            }
            st = self
                .ready
                .wait_timeout(st, Duration::from_nanos(wake.saturating_sub(now).max(1)))
                .unwrap_or_else(|e| e.into_inner())
                .0;
        }
    }

    fn arrival_ns(&self) -> Option<u64> {
        self.last_arrival_ns
    }

    fn virtual_now_ns(&self) -> Option<u64> {
        if self.bus.clock != WireClock::Virtual {
            return None;
        }
        let mut st = lock(&self.bus);
        st.wire.as_ref()?;
        self.slot(&mut st).map(|s| s.clock_ns)
    }

    fn advance_virtual_clock(&mut self, now_ns: u64) {
        if self.bus.clock == WireClock::Virtual {
            let mut st = lock(&self.bus);
            if let Some(s) = self.slot(&mut st) {
                s.clock_ns = s.clock_ns.max(now_ns);
            }
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

    #[test]
    fn with_wire_time_five_latch_frames_take_0_675_ms_and_arrive_lowest_id_first() {
        // Virtual clock. The master sends RPDO1 (6 bytes: 115 bits) and SYNC (55 bits)
        // at 1 ms: they arrive at 1.115 and 1.170 ms. The five drives answer the SYNC
        // with an 8-byte latch frame each (135 bits = 135 us at 1 Mbit/s), sent node 5
        // first: they go out in id order and the last arrives 5 * 135 = 675 us after
        // the SYNC, at 1.845 ms.
        let bus = InprocBus::with_wire_time(1_000_000, WireClock::Virtual);
        let mut master = bus.endpoint();
        let mut drives = bus.endpoint_for_devices();
        assert_eq!(master.virtual_now_ns(), Some(0));
        master.advance_virtual_clock(1_000_000);
        master
            .transmit_all(&[
                CanFrame::new(0x201, &[0; 6]).unwrap(),
                CanFrame::new(0x080, &[]).unwrap(),
            ])
            .unwrap();
        let mut heard = Vec::new();
        while let Some(f) = drives.receive(Duration::ZERO).unwrap() {
            heard.push((f.cob_id(), drives.arrival_ns().unwrap()));
        }
        assert_eq!(heard, [(0x201, 1_115_000), (0x080, 1_170_000)]);
        let latches: Vec<CanFrame> = (1..=5u16)
            .rev()
            .map(|n| CanFrame::new(0x280 + n, &[n as u8; 8]).unwrap())
            .collect();
        drives.transmit_all(&latches).unwrap();
        let mut got = Vec::new();
        while let Some(f) = master.receive(Duration::ZERO).unwrap() {
            got.push((f.cob_id(), master.arrival_ns().unwrap()));
        }
        assert_eq!(
            got,
            [
                (0x281, 1_305_000),
                (0x282, 1_440_000),
                (0x283, 1_575_000),
                (0x284, 1_710_000),
                (0x285, 1_845_000)
            ]
        );
        // The master's clock followed what it received.
        assert_eq!(master.virtual_now_ns(), Some(1_845_000));
    }

    #[test]
    fn with_wire_time_in_real_time_a_frame_is_received_no_earlier_than_its_last_bit() {
        // 10 kbit/s: an 8-byte frame takes 13.5 ms, five of them 67.5 ms.
        let bus = InprocBus::with_wire_time(10_000, WireClock::Monotonic);
        let mut rx = bus.endpoint();
        let mut drives = bus.endpoint_for_devices();
        let latches: Vec<CanFrame> = (1..=5u16)
            .rev()
            .map(|n| CanFrame::new(0x280 + n, &[0; 8]).unwrap())
            .collect();
        let sent = monotonic_ns();
        drives.transmit_all(&latches).unwrap();
        let mut prev = sent;
        for n in 1..=5u16 {
            let f = rx.receive(Duration::from_secs(10)).unwrap().unwrap();
            let now = monotonic_ns();
            let arrival = rx.arrival_ns().unwrap();
            assert_eq!(f.cob_id(), 0x280 + n, "lowest id first");
            // Each frame 13.5 ms after the previous one, from the send on.
            assert!(arrival >= prev + 13_500_000, "frame {n} at {arrival}");
            assert!(now >= arrival, "received before its last bit arrived");
            prev = arrival;
        }
        assert!(prev - sent >= 67_500_000);
    }
}
