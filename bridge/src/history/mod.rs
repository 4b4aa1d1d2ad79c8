//! Calibration history: every measurement (who asked, the program, how it ended, every
//! Q result, cycle 451's errors before and after by ISO name, the measuring logs) in
//! an SQLite file, one per gateway. A run is recorded as "running" before the first
//! move and completed in one transaction at its end, so a gateway killed mid-run
//! leaves the run visible as "running", never half-written results.

pub mod time;
pub mod trend;

use cycles::results::ProgramReport;
use rusqlite::{params, Connection, OptionalExtension};
use serde::Serialize;
use std::path::{Path, PathBuf};

const SCHEMA: &str = "
CREATE TABLE IF NOT EXISTS runs (
    id INTEGER PRIMARY KEY,
    started TEXT NOT NULL,
    finished TEXT,
    machine TEXT NOT NULL,
    source TEXT NOT NULL,
    request_seq INTEGER,
    program_number INTEGER,
    program TEXT NOT NULL,
    status TEXT NOT NULL,
    message TEXT,
    protocols TEXT NOT NULL DEFAULT '[]',
    max_modification REAL
);
CREATE INDEX IF NOT EXISTS runs_machine_started ON runs (machine, started);
CREATE TABLE IF NOT EXISTS results (
    run_id INTEGER NOT NULL REFERENCES runs (id),
    position INTEGER NOT NULL,
    block INTEGER NOT NULL,
    cycle INTEGER NOT NULL,
    name TEXT NOT NULL,
    value REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS iso_errors (
    run_id INTEGER NOT NULL REFERENCES runs (id),
    block INTEGER NOT NULL,
    name TEXT NOT NULL,
    before REAL NOT NULL,
    after REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS axis_dispersion (
    run_id INTEGER NOT NULL REFERENCES runs (id),
    block INTEGER NOT NULL,
    axis TEXT NOT NULL,
    before REAL NOT NULL,
    after REAL NOT NULL
);
";

#[derive(Debug, thiserror::Error)]
#[error("history {path}: {message}")]
pub struct HistoryError {
    pub path: PathBuf,
    pub message: String,
}

/// Who started a run.
#[derive(Clone, Debug)]
pub struct RunStart<'a> {
    pub machine: &'a str,
    /// "serve" or "run".
    pub source: &'a str,
    pub request_seq: Option<u16>,
    pub program_number: Option<u16>,
    pub program: &'a Path,
    /// The machine's maxModification (the trend page's band).
    pub max_modification: Option<f64>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ResultRow {
    pub block: u32,
    pub cycle: u16,
    pub name: String,
    pub value: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct IsoErrorRow {
    pub block: u32,
    pub name: String,
    pub before: f64,
    pub after: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DispersionRow {
    pub block: u32,
    pub axis: String,
    pub before: f64,
    pub after: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RunRow {
    pub id: i64,
    pub started: String,
    pub finished: Option<String>,
    pub machine: String,
    pub source: String,
    pub request_seq: Option<u16>,
    pub program_number: Option<u16>,
    pub program: String,
    pub status: String,
    pub message: Option<String>,
    pub protocols: Vec<String>,
    pub results: Vec<ResultRow>,
    pub iso_errors: Vec<IsoErrorRow>,
    pub max_modification: Option<f64>,
    pub dispersion: Vec<DispersionRow>,
}

/// Which runs to list.
#[derive(Clone, Debug, Default)]
pub struct Filter {
    pub machine: Option<String>,
    /// ISO 8601 UTC, `YYYY-MM-DD` or `YYYY-MM-DDTHH:MM:SSZ`: runs started at or after.
    pub since: Option<String>,
}

pub struct History {
    conn: Connection,
    path: PathBuf,
}

impl History {
    pub fn open(path: &Path) -> Result<Self, HistoryError> {
        let err = |e: rusqlite::Error| HistoryError {
            path: path.to_path_buf(),
            message: e.to_string(),
        };
        let conn = Connection::open(path).map_err(err)?;
        conn.busy_timeout(std::time::Duration::from_secs(5))
            .map_err(err)?;
        // WAL: a reader (`probebridge history`) never blocks the gateway's writes, and
        // a crash leaves the last committed transaction.
        conn.pragma_update(None, "journal_mode", "WAL")
            .map_err(err)?;
        conn.execute_batch(SCHEMA).map_err(err)?;
        Ok(Self {
            conn,
            path: path.to_path_buf(),
        })
    }

    fn err(&self, e: rusqlite::Error) -> HistoryError {
        HistoryError {
            path: self.path.clone(),
            message: e.to_string(),
        }
    }

    /// Records a run as "running" before it moves; its id.
    pub fn begin(&self, run: &RunStart) -> Result<i64, HistoryError> {
        self.conn
            .execute(
                "INSERT INTO runs (started, machine, source, request_seq, program_number, program, status, max_modification)
                 VALUES (?1, ?2, ?3, ?4, ?5, ?6, 'running', ?7)",
                params![
                    time::now_utc(),
                    run.machine,
                    run.source,
                    run.request_seq,
                    run.program_number,
                    run.program.display().to_string(),
                    run.max_modification,
                ],
            )
            .map_err(|e| self.err(e))?;
        Ok(self.conn.last_insert_rowid())
    }

    /// Completes run `id`: status ("done", "error", "aborted"), every result, in one
    /// transaction.
    pub fn finish(
        &mut self,
        id: i64,
        status: &str,
        report: &ProgramReport,
    ) -> Result<(), HistoryError> {
        let path = self.path.clone();
        let err = |e: rusqlite::Error| HistoryError {
            path: path.clone(),
            message: e.to_string(),
        };
        let tx = self.conn.transaction().map_err(err)?;
        let protocols: Vec<String> = report
            .protocols
            .iter()
            .map(|p| p.display().to_string())
            .collect();
        let protocols = serde_json::to_string(&protocols).expect("strings serialise");
        tx.execute(
            "UPDATE runs SET finished = ?1, status = ?2, message = ?3, protocols = ?4 WHERE id = ?5",
            params![time::now_utc(), status, report.stopped, protocols, id],
        )
        .map_err(err)?;
        for (position, c) in report.cycles.iter().enumerate() {
            for (name, value) in &c.q {
                tx.execute(
                    "INSERT INTO results (run_id, position, block, cycle, name, value) VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
                    params![id, position as i64, c.block, c.cycle, name, value],
                )
                .map_err(err)?;
            }
            if let Some(k) = &c.kinematics {
                for (name, before) in &k.errors_before {
                    let after = k.errors_after.get(name).copied().unwrap_or(*before);
                    tx.execute(
                        "INSERT INTO iso_errors (run_id, block, name, before, after) VALUES (?1, ?2, ?3, ?4, ?5)",
                        params![id, c.block, name, before, after],
                    )
                    .map_err(err)?;
                }
                for a in &k.axes {
                    tx.execute(
                        "INSERT INTO axis_dispersion (run_id, block, axis, before, after) VALUES (?1, ?2, ?3, ?4, ?5)",
                        params![id, c.block, a.axis, a.dispersion_before, a.dispersion_after],
                    )
                    .map_err(err)?;
                }
            }
        }
        tx.commit().map_err(err)
    }

    pub fn list(&self, filter: &Filter) -> Result<Vec<RunRow>, HistoryError> {
        let mut stmt = self
            .conn
            .prepare(
                "SELECT id, started, finished, machine, source, request_seq, program_number, program, status, message, protocols, max_modification
                 FROM runs WHERE (?1 IS NULL OR machine = ?1) AND (?2 IS NULL OR started >= ?2) ORDER BY started, id",
            )
            .map_err(|e| self.err(e))?;
        let rows = stmt
            .query_map(params![filter.machine, filter.since], |r| {
                let protocols: String = r.get(10)?;
                Ok(RunRow {
                    id: r.get(0)?,
                    started: r.get(1)?,
                    finished: r.get(2)?,
                    machine: r.get(3)?,
                    source: r.get(4)?,
                    request_seq: r.get(5)?,
                    program_number: r.get(6)?,
                    program: r.get(7)?,
                    status: r.get(8)?,
                    message: r.get(9)?,
                    protocols: serde_json::from_str(&protocols).unwrap_or_default(),
                    results: Vec::new(),
                    iso_errors: Vec::new(),
                    max_modification: r.get(11)?,
                    dispersion: Vec::new(),
                })
            })
            .map_err(|e| self.err(e))?;
        let mut runs = Vec::new();
        for row in rows {
            let mut run = row.map_err(|e| self.err(e))?;
            run.results = self.results(run.id)?;
            run.iso_errors = self.iso_errors(run.id)?;
            run.dispersion = self.dispersion(run.id)?;
            runs.push(run);
        }
        Ok(runs)
    }

    fn results(&self, id: i64) -> Result<Vec<ResultRow>, HistoryError> {
        let mut stmt = self
            .conn
            .prepare_cached(
                "SELECT block, cycle, name, value FROM results WHERE run_id = ?1 ORDER BY position, name",
            )
            .map_err(|e| self.err(e))?;
        let rows = stmt
            .query_map([id], |r| {
                Ok(ResultRow {
                    block: r.get(0)?,
                    cycle: r.get(1)?,
                    name: r.get(2)?,
                    value: r.get(3)?,
                })
            })
            .map_err(|e| self.err(e))?;
        rows.collect::<Result<_, _>>().map_err(|e| self.err(e))
    }

    fn iso_errors(&self, id: i64) -> Result<Vec<IsoErrorRow>, HistoryError> {
        let mut stmt = self
            .conn
            .prepare_cached(
                "SELECT block, name, before, after FROM iso_errors WHERE run_id = ?1 ORDER BY block, name",
            )
            .map_err(|e| self.err(e))?;
        let rows = stmt
            .query_map([id], |r| {
                Ok(IsoErrorRow {
                    block: r.get(0)?,
                    name: r.get(1)?,
                    before: r.get(2)?,
                    after: r.get(3)?,
                })
            })
            .map_err(|e| self.err(e))?;
        rows.collect::<Result<_, _>>().map_err(|e| self.err(e))
    }

    fn dispersion(&self, id: i64) -> Result<Vec<DispersionRow>, HistoryError> {
        let mut stmt = self
            .conn
            .prepare_cached(
                "SELECT block, axis, before, after FROM axis_dispersion WHERE run_id = ?1 ORDER BY block, axis",
            )
            .map_err(|e| self.err(e))?;
        let rows = stmt
            .query_map([id], |r| {
                Ok(DispersionRow {
                    block: r.get(0)?,
                    axis: r.get(1)?,
                    before: r.get(2)?,
                    after: r.get(3)?,
                })
            })
            .map_err(|e| self.err(e))?;
        rows.collect::<Result<_, _>>().map_err(|e| self.err(e))
    }

    /// Runs still "running" (the gateway died during them) become "interrupted".
    pub fn close_interrupted(&self) -> Result<usize, HistoryError> {
        self.conn
            .execute(
                "UPDATE runs SET status = 'interrupted' WHERE status = 'running'",
                [],
            )
            .map_err(|e| self.err(e))
    }

    /// The number of runs (tests, logs).
    pub fn count(&self) -> Result<i64, HistoryError> {
        self.conn
            .query_row("SELECT COUNT(*) FROM runs", [], |r| r.get(0))
            .optional()
            .map(|n| n.unwrap_or(0))
            .map_err(|e| self.err(e))
    }
}

/// `probebridge run --history FILE`: the run recorded as started, before it moves.
pub fn record_run_start(
    path: Option<&Path>,
    cfg: &cycles::CyclesConfig,
    program: &cycles::program::Program,
) -> Result<Option<(History, i64)>, String> {
    let Some(path) = path else { return Ok(None) };
    let h = History::open(path).map_err(|e| e.to_string())?;
    let program_path = program.path.clone().unwrap_or_default();
    let id = h
        .begin(&RunStart {
            machine: &cfg.machine.name,
            source: "run",
            request_seq: None,
            program_number: None,
            program: &program_path,
            max_modification: Some(cfg.parameters.max_modification),
        })
        .map_err(|e| e.to_string())?;
    Ok(Some((h, id)))
}

/// One line per run: id, start, machine, program, status, results.
pub fn to_text(runs: &[RunRow]) -> String {
    let mut s = String::new();
    for r in runs {
        let program = Path::new(&r.program)
            .file_name()
            .map_or(r.program.clone(), |f| f.to_string_lossy().into_owned());
        s.push_str(&format!(
            "{:>5}  {}  {:<20} {:<24} {:<11} {:>3} results",
            r.id,
            r.started,
            r.machine,
            program,
            r.status,
            r.results.len()
        ));
        for e in &r.iso_errors {
            s.push_str(&format!("  {} {:+.4}->{:+.4}", e.name, e.before, e.after));
        }
        s.push('\n');
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use cycles::results::{CycleResult, Status};

    fn report() -> ProgramReport {
        ProgramReport {
            cycles: vec![CycleResult {
                block: 6,
                cycle: 431,
                q: [("Q158".to_string(), 5.0), ("Q159".into(), -3.0)]
                    .into_iter()
                    .collect(),
                qs: Default::default(),
                status: Status::Ok,
                message: None,
                kinematics: None,
            }],
            stopped: None,
            aborted: false,
            protocols: vec![PathBuf::from("/tmp/TCHPR431.TXT")],
        }
    }

    #[test]
    fn a_run_is_recorded_and_listed_by_machine_and_date() {
        let dir = std::env::temp_dir().join(format!("pb-history-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let mut h = History::open(&dir.join("h.sqlite")).unwrap();
        let start = RunStart {
            machine: "table-ac",
            source: "serve",
            request_seq: Some(3),
            program_number: Some(431),
            program: Path::new("/p/431.h"),
            max_modification: Some(0.05),
        };
        let id = h.begin(&start).unwrap();
        assert_eq!(h.list(&Filter::default()).unwrap()[0].status, "running");
        h.finish(id, "done", &report()).unwrap();
        let other = h
            .begin(&RunStart {
                machine: "other",
                ..start.clone()
            })
            .unwrap();
        assert_eq!(h.close_interrupted().unwrap(), 1);
        let runs = h
            .list(&Filter {
                machine: Some("table-ac".into()),
                since: Some("2000-01-01".into()),
            })
            .unwrap();
        assert_eq!(runs.len(), 1);
        let r = &runs[0];
        assert_eq!((r.status.as_str(), r.request_seq), ("done", Some(3)));
        assert_eq!(r.results.len(), 2);
        assert_eq!(r.results[0].name, "Q158");
        assert_eq!(r.protocols, vec!["/tmp/TCHPR431.TXT".to_string()]);
        assert!(h
            .list(&Filter {
                since: Some("2999-01-01".into()),
                ..Filter::default()
            })
            .unwrap()
            .is_empty());
        let all = h.list(&Filter::default()).unwrap();
        assert_eq!(
            all.iter().find(|r| r.id == other).unwrap().status,
            "interrupted"
        );
        assert!(to_text(&all).contains("431.h"));
    }
}
