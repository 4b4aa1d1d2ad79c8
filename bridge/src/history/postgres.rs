//! The history on a central PostgreSQL server, for a factory whose gateways report into
//! one place: the same tables and columns as the SQLite file, with PostgreSQL's types.
//! Each gateway only ever closes its own machine's interrupted runs.

use super::{DispersionRow, Filter, IsoErrorRow, ResultRow, Rows, RunRow, RunStart, Store};
use postgres::{Client, NoTls};

const SCHEMA: &str = "
CREATE TABLE IF NOT EXISTS runs (
    id BIGSERIAL PRIMARY KEY,
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
    max_modification DOUBLE PRECISION
);
CREATE INDEX IF NOT EXISTS runs_machine_started ON runs (machine, started);
CREATE TABLE IF NOT EXISTS results (
    run_id BIGINT NOT NULL REFERENCES runs (id),
    position INTEGER NOT NULL,
    block BIGINT NOT NULL,
    cycle INTEGER NOT NULL,
    name TEXT NOT NULL,
    value DOUBLE PRECISION NOT NULL
);
CREATE TABLE IF NOT EXISTS iso_errors (
    run_id BIGINT NOT NULL REFERENCES runs (id),
    block BIGINT NOT NULL,
    name TEXT NOT NULL,
    before DOUBLE PRECISION NOT NULL,
    after DOUBLE PRECISION NOT NULL
);
CREATE TABLE IF NOT EXISTS parameters (
    run_id BIGINT NOT NULL REFERENCES runs (id),
    number INTEGER NOT NULL,
    value DOUBLE PRECISION NOT NULL
);
CREATE TABLE IF NOT EXISTS axis_dispersion (
    run_id BIGINT NOT NULL REFERENCES runs (id),
    block BIGINT NOT NULL,
    axis TEXT NOT NULL,
    before DOUBLE PRECISION NOT NULL,
    after DOUBLE PRECISION NOT NULL
);
";

/// Held while one gateway creates the tables, so that two starting at once do not
/// race on them (an arbitrary key of this schema).
const SCHEMA_LOCK: i64 = 0x7072_6f62_6562_7231;

pub struct PgStore {
    client: Client,
}

fn text(e: postgres::Error) -> String {
    // The server's own message (e.g. "password authentication failed"), not only
    // "db error".
    match e.as_db_error() {
        Some(db) => format!("{}: {}", db.severity(), db.message()),
        None => e.to_string(),
    }
}

fn u16_of(v: Option<i32>) -> Option<u16> {
    v.and_then(|v| u16::try_from(v).ok())
}

impl PgStore {
    /// Connects to `url` (`postgres://user:password@host:port/database`; no TLS).
    pub fn open(url: &str) -> Result<Self, String> {
        let mut client = Client::connect(url, NoTls).map_err(text)?;
        let mut tx = client.transaction().map_err(text)?;
        tx.execute("SELECT pg_advisory_xact_lock($1)", &[&SCHEMA_LOCK])
            .map_err(text)?;
        tx.batch_execute(SCHEMA).map_err(text)?;
        tx.commit().map_err(text)?;
        Ok(Self { client })
    }

    fn details(&mut self, run: &mut RunRow) -> Result<(), postgres::Error> {
        run.results = self
            .client
            .query(
                "SELECT block, cycle, name, value FROM results WHERE run_id = $1 ORDER BY position, name",
                &[&run.id],
            )?
            .iter()
            .map(|r| ResultRow {
                block: r.get::<_, i64>(0) as u32,
                cycle: r.get::<_, i32>(1) as u16,
                name: r.get(2),
                value: r.get(3),
            })
            .collect();
        run.iso_errors = self
            .client
            .query(
                "SELECT block, name, before, after FROM iso_errors WHERE run_id = $1 ORDER BY block, name",
                &[&run.id],
            )?
            .iter()
            .map(|r| IsoErrorRow {
                block: r.get::<_, i64>(0) as u32,
                name: r.get(1),
                before: r.get(2),
                after: r.get(3),
            })
            .collect();
        run.dispersion = self
            .client
            .query(
                "SELECT block, axis, before, after FROM axis_dispersion WHERE run_id = $1 ORDER BY block, axis",
                &[&run.id],
            )?
            .iter()
            .map(|r| DispersionRow {
                block: r.get::<_, i64>(0) as u32,
                axis: r.get(1),
                before: r.get(2),
                after: r.get(3),
            })
            .collect();
        run.parameters = self
            .client
            .query(
                "SELECT value FROM parameters WHERE run_id = $1 ORDER BY number",
                &[&run.id],
            )?
            .iter()
            .map(|r| r.get(0))
            .collect();
        Ok(())
    }
}

impl Store for PgStore {
    fn begin(&mut self, run: &RunStart, now: &str) -> Result<i64, String> {
        let mut tx = self.client.transaction().map_err(text)?;
        let row = tx
            .query_one(
                "INSERT INTO runs (started, machine, source, request_seq, program_number, program, status, max_modification)
                 VALUES ($1, $2, $3, $4, $5, $6, 'running', $7) RETURNING id",
                &[
                    &now,
                    &run.machine,
                    &run.source,
                    &run.request_seq.map(i32::from),
                    &run.program_number.map(i32::from),
                    &run.program.display().to_string(),
                    &run.max_modification,
                ],
            )
            .map_err(text)?;
        let id: i64 = row.get(0);
        for (i, v) in run.parameters.iter().enumerate() {
            tx.execute(
                "INSERT INTO parameters (run_id, number, value) VALUES ($1, $2, $3)",
                &[&id, &(i as i32 + 1), v],
            )
            .map_err(text)?;
        }
        tx.commit().map_err(text)?;
        Ok(id)
    }

    fn finish(&mut self, id: i64, rows: &Rows) -> Result<(), String> {
        let mut tx = self.client.transaction().map_err(text)?;
        tx.execute(
            "UPDATE runs SET finished = $1, status = $2, message = $3, protocols = $4 WHERE id = $5",
            &[&rows.finished, &rows.status, &rows.message, &rows.protocols, &id],
        )
        .map_err(text)?;
        for (position, r) in &rows.results {
            tx.execute(
                "INSERT INTO results (run_id, position, block, cycle, name, value) VALUES ($1, $2, $3, $4, $5, $6)",
                &[&id, &(*position as i32), &i64::from(r.block), &i32::from(r.cycle), &r.name, &r.value],
            )
            .map_err(text)?;
        }
        for e in &rows.iso_errors {
            tx.execute(
                "INSERT INTO iso_errors (run_id, block, name, before, after) VALUES ($1, $2, $3, $4, $5)",
                &[&id, &i64::from(e.block), &e.name, &e.before, &e.after],
            )
            .map_err(text)?;
        }
        for d in &rows.dispersion {
            tx.execute(
                "INSERT INTO axis_dispersion (run_id, block, axis, before, after) VALUES ($1, $2, $3, $4, $5)",
                &[&id, &i64::from(d.block), &d.axis, &d.before, &d.after],
            )
            .map_err(text)?;
        }
        tx.commit().map_err(text)
    }

    fn list(&mut self, filter: &Filter) -> Result<Vec<RunRow>, String> {
        let rows = self
            .client
            .query(
                "SELECT id, started, finished, machine, source, request_seq, program_number, program, status, message, protocols, max_modification
                 FROM runs WHERE ($1::TEXT IS NULL OR machine = $1) AND ($2::TEXT IS NULL OR started >= $2) ORDER BY started, id",
                &[&filter.machine, &filter.since],
            )
            .map_err(text)?;
        let mut runs = Vec::new();
        for r in rows {
            let protocols: String = r.get(10);
            let mut run = RunRow {
                id: r.get(0),
                started: r.get(1),
                finished: r.get(2),
                machine: r.get(3),
                source: r.get(4),
                request_seq: u16_of(r.get(5)),
                program_number: u16_of(r.get(6)),
                program: r.get(7),
                status: r.get(8),
                message: r.get(9),
                protocols: serde_json::from_str(&protocols).unwrap_or_default(),
                results: Vec::new(),
                iso_errors: Vec::new(),
                max_modification: r.get(11),
                dispersion: Vec::new(),
                parameters: Vec::new(),
            };
            self.details(&mut run).map_err(text)?;
            runs.push(run);
        }
        Ok(runs)
    }

    fn close_interrupted(&mut self, machine: &str) -> Result<usize, String> {
        self.client
            .execute(
                "UPDATE runs SET status = 'interrupted' WHERE status = 'running' AND machine = $1",
                &[&machine],
            )
            .map(|n| n as usize)
            .map_err(text)
    }

    fn count(&mut self) -> Result<i64, String> {
        self.client
            .query_one("SELECT COUNT(*) FROM runs", &[])
            .map(|r| r.get(0))
            .map_err(text)
    }
}
