//! The CANopen master as a [`Machine`]: start-up over SDO, then the real-time loop in
//! its own thread, talked to through bounded channels (no locks shared with the loop).

pub mod command;
pub mod pacing;
pub mod process_data;
pub mod rt_loop;
pub mod startup;

use crate::abort::AbortFlag;
use crate::axis::{AxisPositions, MAX_AXES};
use crate::can::CanTransport;
use crate::config::MachineConfig;
use crate::contact_sample::SampleSink;
use crate::machine::{Contact, ErrorKind, Machine, MachineError, ProbeMove};
use crate::motion_guard::MotionGuard;
use command::{Command, Detail, Reply, RtError};
pub use pacing::PacedLoop;
pub use process_data::BusLoad;
pub use rt_loop::Pacing;
pub use rt_loop::{LoopConfig, LoopStats, RtLoop};
use std::io::Write as _;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, RecvTimeoutError, SyncSender};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

/// What start-up found and got.
#[derive(Clone, Debug)]
pub struct StartupReport {
    pub bus_load: BusLoad,
    /// The loop thread runs under SCHED_FIFO.
    pub realtime_priority: bool,
    /// The process's memory is locked (no page faults in the loop).
    pub memory_locked: bool,
    /// CPU wake-up latency is held at 0 µs while the loop runs (see
    /// [`crate::rt::hold_cpu_latency_zero`]).
    pub cpu_latency_held: bool,
    /// The CPU the loop thread is pinned to ([`MasterOptions::rt_cpu`]; `None`: not
    /// asked, refused, or not in real time).
    pub rt_cpu: Option<usize>,
    /// Each drive: axis, node and the device name it reports.
    pub drives: Vec<String>,
    pub notes: Vec<String>,
}

#[derive(Clone, Copy, Debug)]
pub struct MasterOptions {
    pub pacing: Pacing,
    /// SCHED_FIFO priority to ask for (1..99); 0 = do not ask.
    pub rt_priority: i32,
    /// Identifies the samples of this session's contacts.
    pub run_id: u64,
    /// Longest wall-clock wait for one command (beyond the loop's own timeouts).
    pub command_timeout: Duration,
    /// The operator's stop request: once raised, a move under way is braked and
    /// answered as [`ErrorKind::Aborted`] (the drives stay enabled), and no further
    /// command is sent until the flag is re-armed ([`AbortFlag::rearm`]).
    pub abort: Option<AbortFlag>,
    /// Pin the loop thread to this CPU (`bench trigger` does, with
    /// [`crate::rt::realtime_cpu_of`] its CPUs); `None`: the scheduler places it. Not the default:
    /// measured by the bench only, not on the machines' own hosts.
    pub rt_cpu: Option<usize>,
}

impl Default for MasterOptions {
    fn default() -> Self {
        Self {
            pacing: Pacing::RealTime,
            rt_priority: 80,
            run_id: 1,
            command_timeout: Duration::from_secs(600),
            abort: None,
            rt_cpu: None,
        }
    }
}

/// A machine whose axes are CiA 402 drives on a CAN bus.
pub struct CanMachine {
    commands: SyncSender<Command>,
    replies: Receiver<Reply>,
    thread: Option<JoinHandle<()>>,
    running: Arc<AtomicBool>,
    stats: Arc<Mutex<LoopStats>>,
    /// The time of the last SYNC, ns (the loop's clock: virtual in lockstep).
    clock: Arc<AtomicU64>,
    config: MachineConfig,
    guard: MotionGuard,
    options: MasterOptions,
    run_id: u64,
    position: AxisPositions,
    /// `position` is not where the axes are (a move ended in an error).
    position_stale: bool,
}

/// SCHED_FIFO at `priority` for the calling thread (0: do not ask) and locked memory;
/// what was granted.
fn apply_rt_settings(priority: i32, rt_cpu: Option<usize>) -> (bool, bool, Option<usize>) {
    let fifo = priority > 0 && crate::rt::set_fifo_priority(priority);
    let cpu = rt_cpu.filter(|&c| crate::rt::pin_thread(&[c]));
    (fifo, crate::rt::lock_memory(), cpu)
}

impl CanMachine {
    /// Boots and configures the drives of `cfg` on `transport`, starts the real-time
    /// loop and waits until every drive is in Operation enabled. Refuses a
    /// configuration whose cyclic traffic would load the bus beyond
    /// `bus.max_load_percent`, before sending anything.
    pub fn start<T, S>(
        cfg: &MachineConfig,
        mut transport: T,
        sink: S,
        options: MasterOptions,
    ) -> Result<(Self, StartupReport), MachineError>
    where
        T: CanTransport + 'static,
        S: SampleSink + 'static,
    {
        let bus = startup::canopen_bus(cfg)?;
        let bus_load = BusLoad::of(cfg);
        if bus_load.percent > bus.max_load_percent {
            let fits = BusLoad::shortest_period_us(cfg, bus.max_load_percent)
                .map_or(String::new(), |p| format!(" (at least {p} us)"));
            return Err(MachineError::new(
                ErrorKind::InvalidRequest,
                format!(
                    "{}: {bus_load}; the limit is {:.0} %: lengthen bus.sync_period_us{fits} or raise the bit rate",
                    cfg.path.display(),
                    bus.max_load_percent
                ),
            ));
        }
        startup::boot(&mut transport, cfg)?;
        let drives = startup::configure(&mut transport, cfg)?;

        let loop_cfg = LoopConfig::from_machine(cfg, options.pacing);
        let (cmd_tx, cmd_rx) = sync_channel::<Command>(1);
        let (reply_tx, reply_rx) = sync_channel::<Reply>(1);
        let running = Arc::new(AtomicBool::new(true));
        let stats = Arc::new(Mutex::new(LoopStats::default()));
        let clock = Arc::new(AtomicU64::new(0));
        type RtSettings = (bool, bool, Option<usize>, bool, Option<String>);
        let (rt_tx, rt_rx) = sync_channel::<RtSettings>(1);
        let machine_cfg = cfg.clone();
        let thread = {
            let running = running.clone();
            let stats = stats.clone();
            let clock = clock.clone();
            let realtime = matches!(options.pacing, Pacing::RealTime);
            let priority = if realtime { options.rt_priority } else { 0 };
            let rt_cpu = options.rt_cpu;
            std::thread::Builder::new()
                .name("probebridge-rt".into())
                .spawn(move || {
                    let got = if realtime {
                        apply_rt_settings(priority, rt_cpu)
                    } else {
                        (false, false, None)
                    };
                    // Held for as long as the loop runs.
                    let latency = if realtime {
                        Some(crate::rt::hold_cpu_latency_zero())
                    } else {
                        None
                    };
                    let latency_note = match &latency {
                        Some(Err(why)) => Some(why.clone()),
                        _ => None,
                    };
                    let held = matches!(latency, Some(Ok(_)));
                    let _ = rt_tx.send((got.0, got.1, got.2, held, latency_note));
                    let mut rt = PacedLoop::new(&machine_cfg, loop_cfg, transport, sink);
                    run_thread(&mut rt, &cmd_rx, &reply_tx, &running, &stats, &clock);
                })
                .map_err(|e| {
                    MachineError::new(
                        ErrorKind::Other,
                        format!("cannot start the real-time thread: {e}"),
                    )
                })?
        };
        let (realtime_priority, memory_locked, rt_cpu, cpu_latency_held, latency_note) =
            rt_rx.recv().unwrap_or((false, false, None, false, None));
        let mut notes = Vec::new();
        if matches!(options.pacing, Pacing::RealTime) {
            if let Some(why) = latency_note {
                notes.push(format!(
                    "CPU idle states not held off ({why}): the first frame after an idle gap may wait for a CPU to wake"
                ));
            }
            if !realtime_priority {
                notes.push(format!(
                    "real-time loop runs without SCHED_FIFO (priority {} not permitted: run as root or grant CAP_SYS_NICE)",
                    options.rt_priority
                ));
            }
            if !memory_locked {
                notes.push("memory not locked (mlockall not permitted: grant CAP_IPC_LOCK or raise RLIMIT_MEMLOCK)".into());
            }
        }
        let mut m = CanMachine {
            commands: cmd_tx,
            replies: reply_rx,
            thread: Some(thread),
            running,
            stats,
            clock,
            config: cfg.clone(),
            guard: MotionGuard::new(cfg),
            options,
            run_id: options.run_id,
            position: AxisPositions::new(),
            position_stale: false,
        };
        match m.wait_reply(Duration::from_secs(10))? {
            Reply::Ready { positions } => m.position = m.to_positions(&positions),
            Reply::Error(e) => return Err(e.into()),
            other => {
                return Err(MachineError::new(
                    ErrorKind::Other,
                    format!("unexpected answer from the real-time loop at start-up: {other:?}"),
                ))
            }
        }
        Ok((
            m,
            StartupReport {
                bus_load,
                realtime_priority,
                memory_locked,
                cpu_latency_held,
                rt_cpu,
                drives,
                notes,
            },
        ))
    }

    pub fn config(&self) -> &MachineConfig {
        &self.config
    }

    /// Counters of the real-time loop (updated once per cycle).
    pub fn stats(&self) -> LoopStats {
        *self.stats.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Samples of following probing moves carry this run ID.
    pub fn set_run_id(&mut self, run_id: u64) {
        self.run_id = run_id;
    }

    fn to_positions(&self, raw: &[f64; MAX_AXES]) -> AxisPositions {
        AxisPositions::from_raw(*raw, self.config.axis_mask())
    }

    fn wait_reply(&mut self, timeout: Duration) -> Result<Reply, MachineError> {
        // Polled in short slices so the operator's stop brakes a move under way
        // instead of waiting it out.
        const POLL: Duration = Duration::from_millis(5);
        let deadline = std::time::Instant::now() + timeout;
        let mut stop_sent = false;
        loop {
            let now = std::time::Instant::now();
            if now >= deadline {
                return Err(MachineError::new(
                    ErrorKind::Timeout,
                    format!(
                        "the real-time loop did not answer within {} s",
                        timeout.as_secs()
                    ),
                ));
            }
            match self.replies.recv_timeout(POLL.min(deadline - now)) {
                Ok(r) => return Ok(r),
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => {
                    return Err(RtError::new(ErrorKind::Bus, Detail::Stopped).into())
                }
            }
            if !stop_sent && self.options.abort.is_some_and(|a| a.is_raised()) {
                // The channel holds one command: if the loop has not taken the last
                // one yet, try again on the next slice.
                stop_sent = self.commands.try_send(Command::Stop).is_ok();
            }
        }
    }

    fn command(&mut self, cmd: Command) -> Result<Reply, MachineError> {
        // Reading positions moves nothing: allowed while the stop is raised.
        let motion = !matches!(cmd, Command::Positions);
        if motion && self.options.abort.is_some_and(|a| a.is_raised()) {
            return Err(RtError::new(ErrorKind::Aborted, Detail::Aborted).into());
        }
        self.commands
            .send(cmd)
            .map_err(|_| MachineError::from(RtError::new(ErrorKind::Bus, Detail::Stopped)))?;
        match self.wait_reply(self.options.command_timeout)? {
            Reply::Error(e) => Err(e.into()),
            r => Ok(r),
        }
    }

    /// Stops the loop and disables the drives.
    pub fn shutdown(&mut self) {
        if let Some(t) = self.thread.take() {
            let _ = self.commands.send(Command::Shutdown);
            self.running.store(false, Ordering::Release);
            let _ = t.join();
        }
    }
}

impl Drop for CanMachine {
    fn drop(&mut self) {
        self.shutdown();
    }
}

fn run_thread<T: CanTransport, S: SampleSink>(
    rt: &mut PacedLoop<T, S>,
    commands: &Receiver<Command>,
    replies: &SyncSender<Reply>,
    running: &AtomicBool,
    stats: &Mutex<LoopStats>,
    clock: &AtomicU64,
) {
    // The startup Ready/Error goes out like any reply.
    let mut shutdown_cycles = 0;
    let lockstep = matches!(rt.pacing(), Pacing::Lockstep { .. });
    // Periods in a row with a failing transport before the loop gives up: the
    // heartbeat timeout, within which the drives still count on us.
    let mut failing = 0u64;
    let give_up_after = {
        let c = rt.rt().config();
        (c.heartbeat_timeout_ns / c.period_ns.max(1)).max(10)
    };
    loop {
        if lockstep && !rt.is_busy() && !rt.is_shut_down() {
            // On a virtual clock nothing happens between commands: wait for one
            // instead of spinning the simulation.
            match commands.recv_timeout(Duration::from_millis(100)) {
                Ok(cmd) => rt.submit(cmd),
                Err(RecvTimeoutError::Timeout) if running.load(Ordering::Acquire) => continue,
                Err(_) => rt.submit(Command::Shutdown),
            }
        } else if let Ok(cmd) = commands.try_recv() {
            rt.submit(cmd);
        }
        match rt.cycle() {
            Ok(()) => failing = 0,
            Err(e) => {
                // The loop has faulted and brakes: keep cycling, so the braking
                // setpoints reach the drives once the transport takes frames again
                // (a bus-off recovers, a queue drains). A transport that stays down
                // longer than the heartbeat timeout is given up.
                if failing == 0 {
                    // A closed or full stderr must not panic the loop thread.
                    let _ = writeln!(std::io::stderr(), "probebridge: CAN transport failed: {e}");
                }
                failing += 1;
                if failing > give_up_after {
                    let _ = replies.try_send(Reply::Error(RtError::new(
                        ErrorKind::Bus,
                        Detail::Transport,
                    )));
                    let _ = writeln!(
                        std::io::stderr(),
                        "probebridge: real-time loop stopped: the transport failed for {failing} periods in a row ({e})"
                    );
                    return;
                }
            }
        }
        // Before the reply: whoever reads the clock after an answer sees its SYNC.
        clock.store(rt.rt().now_ns(), Ordering::Release);
        if let Some(r) = rt.take_reply() {
            let _ = replies.try_send(r);
        }
        if let Ok(mut s) = stats.try_lock() {
            *s = rt.stats();
        }
        if rt.is_finished() {
            return;
        }
        if !running.load(Ordering::Acquire) {
            // Shutdown was submitted above; a loop that does not finish it is left.
            shutdown_cycles += 1;
            if shutdown_cycles > 2 * rt_loop::SHUTDOWN_TICKS + 2 {
                return;
            }
        }
    }
}

impl Machine for CanMachine {
    type Error = MachineError;

    fn set_run(&mut self, run_id: u64) {
        self.set_run_id(run_id);
    }

    /// The time of the last SYNC: the drives' time, virtual in lockstep.
    fn clock_ns(&mut self) -> u64 {
        self.clock.load(Ordering::Acquire)
    }

    /// The loop's own supervision (heartbeats, EMCY, statusword fault) and whether the
    /// loop still runs (a transport failure ends it); sends nothing.
    fn health(&mut self) -> Result<(), MachineError> {
        if self.thread.as_ref().is_none_or(JoinHandle::is_finished) {
            return Err(RtError::new(ErrorKind::Bus, Detail::Stopped).into());
        }
        match self.stats().fault {
            Some(f) => Err(f.into()),
            None => Ok(()),
        }
    }

    fn axes(&self) -> u8 {
        self.config.axis_mask()
    }

    fn positions(&mut self) -> Result<AxisPositions, MachineError> {
        match self.command(Command::Positions)? {
            Reply::Done { positions } => Ok(self.to_positions(&positions)),
            other => Err(MachineError::new(
                ErrorKind::Other,
                format!("unexpected answer {other:?}"),
            )),
        }
    }

    fn move_to(&mut self, target: &AxisPositions, feed: f64) -> Result<(), MachineError> {
        if self.position_stale {
            // The last motion ended early (braked): check the duration from where the
            // axes came to rest.
            self.position = self.positions()?;
            self.position_stale = false;
        }
        self.guard.check_move_from(&self.position, target, feed)?;
        let reply = self.command(Command::MoveTo {
            target: target.raw(),
            mask: target.mask(),
            feed,
        });
        self.position_stale = reply.is_err();
        match reply? {
            Reply::Done { positions } => {
                self.position = self.to_positions(&positions);
                Ok(())
            }
            other => Err(MachineError::new(
                ErrorKind::Other,
                format!("unexpected answer {other:?}"),
            )),
        }
    }

    /// An oriented stop by the spindle's drive (`[spindle]`, profile position);
    /// `Ok(false)` without one, nothing moved.
    fn orient_spindle(&mut self, angle_deg: f64) -> Result<bool, MachineError> {
        if self.config.spindle.is_none() {
            return Ok(false);
        }
        if !angle_deg.is_finite() {
            return Err(RtError::new(ErrorKind::InvalidRequest, Detail::InvalidAngle).into());
        }
        match self.command(Command::OrientSpindle { angle_deg })? {
            Reply::Done { .. } => Ok(true),
            other => Err(MachineError::new(
                ErrorKind::Other,
                format!("unexpected answer {other:?}"),
            )),
        }
    }

    fn probe(&mut self, mv: &ProbeMove) -> Result<Contact, MachineError> {
        // The request first: a bad one is refused without asking the loop anything.
        self.guard.check_probe_request(mv)?;
        let here = self.positions()?;
        let dir = self.guard.check_probe(&here, mv)?.direction;
        let reply = self.command(Command::Probe {
            direction: dir,
            feed: mv.feed,
            max_distance: mv.max_distance,
            run_id: self.run_id,
        });
        self.position_stale = reply.is_err();
        match reply? {
            Reply::Contact(s) => Ok(Contact {
                // Where the axes are is close to the latch (the stop runs on by the
                // braking distance): good enough for the next move's duration check.
                positions: {
                    self.position = s.axis_positions();
                    self.position
                },
                trigger_ns: s.trigger_ns,
                sequence: s.sequence,
                direction: dir,
            }),
            other => Err(MachineError::new(
                ErrorKind::Other,
                format!("unexpected answer {other:?}"),
            )),
        }
    }
}
