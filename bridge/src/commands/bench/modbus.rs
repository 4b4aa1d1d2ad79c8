//! `probebridge bench trigger --modbus`: latch to estimator over Modbus TCP on loopback.
//!
//! ```text
//!  simulated PLC ──latch ring──> ModbusMachine ──ContactSample──> estimator process
//!  (t0: CLOCK_MONOTONIC   (status polled   (ContactPublisher,      (t1: CLOCK_MONOTONIC
//!   when the PLC latches)  every poll_ms)   iceoryx2)               when it has it)
//! ```
//!
//! The PLC (this process, real-time pacing at `--period-us`) has already stopped the
//! axes on the latch; what this measures is when the estimator has the contact: the
//! status poll period, two requests (status, ring), the acknowledge and the IPC hop. The
//! contact's accuracy comes from the PLC's capture, not from this latency.

use crate::bench::{self, Summary};
use crate::configs;
use crate::estimator::ReceiveTime;
use crate::ipc::{ContactPublisher, EstimatorChild};
use hal::config::BusConfig;
use hal::modbus::{ModbusBusConfig, ModbusMachine, ModbusOptions};
use hal::{AxisPositions, Machine, ProbeMove};
use serde_json::json;
use sim::machine::LatchLog;
use sim::plc::{PlcPacing, PlcProgram, SimPlc};
use sim::Scenario;
use std::collections::HashMap;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const TRIGGER_RUN: u64 = 1;

pub struct ModbusBenchArgs {
    pub triggers: u64,
    pub warmup: Option<u64>,
    /// The PLC task cycle, µs.
    pub plc_cycle_us: u32,
    /// The bridge's status poll period, ms.
    pub poll_ms: u32,
    pub json: Option<PathBuf>,
}

fn start_estimator(
    prefix: &str,
    times: &std::path::Path,
    log: &std::path::Path,
    capacity: u64,
) -> Result<EstimatorChild, String> {
    let mut command = Command::new(std::env::current_exe().map_err(|e| e.to_string())?);
    command.args(["estimator", "--service", prefix, "--record-times"]);
    command.arg(times);
    command.args(["--record-capacity", &capacity.to_string()]);
    let log = std::fs::File::create(log).map_err(|e| format!("{}: {e}", log.display()))?;
    command.stderr(Stdio::from(log));
    EstimatorChild::spawn_command(command, prefix, crate::ipc::START_TIMEOUT)
        .map_err(|e| format!("cannot start the estimator: {e}"))
}

pub fn run(args: &ModbusBenchArgs) -> Result<(), String> {
    if args.triggers == 0 {
        return Err("--triggers must be at least 1".into());
    }
    let warmup = args.warmup.unwrap_or((args.triggers / 10).clamp(1, 100));
    let total = warmup + args.triggers;
    let ws = super::Workspace::new(format!("probebridge-bench-modbus-{}", std::process::id()))?;

    let mut scenario = Scenario::parse(
        bench::SCENARIO,
        &configs::configs_dir().join("scenarios/bench-trigger.toml"),
        Some(&configs::machines_dir()),
    )
    .map_err(|e| e.to_string())?;
    // Short moves of a few µm are acceleration-bound (the same stiff machine as the
    // CANopen bench).
    for a in &mut scenario.machine.axes {
        a.max_acceleration = a.max_acceleration.max(bench::ACCELERATION);
    }
    let mut bus = ModbusBusConfig::tcp("127.0.0.1:0");
    bus.plc_cycle_us = args.plc_cycle_us;
    bus.poll_ms = args.poll_ms;
    bus.validate()
        .map_err(|e| format!("{}: {}", e.key, e.reason))?;

    tell!("bench: starting the estimator process ...");
    let estimator = start_estimator(
        &ws.prefix,
        &ws.times_file,
        &ws.estimator_log,
        2 * total + 64,
    )?;
    let latches = LatchLog::new();
    let mut program = PlcProgram::new(&scenario, &bus);
    program.set_latch_log(latches.clone());
    let plc = SimPlc::serve_tcp(
        program,
        bus.unit,
        "127.0.0.1:0".parse().expect("loopback address"),
        PlcPacing::RealTime,
    )
    .map_err(|e| format!("simulated PLC: {e}"))?;
    bus.address = plc.local_addr().map(|a| a.to_string());
    let mut cfg = crate::session::machine_config(&scenario);
    cfg.bus = BusConfig::Modbus(bus.clone());
    cfg.spindle = None;
    let sink = ContactPublisher::new(&ws.prefix).map_err(|e| e.to_string())?;
    sink.update_connections().map_err(|e| e.to_string())?;
    let options = ModbusOptions {
        run_id: TRIGGER_RUN,
        ..ModbusOptions::default()
    };
    let mut machine = ModbusMachine::start(&cfg, sink, options).map_err(|e| e.to_string())?;
    tell!(
        "bench: {warmup} warm-up + {} measured triggers over Modbus TCP {} ...",
        args.triggers,
        bus.address.as_deref().unwrap_or("?")
    );
    let began = Instant::now();
    let (t0_of, missing_t0) = triggers(&mut machine, &latches, warmup, total)?;
    let elapsed = began.elapsed();
    let client = machine.client_stats();
    let latch_stats = machine.latch_stats();
    drop(machine);
    drop(plc);

    let records = super::collect_records(estimator, &ws)?;
    let by_key: HashMap<(u64, u64), ReceiveTime> = records
        .iter()
        .map(|r| ((r.run_id, r.sequence), *r))
        .collect();
    let _ = std::fs::remove_dir_all(&ws.dir);
    let (mut trigger, mut to_bridge, mut to_estimator) = (Vec::new(), Vec::new(), Vec::new());
    let mut lost = 0u64;
    let mut seqs: Vec<&u64> = t0_of.keys().collect();
    seqs.sort_unstable();
    for seq in seqs {
        let t0 = t0_of[seq];
        match by_key.get(&(TRIGGER_RUN, *seq)) {
            Some(r) => {
                trigger.push(r.t1_ns.saturating_sub(t0));
                to_bridge.push(r.receive_ns.saturating_sub(t0));
                to_estimator.push(r.t1_ns.saturating_sub(r.receive_ns));
            }
            None => lost += 1,
        }
    }
    report(
        args,
        warmup,
        elapsed,
        &Hops {
            trigger,
            to_bridge,
            to_estimator,
            lost,
            missing_t0,
        },
        &client,
        &latch_stats,
    )
}

/// Runs `total` probing moves from just above the face; per measured trigger, its
/// sample sequence and the PLC's latch instant.
fn triggers(
    machine: &mut ModbusMachine,
    latches: &LatchLog,
    warmup: u64,
    total: u64,
) -> Result<(HashMap<u64, u64>, u64), String> {
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
    let mut t0_of = HashMap::with_capacity(total as usize);
    let mut missing_t0 = 0u64;
    for k in 0..total {
        let before = latches.count();
        let contact = machine
            .probe(&probe)
            .map_err(|e| format!("trigger {}: {e}", k + 1))?;
        let t0 = (latches.count() == before + 1)
            .then(|| latches.get(before))
            .flatten();
        if k >= warmup {
            match t0 {
                Some(t0) => {
                    t0_of.insert(contact.sequence, t0);
                }
                None => missing_t0 += 1,
            }
        }
        machine
            .move_to(&start, 5000.0)
            .map_err(|e| format!("retract after trigger {}: {e}", k + 1))?;
    }
    Ok((t0_of, missing_t0))
}

struct Hops {
    trigger: Vec<u64>,
    to_bridge: Vec<u64>,
    to_estimator: Vec<u64>,
    lost: u64,
    missing_t0: u64,
}

fn report(
    args: &ModbusBenchArgs,
    warmup: u64,
    elapsed: Duration,
    hops: &Hops,
    client: &hal::modbus::client::ClientStats,
    latch_stats: &hal::modbus::machine::LatchStats,
) -> Result<(), String> {
    let Hops {
        trigger,
        to_bridge,
        to_estimator,
        lost,
        missing_t0,
    } = hops;
    let Some(trig) = Summary::of(trigger) else {
        return Err("no trigger sample reached the estimator".into());
    };
    say!(
        "probebridge bench trigger --modbus: {} triggers ({warmup} warm-up not counted) in {:.1} s; \
         simulated PLC on Modbus TCP loopback, PLC cycle {} us, status poll {} ms; sink: ContactPublisher (one hop)",
        args.triggers,
        elapsed.as_secs_f64(),
        args.plc_cycle_us,
        args.poll_ms
    );
    say!();
    say!("{:<44}{}", "", Summary::HEADER);
    say!(
        "{:<44}{}",
        "trigger -> estimator (PLC latch t0 to t1)",
        trig.row()
    );
    let hop = Summary::of(to_bridge);
    if let Some(s) = hop {
        say!("{:<44}{}", "  PLC latch -> bridge has the contact", s.row());
    }
    let ipc = Summary::of(to_estimator);
    if let Some(s) = ipc {
        say!("{:<44}{}", "  bridge -> estimator", s.row());
    }
    say!(
        "lost: {lost} samples, {missing_t0} triggers without t0; latch ring: {} contacts, {} discarded, {} lost; \
         Modbus: {} requests, {} timeouts, {} reconnects",
        latch_stats.contacts,
        latch_stats.discarded,
        latch_stats.lost,
        client.requests,
        client.timeouts,
        client.reconnects
    );
    // The path's own floor: a latch waits up to one PLC task cycle to be seen and up to
    // one status poll to be read.
    let floor_us = args.plc_cycle_us as f64 + args.poll_ms as f64 * 1000.0;
    say!(
        "floor: PLC task cycle + status poll = {floor_us:.0} us; trigger -> estimator vs the floor: p50 {:.2}x, p99 {:.2}x",
        trig.p50_us / floor_us,
        trig.p99_us / floor_us
    );
    say!("the axes stop in the PLC on its latch; this latency is when the estimator has the contact, not its accuracy");
    if let Some(path) = &args.json {
        let v = json!({
            "bus": "modbus-tcp-loopback",
            "triggers": args.triggers,
            "warmup": warmup,
            "plc_cycle_us": args.plc_cycle_us,
            "poll_ms": args.poll_ms,
            "trigger_to_estimator": trig.to_json(),
            "floor_us": floor_us,
            "trigger_vs_floor": {
                "p50_ratio": trig.p50_us / floor_us,
                "p99_ratio": trig.p99_us / floor_us,
            },
            "latch_to_bridge": hop.map(Summary::to_json),
            "bridge_to_estimator": ipc.map(Summary::to_json),
            "lost_samples": lost,
            "missing_t0": missing_t0,
            "modbus_requests": client.requests,
            "modbus_timeouts": client.timeouts,
        });
        crate::output::write_json(path, &v)?;
    }
    Ok(())
}
