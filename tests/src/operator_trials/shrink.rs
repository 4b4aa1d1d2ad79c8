//! Shrinking a failing case: gene by gene, toward the nominal value (first the
//! nominal itself, then halfway), keeping a change only when the case still fails the
//! same way (same invariant, same defect class); then printing it as a ready-to-paste
//! regression test.

use super::draw::Case;
use super::invariants::Violation;

/// Genes that stay as drawn: the cycle under test.
const FIXED: [&str; 1] = ["cycle"];
/// Genes that are choices or counts: halfway is rounded to a whole number.
const WHOLE: [&str; 13] = [
    "machine",
    "backend",
    "inch",
    "flow",
    "mode",
    "q431",
    "axes",
    "points",
    "q301",
    "q455",
    "calibrate",
    "seed",
    "cycle",
];

fn same(a: f64, b: f64) -> bool {
    a == b || (a.is_nan() && b.is_nan())
}

fn round6(v: f64) -> f64 {
    (v * 1e6).round() / 1e6
}

/// The smallest case found from `case` that still gives a violation like `target`,
/// trying at most `budget` trials; with that violation.
pub fn shrink(
    case: &Case,
    target: &Violation,
    budget: usize,
    mut run: impl FnMut(&Case) -> Vec<Violation>,
) -> (Case, Violation) {
    let nominal = Case::nominal();
    let mut best = (case.clone(), target.clone());
    let mut tries = 0;
    loop {
        let mut changed = false;
        for (i, name) in Case::NAMES.iter().enumerate() {
            if FIXED.contains(name) {
                continue;
            }
            let (cur, nom) = (best.0.get(i), nominal.get(i));
            if same(cur, nom) {
                continue;
            }
            let mut candidates = vec![nom];
            if !cur.is_nan() && !nom.is_nan() {
                let mid = if WHOLE.contains(name) {
                    ((cur + nom) / 2.0).round()
                } else {
                    round6((cur + nom) / 2.0)
                };
                if !same(mid, cur) && !same(mid, nom) {
                    candidates.push(mid);
                }
            }
            for cand in candidates {
                if tries >= budget {
                    return best;
                }
                tries += 1;
                let mut c = best.0.clone();
                c.set(i, cand);
                let found = run(&c)
                    .into_iter()
                    .find(|v| v.invariant == target.invariant && v.class == target.class);
                if let Some(v) = found {
                    best = (c, v);
                    changed = true;
                    break;
                }
            }
        }
        if !changed {
            return best;
        }
    }
}

fn literal(v: f64) -> String {
    if v.is_nan() {
        "f64::NAN".into()
    } else {
        format!("{v:?}")
    }
}

/// `case` as a regression test to paste into `tests/tests/operator_trials.rs`.
pub fn regression(case: &Case, v: &Violation) -> String {
    let nominal = Case::nominal();
    let fields: Vec<String> = Case::NAMES
        .iter()
        .enumerate()
        .filter(|(i, _)| !same(case.get(*i), nominal.get(*i)) || Case::NAMES[*i] == "cycle")
        .map(|(i, n)| format!("{n}: {}", literal(case.get(i))))
        .collect();
    let detail = v.detail.replace('\n', " / ");
    format!(
        "// {} {} ({}): {detail}\nlet case = Case {{ {}, ..Case::nominal() }};\nassert_eq!(operator_trials::violations(&case), vec![]);",
        v.invariant,
        case.cycle,
        v.class,
        fields.join(", ")
    )
}
