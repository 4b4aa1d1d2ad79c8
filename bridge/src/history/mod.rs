//! Calibration history: every measurement (who asked, the program, how it ended, every
//! Q result, cycle 451's errors before and after by ISO name, the measuring logs) in
//! an SQLite file, one per gateway ([`sqlite`]), or on a central PostgreSQL server that
//! many gateways report into ([`postgres`]): the same tables in both. A run is recorded
//! as "running" before the first move and completed in one transaction at its end, so
//! a gateway killed mid-run leaves the run visible as "running", never half-written
//! results. The gateway reaches its history through a [`recorder::Recorder`]: a thread
//! of its own with bounded waits, and a [`spool`] for ends of runs the history could not
//! take when they happened.

pub mod postgres;
pub mod recorder;
pub mod spool;
pub mod sqlite;
pub mod status;
pub mod time;
pub mod trend;

use cycles::results::ProgramReport;
use serde::{Deserialize, Serialize};
pub use status::RunStatus;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// How long the history may take: the connection (PostgreSQL), each statement or
/// transaction (SQLite: the wait for another process's lock), and the TCP keepalive
/// (PostgreSQL: idle time before the first probe).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Timeouts {
    pub connect: Duration,
    pub statement: Duration,
    pub keepalive: Duration,
}

impl Default for Timeouts {
    fn default() -> Self {
        Self {
            connect: Duration::from_secs(3),
            statement: Duration::from_secs(2),
            keepalive: Duration::from_secs(10),
        }
    }
}

#[derive(Debug, thiserror::Error)]
#[error("history {target}: {message}")]
pub struct HistoryError {
    /// The file, or the server's URL without its password.
    pub target: String,
    pub kind: HistoryErrorKind,
    pub message: String,
}

impl HistoryError {
    pub fn kind(&self) -> HistoryErrorKind {
        self.kind
    }
}

/// What a history operation failed on, where its caller acts on it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HistoryErrorKind {
    /// The run to complete is not in the history (one restored from before the run
    /// began): not the store's failure; the history works.
    NoRun,
    /// The history cannot take or give what was asked: unreachable, unreadable,
    /// refused, or no answer in time.
    Unavailable,
}

/// A backend's error: its kind, and what happened.
#[derive(Debug)]
struct StoreError {
    kind: HistoryErrorKind,
    message: String,
}

impl StoreError {
    fn no_run(id: i64) -> Self {
        StoreError {
            kind: HistoryErrorKind::NoRun,
            message: format!("there is no run {id} to complete"),
        }
    }
}

impl From<String> for StoreError {
    fn from(message: String) -> Self {
        StoreError {
            kind: HistoryErrorKind::Unavailable,
            message,
        }
    }
}

/// Where the history is kept: an SQLite file, or a PostgreSQL server named by a
/// `postgres://` (or `postgresql://`) URL.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum HistoryTarget {
    Sqlite(PathBuf),
    Postgres(String),
}

impl HistoryTarget {
    /// A URL starting `postgres://` or `postgresql://`, else a file path.
    pub fn parse(s: &str) -> Self {
        if s.starts_with("postgres://") || s.starts_with("postgresql://") {
            HistoryTarget::Postgres(s.to_string())
        } else {
            HistoryTarget::Sqlite(PathBuf::from(s))
        }
    }

    /// A command-line argument: a path, or a URL.
    pub fn from_arg(p: &Path) -> Self {
        match p.to_str() {
            Some(s) => Self::parse(s),
            None => HistoryTarget::Sqlite(p.to_path_buf()),
        }
    }

    /// For messages and logs: the URL's password is left out.
    pub fn display(&self) -> String {
        match self {
            HistoryTarget::Sqlite(p) => p.display().to_string(),
            HistoryTarget::Postgres(url) => redact(url),
        }
    }
}

/// `postgres://user:secret@host/db` -> `postgres://user:***@host/db`.
fn redact(url: &str) -> String {
    let Some((scheme, rest)) = url.split_once("://") else {
        return url.to_string();
    };
    let (auth, host) = match rest.rsplit_once('@') {
        Some(x) => x,
        None => return url.to_string(),
    };
    match auth.split_once(':') {
        Some((user, _)) => format!("{scheme}://{user}:***@{host}"),
        None => url.to_string(),
    }
}

/// What a backend keeps: the same operations on SQLite and PostgreSQL.
trait Store: Send {
    fn begin(&mut self, run: &NewRun, now: &str) -> Result<i64, String>;
    /// Completes run `id` in one transaction, if it is still `running` (or was marked
    /// `interrupted`): a run already completed is left alone, so that an end recorded
    /// twice (a retry, a replayed spool) makes one row. Errs when there is no run `id`.
    fn finish(&mut self, id: i64, rows: &Rows) -> Result<(), StoreError>;
    /// Removes run `id` and its rows: begun for a start that was refused after all.
    fn discard(&mut self, id: i64) -> Result<(), String>;
    fn list(&mut self, filter: &Filter) -> Result<Vec<RunRow>, String>;
    fn close_interrupted(&mut self, machine: &str) -> Result<usize, String>;
    fn count(&mut self) -> Result<i64, String>;
    /// The run begun as `start` says (machine, start time, program, source, request
    /// sequence), `id` first if it is that run, if the history has it: a spooled end
    /// finds its run by what it is, not by an id a fresh file may have given another.
    fn find_run(&mut self, id: i64, start: &spool::SpooledStart) -> Result<Option<i64>, String>;
    /// Whether the store reads back whole (SQLite: `PRAGMA quick_check`); a server
    /// checks its own files.
    fn check(&mut self) -> Result<(), String> {
        Ok(())
    }
}

/// Run `id`'s status word as the history holds it; an error naming the run if it is
/// none of [`RunStatus`]'s (a row written by hand).
fn status_of(id: i64, word: &str) -> Result<RunStatus, String> {
    word.parse().map_err(|e| format!("run {id}: {e}"))
}

/// The end of a run as rows, the same for every backend (and in the spool).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Rows {
    finished: String,
    status: RunStatus,
    message: Option<String>,
    /// JSON list of the measuring logs.
    protocols: String,
    /// (position of the cycle in the program, result).
    results: Vec<(i64, ResultRow)>,
    iso_errors: Vec<IsoErrorRow>,
    dispersion: Vec<DispersionRow>,
    /// The cycles' machine time, s (`None`: no cycle ran; a spool written before
    /// the column has none).
    #[serde(default)]
    machine_time_s: Option<f64>,
}

impl Rows {
    fn of(status: RunStatus, report: &ProgramReport) -> Self {
        let protocols: Vec<String> = report
            .protocols
            .iter()
            .map(|p| p.display().to_string())
            .collect();
        let mut rows = Rows {
            finished: time::now_utc(),
            status,
            message: report.stopped.clone(),
            protocols: serde_json::to_string(&protocols).expect("strings serialise"),
            results: Vec::new(),
            iso_errors: Vec::new(),
            dispersion: Vec::new(),
            machine_time_s: report
                .cycles
                .iter()
                .filter_map(|c| c.machine_time_s)
                .reduce(|a, b| a + b),
        };
        for (position, c) in report.cycles.iter().enumerate() {
            for (name, value) in &c.q {
                rows.results.push((
                    position as i64,
                    ResultRow {
                        block: c.block,
                        cycle: c.cycle,
                        name: name.clone(),
                        value: *value,
                        u: c.u.get(name).copied(),
                    },
                ));
            }
            if let Some(k) = &c.kinematics {
                for (name, before) in &k.errors_before {
                    rows.iso_errors.push(IsoErrorRow {
                        block: c.block,
                        name: name.clone(),
                        before: *before,
                        after: k.errors_after.get(name).copied().unwrap_or(*before),
                        u: k.errors_u.get(name).copied(),
                    });
                }
                for a in &k.axes {
                    rows.dispersion.push(DispersionRow {
                        block: c.block,
                        axis: a.axis.clone(),
                        before: a.dispersion_before,
                        after: a.dispersion_after,
                    });
                }
            }
        }
        rows
    }
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
    /// The request's parameters 1..8 (a start from the PLC), in order; empty for `run`.
    pub parameters: &'a [f64],
}

/// A run as it is begun (owned, for the recorder's thread; in the spool with its end).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NewRun {
    pub machine: String,
    pub source: String,
    pub request_seq: Option<u16>,
    pub program_number: Option<u16>,
    pub program: PathBuf,
    pub max_modification: Option<f64>,
    pub parameters: Vec<f64>,
}

impl From<&RunStart<'_>> for NewRun {
    fn from(r: &RunStart<'_>) -> Self {
        Self {
            machine: r.machine.to_string(),
            source: r.source.to_string(),
            request_seq: r.request_seq,
            program_number: r.program_number,
            program: r.program.to_path_buf(),
            max_modification: r.max_modification,
            parameters: r.parameters.to_vec(),
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ResultRow {
    pub block: u32,
    pub cycle: u16,
    pub name: String,
    pub value: f64,
    /// Its standard uncertainty (k = 1); None: none reported (or recorded before).
    #[serde(default)]
    pub u: Option<f64>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct IsoErrorRow {
    pub block: u32,
    pub name: String,
    pub before: f64,
    pub after: f64,
    /// The standard uncertainty (k = 1) of `after`; None: not identified (or
    /// recorded before uncertainties were).
    #[serde(default)]
    pub u: Option<f64>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
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
    pub status: RunStatus,
    pub message: Option<String>,
    pub protocols: Vec<String>,
    pub results: Vec<ResultRow>,
    pub iso_errors: Vec<IsoErrorRow>,
    pub max_modification: Option<f64>,
    /// How long the run's cycles kept the machine, s (`None`: unfinished, or
    /// recorded before the machine time was).
    pub machine_time_s: Option<f64>,
    pub dispersion: Vec<DispersionRow>,
    /// The request's parameters 1..8 (empty: not started by the PLC).
    pub parameters: Vec<f64>,
}

/// Which runs to list.
#[derive(Clone, Debug, Default)]
pub struct Filter {
    pub machine: Option<String>,
    /// ISO 8601 UTC, `YYYY-MM-DD` or `YYYY-MM-DDTHH:MM:SSZ`: runs started at or after.
    pub since: Option<String>,
}

pub struct History {
    store: Box<dyn Store>,
    target: HistoryTarget,
}

impl History {
    /// Opens (and creates the tables of) the history at `target`, for a command
    /// (`history`, `run --history`): with room for a long listing or a slow server.
    pub fn open(target: &HistoryTarget) -> Result<Self, HistoryError> {
        Self::open_with(
            target,
            &Timeouts {
                connect: Duration::from_secs(10),
                statement: Duration::from_secs(30),
                ..Timeouts::default()
            },
        )
    }

    /// As [`History::open`], within `timeouts`.
    pub fn open_with(target: &HistoryTarget, timeouts: &Timeouts) -> Result<Self, HistoryError> {
        let store: Result<Box<dyn Store>, String> = match target {
            HistoryTarget::Sqlite(path) => {
                sqlite::SqliteStore::open(path, timeouts).map(|s| Box::new(s) as Box<dyn Store>)
            }
            HistoryTarget::Postgres(url) => {
                postgres::PgStore::open(url, timeouts).map(|s| Box::new(s) as Box<dyn Store>)
            }
        };
        let store = store.map_err(|message| HistoryError {
            target: target.display(),
            kind: HistoryErrorKind::Unavailable,
            message,
        })?;
        Ok(Self {
            store,
            target: target.clone(),
        })
    }

    pub fn target(&self) -> &HistoryTarget {
        &self.target
    }

    /// A backend's error (or its message: the history unavailable) as this history's.
    fn err(&self, e: impl Into<StoreError>) -> HistoryError {
        let StoreError { kind, message } = e.into();
        HistoryError {
            target: self.target.display(),
            kind,
            message,
        }
    }

    /// Records a run as "running" before it moves; its id.
    pub fn begin(&mut self, run: &RunStart) -> Result<i64, HistoryError> {
        self.begin_at(&NewRun::from(run), &time::now_utc())
    }

    /// Records run `run` begun at `started` as `running`; its id.
    fn begin_at(&mut self, run: &NewRun, started: &str) -> Result<i64, HistoryError> {
        self.store.begin(run, started).map_err(|e| self.err(e))
    }

    fn finish_rows(&mut self, id: i64, rows: &Rows) -> Result<(), HistoryError> {
        self.store.finish(id, rows).map_err(|e| self.err(e))
    }

    /// Completes a spooled end. With its start, the run is found by what it is
    /// (machine, start time, program, source, request sequence; its id first, for two
    /// runs begun within the same second), or begun anew when the history does not have it
    /// (a fresh file that replaced a corrupted one): never another run under its old
    /// id. Without (a spool from before starts were kept), by its id.
    fn finish_record(&mut self, record: &spool::SpoolRecord) -> Result<(), HistoryError> {
        let Some(start) = &record.start else {
            return self.finish_rows(record.id, &record.rows);
        };
        let found = self
            .store
            .find_run(record.id, start)
            .map_err(|e| self.err(e))?;
        let id = match found {
            Some(id) => id,
            None => self.begin_at(&start.run, &start.started)?,
        };
        self.finish_rows(id, &record.rows)
    }

    /// The store's integrity check (SQLite: `PRAGMA quick_check`).
    pub fn check(&mut self) -> Result<(), HistoryError> {
        self.store.check().map_err(|e| self.err(e))
    }

    fn discard(&mut self, id: i64) -> Result<(), HistoryError> {
        self.store.discard(id).map_err(|e| self.err(e))
    }

    /// Completes run `id`: its status (done, error, aborted), every result, in one
    /// transaction.
    pub fn finish(
        &mut self,
        id: i64,
        status: RunStatus,
        report: &ProgramReport,
    ) -> Result<(), HistoryError> {
        self.finish_rows(id, &Rows::of(status, report))
    }

    pub fn list(&mut self, filter: &Filter) -> Result<Vec<RunRow>, HistoryError> {
        self.store.list(filter).map_err(|e| self.err(e))
    }

    /// Runs of `machine` still "running" (its gateway died during them) become
    /// "interrupted"; other machines' runs on a shared server are left alone.
    pub fn close_interrupted(&mut self, machine: &str) -> Result<usize, HistoryError> {
        self.store
            .close_interrupted(machine)
            .map_err(|e| self.err(e))
    }

    /// The number of runs (tests, logs).
    pub fn count(&mut self) -> Result<i64, HistoryError> {
        self.store.count().map_err(|e| self.err(e))
    }
}

/// `probebridge run --history FILE|URL`: the run recorded as started, before it moves.
pub fn record_run_start(
    path: Option<&Path>,
    cfg: &cycles::CyclesConfig,
    program: &cycles::program::Program,
) -> Result<Option<(History, i64)>, String> {
    let Some(path) = path else { return Ok(None) };
    let mut h = History::open(&HistoryTarget::from_arg(path)).map_err(|e| e.to_string())?;
    let program_path = program.path.clone().unwrap_or_default();
    let id = h
        .begin(&RunStart {
            machine: &cfg.machine.name,
            source: "run",
            request_seq: None,
            program_number: None,
            program: &program_path,
            max_modification: Some(cfg.parameters.max_modification),
            parameters: &[],
        })
        .map_err(|e| e.to_string())?;
    Ok(Some((h, id)))
}

/// One line per run: id, start, machine, program, status, results. Stored strings
/// are printed escaped: a name with terminal escape codes cannot move the cursor,
/// recolour or retitle the terminal of whoever lists the history.
pub fn to_text(runs: &[RunRow]) -> String {
    let mut s = String::new();
    for r in runs {
        let program = Path::new(&r.program)
            .file_name()
            .map_or(r.program.clone(), |f| f.to_string_lossy().into_owned());
        s.push_str(&format!(
            "{:>5}  {}  {:<20} {:<24} {:<11} {:>3} results",
            r.id,
            printable(&r.started),
            printable(&r.machine),
            printable(&program),
            r.status,
            r.results.len()
        ));
        if let Some(t) = r.machine_time_s {
            s.push_str(&format!("  {t:.1} s"));
        }
        for e in &r.iso_errors {
            let name = printable(&e.name);
            s.push_str(&format!("  {name} {:+.4}->{:+.4}", e.before, e.after));
            if let Some(u) = e.u {
                s.push_str(&format!("±{u:.4}"));
            }
        }
        s.push('\n');
    }
    s
}

/// Control characters (ESC, BEL, CR, ...), the bidirectional and zero-width format
/// characters, and the backslash as Rust escapes (`\u{1b}`), the rest as it is.
pub fn printable(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        let format_char = matches!(c, '\u{200b}'..='\u{200f}' | '\u{202a}'..='\u{202e}' | '\u{2066}'..='\u{2069}' | '\u{feff}');
        if c.is_control() || c == '\\' {
            out.extend(c.escape_default());
        } else if format_char {
            out.extend(c.escape_unicode());
        } else {
            out.push(c);
        }
    }
    out
}

/// A folder of one test's own under the temporary folder, removed when the test ends,
/// however it ends: a run outside `scripts/test` (whose TMPDIR is removed) leaves
/// nothing in /tmp either.
#[cfg(test)]
pub(crate) struct TestDir(PathBuf);

#[cfg(test)]
impl TestDir {
    pub(crate) fn new(name: &str) -> Self {
        let d = std::env::temp_dir().join(format!("pb-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        TestDir(d)
    }
}

#[cfg(test)]
impl std::ops::Deref for TestDir {
    type Target = Path;

    fn deref(&self) -> &Path {
        &self.0
    }
}

#[cfg(test)]
impl Drop for TestDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
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
                u: [("Q158".to_string(), 0.0002)].into_iter().collect(),
                kinematics: None,
                calibration: None,
                machine_time_s: None,
                machine_time_split_s: None,
            }
            .timed(cycles::machine_time::TimeSplit {
                positioning: 3.25,
                rotary: 0.0,
                probing: 3.5,
                standing: 0.125,
            })],
            stopped: None,
            aborted: false,
            protocols: vec![PathBuf::from("/tmp/TCHPR431.TXT")],
            ..ProgramReport::default()
        }
    }

    /// A 431 the PLC started with request 3 and eight parameters.
    fn plc_431() -> RunStart<'static> {
        RunStart {
            machine: "table-ac",
            source: "serve",
            request_seq: Some(3),
            program_number: Some(431),
            program: Path::new("/p/431.h"),
            max_modification: Some(0.05),
            parameters: &[1.5, -2.25, 0.0, 0.0, 0.0, 0.0, 0.0, 7.0],
        }
    }

    #[test]
    fn a_run_is_recorded_and_listed_by_machine_and_date() {
        let dir = TestDir::new("history");
        let mut h = History::open(&HistoryTarget::Sqlite(dir.join("h.sqlite"))).unwrap();
        let start = plc_431();
        let id = h.begin(&start).unwrap();
        assert_eq!(
            h.list(&Filter::default()).unwrap()[0].status,
            RunStatus::Running
        );
        h.finish(id, RunStatus::Done, &report()).unwrap();
        let other = h
            .begin(&RunStart {
                machine: "other",
                ..start.clone()
            })
            .unwrap();
        assert_eq!(h.close_interrupted("other").unwrap(), 1);
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
        assert_eq!((r.results[0].u, r.results[1].u), (Some(0.0002), None));
        assert_eq!(r.parameters, [1.5, -2.25, 0.0, 0.0, 0.0, 0.0, 0.0, 7.0]);
        assert_eq!(r.protocols, vec!["/tmp/TCHPR431.TXT".to_string()]);
        assert!(h
            .list(&Filter {
                since: Some("2999-01-01".into()),
                ..Filter::default()
            })
            .unwrap()
            .is_empty());
        // The same end again (a retry, a replayed spool): still one set of rows.
        h.finish(id, RunStatus::Done, &report()).unwrap();
        assert_eq!(h.list(&Filter::default()).unwrap()[0].results.len(), 2);
        let e = h.finish(9999, RunStatus::Done, &report()).unwrap_err();
        assert_eq!(e.kind(), HistoryErrorKind::NoRun, "no such run: {e}");
        let all = h.list(&Filter::default()).unwrap();
        assert_eq!(
            all.iter().find(|r| r.id == other).unwrap().status,
            RunStatus::Interrupted
        );
        // A run marked interrupted whose end comes later (from the spool) is completed.
        h.finish(other, RunStatus::Aborted, &report()).unwrap();
        let all = h.list(&Filter::default()).unwrap();
        assert_eq!(
            all.iter().find(|r| r.id == other).unwrap().status,
            RunStatus::Aborted
        );
        assert!(to_text(&all).contains("431.h"));
    }

    #[test]
    fn a_status_written_by_hand_that_is_no_run_status_fails_the_listing_naming_the_run() {
        let dir = TestDir::new("history-status");
        let file = dir.join("h.sqlite");
        let mut h = History::open(&HistoryTarget::Sqlite(file.clone())).unwrap();
        let id = h.begin(&plc_431()).unwrap();
        h.finish(id, RunStatus::Done, &report()).unwrap();
        let c = rusqlite::Connection::open(&file).unwrap();
        c.execute("UPDATE runs SET status = 'finished' WHERE id = ?1", [id])
            .unwrap();
        drop(c);
        let e = h.list(&Filter::default()).unwrap_err().to_string();
        assert!(
            e.contains(&format!(
                "run {id}: status \"finished\" is not a run status"
            )),
            "{e}"
        );
    }

    #[test]
    fn a_spooled_end_replays_into_a_fresh_file_without_touching_another_run_of_its_id() {
        let dir = TestDir::new("history-fresh");
        let run = NewRun {
            machine: "table-ac".into(),
            source: "serve".into(),
            request_seq: Some(3),
            program_number: Some(431),
            program: PathBuf::from("/p/431.h"),
            max_modification: Some(0.05),
            parameters: vec![1.5],
        };
        // Run 1 of a file since corrupted: its end, with its start, in the spool.
        let start = spool::SpooledStart {
            run: run.clone(),
            started: "2026-11-28T10:00:00Z".into(),
        };
        let record = spool::SpoolRecord::new(
            "h".into(),
            1,
            Rows::of(RunStatus::Done, &report()),
            Some(start),
        );
        // The fresh file in its place, whose run 1 is another run begun since.
        let mut h = History::open(&HistoryTarget::Sqlite(dir.join("h.sqlite"))).unwrap();
        let other = NewRun {
            program: PathBuf::from("/p/444.h"),
            ..run.clone()
        };
        assert_eq!(h.begin_at(&other, "2026-11-28T11:00:00Z").unwrap(), 1);
        h.finish_record(&record).unwrap();
        // Replayed again (a crash before the spool forgot it): still one run.
        h.finish_record(&record).unwrap();
        let runs = h.list(&Filter::default()).unwrap();
        assert_eq!(runs.len(), 2, "{runs:?}");
        let r = runs.iter().find(|r| r.program == "/p/431.h").unwrap();
        assert_eq!(
            (r.status.as_str(), r.started.as_str(), r.results.len()),
            ("done", "2026-11-28T10:00:00Z", 2)
        );
        assert_eq!(r.parameters, [1.5]);
        let o = runs.iter().find(|r| r.id == 1).unwrap();
        assert_eq!(
            (o.program.as_str(), o.status.as_str()),
            ("/p/444.h", "running")
        );
        // Two runs alike begun within the same second (an abort, a start at once; OPC
        // UA's have no sequence): the end of the second completes the second.
        let twin = NewRun {
            request_seq: None,
            ..run.clone()
        };
        let at = "2026-11-28T12:00:00Z";
        let first = h.begin_at(&twin, at).unwrap();
        let second = h.begin_at(&twin, at).unwrap();
        let start = spool::SpooledStart {
            run: twin,
            started: at.into(),
        };
        let end = spool::SpoolRecord::new(
            "h".into(),
            second,
            Rows::of(RunStatus::Done, &report()),
            Some(start),
        );
        h.finish_record(&end).unwrap();
        let runs = h.list(&Filter::default()).unwrap();
        let status = |id| runs.iter().find(|r| r.id == id).unwrap().status;
        assert_eq!(
            (status(first), status(second)),
            (RunStatus::Running, RunStatus::Done)
        );
    }

    #[test]
    fn a_history_from_before_the_uncertainties_gains_their_columns() {
        let dir = TestDir::new("history-old");
        let path = dir.join("old.sqlite");
        {
            // The tables as the first schema made them, with a completed 451 run.
            let c = rusqlite::Connection::open(&path).unwrap();
            c.execute_batch(
                "CREATE TABLE runs (id INTEGER PRIMARY KEY, started TEXT NOT NULL, finished TEXT, machine TEXT NOT NULL, source TEXT NOT NULL, request_seq INTEGER, program_number INTEGER, program TEXT NOT NULL, status TEXT NOT NULL, message TEXT, protocols TEXT NOT NULL DEFAULT '[]', max_modification REAL);
                 CREATE TABLE results (run_id INTEGER NOT NULL REFERENCES runs (id), position INTEGER NOT NULL, block INTEGER NOT NULL, cycle INTEGER NOT NULL, name TEXT NOT NULL, value REAL NOT NULL);
                 CREATE TABLE iso_errors (run_id INTEGER NOT NULL REFERENCES runs (id), block INTEGER NOT NULL, name TEXT NOT NULL, before REAL NOT NULL, after REAL NOT NULL);
                 INSERT INTO runs VALUES (1, '2026-01-01T00:00:00Z', '2026-01-01T00:10:00Z', 'table-ac', 'run', NULL, NULL, '451.h', 'done', NULL, '[]', 0.03);
                 INSERT INTO results VALUES (1, 0, 3, 451, 'Q141', 0.002);
                 INSERT INTO iso_errors VALUES (1, 3, 'EX0C', 0.0, 0.012);",
            )
            .unwrap();
        }
        let mut h = History::open(&HistoryTarget::Sqlite(path.clone())).unwrap();
        let runs = h.list(&Filter::default()).unwrap();
        assert_eq!(runs.len(), 1);
        assert_eq!(
            (runs[0].results[0].value, runs[0].results[0].u),
            (0.002, None)
        );
        assert_eq!(
            (runs[0].iso_errors[0].after, runs[0].iso_errors[0].u),
            (0.012, None)
        );
        // A new run on the migrated file stores its uncertainties; opening it again
        // migrates nothing twice.
        let id = h
            .begin(&RunStart {
                machine: "table-ac",
                source: "run",
                request_seq: None,
                program_number: None,
                program: Path::new("/p/431.h"),
                max_modification: None,
                parameters: &[],
            })
            .unwrap();
        h.finish(id, RunStatus::Done, &report()).unwrap();
        drop(h);
        let mut h = History::open(&HistoryTarget::Sqlite(path)).unwrap();
        let runs = h.list(&Filter::default()).unwrap();
        assert_eq!(runs[1].results[0].u, Some(0.0002));
        // And its machine time; the run from before the column has none.
        assert_eq!(
            (runs[0].machine_time_s, runs[1].machine_time_s),
            (None, Some(6.875))
        );
    }
}
