//! The history in an SQLite file, one per gateway (the embedded default). WAL mode: a
//! reader (`probebridge history`) never blocks the gateway's writes, and a crash
//! leaves the last committed transaction.

use super::spool::SpooledStart;
use super::{
    status_of, DispersionRow, Filter, IsoErrorRow, NewRun, ResultRow, Rows, RunRow, RunStatus,
    Store, StoreError, Timeouts,
};
use rusqlite::{params, Connection, OpenFlags};
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
    max_modification REAL,
    machine_time_s REAL
);
CREATE INDEX IF NOT EXISTS runs_machine_started ON runs (machine, started);
CREATE TABLE IF NOT EXISTS results (
    run_id INTEGER NOT NULL REFERENCES runs (id),
    position INTEGER NOT NULL,
    block INTEGER NOT NULL,
    cycle INTEGER NOT NULL,
    name TEXT NOT NULL,
    value REAL NOT NULL,
    u REAL
);
CREATE TABLE IF NOT EXISTS iso_errors (
    run_id INTEGER NOT NULL REFERENCES runs (id),
    block INTEGER NOT NULL,
    name TEXT NOT NULL,
    before REAL NOT NULL,
    after REAL NOT NULL,
    u REAL
);
CREATE TABLE IF NOT EXISTS parameters (
    run_id INTEGER NOT NULL REFERENCES runs (id),
    number INTEGER NOT NULL,
    value REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS axis_dispersion (
    run_id INTEGER NOT NULL REFERENCES runs (id),
    block INTEGER NOT NULL,
    axis TEXT NOT NULL,
    before REAL NOT NULL,
    after REAL NOT NULL
);
";

/// Columns added since the first schema, as (table, column, type): a history written
/// before them gains them (NULL in its old rows) when it is opened.
const ADDED_COLUMNS: [(&str, &str, &str); 3] = [
    ("results", "u", "REAL"),
    ("iso_errors", "u", "REAL"),
    ("runs", "machine_time_s", "REAL"),
];

/// Adds the [`ADDED_COLUMNS`] a file lacks, in one transaction (SQLite has no
/// `ADD COLUMN IF NOT EXISTS`).
fn migrate(conn: &Connection) -> rusqlite::Result<()> {
    let has = |table: &str, column: &str| -> rusqlite::Result<bool> {
        let mut stmt = conn.prepare(&format!("PRAGMA table_info({table})"))?;
        let names = stmt.query_map([], |r| r.get::<_, String>(1))?;
        for n in names {
            if n? == column {
                return Ok(true);
            }
        }
        Ok(false)
    };
    let mut missing = Vec::new();
    for (table, column, kind) in ADDED_COLUMNS {
        if !has(table, column)? {
            missing.push(format!("ALTER TABLE {table} ADD COLUMN {column} {kind};"));
        }
    }
    if missing.is_empty() {
        return Ok(());
    }
    conn.execute_batch(&format!("BEGIN IMMEDIATE; {} COMMIT;", missing.join(" ")))
}

pub struct SqliteStore {
    conn: Connection,
    path: PathBuf,
    timeouts: Timeouts,
}

fn text(e: rusqlite::Error) -> String {
    e.to_string()
}

impl SqliteStore {
    /// Opens the file; a lock another process holds is waited for at most
    /// `timeouts.statement`.
    pub fn open(path: &Path, timeouts: &Timeouts) -> Result<Self, String> {
        let conn = Connection::open(path).map_err(text)?;
        conn.busy_timeout(timeouts.statement).map_err(text)?;
        conn.pragma_update(None, "journal_mode", "WAL")
            .map_err(text)?;
        conn.execute_batch(SCHEMA).map_err(text)?;
        migrate(&conn).map_err(text)?;
        Ok(Self {
            conn,
            path: path.to_path_buf(),
            timeouts: *timeouts,
        })
    }

    /// Reads run `id` back through a connection of its own, as `probebridge history`
    /// would: its status and its number of results. The writing connection's commit
    /// alone proves little: it keeps the pages it wrote in its cache and appends to the
    /// WAL where it last left it, so a file overwritten under it (the WAL, the first
    /// page) still takes its commits while nobody else can read them.
    fn read_back(&self, id: i64, status: RunStatus, results: usize) -> Result<(), String> {
        let fresh = || -> rusqlite::Result<(String, i64)> {
            let c = Connection::open_with_flags(&self.path, OpenFlags::SQLITE_OPEN_READ_ONLY)?;
            c.busy_timeout(self.timeouts.statement)?;
            c.query_row(
                "SELECT status, (SELECT COUNT(*) FROM results WHERE run_id = ?1) FROM runs WHERE id = ?1",
                [id],
                |r| Ok((r.get(0)?, r.get(1)?)),
            )
        };
        match fresh() {
            Ok((s, n)) if s == status.as_str() && n == results as i64 => Ok(()),
            Ok((s, n)) => Err(format!(
                "run {id} written as \"{status}\" with {results} results reads back as {s:?} with {n}"
            )),
            Err(e) => Err(format!(
                "run {id} written, but the file cannot be read back: {e}"
            )),
        }
    }

    fn results(&self, id: i64) -> rusqlite::Result<Vec<ResultRow>> {
        let mut stmt = self.conn.prepare_cached(
            "SELECT block, cycle, name, value, u FROM results WHERE run_id = ?1 ORDER BY position, name",
        )?;
        let rows = stmt.query_map([id], |r| {
            Ok(ResultRow {
                block: r.get(0)?,
                cycle: r.get(1)?,
                name: r.get(2)?,
                value: r.get(3)?,
                u: r.get(4)?,
            })
        })?;
        rows.collect()
    }

    fn iso_errors(&self, id: i64) -> rusqlite::Result<Vec<IsoErrorRow>> {
        let mut stmt = self.conn.prepare_cached(
            "SELECT block, name, before, after, u FROM iso_errors WHERE run_id = ?1 ORDER BY block, name",
        )?;
        let rows = stmt.query_map([id], |r| {
            Ok(IsoErrorRow {
                block: r.get(0)?,
                name: r.get(1)?,
                before: r.get(2)?,
                after: r.get(3)?,
                u: r.get(4)?,
            })
        })?;
        rows.collect()
    }

    fn dispersion(&self, id: i64) -> rusqlite::Result<Vec<DispersionRow>> {
        let mut stmt = self.conn.prepare_cached(
            "SELECT block, axis, before, after FROM axis_dispersion WHERE run_id = ?1 ORDER BY block, axis",
        )?;
        let rows = stmt.query_map([id], |r| {
            Ok(DispersionRow {
                block: r.get(0)?,
                axis: r.get(1)?,
                before: r.get(2)?,
                after: r.get(3)?,
            })
        })?;
        rows.collect()
    }

    fn parameters(&self, id: i64) -> rusqlite::Result<Vec<f64>> {
        let mut stmt = self
            .conn
            .prepare_cached("SELECT value FROM parameters WHERE run_id = ?1 ORDER BY number")?;
        let rows = stmt.query_map([id], |r| r.get(0))?;
        rows.collect()
    }

    fn list_runs(&self, filter: &Filter) -> rusqlite::Result<Vec<RunRow>> {
        let mut stmt = self.conn.prepare(
            "SELECT id, started, finished, machine, source, request_seq, program_number, program, status, message, protocols, max_modification, machine_time_s
             FROM runs WHERE (?1 IS NULL OR machine = ?1) AND (?2 IS NULL OR started >= ?2) ORDER BY started, id",
        )?;
        let rows = stmt.query_map(params![filter.machine, filter.since], |r| {
            let protocols: String = r.get(10)?;
            let id: i64 = r.get(0)?;
            let word: String = r.get(8)?;
            let status = status_of(id, &word).map_err(|e| {
                rusqlite::Error::FromSqlConversionFailure(8, rusqlite::types::Type::Text, e.into())
            })?;
            Ok(RunRow {
                id,
                started: r.get(1)?,
                finished: r.get(2)?,
                machine: r.get(3)?,
                source: r.get(4)?,
                request_seq: r.get(5)?,
                program_number: r.get(6)?,
                program: r.get(7)?,
                status,
                message: r.get(9)?,
                protocols: serde_json::from_str(&protocols).unwrap_or_default(),
                results: Vec::new(),
                iso_errors: Vec::new(),
                max_modification: r.get(11)?,
                machine_time_s: r.get(12)?,
                dispersion: Vec::new(),
                parameters: Vec::new(),
            })
        })?;
        let mut runs = Vec::new();
        for row in rows {
            let mut run = row?;
            run.results = self.results(run.id)?;
            run.iso_errors = self.iso_errors(run.id)?;
            run.dispersion = self.dispersion(run.id)?;
            run.parameters = self.parameters(run.id)?;
            runs.push(run);
        }
        Ok(runs)
    }
}

impl Store for SqliteStore {
    fn begin(&mut self, run: &NewRun, now: &str) -> Result<i64, String> {
        let tx = self.conn.transaction().map_err(text)?;
        tx.execute(
                "INSERT INTO runs (started, machine, source, request_seq, program_number, program, status, max_modification)
                 VALUES (?1, ?2, ?3, ?4, ?5, ?6, 'running', ?7)",
                params![
                    now,
                    run.machine,
                    run.source,
                    run.request_seq,
                    run.program_number,
                    run.program.display().to_string(),
                    run.max_modification,
                ],
            )
        .map_err(text)?;
        let id = tx.last_insert_rowid();
        for (i, v) in run.parameters.iter().enumerate() {
            tx.execute(
                "INSERT INTO parameters (run_id, number, value) VALUES (?1, ?2, ?3)",
                params![id, i as i64 + 1, v],
            )
            .map_err(text)?;
        }
        tx.commit().map_err(text)?;
        self.read_back(id, RunStatus::Running, 0)?;
        Ok(id)
    }

    fn finish(&mut self, id: i64, rows: &Rows) -> Result<(), StoreError> {
        let tx = self.conn.transaction().map_err(text)?;
        let updated = tx
            .execute(
                "UPDATE runs SET finished = ?1, status = ?2, message = ?3, protocols = ?4, machine_time_s = ?6
                 WHERE id = ?5 AND status IN ('running', 'interrupted')",
                params![
                    rows.finished,
                    rows.status.as_str(),
                    rows.message,
                    rows.protocols,
                    id,
                    rows.machine_time_s
                ],
            )
            .map_err(text)?;
        if updated == 0 {
            let known: i64 = tx
                .query_row("SELECT COUNT(*) FROM runs WHERE id = ?1", [id], |r| {
                    r.get(0)
                })
                .map_err(text)?;
            // Completed already (a retry, a replay): nothing more to write.
            return if known == 1 {
                Ok(())
            } else {
                Err(StoreError::no_run(id))
            };
        }
        for (position, r) in &rows.results {
            tx.execute(
                "INSERT INTO results (run_id, position, block, cycle, name, value, u) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)",
                params![id, position, r.block, r.cycle, r.name, r.value, r.u],
            )
            .map_err(text)?;
        }
        for e in &rows.iso_errors {
            tx.execute(
                "INSERT INTO iso_errors (run_id, block, name, before, after, u) VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
                params![id, e.block, e.name, e.before, e.after, e.u],
            )
            .map_err(text)?;
        }
        for d in &rows.dispersion {
            tx.execute(
                "INSERT INTO axis_dispersion (run_id, block, axis, before, after) VALUES (?1, ?2, ?3, ?4, ?5)",
                params![id, d.block, d.axis, d.before, d.after],
            )
            .map_err(text)?;
        }
        tx.commit().map_err(text)?;
        Ok(self.read_back(id, rows.status, rows.results.len())?)
    }

    fn discard(&mut self, id: i64) -> Result<(), String> {
        let tx = self.conn.transaction().map_err(text)?;
        for table in ["parameters", "results", "iso_errors", "axis_dispersion"] {
            tx.execute(&format!("DELETE FROM {table} WHERE run_id = ?1"), [id])
                .map_err(text)?;
        }
        tx.execute("DELETE FROM runs WHERE id = ?1", [id])
            .map_err(text)?;
        tx.commit().map_err(text)
    }

    fn list(&mut self, filter: &Filter) -> Result<Vec<RunRow>, String> {
        self.list_runs(filter).map_err(text)
    }

    fn close_interrupted(&mut self, machine: &str) -> Result<usize, String> {
        self.conn
            .execute(
                "UPDATE runs SET status = 'interrupted' WHERE status = 'running' AND machine = ?1",
                [machine],
            )
            .map_err(text)
    }

    fn count(&mut self) -> Result<i64, String> {
        self.conn
            .query_row("SELECT COUNT(*) FROM runs", [], |r| r.get(0))
            .map_err(text)
    }

    fn find_run(&mut self, id: i64, start: &SpooledStart) -> Result<Option<i64>, String> {
        let r = &start.run;
        let found = self.conn.query_row(
            "SELECT id FROM runs WHERE machine = ?1 AND started = ?2 AND program = ?3 AND source = ?4
             AND request_seq IS ?5 ORDER BY id = ?6 DESC, id LIMIT 1",
            params![
                r.machine,
                start.started,
                r.program.display().to_string(),
                r.source,
                r.request_seq,
                id
            ],
            |r| r.get(0),
        );
        match found {
            Ok(id) => Ok(Some(id)),
            Err(rusqlite::Error::QueryReturnedNoRows) => Ok(None),
            Err(e) => Err(text(e)),
        }
    }

    /// `PRAGMA quick_check` through a connection of its own (the file as a reader
    /// finds it, not the writer's cache).
    fn check(&mut self) -> Result<(), String> {
        let run = || -> rusqlite::Result<Vec<String>> {
            let c = Connection::open_with_flags(&self.path, OpenFlags::SQLITE_OPEN_READ_ONLY)?;
            c.busy_timeout(self.timeouts.statement)?;
            let mut stmt = c.prepare("PRAGMA quick_check")?;
            let rows = stmt.query_map([], |r| r.get::<_, String>(0))?;
            rows.collect()
        };
        match run() {
            Ok(lines) if lines == ["ok"] => Ok(()),
            Ok(lines) => Err(format!(
                "integrity check (quick_check) failed: {}",
                lines.join("; ")
            )),
            Err(e) => Err(format!("integrity check (quick_check) failed: {e}")),
        }
    }
}
