//! The thin driver around the real-time loop's protocol core ([`RtLoop`]): it owns the
//! transport and the clock, feeds received frames to the core and sends what each tick
//! gives. Two pacings:
//! - `RealTime`: ticks on CLOCK_MONOTONIC at the SYNC period; frames are handled as
//!   they arrive, so a latch is published the moment its frame is received. After a
//!   stall longer than a whole period the missed SYNC slots are dropped.
//! - `Lockstep`: for the simulator on a virtual clock: after each SYNC the driver waits
//!   until every drive's TPDO1 (the last frame of a drive's answer to SYNC) is in, then
//!   advances virtual time by one period. Runs as fast as the simulation can.
//!
//! Frames are stamped with their arrival (their last bit) when the transport models
//! wire time (the in-process bus, on CLOCK_MONOTONIC or its virtual clock), else with
//! the time the driver takes them in.

use super::command::{Command, Reply};
use super::rt_loop::{LoopConfig, LoopStats, Pacing, RtLoop, TickFrames};
use crate::can::{CanTransport, TransportError};
use crate::clock::monotonic_ns;
use crate::config::MachineConfig;
use crate::contact_sample::SampleSink;
use core::time::Duration;

/// Where the next SYNC slot of a real-time grid is, from the loop's start `epoch_ns`,
/// the slots used so far and the time `now_ns`: the deadline, and how many slots were
/// missed (a stall past a whole period) and are to be dropped.
pub fn next_slot(epoch_ns: u64, slots: u64, period_ns: u64, now_ns: u64) -> (u64, u64) {
    let deadline = epoch_ns + (slots + 1) * period_ns;
    if now_ns >= deadline + period_ns {
        let missed = (now_ns - deadline) / period_ns + 1;
        (deadline + missed * period_ns, missed)
    } else {
        (deadline, 0)
    }
}

/// The real-time loop on a transport, paced as its [`LoopConfig`] says.
pub struct PacedLoop<T: CanTransport, S: SampleSink> {
    rt: RtLoop<S>,
    transport: T,
    /// SYNC slots used since the start (real time: sent or skipped).
    slots: u64,
    epoch_ns: u64,
    late_cycles: u64,
    skipped_cycles: u64,
    frames: TickFrames,
}

impl<T: CanTransport, S: SampleSink> PacedLoop<T, S> {
    /// The loop for the drives of `machine` (configured and operational, see
    /// `startup`); time starts now (real time) or at 0 (lockstep).
    pub fn new(machine: &MachineConfig, cfg: LoopConfig, transport: T, sink: S) -> Self {
        // Lockstep runs on the transport's virtual clock when it has one (a simulated
        // bus with wire time, whose clock the start-up traffic has already advanced).
        let now = match cfg.pacing {
            Pacing::RealTime => monotonic_ns(),
            Pacing::Lockstep { .. } => transport.virtual_now_ns().unwrap_or(0),
        };
        Self {
            rt: RtLoop::new(machine, cfg, sink, now),
            transport,
            slots: 0,
            epoch_ns: now,
            late_cycles: 0,
            skipped_cycles: 0,
            frames: TickFrames::new(),
        }
    }

    pub fn pacing(&self) -> Pacing {
        self.rt.config().pacing
    }

    /// The protocol core.
    pub fn rt(&mut self) -> &mut RtLoop<S> {
        &mut self.rt
    }

    /// The transport (a test reads what a replay has left).
    pub fn transport_mut(&mut self) -> &mut T {
        &mut self.transport
    }

    pub fn sink_mut(&mut self) -> &mut S {
        self.rt.sink_mut()
    }

    /// The core's counters plus the pacing's.
    pub fn stats(&self) -> LoopStats {
        let mut s = self.rt.stats();
        s.late_cycles = self.late_cycles;
        s.skipped_cycles = self.skipped_cycles;
        s
    }

    pub fn submit(&mut self, cmd: Command) {
        self.rt.submit(cmd);
    }

    pub fn take_reply(&mut self) -> Option<Reply> {
        self.rt.take_reply()
    }

    pub fn is_busy(&self) -> bool {
        self.rt.is_busy()
    }

    pub fn is_shut_down(&self) -> bool {
        self.rt.is_shut_down()
    }

    /// The shutdown and its goodbye are sent (see [`RtLoop::is_finished`]).
    pub fn is_finished(&self) -> bool {
        self.rt.is_finished()
    }

    /// One SYNC period: take in what the drives sent, tick, send setpoints and SYNC.
    ///
    /// A transport error does not end the period: the core is told (it faults and
    /// brakes), the period still ticks on the grid, and the error is returned for the
    /// driver to decide how long to keep trying.
    pub fn cycle(&mut self) -> Result<(), TransportError> {
        let gathered = match self.rt.config().pacing {
            Pacing::Lockstep { answer_timeout } => self.gather_lockstep(answer_timeout),
            Pacing::RealTime => self.gather_real_time(),
        };
        let mut failed = None;
        let now = match gathered {
            Ok(now) => now,
            Err(e) => {
                self.rt.transport_failed();
                failed = Some(e);
                self.next_tick_after_failure()
            }
        };
        self.rt.tick(now, &mut self.frames);
        if let Pacing::Lockstep { .. } = self.rt.config().pacing {
            self.transport.advance_virtual_clock(now);
        }
        if let Err(e) = self.transport.transmit_all(&self.frames) {
            // The rest of this period's frames would fail the same way.
            self.rt.transport_failed();
            failed.get_or_insert(e);
        }
        let sent = match self.rt.config().pacing {
            Pacing::RealTime => monotonic_ns(),
            Pacing::Lockstep { .. } => now,
        };
        self.rt.frames_sent(sent);
        self.slots += 1;
        failed.map_or(Ok(()), Err)
    }

    /// The time of the next tick when receiving failed: one period on (lockstep), or
    /// the next slot of the grid, waited for (real time), so a failing transport does
    /// not spin the loop.
    fn next_tick_after_failure(&mut self) -> u64 {
        let period = self.rt.config().period_ns;
        match self.rt.config().pacing {
            Pacing::Lockstep { .. } => self.rt.now_ns() + period,
            Pacing::RealTime => {
                let (deadline, missed) =
                    next_slot(self.epoch_ns, self.slots, period, monotonic_ns());
                self.slots += missed;
                self.skipped_cycles += missed;
                let now = monotonic_ns();
                if deadline > now {
                    std::thread::sleep(Duration::from_nanos(deadline - now));
                }
                monotonic_ns()
            }
        }
    }

    /// Waits (wall clock, at most `answer_timeout`) for every drive's answer to the last
    /// SYNC, takes in whatever else is queued, and returns the virtual time of the next
    /// SYNC, one period on. Frames carry that time: they arrived within the period.
    fn gather_lockstep(&mut self, answer_timeout: Duration) -> Result<u64, TransportError> {
        let next = self.rt.now_ns() + self.rt.config().period_ns;
        if self.slots > 0 {
            let deadline = monotonic_ns() + answer_timeout.as_nanos() as u64;
            while self.rt.answers_pending() {
                let now = monotonic_ns();
                if now >= deadline {
                    break;
                }
                match self
                    .transport
                    .receive(Duration::from_nanos(deadline - now))?
                {
                    Some(f) => {
                        let at = self.transport.arrival_ns().unwrap_or(next);
                        self.rt.on_frame(&f, at);
                    }
                    None => break,
                }
            }
            self.rt.stop_waiting_for_answers();
        }
        // Anything else already queued (EMCY, heartbeats) belongs to this period.
        while let Some(f) = self.transport.receive(Duration::ZERO)? {
            let at = self.transport.arrival_ns().unwrap_or(next);
            self.rt.on_frame(&f, at);
        }
        Ok(next)
    }

    /// Handles frames as they arrive until the next slot of the SYNC grid; returns the
    /// time the slot was reached.
    fn gather_real_time(&mut self) -> Result<u64, TransportError> {
        let period = self.rt.config().period_ns;
        let (deadline, missed) = next_slot(self.epoch_ns, self.slots, period, monotonic_ns());
        // Stalled past a whole slot: the missed slots are dropped and the loop resumes
        // at the next slot of the grid. Sending them now would put SYNCs back to back,
        // and a drive interpolating over the SYNC period would take each setpoint step
        // as a period's worth of motion: a velocity spike. The profile advances per
        // SYNC sent, so the path pauses.
        self.slots += missed;
        self.skipped_cycles += missed;
        loop {
            let now = monotonic_ns();
            if now >= deadline {
                if now > deadline + period / 2 {
                    self.late_cycles += 1;
                }
                break;
            }
            if let Some(f) = self
                .transport
                .receive(Duration::from_nanos(deadline - now))?
            {
                let at = self.transport.arrival_ns().unwrap_or_else(monotonic_ns);
                self.rt.on_frame(&f, at);
            }
        }
        // Frames that came in while this cycle was late belong to it too.
        while let Some(f) = self.transport.receive(Duration::ZERO)? {
            let at = self.transport.arrival_ns().unwrap_or_else(monotonic_ns);
            self.rt.on_frame(&f, at);
        }
        Ok(monotonic_ns())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::CanFrame;
    use crate::canopen::sync;
    use crate::contact_sample::NullSink;
    use std::path::Path;
    use std::time::Instant;

    #[test]
    fn the_real_time_grid_drops_missed_slots() {
        // On time, or late by less than a period: the next slot, nothing dropped.
        assert_eq!(next_slot(0, 0, 1000, 500), (1000, 0));
        assert_eq!(next_slot(0, 3, 1000, 4999), (4000, 0));
        // A stall of ten periods after slot 3: slots 4..=13 are dropped.
        assert_eq!(next_slot(0, 3, 1000, 14_200), (15_000, 11));
    }

    /// Records when each SYNC went out; hears nothing.
    struct SyncTimes(Vec<Instant>);

    impl CanTransport for SyncTimes {
        fn transmit(&mut self, frame: &CanFrame) -> Result<(), TransportError> {
            if frame.cob_id() == sync::encode().cob_id() {
                self.0.push(Instant::now());
            }
            Ok(())
        }
        fn receive(&mut self, timeout: Duration) -> Result<Option<CanFrame>, TransportError> {
            std::thread::sleep(timeout);
            Ok(None)
        }
    }

    #[test]
    fn a_stalled_real_time_loop_skips_the_missed_syncs_instead_of_bursting_them() {
        let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/machines/table-ac.toml");
        let machine = MachineConfig::load(&p).unwrap();
        let mut cfg = LoopConfig::from_machine(&machine, Pacing::RealTime);
        cfg.period_ns = 1_000_000;
        let mut rt = PacedLoop::new(&machine, cfg, SyncTimes(Vec::new()), NullSink);
        for _ in 0..3 {
            rt.cycle().unwrap();
        }
        // The stall being simulated: the loop does not run for 10 periods.
        std::thread::sleep(Duration::from_millis(10));
        let before = rt.transport_mut().0.len();
        let resumed = Instant::now();
        for _ in 0..3 {
            rt.cycle().unwrap();
        }
        let after = &rt.transport_mut().0[before..];
        assert_eq!(after.len(), 3);
        // Bursting would send these three within microseconds of resuming; on the grid
        // the first waits for the next slot and the other two follow a period apart.
        let span = after[2] - resumed;
        assert!(
            span >= Duration::from_millis(2),
            "3 SYNCs within {span:?} after a stall, period 1 ms"
        );
        let skipped = rt.stats().skipped_cycles;
        assert!(skipped >= 9, "{skipped} slots skipped over a 10 ms stall");
    }
}
