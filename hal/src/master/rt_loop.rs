//! The cyclic part of the CANopen master: once per SYNC period it takes in the drives'
//! process data, advances the motion, reacts to the touch-probe latch, and sends
//! setpoints and SYNC. It owns no thread (the caller calls [`RtLoop::cycle`]), so tests
//! can step it, and it allocates nothing after construction.
//!
//! Two pacings:
//! - `RealTime`: cycles on CLOCK_MONOTONIC at the SYNC period; frames are handled as
//!   they arrive, so a latch is published the moment its frame is received.
//! - `Lockstep`: for the simulator on a virtual clock: after each SYNC the loop waits
//!   until every drive's TPDO1 (the last frame of a drive's answer to SYNC) is in, then
//!   advances virtual time by one period. Runs as fast as the simulation can.

use super::command::{Command, Detail, Reply, RtError};
use crate::axis::{Axis, MAX_AXES};
use crate::can::{CanFrame, CanTransport, TransportError};
use crate::canopen::cob_id::{self, CobKind};
use crate::canopen::emcy::Emcy;
use crate::canopen::heartbeat::{HeartbeatConsumer, HeartbeatEvent};
use crate::canopen::sync;
use crate::cia402::controlword::Controlword;
use crate::cia402::state::State;
use crate::cia402::statusword::Statusword;
use crate::cia402::touch_probe::{Probe, TouchProbeFunction, TouchProbeStatus};
use crate::clock::monotonic_ns;
use crate::config::MachineConfig;
use crate::contact_sample::{ContactSample, SampleSink, FLAG_HW_LATCH};
use crate::machine::ErrorKind;
use crate::motion::{AxisLimits, Profile};
use core::time::Duration;

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Pacing {
    RealTime,
    Lockstep {
        /// Longest wall-clock wait for the drives' answers to one SYNC; a drive that
        /// does not answer in time is not waited for again (its heartbeat decides).
        answer_timeout: Duration,
    },
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LoopConfig {
    pub period_ns: u64,
    pub pacing: Pacing,
    /// A move is done when every axis is this close to its setpoint (mm / deg).
    pub in_position_window: f64,
    pub settle_timeout_ns: u64,
    pub enable_timeout_ns: u64,
    pub arm_timeout_ns: u64,
    pub heartbeat_timeout_ns: u64,
}

impl LoopConfig {
    pub fn from_machine(cfg: &MachineConfig, pacing: Pacing) -> Self {
        Self {
            period_ns: cfg.canopen_or_default().sync_period_us as u64 * 1000,
            pacing,
            in_position_window: 0.001,
            settle_timeout_ns: 2_000_000_000,
            enable_timeout_ns: 2_000_000_000,
            arm_timeout_ns: 200_000_000,
            heartbeat_timeout_ns: cfg.canopen_or_default().heartbeat_timeout_ms as u64 * 1_000_000,
        }
    }
}

/// Counters of the loop, read by benchmarks and the CLI.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LoopStats {
    pub cycles: u64,
    pub samples_published: u64,
    pub publish_failures: u64,
    /// Real-time pacing: cycles whose work ended after their deadline.
    pub late_cycles: u64,
    /// Real-time pacing: SYNC slots not sent because the loop had stalled for longer
    /// than a whole period (sending them late would put SYNCs back to back).
    pub skipped_cycles: u64,
    /// Latch frame received -> stop setpoint sent, of the last contact, ns.
    pub last_stop_latency_ns: u64,
    /// The same in whole cycles (the stop goes out with the next SYNC).
    pub last_stop_latency_cycles: u64,
}

/// What the master knows of one drive.
#[derive(Clone, Copy, Debug)]
struct DriveLink {
    axis: Axis,
    node: u8,
    scale: f64,
    statusword: u16,
    seen_tpdo1: bool,
    answered: bool,
    silent: bool,
    actual_inc: i32,
    tp_status: u16,
    tp_status_fresh: bool,
    /// Probe input level last reported (bit 7 of 0x60B9).
    probe_level: bool,
    latch_inc: Option<i32>,
    latch_rx_ns: u64,
    last_emcy: Option<u16>,
    controlword: u16,
    target_inc: i32,
    tp_function: u16,
    tp_function_sent: Option<u16>,
}

impl DriveLink {
    fn actual(&self) -> f64 {
        self.actual_inc as f64 / self.scale
    }

    fn increments(&self, v: f64) -> i32 {
        (v * self.scale)
            .round()
            .clamp(i32::MIN as f64, i32::MAX as f64) as i32
    }
}

#[derive(Clone, Copy, Debug)]
enum ArmStage {
    Disarm,
    Enable,
    WaitArmed,
}

#[derive(Clone, Copy, Debug)]
enum Activity {
    /// Start-up: waiting for every drive's TPDO1, then walking each to Operation enabled.
    Enabling {
        since_ns: u64,
    },
    Idle,
    Moving {
        profile: Profile,
        t: f64,
    },
    Arming {
        stage: ArmStage,
        since_ns: u64,
        direction: [f64; 3],
        feed: f64,
        max_distance: f64,
        run_id: u64,
    },
    Probing {
        profile: Profile,
        t: f64,
        direction: [f64; 3],
        feed: f64,
        max_distance: f64,
        run_id: u64,
    },
    /// Braking along the path; then `then` is answered (after the axes settle, unless
    /// it is an error: a faulted drive would never settle).
    Stopping {
        profile: Profile,
        t: f64,
        then: Reply,
    },
    /// Waiting for the actual positions to reach the setpoint.
    Settling {
        since_ns: u64,
        then: Reply,
    },
    Shutdown,
}

pub struct RtLoop<T: CanTransport, S: SampleSink> {
    transport: T,
    sink: S,
    cfg: LoopConfig,
    drives: heapless::Vec<DriveLink, MAX_AXES>,
    limits: AxisLimits,
    mask: u8,
    heartbeat: HeartbeatConsumer,
    cycle: u64,
    /// Time of the SYNC most recently sent (virtual under lockstep).
    sync_ns: u64,
    epoch_ns: u64,
    /// Clock of the heartbeat supervision: advances with the loop but at most two
    /// periods per cycle, so a stall of the loop itself (no SCHED_FIFO on a loaded
    /// machine) is not taken for silent nodes: a consumer that was not running cannot
    /// judge what it missed. Real losses are still seen after the timeout of
    /// supervised time.
    supervised_ns: u64,
    setpoint: [f64; MAX_AXES],
    activity: Activity,
    reply: Option<Reply>,
    fault: Option<RtError>,
    sequence: u64,
    stop_pending_since: Option<u64>,
    stats: LoopStats,
}

impl<T: CanTransport, S: SampleSink> RtLoop<T, S> {
    /// A loop for the drives of `cfg`, which must already be configured and
    /// operational (see `startup`). The first cycles walk them to Operation enabled;
    /// [`Reply::Ready`] is answered when they are there.
    pub fn new(machine: &MachineConfig, cfg: LoopConfig, transport: T, sink: S) -> Self {
        let mut drives = heapless::Vec::new();
        let mut limits = AxisLimits {
            max_velocity: [0.0; MAX_AXES],
            max_acceleration: [0.0; MAX_AXES],
        };
        let mut heartbeat = HeartbeatConsumer::new();
        for a in &machine.axes {
            let link = DriveLink {
                axis: a.name,
                node: a.node,
                scale: a.increments_per_unit,
                statusword: 0,
                seen_tpdo1: false,
                answered: false,
                silent: false,
                actual_inc: 0,
                tp_status: 0,
                tp_status_fresh: false,
                probe_level: false,
                latch_inc: None,
                latch_rx_ns: 0,
                last_emcy: None,
                controlword: Controlword::SHUTDOWN,
                target_inc: 0,
                tp_function: 0,
                tp_function_sent: None,
            };
            // MachineConfig allows at most one entry per axis, so at most 6.
            let _ = drives.push(link);
            limits.max_velocity[a.name.index()] = a.max_feed / 60.0;
            limits.max_acceleration[a.name.index()] = a.max_acceleration;
            // Node IDs were validated (1..=127) with the configuration.
            let _ = heartbeat.watch(a.node, cfg.heartbeat_timeout_ns);
        }
        let now = match cfg.pacing {
            Pacing::RealTime => monotonic_ns(),
            Pacing::Lockstep { .. } => 0,
        };
        Self {
            transport,
            sink,
            cfg,
            drives,
            limits,
            mask: machine.axis_mask(),
            heartbeat,
            cycle: 0,
            sync_ns: now,
            epoch_ns: now,
            supervised_ns: 0,
            setpoint: [0.0; MAX_AXES],
            activity: Activity::Enabling { since_ns: now },
            reply: None,
            fault: None,
            sequence: 0,
            stop_pending_since: None,
            stats: LoopStats::default(),
        }
    }

    pub fn pacing(&self) -> Pacing {
        self.cfg.pacing
    }

    pub fn stats(&self) -> LoopStats {
        self.stats
    }

    /// Current time of the loop's clock (virtual under lockstep), ns.
    pub fn now_ns(&self) -> u64 {
        self.sync_ns
    }

    pub fn is_shut_down(&self) -> bool {
        matches!(self.activity, Activity::Shutdown)
    }

    /// The answer to the last command, once it is finished.
    pub fn take_reply(&mut self) -> Option<Reply> {
        self.reply.take()
    }

    /// Is a command running (or start-up not finished)?
    pub fn is_busy(&self) -> bool {
        !matches!(self.activity, Activity::Idle | Activity::Shutdown) || self.reply.is_some()
    }

    /// Accepts a command; it is carried out by the following cycles.
    pub fn submit(&mut self, cmd: Command) {
        if let Command::Shutdown = cmd {
            self.hold_all();
            for d in self.drives.iter_mut() {
                d.controlword = Controlword::SHUTDOWN;
                d.tp_function = 0;
            }
            self.activity = Activity::Shutdown;
            return;
        }
        if self.is_busy() {
            self.reply = Some(Reply::Error(RtError::new(ErrorKind::Other, Detail::Busy)));
            return;
        }
        if let Command::Positions = cmd {
            self.reply = Some(Reply::Done {
                positions: self.actual_positions(),
            });
            return;
        }
        if let Some(f) = self.fault {
            // A faulted or lost drive refuses motion until the bridge is restarted.
            self.reply = Some(Reply::Error(f));
            return;
        }
        let now = self.sync_ns;
        match cmd {
            Command::MoveTo { target, mask, feed } => {
                let from = self.setpoint;
                let mut to = from;
                for i in 0..MAX_AXES {
                    if mask & self.mask & (1 << i) != 0 {
                        to[i] = target[i];
                    }
                }
                self.activity = Activity::Moving {
                    profile: Profile::line(from, to, feed, &self.limits),
                    t: 0.0,
                };
            }
            Command::Probe {
                direction,
                feed,
                max_distance,
                run_id,
            } => {
                self.activity = Activity::Arming {
                    stage: ArmStage::Disarm,
                    since_ns: now,
                    direction,
                    feed,
                    max_distance,
                    run_id,
                };
            }
            Command::Positions | Command::Shutdown => {}
        }
    }

    fn actual_positions(&self) -> [f64; MAX_AXES] {
        let mut p = [0.0; MAX_AXES];
        for d in &self.drives {
            p[d.axis.index()] = d.actual();
        }
        p
    }

    fn hold_all(&mut self) {
        for d in self.drives.iter_mut() {
            self.setpoint[d.axis.index()] = d.actual();
        }
    }

    /// One SYNC period: take in what the drives sent, advance, send setpoints and SYNC.
    pub fn cycle(&mut self) -> Result<(), TransportError> {
        self.gather()?;
        if let Some(HeartbeatEvent::Lost {
            node,
            silent_for_ns,
        }) = self.heartbeat.check(self.supervised_ns)
        {
            self.set_fault(
                RtError::new(
                    ErrorKind::NodeLost,
                    Detail::HeartbeatLost {
                        silent_ms: silent_for_ns as f64 / 1e6,
                    },
                )
                .node(node),
            );
        }
        self.check_fault_bits();
        self.step();
        self.transmit()?;
        self.stats.cycles += 1;
        Ok(())
    }

    fn gather(&mut self) -> Result<(), TransportError> {
        match self.cfg.pacing {
            Pacing::Lockstep { answer_timeout } => {
                if self.cycle > 0 {
                    let deadline = monotonic_ns() + answer_timeout.as_nanos() as u64;
                    while self.drives.iter().any(|d| !d.answered && !d.silent) {
                        let now = monotonic_ns();
                        if now >= deadline {
                            break;
                        }
                        match self
                            .transport
                            .receive(Duration::from_nanos(deadline - now))?
                        {
                            Some(f) => self.on_frame(&f),
                            None => break,
                        }
                    }
                    for d in self.drives.iter_mut() {
                        if !d.answered {
                            d.silent = true;
                        }
                    }
                }
                // Anything else already queued (EMCY, heartbeats) belongs to this period.
                while let Some(f) = self.transport.receive(Duration::ZERO)? {
                    self.on_frame(&f);
                }
                self.sync_ns += self.cfg.period_ns;
                self.supervised_ns += self.cfg.period_ns;
            }
            Pacing::RealTime => {
                let period = self.cfg.period_ns;
                let mut deadline = self.epoch_ns + (self.cycle + 1) * period;
                let now = monotonic_ns();
                if now >= deadline + period {
                    // Stalled past a whole slot: drop the missed slots and resume at the
                    // next slot of the grid. Sending them now would put SYNCs back to
                    // back, and a drive interpolating over the SYNC period would take
                    // each setpoint step as a period's worth of motion: a velocity
                    // spike. The profile advances per SYNC sent, so the path pauses.
                    let missed = (now - deadline) / period + 1;
                    self.cycle += missed;
                    self.stats.skipped_cycles += missed;
                    deadline += missed * period;
                }
                loop {
                    let now = monotonic_ns();
                    if now >= deadline {
                        if now > deadline + period / 2 {
                            self.stats.late_cycles += 1;
                        }
                        break;
                    }
                    if let Some(f) = self
                        .transport
                        .receive(Duration::from_nanos(deadline - now))?
                    {
                        self.on_frame(&f);
                    }
                }
                // Frames that came in while this cycle was late belong to it too.
                while let Some(f) = self.transport.receive(Duration::ZERO)? {
                    self.on_frame(&f);
                }
                let now = monotonic_ns();
                self.supervised_ns += (now - self.sync_ns).min(2 * self.cfg.period_ns);
                self.sync_ns = now;
            }
        }
        Ok(())
    }

    fn drive_index(&self, node: u8) -> Option<usize> {
        self.drives.iter().position(|d| d.node == node)
    }

    fn on_frame(&mut self, f: &CanFrame) {
        let data = f.data();
        match cob_id::classify(f.cob_id()) {
            CobKind::Tpdo { num: 1, node } if data.len() >= 6 => {
                if let Some(i) = self.drive_index(node) {
                    let d = &mut self.drives[i];
                    d.statusword = u16::from_le_bytes([data[0], data[1]]);
                    d.actual_inc = i32::from_le_bytes([data[2], data[3], data[4], data[5]]);
                    d.seen_tpdo1 = true;
                    d.answered = true;
                    d.silent = false;
                }
            }
            CobKind::Tpdo { num: 2, node } if data.len() >= 6 => {
                if let Some(i) = self.drive_index(node) {
                    let status = u16::from_le_bytes([data[0], data[1]]);
                    let value = i32::from_le_bytes([data[2], data[3], data[4], data[5]]);
                    let d = &mut self.drives[i];
                    d.tp_status = status;
                    d.tp_status_fresh = true;
                    let st = TouchProbeStatus::from_bits(status);
                    let level = st.input_level(Probe::One);
                    let rising = level && !d.probe_level;
                    d.probe_level = level;
                    // A touch while positioning (probe not armed) is a collision: brake.
                    // Every drive sees the same probe, so no node is to blame.
                    if rising && matches!(self.activity, Activity::Moving { .. }) {
                        self.abort_motion(RtError::new(
                            ErrorKind::ProbeCollision,
                            Detail::Collision,
                        ));
                        return;
                    }
                    if st.enabled(Probe::One)
                        && st.positive_edge_stored(Probe::One)
                        && d.tp_function != 0
                        && d.latch_inc.is_none()
                    {
                        d.latch_inc = Some(value);
                        d.latch_rx_ns = monotonic_ns();
                        self.try_complete_contact();
                    }
                }
            }
            CobKind::Emcy { node } => {
                if let Ok(e) = Emcy::decode(f) {
                    if let Some(i) = self.drive_index(node) {
                        if e.error_code != 0 {
                            self.drives[i].last_emcy = Some(e.error_code);
                            let mut err =
                                RtError::new(ErrorKind::DriveFault, Detail::Emcy).node(node);
                            err.code = Some(e.error_code);
                            self.set_fault(err);
                        }
                    }
                }
            }
            CobKind::Heartbeat { .. } => {
                self.heartbeat.on_frame(f, self.supervised_ns);
            }
            _ => {}
        }
    }

    /// Every drive has reported its latch: publish the contact and brake, in this cycle.
    fn try_complete_contact(&mut self) {
        let Activity::Probing {
            profile,
            t,
            direction,
            feed,
            run_id,
            ..
        } = self.activity
        else {
            return;
        };
        if self.drives.iter().any(|d| d.latch_inc.is_none()) {
            return;
        }
        let mut positions = [0.0; MAX_AXES];
        // The fraction of the last period at which the latch happened, from the axis
        // that moved most: the drives latch position, not time.
        let mut best = 0.0;
        let mut fraction = 1.0;
        for d in &self.drives {
            let latched = d.latch_inc.unwrap_or(d.actual_inc);
            positions[d.axis.index()] = latched as f64 / d.scale;
            let span = (d.target_inc as f64 - d.actual_inc as f64).abs();
            if span > best {
                best = span;
                fraction = ((latched as f64 - d.actual_inc as f64)
                    / (d.target_inc as f64 - d.actual_inc as f64))
                    .clamp(0.0, 1.0);
            }
        }
        let receive_ns = match self.cfg.pacing {
            Pacing::RealTime => monotonic_ns(),
            Pacing::Lockstep { .. } => self.sync_ns + self.cfg.period_ns,
        };
        self.sequence += 1;
        let sample = ContactSample {
            sequence: self.sequence,
            run_id,
            trigger_ns: self.sync_ns + (fraction * self.cfg.period_ns as f64) as u64,
            receive_ns,
            positions,
            direction: [direction[0], direction[1], direction[2]],
            feed,
            axis_mask: self.mask as u32,
            flags: FLAG_HW_LATCH,
        };
        match self.sink.publish(&sample) {
            Ok(()) => self.stats.samples_published += 1,
            Err(_) => self.stats.publish_failures += 1,
        }
        for d in self.drives.iter_mut() {
            d.tp_function = 0;
        }
        self.stop_pending_since = Some(receive_ns);
        self.activity = Activity::Stopping {
            profile: profile.stop_at(t, &self.limits),
            t: 0.0,
            then: Reply::Contact(sample),
        };
    }

    /// Brakes a positioning move and fails it with `err`, without marking the machine
    /// faulted (nothing is broken: the operator retracts and goes on).
    fn abort_motion(&mut self, err: RtError) {
        if let Activity::Moving { profile, t } = self.activity {
            self.activity = Activity::Stopping {
                profile: profile.stop_at(t, &self.limits),
                t: 0.0,
                then: Reply::Error(err),
            };
        }
    }

    fn set_fault(&mut self, err: RtError) {
        if self.fault.is_some() {
            return;
        }
        self.fault = Some(err);
        for d in self.drives.iter_mut() {
            d.tp_function = 0;
        }
        self.activity = match self.activity {
            Activity::Moving { profile, t } | Activity::Probing { profile, t, .. } => {
                Activity::Stopping {
                    profile: profile.stop_at(t, &self.limits),
                    t: 0.0,
                    then: Reply::Error(err),
                }
            }
            Activity::Stopping { profile, t, .. } => Activity::Stopping {
                profile,
                t,
                then: Reply::Error(err),
            },
            Activity::Arming { .. } | Activity::Settling { .. } | Activity::Enabling { .. } => {
                self.reply = Some(Reply::Error(err));
                Activity::Idle
            }
            a @ (Activity::Idle | Activity::Shutdown) => a,
        };
    }

    fn check_fault_bits(&mut self) {
        if matches!(self.activity, Activity::Enabling { .. }) {
            return;
        }
        for i in 0..self.drives.len() {
            let d = self.drives[i];
            if d.seen_tpdo1 && d.statusword & Statusword::FAULT != 0 {
                let mut err = RtError::new(ErrorKind::DriveFault, Detail::FaultBit).node(d.node);
                err.code = d.last_emcy;
                self.set_fault(err);
                return;
            }
        }
    }

    /// The axis furthest from its setpoint beyond the window, if any. A drive that is
    /// faulted, silent or the source of the fault cannot follow and is not waited for.
    fn settled(&self) -> Option<(u8, f64)> {
        let culprit = self.fault.and_then(|f| f.node);
        let mut worst: Option<(u8, f64)> = None;
        for d in &self.drives {
            if d.silent || d.statusword & Statusword::FAULT != 0 || Some(d.node) == culprit {
                continue;
            }
            let e = (d.actual() - self.setpoint[d.axis.index()]).abs();
            if e > self.cfg.in_position_window && worst.is_none_or(|w| e > w.1) {
                worst = Some((d.axis.index() as u8, e));
            }
        }
        worst
    }

    fn step(&mut self) {
        let dt = self.cfg.period_ns as f64 * 1e-9;
        let now = self.sync_ns;
        match self.activity {
            Activity::Enabling { since_ns } => {
                let mut all = true;
                for d in self.drives.iter_mut() {
                    if !d.seen_tpdo1 {
                        all = false;
                        continue;
                    }
                    // Hold where the drive is: enabling must not move anything.
                    d.target_inc = d.actual_inc;
                    let state = State::from_statusword(d.statusword);
                    match state.and_then(|s| s.command_towards_operation_enabled()) {
                        Some(cw) => {
                            all = false;
                            d.controlword = cw;
                        }
                        None if state == Some(State::OperationEnabled) => {
                            d.controlword = Controlword::ENABLE_OPERATION_CMD
                        }
                        None => all = false,
                    }
                }
                if all {
                    self.hold_all();
                    self.activity = Activity::Idle;
                    self.reply = Some(Reply::Ready {
                        positions: self.actual_positions(),
                    });
                } else if now - since_ns > self.cfg.enable_timeout_ns {
                    let (node, sw) = self
                        .drives
                        .iter()
                        .find(|d| {
                            State::from_statusword(d.statusword) != Some(State::OperationEnabled)
                        })
                        .map_or((0, 0), |d| (d.node, d.statusword));
                    let kind = if self.drives.iter().any(|d| !d.seen_tpdo1) {
                        ErrorKind::NodeLost
                    } else {
                        ErrorKind::DriveFault
                    };
                    self.fault =
                        Some(RtError::new(kind, Detail::NotEnabled { state: sw }).node(node));
                    self.reply = Some(Reply::Error(
                        self.fault.unwrap_or(RtError::new(kind, Detail::Stopped)),
                    ));
                    self.activity = Activity::Idle;
                }
            }
            Activity::Idle | Activity::Shutdown => {}
            Activity::Moving { profile, t } => {
                let t = t + dt;
                self.setpoint = profile.position(t);
                self.activity = if profile.is_done(t) {
                    Activity::Settling {
                        since_ns: now,
                        then: Reply::Done {
                            positions: profile.end(),
                        },
                    }
                } else {
                    Activity::Moving { profile, t }
                };
            }
            Activity::Arming {
                stage,
                since_ns,
                direction,
                feed,
                max_distance,
                run_id,
            } => {
                let next = match stage {
                    ArmStage::Disarm => {
                        for d in self.drives.iter_mut() {
                            d.tp_function = 0;
                            d.latch_inc = None;
                        }
                        ArmStage::Enable
                    }
                    ArmStage::Enable => {
                        for d in self.drives.iter_mut() {
                            d.tp_function = TouchProbeFunction::probe1_first_positive_edge();
                            d.tp_status_fresh = false;
                        }
                        ArmStage::WaitArmed
                    }
                    ArmStage::WaitArmed => ArmStage::WaitArmed,
                };
                let armed = matches!(stage, ArmStage::WaitArmed)
                    && self.drives.iter().all(|d| {
                        let s = TouchProbeStatus::from_bits(d.tp_status);
                        d.tp_status_fresh
                            && s.enabled(Probe::One)
                            && !s.positive_edge_stored(Probe::One)
                    });
                if armed {
                    if let Some(d) = self
                        .drives
                        .iter()
                        .find(|d| TouchProbeStatus::from_bits(d.tp_status).input_level(Probe::One))
                    {
                        let err = RtError::new(ErrorKind::AlreadyDeflected, Detail::Deflected)
                            .node(d.node);
                        for d in self.drives.iter_mut() {
                            d.tp_function = 0;
                        }
                        self.reply = Some(Reply::Error(err));
                        self.activity = Activity::Idle;
                        return;
                    }
                    let from = self.setpoint;
                    let mut to = from;
                    for i in 0..3 {
                        to[i] += direction[i] * max_distance;
                    }
                    self.activity = Activity::Probing {
                        profile: Profile::line(from, to, feed, &self.limits),
                        t: 0.0,
                        direction,
                        feed,
                        max_distance,
                        run_id,
                    };
                } else if now - since_ns > self.cfg.arm_timeout_ns {
                    for d in self.drives.iter_mut() {
                        d.tp_function = 0;
                    }
                    self.reply = Some(Reply::Error(RtError::new(
                        ErrorKind::Timeout,
                        Detail::ArmTimeout,
                    )));
                    self.activity = Activity::Idle;
                } else {
                    self.activity = Activity::Arming {
                        stage: next,
                        since_ns,
                        direction,
                        feed,
                        max_distance,
                        run_id,
                    };
                }
            }
            Activity::Probing {
                profile,
                t,
                direction,
                feed,
                max_distance,
                run_id,
            } => {
                if profile.is_done(t) && self.settled().is_none() {
                    // End of the path reached and the axes are there: no contact.
                    for d in self.drives.iter_mut() {
                        d.tp_function = 0;
                    }
                    self.reply = Some(Reply::Error(RtError::new(
                        ErrorKind::NotTriggered,
                        Detail::NotTriggered {
                            distance: max_distance,
                        },
                    )));
                    self.activity = Activity::Idle;
                    return;
                }
                let t = t + dt;
                self.setpoint = profile.position(t);
                self.activity = Activity::Probing {
                    profile,
                    t,
                    direction,
                    feed,
                    max_distance,
                    run_id,
                };
            }
            Activity::Stopping { profile, t, then } => {
                let t = t + dt;
                self.setpoint = profile.position(t);
                self.activity = if profile.is_done(t) {
                    // Answer only when the axes have come to rest, errors included.
                    Activity::Settling {
                        since_ns: now,
                        then,
                    }
                } else {
                    Activity::Stopping { profile, t, then }
                };
            }
            Activity::Settling { since_ns, then } => match self.settled() {
                None => {
                    self.reply = Some(match then {
                        Reply::Done { .. } => Reply::Done {
                            positions: self.actual_positions(),
                        },
                        other => other,
                    });
                    self.activity = Activity::Idle;
                }
                Some((axis, error)) if now - since_ns > self.cfg.settle_timeout_ns => {
                    let err = match then {
                        // The original fault says more than the axis that then lagged.
                        Reply::Error(e) => e,
                        _ => {
                            RtError::new(ErrorKind::Timeout, Detail::NotInPosition { axis, error })
                        }
                    };
                    self.reply = Some(Reply::Error(err));
                    self.activity = Activity::Idle;
                }
                Some(_) => {}
            },
        }
    }

    fn transmit(&mut self) -> Result<(), TransportError> {
        let enabled = !matches!(self.activity, Activity::Enabling { .. });
        for i in 0..self.drives.len() {
            let d = &mut self.drives[i];
            if enabled {
                d.target_inc = d.increments(self.setpoint[d.axis.index()]);
                if !matches!(self.activity, Activity::Shutdown) {
                    d.controlword = Controlword::ENABLE_OPERATION_CMD;
                }
            }
            d.answered = false;
            let mut rpdo1 = [0u8; 6];
            rpdo1[..2].copy_from_slice(&d.controlword.to_le_bytes());
            rpdo1[2..].copy_from_slice(&d.target_inc.to_le_bytes());
            let node = d.node;
            let tp = d.tp_function;
            let send_tp = d.tp_function_sent != Some(tp);
            d.tp_function_sent = Some(tp);
            if let Some(f) = CanFrame::new(cob_id::rpdo_cob(1, node), &rpdo1) {
                self.transport.transmit(&f)?;
            }
            if send_tp {
                if let Some(f) = CanFrame::new(cob_id::rpdo_cob(2, node), &tp.to_le_bytes()) {
                    self.transport.transmit(&f)?;
                }
            }
        }
        self.transport.transmit(&sync::encode())?;
        if let Some(rx) = self.stop_pending_since.take() {
            let sent = match self.cfg.pacing {
                Pacing::RealTime => monotonic_ns(),
                Pacing::Lockstep { .. } => self.sync_ns + self.cfg.period_ns,
            };
            self.stats.last_stop_latency_ns = sent.saturating_sub(rx);
            self.stats.last_stop_latency_cycles = self
                .stats
                .last_stop_latency_ns
                .div_ceil(self.cfg.period_ns)
                .max(1);
        }
        self.cycle += 1;
        Ok(())
    }

    /// Drains frames without waiting (used between cycles by tests).
    pub fn transport_mut(&mut self) -> &mut T {
        &mut self.transport
    }

    pub fn sink_mut(&mut self) -> &mut S {
        &mut self.sink
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact_sample::NullSink;
    use std::path::Path;
    use std::time::Instant;

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
        let mut rt = RtLoop::new(&machine, cfg, SyncTimes(Vec::new()), NullSink);
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
