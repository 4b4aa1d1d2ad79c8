//! The PLC as a [`Machine`](crate::Machine): each call writes one command into the mailbox and polls
//! the status block until the PLC reports it done; a probing move's contact comes out
//! of the latch ring (see [`super::latch_ring`]) and is published as a
//! [`ContactSample`](crate::ContactSample) through the same [`SampleSink`] the CANopen
//! backend uses.
//!
//! The PLC owns motion and stops on the latch in its own real-time task; nothing
//! here is on the trigger path. Reads are idempotent and a command is identified by
//! its sequence number, so a request that timed out (and made the client reconnect)
//! is simply asked again.

use super::client::{Answer, ClientStats, ModbusClient};
use super::config::{CaptureKind, ModbusBusConfig};
use super::exception::{describe, exception_kind};
use super::latch_ring::LatchTracker;
use super::mailbox::{
    CommandBlock, CommandCode, LatchSlot, Layout, ResultCode, Scale, StatusBlock, STATUS_LEN,
};
use crate::abort::{aborted_error, AbortFlag};
use crate::axis::{AxisPositions, MAX_AXES};
use crate::clock::monotonic_ns;
use crate::config::MachineConfig;
use crate::contact_sample::SampleSink;
use crate::machine::{ErrorKind, MachineError};
use crate::motion_guard::MotionGuard;
use std::time::{Duration, Instant};

mod commands;
mod latch;

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
    /// The PLC's free-running µs clock, unwrapped (it wraps after 71 min): the
    /// machine's own time, which [`Machine::clock_ns`] reports.
    plc_clock: PlcClock,
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
            plc_clock: PlcClock::default(),
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
        self.plc_clock.saw(s.plc_time_us);
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
        self.run_block(command, counts, targets.mask() as u16, feed)
    }

    /// As [`Self::run`], with the target registers and the axis mask as written.
    pub(super) fn run_block(
        &mut self,
        command: CommandCode,
        counts: [i32; MAX_AXES],
        axis_mask: u16,
        feed: f64,
    ) -> Result<(StatusBlock, Option<LatchSlot>), MachineError> {
        if self.abort_raised() {
            return Err(aborted_error("stop requested; nothing moved"));
        }
        let sequence = self.next_sequence();
        self.heartbeat = self.heartbeat.wrapping_add(1);
        let block = CommandBlock {
            command: command as u16,
            axis_mask,
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
}

/// The PLC's u32 µs clock made monotonic over wraps: each read adds the time since
/// the one before (reads are far less than 71 min apart while a cycle runs).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct PlcClock {
    last_us: Option<u32>,
    total_us: u64,
}

impl PlcClock {
    pub(super) fn saw(&mut self, now_us: u32) {
        if let Some(last) = self.last_us {
            self.total_us += u64::from(now_us.wrapping_sub(last));
        }
        self.last_us = Some(now_us);
    }

    pub(super) fn ns(&self) -> u64 {
        self.total_us * 1000
    }
}

#[cfg(test)]
mod plc_clock_tests {
    use super::PlcClock;

    #[test]
    fn the_plc_clock_runs_on_over_its_wrap() {
        let mut c = PlcClock::default();
        c.saw(u32::MAX - 499);
        assert_eq!(c.ns(), 0);
        c.saw(500);
        assert_eq!(c.ns(), 1_000_000);
        c.saw(1500);
        assert_eq!(c.ns(), 2_000_000);
    }
}
