//! Generated operators (issue 34, section 4): a seeded draw of what an operator can
//! type and do around cycles 451, 460, 431 and 444 on the four shipped machines
//! ([`draw`]), run with `check` and `run` on the simulator ([`setup`], [`recorder`]),
//! held against four invariants ([`invariants`]), sorted into the known defect
//! classes ([`known`]), and a failing case shrunk to a minimal regression ([`shrink`]).
//! `tests/tests/operator_trials.rs` runs a sample in CI; `scripts/operator-trials`
//! runs any number. See docs/testing.md, "Generated operators".

pub mod draw;
pub mod invariants;
pub mod known;
pub mod recorder;
pub mod setup;
pub mod shrink;

pub use draw::Case;
pub use invariants::Violation;

use crate::conformance::{Backend, CanInproc};
use crate::conformance_modbus::open_tcp;
use crate::world_machine::WorldMachine;
use cycles::program::Program;
use cycles::progress::ProgressEvent;
use cycles::results::{ProgramReport, Status};
use cycles::runner::{preflight_program, run_program, RunOptions};
use hal::{Machine, MachineError};
use recorder::{Act, Recorder};
use setup::{snapshot, Setup};
use std::collections::BTreeMap;
use std::time::Instant;

/// How a trial ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Outcome {
    /// The program ran to its end, every cycle ok.
    Ok,
    /// Refused before anything moved (`check` and `run`).
    Refused,
    /// Stopped after moving (a cycle's stop, a probe that found nothing, ...).
    Stopped,
    /// A contact outside a probing move.
    Contact,
    /// The run panicked.
    Panicked,
}

impl Outcome {
    pub fn name(self) -> &'static str {
        match self {
            Outcome::Ok => "ok",
            Outcome::Refused => "refused",
            Outcome::Stopped => "stopped",
            Outcome::Contact => "contact",
            Outcome::Panicked => "panicked",
        }
    }
}

/// One case's run.
pub struct Trial {
    pub outcome: Outcome,
    pub violations: Vec<Violation>,
    /// Why it was refused or stopped.
    pub message: Option<String>,
}

/// The violations `case` gives (each with its known class): a regression test
/// asserts none.
pub fn violations(case: &Case) -> Vec<Violation> {
    trial(case).violations
}

type Ran = (ProgramReport, Vec<Act>, Vec<Vec<(String, Vec<u8>)>>);

fn run_on<M: Machine<Error = MachineError>>(m: M, s: &Setup, program: &Program) -> Ran {
    let mut rec = Recorder::new(m, hal::motion_guard::MotionGuard::new(&s.cfg.machine));
    let mut starts = Vec::new();
    let state = s.state.clone();
    let mut confirm = |_: &cycles::confirmation::Confirmation| true;
    let mut progress = |e: ProgressEvent| {
        if matches!(e, ProgressEvent::CycleStarted { .. }) {
            starts.push(snapshot(&state));
        }
    };
    let mut opts = RunOptions {
        out_dir: s.out.clone(),
        confirm: &mut confirm,
        progress: &mut progress,
        kinematics: Some(s.kinematics.clone()),
        estimator: None,
    };
    let report = run_program(program, &mut rec, &s.cfg, &mut opts);
    drop(opts);
    (report, rec.acts, starts)
}

/// Runs one case: builds it, `check`s it, runs it on its backend, judges it.
pub fn trial(case: &Case) -> Trial {
    let s = match setup::build(case) {
        Ok(s) => s,
        Err(e) => {
            return Trial {
                outcome: Outcome::Panicked,
                violations: vec![Violation {
                    invariant: "I2",
                    class: "NEW",
                    detail: format!("the case cannot be set up: {e}"),
                }],
                message: Some(e),
            }
        }
    };
    let program = match Program::parse(&s.text, &s.cfg) {
        Ok(p) => p,
        Err(e) => {
            // `check` and `run` read the program the same way: both refuse it here.
            let msg = e.to_string();
            let mut violations = Vec::new();
            if !invariants::names_what_to_check(&msg) {
                violations.push(Violation {
                    invariant: "I2",
                    class: "NEW",
                    detail: format!("refused with a message that names nothing to check: {msg}"),
                });
            }
            return classified(case, Outcome::Refused, violations, Some(msg));
        }
    };
    let check = preflight_program(&program, s.cfg.machine.axis_mask(), &s.cfg, &s.kinematics)
        .err()
        .map(|e| e.to_string());
    let before = snapshot(&s.state);
    let ran = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| match case.backend as u8 {
        1 => run_on(CanInproc::open(&s.sc), &s, &program),
        2 => {
            let orient = true;
            run_on(
                open_tcp(&s.sc, |b| b.spindle_orientation = orient),
                &s,
                &program,
            )
        }
        _ => run_on(WorldMachine::new(&s.sc), &s, &program),
    }));
    let (report, acts, at_cycle_start) = match ran {
        Ok(r) => r,
        Err(p) => {
            let why = p
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_default();
            let v = Violation {
                invariant: "I2",
                class: "NEW",
                detail: format!("the run panicked: {why}"),
            };
            return classified(case, Outcome::Panicked, vec![v], Some(why));
        }
    };
    let seen = invariants::Seen {
        setup: &s,
        check,
        report: &report,
        acts: &acts,
        before,
        at_cycle_start,
        after: snapshot(&s.state),
    };
    let violations = invariants::check(&seen);
    let outcome = if acts.iter().any(|a| {
        !a.probing
            && matches!(
                a.failed,
                Some(hal::ErrorKind::ProbeCollision) | Some(hal::ErrorKind::AlreadyDeflected)
            )
    }) {
        Outcome::Contact
    } else if report.completed() {
        Outcome::Ok
    } else if acts.is_empty() {
        Outcome::Refused
    } else {
        Outcome::Stopped
    };
    let message = invariants::run_message(&report).or(seen.check.clone());
    classified(case, outcome, violations, message)
}

fn classified(
    case: &Case,
    outcome: Outcome,
    mut violations: Vec<Violation>,
    message: Option<String>,
) -> Trial {
    for v in &mut violations {
        v.class = known::classify(case, v);
    }
    Trial {
        outcome,
        violations,
        message,
    }
}

/// A violation found in a run, with its case and (when shrunk) the minimal case.
pub struct Finding {
    pub index: u64,
    pub case: Case,
    pub violation: Violation,
    pub shrunk: Option<(Case, Violation)>,
}

/// What a run of many cases found.
#[derive(Default)]
pub struct Summary {
    pub seed: u64,
    pub cases: usize,
    /// Per cycle, per outcome.
    pub outcomes: BTreeMap<u16, BTreeMap<&'static str, usize>>,
    /// Cases per backend: world, CANopen, Modbus.
    pub backends: [usize; 3],
    pub findings: Vec<Finding>,
    pub seconds: f64,
}

impl Summary {
    /// The line a CI log shows: counts per cycle and outcome, per backend, and the
    /// violations per invariant and class.
    pub fn line(&self) -> String {
        let cycles: Vec<String> = self
            .outcomes
            .iter()
            .map(|(c, o)| {
                let parts: Vec<String> = o.iter().map(|(k, n)| format!("{k} {n}")).collect();
                format!("{c}: {}", parts.join(", "))
            })
            .collect();
        let mut by: BTreeMap<String, usize> = BTreeMap::new();
        for f in &self.findings {
            *by.entry(format!(
                "{} {} {}",
                f.violation.invariant, f.case.cycle, f.violation.class
            ))
            .or_default() += 1;
        }
        let classes: Vec<String> = by.iter().map(|(k, n)| format!("{k} x{n}")).collect();
        format!(
            "operator trials: seed {} | {} cases in {:.1} s | {} | world {}, CANopen {}, Modbus {} | {} violations{}",
            self.seed,
            self.cases,
            self.seconds,
            cycles.join(" | "),
            self.backends[0],
            self.backends[1],
            self.backends[2],
            self.findings.len(),
            if classes.is_empty() { String::new() } else { format!(": {}", classes.join(", ")) }
        )
    }

    /// Each distinct violation (invariant, cycle, class) once, with its shrunk case.
    pub fn report(&self) -> String {
        let mut out = String::new();
        for f in &self.findings {
            out.push_str(&format!(
                "\nVIOLATION {} cycle {} class {} (case {} of seed {}): {}\n",
                f.violation.invariant,
                f.case.cycle,
                f.violation.class,
                f.index,
                self.seed,
                f.violation.detail
            ));
            if let Some((c, v)) = &f.shrunk {
                out.push_str("shrunk to:\n");
                out.push_str(&shrink::regression(c, v));
                out.push('\n');
            }
        }
        out
    }
}

/// How many findings of one kind (invariant, cycle, class) are shrunk, and the trials
/// each shrink may spend.
pub struct ShrinkPolicy {
    pub per_kind: usize,
    pub budget: usize,
}

/// Runs cases `0..cases` of `seed`; `progress` sees each case's index and trial.
pub fn run(
    seed: u64,
    cases: u64,
    shares: &draw::Shares,
    policy: &ShrinkPolicy,
    progress: impl FnMut(u64, &Case, &Trial),
) -> Summary {
    run_on_threads(seed, cases, shares, policy, 1, progress)
}

/// How many cases the threads of [`run_on_threads`] try before their trials are
/// taken in order.
const BATCH: u64 = 64;

/// [`run`] with the trials on `jobs` threads (each case is independent: case `i` of
/// `seed` is always the same case). The trials are taken in the order of their index,
/// and shrinking runs on the caller's thread, so the summary is the sequential one
/// (but for its duration) and `progress` sees the cases in order.
pub fn run_on_threads(
    seed: u64,
    cases: u64,
    shares: &draw::Shares,
    policy: &ShrinkPolicy,
    jobs: usize,
    mut progress: impl FnMut(u64, &Case, &Trial),
) -> Summary {
    let start = Instant::now();
    let mut sum = Summary {
        seed,
        ..Summary::default()
    };
    let mut shrunk_kinds: BTreeMap<String, usize> = BTreeMap::new();
    let jobs = jobs.max(1) as u64;
    let mut first = 0;
    while first < cases {
        let end = cases.min(first + BATCH * jobs);
        // Every `jobs`-th case of the batch from its `k`-th.
        let stride = move |k: u64| {
            (first + k..end)
                .step_by(jobs as usize)
                .map(|i| {
                    let case = draw::draw(seed, i, shares);
                    let t = trial(&case);
                    (i, case, t)
                })
                .collect::<Vec<_>>()
        };
        let mut tried: Vec<(u64, Case, Trial)> = if jobs == 1 {
            stride(0)
        } else {
            std::thread::scope(|scope| {
                let threads: Vec<_> = (0..jobs).map(|k| scope.spawn(move || stride(k))).collect();
                threads
                    .into_iter()
                    .flat_map(|h| h.join().expect("a trial thread panicked"))
                    .collect()
            })
        };
        tried.sort_by_key(|(i, ..)| *i);
        first = end;
        for (i, case, t) in tried {
            sum.add(i, case, t, policy, &mut shrunk_kinds, &mut progress);
        }
    }
    sum.seconds = start.elapsed().as_secs_f64();
    sum
}

impl Summary {
    /// Counts case `i`'s trial `t` and its violations, the first of each kind
    /// (invariant, cycle, class) shrunk as `policy` allows.
    fn add(
        &mut self,
        i: u64,
        case: Case,
        t: Trial,
        policy: &ShrinkPolicy,
        shrunk_kinds: &mut BTreeMap<String, usize>,
        progress: &mut impl FnMut(u64, &Case, &Trial),
    ) {
        let sum = self;
        progress(i, &case, &t);
        sum.cases += 1;
        sum.backends[(case.backend as usize).min(2)] += 1;
        *sum.outcomes
            .entry(case.cycle as u16)
            .or_default()
            .entry(t.outcome.name())
            .or_default() += 1;
        for v in t.violations {
            let kind = format!("{} {} {}", v.invariant, case.cycle, v.class);
            let n = shrunk_kinds.entry(kind).or_default();
            let shrunk = (*n < policy.per_kind).then(|| {
                *n += 1;
                shrink::shrink(&case, &v, policy.budget, violations)
            });
            sum.findings.push(Finding {
                index: i,
                case: case.clone(),
                violation: v,
                shrunk,
            });
        }
    }
}

/// Whether the trial's cycle results all passed (for callers that count).
pub fn all_ok(report: &ProgramReport) -> bool {
    report.cycles.iter().all(|c| c.status == Status::Ok)
}
