//! `probebridge bench trigger`: the latency of the hot trigger path across processes.
//!
//! ```text
//!  simulated drives ──latch frame──> real-time loop ──ContactSample──> estimator process
//!  (t0: CLOCK_MONOTONIC  (CAN: in-process   decodes, starts the stop,   (t1: CLOCK_MONOTONIC
//!   when the drives       bus or --can)     publishes over iceoryx2)     when it has it)
//!   latch)
//! ```
//!
//! The bridge side is the real one: `CanMachine` with its real-time thread (SCHED_FIFO
//! and locked memory where permitted), the sink the bridge uses (`ForwardingSink`, or
//! with `--direct` a `ContactPublisher` called in the real-time thread), the estimator
//! as a child process (`probebridge estimator --record-times FILE`) woken by the
//! iceoryx2 event. The drives are the simulator in this process (the in-process bus, or
//! a second socket on `--can IFACE`), which records t0 in a lock-free ring
//! (`sim::machine::LatchLog`).
//!
//! In the same run, after every trigger, the floor: one `ContactSample` published by
//! this process with `ContactPublisher` straight to the same estimator (same services,
//! same payload, same event wake-up), t0 taken right before the send. After the
//! triggers, the host's own floor: a bare eventfd wake-up of a forked process on the
//! other CPU ([`crate::bench::wakeup`]).
//!
//! The in-process bus has the machine's bit rate (wire time, arbitration by id), and
//! the bench refuses a SYNC period whose traffic would load it above the limit. So the
//! report gives the path end to end (latch to estimator, wire time included) and the
//! software path alone (from the last bit of the latch frame, when the real-time loop
//! could first have it, to the estimator), each against both floors, and the stop
//! latency in SYNC cycles.

use crate::bench::{self, Summary};
use crate::commands::estimator::DEFAULT_RECORD_CAPACITY;
use crate::configs;
use crate::estimator::{ReceiveTime, ReceiveTimes};
use crate::ipc::{ContactPublisher, EstimatorChild, ForwardingSink};
use hal::can::inproc::{InprocBus, WireClock};
use hal::can::socketcan::SocketCanTransport;
use hal::can::CanTransport;
use hal::config::MachineConfig;
use hal::master::{BusLoad, CanMachine, LoopStats, MasterOptions, Pacing, StartupReport};
use hal::{AxisPositions, ContactSample, Machine, ProbeMove, SampleSink};
use serde_json::json;
use sim::machine::{LatchLog, SimClock, SimMachine, SimRunner};
use sim::Scenario;
use std::collections::HashMap;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Run IDs that tell the estimator's records apart.
const TRIGGER_RUN: u64 = 1;
const FLOOR_RUN: u64 = 2;

/// The options of `probebridge bench trigger`, parsed by clap straight into this.
#[derive(clap::Args, Clone, Debug)]
pub struct BenchArgs {
    /// Measured triggers (plus a warm-up of 10 %, at most 100).
    #[arg(long, default_value_t = 10_000)]
    pub triggers: u64,
    /// SYNC period of the real-time loop, µs (default: the machine's, 2000). Refused
    /// when the cyclic traffic would load the bus above its limit (70 % of the bit
    /// rate). Modbus: the simulated PLC's task cycle (default 250).
    #[arg(long)]
    pub period_us: Option<u32>,
    /// Run the latch over this SocketCAN interface (simulated drives on a second
    /// socket in this process) instead of the in-process bus.
    #[arg(long)]
    pub can: Option<String>,
    /// Write all figures as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Publish from the real-time thread with ContactPublisher (one heap allocation
    /// per sample inside iceoryx2 0.10) instead of the ForwardingSink.
    #[arg(long)]
    pub direct: bool,
    /// Warm-up triggers, not counted.
    #[arg(long)]
    pub warmup: Option<u64>,
    /// SCHED_FIFO priority of the real-time thread (0: do not ask); the simulated
    /// drives get one less, the forwarder two less.
    #[arg(long, default_value_t = 80)]
    pub rt_priority: i32,
    /// Run the estimator process under SCHED_FIFO at this priority (0: an
    /// ordinary process, as the bridge starts it). Every thread on the measured
    /// path runs under SCHED_FIFO by default, so other load on the machine does
    /// not decide the result.
    #[arg(long, default_value_t = 70)]
    pub estimator_priority: i32,
    /// SCHED_FIFO priority of the simulated drives' thread (default: the real-time
    /// loop's minus one; 0: ordinary).
    #[arg(long)]
    pub drives_priority: Option<i32>,
    /// Over Modbus TCP on loopback instead: the simulated PLC (its task cycle
    /// --period-us) latches, the bridge polls its status every --poll-ms.
    #[arg(long, conflicts_with_all = ["can", "direct"])]
    pub modbus: bool,
    /// Modbus: status poll period, ms.
    #[arg(long, default_value_t = 1, requires = "modbus")]
    pub poll_ms: u32,
}

impl BenchArgs {
    /// The SYNC period once resolved (see `run`).
    fn period(&self) -> u32 {
        self.period_us.unwrap_or(0)
    }
}

/// Whether process `pid` runs under SCHED_FIFO (field 41 of /proc/PID/stat).
fn is_fifo(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .ok()
        .and_then(|s| {
            // The command name (field 2) may hold spaces: count after its ')'.
            let rest = &s[s.rfind(')')? + 2..];
            rest.split_whitespace().nth(38)?.parse::<u32>().ok()
        })
        == Some(1)
}

/// Where the run keeps its files and names its services.
pub(crate) struct Workspace {
    pub(crate) prefix: String,
    pub(crate) dir: PathBuf,
    pub(crate) times_file: PathBuf,
    pub(crate) estimator_log: PathBuf,
}

impl Workspace {
    /// A scratch folder named `prefix` (also the iceoryx2 service prefix) for the
    /// estimator's receive times and its log.
    pub(crate) fn new(prefix: String) -> Result<Self, String> {
        let dir = std::env::temp_dir().join(&prefix);
        std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        Ok(Self {
            prefix,
            times_file: dir.join("receive-times.txt"),
            estimator_log: dir.join("estimator.log"),
            dir,
        })
    }
}

/// The processes and threads of one run, and which real-time settings they got.
struct Rig {
    estimator: EstimatorChild,
    estimator_fifo: bool,
    /// The simulated drives; taken and stopped once the machine has shut down.
    sim: Option<SimRunner>,
    sim_fifo: bool,
    drive_priority: i32,
    forwarder_priority: i32,
    forwarder_fifo: bool,
    machine: CanMachine,
    startup: StartupReport,
    floor: ContactPublisher,
    /// This thread (the floor's sender) under SCHED_FIFO.
    main_fifo: bool,
    latches: Arc<LatchLog>,
}

/// What the trigger loop recorded.
struct Measured {
    /// Sequence of each measured contact -> its t0.
    t0_of: HashMap<u64, u64>,
    floor_seqs: Vec<u64>,
    stop_ns: Vec<u64>,
    stop_cycles: Vec<u64>,
    missing_t0: u64,
    elapsed: Duration,
    loop_stats: LoopStats,
    /// The host's cross-CPU wake-up floor (`None`: could not be measured, and why).
    wakeup: Result<bench::wakeup::Wakeup, String>,
}

/// The latencies, matched with the estimator's receive times.
struct Latencies {
    trigger: Vec<u64>,
    to_rt: Vec<u64>,
    rt_to_estimator: Vec<u64>,
    floor: Vec<u64>,
    lost_triggers: u64,
    lost_floor: u64,
}

pub fn run(args: &BenchArgs) -> Result<(), String> {
    if args.triggers == 0 {
        return Err("--triggers must be at least 1".into());
    }
    crate::output::check_output(args.json.as_deref())?;
    let (scenario, cfg, mut notes) = bench_machine(args)?;
    // From here on the period is the one the machine runs.
    let args = &BenchArgs {
        period_us: cfg.canopen_bus().map(|b| b.sync_period_us),
        ..args.clone()
    };
    let warmup = args.warmup.unwrap_or((args.triggers / 10).clamp(1, 100));
    let total = warmup + args.triggers;
    let pid = std::process::id();
    let ws = Workspace::new(format!("probebridge-bench-{pid}"))?;
    let rig = start_rig(args, &ws, &scenario, &cfg, total)?;
    notes.extend(rig.startup.notes.iter().cloned());
    let (measured, rig) = measure(args, rig, warmup, total)?;
    let records = collect_records(rig.estimator, &ws)?;
    let latencies = match_records(&measured, &records);
    let _ = std::fs::remove_dir_all(&ws.dir);
    let report = Report {
        args,
        warmup,
        notes,
        startup: rig.startup,
        sim_fifo: rig.sim_fifo,
        drive_priority: rig.drive_priority,
        forwarder_priority: rig.forwarder_priority,
        forwarder_fifo: rig.forwarder_fifo,
        estimator_fifo: rig.estimator_fifo,
        main_fifo: rig.main_fifo,
        measured,
        latencies,
    };
    report.print_and_write()
}

/// The machine: table-ac with a flat face, SYNC at the requested period; notes for
/// the report.
fn bench_machine(args: &BenchArgs) -> Result<(Scenario, MachineConfig, Vec<String>), String> {
    let scenario_path = configs::configs_dir().join("scenarios/bench-trigger.toml");
    let scenario = Scenario::parse(
        bench::SCENARIO,
        &scenario_path,
        Some(&configs::machines_dir()),
    )
    .map_err(|e| e.to_string())?;
    let mut cfg = crate::session::machine_config(&scenario);
    let bus = cfg
        .canopen_bus_mut()
        .ok_or("the bench scenario's machine is not on CANopen")?;
    let period_us = args.period_us.unwrap_or(bus.sync_period_us);
    if !(50..=100_000).contains(&period_us) {
        return Err(format!("--period-us {period_us}: must be 50 .. 100000"));
    }
    bus.sync_period_us = period_us;
    let limit = bus.max_load_percent;
    // Short moves of a few µm are acceleration-bound: a stiffer machine brings a
    // trigger (probe, stop, retract) down to about a dozen SYNC periods. The hot path
    // does not depend on it.
    for a in &mut cfg.axes {
        a.max_acceleration = a.max_acceleration.max(bench::ACCELERATION);
    }
    // A bus that exists: the traffic must fit the bit rate, in-process as on SocketCAN.
    let load = BusLoad::of(&cfg);
    if load.percent > limit {
        let fits = BusLoad::shortest_period_us(&cfg, limit)
            .map_or("no period fits".to_string(), |p| {
                format!("the shortest period that fits is {p} us")
            });
        return Err(format!(
            "--period-us {period_us}: {load}, above the bus-load limit of {limit:.0} % ({}: bus.max_load_percent); {fits}",
            cfg.path.display()
        ));
    }
    let notes = vec![format!("bus: {load}; limit {limit:.0} %")];
    Ok((scenario, cfg, notes))
}

/// The estimator process (under SCHED_FIFO when asked) recording receive times;
/// whether it got SCHED_FIFO.
fn spawn_estimator(
    args: &BenchArgs,
    ws: &Workspace,
    total: u64,
) -> Result<(EstimatorChild, bool), String> {
    let (prefix, times_file, estimator_log) =
        (ws.prefix.as_str(), &ws.times_file, &ws.estimator_log);
    tell!("bench: starting the estimator process ...");
    let mut command = Command::new(std::env::current_exe().map_err(|e| e.to_string())?);
    command.args([
        "estimator",
        "--service",
        prefix,
        "--record-times",
        &times_file.to_string_lossy(),
        "--record-capacity",
        &(2 * total + 64)
            .max(DEFAULT_RECORD_CAPACITY as u64)
            .to_string(),
    ]);
    let log = std::fs::File::create(estimator_log)
        .map_err(|e| format!("{}: {e}", estimator_log.display()))?;
    command.stderr(Stdio::from(log));
    if args.estimator_priority > 0 {
        use std::os::unix::process::CommandExt;
        let priority = args.estimator_priority;
        // SAFETY: runs in the forked child before exec; sched_setscheduler is a plain
        // syscall (async-signal-safe) and SCHED_FIFO is kept across exec. Failure is
        // detected below through the child's scheduling policy.
        unsafe {
            command.pre_exec(move || {
                hal::rt::set_fifo_priority(priority);
                Ok(())
            });
        }
    }
    let estimator = EstimatorChild::spawn_command(command, prefix, Duration::from_secs(10))
        .map_err(|e| format!("cannot start the estimator: {e}"))?;
    let estimator_fifo = args.estimator_priority > 0 && is_fifo(estimator.id());

    Ok((estimator, estimator_fifo))
}

/// The bus between the bridge and the simulated drives: the in-process bus, or two
/// sockets on `--can`.
/// The bridge's end and the drives' end of the bench's bus.
type Ends = (Box<dyn CanTransport>, Box<dyn CanTransport>);

fn bench_transports(args: &BenchArgs, bitrate: u32) -> Result<Ends, String> {
    Ok(match &args.can {
        None => {
            // The machine's bit rate, wire time in real time; the drives arbitrate as
            // separate devices.
            let bus = InprocBus::with_wire_time(bitrate, WireClock::Monotonic);
            (
                Box::new(bus.endpoint()),
                Box::new(bus.endpoint_for_devices()),
            )
        }
        Some(iface) => {
            let open =
                |who: &str| SocketCanTransport::open(iface).map_err(|e| format!("{who}: {e}"));
            (
                Box::new(open("bridge")?),
                Box::new(open("simulated drives")?),
            )
        }
    })
}

/// The estimator, the simulated drives, the bridge's sink and `CanMachine`, the floor
/// publisher; every thread on the measured path under SCHED_FIFO where permitted.
fn start_rig(
    args: &BenchArgs,
    ws: &Workspace,
    scenario: &Scenario,
    cfg: &MachineConfig,
    total: u64,
) -> Result<Rig, String> {
    let prefix = ws.prefix.as_str();
    let (estimator, estimator_fifo) = spawn_estimator(args, ws, total)?;
    let latches = LatchLog::new();
    let mut sim_machine = SimMachine::new(scenario);
    sim_machine.set_latch_log(latches.clone());
    sim_machine.set_clock(SimClock::Monotonic);
    let bitrate = cfg.canopen_bus().map_or(1_000_000, |b| b.bitrate);
    let (master_transport, sim_transport) = bench_transports(args, bitrate)?;
    // The simulated drives stand for hardware: they should not wait for the scheduler
    // either (default: the real-time loop's priority minus one).
    let drive_priority = args.drives_priority.unwrap_or(args.rt_priority - 1);
    let (sim_fifo_tx, sim_fifo_rx) = std::sync::mpsc::sync_channel(1);
    let sim = SimRunner::spawn_with_init(sim_machine, sim_transport, move || {
        let _ = sim_fifo_tx.send(drive_priority > 0 && hal::rt::set_fifo_priority(drive_priority));
    });
    let sim_fifo = sim_fifo_rx.recv().unwrap_or(false);
    // The forwarder is on the hot path too: the real-time loop's priority minus two.
    let forwarder_priority = args.rt_priority - 2;
    let mut forwarder_fifo = false;
    let sink: Box<dyn SampleSink> = if args.direct {
        Box::new(ContactPublisher::new(prefix).map_err(|e| e.to_string())?)
    } else {
        let (sink, fifo) = ForwardingSink::spawn_realtime(prefix, forwarder_priority.max(0))
            .map_err(|e| e.to_string())?;
        forwarder_fifo = fifo;
        Box::new(sink)
    };
    let options = MasterOptions {
        pacing: Pacing::RealTime,
        rt_priority: args.rt_priority,
        run_id: TRIGGER_RUN,
        command_timeout: Duration::from_secs(10),
        abort: None,
    };
    tell!(
        "bench: bringing up the drives ({} bus, SYNC every {} us) ...",
        args.can.as_deref().unwrap_or("in-process"),
        args.period()
    );
    let (machine, startup) =
        CanMachine::start(cfg, master_transport, sink, options).map_err(|e| e.to_string())?;
    let floor = ContactPublisher::new(prefix).map_err(|e| e.to_string())?;
    floor.update_connections().map_err(|e| e.to_string())?;
    // This thread publishes the floor samples: at the forwarder's priority, so the
    // floor's sender waits for the scheduler no more than the bridge's does.
    let main_fifo = forwarder_priority > 0 && hal::rt::set_fifo_priority(forwarder_priority);

    Ok(Rig {
        estimator,
        estimator_fifo,
        sim: Some(sim),
        sim_fifo,
        drive_priority,
        forwarder_priority,
        forwarder_fifo,
        machine,
        startup,
        floor,
        main_fifo,
        latches,
    })
}

/// The triggers: probe, the floor sample, retract; `warmup` first, not counted.
fn measure(args: &BenchArgs, rig: Rig, warmup: u64, total: u64) -> Result<(Measured, Rig), String> {
    let mut rig = rig;
    let (machine, floor, latches) = (&mut rig.machine, &mut rig.floor, &rig.latches);
    let start = AxisPositions::linear([
        bench::START_XY[0],
        bench::START_XY[1],
        bench::TOUCH_Z + bench::GAP,
    ]);
    machine
        .move_to(&start, 5000.0)
        .map_err(|e| format!("moving to the start: {e}"))?;
    let probe = ProbeMove {
        direction: [0.0, 0.0, -1.0],
        feed: bench::FEED,
        max_distance: bench::DISTANCE,
    };

    tell!(
        "bench: {warmup} warm-up + {} measured triggers ...",
        args.triggers
    );
    // Per measured trigger: (sequence, t0) and the stop latency.
    let mut t0_of = HashMap::with_capacity(total as usize);
    let mut floor_seqs = Vec::with_capacity(args.triggers as usize);
    let mut stop_ns = Vec::with_capacity(args.triggers as usize);
    let mut stop_cycles = Vec::with_capacity(args.triggers as usize);
    let mut missing_t0 = 0u64;
    let began = Instant::now();
    let mut last_report = Instant::now();
    for k in 0..total {
        let before = latches.count();
        let contact = machine
            .probe(&probe)
            .map_err(|e| format!("trigger {}: {e}", k + 1))?;
        let measured = k >= warmup;
        let t0 = (latches.count() == before + 1)
            .then(|| latches.get(before))
            .flatten();
        if measured {
            match t0 {
                Some(t0) => {
                    t0_of.insert(contact.sequence, t0);
                }
                None => missing_t0 += 1,
            }
            let s = machine.stats();
            stop_ns.push(s.last_stop_latency_ns);
            stop_cycles.push(s.last_stop_latency_cycles);
        }
        // The floor: the same payload, this process -> the estimator, nothing between.
        let mut sample = ContactSample::zeroed();
        sample.sequence = contact.sequence;
        sample.run_id = FLOOR_RUN;
        sample.trigger_ns = hal::clock::monotonic_ns();
        floor
            .send(&sample)
            .map_err(|_| "the floor sample could not be published".to_string())?;
        if measured {
            floor_seqs.push(contact.sequence);
        }
        machine
            .move_to(&start, 5000.0)
            .map_err(|e| format!("retract after trigger {}: {e}", k + 1))?;
        if last_report.elapsed() > Duration::from_secs(10) {
            last_report = Instant::now();
            tell!(
                "bench: {} of {total} triggers, {:.0} s",
                k + 1,
                began.elapsed().as_secs_f64()
            );
        }
    }
    let elapsed = began.elapsed();
    let loop_stats = machine.stats();
    machine.shutdown();
    drop(rig.sim.take());
    tell!("bench: the host's cross-CPU wake-up floor ...");
    let pings = args.triggers as usize;
    let wakeup = bench::wakeup::measure(pings, warmup as usize, args.estimator_priority.max(0));

    Ok((
        Measured {
            t0_of,
            floor_seqs,
            stop_ns,
            stop_cycles,
            missing_t0,
            elapsed,
            loop_stats,
            wakeup,
        },
        rig,
    ))
}

/// Stops the estimator and reads the receive times it recorded.
pub(crate) fn collect_records(
    mut estimator: EstimatorChild,
    ws: &Workspace,
) -> Result<Vec<ReceiveTime>, String> {
    let estimator_log = &ws.estimator_log;
    // Let the estimator write its records and exit.
    let _ = estimator.client().shutdown(Duration::from_secs(5));
    let deadline = Instant::now() + Duration::from_secs(30);
    while estimator.try_wait().map_err(|e| e.to_string())?.is_none() {
        if Instant::now() > deadline {
            return Err(format!(
                "the estimator did not exit; its log: {}",
                estimator_log.display()
            ));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    drop(estimator);
    let records = ReceiveTimes::read(&ws.times_file)
        .map_err(|e| format!("{e} (estimator log: {})", estimator_log.display()))?;
    Ok(records)
}

/// Each measured trigger and floor sample matched with the estimator's record of it.
fn match_records(m: &Measured, records: &[ReceiveTime]) -> Latencies {
    let t0_of = &m.t0_of;
    let by_key: HashMap<(u64, u64), ReceiveTime> = records
        .iter()
        .map(|r| ((r.run_id, r.sequence), *r))
        .collect();

    let mut trigger = Vec::with_capacity(t0_of.len());
    let mut to_rt = Vec::with_capacity(t0_of.len());
    let mut rt_to_estimator = Vec::with_capacity(t0_of.len());
    let mut lost_triggers = 0u64;
    let mut seqs: Vec<&u64> = t0_of.keys().collect();
    seqs.sort_unstable();
    for seq in seqs {
        let t0 = t0_of[seq];
        match by_key.get(&(TRIGGER_RUN, *seq)) {
            Some(r) => {
                trigger.push(r.t1_ns.saturating_sub(t0));
                to_rt.push(r.receive_ns.saturating_sub(t0));
                rt_to_estimator.push(r.t1_ns.saturating_sub(r.receive_ns));
            }
            None => lost_triggers += 1,
        }
    }
    let mut floor_ns = Vec::with_capacity(m.floor_seqs.len());
    let mut lost_floor = 0u64;
    for seq in &m.floor_seqs {
        match by_key.get(&(FLOOR_RUN, *seq)) {
            Some(r) => floor_ns.push(r.t1_ns.saturating_sub(r.trigger_ns)),
            None => lost_floor += 1,
        }
    }
    Latencies {
        trigger,
        to_rt,
        rt_to_estimator,
        floor: floor_ns,
        lost_triggers,
        lost_floor,
    }
}

/// Everything the report prints and writes.
struct Report<'a> {
    args: &'a BenchArgs,
    warmup: u64,
    notes: Vec<String>,
    startup: StartupReport,
    sim_fifo: bool,
    drive_priority: i32,
    forwarder_priority: i32,
    forwarder_fifo: bool,
    estimator_fifo: bool,
    main_fifo: bool,
    measured: Measured,
    latencies: Latencies,
}

/// The figures of the report.
struct Figures {
    /// End to end: latch (t0) to the estimator having the sample (t1).
    trig: Summary,
    /// The bare iceoryx2 hop, same processes.
    fl: Summary,
    /// Latch to the last bit of the frame that completed the contact (the modelled
    /// wire time on the in-process bus; the real bus on `--can`).
    bus_hop: Option<Summary>,
    /// The software path: that last bit to the estimator.
    ipc_hop: Option<Summary>,
    /// The host's cross-CPU wake-up (eventfd between two processes).
    wake: Option<Summary>,
    stop: Option<Summary>,
    cycles_sorted: Vec<u64>,
    bus_name: String,
    wire_modelled: bool,
    cpuidle: Option<String>,
}

/// `a` against a floor `b`: ratio and difference, at p50 and p99.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Against {
    p50_ratio: f64,
    p99_ratio: f64,
    p50_above_us: f64,
    p99_above_us: f64,
}

impl Against {
    fn of(a: &Summary, floor: &Summary) -> Self {
        Self {
            p50_ratio: a.p50_us / floor.p50_us,
            p99_ratio: a.p99_us / floor.p99_us,
            p50_above_us: a.p50_us - floor.p50_us,
            p99_above_us: a.p99_us - floor.p99_us,
        }
    }

    fn text(&self) -> String {
        format!(
            "p50 {:.2}x (+{:.1} us), p99 {:.2}x (+{:.1} us)",
            self.p50_ratio, self.p50_above_us, self.p99_ratio, self.p99_above_us
        )
    }

    fn to_json(self) -> serde_json::Value {
        json!({
            "p50_ratio": self.p50_ratio,
            "p99_ratio": self.p99_ratio,
            "p50_above_us": self.p50_above_us,
            "p99_above_us": self.p99_above_us,
        })
    }
}

impl Figures {
    /// The software path: the last-bit-to-estimator hop when measured, else the whole
    /// path (no receive time).
    fn software(&self) -> &Summary {
        self.ipc_hop.as_ref().unwrap_or(&self.trig)
    }

    /// Stop latency in cycles at percentile `p`.
    fn stop_cycles(&self, p: f64) -> u64 {
        bench::percentile(&self.cycles_sorted, p)
    }

    /// The latency table and how far the path is from both floors, as printed.
    fn lines(&self) -> Vec<String> {
        let row = |name: &str, s: &Summary| format!("{name:<52}{}", s.row());
        let mut out = vec![format!("{:<52}{}", "", Summary::HEADER)];
        out.push(row("end to end: latch -> estimator (t0 to t1)", &self.trig));
        if let Some(s) = &self.bus_hop {
            let name = if self.wire_modelled {
                "  wire: latch -> last bit of the frame (modelled)"
            } else {
                "  bus: latch -> real-time loop has the frame"
            };
            out.push(row(name, s));
        }
        if let Some(s) = &self.ipc_hop {
            out.push(row("  software path: frame in -> estimator", s));
        }
        out.push(row("floor: bare iceoryx2 hop, same processes", &self.fl));
        match &self.wake {
            Some(w) => out.push(row("floor: host cross-CPU wake-up (eventfd)", w)),
            None => out.push("floor: host cross-CPU wake-up: not measured".into()),
        }
        if let Some(s) = &self.stop {
            out.push(row("stop: first latch frame in -> stop sent", s));
        }
        out.push(String::new());
        let sw = self.software();
        out.push(format!(
            "software path vs the iceoryx2 floor: {}",
            Against::of(sw, &self.fl).text()
        ));
        out.push(format!(
            "end to end vs the iceoryx2 floor: {}",
            Against::of(&self.trig, &self.fl).text()
        ));
        if let Some(w) = &self.wake {
            out.push(format!(
                "software path vs the host's wake-up: {}",
                Against::of(sw, w).text()
            ));
            out.push(format!(
                "end to end vs the host's wake-up: {}",
                Against::of(&self.trig, w).text()
            ));
        }
        out.push(format!(
            "stop latency: p50 {} cycle(s), p99 {} (max {}), counted from the cycle the first latch frame arrived in; target p99 <= 1: {}",
            self.stop_cycles(50.0),
            self.stop_cycles(99.0),
            self.cycles_sorted.last().copied().unwrap_or(0),
            yes_no(self.stop_cycles(99.0) <= 1)
        ));
        out.push(format!(
            "software path targets: p99 <= 20 us: {}; p99.9 <= 50 us: {}; p50 within 2x the iceoryx2 floor: {}",
            yes_no(sw.p99_us <= 20.0),
            yes_no(sw.p999_us <= 50.0),
            yes_no(Against::of(sw, &self.fl).p50_ratio <= 2.0)
        ));
        out
    }

    /// The figures as JSON (part of `--json`).
    fn json(&self) -> serde_json::Value {
        let sw = self.software();
        json!({
            "end_to_end_us": self.trig.to_json(),
            "trigger_latency_us": self.trig.to_json(),
            "latch_to_rt_us": self.bus_hop.map(Summary::to_json),
            "wire_time_modelled": self.wire_modelled,
            "software_path_us": self.ipc_hop.map(Summary::to_json),
            "rt_to_estimator_us": self.ipc_hop.map(Summary::to_json),
            "floor_us": self.fl.to_json(),
            "host_wakeup_us": self.wake.map(Summary::to_json),
            "software_vs_floor": Against::of(sw, &self.fl).to_json(),
            "end_to_end_vs_floor": Against::of(&self.trig, &self.fl).to_json(),
            "software_vs_host_wakeup": self.wake.map(|w| Against::of(sw, &w).to_json()),
            "end_to_end_vs_host_wakeup": self.wake.map(|w| Against::of(&self.trig, &w).to_json()),
            "stop_latency": {
                "us": self.stop.map(Summary::to_json),
                "cycles": {
                    "min": self.cycles_sorted.first(),
                    "p50": self.stop_cycles(50.0),
                    "p99": self.stop_cycles(99.0),
                    "max": self.cycles_sorted.last(),
                },
            },
            "targets": {
                "software_p99_le_20us": sw.p99_us <= 20.0,
                "software_p99_9_le_50us": sw.p999_us <= 50.0,
                "software_p50_within_2x_floor": Against::of(sw, &self.fl).p50_ratio <= 2.0,
                "stop_p99_le_1_cycle": self.stop_cycles(99.0) <= 1,
            },
        })
    }
}

impl Report<'_> {
    fn print_and_write(&self) -> Result<(), String> {
        let l = &self.latencies;
        let (Some(trig), Some(fl)) = (Summary::of(&l.trigger), Summary::of(&l.floor)) else {
            return Err("no trigger or floor sample reached the estimator".into());
        };
        let mut cycles_sorted = self.measured.stop_cycles.clone();
        cycles_sorted.sort_unstable();
        let f = Figures {
            trig,
            fl,
            bus_hop: Summary::of(&l.to_rt),
            ipc_hop: Summary::of(&l.rt_to_estimator),
            wake: self
                .measured
                .wakeup
                .as_ref()
                .ok()
                .and_then(|w| Summary::of(&w.latencies_ns)),
            stop: Summary::of(&self.measured.stop_ns),
            cycles_sorted,
            bus_name: self
                .args
                .can
                .clone()
                .unwrap_or_else(|| "in-process".to_string()),
            wire_modelled: self.args.can.is_none(),
            cpuidle: hal::rt::cpuidle_driver(),
        };
        self.print_settings(&f);
        self.print_figures(&f);
        if let Some(path) = &self.args.json {
            crate::output::write_json(path, &self.json(&f))?;
        }
        Ok(())
    }

    /// What ran, and which real-time settings it got.
    fn print_settings(&self, f: &Figures) {
        let args = self.args;
        let startup = &self.startup;
        let sink_name = if args.direct {
            "ContactPublisher in the real-time thread (--direct)"
        } else {
            "ForwardingSink (forwarder thread publishes)"
        };
        say!(
            "probebridge bench trigger: {} triggers ({} warm-up not counted) in {:.1} s; SYNC {} us; {} bus; sink: {}",
            args.triggers,
            self.warmup,
            self.measured.elapsed.as_secs_f64(),
            args.period(),
            f.bus_name,
            sink_name
        );
        let granted = |b: bool| if b { "granted" } else { "NOT granted" };
        say!(
            "SCHED_FIFO: real-time loop {} (priority {}), simulated drives {} ({}), {}, {}; memory {}; CPU wake-up latency {} (cpuidle driver: {}); {} CPUs",
            granted(startup.realtime_priority),
            args.rt_priority,
            granted(self.sim_fifo),
            self.drive_priority,
            if args.direct {
                "no forwarder (--direct)".to_string()
            } else {
                format!("forwarder {} ({})", granted(self.forwarder_fifo), self.forwarder_priority)
            },
            if args.estimator_priority > 0 {
                format!(
                    "estimator {} ({})",
                    granted(self.estimator_fifo),
                    args.estimator_priority
                )
            } else {
                "estimator: ordinary process".to_string()
            },
            if startup.memory_locked { "locked" } else { "NOT locked" },
            if startup.cpu_latency_held {
                "held at 0 us"
            } else {
                "NOT held"
            },
            f.cpuidle.as_deref().unwrap_or("not reported"),
            std::thread::available_parallelism().map_or(0, |n| n.get())
        );
        match &self.measured.wakeup {
            Ok(w) => say!(
                "host wake-up floor: {} eventfd pings between two processes, {}, {}",
                w.latencies_ns.len(),
                if w.cross_cpu {
                    "pinned to different CPUs"
                } else {
                    "NOT pinned to different CPUs"
                },
                if w.fifo {
                    format!("SCHED_FIFO {}", args.estimator_priority)
                } else {
                    "ordinary scheduling".to_string()
                }
            ),
            Err(e) => say!("host wake-up floor: not measured: {e}"),
        }
        for n in &self.notes {
            say!("note: {n}");
        }
    }

    /// The latency table, the comparisons with both floors, the targets, anything
    /// lost.
    fn print_figures(&self, f: &Figures) {
        say!();
        for line in f.lines() {
            say!("{line}");
        }
        let (l, m) = (&self.latencies, &self.measured);
        let stats = &m.loop_stats;
        let anomalies = l.lost_triggers + l.lost_floor + m.missing_t0 + stats.publish_failures;
        if anomalies > 0 || stats.late_cycles > 0 || stats.skipped_cycles > 0 {
            say!(
                "lost: {} trigger and {} floor samples; {} triggers without t0; {} publish failures; {} late cycles, {} SYNC slots skipped after stalls",
                l.lost_triggers, l.lost_floor, m.missing_t0, stats.publish_failures, stats.late_cycles, stats.skipped_cycles
            );
        }
    }

    /// All figures as JSON (`--json`).
    fn json(&self, f: &Figures) -> serde_json::Value {
        let (args, startup, l, m) = (self.args, &self.startup, &self.latencies, &self.measured);
        let mut doc = json!({
            "benchmark": "trigger",
            "triggers": args.triggers,
            "warmup": self.warmup,
            "period_us": args.period(),
            "bus": f.bus_name,
            "bus_load": self.startup.bus_load.percent,
            "bus_load_latch_cycle": self.startup.bus_load.burst_percent,
            "sink": if args.direct { "direct" } else { "forwarding" },
            "elapsed_s": m.elapsed.as_secs_f64(),
            "cpus": std::thread::available_parallelism().map_or(0, |n| n.get()),
            "realtime": {
                "sched_fifo": startup.realtime_priority,
                "priority": args.rt_priority,
                "simulated_drives_sched_fifo": self.sim_fifo,
                "forwarder_sched_fifo": self.forwarder_fifo,
                "estimator_priority": args.estimator_priority,
                "estimator_sched_fifo": self.estimator_fifo,
                "simulated_drives_priority": self.drive_priority,
                "floor_sender_sched_fifo": self.main_fifo,
                "memory_locked": startup.memory_locked,
                "cpu_latency_held": startup.cpu_latency_held,
                "cpuidle_driver": f.cpuidle,
                "host_wakeup_cross_cpu": m.wakeup.as_ref().is_ok_and(|w| w.cross_cpu),
                "host_wakeup_sched_fifo": m.wakeup.as_ref().is_ok_and(|w| w.fifo),
                "notes": self.notes,
            },
            "lost": {
                "trigger_samples": l.lost_triggers,
                "floor_samples": l.lost_floor,
                "triggers_without_t0": m.missing_t0,
                "publish_failures": m.loop_stats.publish_failures,
            },
            "late_cycles": m.loop_stats.late_cycles,
            "skipped_cycles": m.loop_stats.skipped_cycles,
        });
        if let (Some(doc), serde_json::Value::Object(figures)) = (doc.as_object_mut(), f.json()) {
            doc.extend(figures);
        }
        doc
    }
}

fn yes_no(ok: bool) -> &'static str {
    if ok {
        "met"
    } else {
        "MISSED"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Synthetic figures: 100 triggers whose software path is 10..=109 us, plus 575 us
    /// of wire time; the iceoryx2 floor 5..=104 us; the host's wake-up 2..=101 us;
    /// the stop in the next cycle every time but once, in the second.
    fn figures() -> Figures {
        let us = |v: u64| v * 1000;
        let sw: Vec<u64> = (10..110).map(us).collect();
        let wire: Vec<u64> = vec![us(575); 100];
        let trig: Vec<u64> = sw.iter().map(|s| s + us(575)).collect();
        let mut cycles = vec![1u64; 100];
        cycles[7] = 2;
        cycles.sort_unstable();
        Figures {
            trig: Summary::of(&trig).unwrap(),
            fl: Summary::of(&(5..105).map(us).collect::<Vec<_>>()).unwrap(),
            bus_hop: Summary::of(&wire),
            ipc_hop: Summary::of(&sw),
            wake: Summary::of(&(2..102).map(us).collect::<Vec<_>>()),
            stop: Summary::of(&[us(1900); 100]),
            cycles_sorted: cycles,
            bus_name: "in-process".into(),
            wire_modelled: true,
            cpuidle: None,
        }
    }

    #[test]
    fn the_report_gives_both_paths_against_both_floors_and_the_stop_in_cycles() {
        let f = figures();
        let lines = f.lines();
        let find = |start: &str| {
            lines
                .iter()
                .find(|l| l.starts_with(start))
                .unwrap_or_else(|| panic!("no line {start:?} in {lines:#?}"))
                .clone()
        };
        for row in [
            "end to end: latch -> estimator",
            "  wire: latch -> last bit of the frame (modelled)",
            "  software path: frame in -> estimator",
            "floor: bare iceoryx2 hop",
            "floor: host cross-CPU wake-up (eventfd)",
            "stop: first latch frame in -> stop sent",
        ] {
            find(row);
        }
        // Software p50 59 us against the floors' p50 54 and 51 us; p99 108 against
        // 103 and 100 us.
        assert_eq!(
            find("software path vs the iceoryx2 floor"),
            "software path vs the iceoryx2 floor: p50 1.09x (+5.0 us), p99 1.05x (+5.0 us)"
        );
        assert_eq!(
            find("software path vs the host's wake-up"),
            "software path vs the host's wake-up: p50 1.16x (+8.0 us), p99 1.08x (+8.0 us)"
        );
        find("end to end vs the iceoryx2 floor: p50 11.74x (+580.0 us)");
        find("end to end vs the host's wake-up");
        // 99 of 100 in one cycle: p50 and p99 are 1, the maximum 2.
        assert!(find("stop latency:").starts_with("stop latency: p50 1 cycle(s), p99 1 (max 2)"));
        assert!(find("stop latency:").ends_with("target p99 <= 1: met"));

        let j = f.json();
        assert_eq!(j["stop_latency"]["cycles"]["p99"], 1);
        assert_eq!(j["stop_latency"]["cycles"]["max"], 2);
        assert_eq!(j["targets"]["stop_p99_le_1_cycle"], true);
        assert_eq!(j["software_path_us"]["p50"], 59.0);
        assert_eq!(j["host_wakeup_us"]["p99"], 100.0);
        assert_eq!(j["end_to_end_us"]["p50"], 634.0);
        assert!(j["software_vs_host_wakeup"]["p99_ratio"].is_number());
    }

    #[test]
    fn a_late_stop_misses_the_cycle_target() {
        let mut f = figures();
        f.cycles_sorted = vec![2; 100];
        assert!(f
            .lines()
            .iter()
            .any(|l| l.starts_with("stop latency: p50 2") && l.ends_with("MISSED")));
        assert_eq!(f.json()["targets"]["stop_p99_le_1_cycle"], false);
    }
}
