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
//! and locked memory where permitted), the sink the bridge uses (`ContactPublisher`,
//! called in the real-time thread: one hop), the estimator as a child process
//! (`probebridge estimator --record-times FILE --armed-receive auto|off`). The drives
//! are the simulator in this process (the in-process bus, or a second socket on
//! `--can IFACE`), which records t0 in a lock-free ring (`sim::machine::LatchLog`).
//!
//! The floors are taken in the trigger's own regime, interleaved with the triggers:
//! after each trigger, one cold eventfd ping to a forked process that has slept since
//! the previous trigger ([`crate::bench::wakeup::Pinger`]), and one bare iceoryx2 hop
//! (`ContactPublisher` in this process, same payload and services) to a second
//! estimator process that has slept as long. Each receiver is woken once per trigger,
//! so all three wake after the same idle gap, at the same priorities. After the
//! triggers, the same two back to back: the hot figures, reported beside them.
//!
//! Both modes of the estimator's receive run, each with its own estimator: armed (it
//! polls during probing moves) and unarmed (it sleeps in the WaitSet throughout).
//!
//! The in-process bus has the machine's bit rate (wire time, arbitration by id), and
//! the bench refuses a SYNC period whose traffic would load it above the limit. So the
//! report gives the path end to end (latch to estimator, wire time included) and the
//! software path alone (from the last bit of the latch frame, when the real-time loop
//! could first have it, to the estimator), each against the floors, and the stop
//! latency in SYNC cycles.

mod measure;
mod options;
mod report;
mod rig;
mod run_id;
mod stats;

use super::{collect_records, Workspace};
use crate::estimator::ArmedReceive;
use hal::config::MachineConfig;
use measure::{match_records, measure};
pub use options::{BenchArgs, Modes};
use report::Report;
use rig::{bench_machine, start_rig};
use sim::Scenario;

pub fn run(args: &BenchArgs) -> Result<(), String> {
    if args.triggers == 0 {
        return Err("--triggers must be at least 1".into());
    }
    crate::output::check_output(args.json.as_deref())?;
    let (scenario, cfg, notes) = bench_machine(args)?;
    // From here on the period is the one the machine runs.
    let args = &BenchArgs {
        period_us: cfg.canopen_bus().map(|b| b.sync_period_us),
        ..args.clone()
    };
    let mut docs = Vec::new();
    for &mode in args.modes.list() {
        let report = run_mode(args, mode, &scenario, &cfg, notes.clone())?;
        docs.push(report.print()?);
    }
    if let Some(path) = &args.json {
        let doc = match <[serde_json::Value; 1]>::try_from(docs) {
            Ok([one]) => one,
            Err(docs) => serde_json::json!({ "benchmark": "trigger", "modes": docs }),
        };
        crate::output::write_json(path, &doc)?;
    }
    Ok(())
}

/// One run: a rig with its estimator receiving in `mode`, the triggers with the
/// floors between them, the hot floors after.
fn run_mode(
    args: &BenchArgs,
    mode: ArmedReceive,
    scenario: &Scenario,
    cfg: &MachineConfig,
    mut notes: Vec<String>,
) -> Result<Report, String> {
    let warmup = args.warmup.unwrap_or((args.triggers / 10).clamp(1, 100));
    let total = warmup + args.triggers;
    let pid = std::process::id();
    let ws = Workspace::new(format!("probebridge-bench-{pid}-{}", mode.as_str()))?;
    let floor_ws = Workspace::new(format!("probebridge-bench-{pid}-{}-floor", mode.as_str()))?;
    let rig = start_rig(args, mode, (&ws, &floor_ws), scenario, cfg, total)?;
    notes.extend(rig.startup.notes.iter().cloned());
    let (measured, rig) = measure(args, rig, warmup, total)?;
    let records = collect_records(rig.estimator, &ws)?;
    let floor_records = collect_records(rig.floor_estimator, &floor_ws)?;
    let latencies = match_records(&measured, &records, &floor_records);
    let armed = armed_in_log(&ws.estimator_log);
    let _ = std::fs::remove_dir_all(&ws.dir);
    let _ = std::fs::remove_dir_all(&floor_ws.dir);
    Ok(Report {
        args: args.clone(),
        mode,
        armed,
        warmup,
        notes,
        startup: rig.startup,
        sim_fifo: rig.sim_fifo,
        drive_priority: rig.drive_priority,
        sender_priority: rig.sender_priority,
        estimator_fifo: rig.estimator_fifo,
        main_fifo: rig.main_fifo,
        measured,
        latencies,
    })
}

/// Whether the estimator armed its receive, from its log (`None`: it did not say).
fn armed_in_log(log: &std::path::Path) -> Option<String> {
    let text = std::fs::read_to_string(log).ok()?;
    text.lines()
        .find_map(|l| l.strip_prefix("estimator: armed receive "))
        .map(str::to_string)
}
