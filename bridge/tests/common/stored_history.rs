//! A calibration history made directly through the history API: cycle 451 runs with
//! the errors, dispersions, machine names and dates a test chooses (a drift over
//! weeks, a tampered name), without the weeks.

use cycles::results::{CycleResult, ProgramReport, Status};
use probebridge::history::{History, HistoryTarget, RunStart, RunStatus};
use std::path::Path;

pub struct StoredRun<'a> {
    pub machine: &'a str,
    /// ISO 8601 UTC, the run's start as the history keeps it.
    pub started: &'a str,
    /// (ISO name, before, after): mm or deg.
    pub errors: &'a [(&'a str, f64, f64)],
    /// (axis, before, after), mm.
    pub dispersion: &'a [(&'a str, f64, f64)],
    pub max_modification: f64,
    pub program: &'a str,
}

fn report(run: &StoredRun) -> ProgramReport {
    let names = |pick: fn(&(&str, f64, f64)) -> f64| -> serde_json::Map<String, serde_json::Value> {
        run.errors
            .iter()
            .map(|e| (e.0.to_string(), pick(e).into()))
            .collect()
    };
    let axes: Vec<serde_json::Value> = run
        .dispersion
        .iter()
        .map(|(axis, before, after)| {
            serde_json::json!({
                "axis": axis, "start": 0.0, "end": 90.0, "points": 4, "hirth": 0.0,
                "pivot": [0.0, 0.0, 0.0], "circle_radius": 100.0, "backlash": null,
                "dispersion_before": before, "max_before": before,
                "dispersion_after": after, "max_after": after,
                "positioning_error_mean": 0.0, "positioning_error_std": 0.0,
                "errors_before": {}, "errors_after": {}, "positions": []
            })
        })
        .collect();
    let kinematics = serde_json::json!({
        "mode": 0, "machine": run.machine, "kinematics_file": "k.toml",
        "estimator": "in-process", "probe": "TS 460", "written": false,
        "incidence": {}, "preset_before": [0.0, 0.0, 0.0], "preset_after": [0.0, 0.0, 0.0],
        "preset_shift": [0.0, 0.0, 0.0], "offset_error": [0.0, 0.0, 0.0],
        "errors_before": names(|e| e.1), "errors_after": names(|e| e.2),
        "axes": axes, "notes": []
    });
    ProgramReport {
        cycles: vec![CycleResult {
            block: 11,
            cycle: 451,
            q: Default::default(),
            qs: Default::default(),
            status: Status::Ok,
            message: None,
            u: Default::default(),
            kinematics: Some(Box::new(serde_json::from_value(kinematics).unwrap())),
            calibration: None,
            machine_time_s: None,
            machine_time_split_s: None,
        }],
        ..ProgramReport::default()
    }
}

/// Records `runs` in the SQLite history `db`; their ids.
pub fn store(db: &Path, runs: &[StoredRun]) -> Vec<i64> {
    let mut h = History::open(&HistoryTarget::Sqlite(db.to_path_buf())).unwrap();
    let ids: Vec<i64> = runs
        .iter()
        .map(|r| {
            let id = h
                .begin(&RunStart {
                    machine: r.machine,
                    source: "serve",
                    request_seq: Some(1),
                    program_number: Some(451),
                    program: Path::new(r.program),
                    max_modification: Some(r.max_modification),
                    parameters: &[],
                })
                .unwrap();
            h.finish(id, RunStatus::Done, &report(r)).unwrap();
            id
        })
        .collect();
    drop(h);
    // The history stamps the clock's time; these runs happened on other days.
    let c = rusqlite::Connection::open(db).unwrap();
    for (id, r) in ids.iter().zip(runs) {
        c.execute(
            "UPDATE runs SET started = ?1 WHERE id = ?2",
            rusqlite::params![r.started, id],
        )
        .unwrap();
    }
    ids
}
