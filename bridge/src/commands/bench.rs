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
//! same payload, same event wake-up), t0 taken right before the send.

use crate::bench::{self, Summary};
use crate::commands::estimator::DEFAULT_RECORD_CAPACITY;
use crate::configs;
use crate::estimator::{ReceiveTime, ReceiveTimes};
use crate::ipc::{ContactPublisher, EstimatorChild, ForwardingSink};
use hal::can::inproc::InprocBus;
use hal::can::socketcan::SocketCanTransport;
use hal::can::CanTransport;
use hal::master::{BusLoad, CanMachine, MasterOptions, Pacing};
use hal::{AxisPositions, ContactSample, Machine, ProbeMove, SampleSink};
use serde_json::json;
use sim::machine::{LatchLog, SimClock, SimMachine, SimRunner};
use sim::Scenario;
use std::collections::HashMap;
use std::path::PathBuf;
use std::process::{Command, Stdio};
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
    /// SYNC period of the real-time loop, µs.
    #[arg(long, default_value_t = 250)]
    pub period_us: u32,
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

pub fn run(args: &BenchArgs) -> Result<(), String> {
    if args.triggers == 0 {
        return Err("--triggers must be at least 1".into());
    }
    if !(50..=100_000).contains(&args.period_us) {
        return Err(format!(
            "--period-us {}: must be 50 .. 100000",
            args.period_us
        ));
    }
    crate::output::check_output(args.json.as_deref())?;
    let warmup = args.warmup.unwrap_or((args.triggers / 10).clamp(1, 100));
    let total = warmup + args.triggers;
    let pid = std::process::id();
    let prefix = format!("probebridge-bench-{pid}");
    let work = std::env::temp_dir().join(format!("probebridge-bench-{pid}"));
    std::fs::create_dir_all(&work).map_err(|e| format!("{}: {e}", work.display()))?;
    let times_file = work.join("receive-times.txt");
    let estimator_log = work.join("estimator.log");

    // The machine: table-ac with a flat face, SYNC at the requested period.
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
    bus.sync_period_us = args.period_us;
    let bitrate = bus.bitrate;
    // Short moves of a few µm are acceleration-bound: a stiffer machine brings a
    // trigger (probe, stop, retract) down to about a dozen SYNC periods. The hot path
    // does not depend on it.
    for a in &mut cfg.axes {
        a.max_acceleration = a.max_acceleration.max(bench::ACCELERATION);
    }
    let load = BusLoad::of(&cfg);
    let mut notes = Vec::new();
    if args.can.is_none() {
        // The in-process bus has no bit rate: nothing to overload.
        if let Some(bus) = cfg.canopen_bus_mut() {
            bus.max_load_percent = f64::INFINITY;
        }
        notes.push(format!(
            "in-process bus: no bit rate, the bus-load limit does not apply (this traffic would be {:.0} % of {} kbit/s)",
            load.percent,
            bitrate / 1000
        ));
    }

    eprintln!("bench: starting the estimator process ...");
    let mut command = Command::new(std::env::current_exe().map_err(|e| e.to_string())?);
    command.args([
        "estimator",
        "--service",
        &prefix,
        "--record-times",
        &times_file.to_string_lossy(),
        "--record-capacity",
        &(2 * total + 64)
            .max(DEFAULT_RECORD_CAPACITY as u64)
            .to_string(),
    ]);
    let log = std::fs::File::create(&estimator_log)
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
    let mut estimator = EstimatorChild::spawn_command(command, &prefix, Duration::from_secs(10))
        .map_err(|e| format!("cannot start the estimator: {e}"))?;
    let estimator_fifo = args.estimator_priority > 0 && is_fifo(estimator.id());

    // Drives and bus.
    let latches = LatchLog::new();
    let mut sim_machine = SimMachine::new(&scenario);
    sim_machine.set_latch_log(latches.clone());
    sim_machine.set_clock(SimClock::Monotonic);
    let (master_transport, sim_transport): (Box<dyn CanTransport>, Box<dyn CanTransport>) =
        match &args.can {
            None => {
                let bus = InprocBus::new();
                (Box::new(bus.endpoint()), Box::new(bus.endpoint()))
            }
            Some(iface) => {
                let open =
                    |who: &str| SocketCanTransport::open(iface).map_err(|e| format!("{who}: {e}"));
                (
                    Box::new(open("bridge")?),
                    Box::new(open("simulated drives")?),
                )
            }
        };
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
        Box::new(ContactPublisher::new(&prefix).map_err(|e| e.to_string())?)
    } else {
        let (sink, fifo) = ForwardingSink::spawn_realtime(&prefix, forwarder_priority.max(0))
            .map_err(|e| e.to_string())?;
        forwarder_fifo = fifo;
        Box::new(sink)
    };
    let options = MasterOptions {
        pacing: Pacing::RealTime,
        rt_priority: args.rt_priority,
        run_id: TRIGGER_RUN,
        command_timeout: Duration::from_secs(10),
    };
    eprintln!(
        "bench: bringing up the drives ({} bus, SYNC every {} us) ...",
        args.can.as_deref().unwrap_or("in-process"),
        args.period_us
    );
    let (mut machine, startup) =
        CanMachine::start(&cfg, master_transport, sink, options).map_err(|e| e.to_string())?;
    notes.extend(startup.notes.iter().cloned());
    let mut floor = ContactPublisher::new(&prefix).map_err(|e| e.to_string())?;
    floor.update_connections().map_err(|e| e.to_string())?;
    // This thread publishes the floor samples: at the forwarder's priority, so the
    // floor's sender waits for the scheduler no more than the bridge's does.
    let main_fifo = forwarder_priority > 0 && hal::rt::set_fifo_priority(forwarder_priority);

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

    eprintln!(
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
            eprintln!(
                "bench: {} of {total} triggers, {:.0} s",
                k + 1,
                began.elapsed().as_secs_f64()
            );
        }
    }
    let elapsed = began.elapsed();
    let loop_stats = machine.stats();
    machine.shutdown();
    drop(machine);
    drop(sim);

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
    let records = ReceiveTimes::read(&times_file)
        .map_err(|e| format!("{e} (estimator log: {})", estimator_log.display()))?;
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
    let mut floor_ns = Vec::with_capacity(floor_seqs.len());
    let mut lost_floor = 0u64;
    for seq in &floor_seqs {
        match by_key.get(&(FLOOR_RUN, *seq)) {
            Some(r) => floor_ns.push(r.t1_ns.saturating_sub(r.trigger_ns)),
            None => lost_floor += 1,
        }
    }
    let _ = std::fs::remove_dir_all(&work);

    let (Some(trig), Some(fl)) = (Summary::of(&trigger), Summary::of(&floor_ns)) else {
        return Err("no trigger or floor sample reached the estimator".into());
    };
    let bus_hop = Summary::of(&to_rt);
    let ipc_hop = Summary::of(&rt_to_estimator);
    let stop = Summary::of(&stop_ns);
    let mut cycles_sorted = stop_cycles.clone();
    cycles_sorted.sort_unstable();
    let ratio_p50 = trig.p50_us / fl.p50_us;
    let ratio_p99 = trig.p99_us / fl.p99_us;
    let sink_name = if args.direct {
        "ContactPublisher in the real-time thread (--direct)"
    } else {
        "ForwardingSink (forwarder thread publishes)"
    };
    let bus_name = args.can.clone().unwrap_or_else(|| "in-process".to_string());
    let targets = json!({
        "p99_le_20us": trig.p99_us <= 20.0,
        "p99_9_le_50us": trig.p999_us <= 50.0,
        "p50_within_2x_floor": ratio_p50 <= 2.0,
    });

    println!(
        "probebridge bench trigger: {} triggers ({} warm-up not counted) in {:.1} s; SYNC {} us; {} bus; sink: {}",
        args.triggers,
        warmup,
        elapsed.as_secs_f64(),
        args.period_us,
        bus_name,
        sink_name
    );
    let granted = |b: bool| if b { "granted" } else { "NOT granted" };
    let cpuidle = hal::rt::cpuidle_driver();
    println!(
        "SCHED_FIFO: real-time loop {} (priority {}), simulated drives {} ({}), {}, {}; memory {}; CPU wake-up latency {} (cpuidle driver: {}); {} CPUs",
        granted(startup.realtime_priority),
        args.rt_priority,
        granted(sim_fifo),
        drive_priority,
        if args.direct {
            "no forwarder (--direct)".to_string()
        } else {
            format!("forwarder {} ({forwarder_priority})", granted(forwarder_fifo))
        },
        if args.estimator_priority > 0 {
            format!(
                "estimator {} ({})",
                granted(estimator_fifo),
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
        cpuidle.as_deref().unwrap_or("not reported"),
        std::thread::available_parallelism().map_or(0, |n| n.get())
    );
    for n in &notes {
        println!("note: {n}");
    }
    println!();
    println!("{:<44}{}", "", Summary::HEADER);
    println!(
        "{:<44}{}",
        "trigger -> estimator (latch t0 to t1)",
        trig.row()
    );
    if let Some(s) = bus_hop {
        println!(
            "{:<44}{}",
            "  latch -> real-time loop has the frame",
            s.row()
        );
    }
    if let Some(s) = ipc_hop {
        println!("{:<44}{}", "  real-time loop -> estimator", s.row());
    }
    println!(
        "{:<44}{}",
        "floor: bare iceoryx2 hop, same processes",
        fl.row()
    );
    if let Some(s) = stop {
        println!(
            "{:<44}{}",
            "stop: latch frame in -> stop setpoint sent",
            s.row()
        );
    }
    println!();
    println!(
        "ratio to the floor: p50 {ratio_p50:.2}x, p99 {ratio_p99:.2}x; stop latency {} .. {} cycle(s) (p50 {})",
        cycles_sorted.first().copied().unwrap_or(0),
        cycles_sorted.last().copied().unwrap_or(0),
        bench::percentile(&cycles_sorted, 50.0)
    );
    println!(
        "targets: p99 <= 20 us: {}; p99.9 <= 50 us: {}; p50 within 2x the floor: {}",
        yes_no(trig.p99_us <= 20.0),
        yes_no(trig.p999_us <= 50.0),
        yes_no(ratio_p50 <= 2.0)
    );
    let anomalies = lost_triggers + lost_floor + missing_t0 + loop_stats.publish_failures;
    if anomalies > 0 || loop_stats.late_cycles > 0 || loop_stats.skipped_cycles > 0 {
        println!(
            "lost: {lost_triggers} trigger and {lost_floor} floor samples; {missing_t0} triggers without t0; {} publish failures; {} late cycles, {} SYNC slots skipped after stalls",
            loop_stats.publish_failures, loop_stats.late_cycles, loop_stats.skipped_cycles
        );
    }

    if let Some(path) = &args.json {
        let doc = json!({
            "benchmark": "trigger",
            "triggers": args.triggers,
            "warmup": warmup,
            "period_us": args.period_us,
            "bus": bus_name,
            "sink": if args.direct { "direct" } else { "forwarding" },
            "elapsed_s": elapsed.as_secs_f64(),
            "cpus": std::thread::available_parallelism().map_or(0, |n| n.get()),
            "realtime": {
                "sched_fifo": startup.realtime_priority,
                "priority": args.rt_priority,
                "simulated_drives_sched_fifo": sim_fifo,
                "forwarder_sched_fifo": forwarder_fifo,
                "estimator_priority": args.estimator_priority,
                "estimator_sched_fifo": estimator_fifo,
                "simulated_drives_priority": drive_priority,
                "floor_sender_sched_fifo": main_fifo,
                "memory_locked": startup.memory_locked,
                "cpu_latency_held": startup.cpu_latency_held,
                "cpuidle_driver": cpuidle,
                "notes": notes,
            },
            "trigger_latency_us": trig.to_json(),
            "latch_to_rt_us": bus_hop.map(Summary::to_json),
            "rt_to_estimator_us": ipc_hop.map(Summary::to_json),
            "floor_us": fl.to_json(),
            "ratio_to_floor": { "p50": ratio_p50, "p99": ratio_p99 },
            "stop_latency": {
                "us": stop.map(Summary::to_json),
                "cycles": {
                    "min": cycles_sorted.first(),
                    "p50": bench::percentile(&cycles_sorted, 50.0),
                    "max": cycles_sorted.last(),
                },
            },
            "lost": {
                "trigger_samples": lost_triggers,
                "floor_samples": lost_floor,
                "triggers_without_t0": missing_t0,
                "publish_failures": loop_stats.publish_failures,
            },
            "late_cycles": loop_stats.late_cycles,
            "skipped_cycles": loop_stats.skipped_cycles,
            "targets": targets,
        });
        crate::output::write_json(path, &doc)?;
    }
    Ok(())
}

fn yes_no(ok: bool) -> &'static str {
    if ok {
        "met"
    } else {
        "MISSED"
    }
}
