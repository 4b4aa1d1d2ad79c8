//! The defect classes issue 34 names, recognised from a violation and its case, so a
//! run's report says which known class each finding is (and which are new). A class
//! is a guess from the case's genes and the message, good enough to sort findings;
//! the shrunk case is the evidence.

use super::draw::Case;
use super::invariants::Violation;

/// The class of `v` found on `case`.
pub fn classify(case: &Case, v: &Violation) -> &'static str {
    let d = v.detail.as_str();
    let cycle = case.cycle as u16;
    let turned = case.rot1 != 0.0 || case.rot2 != 0.0;
    match (v.invariant, cycle) {
        ("I2", _) if d.contains("ran to its end without a word") && case.flow == 2.0 => {
            "call-lbl-before"
        }
        ("I1", 451) if case.q407_err * super::setup::SPHERE < -0.1 => "451-q407-small",
        ("I1", 451)
            if (case.q431 == 0.0 || case.q431 == 2.0)
                && (case.preset_err > 0.0 || case.preset_up != 0.0)
                && case.stale_r.abs() <= 0.1 =>
        {
            "451-preset-away"
        }
        ("I1", 451) if case.stale_r.abs() > 0.1 => "NEW:451-stale-r-contact",
        ("I2", 451)
            if (case.q431 == 1.0 || case.q431 == 3.0)
                && turned
                && (d.starts_with("preset") || d.starts_with("Q14")) =>
        {
            "451-rotary-turned"
        }
        ("I2", 451)
            if (case.q431 == 0.0 || case.q431 == 2.0)
                && (case.preset_err > 0.0 || case.preset_up != 0.0)
                && d.contains("did not trigger") =>
        {
            "451-preset-away"
        }
        ("I2", 451) if case.off > 1.0 && d.contains("did not trigger") => {
            "NEW:451-beyond-reach-stop-unnamed"
        }
        ("I1", 460) if case.off > 1.0 => "460-beyond-reach",
        ("I1", 460) if case.stale_r != 0.0 && d.contains("within the documented reach") => {
            "460-stale-r"
        }
        ("I1", 460) if case.q407_err * super::setup::SPHERE < -0.1 => "460-q407-small",
        ("I2", 460)
            if (case.q407_err * super::setup::SPHERE).abs() > 0.1
                && (d.starts_with('R') || d.starts_with('L')) =>
        {
            "NEW:460-q407-off-completes"
        }
        ("I2", 460) if case.stale_r != 0.0 && (d.starts_with('R') || d.starts_with('L')) => {
            "460-stale-r"
        }
        ("I2", 444) if case.calibrate == 1.0 && case.el < 0.0 => "444-below-equator-3d",
        ("I3", 451) if case.q408 > 0.0 || d.contains("software limit") => "check-run-q408",
        _ if case.inch == 1.0 && d.contains("inch") => "inch-measured-length",
        ("I1", 431 | 444) if d.contains("names nothing to check") => {
            "NEW:contact-beyond-names-nothing"
        }
        _ => "NEW",
    }
}
