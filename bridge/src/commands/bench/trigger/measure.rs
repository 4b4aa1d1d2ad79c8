//! The triggers and the floor samples, and their latencies matched with the
//! estimator's receive times.

use super::rig::Rig;
use super::{BenchArgs, FLOOR_RUN, TRIGGER_RUN};
use crate::bench::{self};
use crate::estimator::ReceiveTime;
use hal::master::LoopStats;
use hal::{AxisPositions, ContactSample, Machine, ProbeMove};
use std::collections::HashMap;
use std::time::{Duration, Instant};

/// What the trigger loop recorded.
pub(super) struct Measured {
    /// Sequence of each measured contact -> its t0.
    pub(super) t0_of: HashMap<u64, u64>,
    pub(super) floor_seqs: Vec<u64>,
    pub(super) stop_ns: Vec<u64>,
    pub(super) stop_cycles: Vec<u64>,
    pub(super) missing_t0: u64,
    pub(super) elapsed: Duration,
    pub(super) loop_stats: LoopStats,
    /// The host's cross-CPU wake-up floor (`None`: could not be measured, and why).
    pub(super) wakeup: Result<bench::wakeup::Wakeup, String>,
}

/// The latencies, matched with the estimator's receive times.
pub(super) struct Latencies {
    pub(super) trigger: Vec<u64>,
    pub(super) to_rt: Vec<u64>,
    pub(super) rt_to_estimator: Vec<u64>,
    pub(super) floor: Vec<u64>,
    pub(super) lost_triggers: u64,
    pub(super) lost_floor: u64,
}

/// The triggers: probe, the floor sample, retract; `warmup` first, not counted.
pub(super) fn measure(
    args: &BenchArgs,
    rig: Rig,
    warmup: u64,
    total: u64,
) -> Result<(Measured, Rig), String> {
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

/// Each measured trigger and floor sample matched with the estimator's record of it.
pub(super) fn match_records(m: &Measured, records: &[ReceiveTime]) -> Latencies {
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
