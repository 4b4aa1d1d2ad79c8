//! Generated operators (issue 34, section 4): a seeded sample of what an operator can
//! type and do around cycles 451, 460, 431 and 444 on the four shipped machines, most
//! on the simulator's physics without a bus and a share over CANopen (lockstep) and
//! Modbus (the simulated PLC on loopback), held against the four invariants (see
//! `probebridge_tests::operator_trials` and docs/testing.md, "Generated operators").
//! A violation is printed with its shrunk case, ready to paste below as a regression.

use probebridge_tests::operator_trials::{
    self, draw, invariants::names_what_to_check, shrink, Case, Outcome, ShrinkPolicy, Violation,
};

/// The seed and size of the CI sample (about a minute in the debug test profile on
/// the 2-core CI machine; `scripts/operator-trials` runs any number).
const SEED: u64 = 34;
const CASES: u64 = 400;

/// Every cycle on every shipped machine, each gene at its nominal value: ok, and no
/// invariant violated (the harness's truth and the cycles agree where nothing is off).
#[test]
fn nominal_operators_on_every_machine_hold_every_invariant() {
    for cycle in draw::CYCLES {
        for machine in 0..4u8 {
            let case = Case {
                cycle: f64::from(cycle),
                machine: f64::from(machine),
                ..Case::nominal()
            };
            let t = operator_trials::trial(&case);
            assert_eq!(
                (t.outcome, t.violations.clone()),
                (Outcome::Ok, Vec::new()),
                "cycle {cycle} on {}: {:?}",
                draw::MACHINES[machine as usize],
                t.message
            );
        }
    }
}

/// The seeded sample: at least 200 cases across the four cycles, some over CANopen
/// and Modbus, with 0 violations.
#[test]
fn a_seeded_sample_of_generated_operators_violates_no_invariant() {
    let shares = draw::Shares {
        can: 0.04,
        modbus: 0.04,
    };
    let policy = ShrinkPolicy {
        per_kind: 1,
        budget: 80,
    };
    let summary = operator_trials::run(SEED, CASES, &shares, &policy, |_, _, _| {});
    println!("{}", summary.line());
    print!("{}", summary.report());
    assert!(summary.cases >= 200);
    for cycle in draw::CYCLES {
        let n: usize = summary.outcomes[&cycle].values().sum();
        assert!(n >= 40, "only {n} cases of cycle {cycle}");
    }
    assert!(
        summary.backends[1] > 0 && summary.backends[2] > 0,
        "{}",
        summary.line()
    );
    let (open, new): (Vec<_>, Vec<_>) = summary.findings.iter().partition(|f| {
        OPEN_CLASSES
            .iter()
            .any(|(i, c, _)| *i == f.violation.invariant && *c == f.violation.class)
    });
    for (i, c, why) in OPEN_CLASSES {
        let n = open
            .iter()
            .filter(|f| f.violation.invariant == *i && f.violation.class == *c)
            .count();
        println!("still open (issue 34): {i} {c}: {n} in this sample; {why}");
    }
    assert!(
        new.is_empty(),
        "{} violations outside the classes still open (see the shrunk cases above)",
        new.len()
    );
}

/// Classes issue 34 still has open (none now: the last four closed together), each
/// found by this sample and named in the closing note: none may be a contact while positioning within the documented reach
/// (I1's safety half), a check that disagrees with run (I3) or a write after a stop
/// (I4). Any other violation fails the test; a class is taken off this list with
/// its fix.
const OPEN_CLASSES: &[(&str, &str, &str)] = &[];

/// The shrunk cases of `451-q407-small` (seeds 2027 and 451): Q407 3.5 mm below the
/// sphere's radius, Q431 = 2 or 0, the preset 12 mm off the sphere centre (beyond the
/// documented reach). The pole probe lands on the flank, the first locating pass
/// (planned with Q407 + R) comes down onto the larger sphere: beyond the docs a
/// contact may happen, but it is caught and its message names what to check (it named
/// nothing). The same with the probe table's R 1.2 mm stale, and with Q431 = 1 and the
/// start 1.3 x the reach off the centre.
#[test]
fn a_contact_beyond_q407_and_the_reach_names_q407_r_and_the_preset_or_the_start() {
    let base = Case {
        cycle: 451.0,
        q407_err: -0.278,
        q431: 2.0,
        preset_err: 1.292,
        ..Case::nominal()
    };
    let cases = [
        base.clone(),
        Case {
            q431: 0.0,
            ..base.clone()
        },
        Case {
            stale_r: -1.2,
            ..base.clone()
        },
        Case {
            q431: 1.0,
            preset_err: 0.0,
            off: 1.3,
            ..base.clone()
        },
    ];
    for case in cases {
        let t = operator_trials::trial(&case);
        assert_eq!(t.violations, vec![], "{case:?}: {:?}", t.message);
        assert_ne!(t.outcome, Outcome::Ok, "{case:?}");
        let m = t.message.unwrap_or_default();
        if t.outcome == Outcome::Contact {
            let place = if case.q431 == 1.0 {
                "position the probe over the sphere centre"
            } else {
                "the preset X"
            };
            for named in ["check Q407 (typed", "the probe table's R", place] {
                assert!(m.contains(named), "{case:?}: {named:?} not in {m}");
            }
        }
    }
}

/// Cycle 460's case of the same kind (case 2092 of seed 3407, the 20 000 cases of issue
/// 34's figures): Q407 3.3 mm small and the start 1.47 x the reach off the centre on
/// the horizontal X machine; a locating point's move to its start met the sphere and
/// the message named nothing. It names Q407, the probe table's R and where to start.
#[test]
fn a_460_contact_beyond_q407_and_the_reach_names_q407_r_and_the_start() {
    let case = Case {
        machine: 2.0,
        cycle: 460.0,
        off: 1.47,
        off_dir: 81.3,
        rise: -0.218,
        q407_err: -0.2678,
        ..Case::nominal()
    };
    let t = operator_trials::trial(&case);
    assert_eq!(t.violations, vec![], "{:?}", t.message);
    assert_ne!(t.outcome, Outcome::Ok);
    let m = t.message.unwrap_or_default();
    if t.outcome == Outcome::Contact {
        for named in [
            "check Q407 (typed",
            "the probe table's R",
            "position the probe over the sphere centre",
        ] {
            assert!(m.contains(named), "{named:?} not in {m}");
        }
    }
}

/// `--jobs`: the cases on two threads give the summary of the sequential run (the
/// same outcomes per cycle, backends and findings), case for case in order.
#[test]
fn two_threads_give_the_sequential_summary() {
    let shares = draw::Shares {
        can: 0.1,
        modbus: 0.1,
    };
    let policy = ShrinkPolicy {
        per_kind: 0,
        budget: 0,
    };
    let (mut one, mut two) = (Vec::new(), Vec::new());
    let a = operator_trials::run(7, 24, &shares, &policy, |i, _, t| one.push((i, t.outcome)));
    let b = operator_trials::run_on_threads(7, 24, &shares, &policy, 2, |i, _, t| {
        two.push((i, t.outcome))
    });
    assert_eq!(one, two);
    assert_eq!((a.cases, a.backends), (b.cases, b.backends));
    assert_eq!(a.outcomes, b.outcomes);
    let found = |s: &operator_trials::Summary| -> Vec<_> {
        s.findings
            .iter()
            .map(|f| (f.index, f.violation.clone()))
            .collect()
    };
    assert_eq!(found(&a), found(&b));
}

/// Shrinking keeps only what the failure needs: a failure that depends on the start
/// being more than 0.5 of the reach off and on Q431 ends as exactly those two genes
/// (the cycle stays), the start halved toward nominal while it still fails; and it
/// prints as a regression case naming only them.
#[test]
fn a_failing_case_shrinks_to_the_genes_it_needs() {
    let case = Case {
        cycle: 460.0,
        off: 1.4,
        q431: 3.0,
        noise: 0.0007,
        rot2: 120.0,
        stale_r: -1.2,
        flow: 4.0,
        ..Case::nominal()
    };
    let fails = |c: &Case| {
        if c.off > 0.5 && c.q431 == 3.0 {
            vec![Violation {
                invariant: "I1",
                class: "NEW",
                detail: format!("off {}", c.off),
            }]
        } else {
            Vec::new()
        }
    };
    let first = fails(&case).remove(0);
    let (small, v) = shrink::shrink(&case, &first, 200, fails);
    let want = Case {
        cycle: 460.0,
        off: small.off,
        q431: 3.0,
        ..Case::nominal()
    };
    assert_eq!(small, want);
    // Halved once (0.7 still fails, 0.35 does not).
    assert_eq!(small.off, 0.7);
    assert_eq!(v.detail, format!("off {}", small.off));
    let text = shrink::regression(&small, &v);
    assert!(
        text.contains(&format!(
            "Case {{ cycle: 460.0, off: {:?}, q431: 3.0, ..Case::nominal() }}",
            small.off
        )),
        "{text}"
    );
}

/// What counts as a message that names what to check: a parameter, a position, the
/// preset or where to put the probe; not the machine's bare words on a contact.
#[test]
fn a_message_names_what_to_check_or_it_does_not() {
    for named in [
        "block 9: Q408=89.134: the retraction height does not clear the sphere",
        "L block: Z+38066.2399 is outside the software limits",
        "probe did not trigger: position the probe over the sphere centre",
        "block 8: cycle 451 failed: locating the sphere (first pass): point 1 of 4: probe deflected during a positioning move: the probe touched while positioning to [52.5, 25.6, 58.9]; the sphere is larger than Q407 + R = 10.8000 mm, or further off, than this move was planned for: check Q407",
    ] {
        assert!(names_what_to_check(named), "{named}");
    }
    for bare in [
        "block 8: cycle 451 failed: approaching the sphere: probe deflected during a positioning move: the probe touched while positioning to [52.5, 25.6, 58.9] (the program's coordinates were relative to preset row 1 of /tmp/x: X+0.0000 Y+0.0000 Z+0.0000; M91 blocks are machine coordinates)",
        "line 3: the condition has no value",
    ] {
        assert!(!names_what_to_check(bare), "{bare}");
    }
}

/// The detectors themselves: a 444 whose real surface stands 4 mm proud of the
/// nominal point (beyond SET_UP + Q320) touches it while positioning: the trial
/// reports a contact (I1's detector on the world machine) and calls the case beyond
/// the docs; a 460 started 3 x its reach off the sphere does not end ok.
#[test]
fn the_detectors_see_a_contact_and_a_stop() {
    let proud = Case {
        cycle: 444.0,
        surf: 4.0,
        ..Case::nominal()
    };
    let t = operator_trials::trial(&proud);
    assert_eq!(t.outcome, Outcome::Contact, "{:?}", t.message);
    let s = operator_trials::setup::build(&proud).unwrap();
    assert!(!s.beyond.is_empty());
    let far = Case {
        cycle: 460.0,
        off: 3.0,
        ..Case::nominal()
    };
    let t = operator_trials::trial(&far);
    assert_ne!(t.outcome, Outcome::Ok, "{:?}", t.message);
}
