//! A probing move's contact out of the latch ring: the slots past the acknowledge are
//! taken (the move's own, the others counted and acknowledged unused), and the slot
//! becomes a [`Contact`] on the bridge's clock, corrected for the capture kind, and a
//! [`ContactSample`] for the sink.

use super::{exception_error, CaptureInfo, ModbusMachine, ATTEMPTS};
use crate::clock::monotonic_ns;
use crate::contact_sample::{ContactSample, ProbeWindow, FLAG_HW_LATCH};
use crate::machine::{Contact, ErrorKind, MachineError, ProbeMove};
use crate::modbus::config::CaptureKind;
use crate::modbus::latch_ring::RingEvent;
use crate::modbus::mailbox::LatchSlot;

impl ModbusMachine {
    pub(super) fn acknowledge(&mut self, n: u16) -> Result<(), MachineError> {
        self.heartbeat = self.heartbeat.wrapping_add(1);
        let mut attempt = 1;
        loop {
            match self
                .client
                .write(self.layout.latch_ack_address(), &[n, self.heartbeat])
            {
                Ok(Ok(())) => {
                    self.tracker.acknowledged(n);
                    return Ok(());
                }
                Ok(Err(e)) => return Err(exception_error("acknowledging a latch", e)),
                Err(e)
                    if attempt < ATTEMPTS
                        && matches!(e.kind, ErrorKind::Timeout | ErrorKind::Bus) =>
                {
                    attempt += 1;
                }
                Err(e) => return Err(e),
            }
        }
    }

    /// Reads the ring and takes every latch past the acknowledge: the first of
    /// command `sequence` is returned; the others are acknowledged unused. An overflow
    /// fails with the number of contacts lost.
    pub(super) fn take_latches(
        &mut self,
        sequence: u16,
    ) -> Result<Option<LatchSlot>, MachineError> {
        let mut found = None;
        for _ in 0..ATTEMPTS {
            let count = self.status.latch_count;
            if self.tracker.pending(count) == 0 {
                break;
            }
            let ring = self
                .read(self.layout.ring_base, self.layout.ring_len())?
                .map_err(|e| exception_error("reading the latch ring", e))?;
            let mut last = None;
            let mut torn = false;
            let mut probe = self.tracker;
            loop {
                match probe.examine(count, &ring, sequence) {
                    RingEvent::Empty => break,
                    RingEvent::Torn { .. } => {
                        torn = true;
                        break;
                    }
                    RingEvent::Contact { n, slot } => {
                        if found.is_none() {
                            found = Some(slot);
                        } else {
                            self.latches.discarded += 1;
                        }
                        probe.acknowledged(n);
                        last = Some(n);
                    }
                    RingEvent::Foreign { n, .. } => {
                        self.latches.discarded += 1;
                        probe.acknowledged(n);
                        last = Some(n);
                    }
                    RingEvent::Overflow { lost, count } => {
                        self.latches.lost += lost as u64;
                        self.acknowledge(count)?;
                        return Err(MachineError::new(
                            ErrorKind::Other,
                            format!(
                                "{lost} contact(s) lost: the PLC latched more than the ring's {} slots before they were read; \
                                 nothing is guessed, repeat the measurement",
                                self.layout.ring_slots
                            ),
                        ));
                    }
                }
            }
            if let Some(n) = last {
                self.acknowledge(n)?;
            }
            if !torn {
                break;
            }
            self.read_status()?;
        }
        if found.is_some() {
            self.latches.contacts += 1;
        }
        Ok(found)
    }

    /// The announcement of a probing move about to be commanded, so that the estimator
    /// may watch for its contact instead of sleeping (the armed receive). Its longest
    /// duration: the travel at the probing feed, then up to two PLC task cycles until
    /// the latch is in the ring and two status polls until the bridge reads it.
    pub(super) fn probe_window(&self, mv: &ProbeMove) -> ProbeWindow {
        let travel_s = if mv.feed > 0.0 {
            mv.max_distance / (mv.feed / 60.0)
        } else {
            0.0
        };
        let plc_s = 2.0 * (self.bus.plc_cycle_us as f64 * 1e-6 + self.bus.poll_ms as f64 * 1e-3);
        let start_ns = monotonic_ns();
        ProbeWindow {
            run_id: self.run_id,
            start_ns,
            end_ns: start_ns.saturating_add(((travel_s + plc_s) * 1e9) as u64),
        }
    }

    /// The contact of `slot`, on the bridge's clock, corrected for the capture kind;
    /// published to the sink.
    pub(super) fn contact(&mut self, slot: &LatchSlot, dir: [f64; 3], feed: f64) -> Contact {
        let mask = slot.axis_mask as u8 & self.config.axis_mask();
        let mut positions = self.scale.positions(&slot.positions);
        // PLC time runs on its own clock: the latch was (status time - latch time) before
        // the status was read, which is mapped onto our clock at the middle of that read.
        let age_us = self.status.plc_time_us.wrapping_sub(slot.latch_time_us) as u64;
        let mut trigger_ns = self.status_ns.saturating_sub(age_us * 1000);
        let v = feed / 60.0;
        let cycle_s = self.bus.plc_cycle_us as f64 * 1e-6;
        let kind = self.bus.capture;
        let (flags, uncertainty_mm) = match kind {
            CaptureKind::HwLatch => (FLAG_HW_LATCH, 0.0),
            CaptureKind::PlcCycle => {
                // Sampled at the end of the cycle that saw the input: on average half a
                // cycle of travel past the edge along the probing direction.
                for (i, d) in dir.iter().enumerate() {
                    positions[i] -= d * v * cycle_s / 2.0;
                }
                trigger_ns = trigger_ns.saturating_sub((cycle_s / 2.0 * 1e9) as u64);
                (0, v * cycle_s / 2.0)
            }
            CaptureKind::Poll => (0, v * self.bus.poll_ms as f64 * 1e-3),
        };
        self.last_capture = Some(CaptureInfo {
            kind,
            uncertainty_mm,
        });
        for (i, p) in positions.iter_mut().enumerate() {
            if mask & (1 << i) == 0 {
                *p = 0.0;
            }
        }
        self.samples += 1;
        let sample = ContactSample {
            sequence: self.samples,
            run_id: self.run_id,
            trigger_ns,
            receive_ns: monotonic_ns(),
            publish_ns: 0,
            positions,
            direction: dir,
            feed,
            axis_mask: mask as u32,
            flags,
        };
        // A lost IPC sample must not fail the measurement: the contact is returned.
        let _ = self.sink.publish(&sample);
        Contact {
            positions: sample.axis_positions(),
            trigger_ns,
            sequence: self.samples,
            direction: dir,
        }
    }
}
