//! CI's fuzz run: every target on its seeds and a fixed number of mutations from a
//! fixed seed (capped in time so the whole test stays short on a slow runner). The
//! only assertion: nothing panicked and no input took more than a second of CPU.

use probebridge_fuzz::{driver, targets, Budget};
use std::time::Duration;

/// Mutated inputs per target.
const ITERATIONS: u64 = 3000;
/// Wall-clock cap per target (19 targets, well under 30 s in a debug build).
const SECONDS: f64 = 1.2;

#[test]
fn every_target_survives_a_short_run() {
    let budget = Budget {
        seconds: SECONDS,
        iterations: Some(ITERATIONS),
        seed: 0x5EED,
        timeout: Duration::from_secs(1),
        ..Budget::default()
    };
    let mut failures = Vec::new();
    for target in targets::all() {
        let report = driver::run(&target, &budget);
        println!("{report}");
        assert!(
            report.executions > report.seeds as u64,
            "{report}: no mutated input ran"
        );
        failures.extend(
            report
                .findings
                .iter()
                .map(|f| format!("{}: {f}", target.name)),
        );
    }
    assert!(failures.is_empty(), "findings:\n{}", failures.join("\n"));
}

#[test]
fn a_target_that_panics_is_reported_with_its_input() {
    let target = driver::Target {
        name: "self-test",
        about: "panics on inputs starting with !",
        max_len: 16,
        prepare: || {},
        seeds: || vec![b"ok".to_vec(), b"!".to_vec()],
        dictionary: &[],
        run: |d| {
            assert!(d.first() != Some(&b'!'), "bang");
            probebridge_fuzz::sig::Sig::default()
        },
    };
    let report = driver::run(
        &target,
        &Budget {
            seconds: 5.0,
            iterations: Some(10),
            ..Budget::default()
        },
    );
    assert_eq!(report.findings.len(), 1, "{report}");
    let f = &report.findings[0];
    assert_eq!(
        (f.message.as_str(), f.input.as_slice()),
        ("bang", &b"!"[..])
    );
    assert!(f.location.contains("short_budget.rs"), "{}", f.location);
}
