//! The latch ring: the PLC writes every latched contact into the next of N slots and
//! counts it (`latch_count` in the status block); the bridge reads the whole ring in
//! one request (no side effects), takes contact `n` only when both copies of its
//! sequence say `n` and its command sequence is the probing move's, then writes the
//! acknowledge (`latch_ack`). The PLC re-arms only after the acknowledge, and keeps
//! the acknowledge, so a restarted bridge resumes from it. Contact `n` (counted from 1,
//! wrapping at 65536) sits in slot `n mod N`; N divides 65536 so the wrap keeps order.
//!
//! Decisions only: registers in, what to do out.

use super::mailbox::{LatchSlot, Layout, SLOT_LEN};

/// What the ring holds beyond the acknowledge.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RingEvent {
    /// Nothing new.
    Empty,
    /// Contact `n` of the awaited command: use it, then acknowledge `n`.
    Contact { n: u16, slot: LatchSlot },
    /// Contact `n` belongs to another command (a stray or second edge): acknowledge
    /// `n` without using it, so it is neither lost nor counted twice.
    Foreign { n: u16, slot: LatchSlot },
    /// Slot `n` is not (yet) whole: the copies of its sequence differ or name another
    /// contact. Read again.
    Torn { n: u16 },
    /// More contacts than slots since the acknowledge: the oldest `lost` were
    /// overwritten. Nothing is guessed; acknowledge up to `count` and report the loss.
    Overflow { lost: u16, count: u16 },
}

/// The bridge's side of the ring.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LatchTracker {
    layout: Layout,
    acked: u16,
}

impl LatchTracker {
    /// Resumes from the acknowledge the PLC holds (status `latch_ack`).
    pub fn resume(layout: Layout, plc_ack: u16) -> Self {
        Self {
            layout,
            acked: plc_ack,
        }
    }

    /// The last contact acknowledged.
    pub fn acked(&self) -> u16 {
        self.acked
    }

    /// Contacts the PLC counted that are not acknowledged yet.
    pub fn pending(&self, latch_count: u16) -> u16 {
        latch_count.wrapping_sub(self.acked)
    }

    /// Slot index of contact `n`.
    pub fn slot_of(&self, n: u16) -> usize {
        (n % self.layout.ring_slots) as usize
    }

    /// Looks at the next contact after the acknowledge in `ring` (the whole ring as
    /// read), awaited for command `command_sequence`.
    pub fn examine(&self, latch_count: u16, ring: &[u16], command_sequence: u16) -> RingEvent {
        let pending = self.pending(latch_count);
        if pending == 0 {
            return RingEvent::Empty;
        }
        if pending > self.layout.ring_slots {
            return RingEvent::Overflow {
                lost: pending - self.layout.ring_slots,
                count: latch_count,
            };
        }
        let n = self.acked.wrapping_add(1);
        let at = self.slot_of(n) * SLOT_LEN as usize;
        let Some(regs) = ring.get(at..at + SLOT_LEN as usize) else {
            return RingEvent::Torn { n };
        };
        let slot = LatchSlot::decode(self.layout.word_order, regs);
        if slot.sequence_head != n || slot.sequence_tail != n {
            RingEvent::Torn { n }
        } else if slot.command_sequence != command_sequence {
            RingEvent::Foreign { n, slot }
        } else {
            RingEvent::Contact { n, slot }
        }
    }

    /// The acknowledge of `n` was written.
    pub fn acknowledged(&mut self, n: u16) {
        self.acked = n;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::modbus::word_order::WordOrder;

    fn layout() -> Layout {
        Layout {
            command_base: 0,
            status_base: 100,
            ring_base: 200,
            ring_slots: 4,
            word_order: WordOrder::CDAB,
        }
    }

    fn ring_with(slots: &[(u16, u16, u16)]) -> Vec<u16> {
        let l = layout();
        let mut r = vec![0u16; l.ring_len() as usize];
        for &(head, tail, cmd) in slots {
            let s = LatchSlot {
                sequence_head: head,
                command_sequence: cmd,
                axis_mask: 0b111,
                positions: [head as i32, 0, 0, 0, 0, 0],
                latch_time_us: 1000,
                sequence_tail: tail,
            };
            let at = (head % 4) as usize * SLOT_LEN as usize;
            r[at..at + SLOT_LEN as usize].copy_from_slice(&s.encode(l.word_order));
        }
        r
    }

    #[test]
    fn takes_the_next_contact_only_when_both_copies_and_the_command_match() {
        let mut t = LatchTracker::resume(layout(), 0);
        let ring = ring_with(&[(1, 1, 7)]);
        assert_eq!(t.examine(0, &ring, 7), RingEvent::Empty);
        match t.examine(1, &ring, 7) {
            RingEvent::Contact { n: 1, slot } => assert_eq!(slot.positions[0], 1),
            e => panic!("{e:?}"),
        }
        // Same registers, other command: not ours.
        assert!(matches!(
            t.examine(1, &ring, 8),
            RingEvent::Foreign { n: 1, .. }
        ));
        // Half written: head is new, tail still the old contact.
        let torn = ring_with(&[(1, 65533, 7)]);
        assert_eq!(t.examine(1, &torn, 7), RingEvent::Torn { n: 1 });
        t.acknowledged(1);
        assert_eq!(t.examine(1, &ring, 7), RingEvent::Empty);
    }

    #[test]
    fn a_second_edge_of_the_same_move_is_not_counted_twice() {
        let mut t = LatchTracker::resume(layout(), 4);
        let ring = ring_with(&[(5, 5, 3), (6, 6, 3)]);
        assert!(matches!(
            t.examine(6, &ring, 3),
            RingEvent::Contact { n: 5, .. }
        ));
        t.acknowledged(5);
        // The caller has its contact for command 3 and is awaiting command 4 now.
        assert!(matches!(
            t.examine(6, &ring, 4),
            RingEvent::Foreign { n: 6, .. }
        ));
    }

    #[test]
    fn overflow_reports_the_lost_contacts() {
        let t = LatchTracker::resume(layout(), 10);
        let ring = ring_with(&[(13, 13, 1), (14, 14, 1), (15, 15, 1), (16, 16, 1)]);
        assert_eq!(t.pending(16), 6);
        assert_eq!(
            t.examine(16, &ring, 1),
            RingEvent::Overflow { lost: 2, count: 16 }
        );
        // Exactly full is no overflow.
        assert!(matches!(t.examine(14, &ring, 1), RingEvent::Torn { n: 11 }));
    }

    #[test]
    fn wraps_at_65536_and_resumes_from_the_plc_acknowledge() {
        let t = LatchTracker::resume(layout(), 65535);
        let ring = ring_with(&[(0, 0, 2)]);
        assert_eq!(t.pending(0), 1);
        assert!(matches!(
            t.examine(0, &ring, 2),
            RingEvent::Contact { n: 0, .. }
        ));
        assert_eq!(t.slot_of(65535), 3);
        assert_eq!(t.slot_of(0), 0);
    }
}
