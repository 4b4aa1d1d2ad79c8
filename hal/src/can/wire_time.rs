//! Wire time of a classic CAN bus: how long a frame occupies the wire at a bit rate
//! (worst-case bit stuffing), and arbitration by identifier: when the bus frees, the
//! pending frame with the lowest CAN id goes next. A frame reaches the receivers when
//! its last bit would have arrived. Pure bookkeeping on times given as arguments (no
//! clock, no I/O, no allocation), so the in-process bus can run it on the wall clock
//! or on a virtual one.
//!
//! Each sender is one CAN controller with a transmit FIFO (SocketCAN sends a socket's
//! frames in the order written): only the oldest pending frame of each sender takes
//! part in arbitration. So a master's setpoints stay ahead of the SYNC it sends after
//! them, while frames of different nodes go out lowest id first.

use super::CanFrame;

/// Nanoseconds a frame of `data_len` bytes occupies a bus of `bitrate` bit/s, worst
/// case: 47 fixed bits (3 of them the interframe space), 8 per data byte, and one
/// stuff bit per 4 of the 34 + 8n stuffable bits ([`CanFrame::wire_bits_worst_case`]).
pub const fn frame_ns(data_len: usize, bitrate: u32) -> u64 {
    CanFrame::wire_bits_worst_case(data_len) as u64 * 1_000_000_000 / bitrate as u64
}

/// The wire time of `frame` (a remote frame carries no data field).
pub fn wire_ns(frame: &CanFrame, bitrate: u32) -> u64 {
    frame_ns(frame.data().len(), bitrate)
}

/// A frame waiting for the bus.
#[derive(Clone, Copy, Debug)]
struct Pending {
    frame: CanFrame,
    sender: u32,
    ready_ns: u64,
    /// Order of submission: FIFO within a sender, and the tie-break.
    seq: u64,
}

/// A frame that won the bus: who sent it, when its first bit went out and when its
/// last bit arrives at the receivers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OnWire {
    pub frame: CanFrame,
    pub sender: u32,
    pub start_ns: u64,
    pub arrival_ns: u64,
}

/// The bus's schedule: frames pending, arbitrated by id, with room for `N` (fixed
/// capacity: submitting and scheduling allocate nothing).
pub struct Arbitration<const N: usize> {
    bitrate: u32,
    pending: heapless::Vec<Pending, N>,
    busy_until_ns: u64,
    seq: u64,
}

impl<const N: usize> Arbitration<N> {
    pub fn new(bitrate: u32) -> Self {
        Self {
            bitrate: bitrate.max(1),
            pending: heapless::Vec::new(),
            busy_until_ns: 0,
            seq: 0,
        }
    }

    pub fn bitrate(&self) -> u32 {
        self.bitrate
    }

    /// When the frame now on the wire (if any) ends.
    pub fn busy_until_ns(&self) -> u64 {
        self.busy_until_ns
    }

    pub fn pending(&self) -> usize {
        self.pending.len()
    }

    /// `sender` queues `frame` for transmission at `ready_ns`. `Err` gives the frame
    /// back when `N` frames are already waiting (the bus is overloaded).
    pub fn submit(&mut self, sender: u32, frame: CanFrame, ready_ns: u64) -> Result<(), CanFrame> {
        let seq = self.seq;
        self.pending
            .push(Pending {
                frame,
                sender,
                ready_ns,
                seq,
            })
            .map_err(|p| p.frame)?;
        self.seq += 1;
        Ok(())
    }

    /// When the next frame would start: when the bus frees, or when the first
    /// pending frame becomes ready if that is later. `None`: nothing pending.
    pub fn next_start_ns(&self) -> Option<u64> {
        let ready = self.pending.iter().map(|p| p.ready_ns).min()?;
        Some(ready.max(self.busy_until_ns))
    }

    /// The frame that wins the bus at the next start, if that start is at or before
    /// `horizon_ns` (a later frame submitted before the start could still win it).
    /// Among the senders' oldest pending frames ready by then, the lowest id wins;
    /// equal ids go in submission order.
    pub fn next_until(&mut self, horizon_ns: u64) -> Option<OnWire> {
        let start = self.next_start_ns()?;
        if start > horizon_ns {
            return None;
        }
        let mut best: Option<usize> = None;
        for (i, p) in self.pending.iter().enumerate() {
            let oldest_of_sender = !self
                .pending
                .iter()
                .any(|q| q.sender == p.sender && q.seq < p.seq);
            if p.ready_ns > start || !oldest_of_sender {
                continue;
            }
            let wins = best.is_none_or(|b| {
                let b = &self.pending[b];
                (p.frame.cob_id(), p.seq) < (b.frame.cob_id(), b.seq)
            });
            if wins {
                best = Some(i);
            }
        }
        // The earliest ready frame is the oldest of its sender (ready times do not go
        // back within one sender), so there is always a candidate.
        let p = self.pending.remove(best?);
        let arrival_ns = start + wire_ns(&p.frame, self.bitrate);
        self.busy_until_ns = arrival_ns;
        Some(OnWire {
            frame: p.frame,
            sender: p.sender,
            start_ns: start,
            arrival_ns,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(id: u16, len: usize) -> CanFrame {
        CanFrame::new(id, &[0xAA; 8][..len]).unwrap()
    }

    /// Everything that `horizon_ns` lets onto the wire, in order.
    fn drain<const N: usize>(a: &mut Arbitration<N>, horizon_ns: u64) -> Vec<OnWire> {
        core::iter::from_fn(|| a.next_until(horizon_ns)).collect()
    }

    #[test]
    fn frame_times_at_1_mbit() {
        // 8 bytes: 47 + 64 = 111 bits + (34 + 64 - 1) / 4 = 24 stuff bits = 135 bits,
        // 135 us at 1 Mbit/s. 6 bytes (TPDO1, TPDO2): 95 + 20 = 115 bits. SYNC, no
        // data: 47 + 8 = 55 bits.
        assert_eq!(frame_ns(8, 1_000_000), 135_000);
        assert_eq!(frame_ns(6, 1_000_000), 115_000);
        assert_eq!(frame_ns(0, 1_000_000), 55_000);
        // At 500 kbit/s every bit takes 2 us.
        assert_eq!(frame_ns(8, 500_000), 270_000);
    }

    #[test]
    fn five_latch_frames_at_1_mbit_arrive_over_0_675_ms_lowest_id_first() {
        // Five drives queue an 8-byte latch frame at the same instant t = 0, node 5
        // first. Each frame is 135 bits = 135 us at 1 Mbit/s, so they arrive at 135,
        // 270, 405, 540 and 675 us: the last 0.675 ms after the latch, not
        // microseconds. Arbitration puts them in id order, 0x281 first.
        let mut a = Arbitration::<16>::new(1_000_000);
        for node in (1..=5u16).rev() {
            a.submit(node as u32, frame(0x280 + node, 8), 0).unwrap();
        }
        let got: Vec<(u16, u64)> = drain(&mut a, u64::MAX)
            .iter()
            .map(|w| (w.frame.cob_id(), w.arrival_ns))
            .collect();
        assert_eq!(
            got,
            [
                (0x281, 135_000),
                (0x282, 270_000),
                (0x283, 405_000),
                (0x284, 540_000),
                (0x285, 675_000)
            ]
        );
    }

    #[test]
    fn a_frame_queued_while_the_bus_is_busy_waits_and_the_lowest_id_goes_next() {
        let mut a = Arbitration::<16>::new(1_000_000);
        // 0x700 (1 byte heartbeat: 47 + 8 + (34 + 8 - 1) / 4 = 65 bits) takes the idle
        // bus at 0 and ends at 65 us.
        a.submit(1, frame(0x701, 1), 0).unwrap();
        let first = a.next_until(0).unwrap();
        assert_eq!((first.start_ns, first.arrival_ns), (0, 65_000));
        // While it is on the wire, 0x285 (at 10 us) and then 0x181 (at 20 us) queue:
        // at 65 us the lower id, 0x181, wins although it came later.
        a.submit(2, frame(0x285, 6), 10_000).unwrap();
        a.submit(3, frame(0x181, 6), 20_000).unwrap();
        // Not before the bus frees: a frame sent until then could still win.
        assert!(a.next_until(64_999).is_none());
        let order: Vec<(u16, u64, u64)> = drain(&mut a, 65_000)
            .iter()
            .chain(drain(&mut a, u64::MAX).iter())
            .map(|w| (w.frame.cob_id(), w.start_ns, w.arrival_ns))
            .collect();
        assert_eq!(order, [(0x181, 65_000, 180_000), (0x285, 180_000, 295_000)]);
    }

    #[test]
    fn one_senders_frames_keep_their_order_and_an_idle_bus_waits_for_the_ready_time() {
        let mut a = Arbitration::<16>::new(1_000_000);
        // The master writes RPDO1 0x201, then SYNC 0x080: the SYNC's lower id does not
        // overtake its own controller's earlier frame.
        a.submit(0, frame(0x201, 6), 1_000_000).unwrap();
        a.submit(0, CanFrame::new(0x080, &[]).unwrap(), 1_000_000)
            .unwrap();
        assert_eq!(a.next_start_ns(), Some(1_000_000));
        assert!(a.next_until(999_999).is_none(), "not ready before 1 ms");
        let order: Vec<(u16, u64)> = drain(&mut a, u64::MAX)
            .iter()
            .map(|w| (w.frame.cob_id(), w.arrival_ns))
            .collect();
        // 115 us for the 6-byte RPDO1, then 55 us for SYNC.
        assert_eq!(order, [(0x201, 1_115_000), (0x080, 1_170_000)]);
        assert_eq!(a.busy_until_ns(), 1_170_000);
    }

    #[test]
    fn a_full_schedule_gives_the_frame_back() {
        let mut a = Arbitration::<2>::new(1_000_000);
        a.submit(0, frame(0x1, 0), 0).unwrap();
        a.submit(0, frame(0x2, 0), 0).unwrap();
        assert_eq!(a.submit(0, frame(0x3, 0), 0), Err(frame(0x3, 0)));
        assert_eq!(a.pending(), 2);
    }
}
