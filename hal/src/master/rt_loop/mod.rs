//! The cyclic part of the CANopen master as a protocol core: frames in
//! ([`RtLoop::on_frame`]), frames out ([`RtLoop::tick`], once per SYNC period), time
//! as arguments. It does no I/O, reads no clock, owns no thread and allocates nothing
//! after construction, so tests step it with a fake clock. Pacing it (in real time, or
//! in lockstep with the simulator's virtual clock) is the job of the thin driver in
//! [`super::pacing`].
//!
//! Each activity has its method: [`RtLoop::supervise`] (heartbeat, EMCY, fault bits),
//! [`RtLoop::interpolate`] (enabling, moves, arming, probing, braking, settling), the
//! latch handling of `on_latch` (the first latch frame starts the stop of every axis,
//! since the probe signal is wired to all drives; the contact is published once every
//! moving axis's latch is in), the stop (`begin_stop`, `set_fault`),
//! [`RtLoop::sync_frames`] (setpoints, the master's heartbeat and SYNC) and the goodbye
//! after a shutdown (NMT reset communication, which also ends the drives' watch on the
//! master's heartbeat).
//!
//! The files: this one (the loop's state and the commands), `probing` (a probing
//! move's request, arming stage and pending contact), `latch` (probe arming and
//! latch collection), `motion` (interpolation, stop and settling), `enable` (the CiA 402
//! enable sequence), `supervision` (heartbeat, EMCY, faults), `frames` (frames in,
//! and the frames of each tick), `spindle` (the spindle drive's link) and `orient` (an
//! oriented spindle stop).

mod enable;
mod frames;
mod latch;
mod motion;
mod orient;
mod probing;
mod spindle;
mod supervision;

use super::command::{Command, Detail, Reply, RtError};
use crate::axis::{Axis, MAX_AXES};
use crate::can::CanFrame;
use crate::canopen::heartbeat::HeartbeatConsumer;
use crate::cia402::controlword::Controlword;
use crate::config::{CanOpenBusConfig, MachineConfig};
use crate::contact_sample::{ProbeWindow, SampleSink};
use crate::machine::ErrorKind;
use crate::motion::{AxisLimits, Profile};
use crate::motion_guard::{may_start_deflected, ProbeInput};
use probing::{ArmStage, PendingContact, ProbeRequest};
use spindle::{OrientStage, SpindleLink};

/// How the loop is paced: on CLOCK_MONOTONIC at the SYNC period, or in lockstep with a
/// simulator on a virtual clock (driven by `master::pacing`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Pacing {
    RealTime,
    Lockstep {
        /// Longest wall-clock wait for the drives' answers to one SYNC; a drive that
        /// does not answer in time is not waited for again (its heartbeat decides).
        answer_timeout: core::time::Duration,
    },
}

/// Most frames one tick sends: RPDO1 and RPDO2 of every axis's drive, the spindle
/// drive's RPDO1, a repeated NMT start while enabling, the master's heartbeat, then
/// SYNC.
pub const MAX_TICK_FRAMES: usize = 2 * MAX_AXES + 4;

/// Ticks after a shutdown that still send the Shutdown controlword (and SYNC, so
/// synchronous RPDOs take effect) before the goodbye.
pub const SHUTDOWN_TICKS: u32 = 3;

/// The frames of one tick, in sending order (fixed capacity: no allocation).
pub type TickFrames = heapless::Vec<CanFrame, MAX_TICK_FRAMES>;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LoopConfig {
    pub period_ns: u64,
    /// How the driver paces the loop (the core itself takes time as arguments).
    pub pacing: Pacing,
    /// A move is done when every axis is this close to its setpoint (mm / deg).
    pub in_position_window: f64,
    pub settle_timeout_ns: u64,
    pub enable_timeout_ns: u64,
    pub arm_timeout_ns: u64,
    pub heartbeat_timeout_ns: u64,
    /// The master's node ID (its heartbeat goes out on 0x700 + this).
    pub master_node: u8,
    /// Period of the master's heartbeat, ns (0: none).
    pub master_heartbeat_ns: u64,
}

impl LoopConfig {
    /// The loop's settings for `cfg`'s CANopen bus (the defaults on another bus, which
    /// the CANopen master refuses before it gets here).
    pub fn from_machine(cfg: &MachineConfig, pacing: Pacing) -> Self {
        let bus = cfg.canopen_bus().unwrap_or(&CanOpenBusConfig::DEFAULT);
        Self {
            period_ns: bus.sync_period_us as u64 * 1000,
            pacing,
            in_position_window: 0.001,
            // Settling waits for the drives' actual positions, one TPDO1 per SYNC: a bus
            // whose drives may be silent for up to the heartbeat timeout (a slow or
            // emulated host) gets 3 of those, as enabling does.
            settle_timeout_ns: (3 * bus.heartbeat_timeout_ms as u64 * 1_000_000).max(2_000_000_000),
            // Enabling is three state transitions, each a round trip per drive
            // (RPDO1 out, TPDO1 back): a bus whose drives may be silent for up to
            // the heartbeat timeout (a slow or emulated host) gets that long for each.
            enable_timeout_ns: (3 * bus.heartbeat_timeout_ms as u64 * 1_000_000).max(2_000_000_000),
            // Arming is a round trip per drive (RPDO2 out, TPDO2 back). A drive may
            // be silent for up to the heartbeat timeout and still count as alive, so
            // its answer may come that long after the enable went out, which is
            // itself a tick or more after the request: twice the heartbeat timeout.
            // (Once was not enough in an emulated VM, 2026-11-30: an answer more
            // than 4 s late from drives whose heartbeats were not.)
            arm_timeout_ns: (2 * bus.heartbeat_timeout_ms as u64 * 1_000_000).max(200_000_000),
            heartbeat_timeout_ns: bus.heartbeat_timeout_ms as u64 * 1_000_000,
            master_node: bus.master_node,
            master_heartbeat_ns: bus.master_heartbeat_ms as u64 * 1_000_000,
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
    /// First latch frame received -> stop setpoint sent, of the last contact, ns.
    pub last_stop_latency_ns: u64,
    /// The cycle whose SYNC carried the stop, counted from the cycle in which the
    /// first latch frame arrived (1: the very next SYNC).
    pub last_stop_latency_cycles: u64,
    /// The fault that stopped the machine (heartbeat lost, EMCY, fault bit), if any:
    /// the loop refuses motion from then on.
    pub fault: Option<RtError>,
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
    /// Probe input level last reported (bit 7 of the touch probe status).
    probe_input: ProbeInput,
    latch_inc: Option<i32>,
    last_emcy: Option<u16>,
    controlword: u16,
    target_inc: i32,
    tp_function: u16,
    tp_function_sent: Option<u16>,
}

impl DriveLink {
    fn new(axis: Axis, node: u8, scale: f64) -> Self {
        Self {
            axis,
            node,
            scale,
            statusword: 0,
            seen_tpdo1: false,
            answered: false,
            silent: false,
            actual_inc: 0,
            tp_status: 0,
            tp_status_fresh: false,
            probe_input: ProbeInput::default(),
            latch_inc: None,
            last_emcy: None,
            controlword: Controlword::SHUTDOWN,
            target_inc: 0,
            tp_function: 0,
            tp_function_sent: None,
        }
    }

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
        request: ProbeRequest,
    },
    Probing {
        profile: Profile,
        t: f64,
        request: ProbeRequest,
    },
    /// Braking along the path; then `then` is answered (after the axes settle, unless
    /// it is an error: a faulted drive would never settle).
    Stopping {
        profile: Profile,
        t: f64,
        then: Reply,
    },
    /// An oriented spindle stop; the axes hold.
    Orienting {
        stage: OrientStage,
        since_ns: u64,
    },
    /// Waiting for the actual positions to reach the setpoint.
    Settling {
        since_ns: u64,
        then: Reply,
    },
    Shutdown,
}

pub struct RtLoop<S: SampleSink> {
    sink: S,
    cfg: LoopConfig,
    drives: heapless::Vec<DriveLink, MAX_AXES>,
    /// The spindle's drive (profile position), when the machine has one.
    spindle: Option<SpindleLink>,
    limits: AxisLimits,
    mask: u8,
    heartbeat: HeartbeatConsumer,
    /// Time of the SYNC most recently sent (the `now_ns` of the last tick).
    sync_ns: u64,
    /// Clock of the heartbeat supervision and of every wait for the drives (enable,
    /// arm, settle, oriented stop): advances with the loop but at most two periods per
    /// tick, so a stall of the loop itself (no SCHED_FIFO on a loaded machine) is not
    /// taken for silent nodes or slow drives: a loop that was not running gave them
    /// nothing to answer (an arm frame not yet sent). Real losses and drives that do
    /// not answer are still seen after the timeout of supervised time.
    supervised_ns: u64,
    setpoint: [f64; MAX_AXES],
    activity: Activity,
    reply: Option<Reply>,
    fault: Option<RtError>,
    sequence: u64,
    /// The first latch frame's arrival and the SYNC of its cycle, until the stop
    /// goes out.
    stop_pending_since: Option<(u64, u64)>,
    contact: Option<PendingContact>,
    /// The probe signal as the drives report it together (see `on_latch`).
    probe_signal: bool,
    /// The linear direction of the motion during which the probe signal last rose
    /// (a probing contact or a collision); `None` when it rose at rest (the stylus
    /// was in contact before anything moved). See [`RtLoop::deflected_move`].
    deflected_along: Option<[f64; 3]>,
    stats: LoopStats,
    /// Enabling: when the NMT start was last repeated (supervised clock); due to go
    /// out with this tick.
    nmt_start_at_ns: u64,
    nmt_start_due: bool,
    /// Arming: cycles waited for the drives to report armed since the last enable.
    arm_waits: u32,
    /// Arming: touch probe functions enabled since the probe request (the first and
    /// the retries), for the timeout's message.
    arm_enables: u32,
    /// Arming again after a wait: only the drives that did not report armed.
    arm_retry: bool,
    /// When the master's next heartbeat is due (`None`: the first tick sends one).
    heartbeat_due_ns: Option<u64>,
    /// Ticks since the shutdown; after [`SHUTDOWN_TICKS`] the goodbye goes out.
    shutdown_ticks: u32,
    /// A probing move started with this tick: told to the sink once its frames are out.
    window_due: Option<ProbeWindow>,
}

impl<S: SampleSink> RtLoop<S> {
    /// A loop for the drives of `cfg`, which must already be configured and
    /// operational (see `startup`), starting at `now_ns`. The first ticks walk them to
    /// Operation enabled; [`Reply::Ready`] is answered when they are there.
    pub fn new(machine: &MachineConfig, cfg: LoopConfig, sink: S, now_ns: u64) -> Self {
        let mut drives = heapless::Vec::new();
        let limits = AxisLimits::of(machine);
        let mut heartbeat = HeartbeatConsumer::new();
        for a in &machine.axes {
            // MachineConfig allows at most one entry per axis, so at most 6.
            let node = a.canopen_node();
            let _ = drives.push(DriveLink::new(a.name, node, a.increments_per_unit));
            // Node IDs were validated (1..=127) with the configuration.
            let _ = heartbeat.watch(node, cfg.heartbeat_timeout_ns);
        }
        let spindle = machine.spindle.as_ref().map(|s| {
            let _ = heartbeat.watch(s.node, cfg.heartbeat_timeout_ns);
            SpindleLink::new(s, cfg.settle_timeout_ns)
        });
        Self {
            sink,
            cfg,
            drives,
            spindle,
            limits,
            mask: machine.axis_mask(),
            heartbeat,
            sync_ns: now_ns,
            supervised_ns: 0,
            setpoint: [0.0; MAX_AXES],
            activity: Activity::Enabling { since_ns: 0 },
            reply: None,
            fault: None,
            sequence: 0,
            stop_pending_since: None,
            contact: None,
            probe_signal: false,
            deflected_along: None,
            stats: LoopStats::default(),
            nmt_start_at_ns: 0,
            nmt_start_due: false,
            arm_waits: 0,
            arm_enables: 0,
            arm_retry: false,
            heartbeat_due_ns: None,
            shutdown_ticks: 0,
            window_due: None,
        }
    }

    pub fn config(&self) -> &LoopConfig {
        &self.cfg
    }

    pub fn stats(&self) -> LoopStats {
        LoopStats {
            fault: self.fault,
            ..self.stats
        }
    }

    /// Time of the SYNC most recently sent (the `now_ns` of the last tick).
    pub fn now_ns(&self) -> u64 {
        self.sync_ns
    }

    pub fn is_shut_down(&self) -> bool {
        matches!(self.activity, Activity::Shutdown)
    }

    /// The shutdown is complete: the drives got the Shutdown controlword for
    /// [`SHUTDOWN_TICKS`] ticks, then the goodbye (NMT reset communication). Nothing
    /// is left to send.
    pub fn is_finished(&self) -> bool {
        self.is_shut_down() && self.shutdown_ticks > SHUTDOWN_TICKS
    }

    /// The answer to the last command, once it is finished.
    pub fn take_reply(&mut self) -> Option<Reply> {
        self.reply.take()
    }

    /// Is a command running (or start-up not finished)?
    pub fn is_busy(&self) -> bool {
        !matches!(self.activity, Activity::Idle | Activity::Shutdown) || self.reply.is_some()
    }

    /// Does a drive that has not fallen silent still owe its answer (TPDO1) to the
    /// last SYNC?
    pub fn answers_pending(&self) -> bool {
        self.drives.iter().any(|d| !d.answered && !d.silent)
            || self.spindle.is_some_and(|s| !s.answered && !s.silent)
    }

    /// The driver stops waiting for this SYNC's answers: drives that did not answer
    /// are not waited for again until they do (their heartbeat decides). When no drive
    /// answered (the SYNC was lost, or the simulation is late), all are waited for
    /// again: with none to wait for, a lockstep loop would run ahead of the drives'
    /// clock and take their heartbeats for lost.
    pub fn stop_waiting_for_answers(&mut self) {
        if !self.drives.iter().any(|d| d.answered) {
            return;
        }
        for d in self.drives.iter_mut() {
            if !d.answered {
                d.silent = true;
            }
        }
        if let Some(s) = self.spindle.as_mut() {
            if !s.answered {
                s.silent = true;
            }
        }
    }

    pub fn sink_mut(&mut self) -> &mut S {
        &mut self.sink
    }

    /// Accepts a command; it is carried out by the following ticks.
    pub fn submit(&mut self, cmd: Command) {
        if let Command::Shutdown = cmd {
            self.hold_all();
            for d in self.drives.iter_mut() {
                d.controlword = Controlword::SHUTDOWN;
                d.tp_function = 0;
            }
            if let Some(s) = self.spindle.as_mut() {
                s.controlword = Controlword::SHUTDOWN;
            }
            self.activity = Activity::Shutdown;
            return;
        }
        if let Command::Stop = cmd {
            self.stop_requested();
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
        match cmd {
            Command::MoveTo { target, mask, feed } => {
                let from = self.setpoint;
                let mut to = from;
                for i in 0..MAX_AXES {
                    if mask & self.mask & (1 << i) != 0 {
                        to[i] = target[i];
                    }
                }
                if let Some(err) = self.deflected_move(&from, &to) {
                    self.reply = Some(Reply::Error(err));
                    return;
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
                self.arm_retry = false;
                self.arm_enables = 0;
                self.activity = Activity::Arming {
                    stage: ArmStage::Disarm,
                    since_ns: self.supervised_ns,
                    request: ProbeRequest {
                        direction,
                        feed,
                        max_distance,
                        run_id,
                    },
                };
            }
            Command::OrientSpindle { angle_deg } => self.begin_orient(angle_deg),
            Command::Positions | Command::Stop | Command::Shutdown => {}
        }
    }

    /// A positioning move from `from` to `to` while the probe signal is already high
    /// (no rising edge will tell a collision): allowed only out of the contact,
    /// against the motion that made it (the retraction after a probing contact or a
    /// collision), see [`may_start_deflected`]. Anything else, and any
    /// move when the stylus was deflected before the last motion (a start inside
    /// material), would push the stylus further in until it breaks; it is refused with
    /// the point, before anything moves.
    fn deflected_move(&self, from: &[f64; MAX_AXES], to: &[f64; MAX_AXES]) -> Option<RtError> {
        if !self.probe_signal {
            return None;
        }
        let linear = [0, 1, 2].map(|i| to[i] - from[i]);
        let rotary = (3..MAX_AXES).any(|i| to[i] != from[i]);
        if may_start_deflected(self.deflected_along, linear, rotary) {
            return None;
        }
        Some(RtError::new(
            ErrorKind::AlreadyDeflected,
            Detail::DeflectedBeforeMove {
                at: [from[0], from[1], from[2]],
            },
        ))
    }

    /// The operator's stop: brake any motion and answer its command as aborted; a
    /// command that has not moved yet (arming, settling) is answered at once. Nothing
    /// is faulted: the drives stay enabled until the shutdown that follows.
    fn stop_requested(&mut self) {
        let err = RtError::new(ErrorKind::Aborted, Detail::Aborted);
        self.contact = None;
        match self.activity {
            Activity::Moving { profile, t } | Activity::Probing { profile, t, .. } => {
                self.disarm_all();
                self.begin_stop(profile, t, Reply::Error(err));
            }
            Activity::Stopping { profile, t, .. } => {
                self.activity = Activity::Stopping {
                    profile,
                    t,
                    then: Reply::Error(err),
                };
            }
            Activity::Arming { .. } | Activity::Settling { .. } => {
                self.disarm_all();
                self.hold_all();
                self.reply = Some(Reply::Error(err));
                self.activity = Activity::Idle;
            }
            Activity::Orienting { .. } => {
                self.halt_spindle();
                self.reply = Some(Reply::Error(err));
                self.activity = Activity::Idle;
            }
            Activity::Enabling { .. } | Activity::Idle | Activity::Shutdown => {}
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

    fn disarm_all(&mut self) {
        for d in self.drives.iter_mut() {
            d.tp_function = 0;
        }
    }
}

#[cfg(test)]
mod tests {
    //! The core driven by a fake clock (a counter) and fake drives that answer in the
    //! test's thread: no transport, no sleeps.

    use super::*;
    use crate::canopen::cob_id::{self, CobKind};
    use crate::canopen::emcy::Emcy;
    use crate::canopen::heartbeat;
    use crate::canopen::nmt::{self, NmtCommand, NmtState};
    use crate::canopen::sync;
    use crate::cia402::state::State;
    use crate::cia402::touch_probe::{TouchProbeFunction, TouchProbeStatus};
    use crate::contact_sample::SinkError;
    use crate::contact_sample::{ContactSample, FLAG_HW_LATCH};
    use crate::machine::MachineError;
    use crate::master::process_data::{ProcessData, Rpdo1, Rpdo2, Tpdo1, Tpdo2};
    use std::path::Path;

    const PERIOD: u64 = 2_000_000;
    const SCALE: f64 = 1000.0;

    fn machine() -> MachineConfig {
        let axis = |name: &str, node: u8| {
            format!(
                "[[axis]]\nname = \"{name}\"\nnode = {node}\nincrements_per_unit = {SCALE}\n\
                 min = -500.0\nmax = 500.0\nmax_feed = 6000.0\nmax_acceleration = 1000.0\n"
            )
        };
        let text = format!(
            "name = \"fake\"\n{}{}{}",
            axis("X", 1),
            axis("Y", 2),
            axis("Z", 3)
        );
        MachineConfig::parse(&text, Path::new("fake.toml")).unwrap()
    }

    #[derive(Default)]
    struct Collect(Vec<ContactSample>);

    impl SampleSink for Collect {
        fn publish(&mut self, s: &ContactSample) -> Result<(), SinkError> {
            self.0.push(*s);
            Ok(())
        }
    }

    /// A CiA 402 drive reduced to what the loop sees: it follows the target at once.
    struct FakeDrive {
        node: u8,
        state: State,
        prev_cw: u16,
        actual: i32,
        target: i32,
        tp_function: u16,
        tp_status: u16,
        latched: i32,
        last_tpdo2: Option<Tpdo2>,
        /// A drive that ignores Switch on (stays in Ready to switch on).
        refuses_switch_on: bool,
        /// A drive whose stored edge survives enabling touch probe 1 again.
        keeps_stored_edge: bool,
    }

    impl FakeDrive {
        fn new(node: u8) -> Self {
            Self {
                node,
                state: State::SwitchOnDisabled,
                prev_cw: 0,
                actual: 0,
                target: 0,
                tp_function: 0,
                tp_status: 0,
                latched: 0,
                last_tpdo2: None,
                refuses_switch_on: false,
                keeps_stored_edge: false,
            }
        }

        fn on_frame(&mut self, f: &CanFrame) {
            match cob_id::classify(f.cob_id()) {
                CobKind::Rpdo { num: 1, node } if node == self.node => {
                    let r = Rpdo1::decode(f).unwrap();
                    let next = self
                        .state
                        .on_controlword(r.controlword, self.prev_cw, false);
                    if !(self.refuses_switch_on && next == State::SwitchedOn) {
                        self.state = next;
                    }
                    self.prev_cw = r.controlword;
                    self.target = r.target_position;
                }
                CobKind::Rpdo { num: 2, node } if node == self.node => {
                    self.tp_function = Rpdo2::decode(f).unwrap().touch_probe_function;
                    let mut kept = TouchProbeStatus::INPUT_LEVEL;
                    if self.keeps_stored_edge {
                        kept |= TouchProbeStatus::POSITIVE_EDGE_STORED;
                    }
                    self.tp_status = self.tp_status & kept
                        | if self.tp_function & TouchProbeFunction::ENABLE != 0 {
                            TouchProbeStatus::ENABLED
                        } else {
                            0
                        };
                }
                _ => {}
            }
        }

        /// The answer to SYNC: TPDO2 when it changed, then TPDO1.
        fn answer_sync(&mut self, out: &mut Vec<CanFrame>) {
            if self.state == State::OperationEnabled {
                self.actual = self.target;
            }
            let tp2 = Tpdo2 {
                touch_probe_status: self.tp_status,
                probe1_positive_edge: self.latched,
            };
            if self.last_tpdo2 != Some(tp2) {
                self.last_tpdo2 = Some(tp2);
                out.push(tp2.encode(self.node));
            }
            let tp1 = Tpdo1 {
                statusword: self.state.statusword_bits(),
                position_actual: self.actual,
            };
            out.push(tp1.encode(self.node));
        }

        /// The probe signal rises: an armed probe 1 latches where the axis is.
        fn touch(&mut self) {
            if self.tp_status & TouchProbeStatus::ENABLED != 0 {
                self.latched = self.actual;
                self.tp_status |= TouchProbeStatus::POSITIVE_EDGE_STORED;
            }
            self.tp_status |= TouchProbeStatus::INPUT_LEVEL;
        }
    }

    /// The loop, three fake drives and the fake clock.
    struct Bench {
        rt: RtLoop<Collect>,
        drives: Vec<FakeDrive>,
        now: u64,
        sent: TickFrames,
        heartbeats: bool,
        /// Latch frames (TPDO2) of these nodes are held back until `release_latches`.
        hold_latches_of: Vec<u8>,
        held: Vec<CanFrame>,
    }

    impl Bench {
        fn new() -> Self {
            let m = machine();
            let cfg = LoopConfig::from_machine(
                &m,
                Pacing::Lockstep {
                    answer_timeout: core::time::Duration::ZERO,
                },
            );
            Self {
                rt: RtLoop::new(&m, cfg, Collect::default(), 0),
                drives: (1..=3).map(FakeDrive::new).collect(),
                now: 0,
                sent: TickFrames::new(),
                heartbeats: true,
                hold_latches_of: Vec::new(),
                held: Vec::new(),
            }
        }

        /// One period: tick, the drives take the frames and answer within the period.
        fn tick(&mut self) {
            self.now += PERIOD;
            self.rt.tick(self.now, &mut self.sent);
            self.rt.frames_sent(self.now);
            let mut answers = Vec::new();
            for f in &self.sent {
                for d in &mut self.drives {
                    d.on_frame(f);
                }
                if f.cob_id() == sync::encode().cob_id() {
                    for d in &mut self.drives {
                        if self.heartbeats {
                            answers.push(heartbeat::encode(d.node, NmtState::Operational));
                        }
                        d.answer_sync(&mut answers);
                    }
                }
            }
            for f in &answers {
                let node = (f.cob_id() & 0x7F) as u8;
                if f.cob_id() == Tpdo2::cob_id(node) && self.hold_latches_of.contains(&node) {
                    self.held.push(*f);
                } else {
                    self.rt.on_frame(f, self.now + PERIOD / 2);
                }
            }
        }

        /// The held-back latch frames arrive now, in this cycle.
        fn release_latches(&mut self) {
            self.hold_latches_of.clear();
            for f in std::mem::take(&mut self.held) {
                self.rt.on_frame(&f, self.now + PERIOD / 2);
            }
        }

        fn until_reply(&mut self) -> Reply {
            for _ in 0..10_000 {
                self.tick();
                if let Some(r) = self.rt.take_reply() {
                    return r;
                }
            }
            panic!("no reply within 10 000 periods");
        }

        fn enabled() -> Self {
            let mut b = Self::new();
            assert!(matches!(b.until_reply(), Reply::Ready { .. }));
            b
        }

        /// Submits a move of `axis` (0 = X) to `to`, the other axes staying, at 3000.
        fn move_axis(&mut self, axis: usize, to: f64) {
            let mut target = [0.0; MAX_AXES];
            target[axis] = to;
            self.rt.submit(Command::MoveTo {
                target,
                mask: 0b111,
                feed: 3000.0,
            });
        }

        /// The RPDO1 sent to `node` by the last tick.
        fn rpdo1(&self, node: u8) -> Rpdo1 {
            let f = self
                .sent
                .iter()
                .find(|f| f.cob_id() == Rpdo1::cob_id(node))
                .expect("RPDO1 every SYNC");
            Rpdo1::decode(f).unwrap()
        }
    }

    /// The operator's stop mid-move: the move is braked short of its target and
    /// answered as aborted, the machine is not faulted, and the loop takes commands.
    #[test]
    fn stop_brakes_a_move_under_way_and_answers_aborted() {
        let mut b = Bench::enabled();
        b.move_axis(0, 400.0);
        for _ in 0..200 {
            b.tick();
        }
        assert!(b.rt.take_reply().is_none(), "the move is still under way");
        b.rt.submit(Command::Stop);
        let reply = b.until_reply();
        let Reply::Error(e) = reply else {
            panic!("expected an aborted move, got {reply:?}");
        };
        assert_eq!(e.kind, ErrorKind::Aborted);
        let x = b.rt.actual_positions()[0];
        assert!(x > 0.0 && x < 400.0, "braked short of the target: X = {x}");
        b.rt.submit(Command::Positions);
        assert!(matches!(b.rt.take_reply(), Some(Reply::Done { .. })));
        b.rt.submit(Command::Stop);
        assert!(
            b.rt.take_reply().is_none(),
            "a stop while idle answers nothing"
        );
    }

    #[test]
    fn sync_sends_every_drives_rpdo1_the_heartbeat_then_sync_and_rpdo2_only_on_change() {
        let mut b = Bench::new();
        b.rt.tick(PERIOD, &mut b.sent);
        let frame = |id, d: &[u8]| CanFrame::new(id, d).unwrap();
        // Shutdown (0x0006) at target 0, the touch probe function 0, the master's
        // first heartbeat (node 127, operational), then SYNC.
        assert_eq!(
            b.sent.as_slice(),
            &[
                frame(0x201, &[0x06, 0, 0, 0, 0, 0]),
                frame(0x301, &[0, 0]),
                frame(0x202, &[0x06, 0, 0, 0, 0, 0]),
                frame(0x302, &[0, 0]),
                frame(0x203, &[0x06, 0, 0, 0, 0, 0]),
                frame(0x303, &[0, 0]),
                frame(0x77F, &[0x05]),
                frame(0x080, &[]),
            ]
        );
        b.rt.tick(2 * PERIOD, &mut b.sent);
        assert_eq!(b.sent.len(), 4, "RPDO2 unchanged: not sent again");
        assert_eq!(b.rt.stats().cycles, 2);
    }

    #[test]
    fn enabling_walks_every_drive_through_the_cia402_states() {
        let mut b = Bench::new();
        let mut controlwords = Vec::new();
        let reply = loop {
            b.tick();
            let cw = b.rpdo1(3).controlword;
            if controlwords.last() != Some(&cw) {
                controlwords.push(cw);
            }
            if let Some(r) = b.rt.take_reply() {
                break r;
            }
        };
        assert!(matches!(reply, Reply::Ready { .. }), "{reply:?}");
        assert_eq!(controlwords, [0x0006, 0x0007, 0x000F]);
        assert!(b.drives.iter().all(|d| d.state == State::OperationEnabled));
    }

    /// A drive that stays in Ready to switch on: enabling fails after the configured
    /// time and not before, naming the node, the time waited and the state.
    #[test]
    fn a_drive_that_does_not_switch_on_fails_enabling_after_the_timeout() {
        let mut b = Bench::new();
        let timeout = b.rt.config().enable_timeout_ns;
        b.drives[1].refuses_switch_on = true;
        let reply = loop {
            b.tick();
            if let Some(r) = b.rt.take_reply() {
                break r;
            }
        };
        assert!(b.now > timeout, "failed after {} of {timeout} ns", b.now);
        assert!(b.now <= timeout + 2 * PERIOD, "failed late: {} ns", b.now);
        let Reply::Error(e) = reply else {
            panic!("expected the enable to fail, got {reply:?}");
        };
        assert_eq!((e.kind, e.node), (ErrorKind::DriveFault, Some(2)));
        let m = crate::machine::MachineError::from(e).message;
        assert!(
            m.contains("did not reach Operation enabled in 200")
                && m.contains(": ReadyToSwitchOn)"),
            "{m}"
        );
    }

    /// A spindle drive (node 4) that never acknowledges a set-point (the fake ignores
    /// bit 4, as a drive not in profile position would): the oriented stop fails after
    /// a whole turn at the orienting speed plus the settle timeout, names the angle,
    /// and the spindle is halted (bit 8).
    #[test]
    fn an_oriented_stop_the_drive_never_acknowledges_times_out_and_halts_it() {
        let mut m = machine();
        m.spindle = Some(crate::config::SpindleConfig {
            node: 4,
            increments_per_degree: 1000.0,
            orient_rpm: 300.0,
            orient_acceleration: 36_000.0,
        });
        let cfg = LoopConfig::from_machine(
            &m,
            Pacing::Lockstep {
                answer_timeout: core::time::Duration::ZERO,
            },
        );
        let mut b = Bench::new();
        b.rt = RtLoop::new(&m, cfg, Collect::default(), 0);
        b.drives.push(FakeDrive::new(4));
        assert!(matches!(b.until_reply(), Reply::Ready { .. }));
        b.rt.submit(Command::OrientSpindle { angle_deg: 180.0 });
        let started = b.now;
        let Reply::Error(e) = b.until_reply() else {
            panic!("an oriented stop without acknowledge succeeded");
        };
        let waited = b.now - started;
        // A turn at 300 rpm is 0.2 s.
        let timeout = cfg.settle_timeout_ns + 200_000_000;
        assert!(
            waited > timeout && waited <= timeout + 2 * PERIOD,
            "{waited} ns"
        );
        assert_eq!((e.kind, e.node), (ErrorKind::Timeout, Some(4)), "{e:?}");
        let msg = crate::machine::MachineError::from(e).message;
        assert!(
            msg.contains("did not acknowledge the set-point 180.000°"),
            "{msg}"
        );
        // The halt went out with the SYNC that ended the stop; the axes' drives stay
        // enabled.
        let cw = b.rpdo1(4).controlword;
        assert_eq!(cw & Controlword::HALT, Controlword::HALT, "0x{cw:04X}");
        assert_eq!(b.rpdo1(1).controlword, Controlword::ENABLE_OPERATION_CMD);
        // The loop takes commands: a move goes on.
        b.move_axis(0, 0.5);
        assert!(matches!(b.until_reply(), Reply::Done { .. }));
    }

    /// A bus whose drives may be silent for seconds (a slow or emulated host) gives
    /// each of the three enable transitions that long, and a move 3 times that to settle.
    #[test]
    fn the_enable_and_settle_timeouts_follow_the_heartbeat_timeout() {
        let mut m = machine();
        let pacing = Pacing::Lockstep {
            answer_timeout: core::time::Duration::ZERO,
        };
        assert_eq!(
            LoopConfig::from_machine(&m, pacing).enable_timeout_ns,
            2_000_000_000
        );
        assert_eq!(
            LoopConfig::from_machine(&m, pacing).settle_timeout_ns,
            2_000_000_000
        );
        let mut bus = CanOpenBusConfig::DEFAULT;
        bus.heartbeat_timeout_ms = 2000;
        m.bus = crate::config::BusConfig::CanOpen(bus);
        assert_eq!(
            LoopConfig::from_machine(&m, pacing).enable_timeout_ns,
            6_000_000_000
        );
        assert_eq!(
            LoopConfig::from_machine(&m, pacing).settle_timeout_ns,
            6_000_000_000
        );
    }

    #[test]
    fn interpolation_reaches_the_target_within_the_feed() {
        let mut b = Bench::enabled();
        b.move_axis(0, 10.0);
        let mut prev = 0;
        let mut steps = 0;
        let reply = loop {
            b.tick();
            let x = b.rpdo1(1).target_position;
            // 3000 mm/min = 50 mm/s: 0.1 mm = 100 increments per 2 ms period at most.
            assert!((0..=100).contains(&(x - prev)), "{prev} -> {x}");
            prev = x;
            steps += 1;
            if let Some(r) = b.rt.take_reply() {
                break r;
            }
        };
        assert_eq!(prev, 10_000);
        assert!(steps >= 100, "10 mm at 0.1 mm per period: {steps} periods");
        match reply {
            Reply::Done { positions } => assert!((positions[0] - 10.0).abs() < 1e-9),
            other => panic!("{other:?}"),
        }
    }

    /// The loop itself stalls for 15 s between the arm request and the touch probe
    /// function going out (an emulated VM on a loaded host did): the drives had
    /// nothing to answer yet, so that is no arm timeout. The function goes out after
    /// the stall, the drives report armed, and the probing move starts.
    #[test]
    fn a_stall_of_the_loop_while_arming_is_not_an_arm_timeout() {
        let mut b = Bench::enabled();
        assert!(b.rt.config().arm_timeout_ns < 15_000_000_000);
        b.rt.submit(Command::Probe {
            direction: [0.0, 0.0, -1.0],
            feed: 600.0,
            max_distance: 5.0,
            run_id: 9,
        });
        b.tick(); // Disarm: nothing changes on the bus yet
        assert!(!b.sent.iter().any(|f| f.cob_id() == Rpdo2::cob_id(3)));
        b.now += 15_000_000_000;
        let mut moved = false;
        for _ in 0..50 {
            b.tick();
            assert!(b.rt.take_reply().is_none(), "no timeout after the stall");
            if b.rpdo1(3).target_position != 0 {
                moved = true;
                break;
            }
        }
        assert!(moved, "armed after the stall, the probing move started");
    }

    /// Nothing answers the arm at all: the timeout still comes, after the arm
    /// timeout of loop time, and names the first drive.
    #[test]
    fn drives_that_never_report_armed_time_out_after_the_arm_timeout() {
        let mut b = Bench::enabled();
        b.hold_latches_of = vec![1, 2, 3];
        b.rt.submit(Command::Probe {
            direction: [0.0, 0.0, -1.0],
            feed: 600.0,
            max_distance: 5.0,
            run_id: 9,
        });
        let timeout = b.rt.config().arm_timeout_ns;
        let t0 = b.now;
        let reply = b.until_reply();
        let Reply::Error(e) = reply else {
            panic!("{reply:?}")
        };
        assert_eq!(e.kind, ErrorKind::Timeout, "{e:?}");
        assert_eq!(e.node, Some(1));
        let waited = b.now - t0;
        assert!(
            waited > timeout && waited <= timeout + 4 * PERIOD,
            "{waited}"
        );
        // The error says what was tried and what came back: nothing, after the
        // first enable and a retry every quarter of the timeout.
        match e.detail {
            Detail::ArmTimeout {
                waited_ms,
                enables,
                status,
            } => {
                assert_eq!(status, None);
                assert_eq!(enables, 4);
                let ns = waited_ms * 1e6;
                assert!(
                    ns > timeout as f64 && ns <= (timeout + 4 * PERIOD) as f64,
                    "{waited_ms}"
                );
            }
            ref other => panic!("{other:?}"),
        }
        let m = MachineError::from(e).to_string();
        assert!(
            m.contains("touch probe 1 of node 1 did not report armed in ")
                && m.contains(
                    "no touch probe status (TPDO2) came since the last of 4 enables sent"
                ),
            "{m}"
        );
    }

    /// A drive that answers the enable with an edge still stored (one that does not
    /// clear it on enabling again): never armed, and the timeout shows its status.
    #[test]
    fn an_arm_timeout_names_the_drive_and_the_status_it_answered() {
        let mut b = Bench::enabled();
        b.drives[1].keeps_stored_edge = true;
        b.drives[1].tp_status |= TouchProbeStatus::POSITIVE_EDGE_STORED;
        b.rt.submit(Command::Probe {
            direction: [0.0, 0.0, -1.0],
            feed: 600.0,
            max_distance: 5.0,
            run_id: 9,
        });
        let Reply::Error(e) = b.until_reply() else {
            panic!("armed with an edge stored")
        };
        assert_eq!((e.kind, e.node), (ErrorKind::Timeout, Some(2)), "{e:?}");
        let m = MachineError::from(e).to_string();
        assert!(
            m.contains("touch probe 1 of node 2 did not report armed in 30")
                && m.contains(
                    " ms: its touch probe status 0x0003 (probe 1 enabled, an edge stored) answered the last of 4 enables sent; nothing moved"
                ),
            "{m}"
        );
        assert_eq!(
            b.rpdo1(3).target_position,
            0,
            "nothing moved: the probing move never started"
        );
    }

    /// Probes down Z, touching after `periods` of the probing move.
    fn probe_and_touch(b: &mut Bench, periods: usize) -> Option<Reply> {
        b.rt.submit(Command::Probe {
            direction: [0.0, 0.0, -1.0],
            feed: 600.0,
            max_distance: 5.0,
            run_id: 9,
        });
        let mut moving = 0;
        while moving < periods {
            b.tick();
            if b.rpdo1(3).target_position != 0 {
                moving += 1;
            }
            if let Some(r) = b.rt.take_reply() {
                return Some(r);
            }
        }
        for d in &mut b.drives {
            d.touch();
        }
        None
    }

    #[test]
    fn the_last_drives_latch_publishes_one_contact_at_the_latched_positions() {
        let mut b = Bench::enabled();
        assert!(probe_and_touch(&mut b, 20).is_none());
        let z_latched = b.drives[2].actual;
        b.tick();
        // Published while the latch frames were taken in, before the next tick.
        assert_eq!(b.rt.sink_mut().0.len(), 1);
        let s = b.rt.sink_mut().0[0];
        assert_eq!(s.positions[2], z_latched as f64 / SCALE);
        assert_eq!((s.sequence, s.run_id, s.flags), (1, 9, FLAG_HW_LATCH));
        assert_eq!(s.receive_ns, b.now + PERIOD / 2);
        // The probe is disarmed with the same tick that starts the stop.
        let disarm = Rpdo2::cob_id(3);
        b.tick();
        assert!(b.sent.iter().any(|f| f.cob_id() == disarm));
        match b.until_reply() {
            Reply::Contact(c) => assert_eq!(c.sequence, 1),
            other => panic!("{other:?}"),
        }
        assert_eq!(b.rt.sink_mut().0.len(), 1, "exactly one sample");
    }

    #[test]
    fn the_stop_brakes_within_the_acceleration_and_ends_beyond_the_contact() {
        let mut b = Bench::enabled();
        assert!(probe_and_touch(&mut b, 50).is_none());
        b.tick(); // latches in: the stop starts
        let at_contact = b.rpdo1(3).target_position;
        let mut path = vec![at_contact];
        let reply = loop {
            b.tick();
            path.push(b.rpdo1(3).target_position);
            if let Some(r) = b.rt.take_reply() {
                break r;
            }
        };
        assert!(matches!(reply, Reply::Contact(_)), "{reply:?}");
        let end = *path.last().unwrap();
        // 10 mm/s at 1000 mm/s^2: 0.05 mm = 50 increments of braking, monotonic.
        assert!(path.windows(2).all(|w| w[1] <= w[0]), "{path:?}");
        assert!((at_contact - end - 50).abs() <= 2, "{at_contact} -> {end}");
        assert_eq!(b.rt.stats().last_stop_latency_cycles, 1);
    }

    /// The probe signal reaches every drive, so the first latch frame stops all axes
    /// with the next SYNC; the contact waits for the moving axis's latch (Z, node 3),
    /// held back here for two more cycles.
    #[test]
    fn the_first_latch_frame_stops_every_axis_and_the_sample_waits_for_the_moving_axis() {
        let mut b = Bench::enabled();
        let mut twin = Bench::enabled();
        assert!(probe_and_touch(&mut b, 20).is_none());
        assert!(probe_and_touch(&mut twin, 20).is_none());
        // Armed and touched: from here on the latch frames of these nodes wait.
        b.hold_latches_of = vec![2, 3];
        twin.hold_latches_of = vec![1, 2, 3];
        let z_latched = b.drives[2].actual;
        // The touch cycle: only node 1's latch frame (X, not moving) arrives.
        b.tick();
        twin.tick();
        assert!(b.rt.sink_mut().0.is_empty(), "Z's latch is not in yet");
        let probing_step = twin.rpdo1(3).target_position;
        // The very next tick carries the stop: Z's setpoint brakes, where the twin
        // (no latch frame at all) goes on at the probing feed.
        b.tick();
        twin.tick();
        let (braking, probing) = (b.rpdo1(3).target_position, twin.rpdo1(3).target_position);
        // 600 mm/min = 0.02 mm = 20 increments per 2 ms down; braking at 1000 mm/s^2
        // takes 2 ms * 2 ms * 1000 / 2 = 0.002 mm = 2 increments off the first step.
        assert_eq!(probing - probing_step, -20);
        assert!(
            braking > probing && braking - probing <= 4,
            "stop setpoint {braking}, probing {probing}"
        );
        assert_eq!(b.rt.stats().last_stop_latency_cycles, 1);
        assert!(b.rt.sink_mut().0.is_empty(), "still no sample");
        b.tick();
        assert!(
            b.rt.take_reply().is_none(),
            "the stop waits for the contact"
        );
        // Z's latch arrives two cycles late: the sample is complete, at the latch.
        b.release_latches();
        assert_eq!(b.rt.sink_mut().0.len(), 1);
        let s = b.rt.sink_mut().0[0];
        assert_eq!(s.positions[2], z_latched as f64 / SCALE);
        assert_eq!(s.receive_ns, b.now + PERIOD / 2);
        match b.until_reply() {
            Reply::Contact(c) => assert_eq!(c.sequence, 1),
            other => panic!("{other:?}"),
        }
        assert_eq!(b.rt.sink_mut().0.len(), 1, "exactly one sample");
    }

    #[test]
    fn a_moving_axis_whose_latch_never_comes_fails_the_probe_after_the_stop() {
        let mut b = Bench::enabled();
        assert!(probe_and_touch(&mut b, 20).is_none());
        b.hold_latches_of = vec![3];
        match b.until_reply() {
            Reply::Error(e) => {
                assert_eq!((e.kind, e.node), (ErrorKind::ContactLost, Some(3)));
                assert!(matches!(e.detail, Detail::LatchLost));
            }
            other => panic!("{other:?}"),
        }
        assert!(b.rt.sink_mut().0.is_empty());
    }

    #[test]
    fn a_touch_while_positioning_brakes_and_fails_as_a_collision() {
        let mut b = Bench::enabled();
        b.move_axis(2, -20.0);
        for _ in 0..50 {
            b.tick();
        }
        for d in &mut b.drives {
            d.touch();
        }
        match b.until_reply() {
            Reply::Error(e) => assert_eq!(e.kind, ErrorKind::ProbeCollision),
            other => panic!("{other:?}"),
        }
        assert!(b.drives[2].actual > -20_000, "braked short of the target");
        assert!(b.rt.sink_mut().0.is_empty());
    }

    #[test]
    fn supervision_a_silent_heartbeat_faults_the_machine() {
        let mut b = Bench::enabled();
        b.heartbeats = false;
        // 150 ms timeout: 75 periods of 2 ms, plus the one that notices.
        for _ in 0..80 {
            b.tick();
        }
        b.rt.submit(Command::MoveTo {
            target: [1.0; MAX_AXES],
            mask: 0b111,
            feed: 3000.0,
        });
        match b.rt.take_reply() {
            Some(Reply::Error(e)) => {
                assert_eq!(e.kind, ErrorKind::NodeLost);
                assert!(matches!(e.detail, Detail::HeartbeatLost { .. }));
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn supervision_an_emcy_stops_the_move_and_names_the_node_and_code() {
        let mut b = Bench::enabled();
        b.move_axis(0, 50.0);
        for _ in 0..20 {
            b.tick();
        }
        let emcy = Emcy {
            error_code: 0x2310,
            error_register: 1,
            manufacturer: [0; 5],
        };
        b.rt.on_frame(&emcy.encode(2), b.now);
        match b.until_reply() {
            Reply::Error(e) => {
                assert_eq!(
                    (e.kind, e.node, e.code),
                    (ErrorKind::DriveFault, Some(2), Some(0x2310))
                );
            }
            other => panic!("{other:?}"),
        }
        assert!(b.drives[0].actual < 50_000, "stopped before the target");
    }

    #[test]
    fn the_master_sends_its_heartbeat_on_the_sync_grid_and_a_goodbye_after_shutdown() {
        let mut b = Bench::enabled();
        let hb = heartbeat::encode(127, NmtState::Operational);
        let start = b.now;
        let mut at = Vec::new();
        for _ in 0..150 {
            b.tick();
            if let Some(i) = b.sent.iter().position(|f| *f == hb) {
                // Before the SYNC, which stays the last frame of a tick.
                assert_eq!(i, b.sent.len() - 2);
                at.push((b.now - start) / PERIOD);
            }
        }
        // Every 100 ms (50 periods of 2 ms), from the loop's first tick.
        assert_eq!(at.len(), 3, "{at:?}");
        assert_eq!(at[1] - at[0], 50);
        assert_eq!(at[2] - at[1], 50);
        // A stall of the loop: one heartbeat when it resumes, not a burst.
        b.now += 500 * PERIOD;
        b.tick();
        assert_eq!(b.sent.iter().filter(|f| **f == hb).count(), 1);
        b.tick();
        assert_eq!(b.sent.iter().filter(|f| **f == hb).count(), 0);

        b.rt.submit(Command::Shutdown);
        for _ in 0..SHUTDOWN_TICKS {
            b.tick();
            assert!(!b.rt.is_finished());
            for n in 1..=3 {
                assert_eq!(b.rpdo1(n).controlword, Controlword::SHUTDOWN);
            }
        }
        // The goodbye: reset communication to each drive (its 0x1016 back to 0), once.
        b.tick();
        let goodbye: Vec<CanFrame> = (1..=3)
            .map(|n| nmt::encode(NmtCommand::ResetCommunication, n))
            .collect();
        assert_eq!(b.sent.as_slice(), goodbye.as_slice());
        assert!(b.rt.is_finished());
        b.tick();
        assert!(b.sent.is_empty());
    }
}
