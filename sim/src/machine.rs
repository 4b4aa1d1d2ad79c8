//! The simulated machine on a CAN bus: every axis's drive, stepped together on each
//! SYNC through the physics of [`crate::world::World`], so all drives latch on the same
//! probe signal at the same instant. Time is SYNC count times the cycle period the
//! master configured (0x1006): the simulation runs on whatever clock the master runs,
//! virtual or real.
//!
//! The drives' own timers (heartbeat producer and consumer, TPDO event timers) run on a
//! [`SimClock`]: the wall clock when the drives stand for hardware on a bus that runs
//! in real time (then they produce heartbeats with no SYNC at all), or the simulated
//! time on a virtual clock, where no time passes between SYNCs.

use crate::drive::{HeartbeatLoss, SimDrive};
use crate::scenario::{FaultKind, Scenario};
use crate::world::World;
use hal::axis::AxisPositions;
use hal::can::{CanFrame, CanTransport, TransportError};
use hal::config::MachineConfig;
use std::io::Write as _;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

/// Penetration of the stylus into material beyond which the simulated probe's
/// overtravel is used up: every drive faults (a real probe would break).
pub const PROBE_OVERTRAVEL_MM: f64 = 5.0;
/// EMCY code the drives send on a probe collision (manufacturer specific).
pub const EMCY_PROBE_COLLISION: u16 = 0xFF01;

/// A drive on the bus: an axis's, or (`axis` `None`) the spindle's, whose angle turns
/// the stylus in the world. `scale`: increments per mm or degree.
struct AxisDrive {
    drive: SimDrive,
    axis: Option<hal::Axis>,
    scale: f64,
}

struct PlannedFault {
    node: u8,
    kind: FaultKind,
    at_us: u64,
    code: u16,
    done: bool,
}

/// The clock of the drives' own timers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SimClock {
    /// The simulated time: SYNCs times the cycle period. For masters on a virtual
    /// clock (lockstep), which advance time only by SYNC.
    Virtual,
    /// CLOCK_MONOTONIC: for masters in real time, on SocketCAN or the in-process bus.
    Monotonic,
}

/// Called by the simulation with the axes' actual positions after every step of
/// motion: a test sees the axes move from the machine's side (and may, say, raise the
/// operator's stop when they pass a point).
pub type MotionWatch = Arc<dyn Fn(&AxisPositions) + Send + Sync>;

/// All drives of one machine plus its physics.
pub struct SimMachine {
    drives: Vec<AxisDrive>,
    world: World,
    time_us: u64,
    clock: SimClock,
    epoch_ns: u64,
    faults: Vec<PlannedFault>,
    syncs: u64,
    latch_log: Option<Arc<LatchLog>>,
    motion_watch: Option<MotionWatch>,
}

/// Latches the ring of a [`LatchLog`] remembers.
pub const LATCH_LOG_CAPACITY: usize = 4096;

/// When the simulated drives latched, on CLOCK_MONOTONIC (the clock every process of
/// the gateway shares): the t0 of trigger-latency benchmarks. The simulation records
/// into it without locking or allocating; a reader in another thread asks for latch
/// number `n` (counted from 0) while it is among the last [`LATCH_LOG_CAPACITY`].
pub struct LatchLog {
    count: AtomicU64,
    t0_ns: [AtomicU64; LATCH_LOG_CAPACITY],
}

impl LatchLog {
    pub fn new() -> Arc<Self> {
        Arc::new(Self {
            count: AtomicU64::new(0),
            t0_ns: [const { AtomicU64::new(0) }; LATCH_LOG_CAPACITY],
        })
    }

    /// Latches recorded so far.
    pub fn count(&self) -> u64 {
        self.count.load(Ordering::Acquire)
    }

    /// Instant of latch `n`, if it happened and is still in the ring.
    pub fn get(&self, n: u64) -> Option<u64> {
        let count = self.count();
        if n >= count || count - n > LATCH_LOG_CAPACITY as u64 {
            return None;
        }
        let t = self.t0_ns[(n % LATCH_LOG_CAPACITY as u64) as usize].load(Ordering::Relaxed);
        // Overwritten meanwhile by a writer that lapped the reader?
        (self.count() - n <= LATCH_LOG_CAPACITY as u64).then_some(t)
    }

    /// Single writer: the simulation thread (drives or PLC).
    pub fn record(&self, t0_ns: u64) {
        let n = self.count.load(Ordering::Relaxed);
        self.t0_ns[(n % LATCH_LOG_CAPACITY as u64) as usize].store(t0_ns, Ordering::Relaxed);
        self.count.store(n + 1, Ordering::Release);
    }
}

impl core::fmt::Debug for LatchLog {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("LatchLog")
            .field("count", &self.count())
            .finish()
    }
}

impl SimMachine {
    /// Drives of `scenario.machine` at [`Self::start_positions`].
    pub fn new(scenario: &Scenario) -> Self {
        Self::with_positions(scenario, &Self::start_positions(scenario))
    }

    /// Where the axes of `scenario` start: its `home`, else [`Self::home`].
    pub fn start_positions(scenario: &Scenario) -> AxisPositions {
        match scenario.home {
            Some(xyz) => AxisPositions::linear(xyz),
            None => Self::home(&scenario.machine),
        }
    }

    /// The home position of a vertical spindle: Z 50 mm below its upper limit (clear
    /// of the table), every other axis at 0.
    pub fn home(cfg: &MachineConfig) -> AxisPositions {
        let mut p = AxisPositions::new();
        if let Some(z) = cfg.axis(hal::Axis::Z) {
            p.set(hal::Axis::Z, (z.max - 50.0).max(z.min));
        }
        p
    }

    /// Drives start at `start` (axes not given: 0).
    pub fn with_positions(scenario: &Scenario, start: &AxisPositions) -> Self {
        let cfg: &MachineConfig = &scenario.machine;
        let mut drives: Vec<AxisDrive> = cfg
            .axes
            .iter()
            .map(|a| {
                let pos = start.get(a.name).unwrap_or(0.0);
                AxisDrive {
                    drive: SimDrive::new(
                        a.canopen_node(),
                        (pos * a.increments_per_unit).round() as i32,
                    ),
                    axis: Some(a.name),
                    scale: a.increments_per_unit,
                }
            })
            .collect();
        // Last on the bus: its TPDO1 ends each SYNC's answers, as every drive's does.
        if let (Some(s), hal::config::BusConfig::CanOpen(_)) = (&cfg.spindle, &cfg.bus) {
            drives.push(AxisDrive {
                drive: SimDrive::spindle(s.node, 0),
                axis: None,
                scale: s.increments_per_degree,
            });
        }
        let faults = scenario
            .faults
            .iter()
            .map(|f| PlannedFault {
                node: f.node,
                kind: f.kind,
                at_us: (f.after_ms * 1000.0) as u64,
                code: f.code.unwrap_or(0x5000),
                done: false,
            })
            .collect();
        Self {
            drives,
            world: World::new(scenario),
            time_us: 0,
            clock: SimClock::Virtual,
            epoch_ns: 0,
            faults,
            syncs: 0,
            latch_log: None,
            motion_watch: None,
        }
    }

    /// Runs the drives' timers on `clock` (default [`SimClock::Virtual`]).
    pub fn set_clock(&mut self, clock: SimClock) {
        self.clock = clock;
        self.epoch_ns = hal::clock::monotonic_ns();
    }

    pub fn clock(&self) -> SimClock {
        self.clock
    }

    /// Now on the drives' clock, µs.
    fn drive_now_us(&self) -> u64 {
        match self.clock {
            SimClock::Virtual => self.time_us,
            SimClock::Monotonic => hal::clock::monotonic_ns().saturating_sub(self.epoch_ns) / 1000,
        }
    }

    /// Power-on: every drive sends its boot-up.
    pub fn power_on(&mut self, tx: &mut dyn FnMut(&CanFrame)) {
        for d in &mut self.drives {
            d.drive.power_on(tx);
        }
    }

    /// Lets the drives' timers run (heartbeats, event-driven TPDOs, EMCYs). On the
    /// virtual clock no time passes between SYNCs: nothing happens.
    pub fn poll(&mut self, tx: &mut dyn FnMut(&CanFrame)) {
        if self.clock == SimClock::Virtual {
            return;
        }
        let now = self.drive_now_us();
        for d in &mut self.drives {
            d.drive.poll(now, tx);
        }
    }

    /// How long until [`Self::poll`] has something to do on its own (`None`: nothing
    /// timed, or the virtual clock).
    pub fn poll_timeout(&self) -> Option<Duration> {
        if self.clock == SimClock::Virtual {
            return None;
        }
        let now = self.drive_now_us();
        self.drives
            .iter()
            .filter_map(|d| d.drive.next_deadline_us())
            .min()
            .map(|t| Duration::from_micros(t.saturating_sub(now)))
    }

    /// Each drive's last loss of the heartbeat it consumes (0x1016), with its node.
    pub fn heartbeat_losses(&self) -> Vec<(u8, HeartbeatLoss)> {
        self.drives
            .iter()
            .filter_map(|d| d.drive.heartbeat_loss().map(|l| (d.drive.node(), l)))
            .collect()
    }

    /// Each drive's loss of the heartbeat it consumes (0x1016) not reported before,
    /// with the drive's node.
    pub fn take_heartbeat_losses(&mut self, report: &mut dyn FnMut(u8, HeartbeatLoss)) {
        for d in &mut self.drives {
            if let Some(l) = d.drive.take_heartbeat_loss() {
                report(d.drive.node(), l);
            }
        }
    }

    /// Records the wall-clock instant of every latch into `log` (benchmarks).
    pub fn set_latch_log(&mut self, log: Arc<LatchLog>) {
        self.latch_log = Some(log);
    }

    /// Calls `watch` with the actual positions after every SYNC step.
    pub fn set_motion_watch(&mut self, watch: MotionWatch) {
        self.motion_watch = Some(watch);
    }

    /// Simulated time since the first SYNC, µs.
    pub fn time_us(&self) -> u64 {
        self.time_us
    }

    pub fn syncs(&self) -> u64 {
        self.syncs
    }

    /// Encoder positions of all axes.
    pub fn positions(&self) -> AxisPositions {
        let mut p = AxisPositions::new();
        for d in &self.drives {
            if let Some(a) = d.axis {
                p.set(a, d.drive.actual_inc() as f64 / d.scale);
            }
        }
        p
    }

    /// The spindle drive's angle, deg (`None`: no spindle drive on the bus).
    pub fn spindle_deg(&self) -> Option<f64> {
        self.drives
            .iter()
            .find(|d| d.axis.is_none())
            .map(|d| d.drive.actual_inc() as f64 / d.scale)
    }

    pub fn world(&self) -> &World {
        &self.world
    }

    /// Handles one frame from the bus; answers through `tx`.
    pub fn on_frame(&mut self, f: &CanFrame, tx: &mut dyn FnMut(&CanFrame)) {
        // SYNC: on the COB-ID of 0x1005 (0x080 unless a master moved it), 0 or 1 byte.
        let sync = f.data().len() <= 1
            && !f.is_rtr()
            && self
                .drives
                .iter()
                .any(|d| d.drive.consumes_sync(f.cob_id()));
        if sync {
            self.on_sync(f.cob_id(), tx);
            return;
        }
        for d in &mut self.drives {
            d.drive.on_frame(f, tx);
        }
    }

    fn on_sync(&mut self, cob: u16, tx: &mut dyn FnMut(&CanFrame)) {
        self.syncs += 1;
        for d in &mut self.drives {
            if d.drive.consumes_sync(cob) {
                d.drive.on_sync();
            }
        }
        let period_us = self
            .drives
            .first()
            .map_or(2000, |d| d.drive.cycle_period_us()) as u64;
        self.time_us += period_us;
        for f in self
            .faults
            .iter_mut()
            .filter(|f| !f.done && self.time_us >= f.at_us)
        {
            f.done = true;
            if let Some(d) = self.drives.iter_mut().find(|d| d.drive.node() == f.node) {
                match f.kind {
                    FaultKind::Emcy => d.drive.raise_fault(f.code),
                    FaultKind::Silent => d.drive.silent = true,
                    FaultKind::Reboot => d.drive.reboot(tx),
                }
            }
        }
        let mut from = AxisPositions::new();
        let mut to = AxisPositions::new();
        for d in &mut self.drives {
            d.drive.begin_step();
            if let Some(a) = d.axis {
                from.set(a, d.drive.actual_inc() as f64 / d.scale);
                to.set(a, d.drive.next_position_inc() as f64 / d.scale);
            }
        }
        let latch = self.world.step(&from, &to);
        let level = self.world.deflected(&to);
        let collision = self.world.penetration(&to) > PROBE_OVERTRAVEL_MM;
        let mut latched = false;
        for d in &mut self.drives {
            let target = d.drive.next_position_inc();
            if d.axis.is_none() {
                // The spindle's drive has no probe input; its angle turns the stylus.
                d.drive.end_step(target, None, false);
                self.world.orient_spindle(target as f64 / d.scale);
            } else {
                latched |= d.drive.end_step(target, latch, level);
            }
            if collision {
                d.drive.raise_fault(EMCY_PROBE_COLLISION);
            }
        }
        if let Some(watch) = &self.motion_watch {
            watch(&self.positions());
        }
        if latched {
            if let Some(log) = &self.latch_log {
                // Before the drives send their latch frames below.
                log.record(hal::clock::monotonic_ns());
            }
        }
        let now = self.drive_now_us();
        for d in &mut self.drives {
            if d.drive.consumes_sync(cob) {
                d.drive.answer_sync(now, tx);
            }
        }
    }
}

/// Most frames taken from the queue before the drives' timers run again: a bus
/// flooded faster than the host keeps up still gets its timers looked at.
const QUEUED_MAX: usize = 1024;

/// Takes every frame already queued for the drives before their timers judge (the
/// heartbeat consumer above all): a real drive takes each frame as it arrives, so a
/// heartbeat queued behind a backlog of a slow host (an emulated CPU under load) was
/// on time, and counting the backlog as silence would stop the axes for nothing.
fn take_queued<T: CanTransport>(
    machine: &mut SimMachine,
    transport: &mut T,
    out: &mut Vec<CanFrame>,
) -> Result<(), TransportError> {
    for _ in 0..QUEUED_MAX {
        // Each frame's answers go out before the next frame is taken, as when taken
        // one at a time.
        if !out.is_empty() {
            transport.transmit_all(out)?;
            out.clear();
        }
        let Some(f) = transport.receive(Duration::ZERO)? else {
            break;
        };
        machine.on_frame(&f, &mut |r| out.push(*r));
    }
    Ok(())
}

/// A simulated machine running on a bus in its own thread until stopped.
pub struct SimRunner {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<Result<SimMachine, TransportError>>>,
}

impl SimRunner {
    /// Serves `machine` on `transport`: powers it on (boot-ups), then handles every
    /// frame as it arrives and runs the drives' timers in between.
    pub fn spawn<T: CanTransport + 'static>(machine: SimMachine, transport: T) -> Self {
        Self::spawn_with_init(machine, transport, || {})
    }

    /// As [`SimRunner::spawn`], calling `init` first in the simulation thread (a
    /// benchmark gives the drives' stand-in real-time priority there).
    pub fn spawn_with_init<T: CanTransport + 'static>(
        mut machine: SimMachine,
        mut transport: T,
        init: impl FnOnce() + Send + 'static,
    ) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let stop2 = stop.clone();
        let thread = std::thread::Builder::new()
            .name("probebridge-sim".into())
            .spawn(move || {
                init();
                let mut out: Vec<CanFrame> = Vec::with_capacity(64);
                machine.power_on(&mut |r| out.push(*r));
                while !stop2.load(Ordering::Acquire) {
                    // One batch: on a bus with wire time the drives' answers
                    // arbitrate together, as separate devices' frames do.
                    transport.transmit_all(&out)?;
                    out.clear();
                    // Wake for the stop flag at least every 50 ms.
                    let wait = machine
                        .poll_timeout()
                        .map_or(Duration::from_millis(50), |t| {
                            t.min(Duration::from_millis(50))
                        });
                    if let Some(f) = transport.receive(wait)? {
                        machine.on_frame(&f, &mut |r| out.push(*r));
                        // Only the wall clock's timers judge time (on the virtual
                        // clock no time passes between frames, and lockstep keeps
                        // its one-frame rhythm).
                        if machine.clock() == SimClock::Monotonic {
                            take_queued(&mut machine, &mut transport, &mut out)?;
                        }
                    }
                    machine.poll(&mut |r| out.push(*r));
                    machine.take_heartbeat_losses(&mut |node, l| {
                        // The drive's own log line (a closed stderr is no reason to stop).
                        let _ = writeln!(
                            std::io::stderr(),
                            "probebridge sim: node {node}: heartbeat of node {} lost ({:.1} ms silent, consumer time {} ms): EMCY 8130, {:?} -> {:?}",
                            l.node,
                            l.silent_us as f64 / 1000.0,
                            l.consumer_ms,
                            l.from,
                            l.to
                        );
                    });
                    // One batch: on a bus with wire time the drives' answers
                    // arbitrate together, as separate devices' frames do.
                    transport.transmit_all(&out)?;
                    out.clear();
                }
                Ok(machine)
            })
            .expect("spawn simulation thread");
        Self {
            stop,
            thread: Some(thread),
        }
    }

    /// Runs until the transport fails (or the process ends).
    pub fn wait(mut self) -> Result<SimMachine, TransportError> {
        self.join()
    }

    fn join(&mut self) -> Result<SimMachine, TransportError> {
        match self.thread.take().map(|t| t.join()) {
            Some(Ok(r)) => r,
            _ => Err(TransportError::new(
                hal::can::TransportErrorKind::Closed,
                "simulation thread panicked",
            )),
        }
    }

    /// Stops the simulation and returns the machine (for inspection in tests).
    pub fn stop(mut self) -> Result<SimMachine, TransportError> {
        self.stop.store(true, Ordering::Release);
        self.join()
    }
}

impl Drop for SimRunner {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
