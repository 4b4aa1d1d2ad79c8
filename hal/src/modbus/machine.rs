//! The PLC as a [`Machine`]: each call writes one command into the mailbox and polls
//! the status block until the PLC reports it done; a probing move's contact comes out
//! of the latch ring (see [`super::latch_ring`]) and is published as a
//! [`ContactSample`] through the same [`SampleSink`] the CANopen backend uses.
//!
//! The PLC owns motion and stops on the latch in its own real-time task; nothing
//! here is on the trigger path. Reads are idempotent and a command is identified by
//! its sequence number, so a request that timed out (and made the client reconnect)
//! is simply asked again.

use super::client::{Answer, ClientStats, ModbusClient};
use super::config::{CaptureKind, ModbusBusConfig};
use super::exception::{describe, exception_kind};
use super::latch_ring::{LatchTracker, RingEvent};
use super::mailbox::{
    bits, CommandBlock, CommandCode, LatchSlot, Layout, ResultCode, Scale, StatusBlock, STATUS_LEN,
};
use crate::abort::{aborted_error, AbortFlag};
use crate::axis::{Axis, AxisPositions, MAX_AXES};
use crate::clock::monotonic_ns;
use crate::config::MachineConfig;
use crate::contact_sample::{ContactSample, SampleSink, FLAG_HW_LATCH};
use crate::machine::{Contact, ErrorKind, Machine, MachineError, ProbeMove};
use crate::motion_guard::{
    deflected_before_move, deflected_before_probing, may_start_deflected, MotionGuard,
};
use std::time::{Duration, Instant};

/// Attempts of an idempotent request that timed out or lost its connection.
const ATTEMPTS: u32 = 3;

#[derive(Clone, Copy, Debug)]
pub struct ModbusOptions {
    /// Identifies the samples of this session's contacts.
    pub run_id: u64,
    /// Longest a command may run.
    pub command_timeout: Duration,
    /// Longest the PLC may take to acknowledge a command.
    pub ack_timeout: Duration,
    /// The operator's stop request: once raised, the command under way is stopped
    /// (a stop command, and the PLC's answer that the axes are at rest) and answered as
    /// [`ErrorKind::Aborted`], and no further command is written until the flag is
    /// re-armed.
    pub abort: Option<AbortFlag>,
}

impl Default for ModbusOptions {
    fn default() -> Self {
        Self {
            run_id: 1,
            command_timeout: Duration::from_secs(600),
            ack_timeout: Duration::from_secs(2),
            abort: None,
        }
    }
}

/// What the latch ring brought, counted over the session.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LatchStats {
    /// Contacts taken (one per probing move).
    pub contacts: u64,
    /// Latches acknowledged without being used: another command's, or a second edge
    /// of a move that already had its contact.
    pub discarded: u64,
    /// Latches overwritten before the bridge read them (ring overflow).
    pub lost: u64,
}

/// How a contact was captured, and what that means for its accuracy.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CaptureInfo {
    pub kind: CaptureKind,
    /// Half-width of the position uncertainty along the probing direction from the
    /// capture alone, mm: 0 for a hardware latch, half a PLC cycle of travel for
    /// `plc_cycle` (after its bias is removed), a whole poll for `poll`.
    pub uncertainty_mm: f64,
}

/// A machine whose axes a PLC moves, reached over Modbus.
pub struct ModbusMachine {
    client: ModbusClient,
    config: MachineConfig,
    /// The checks every backend makes before it moves.
    guard: MotionGuard,
    bus: ModbusBusConfig,
    layout: Layout,
    scale: Scale,
    sink: Box<dyn SampleSink>,
    tracker: LatchTracker,
    sequence: u16,
    heartbeat: u16,
    run_id: u64,
    samples: u64,
    options: ModbusOptions,
    latches: LatchStats,
    last_capture: Option<CaptureInfo>,
    /// The last status read, and the bridge's clock at that read (mid request).
    status: StatusBlock,
    status_ns: u64,
    /// The linear direction of the motion that put the stylus in contact (the last
    /// probing contact or collision), while it may still be; see
    /// [`may_start_deflected`].
    contact_along: Option<[f64; 3]>,
}

fn exception_error(what: &str, e: tokio_modbus::ExceptionCode) -> MachineError {
    MachineError::new(
        exception_kind(e),
        format!("{what}: the PLC answered {}", describe(e)),
    )
}

impl ModbusMachine {
    /// Connects to the PLC of `cfg` (whose `[bus]` must be `kind = "modbus"`), reads
    /// its status and resumes the latch ring from the acknowledge the PLC holds.
    pub fn start<S: SampleSink + 'static>(
        cfg: &MachineConfig,
        sink: S,
        options: ModbusOptions,
    ) -> Result<Self, MachineError> {
        let Some(bus) = cfg.modbus_bus() else {
            return Err(MachineError::new(
                ErrorKind::InvalidRequest,
                format!("{}: [bus] is not kind = \"modbus\"", cfg.path.display()),
            ));
        };
        let client = ModbusClient::open(bus)?;
        let layout = bus.layout();
        let mut m = Self {
            guard: MotionGuard::new(cfg),
            client,
            config: cfg.clone(),
            bus: bus.clone(),
            layout,
            scale: Scale {
                per_mm: bus.counts_per_mm,
                per_deg: bus.counts_per_deg,
            },
            sink: Box::new(sink),
            tracker: LatchTracker::resume(layout, 0),
            sequence: 0,
            heartbeat: 0,
            run_id: options.run_id,
            samples: 0,
            options,
            latches: LatchStats::default(),
            last_capture: None,
            status: StatusBlock::default(),
            status_ns: 0,
            contact_along: None,
        };
        let s = m.read_status()?;
        m.tracker = LatchTracker::resume(layout, s.latch_ack);
        m.sequence = s.acked;
        Ok(m)
    }

    pub fn config(&self) -> &MachineConfig {
        &self.config
    }

    pub fn client_stats(&self) -> ClientStats {
        self.client.stats()
    }

    pub fn latch_stats(&self) -> LatchStats {
        self.latches
    }

    /// How the last contact was captured.
    pub fn last_capture(&self) -> Option<CaptureInfo> {
        self.last_capture
    }

    /// The last acknowledge written to the PLC's latch ring.
    pub fn latch_acknowledged(&self) -> u16 {
        self.tracker.acked()
    }

    /// An idempotent read, asked again after a timeout or a lost connection (the
    /// client has reconnected by then).
    fn read(&self, addr: u16, count: u16) -> Answer<Vec<u16>> {
        let mut attempt = 1;
        loop {
            match self.client.read(addr, count) {
                Err(e)
                    if attempt < ATTEMPTS
                        && matches!(e.kind, ErrorKind::Timeout | ErrorKind::Bus) =>
                {
                    attempt += 1;
                }
                other => return other,
            }
        }
    }

    fn read_status(&mut self) -> Result<StatusBlock, MachineError> {
        let t0 = monotonic_ns();
        let regs = self
            .read(self.layout.status_base, STATUS_LEN)?
            .map_err(|e| exception_error("reading the status block", e))?;
        let t1 = monotonic_ns();
        let s = StatusBlock::decode(self.layout.word_order, &regs)
            .ok_or_else(|| MachineError::new(ErrorKind::Bus, "status block of the wrong length"))?;
        self.status = s;
        self.status_ns = t0 + (t1 - t0) / 2;
        Ok(s)
    }

    fn next_sequence(&mut self) -> u16 {
        self.sequence = self.sequence.wrapping_add(1);
        if self.sequence == 0 {
            self.sequence = 1;
        }
        self.sequence
    }

    /// Writes `block` (one FC16, sequence last). After a timeout or lost connection
    /// the status tells whether the PLC took it; if not, it is written again.
    fn write_command(&mut self, block: &CommandBlock) -> Result<(), MachineError> {
        let regs = block.encode(self.layout.word_order);
        let mut attempt = 1;
        loop {
            match self.client.write(self.layout.command_base, &regs) {
                Ok(Ok(())) => return Ok(()),
                Ok(Err(e)) => return Err(exception_error("writing the command block", e)),
                Err(e)
                    if attempt < ATTEMPTS
                        && matches!(e.kind, ErrorKind::Timeout | ErrorKind::Bus) =>
                {
                    attempt += 1;
                    if self.read_status()?.acked == block.sequence {
                        return Ok(());
                    }
                }
                Err(e) => return Err(e),
            }
        }
    }

    fn acknowledge(&mut self, n: u16) -> Result<(), MachineError> {
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
    fn take_latches(&mut self, sequence: u16) -> Result<Option<LatchSlot>, MachineError> {
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

    /// Writes a command and polls until the PLC reports it done. While probing, the
    /// ring is read as soon as the PLC counts a latch.
    fn run(
        &mut self,
        command: CommandCode,
        targets: &AxisPositions,
        feed: f64,
    ) -> Result<(StatusBlock, Option<LatchSlot>), MachineError> {
        let mut counts = [0i32; MAX_AXES];
        for (axis, v) in targets.iter() {
            counts[axis.index()] = self.scale.to_counts(axis, v).ok_or_else(|| {
                MachineError::new(
                    ErrorKind::InvalidRequest,
                    format!("{axis}{v:+.4} does not fit the PLC's 32-bit position"),
                )
            })?;
        }
        if self.abort_raised() {
            return Err(aborted_error("stop requested; nothing moved"));
        }
        let sequence = self.next_sequence();
        self.heartbeat = self.heartbeat.wrapping_add(1);
        let block = CommandBlock {
            command: command as u16,
            axis_mask: targets.mask() as u16,
            feed_milli: (feed * 1000.0).round().clamp(0.0, u32::MAX as f64) as u32,
            targets: counts,
            probe_edge: u16::from(command == CommandCode::Probe),
            latch_ack: self.tracker.acked(),
            heartbeat: self.heartbeat,
            sequence,
        };
        self.write_command(&block)?;
        let started = Instant::now();
        let poll = Duration::from_millis(self.bus.poll_ms as u64);
        let mut latch = None;
        loop {
            let s = self.read_status()?;
            if command == CommandCode::Probe && self.tracker.pending(s.latch_count) != 0 {
                if let Some(slot) = self.take_latches(sequence)? {
                    latch.get_or_insert(slot);
                }
            }
            if s.done == sequence {
                return Ok((s, latch));
            }
            if self.abort_raised() {
                self.stop_and_wait()?;
                return Err(aborted_error("stop requested; all axes braked"));
            }
            let waited = started.elapsed();
            let late = if s.acked != sequence && waited > self.options.ack_timeout {
                Some("did not acknowledge the command")
            } else if waited > self.options.command_timeout {
                Some("did not finish the command")
            } else {
                None
            };
            if let Some(what) = late {
                self.stop_best_effort();
                return Err(MachineError::new(
                    ErrorKind::Timeout,
                    format!(
                        "the PLC {what} within {:.1} s; stop sent",
                        waited.as_secs_f64()
                    ),
                ));
            }
            std::thread::sleep(poll);
        }
    }

    fn abort_raised(&self) -> bool {
        self.options.abort.is_some_and(|a| a.is_raised())
    }

    /// The operator's stop: a stop command, then the PLC's word that it is done (its
    /// axes braked to rest), so the next command starts from a machine at rest.
    fn stop_and_wait(&mut self) -> Result<(), MachineError> {
        let sequence = self.stop_best_effort();
        let started = Instant::now();
        let poll = Duration::from_millis(self.bus.poll_ms as u64);
        loop {
            let s = self.read_status()?;
            if s.done == sequence {
                return Ok(());
            }
            let waited = started.elapsed();
            if (s.acked != sequence && waited > self.options.ack_timeout)
                || waited > self.options.command_timeout
            {
                return Err(MachineError::new(
                    ErrorKind::Timeout,
                    format!(
                        "stop requested, but the PLC did not report the axes stopped within {:.1} s",
                        waited.as_secs_f64()
                    ),
                ));
            }
            std::thread::sleep(poll);
        }
    }

    /// Writes a stop command; its sequence number.
    fn stop_best_effort(&mut self) -> u16 {
        let sequence = self.next_sequence();
        let block = CommandBlock {
            command: CommandCode::Stop as u16,
            axis_mask: 0,
            feed_milli: 0,
            targets: [0; MAX_AXES],
            probe_edge: 0,
            latch_ack: self.tracker.acked(),
            heartbeat: self.heartbeat,
            sequence,
        };
        let _ = self.write_command(&block);
        sequence
    }

    fn result_error(&self, s: &StatusBlock, what: &str, max_distance: f64) -> MachineError {
        let unit = self.bus.unit;
        match ResultCode::from_u16(s.result) {
            Some(ResultCode::NotTriggered) => MachineError::new(
                ErrorKind::NotTriggered,
                format!("no contact within {max_distance:.3} mm; axes stopped at the end of the path"),
            ),
            Some(ResultCode::AlreadyDeflected) => MachineError::new(
                ErrorKind::AlreadyDeflected,
                "the probe signal is high before the move; nothing moved",
            ),
            Some(ResultCode::Collision) => MachineError::new(
                ErrorKind::ProbeCollision,
                "the stylus touched something while positioning; the PLC braked all axes. Retract away from the contact",
            ),
            Some(ResultCode::Limit) => MachineError::new(
                ErrorKind::SoftwareLimit,
                format!("{what}: the PLC's limits refused the move"),
            ),
            Some(ResultCode::Fault) => MachineError::new(
                ErrorKind::DriveFault,
                format!("{what}: the PLC reports a fault; all axes stopped"),
            )
            .with_node(unit)
            .with_code(s.fault_code),
            Some(ResultCode::Rejected) => MachineError::new(
                ErrorKind::InvalidRequest,
                format!("{what}: the PLC rejected the command"),
            ),
            Some(ResultCode::Stopped) => {
                MachineError::new(ErrorKind::Other, format!("{what}: stopped by the PLC"))
            }
            Some(ResultCode::Contact) => MachineError::new(
                ErrorKind::Other,
                format!("{what}: the PLC reports a contact but the latch ring holds none for this move"),
            ),
            Some(ResultCode::Ok) | None => MachineError::new(
                ErrorKind::Other,
                format!("{what}: unexpected result code {}", s.result),
            ),
        }
    }

    /// The contact of `slot`, on the bridge's clock, corrected for the capture kind;
    /// published to the sink.
    fn contact(&mut self, slot: &LatchSlot, dir: [f64; 3], feed: f64) -> Contact {
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

impl Machine for ModbusMachine {
    type Error = MachineError;

    fn axes(&self) -> u8 {
        self.config.axis_mask()
    }

    fn positions(&mut self) -> Result<AxisPositions, MachineError> {
        let s = self.read_status()?;
        Ok(AxisPositions::from_raw(
            self.scale.positions(&s.actual),
            self.config.axis_mask(),
        ))
    }

    fn move_to(&mut self, target: &AxisPositions, feed: f64) -> Result<(), MachineError> {
        // From where the last status read saw the axes (every command ends with one):
        // the same checks as every backend, the move's duration included.
        let here = AxisPositions::from_raw(
            self.scale.positions(&self.status.actual),
            self.config.axis_mask(),
        );
        self.guard.check_move_from(&here, target, feed)?;
        let mut linear = [0.0; 3];
        let mut rotary = false;
        for (axis, v) in target.iter() {
            let d = v - here.get(axis).unwrap_or(v);
            match axis.index() {
                i @ 0..=2 => linear[i] = d,
                _ => rotary |= d != 0.0,
            }
        }
        // A stylus already in contact from this bridge's last contact or collision
        // gives no rising edge: the PLC would not see a collision, only the broken
        // stylus. (A contact from before this bridge started, whose direction is
        // unknown, is left to the PLC.)
        if self.status.has(bits::DEFLECTED)
            && self.contact_along.is_some()
            && !may_start_deflected(self.contact_along, linear, rotary)
        {
            return Err(MachineError::new(
                ErrorKind::AlreadyDeflected,
                deflected_before_move(here.xyz()),
            ));
        }
        let (s, _) = self.run(CommandCode::Move, target, feed)?;
        match ResultCode::from_u16(s.result) {
            Some(ResultCode::Ok) => {
                if !s.has(bits::DEFLECTED) {
                    self.contact_along = None;
                }
                Ok(())
            }
            Some(ResultCode::Collision) => {
                self.contact_along = Some(linear);
                Err(self.result_error(&s, "move", 0.0))
            }
            _ => Err(self.result_error(&s, "move", 0.0)),
        }
    }

    fn probe(&mut self, mv: &ProbeMove) -> Result<Contact, MachineError> {
        if self.bus.capture == CaptureKind::Poll && !self.bus.allow_poll {
            return Err(MachineError::new(
                ErrorKind::InvalidRequest,
                format!(
                    "{}: bus.capture = \"poll\" is for set-up only: polled positions are not a latch; \
                     set bus.allow_poll = true to measure with it anyway; nothing moved",
                    self.config.path.display()
                ),
            ));
        }
        let here = self.positions()?;
        let dir = self.guard.check_probe(&here, mv)?.direction;
        let mut end = here;
        for (i, a) in Axis::LINEAR.iter().enumerate() {
            end.set(*a, here.get(*a).unwrap_or(0.0) + dir[i] * mv.max_distance);
        }
        // Latches left from before (a stray edge) are acknowledged first, so the PLC
        // re-arms; a deflected probe refuses before anything is written.
        if self.tracker.pending(self.status.latch_count) != 0 {
            self.take_latches(0)?;
        }
        if self.status.has(bits::DEFLECTED) {
            return Err(MachineError::new(
                ErrorKind::AlreadyDeflected,
                deflected_before_probing(here.xyz()),
            ));
        }
        self.contact_along = Some(dir);
        let (s, latch) = self.run(CommandCode::Probe, &end, mv.feed)?;
        match (ResultCode::from_u16(s.result), latch) {
            (Some(ResultCode::Contact), None) => {
                // Counted after the status was read: one more look at the ring.
                let s = self.read_status()?;
                match self.take_latches(s.acked)? {
                    Some(slot) => Ok(self.contact(&slot, dir, mv.feed)),
                    None => Err(self.result_error(&s, "probing move", mv.max_distance)),
                }
            }
            (Some(ResultCode::Contact), Some(slot)) => Ok(self.contact(&slot, dir, mv.feed)),
            _ => Err(self.result_error(&s, "probing move", mv.max_distance)),
        }
    }

    fn set_run(&mut self, run_id: u64) {
        self.run_id = run_id;
    }

    /// One status read: the connection (after the client's retries and reconnects),
    /// and the PLC's fault bit.
    fn health(&mut self) -> Result<(), MachineError> {
        let s = self.read_status()?;
        if s.has(bits::FAULT) {
            return Err(MachineError::new(
                ErrorKind::DriveFault,
                "the PLC reports a fault (acknowledge it at the PLC)",
            ));
        }
        Ok(())
    }
}
