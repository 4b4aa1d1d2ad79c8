//! The CANopen master on an unreliable bus: the seeded fault layer
//! (`hal::can::fault_injection`) between the master and the simulated drives drops,
//! duplicates, delays or reorders frames, or fails the transport. Whatever it does, a
//! cycle either completes with the results of the fault-free run or fails with a
//! clear error; it never returns a wrong result.

use cycles::results::{ProgramReport, Status};
use hal::can::fault_injection::{BusFaults, FaultControl, FaultRates, FaultyTransport};
use hal::can::inproc::InprocBus;
use hal::can::TransportErrorKind;
use hal::master::{CanMachine, MasterOptions, Pacing};
use hal::{Axis, AxisPositions, ContactSample, ErrorKind, Machine, SampleSink, SinkError};
use probebridge_tests::conformance::Held;
use probebridge_tests::{
    configs_dir, machine_config, progress, run_shipped_program, table_ac_plane,
};
use sim::machine::{SimMachine, SimRunner};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// Counts the contacts the master publishes (their sequence numbers).
#[derive(Clone, Default)]
struct Contacts(Arc<Mutex<Vec<u64>>>);

impl SampleSink for Contacts {
    fn publish(&mut self, s: &ContactSample) -> Result<(), SinkError> {
        self.0.lock().unwrap().push(s.sequence);
        Ok(())
    }
}

struct Faulty {
    machine: Held<SimRunner>,
    control: FaultControl,
    contacts: Contacts,
}

/// The master's endpoint behind the fault layer; the drives see and send frames as
/// usual. Lockstep pacing with a short answer timeout: a lost TPDO1 or SYNC costs that
/// much wall time. `Err` when start-up failed (with its error).
fn open(sc: &sim::Scenario, faults: BusFaults) -> Result<Faulty, hal::MachineError> {
    open_with(sc, faults, None)
}

/// As [`open`], with the heartbeat consumer's timeout set (ms).
fn open_with(
    sc: &sim::Scenario,
    faults: BusFaults,
    heartbeat_timeout_ms: Option<u16>,
) -> Result<Faulty, hal::MachineError> {
    let bus = InprocBus::new();
    let sim = SimRunner::spawn(SimMachine::new(sc), bus.endpoint());
    let transport = FaultyTransport::new(bus.endpoint(), faults);
    let control = transport.control();
    let contacts = Contacts::default();
    let options = MasterOptions {
        pacing: Pacing::Lockstep {
            answer_timeout: Duration::from_millis(10),
        },
        ..MasterOptions::default()
    };
    let mut cfg = machine_config(sc);
    if let Some(ms) = heartbeat_timeout_ms {
        cfg.canopen_bus_mut()
            .expect("a CANopen machine")
            .heartbeat_timeout_ms = ms;
    }
    let (machine, _) = CanMachine::start(&cfg, transport, contacts.clone(), options)?;
    Ok(Faulty {
        machine: Held { machine, keep: sim },
        control,
        contacts,
    })
}

fn load(scenario: &str) -> sim::Scenario {
    sim::Scenario::load(
        &configs_dir().join("scenarios").join(scenario),
        Some(&configs_dir().join("machines")),
    )
    .unwrap()
}

/// How a run under faults ended.
#[derive(Debug, PartialEq)]
enum Outcome {
    /// Every result equal to the fault-free run's, bit for bit.
    Identical,
    /// Every result within `TOLERANCE` of the fault-free run's (a lost setpoint in the
    /// very period of a contact moves the path by one step's fraction of a µm).
    Exact,
    /// Failed with this error, before or during a cycle; every result given before it
    /// was exact.
    Failed(String),
}

/// Largest difference of a result from the fault-free run's that still counts as the
/// same measurement (mm, degrees).
const TOLERANCE: f64 = 1e-4;

/// Compares a run under faults with the fault-free reference; panics on any result
/// that was reported as good but differs.
fn judge(reference: &ProgramReport, got: &ProgramReport, what: &str) -> Outcome {
    let mut identical = true;
    for (r, g) in reference.cycles.iter().zip(&got.cycles) {
        assert_eq!((r.block, r.cycle), (g.block, g.cycle), "{what}");
        if g.status != Status::Ok {
            let msg = g.message.clone().unwrap_or_default();
            assert!(
                !msg.trim().is_empty(),
                "{what}: a failed cycle without a message"
            );
            return Outcome::Failed(msg);
        }
        assert_eq!(
            r.q.keys().collect::<Vec<_>>(),
            g.q.keys().collect::<Vec<_>>(),
            "{what}"
        );
        for (k, v) in &r.q {
            let w = g.q[k];
            assert!(
                (v - w).abs() <= TOLERANCE,
                "{what}: cycle {} {k} = {w:.9} reported as good, the fault-free run gives {v:.9}",
                g.cycle
            );
            identical &= v.to_bits() == w.to_bits();
        }
    }
    if !got.completed() {
        let why = got
            .stopped
            .clone()
            .unwrap_or_else(|| "the program did not complete".into());
        return Outcome::Failed(why);
    }
    assert_eq!(reference.cycles.len(), got.cycles.len(), "{what}");
    if identical {
        Outcome::Identical
    } else {
        Outcome::Exact
    }
}

/// Errors a lossy bus may end a cycle with: each says what happened.
fn is_clear(why: &str) -> bool {
    [
        "latch frame of node",
        "contact lost in transfer",
        "no heartbeat for",
        "touch probe did not report armed",
        "no SDO answer",
        "no boot-up",
        "did not reach Operation enabled",
        "did not reach its position",
    ]
    .iter()
    .any(|s| why.contains(s))
}

/// Runs at once, at most: a lost answer costs the 10 ms answer timeout in wall time
/// (a 451 at 1 % loss ran 156 s, 9 s without faults), so the runs mostly wait and
/// several overlap their waits; more would make answers late on a busy 2-core machine.
const AT_ONCE: usize = 4;

/// A run of `program` under `faults` (none for the reference): its report and the
/// fault layer's counts, or the start-up's error.
fn faulty_run(
    program: &str,
    sc: &sim::Scenario,
    faults: BusFaults,
    heartbeat_timeout_ms: Option<u16>,
    tag: &str,
) -> Result<(ProgramReport, String), String> {
    let mut f = open_with(sc, faults, heartbeat_timeout_ms).map_err(|e| e.to_string())?;
    let report = run_shipped_program(&mut f.machine, program, sc, tag);
    Ok((report, format!("{:?}", f.control.counts())))
}

/// `program` on `scenario` once without faults (the reference) and once per seed with
/// `rates`, [`AT_ONCE`] runs at a time; returns the outcomes. `heartbeat_timeout_ms`:
/// instead of the machine's.
fn under_faults(
    program: &str,
    scenario: &str,
    rates: FaultRates,
    seeds: std::ops::RangeInclusive<u64>,
    heartbeat_timeout_ms: Option<u16>,
) -> Vec<(u64, Outcome)> {
    let sc = load(scenario);
    // `None`: the reference.
    let jobs: Vec<Option<u64>> = std::iter::once(None).chain(seeds.map(Some)).collect();
    let mut runs = Vec::new();
    for batch in jobs.chunks(AT_ONCE) {
        std::thread::scope(|s| {
            let handles: Vec<_> = batch
                .iter()
                .map(|&seed| {
                    let sc = &sc;
                    s.spawn(move || {
                        let t0 = std::time::Instant::now();
                        let run = match seed {
                            None => faulty_run(
                                program,
                                sc,
                                BusFaults::new(0),
                                heartbeat_timeout_ms,
                                "clean",
                            ),
                            Some(seed) => faulty_run(
                                program,
                                sc,
                                BusFaults::both(seed, rates),
                                heartbeat_timeout_ms,
                                &format!("s{seed}"),
                            ),
                        };
                        let what = seed.map_or("without faults (the reference)".into(), |s| {
                            format!("seed {s}")
                        });
                        progress(
                            "bus_faults",
                            format_args!(
                                "{program} on {scenario}, {what}: ended ({:.1} s)",
                                t0.elapsed().as_secs_f64()
                            ),
                        );
                        (seed, run)
                    })
                })
                .collect();
            runs.extend(
                handles
                    .into_iter()
                    .map(|h| h.join().expect("a run's thread panicked")),
            );
        });
    }
    let (reference, _) = match &runs[0] {
        (None, Ok(run)) => run,
        (_, Err(e)) => panic!("fault-free {program}: start-up failed: {e}"),
        (Some(_), _) => unreachable!("the reference is the first job"),
    };
    assert!(
        reference.completed(),
        "fault-free {program}: {}",
        reference.to_json()
    );
    let mut outcomes = Vec::new();
    for (seed, run) in &runs[1..] {
        let seed = seed.expect("every job after the reference has a seed");
        let what = format!("{program} on {scenario}, seed {seed}");
        let outcome = match run {
            Ok((report, counts)) => {
                let o = judge(reference, report, &what);
                println!("{what}: {o:?}; {counts}");
                o
            }
            Err(e) => {
                println!("{what}: start-up failed: {e}");
                Outcome::Failed(e.clone())
            }
        };
        progress("bus_faults", format_args!("{what}: {outcome:?}"));
        if let Outcome::Failed(why) = &outcome {
            assert!(is_clear(why), "{what}: unclear failure: {why}");
        }
        outcomes.push((seed, outcome));
    }
    let completed = outcomes
        .iter()
        .filter(|(_, o)| !matches!(o, Outcome::Failed(_)))
        .count();
    let identical = outcomes
        .iter()
        .filter(|(_, o)| *o == Outcome::Identical)
        .count();
    println!(
        "{program} on {scenario} with {rates:?}: {} seeds, {completed} completed with the fault-free results ({identical} bit-identical), {} failed clearly",
        outcomes.len(),
        outcomes.len() - completed
    );
    outcomes
}

#[test]
fn cycle_431_with_one_percent_frame_loss_is_exact_or_fails_clearly() {
    let outcomes = under_faults(
        "431-plane.h",
        "tilted-plane.toml",
        FaultRates::loss(0.01),
        1..=8,
        None,
    );
    // The retries and repeats work: most runs complete.
    let completed = outcomes
        .iter()
        .filter(|(_, o)| !matches!(o, Outcome::Failed(_)))
        .count();
    assert!(completed * 2 >= outcomes.len(), "{outcomes:?}");
}

/// With the shipped heartbeat rules (producer 50 ms, consumer timeout 150 ms), two
/// heartbeats lost in a row are a lost node: over the length of a 451 run at 1 % loss
/// that happens in most runs, and the run stops with "no heartbeat". Never a wrong
/// result.
#[test]
fn cycle_451_with_one_percent_frame_loss_is_exact_or_fails_clearly() {
    under_faults(
        "451-check.h",
        "demo-sphere.toml",
        FaultRates::loss(0.01),
        1..=3,
        None,
    );
}

/// A machine configured for a lossy bus (a heartbeat timeout of 8 producer periods):
/// the lost SDO transfers, setpoints, SYNCs, answers, touch probe frames and latches of
/// a whole 451 run are retried, repeated or tolerated, and it completes exactly.
///
/// One seed: every lost answer costs the 10 ms answer timeout, and a run took 156 s
/// (9 s without faults); a second seed (12) also completed bit-identically and added
/// as much to every run of the test suite.
#[test]
fn cycle_451_with_one_percent_frame_loss_and_lenient_heartbeats_completes_exactly() {
    let outcomes = under_faults(
        "451-check.h",
        "demo-sphere.toml",
        FaultRates::loss(0.01),
        11..=11,
        Some(400),
    );
    let completed = outcomes
        .iter()
        .filter(|(_, o)| !matches!(o, Outcome::Failed(_)))
        .count();
    assert_eq!(completed, 1, "{outcomes:?}");
}

#[test]
fn duplicated_latch_frames_give_exactly_one_contact_each() {
    let sc = load("tilted-plane.toml");
    let mut clean = open(&sc, BusFaults::new(0)).unwrap();
    let reference = run_shipped_program(&mut clean.machine, "431-plane.h", &sc, "dup-clean");
    let want = clean.contacts.0.lock().unwrap().clone();
    drop(clean);
    // Every latch frame (TPDO2, 0x281..) the master receives comes twice.
    let mut faults = BusFaults::new(9);
    faults.receive.duplicate = 1.0;
    faults.cob_ids = 0x281..=0x2FF;
    let mut f = open(&sc, faults).unwrap();
    let report = run_shipped_program(&mut f.machine, "431-plane.h", &sc, "dup");
    assert_eq!(
        judge(&reference, &report, "duplicated latches"),
        Outcome::Identical
    );
    let got = f.contacts.0.lock().unwrap().clone();
    let dups = f.control.counts().duplicated;
    assert!(dups >= 3 * 5, "{dups} latch frames duplicated");
    assert_eq!(got, want, "one contact per probing move, numbered 1, 2, 3");
    assert_eq!(got, (1..=want.len() as u64).collect::<Vec<_>>());
}

const LONG_MOVE: [f64; 3] = [300.0, 200.0, 100.0];

/// The move was cut short on every axis (the other axes braked too).
fn assert_stopped_short(p: &AxisPositions) {
    for (i, a) in Axis::LINEAR.iter().enumerate() {
        let v = p.get(*a).unwrap();
        assert!(
            (v - LONG_MOVE[i]).abs() > 1.0,
            "{a} reached {v}: the move was not stopped"
        );
    }
}

#[test]
fn a_node_that_restarts_mid_move_stops_everything() {
    let sc = table_ac_plane(
        -150.0,
        "[[fault]]\nnode = 3\nkind = \"reboot\"\nafter_ms = 1500.0",
    );
    let mut f = open(&sc, BusFaults::new(0)).unwrap();
    let e = f
        .machine
        .move_to(&AxisPositions::linear(LONG_MOVE), 6000.0)
        .unwrap_err();
    assert_eq!(e.kind, ErrorKind::NodeLost, "{e}");
    assert_eq!(e.node, Some(3), "{e}");
    assert!(e.message.contains("node 3 restarted"), "{e}");
    let p = f.machine.positions().unwrap();
    assert_stopped_short(&p);
    // Nothing moves any more: the node's configuration is gone.
    let again = f
        .machine
        .move_to(&AxisPositions::linear([0.0, 0.0, 300.0]), 1000.0)
        .unwrap_err();
    assert!(again.message.contains("node 3 restarted"), "{again}");
}

#[test]
fn a_node_that_restarts_during_cycle_431_fails_the_cycle() {
    let mut sc = load("tilted-plane.toml");
    sc.faults.push(sim::scenario::Fault {
        node: 2,
        kind: sim::scenario::FaultKind::Reboot,
        after_ms: 3000.0,
        code: None,
    });
    let mut f = open(&sc, BusFaults::new(0)).unwrap();
    let report = run_shipped_program(&mut f.machine, "431-plane.h", &sc, "reboot");
    assert!(!report.completed());
    let failed = report
        .cycles
        .iter()
        .find(|c| c.status != Status::Ok)
        .expect("a failed cycle");
    let msg = failed.message.clone().unwrap_or_default();
    assert!(msg.contains("node 2 restarted"), "{msg}");
}

#[test]
fn a_transport_failure_mid_move_brakes_every_axis() {
    let sc = table_ac_plane(-150.0, "");
    let mut f = open(&sc, BusFaults::new(0)).unwrap();
    // About 1.5 s of virtual time into the move (a period sends 6 frames: 5 RPDO1 and
    // SYNC), the transport fails for 20 calls, then recovers: a bus-off and its
    // automatic recovery.
    let at = f.control.counts().transmitted + 6 * 750;
    f.control.fail_after(at, 20, TransportErrorKind::BusOff);
    let e = f
        .machine
        .move_to(&AxisPositions::linear(LONG_MOVE), 6000.0)
        .unwrap_err();
    assert_eq!(e.kind, ErrorKind::Bus, "{e}");
    assert!(
        e.message.contains("CAN transport failed; all axes stopped"),
        "{e}"
    );
    assert_eq!(f.control.counts().failed_calls, 20);
    // The braking setpoints went out once the transport was back: every axis stands
    // short of the target, where the loop reads it.
    let p = f.machine.positions().unwrap();
    assert_stopped_short(&p);
    // A faulted machine refuses motion.
    let again = f
        .machine
        .move_to(&AxisPositions::linear([0.0, 0.0, 300.0]), 1000.0)
        .unwrap_err();
    assert_eq!(again.kind, ErrorKind::Bus, "{again}");
    // The drives stand where the master reads them.
    let Held { machine, keep } = f.machine;
    drop(machine);
    let sim = keep.stop().unwrap().positions();
    for a in Axis::LINEAR {
        assert!(
            (sim.get(a).unwrap() - p.get(a).unwrap()).abs() < 1e-3,
            "{a}: {sim:?} vs {p:?}"
        );
    }
}

#[test]
fn a_transport_that_stays_down_mid_move_ends_the_move_with_a_bus_error() {
    let sc = table_ac_plane(-150.0, "");
    let mut f = open(&sc, BusFaults::new(0)).unwrap();
    let at = f.control.counts().transmitted + 6 * 750;
    f.control
        .fail_after(at, u64::MAX, TransportErrorKind::BusOff);
    let e = f
        .machine
        .move_to(&AxisPositions::linear(LONG_MOVE), 6000.0)
        .unwrap_err();
    assert_eq!(e.kind, ErrorKind::Bus, "{e}");
    // No SYNC reaches the drives any more: they stand where the bus went down,
    // short of the target on every axis.
    let Faulty { machine, .. } = f;
    let Held { machine, keep } = machine;
    drop(machine);
    let p = keep.stop().unwrap().positions();
    assert_stopped_short(&p);
}

/// 8 % of the touch probe frames (TPDO2: armed, latch) lost: the contact is not used
/// when one drive's latch is missing, the cycle probes that point again, and the
/// results are the fault-free run's; only a point whose latch is lost twice fails,
/// clearly.
#[test]
fn lost_latch_frames_are_probed_again() {
    let mut rates = BusFaults::new(0);
    rates.receive.drop = 0.08;
    rates.cob_ids = 0x281..=0x2FF;
    let sc = load("tilted-plane.toml");
    let mut clean = open(&sc, BusFaults::new(0)).unwrap();
    let reference = run_shipped_program(&mut clean.machine, "431-plane.h", &sc, "latch-clean");
    drop(clean);
    let (mut completed, mut retried) = (0, 0);
    for seed in 1..=6 {
        let mut faults = rates.clone();
        faults.seed = seed;
        let f = open(&sc, faults).unwrap();
        let mut m = CountLost {
            inner: f.machine,
            lost: 0,
        };
        let report = run_shipped_program(&mut m, "431-plane.h", &sc, &format!("latch{seed}"));
        let o = judge(&reference, &report, &format!("lost latches, seed {seed}"));
        let n = f.control.counts();
        progress(
            "bus_faults",
            format_args!(
                "lost touch probe frames, seed {seed}: {o:?}; {} dropped, {} contact(s) lost and probed again",
                n.dropped, m.lost
            ),
        );
        match &o {
            Outcome::Failed(why) => assert!(why.contains("latch frame of node"), "{why}"),
            _ => {
                completed += 1;
                retried += usize::from(m.lost > 0);
            }
        }
    }
    assert!(completed >= 3, "{completed} of 6 completed");
    assert!(retried >= 1, "no completed run had a lost latch");
}

/// Counts the probing moves that ended with a lost contact.
struct CountLost<M> {
    inner: M,
    lost: usize,
}

impl<M: Machine<Error = hal::MachineError>> Machine for CountLost<M> {
    type Error = hal::MachineError;
    fn axes(&self) -> u8 {
        self.inner.axes()
    }
    fn positions(&mut self) -> Result<AxisPositions, hal::MachineError> {
        self.inner.positions()
    }
    fn move_to(&mut self, target: &AxisPositions, feed: f64) -> Result<(), hal::MachineError> {
        self.inner.move_to(target, feed)
    }
    fn probe(&mut self, mv: &hal::ProbeMove) -> Result<hal::Contact, hal::MachineError> {
        let r = self.inner.probe(mv);
        if r.as_ref().is_err_and(|e| e.kind == ErrorKind::ContactLost) {
            self.lost += 1;
        }
        r
    }
    fn set_run(&mut self, run_id: u64) {
        self.inner.set_run(run_id)
    }

    fn clock_ns(&mut self) -> u64 {
        self.inner.clock_ns()
    }
}
