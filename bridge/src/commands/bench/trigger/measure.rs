//! The triggers with the floors between them, the hot floors after, and their
//! latencies matched with the estimators' receive times.

use super::options::BenchArgs;
use super::rig::Rig;
use super::run_id::{FLOOR_RUN, HOT_RUN, TRIGGER_RUN};
use crate::bench::{self};
use crate::estimator::ReceiveTime;
use crate::ipc::ContactPublisher;
use hal::master::LoopStats;
use hal::{AxisPositions, ContactSample, Machine, ProbeMove};
use std::collections::HashMap;
use std::time::{Duration, Instant};

/// Spacing of the hot iceoryx2 hops: the floors' estimator is still awake.
const HOT_SPACING: Duration = Duration::from_micros(50);
/// The timer floor's sleep: about one frame's wire time at 1 Mbit/s, as long as the
/// real-time thread waits between two frames of a cycle on the in-process bus.
const TIMER_SLEEP: Duration = Duration::from_micros(125);

/// What the trigger loop recorded.
pub(super) struct Measured {
    /// Sequence of each measured contact -> its t0.
    pub(super) t0_of: HashMap<u64, u64>,
    /// Sequences of the cold iceoryx2 floor hops (one per measured trigger).
    pub(super) floor_seqs: Vec<u64>,
    /// Sequences of the hot iceoryx2 floor hops.
    pub(super) hot_seqs: Vec<u64>,
    /// The cold eventfd pings, one per measured trigger, ns.
    pub(super) cold_wakeup_ns: Vec<u64>,
    /// Why the cold eventfd floor is missing, if it is.
    pub(super) cold_wakeup_error: Option<String>,
    /// The timer floor, one per measured trigger: how late a timed wait ran, ns.
    pub(super) cold_timer_ns: Vec<u64>,
    pub(super) cold_timer_error: Option<String>,
    pub(super) stop_ns: Vec<u64>,
    pub(super) stop_cycles: Vec<u64>,
    pub(super) missing_t0: u64,
    pub(super) elapsed: Duration,
    pub(super) loop_stats: LoopStats,
    /// The host's wake-up back to back (hot; `Err`: could not be measured, and why).
    pub(super) wakeup: Result<bench::wakeup::Wakeup, String>,
}

/// The latencies, matched with the estimators' receive times.
pub(super) struct Latencies {
    pub(super) trigger: Vec<u64>,
    pub(super) to_rt: Vec<u64>,
    pub(super) rt_to_estimator: Vec<u64>,
    /// The software path's two stages: to the publisher's send, and from it on.
    pub(super) rt_to_published: Vec<u64>,
    pub(super) published_to_estimator: Vec<u64>,
    pub(super) floor: Vec<u64>,
    pub(super) floor_hot: Vec<u64>,
    pub(super) lost_triggers: u64,
    pub(super) lost_floor: u64,
}

/// Per measured trigger, filled by the loop.
#[derive(Default)]
struct Records {
    t0_of: HashMap<u64, u64>,
    floor_seqs: Vec<u64>,
    cold_wakeup_ns: Vec<u64>,
    cold_wakeup_error: Option<String>,
    cold_timer_ns: Vec<u64>,
    cold_timer_error: Option<String>,
    stop_ns: Vec<u64>,
    stop_cycles: Vec<u64>,
    missing_t0: u64,
}

/// The triggers: probe, retract, the two cold floors; `warmup` first, not counted.
/// Then the hot floors.
pub(super) fn measure(
    args: &BenchArgs,
    rig: Rig,
    warmup: u64,
    total: u64,
) -> Result<(Measured, Rig), String> {
    let mut rig = rig;
    let start = AxisPositions::linear([
        bench::START_XY[0],
        bench::START_XY[1],
        bench::TOUCH_Z + bench::GAP,
    ]);
    rig.machine
        .move_to(&start, 5000.0)
        .map_err(|e| format!("moving to the start: {e}"))?;
    tell!(
        "bench: {warmup} warm-up + {} measured triggers ...",
        args.triggers
    );
    let mut rec = Records {
        t0_of: HashMap::with_capacity(total as usize),
        ..Records::default()
    };
    let began = Instant::now();
    let mut last_report = Instant::now();
    for k in 0..total {
        let sequence = trigger(&mut rig, k >= warmup, &mut rec)
            .map_err(|e| format!("trigger {}: {e}", k + 1))?;
        rig.machine
            .move_to(&start, 5000.0)
            .map_err(|e| format!("retract after trigger {}: {e}", k + 1))?;
        cold_floors(&mut rig, sequence, k >= warmup, &mut rec)?;
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
    let loop_stats = rig.machine.stats();
    rig.machine.shutdown();
    drop(rig.sim.take());
    tell!("bench: the hot floors (back to back) ...");
    let hot_seqs = hot_hops(&mut rig.floor, args.triggers, total)?;
    let pings = args.triggers as usize;
    let wakeup = bench::wakeup::measure(pings, warmup as usize, args.estimator_priority.max(0));
    Ok((
        Measured {
            t0_of: rec.t0_of,
            floor_seqs: rec.floor_seqs,
            hot_seqs,
            cold_wakeup_ns: rec.cold_wakeup_ns,
            cold_wakeup_error: rec.cold_wakeup_error,
            cold_timer_ns: rec.cold_timer_ns,
            cold_timer_error: rec.cold_timer_error,
            stop_ns: rec.stop_ns,
            stop_cycles: rec.stop_cycles,
            missing_t0: rec.missing_t0,
            elapsed,
            loop_stats,
            wakeup,
        },
        rig,
    ))
}

/// One probing move; records its t0 and stop when `measured`. Returns the contact's
/// sequence.
fn trigger(rig: &mut Rig, measured: bool, rec: &mut Records) -> Result<u64, String> {
    let probe = ProbeMove {
        direction: [0.0, 0.0, -1.0],
        feed: bench::FEED,
        max_distance: bench::DISTANCE,
    };
    let before = rig.latches.count();
    let contact = rig.machine.probe(&probe).map_err(|e| e.to_string())?;
    if measured {
        let t0 = (rig.latches.count() == before + 1)
            .then(|| rig.latches.get(before))
            .flatten();
        match t0 {
            Some(t0) => {
                rec.t0_of.insert(contact.sequence, t0);
            }
            None => rec.missing_t0 += 1,
        }
        let s = rig.machine.stats();
        rec.stop_ns.push(s.last_stop_latency_ns);
        rec.stop_cycles.push(s.last_stop_latency_cycles);
    }
    Ok(contact.sequence)
}

/// The floors in the trigger's regime: one timed wait at the real-time loop's
/// priority, one eventfd ping to the partner, one bare iceoryx2 hop to the floors'
/// estimator. The last two slept since the previous trigger, as the estimator did.
fn cold_floors(
    rig: &mut Rig,
    sequence: u64,
    measured: bool,
    rec: &mut Records,
) -> Result<(), String> {
    match &mut rig.timer {
        Ok(t) => match t.sample(TIMER_SLEEP) {
            Some(ns) if measured => rec.cold_timer_ns.push(ns),
            Some(_) => {}
            None => rec.cold_timer_error = Some("the timer thread stopped answering".into()),
        },
        Err(e) => rec.cold_timer_error = Some(e.clone()),
    }
    match &mut rig.pinger {
        Ok(p) => match p.ping() {
            Some(ns) if measured => rec.cold_wakeup_ns.push(ns),
            Some(_) => {}
            None => rec.cold_wakeup_error = Some("the partner stopped answering".into()),
        },
        Err(e) => rec.cold_wakeup_error = Some(e.clone()),
    }
    send_floor(&mut rig.floor, FLOOR_RUN, sequence)?;
    if measured {
        rec.floor_seqs.push(sequence);
    }
    Ok(())
}

/// The same payload, this process -> the floors' estimator, nothing between; t0 in
/// `trigger_ns`, taken right before the send.
fn send_floor(floor: &mut ContactPublisher, run_id: u64, sequence: u64) -> Result<(), String> {
    let mut sample = ContactSample::zeroed();
    sample.sequence = sequence;
    sample.run_id = run_id;
    sample.trigger_ns = hal::clock::monotonic_ns();
    floor
        .send(&sample)
        .map(|_| ())
        .map_err(|_| "the floor sample could not be published".to_string())
}

/// `count` iceoryx2 hops [`HOT_SPACING`] apart (after a warm-up): the receiver is
/// awake. Returns the measured sequences.
fn hot_hops(floor: &mut ContactPublisher, count: u64, total: u64) -> Result<Vec<u64>, String> {
    let warmup = total - count;
    let mut seqs = Vec::with_capacity(count as usize);
    for i in 0..total {
        let next = Instant::now() + HOT_SPACING;
        send_floor(floor, HOT_RUN, i)?;
        if i >= warmup {
            seqs.push(i);
        }
        while Instant::now() < next {
            core::hint::spin_loop();
        }
    }
    Ok(seqs)
}

/// Each measured trigger matched with the estimator's record of it, each floor hop
/// with the floors' estimator's.
pub(super) fn match_records(
    m: &Measured,
    records: &[ReceiveTime],
    floor_records: &[ReceiveTime],
) -> Latencies {
    let t0_of = &m.t0_of;
    let by_key: HashMap<(u64, u64), ReceiveTime> = records
        .iter()
        .map(|r| ((r.run_id, r.sequence), *r))
        .collect();
    let mut trigger = Vec::with_capacity(t0_of.len());
    let mut to_rt = Vec::with_capacity(t0_of.len());
    let mut rt_to_estimator = Vec::with_capacity(t0_of.len());
    let mut rt_to_published = Vec::with_capacity(t0_of.len());
    let mut published_to_estimator = Vec::with_capacity(t0_of.len());
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
                rt_to_published.push(r.publish_ns.saturating_sub(r.receive_ns));
                published_to_estimator.push(r.t1_ns.saturating_sub(r.publish_ns));
            }
            None => lost_triggers += 1,
        }
    }
    let floors: HashMap<(u64, u64), ReceiveTime> = floor_records
        .iter()
        .map(|r| ((r.run_id, r.sequence), *r))
        .collect();
    let hop = |run: u64, seqs: &[u64], lost: &mut u64| -> Vec<u64> {
        let mut out = Vec::with_capacity(seqs.len());
        for seq in seqs {
            match floors.get(&(run, *seq)) {
                Some(r) => out.push(r.t1_ns.saturating_sub(r.trigger_ns)),
                None => *lost += 1,
            }
        }
        out
    };
    let mut lost_floor = 0u64;
    let floor = hop(FLOOR_RUN, &m.floor_seqs, &mut lost_floor);
    let floor_hot = hop(HOT_RUN, &m.hot_seqs, &mut lost_floor);
    Latencies {
        trigger,
        to_rt,
        rt_to_estimator,
        rt_to_published,
        published_to_estimator,
        floor,
        floor_hot,
        lost_triggers,
        lost_floor,
    }
}
