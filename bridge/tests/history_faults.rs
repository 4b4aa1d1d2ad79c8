//! "Nothing reported that was not kept": `probebridge serve` (simulator, real-time
//! pace) with a PLC (`tests/gateway/history_plc.py`) while the history fails under it.
//! Each test breaks the history the way a plant does and checks docs/history.md's promise:
//! a start whose `running` row cannot be written is refused (reason 9, nothing moves);
//! a run that ends while the history fails is kept in the spool, the PLC sees "results
//! not yet recorded" (bit 6), and the spool is replayed into the history once it works
//! again, as one row, never relabelled `interrupted`.
//!
//! SQLite: the file locked by another process (python3's sqlite3 holding an exclusive
//! transaction), the disk full before and during a run (a small tmpfs the test mounts:
//! skipped with a message where mount is refused, failed in CI), an unwritable WAL, a
//! corrupted page. PostgreSQL (a private server, `common/postgres_server.rs`): down,
//! restarted, paused with SIGSTOP (abort and SIGTERM still work).
//!
//! Python with pymodbus: `PROBEBRIDGE_PYTHON`, else `/opt/probebridge-venv/bin/python`;
//! skipped with a message where it is missing, never in CI.

// `run_program` is for the CLI tests.
#[allow(dead_code)]
mod common;
#[path = "common/pymodbus_venv.rs"]
mod pymodbus_venv;
use pymodbus_venv::python;
#[path = "common/serve.rs"]
mod serve;
use serve::{copy_programs, Serve};
#[path = "common/postgres_server.rs"]
mod postgres_server;
#[path = "common/sqlite_lock.rs"]
mod sqlite_lock;
use sqlite_lock::lock_sqlite;

use common::*;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

const REFUSED: u64 = 0x8000;
const START: u64 = 1;
const REASON_HISTORY_UNAVAILABLE: u64 = 9;
const BUSY: u64 = 1;
const DONE: u64 = 2;
const ERROR: u64 = 3;
const ABORTED: u64 = 4;
const BIT_RESULTS_VALID: u64 = 1 << 5;
const BIT_NOT_RECORDED: u64 = 1 << 6;

fn in_ci() -> bool {
    std::env::var("CI").ok().as_deref() == Some("true")
}

/// `probebridge serve` on the tilted plane, program 431, history as `history` says,
/// and the Python that plays its PLC.
struct Gateway {
    serve: Serve,
    py: PathBuf,
}

impl std::ops::Deref for Gateway {
    type Target = Serve;
    fn deref(&self) -> &Serve {
        &self.serve
    }
}

impl std::ops::DerefMut for Gateway {
    fn deref_mut(&mut self) -> &mut Serve {
        &mut self.serve
    }
}

impl Gateway {
    /// `history`: the keys of the `[history]` section.
    fn start(py: &Path, dir: &Path, name: &str, history: &str) -> Self {
        copy_programs(dir, &[(431, "431-plane.h")]);
        let scenario = slow_heartbeat_scenario(dir);
        let config = dir.join("gateway.toml");
        std::fs::write(
            &config,
            format!(
                "[machine]\nscenario = {:?}\nrealtime = true\nservice = \"pbhist-{name}-{}\"\n\
                 [programs]\nfolder = \"programs\"\n\
                 [plc]\nlisten = \"127.0.0.1:0\"\nheartbeat_timeout_ms = 0\n\
                 [history]\nstatement_timeout_ms = 500\nconnect_timeout_ms = 1000\n{history}",
                scenario.to_str().unwrap(),
                std::process::id(),
            ),
        )
        .unwrap();
        Self {
            serve: Serve::spawn(bin(), dir, &config),
            py: py.to_path_buf(),
        }
    }

    fn plc(&self, args: &[&str]) -> serde_json::Value {
        self.serve.plc_script(&self.py, "history_plc.py", args)
    }

    /// A start of 431 that is refused: "history unavailable", nothing moved. What the
    /// PLC read.
    fn start_refused(&self) -> serde_json::Value {
        let st = self.plc(&["start", "431"]);
        assert_eq!(st["ack_code"], START | REFUSED, "{st}\n{}", self.log());
        assert_eq!(st["reason"], REASON_HISTORY_UNAVAILABLE, "{st}");
        // Nothing started: the state is the last run's, never busy.
        assert_ne!(st["state"], BUSY, "{st}");
        st
    }

    /// Starts 431 until the start is taken (the history is opened again in the
    /// background); refusals meanwhile are "history unavailable". The sequence.
    fn start_taken(&self) -> String {
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            let st = self.plc(&["start", "431"]);
            if st["ack_code"] == START {
                return st["seq"].to_string();
            }
            assert_eq!(st["reason"], REASON_HISTORY_UNAVAILABLE, "{st}");
            assert!(
                Instant::now() < deadline,
                "start never taken\n{}",
                self.log()
            );
            std::thread::sleep(Duration::from_millis(200));
        }
    }

    /// A done run whose end is in the history: written at once or, on a loaded machine
    /// where the write took longer than the statement timeout, through the spool and
    /// replayed (as designed: the end is kept either way). What the test asserts
    /// after this (the history's rows) holds in both cases.
    fn assert_recorded(&self, end: &serde_json::Value) {
        let spooled = end["bits"].as_u64().unwrap() & BIT_NOT_RECORDED != 0;
        assert_done(end, spooled);
        if spooled {
            eprintln!("the history was slow here: the end went through the spool");
            self.wait_recorded();
        }
    }

    /// Until the "results not yet recorded" bit is clear (the spool replayed).
    fn wait_recorded(&self) {
        let deadline = Instant::now() + Duration::from_secs(60);
        while self.plc(&["state"])["bits"].as_u64().unwrap() & BIT_NOT_RECORDED != 0 {
            assert!(
                Instant::now() < deadline,
                "spool never replayed\n{}",
                self.log()
            );
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    fn signal(&self, sig: i32) {
        // SAFETY: kill(2) on our own child, not yet reaped.
        unsafe { libc::kill(self.child.id() as i32, sig) };
    }
}

impl Drop for Gateway {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            self.signal(libc::SIGKILL);
            let _ = self.child.wait();
        }
    }
}

/// The tilted plane on a copy of table-ac whose heartbeats may be seconds late. These
/// tests run in real time (a run must be under way while the history breaks), and on
/// a loaded CI machine the simulated drives' heartbeats were once late by more than the
/// machine's 150 ms: the run ended "node lost" (error kind 5), as it should on a real
/// bus, but it is the history that is under test here, not the bus.
fn slow_heartbeat_scenario(dir: &Path) -> PathBuf {
    let machine = std::fs::read_to_string(configs().join("machines/table-ac.toml")).unwrap();
    let mut replaced = 0;
    let machine: String = machine
        .lines()
        .map(|l| match l.split('=').next().map(str::trim) {
            Some("heartbeat_timeout_ms") => {
                replaced += 1;
                "heartbeat_timeout_ms = 5000".to_string()
            }
            Some("master_heartbeat_ms") => {
                replaced += 1;
                "master_heartbeat_ms = 1000".to_string()
            }
            _ => l.to_string(),
        })
        .map(|l| l + "\n")
        .collect();
    assert_eq!(replaced, 2, "table-ac.toml's heartbeat keys changed");
    for sub in ["machines", "scenarios"] {
        std::fs::create_dir_all(dir.join(sub)).unwrap();
    }
    std::fs::write(dir.join("machines/table-ac.toml"), machine).unwrap();
    let scenario = dir.join("scenarios/tilted-plane.toml");
    std::fs::copy(configs().join("scenarios/tilted-plane.toml"), &scenario).unwrap();
    scenario
}

/// A done run as the PLC saw it: results, and whether they wait in the spool.
fn assert_done(end: &serde_json::Value, spooled: bool) {
    assert_eq!(end["state"], DONE, "{end}");
    let bits = end["bits"].as_u64().unwrap();
    assert_eq!(bits & BIT_RESULTS_VALID, BIT_RESULTS_VALID, "{end}");
    assert_eq!(bits & BIT_NOT_RECORDED != 0, spooled, "{end}");
    assert!(end["results"]["Q158"].is_number(), "{end}");
}

fn history(db: &str) -> Vec<serde_json::Value> {
    let out = run(bin().args(["history", "--db", db, "--json"]));
    assert!(out.status.success());
    serde_json::from_slice::<serde_json::Value>(&out.stdout)
        .unwrap()
        .as_array()
        .unwrap()
        .clone()
}

/// The one run of the history: done, with 431's results.
fn assert_one_done_run(db: &str) {
    let h = history(db);
    assert_eq!(h.len(), 1, "{h:?}");
    assert_eq!(h[0]["status"], "done", "{h:?}");
    let results = h[0]["results"].as_array().unwrap();
    assert!(results.iter().any(|r| r["name"] == "Q158"), "{h:?}");
}

fn spool_lines(path: &Path) -> usize {
    std::fs::read_to_string(path).map_or(0, |t| t.lines().count())
}

#[test]
fn a_locked_history_refuses_the_start_and_a_run_ending_under_the_lock_is_spooled_then_recorded() {
    let Some(py) = python() else { return };
    let dir = tmpdir("hist-locked");
    let db = dir.join("history.sqlite");
    let g = Gateway::start(&py, &dir, "locked", &format!("sqlite = {db:?}\n"));
    {
        let _lock = lock_sqlite(&py, &db);
        g.start_refused();
    }
    assert!(history(db.to_str().unwrap()).is_empty());
    assert!(g.log().contains("start refused"), "{}", g.log());
    // Locked while the run is under way: its end goes to the spool.
    let seq = g.start_taken();
    let lock = lock_sqlite(&py, &db);
    let end = g.plc(&["end", &seq]);
    assert_done(&end, true);
    let spool = dir.join("history.spool");
    assert_eq!(spool_lines(&spool), 1, "{}", g.log());
    let h = history(db.to_str().unwrap());
    assert_eq!(h[0]["status"], "running", "{h:?}");
    drop(lock);
    g.wait_recorded();
    assert_one_done_run(db.to_str().unwrap());
    assert_eq!(spool_lines(&spool), 0);
}

#[test]
fn a_spooled_run_survives_kill_9_and_is_replayed_not_relabelled_interrupted() {
    let Some(py) = python() else { return };
    let dir = tmpdir("hist-kill9");
    let db = dir.join("history.sqlite");
    let cfg = format!("sqlite = {db:?}\n");
    let mut g = Gateway::start(&py, &dir, "kill9", &cfg);
    let seq = g.start_taken();
    let lock = lock_sqlite(&py, &db);
    assert_done(&g.plc(&["end", &seq]), true);
    g.child.kill().unwrap();
    g.child.wait().unwrap();
    drop(g);
    drop(lock);
    // A crash tore a second record in half: reported and kept aside, not replayed.
    let spool = dir.join("history.spool");
    let text = std::fs::read_to_string(&spool).unwrap();
    std::fs::OpenOptions::new()
        .append(true)
        .open(&spool)
        .unwrap()
        .write_all(&text.as_bytes()[..text.len() / 2])
        .unwrap();
    let g = Gateway::start(&py, &dir, "kill9", &cfg);
    g.wait_recorded();
    assert_one_done_run(db.to_str().unwrap());
    let log = g.log();
    assert!(log.contains("line 2") && log.contains("torn"), "{log}");
    let damaged = std::fs::read_to_string(dir.join("history.spool.damaged")).unwrap();
    assert_eq!(damaged.trim_end(), text[..text.len() / 2].trim_end());
    assert_eq!(spool_lines(&spool), 0);
}

/// A tmpfs of `size` mounted at `dir` for this test (unmounted on drop), or `None`
/// with the reason printed where mounting is refused (never in CI).
struct Tmpfs(PathBuf);

fn tmpfs(dir: &Path, size: &str) -> Option<Tmpfs> {
    std::fs::create_dir_all(dir).unwrap();
    // SAFETY: geteuid cannot fail.
    if unsafe { libc::geteuid() } != 0 {
        eprintln!("SKIPPED: mounting a tmpfs for the full-disk test needs root");
        return None;
    }
    let out = Command::new("mount")
        .args([
            "-t",
            "tmpfs",
            "-o",
            &format!("size={size},mode=0755"),
            "tmpfs",
        ])
        .arg(dir)
        .output();
    match out {
        Ok(o) if o.status.success() => Some(Tmpfs(dir.to_path_buf())),
        other => {
            let why = match other {
                Ok(o) => String::from_utf8_lossy(&o.stderr).trim().to_string(),
                Err(e) => e.to_string(),
            };
            // As root it should work: in CI a refusal is a failure.
            assert!(!in_ci(), "cannot mount a tmpfs in CI as root: {why}");
            eprintln!("SKIPPED: mount refused a tmpfs for the full-disk test: {why}");
            None
        }
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg("-l").arg(&self.0).status();
    }
}

/// Fills the file system of `dir` (`dir/filler`) until it has no byte left.
fn fill(dir: &Path) {
    let mut f = std::fs::File::create(dir.join("filler")).unwrap();
    let block = vec![0xA5u8; 4096];
    loop {
        match f.write(&block) {
            Ok(0) => break,
            Ok(_) => {}
            Err(e) if e.raw_os_error() == Some(libc::ENOSPC) => break,
            Err(e) => panic!("filling {}: {e}", dir.display()),
        }
    }
    let _ = f.sync_all();
}

#[test]
fn a_full_disk_refuses_the_start_and_a_run_that_fills_it_is_spooled_then_recorded() {
    let Some(py) = python() else { return };
    let dir = tmpdir("hist-full");
    let Some(mount) = tmpfs(&dir.join("disk"), "1m") else {
        return;
    };
    let db = mount.0.join("history.sqlite");
    let spool = dir.join("history.spool");
    // Full before the gateway starts: the history cannot even be made.
    fill(&mount.0);
    let g = Gateway::start(
        &py,
        &dir,
        "full",
        &format!("sqlite = {db:?}\nspool = {spool:?}\n"),
    );
    g.start_refused();
    std::fs::remove_file(mount.0.join("filler")).unwrap();
    let seq = g.start_taken();
    // Full while the run is under way.
    fill(&mount.0);
    assert_done(&g.plc(&["end", &seq]), true);
    assert_eq!(spool_lines(&spool), 1);
    g.start_refused();
    std::fs::remove_file(mount.0.join("filler")).unwrap();
    g.wait_recorded();
    assert_one_done_run(db.to_str().unwrap());
    drop(g);
    drop(mount);
}

#[test]
fn a_full_disk_under_the_spool_too_reports_an_error_without_results() {
    let Some(py) = python() else { return };
    let dir = tmpdir("hist-fullspool");
    let Some(mount) = tmpfs(&dir.join("disk"), "1m") else {
        return;
    };
    let db = mount.0.join("history.sqlite");
    let g = Gateway::start(&py, &dir, "fullspool", &format!("sqlite = {db:?}\n"));
    let seq = g.start_taken();
    fill(&mount.0);
    // Neither the history nor the spool (beside it) takes the end: no DONE.
    let end = g.plc(&["end", &seq]);
    assert_eq!(end["state"], ERROR, "{end}");
    assert_eq!(end["error_kind"], 23, "{end}");
    assert_eq!(
        end["bits"].as_u64().unwrap() & BIT_RESULTS_VALID,
        0,
        "{end}"
    );
    // Held in memory meanwhile, and recorded once there is room again.
    std::fs::remove_file(mount.0.join("filler")).unwrap();
    g.wait_recorded();
    assert_one_done_run(db.to_str().unwrap());
    drop(g);
    drop(mount);
}

#[test]
fn an_unwritable_wal_refuses_starts_until_it_is_writable() {
    let Some(py) = python() else { return };
    let dir = tmpdir("hist-wal");
    let db = dir.join("history.sqlite");
    // A directory where SQLite's write-ahead log must go.
    let wal = dir.join("history.sqlite-wal");
    std::fs::create_dir(&wal).unwrap();
    let g = Gateway::start(&py, &dir, "wal", &format!("sqlite = {db:?}\n"));
    g.start_refused();
    assert!(g.log().contains("disk I/O error"), "{}", g.log());
    std::fs::remove_dir(&wal).unwrap();
    let seq = g.start_taken();
    g.assert_recorded(&g.plc(&["end", &seq]));
    assert_one_done_run(db.to_str().unwrap());
}

#[test]
fn a_corrupted_page_refuses_starts_and_nothing_moves() {
    let Some(py) = python() else { return };
    let dir = tmpdir("hist-corrupt");
    let db = dir.join("history.sqlite");
    let cfg = format!("sqlite = {db:?}\n");
    let mut g = Gateway::start(&py, &dir, "corrupt", &cfg);
    let seq = g.start_taken();
    g.assert_recorded(&g.plc(&["end", &seq]));
    g.signal(libc::SIGTERM);
    assert!(g.child.wait().unwrap().success());
    drop(g);
    // The page of the runs table, overwritten with garbage.
    let (page, size): (i64, i64) = {
        let c = rusqlite::Connection::open(&db).unwrap();
        (
            c.query_row(
                "SELECT rootpage FROM sqlite_master WHERE name = 'runs'",
                [],
                |r| r.get(0),
            )
            .unwrap(),
            c.query_row("PRAGMA page_size", [], |r| r.get(0)).unwrap(),
        )
    };
    let good = std::fs::read(&db).unwrap();
    let mut bad = good.clone();
    let at = ((page - 1) * size) as usize;
    bad[at..at + size as usize].fill(0x5A);
    std::fs::write(&db, &bad).unwrap();
    let g = Gateway::start(&py, &dir, "corrupt", &cfg);
    g.start_refused();
    assert!(g.log().contains("malformed"), "{}", g.log());
    // The operator puts the good file back: starts are taken again.
    std::fs::write(&db, &good).unwrap();
    let seq = g.start_taken();
    g.assert_recorded(&g.plc(&["end", &seq]));
    assert_eq!(history(db.to_str().unwrap()).len(), 2);
}

/// Issue 35: the WAL, then the first page of the file overwritten while `serve` runs
/// and a run is under way. The run's end goes to the spool (bit 6 set), never
/// reported as recorded; the next starts are refused at once (reason 9). The plant's
/// way out (docs/history.md): the corrupted file moved aside, the gateway makes a
/// fresh one and replays the spool into it, starts are taken again.
#[test]
fn a_history_overwritten_while_serving_keeps_the_end_in_the_spool_and_refuses_starts() {
    let Some(py) = python() else { return };
    let dir = tmpdir("hist-overwritten");
    let db = dir.join("history.sqlite");
    let wal = dir.join("history.sqlite-wal");
    let g = Gateway::start(&py, &dir, "overwritten", &format!("sqlite = {db:?}\n"));
    let seq = g.start_taken();
    g.assert_recorded(&g.plc(&["end", &seq]));
    let seq = g.start_taken();
    assert!(wal.is_file(), "the history writes ahead");
    overwrite_with_noise(&wal, 0, u64::MAX);
    overwrite_with_noise(&db, 0, 4096);
    let end = g.plc(&["end", &seq]);
    assert_done(&end, true);
    let spool = dir.join("history.spool");
    assert_eq!(spool_lines(&spool), 1, "{}", g.log());
    // Known down: refused at once (the recorder's "unavailable", no write tried).
    for _ in 0..2 {
        let st = g.start_refused();
        eprintln!(
            "start refused (history corrupted), answered in {} ms",
            st["answer_ms"]
        );
    }
    let log = g.log();
    assert!(log.contains("unavailable: history"), "{log}");
    assert!(
        log.contains("cannot be read back") || log.contains("quick_check"),
        "{log}"
    );
    // The plant moves the corrupted file aside; the gateway opens a fresh one by itself
    // and replays the spool into it: the run is there, done, with its results.
    let aside = dir.join("aside");
    std::fs::create_dir(&aside).unwrap();
    for f in ["history.sqlite", "history.sqlite-wal", "history.sqlite-shm"] {
        if dir.join(f).exists() {
            std::fs::rename(dir.join(f), aside.join(f)).unwrap();
        }
    }
    g.wait_recorded();
    assert_one_done_run(db.to_str().unwrap());
    assert_eq!(spool_lines(&spool), 0);
    let seq = g.start_taken();
    g.assert_recorded(&g.plc(&["end", &seq]));
    assert_eq!(history(db.to_str().unwrap()).len(), 2);
    // The old file stays as it was put aside: nothing reads it as a history.
    let old = run(bin().args([
        "history",
        "--db",
        aside.join("history.sqlite").to_str().unwrap(),
    ]));
    assert!(!old.status.success());
    drop(g);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The PostgreSQL server, or `None` with the reason printed (never in CI).
fn pg_server(name: &str) -> Option<postgres_server::Server> {
    let Some(bin) = postgres_server::pg_bin() else {
        assert!(
            !in_ci(),
            "PostgreSQL (initdb, postgres) is missing in CI: scripts/install-test-peers installs Debian's postgresql"
        );
        eprintln!("SKIPPED: no PostgreSQL server binaries (initdb, postgres)");
        return None;
    };
    Some(postgres_server::Server::start(&bin, name))
}

#[test]
fn postgres_down_refuses_starts_and_after_a_restart_runs_are_recorded_again() {
    let Some(py) = python() else { return };
    let Some(mut server) = pg_server("pg-restart") else {
        return;
    };
    let url = server.url();
    let dir = tmpdir("hist-pg-restart");
    let spool = dir.join("history.spool");
    let g = Gateway::start(
        &py,
        &dir,
        "pgrestart",
        &format!("postgres = {url:?}\nspool = {spool:?}\n"),
    );
    let seq = g.start_taken();
    g.assert_recorded(&g.plc(&["end", &seq]));
    // The server goes down between runs: the next start is refused.
    server.stop();
    g.start_refused();
    // Back (restarted): the gateway connects again by itself.
    server.start_again();
    let seq = g.start_taken();
    // Down while a run is under way: its end is spooled, and replayed after.
    server.stop();
    assert_done(&g.plc(&["end", &seq]), true);
    server.start_again();
    g.wait_recorded();
    let h = history(&url);
    assert_eq!(h.len(), 2, "{h:?}");
    assert!(h.iter().all(|r| r["status"] == "done"), "{h:?}");
    assert_eq!(spool_lines(&spool), 0);
}

#[test]
fn a_paused_postgres_holds_neither_a_start_nor_abort_nor_sigterm() {
    let Some(py) = python() else { return };
    let Some(server) = pg_server("pg-pause") else {
        return;
    };
    let url = server.url();
    let dir = tmpdir("hist-pg-pause");
    let spool = dir.join("history.spool");
    let mut g = Gateway::start(
        &py,
        &dir,
        "pgpause",
        &format!("postgres = {url:?}\nspool = {spool:?}\n"),
    );
    // Paused while idle: a start is refused after the statement timeout.
    server.pause(true);
    g.start_refused();
    server.pause(false);
    // Paused mid-run: abort still stops the run, and its end is spooled.
    let seq = g.start_taken();
    server.pause(true);
    let ab = g.plc(&["abort"]);
    assert_eq!(ab["ack_code"], 2, "{ab}");
    let end = g.plc(&["end", &seq]);
    assert_eq!(end["state"], ABORTED, "{end}");
    assert_ne!(end["bits"].as_u64().unwrap() & BIT_NOT_RECORDED, 0, "{end}");
    // SIGTERM with the server still paused: the service ends, within the unit's
    // TimeoutStopSec.
    let unit = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../deploy/probebridge.service"),
    )
    .unwrap();
    let stop_sec: u64 = unit
        .lines()
        .find_map(|l| l.strip_prefix("TimeoutStopSec="))
        .and_then(|v| v.trim_end_matches('s').parse().ok())
        .expect("TimeoutStopSec= in the unit");
    let asked = Instant::now();
    g.signal(libc::SIGTERM);
    let status = loop {
        if let Some(s) = g.child.try_wait().unwrap() {
            break Some(s);
        }
        if asked.elapsed() > Duration::from_secs(stop_sec) {
            break None;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    eprintln!(
        "SIGTERM with PostgreSQL paused: exited after {} ms",
        asked.elapsed().as_millis()
    );
    let status = status.unwrap_or_else(|| {
        panic!(
            "still running after TimeoutStopSec={stop_sec}s\n{}",
            g.log()
        )
    });
    assert_eq!(status.code(), Some(0), "{}", g.log());
    server.pause(false);
    assert_eq!(spool_lines(&spool), 1);
    // The next gateway replays it: the aborted run, one row.
    let g = Gateway::start(
        &py,
        &dir,
        "pgpause",
        &format!("postgres = {url:?}\nspool = {spool:?}\n"),
    );
    g.wait_recorded();
    let h = history(&url);
    assert_eq!(h.len(), 1, "{h:?}");
    assert_eq!(h[0]["status"], "aborted", "{h:?}");
}
