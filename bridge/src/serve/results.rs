//! The results of a run by what they are: written in one place (here, from the cycle's
//! report, on the machine thread) and read by every face: the PLC's result,
//! uncertainty and calibration blocks ([`super::register_map`]) and OPC UA's
//! Measurements. A result's name as the faces show it (`Q158`, `before.EX0C`,
//! `u.after.EX0C`) is its [`std::fmt::Display`], made here and nowhere else.

use cycles::iso230_7::error_names;
use cycles::results::{CycleResult, ProgramReport, Status};
use hal::Axis;
use std::collections::BTreeMap;
use std::fmt;

/// What a result measures.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Quantity {
    /// A result by the cycle's own name: Q141..Q183, or a column of the probe table
    /// row 460 writes (R, CAL_OF1, CAL_OF2, L).
    Named(String),
    /// An ISO 230-7 error of a rotary axis (EX0C ...) before cycle 451's optimisation.
    ErrorBefore(String),
    /// The same error after it.
    ErrorAfter(String),
}

impl Quantity {
    pub fn named(name: &str) -> Self {
        Quantity::Named(name.to_string())
    }
}

impl fmt::Display for Quantity {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Quantity::Named(n) => f.write_str(n),
            Quantity::ErrorBefore(n) => write!(f, "before.{n}"),
            Quantity::ErrorAfter(n) => write!(f, "after.{n}"),
        }
    }
}

/// A result, or the standard uncertainty (k = 1) of one.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum ResultKey {
    Value(Quantity),
    Uncertainty(Quantity),
}

impl fmt::Display for ResultKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ResultKey::Value(q) => q.fmt(f),
            ResultKey::Uncertainty(q) => write!(f, "u.{q}"),
        }
    }
}

/// The results of one cycle, with their uncertainties.
pub type ResultValues = BTreeMap<ResultKey, f64>;

/// Cycle 460's probe table columns, in the order every face lists them (the PLC's
/// calibration block, OPC UA's 460 results).
pub const CAL_COLUMNS: [&str; 4] = ["R", "CAL_OF1", "CAL_OF2", "L"];

/// The result slots of the PLC's result block, in register order: Q141..Q175, Q183,
/// then the ISO 230-7 errors of A, B and C before optimisation and after.
pub fn slots() -> Vec<Quantity> {
    let mut v: Vec<Quantity> = (141..=175)
        .map(|n| Quantity::Named(format!("Q{n}")))
        .collect();
    v.push(Quantity::named("Q183"));
    for when in [Quantity::ErrorBefore, Quantity::ErrorAfter] {
        for axis in [Axis::A, Axis::B, Axis::C] {
            v.extend(error_names(axis).iter().map(|n| when(n.to_string())));
        }
    }
    v
}

/// The last successful cycle of a run: its number and results (0 and none without).
pub fn last_results(report: &ProgramReport) -> (u16, ResultValues) {
    let Some(last) = report.cycles.iter().rev().find(|c| c.status == Status::Ok) else {
        return (0, BTreeMap::new());
    };
    (last.cycle, of_cycle(last))
}

/// How long the run's cycles kept the machine, part by part (`None`: no cycle ran).
pub fn machine_time(report: &ProgramReport) -> Option<cycles::machine_time::TimeSplit> {
    report
        .cycles
        .iter()
        .filter_map(|c| c.machine_time_split_s)
        .reduce(|a, b| a.plus(&b))
}

/// A cycle's results: its Q parameters (460: the probe table row's columns), for 451
/// the errors before and after; with their standard uncertainties.
pub fn of_cycle(c: &CycleResult) -> ResultValues {
    let mut v: ResultValues =
        c.q.iter()
            .map(|(n, x)| (ResultKey::Value(Quantity::named(n)), *x))
            .collect();
    for (name, u) in &c.u {
        v.insert(ResultKey::Uncertainty(Quantity::named(name)), *u);
    }
    if let Some(k) = &c.kinematics {
        for (name, e) in &k.errors_before {
            v.insert(ResultKey::Value(Quantity::ErrorBefore(name.clone())), *e);
        }
        for (name, e) in &k.errors_after {
            v.insert(ResultKey::Value(Quantity::ErrorAfter(name.clone())), *e);
        }
        for (name, u) in &k.errors_u {
            v.insert(
                ResultKey::Uncertainty(Quantity::ErrorAfter(name.clone())),
                *u,
            );
        }
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_the_documented_ones() {
        let s = slots();
        assert_eq!(s.len(), super::super::register_map::SLOTS);
        let names: Vec<String> = s.iter().map(ToString::to_string).collect();
        assert_eq!(
            (
                &names[0][..],
                &names[35][..],
                &names[36][..],
                &names[65][..]
            ),
            ("Q141", "Q183", "before.EY0A", "after.EC0C")
        );
        let u = ResultKey::Uncertainty(Quantity::ErrorAfter("EX0C".into()));
        assert_eq!(u.to_string(), "u.after.EX0C");
        assert_eq!(ResultKey::Value(Quantity::named("R")).to_string(), "R");
    }
}
