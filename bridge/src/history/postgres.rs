//! The history on a central PostgreSQL server, for a factory whose gateways report into
//! one place: the same tables and columns as the SQLite file, with PostgreSQL's types.
//! Each gateway only ever closes its own machine's interrupted runs.
//!
//! Every call is bounded on the client's side: a server that stops answering (paused,
//! a network that drops packets) cannot hold the caller longer than the connect or
//! statement timeout, whatever the kernel's TCP timers say. A connection that timed
//! out is dropped; the caller opens a new one.

use super::spool::SpooledStart;
use super::{
    status_of, DispersionRow, Filter, IsoErrorRow, NewRun, ResultRow, Rows, RunRow, Store,
    StoreError, Timeouts,
};
use std::future::Future;
use std::time::Duration;
use tokio_postgres::{Client, NoTls};

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
    max_modification DOUBLE PRECISION,
    machine_time_s DOUBLE PRECISION
);
CREATE INDEX IF NOT EXISTS runs_machine_started ON runs (machine, started);
CREATE TABLE IF NOT EXISTS results (
    run_id BIGINT NOT NULL REFERENCES runs (id),
    position INTEGER NOT NULL,
    block BIGINT NOT NULL,
    cycle INTEGER NOT NULL,
    name TEXT NOT NULL,
    value DOUBLE PRECISION NOT NULL,
    u DOUBLE PRECISION
);
CREATE TABLE IF NOT EXISTS iso_errors (
    run_id BIGINT NOT NULL REFERENCES runs (id),
    block BIGINT NOT NULL,
    name TEXT NOT NULL,
    before DOUBLE PRECISION NOT NULL,
    after DOUBLE PRECISION NOT NULL,
    u DOUBLE PRECISION
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
-- Histories from before the standard uncertainties: the column added, NULL in old rows.
ALTER TABLE results ADD COLUMN IF NOT EXISTS u DOUBLE PRECISION;
ALTER TABLE iso_errors ADD COLUMN IF NOT EXISTS u DOUBLE PRECISION;
-- And from before the machine time.
ALTER TABLE runs ADD COLUMN IF NOT EXISTS machine_time_s DOUBLE PRECISION;
";

/// Held while one gateway creates the tables, so that two starting at once do not
/// race on them (an arbitrary key of this schema).
const SCHEMA_LOCK: i64 = 0x7072_6f62_6562_7231;

pub struct PgStore {
    client: Client,
    /// Drives the connection while a call waits (current thread: only then).
    rt: tokio::runtime::Runtime,
    statement: Duration,
}

/// `f` within `limit`, or an error saying so.
fn within<T>(
    rt: &tokio::runtime::Runtime,
    limit: Duration,
    what: &str,
    f: impl Future<Output = Result<T, tokio_postgres::Error>>,
) -> Result<T, String> {
    match rt.block_on(async { tokio::time::timeout(limit, f).await }) {
        Ok(r) => r.map_err(text),
        Err(_) => Err(format!(
            "no answer from the server within {} ms ({what})",
            limit.as_millis()
        )),
    }
}

fn text(e: tokio_postgres::Error) -> String {
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
    /// Connects to `url` (`postgres://user:password@host:port/database`; no TLS) with
    /// TCP keepalive, within `timeouts.connect`; every later call is bounded by
    /// `timeouts.statement` (also the server's `statement_timeout`).
    pub fn open(url: &str, timeouts: &Timeouts) -> Result<Self, String> {
        let mut cfg: tokio_postgres::Config = url.parse().map_err(text)?;
        let keepalive = timeouts.keepalive;
        cfg.connect_timeout(timeouts.connect)
            .keepalives(true)
            .keepalives_idle(keepalive)
            .keepalives_interval((keepalive / 3).max(Duration::from_secs(1)))
            .keepalives_retries(3)
            .tcp_user_timeout(keepalive)
            .options(format!(
                "-c statement_timeout={}",
                timeouts.statement.as_millis()
            ));
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .map_err(|e| format!("cannot start the client's runtime: {e}"))?;
        let (mut client, connection) =
            within(&rt, timeouts.connect, "connecting", cfg.connect(NoTls))?;
        rt.spawn(async move {
            if let Err(e) = connection.await {
                tracing::debug!("history connection ended: {e}");
            }
        });
        let statement = timeouts.statement;
        within(&rt, statement, "creating the tables", async {
            let tx = client.transaction().await?;
            tx.execute("SELECT pg_advisory_xact_lock($1)", &[&SCHEMA_LOCK])
                .await?;
            tx.batch_execute(SCHEMA).await?;
            tx.commit().await
        })?;
        Ok(Self {
            client,
            rt,
            statement,
        })
    }

    async fn details(client: &Client, run: &mut RunRow) -> Result<(), tokio_postgres::Error> {
        run.results = client
            .query(
                "SELECT block, cycle, name, value, u FROM results WHERE run_id = $1 ORDER BY position, name",
                &[&run.id],
            )
            .await?
            .iter()
            .map(|r| ResultRow {
                block: r.get::<_, i64>(0) as u32,
                cycle: r.get::<_, i32>(1) as u16,
                name: r.get(2),
                value: r.get(3),
                u: r.get(4),
            })
            .collect();
        run.iso_errors = client
            .query(
                "SELECT block, name, before, after, u FROM iso_errors WHERE run_id = $1 ORDER BY block, name",
                &[&run.id],
            )
            .await?
            .iter()
            .map(|r| IsoErrorRow {
                block: r.get::<_, i64>(0) as u32,
                name: r.get(1),
                before: r.get(2),
                after: r.get(3),
                u: r.get(4),
            })
            .collect();
        run.dispersion = client
            .query(
                "SELECT block, axis, before, after FROM axis_dispersion WHERE run_id = $1 ORDER BY block, axis",
                &[&run.id],
            )
            .await?
            .iter()
            .map(|r| DispersionRow {
                block: r.get::<_, i64>(0) as u32,
                axis: r.get(1),
                before: r.get(2),
                after: r.get(3),
            })
            .collect();
        run.parameters = client
            .query(
                "SELECT value FROM parameters WHERE run_id = $1 ORDER BY number",
                &[&run.id],
            )
            .await?
            .iter()
            .map(|r| r.get(0))
            .collect();
        Ok(())
    }
}

impl Store for PgStore {
    fn begin(&mut self, run: &NewRun, now: &str) -> Result<i64, String> {
        let client = &mut self.client;
        within(&self.rt, self.statement, "recording the start", async {
            let tx = client.transaction().await?;
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
                .await?;
            let id: i64 = row.get(0);
            for (i, v) in run.parameters.iter().enumerate() {
                tx.execute(
                    "INSERT INTO parameters (run_id, number, value) VALUES ($1, $2, $3)",
                    &[&id, &(i as i32 + 1), v],
                )
                .await?;
            }
            tx.commit().await?;
            Ok(id)
        })
    }

    fn finish(&mut self, id: i64, rows: &Rows) -> Result<(), StoreError> {
        let client = &mut self.client;
        let known = within(&self.rt, self.statement, "recording the end", async {
            let tx = client.transaction().await?;
            let updated = tx
                .execute(
                    "UPDATE runs SET finished = $1, status = $2, message = $3, protocols = $4, machine_time_s = $6
                     WHERE id = $5 AND status IN ('running', 'interrupted')",
                    &[
                        &rows.finished,
                        &rows.status.as_str(),
                        &rows.message,
                        &rows.protocols,
                        &id,
                        &rows.machine_time_s,
                    ],
                )
                .await?;
            if updated == 0 {
                // Completed already (a retry, a replay), or unknown.
                let n: i64 = tx
                    .query_one("SELECT COUNT(*) FROM runs WHERE id = $1", &[&id])
                    .await?
                    .get(0);
                return Ok(n == 1);
            }
            for (position, r) in &rows.results {
                tx.execute(
                    "INSERT INTO results (run_id, position, block, cycle, name, value, u) VALUES ($1, $2, $3, $4, $5, $6, $7)",
                    &[&id, &(*position as i32), &i64::from(r.block), &i32::from(r.cycle), &r.name, &r.value, &r.u],
                )
                .await?;
            }
            for e in &rows.iso_errors {
                tx.execute(
                    "INSERT INTO iso_errors (run_id, block, name, before, after, u) VALUES ($1, $2, $3, $4, $5, $6)",
                    &[&id, &i64::from(e.block), &e.name, &e.before, &e.after, &e.u],
                )
                .await?;
            }
            for d in &rows.dispersion {
                tx.execute(
                    "INSERT INTO axis_dispersion (run_id, block, axis, before, after) VALUES ($1, $2, $3, $4, $5)",
                    &[&id, &i64::from(d.block), &d.axis, &d.before, &d.after],
                )
                .await?;
            }
            tx.commit().await?;
            Ok(true)
        })?;
        if known {
            Ok(())
        } else {
            Err(StoreError::no_run(id))
        }
    }

    fn discard(&mut self, id: i64) -> Result<(), String> {
        let client = &mut self.client;
        within(
            &self.rt,
            self.statement,
            "removing a refused start",
            async {
                let tx = client.transaction().await?;
                for table in ["parameters", "results", "iso_errors", "axis_dispersion"] {
                    tx.execute(
                        format!("DELETE FROM {table} WHERE run_id = $1").as_str(),
                        &[&id],
                    )
                    .await?;
                }
                tx.execute("DELETE FROM runs WHERE id = $1", &[&id]).await?;
                tx.commit().await
            },
        )
    }

    fn list(&mut self, filter: &Filter) -> Result<Vec<RunRow>, String> {
        let client = &self.client;
        // A status word that is no run status (a row written by hand): the listing
        // fails naming the run, after the query.
        let mut unknown = None;
        let runs = within(&self.rt, self.statement, "listing", async {
            let rows = client
                .query(
                    "SELECT id, started, finished, machine, source, request_seq, program_number, program, status, message, protocols, max_modification, machine_time_s
                     FROM runs WHERE ($1::TEXT IS NULL OR machine = $1) AND ($2::TEXT IS NULL OR started >= $2) ORDER BY started, id",
                    &[&filter.machine, &filter.since],
                )
                .await?;
            let mut runs = Vec::new();
            for r in rows {
                let protocols: String = r.get(10);
                let word: String = r.get(8);
                let status = match status_of(r.get(0), &word) {
                    Ok(s) => s,
                    Err(e) => {
                        unknown = Some(e);
                        break;
                    }
                };
                let mut run = RunRow {
                    id: r.get(0),
                    started: r.get(1),
                    finished: r.get(2),
                    machine: r.get(3),
                    source: r.get(4),
                    request_seq: u16_of(r.get(5)),
                    program_number: u16_of(r.get(6)),
                    program: r.get(7),
                    status,
                    message: r.get(9),
                    protocols: serde_json::from_str(&protocols).unwrap_or_default(),
                    results: Vec::new(),
                    iso_errors: Vec::new(),
                    max_modification: r.get(11),
                    machine_time_s: r.get(12),
                    dispersion: Vec::new(),
                    parameters: Vec::new(),
                };
                Self::details(client, &mut run).await?;
                runs.push(run);
            }
            Ok(runs)
        })?;
        match unknown {
            Some(e) => Err(e),
            None => Ok(runs),
        }
    }

    fn close_interrupted(&mut self, machine: &str) -> Result<usize, String> {
        let client = &self.client;
        within(
            &self.rt,
            self.statement,
            "closing interrupted runs",
            async {
                client
                .execute(
                    "UPDATE runs SET status = 'interrupted' WHERE status = 'running' AND machine = $1",
                    &[&machine],
                )
                .await
                .map(|n| n as usize)
            },
        )
    }

    fn find_run(&mut self, id: i64, start: &SpooledStart) -> Result<Option<i64>, String> {
        let client = &self.client;
        let r = &start.run;
        let program = r.program.display().to_string();
        let seq = r.request_seq.map(i32::from);
        within(&self.rt, self.statement, "finding a spooled run", async {
            Ok(client
                .query_opt(
                    "SELECT id FROM runs WHERE machine = $1 AND started = $2 AND program = $3 AND source = $4
                     AND request_seq IS NOT DISTINCT FROM $5 ORDER BY id = $6 DESC, id LIMIT 1",
                    &[&r.machine, &start.started, &program, &r.source, &seq, &id],
                )
                .await?
                .map(|row| row.get(0)))
        })
    }

    fn count(&mut self) -> Result<i64, String> {
        let client = &self.client;
        within(&self.rt, self.statement, "counting", async {
            Ok(client
                .query_one("SELECT COUNT(*) FROM runs", &[])
                .await?
                .get(0))
        })
    }
}
