//! The series of a machine's page: one per ISO 230-7 error and per rotary axis's
//! dispersion, each run's values in the series' unit, and what they say (the change
//! since the previous run, the drift, the alarms, the tolerance).

use super::super::time::parse_utc;
use super::super::{RunRow, RunStatus};
use super::alarm::Alarm;
use std::collections::BTreeMap;

#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Unit {
    Um,
    Arcsec,
}

impl Unit {
    /// ISO 230-7: `E` + the error's direction + `0` + the axis; X/Y/Z are positions
    /// (mm), A/B/C orientations (deg).
    pub(super) fn of_error(name: &str) -> Self {
        match name.as_bytes().get(1) {
            Some(b'X' | b'Y' | b'Z') => Unit::Um,
            _ => Unit::Arcsec,
        }
    }
    /// From the stored unit (mm, deg).
    pub(super) fn scale(self) -> f64 {
        match self {
            Unit::Um => 1000.0,
            Unit::Arcsec => 3600.0,
        }
    }
    pub(super) fn label(self) -> &'static str {
        match self {
            Unit::Um => "µm",
            Unit::Arcsec => "arcsec",
        }
    }
    pub(super) fn threshold(self, a: &Alarm) -> f64 {
        match self {
            Unit::Um => a.um,
            Unit::Arcsec => a.arcsec,
        }
    }
}

/// One run's values of one series, in the series' unit.
#[derive(Clone, Debug)]
pub(super) struct Point {
    pub(super) run: i64,
    pub(super) started: String,
    pub(super) t: Option<i64>,
    pub(super) before: f64,
    pub(super) after: f64,
    /// The standard uncertainty (k = 1) of `after`, in the series' unit (None: not
    /// recorded).
    pub(super) u: Option<f64>,
    /// maxModification in the series' unit (errors only).
    pub(super) tol: Option<f64>,
}

/// What a series shows: the page charts them in two sections.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum SeriesKind {
    /// An ISO 230-7 error of a rotary axis identified by cycle 451.
    Error,
    /// A rotary axis's dispersion over the sphere's points.
    Dispersion,
}

#[derive(Clone, Debug)]
pub(super) struct Series {
    pub(super) kind: SeriesKind,
    pub(super) title: String,
    pub(super) unit: Unit,
    pub(super) points: Vec<Point>,
}

/// What a series says about its runs.
#[derive(Clone, Debug)]
pub(super) struct Verdict {
    /// Change of the identified value since the previous run.
    pub(super) change: Option<f64>,
    /// Since the first run shown.
    pub(super) drift: f64,
    /// Indices of the runs whose change exceeds the alarm.
    pub(super) alarms: Vec<usize>,
    /// Indices of the runs whose change exceeds 2 combined standard uncertainties
    /// (of this run and the previous): a change, not noise.
    pub(super) moved: Vec<usize>,
    /// The latest correction (after - before) within maxModification.
    pub(super) in_tolerance: Option<bool>,
    pub(super) threshold: f64,
}

impl Series {
    pub(super) fn verdict(&self, alarm: &Alarm) -> Verdict {
        let threshold = self.unit.threshold(alarm);
        let p = &self.points;
        let alarms = (1..p.len())
            .filter(|&i| (p[i].after - p[i - 1].after).abs() > threshold)
            .collect();
        let moved = (1..p.len())
            .filter(|&i| {
                let change = (p[i].after - p[i - 1].after).abs();
                combined(p[i].u, p[i - 1].u).is_some_and(|uc| change > 2.0 * uc)
            })
            .collect();
        let last = p.last();
        Verdict {
            moved,
            change: (p.len() >= 2).then(|| p[p.len() - 1].after - p[p.len() - 2].after),
            drift: match (p.first(), last) {
                (Some(a), Some(b)) => b.after - a.after,
                _ => 0.0,
            },
            alarms,
            in_tolerance: last.and_then(|l| l.tol.map(|t| (l.after - l.before).abs() <= t)),
            threshold,
        }
    }

    /// The combined standard uncertainty of the change from run `i - 1` to run `i`.
    pub(super) fn change_u(&self, i: usize) -> Option<f64> {
        let p = &self.points;
        (i >= 1 && i < p.len())
            .then(|| combined(p[i].u, p[i - 1].u))
            .flatten()
    }

    /// How strongly it moved, in alarms: the order of the summary.
    pub(super) fn weight(&self, v: &Verdict) -> f64 {
        v.drift.abs().max(v.change.unwrap_or(0.0).abs()) / v.threshold.max(1e-12)
    }
}

pub(super) fn done_runs<'a>(
    runs: &'a [RunRow],
    machine: &'a str,
) -> impl Iterator<Item = &'a RunRow> {
    runs.iter()
        .filter(move |r| r.status == RunStatus::Done && r.machine == machine)
}

/// The errors (by ISO name) and dispersions (by axis) of `machine`'s completed runs.
pub(super) fn collect(runs: &[RunRow], machine: &str) -> Vec<Series> {
    let mut errors: BTreeMap<&str, Vec<Point>> = BTreeMap::new();
    let mut dispersion: BTreeMap<&str, Vec<Point>> = BTreeMap::new();
    for r in done_runs(runs, machine) {
        let point = |unit: Unit, before: f64, after: f64, u: Option<f64>, tol: Option<f64>| Point {
            run: r.id,
            started: r.started.clone(),
            t: parse_utc(&r.started),
            before: before * unit.scale(),
            after: after * unit.scale(),
            u: u.map(|u| u * unit.scale()),
            tol: tol.map(|t| t * unit.scale()),
        };
        for e in &r.iso_errors {
            let u = Unit::of_error(&e.name);
            errors.entry(&e.name).or_default().push(point(
                u,
                e.before,
                e.after,
                e.u,
                r.max_modification,
            ));
        }
        for d in &r.dispersion {
            // Dispersion is a length (mm).
            dispersion.entry(&d.axis).or_default().push(point(
                Unit::Um,
                d.before,
                d.after,
                None,
                None,
            ));
        }
    }
    let errors = errors.into_iter().map(|(name, points)| Series {
        kind: SeriesKind::Error,
        title: name.to_string(),
        unit: Unit::of_error(name),
        points,
    });
    let dispersion = dispersion.into_iter().map(|(axis, points)| Series {
        kind: SeriesKind::Dispersion,
        title: format!("dispersion {axis}"),
        unit: Unit::Um,
        points,
    });
    errors.chain(dispersion).collect()
}

/// `sqrt(a² + b²)` of two independent standard uncertainties, when both are known.
pub(super) fn combined(a: Option<f64>, b: Option<f64>) -> Option<f64> {
    Some(a?.hypot(b?))
}

/// The machines of the history with a completed run, in order: the index's pages.
pub fn machines(runs: &[RunRow]) -> Vec<String> {
    let set: std::collections::BTreeSet<&str> = runs
        .iter()
        .filter(|r| r.status == RunStatus::Done)
        .map(|r| r.machine.as_str())
        .collect();
    set.into_iter().map(str::to_string).collect()
}
