//! The rig of a run: the bench machine, the estimator process and the floors' second
//! estimator, the simulated drives, the bridge's `CanMachine` with its sink, the
//! floors' publisher and eventfd partner.

use super::options::BenchArgs;
use super::run_id::TRIGGER_RUN;
use crate::bench::{self};
use crate::commands::bench::Workspace;
use crate::commands::estimator::DEFAULT_RECORD_CAPACITY;
use crate::configs;
use crate::estimator::ArmedReceive;
use crate::ipc::{ContactPublisher, EstimatorChild};
use hal::can::inproc::{InprocBus, WireClock};
use hal::can::socketcan::SocketCanTransport;
use hal::can::CanTransport;
use hal::config::MachineConfig;
use hal::master::{BusLoad, CanMachine, MasterOptions, Pacing, StartupReport};
use sim::machine::{LatchLog, SimClock, SimMachine, SimRunner};
use sim::Scenario;
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::time::Duration;

/// Whether process `pid` runs under SCHED_FIFO (field 41 of /proc/PID/stat).
pub(super) fn is_fifo(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .ok()
        .and_then(|s| {
            // The command name (field 2) may hold spaces: count after its ')'.
            let rest = &s[s.rfind(')')? + 2..];
            rest.split_whitespace().nth(38)?.parse::<u32>().ok()
        })
        == Some(1)
}

/// The processes and threads of one run, and which real-time settings they got.
pub(super) struct Rig {
    pub(super) estimator: EstimatorChild,
    pub(super) estimator_fifo: bool,
    /// The floors' receiver: an estimator that never arms, on its own services.
    pub(super) floor_estimator: EstimatorChild,
    /// The simulated drives; taken and stopped once the machine has shut down.
    pub(super) sim: Option<SimRunner>,
    pub(super) sim_fifo: bool,
    pub(super) drive_priority: i32,
    /// This thread's priority: it sends the floors.
    pub(super) sender_priority: i32,
    pub(super) machine: CanMachine,
    pub(super) startup: StartupReport,
    pub(super) floor: ContactPublisher,
    /// The cold eventfd floor's partner process, asleep between triggers.
    pub(super) pinger: Result<bench::wakeup::Pinger, String>,
    /// The timer wake-up floor, at the real-time loop's priority.
    pub(super) timer: Result<bench::timer_wakeup::TimerFloor, String>,
    /// This thread (the floor's sender) under SCHED_FIFO.
    pub(super) main_fifo: bool,
    pub(super) latches: Arc<LatchLog>,
}

/// The machine: table-ac with a flat face, SYNC at the requested period; notes for
/// the report.
pub(super) fn bench_machine(
    args: &BenchArgs,
) -> Result<(Scenario, MachineConfig, Vec<String>), String> {
    let scenario_path = configs::configs_dir().join("scenarios/bench-trigger.toml");
    let mut scenario = Scenario::parse(
        bench::SCENARIO,
        &scenario_path,
        Some(&configs::machines_dir()),
    )
    .map_err(|e| e.to_string())?;
    // The trigger path of the five axes' drives, as docs/benchmark.md measures it: the
    // spindle's drive (idle while probing) stays off the bus.
    scenario.machine.spindle = None;
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

/// The CPU the bench pins the real-time loop to: [`hal::rt::realtime_cpu_of`] the
/// process as it started (taken once: the floors' sender is pinned to it afterwards,
/// and a second mode must find the same layout).
pub(super) fn bench_rt_cpu() -> Option<usize> {
    bench_cpus().map(|(rt, _)| rt)
}

/// The real-time loop's CPU and another (the estimators'), taken once as for
/// [`bench_rt_cpu`].
fn bench_cpus() -> Option<(usize, usize)> {
    static CPUS: std::sync::OnceLock<Option<(usize, usize)>> = std::sync::OnceLock::new();
    *CPUS.get_or_init(|| {
        let allowed = hal::rt::allowed_cpus();
        let rt = hal::rt::realtime_cpu_of(&allowed)?;
        Some((rt, allowed.into_iter().find(|&c| c != rt)?))
    })
}

/// The estimator process (under SCHED_FIFO when asked) recording receive times;
/// whether it got SCHED_FIFO.
pub(super) fn spawn_estimator(
    args: &BenchArgs,
    ws: &Workspace,
    mode: ArmedReceive,
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
        "--armed-receive",
        mode.as_str(),
    ]);
    if let Some(rt) = bench_rt_cpu() {
        command.args(["--avoid-cpu", &rt.to_string()]);
    }
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
    let estimator = EstimatorChild::spawn_command(command, prefix, crate::ipc::START_TIMEOUT)
        .map_err(|e| format!("cannot start the estimator: {e}"))?;
    let estimator_fifo = args.estimator_priority > 0 && is_fifo(estimator.id());

    Ok((estimator, estimator_fifo))
}

/// The bus between the bridge and the simulated drives: the in-process bus, or two
/// sockets on `--can`.
/// The bridge's end and the drives' end of the bench's bus.
type Ends = (Box<dyn CanTransport>, Box<dyn CanTransport>);

pub(super) fn bench_transports(args: &BenchArgs, bitrate: u32) -> Result<Ends, String> {
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

/// The estimators, the simulated drives, the bridge's sink and `CanMachine`, the
/// floors' publisher and partner; every thread on the measured path under SCHED_FIFO
/// where permitted.
pub(super) fn start_rig(
    args: &BenchArgs,
    mode: ArmedReceive,
    (ws, floor_ws): (&Workspace, &Workspace),
    scenario: &Scenario,
    cfg: &MachineConfig,
    total: u64,
) -> Result<Rig, String> {
    let (estimator, estimator_fifo) = spawn_estimator(args, ws, mode, total)?;
    // The floors' receiver sleeps in the WaitSet like an unarmed estimator.
    let (floor_estimator, _) = spawn_estimator(args, floor_ws, ArmedReceive::Off, 2 * total)?;
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
        // On the real-time loop's CPU: hardware takes no host CPU, and here the drives
        // never take the one the estimator's armed receive spins on.
        if let Some(cpu) = bench_rt_cpu() {
            hal::rt::pin_thread(&[cpu]);
        }
        let _ = sim_fifo_tx.send(drive_priority > 0 && hal::rt::set_fifo_priority(drive_priority));
    });
    let sim_fifo = sim_fifo_rx.recv().unwrap_or(false);
    // One hop: the real-time thread publishes itself.
    let sink = ContactPublisher::new(&ws.prefix).map_err(|e| e.to_string())?;
    sink.update_connections().map_err(|e| e.to_string())?;
    let options = MasterOptions {
        pacing: Pacing::RealTime,
        rt_priority: args.rt_priority,
        run_id: TRIGGER_RUN,
        command_timeout: Duration::from_secs(10),
        abort: None,
        // The loop on its own CPU, the estimators on the others (`--avoid-cpu`).
        rt_cpu: bench_rt_cpu(),
    };
    tell!(
        "bench: bringing up the drives ({} bus, SYNC every {} us; estimator receive {}) ...",
        args.can.as_deref().unwrap_or("in-process"),
        args.period(),
        mode.as_str()
    );
    let (machine, startup) =
        CanMachine::start(cfg, master_transport, sink, options).map_err(|e| e.to_string())?;
    let floor = ContactPublisher::new(&floor_ws.prefix).map_err(|e| e.to_string())?;
    floor.update_connections().map_err(|e| e.to_string())?;
    // The cold eventfd floor on the trigger's CPUs: this thread (the floors' sender)
    // on the real-time loop's, the partner on the estimators'.
    let floor_cpus = bench_cpus().filter(|(rt, _)| startup.rt_cpu == Some(*rt));
    let pinger = bench::wakeup::Pinger::start(args.estimator_priority.max(0), floor_cpus);
    let timer = bench::timer_wakeup::TimerFloor::start(args.rt_priority.max(0), startup.rt_cpu);
    // This thread sends the floors: below the drives, above the estimators.
    let sender_priority = args.rt_priority - 2;
    let main_fifo = sender_priority > 0 && hal::rt::set_fifo_priority(sender_priority);

    Ok(Rig {
        estimator,
        estimator_fifo,
        floor_estimator,
        sim: Some(sim),
        sim_fifo,
        drive_priority,
        sender_priority,
        machine,
        startup,
        floor,
        pinger,
        timer,
        main_fifo,
        latches,
    })
}
