//! The history as the gateway keeps it: a thread of its own owns the connection, so
//! that a slow, locked, full or vanished store never holds the machine thread or the
//! PLC face longer than the configured timeouts.
//!
//! - A start is recorded (`running`) before anything moves, or refused: when the store
//!   is down, at once; else after at most the statement timeout.
//! - The end of a run is written in one transaction, tried again twice; if that fails
//!   it is appended to the [`Spool`] (fsynced) before the PLC is told the run ended,
//!   and replayed into the history once it works again. A replay is idempotent: an
//!   end recorded twice makes one row.
//! - A store that failed is dropped and opened again in the background (0.5 s, then a
//!   doubled wait up to 5 s); PostgreSQL thus reconnects after a server restart.
//! - Runs a killed gateway left `running` become `interrupted` at the first open, after
//!   the spool's ends have been replayed, so that a run that completed is never
//!   relabelled.

use super::spool::{Spool, SpoolRecord, SpooledStart};
use super::{time, History, HistoryErrorKind, HistoryTarget, NewRun, Rows, RunStatus, Timeouts};
use cycles::results::ProgramReport;
use std::collections::HashMap;
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

const REOPEN_FIRST: Duration = Duration::from_millis(500);
const REOPEN_MAX: Duration = Duration::from_secs(5);
/// Attempts at writing the end of a run before it goes to the spool.
const FINISH_ATTEMPTS: u32 = 3;
const RETRY_PAUSE: Duration = Duration::from_millis(100);
/// How often the open history's integrity is checked (`PRAGMA quick_check`), besides
/// at each open.
const CHECK_EVERY: Duration = Duration::from_secs(24 * 3600);

/// Where the end of a run was kept.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Kept {
    /// In the history.
    Recorded,
    /// In the spool, to be replayed into the history.
    Spooled,
    /// Neither: the history and the spool both failed (the message says why). The
    /// record is held in memory and tried again, but a restart loses it.
    NotKept(String),
}

enum Op {
    Begin {
        run: NewRun,
        started: String,
        reply: mpsc::SyncSender<Result<i64, String>>,
    },
    Finish {
        record: SpoolRecord,
        reply: mpsc::SyncSender<Kept>,
    },
    /// An end the caller could neither get recorded nor spool: hold it, try again.
    Hold(SpoolRecord),
    Quit,
}

struct Status {
    up: AtomicBool,
    /// Ends not yet in the history (spooled or held).
    pending: AtomicUsize,
    last_error: Mutex<String>,
}

/// A handle on the recorder thread; clones share it.
#[derive(Clone)]
pub struct Recorder {
    tx: Sender<Op>,
    spool: Arc<Mutex<Spool>>,
    status: Arc<Status>,
    timeouts: Timeouts,
    target: HistoryTarget,
    worker: Arc<Mutex<Option<JoinHandle<()>>>>,
    /// The runs begun and not yet ended: their start goes into the spool with their
    /// end, so that a fresh history can take it.
    begun: Arc<Mutex<HashMap<i64, SpooledStart>>>,
}

fn guard<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

impl Recorder {
    /// Opens the spool at `spool` (its damaged lines reported in the log) and starts
    /// the thread, which opens the history. Only a spool that cannot be opened is an
    /// error: a history that is down is opened again until it works.
    pub fn start(
        target: HistoryTarget,
        timeouts: Timeouts,
        spool: &Path,
        machine: &str,
    ) -> Result<Self, String> {
        let (spool, problems) = Spool::open(spool)?;
        for p in &problems {
            tracing::error!("{p}");
        }
        let foreign: Vec<i64> = spool
            .records()
            .iter()
            .filter(|r| r.history != target.display())
            .map(|r| r.id)
            .collect();
        if !foreign.is_empty() {
            tracing::error!(
                "spool {}: runs {foreign:?} belong to another history than {}; they stay in the spool until that history is configured again",
                spool.path().display(),
                target.display()
            );
        }
        if !spool.is_empty() {
            tracing::warn!(
                runs = spool.len(),
                "spool {}: ends of runs not yet in the history",
                spool.path().display()
            );
        }
        let status = Arc::new(Status {
            up: AtomicBool::new(false),
            pending: AtomicUsize::new(spool.len()),
            last_error: Mutex::new("not opened yet".into()),
        });
        let spool = Arc::new(Mutex::new(spool));
        let (tx, rx) = mpsc::channel();
        let (opened_tx, opened) = mpsc::sync_channel(1);
        let worker = Worker {
            target: target.clone(),
            timeouts,
            machine: machine.to_string(),
            store: None,
            spool: spool.clone(),
            status: status.clone(),
            held: Vec::new(),
            interrupted_closed: false,
            next_open: Instant::now(),
            wait: REOPEN_FIRST,
            unknown: Vec::new(),
            failing: None,
            opened_once: false,
            checked: Instant::now(),
        };
        let handle = std::thread::Builder::new()
            .name("probebridge-history".into())
            .spawn(move || worker.run(&rx, &opened_tx))
            .map_err(|e| format!("cannot start the history thread: {e}"))?;
        // The first open is waited for (bounded), so that a start right after READY
        // finds the history open when it can be.
        let _ = opened.recv_timeout(timeouts.connect + timeouts.statement * 3);
        Ok(Self {
            tx,
            spool,
            status,
            timeouts,
            target,
            worker: Arc::new(Mutex::new(Some(handle))),
            begun: Arc::default(),
        })
    }

    pub fn target(&self) -> &HistoryTarget {
        &self.target
    }

    /// Whether the store is open (a start is then tried).
    pub fn is_up(&self) -> bool {
        self.status.up.load(Ordering::Acquire)
    }

    /// Ends of runs not yet in the history (spooled, or held in memory).
    pub fn pending(&self) -> usize {
        self.status.pending.load(Ordering::Acquire)
    }

    /// Records a run as `running`; its id. Refused at once while the store is down,
    /// else within the statement timeout (plus the time to open the store again).
    pub fn begin(&self, run: NewRun) -> Result<i64, String> {
        if !self.is_up() {
            return Err(format!(
                "history {} unavailable: {}",
                self.target.display(),
                guard(&self.status.last_error)
            ));
        }
        let (reply, answer) = mpsc::sync_channel(1);
        let started = time::now_utc();
        self.tx
            .send(Op::Begin {
                run: run.clone(),
                started: started.clone(),
                reply,
            })
            .map_err(|_| "the history thread has ended".to_string())?;
        let limit = self.timeouts.statement + Duration::from_millis(500);
        match answer.recv_timeout(limit) {
            Ok(Ok(id)) => {
                guard(&self.begun).insert(id, SpooledStart { run, started });
                Ok(id)
            }
            Ok(Err(e)) => Err(e),
            Err(_) => Err(format!(
                "history {}: the start was not recorded within {} ms",
                self.target.display(),
                limit.as_millis()
            )),
        }
    }

    /// Completes run `id`. Returns once the end is in the history or fsynced in the
    /// spool (at most about twice the statement timeout), or says it was not kept.
    pub fn finish(&self, id: i64, status: RunStatus, report: &ProgramReport) -> Kept {
        let start = guard(&self.begun).remove(&id);
        let record = SpoolRecord::new(self.target.display(), id, Rows::of(status, report), start);
        let (reply, answer) = mpsc::sync_channel(1);
        let sent = self.tx.send(Op::Finish {
            record: record.clone(),
            reply,
        });
        let limit = self.timeouts.statement * 2 + Duration::from_millis(500);
        if sent.is_ok() {
            if let Ok(kept) = answer.recv_timeout(limit) {
                return kept;
            }
            tracing::warn!(
                run = id,
                "history: the end of the run not recorded within {} ms; spooling it",
                limit.as_millis()
            );
        }
        // The thread is stuck in a call (bounded, but not by us): keep it ourselves.
        // Should the thread record or spool it after all, the spool keeps one copy and
        // the replay leaves a completed run alone.
        let appended = guard(&self.spool).append(record.clone());
        match appended {
            Ok(()) => {
                self.refresh_pending();
                Kept::Spooled
            }
            Err(e) => {
                let _ = self.tx.send(Op::Hold(record));
                Kept::NotKept(e)
            }
        }
    }

    fn refresh_pending(&self) {
        let n = guard(&self.spool).len();
        // The held records are the thread's; it corrects the count on its next turn.
        self.status.pending.fetch_max(n, Ordering::AcqRel);
    }

    /// Stops the thread: waits for it at most the statement timeout, then leaves it
    /// (what it has not written is in the spool already).
    pub fn stop(&self) {
        let _ = self.tx.send(Op::Quit);
        let Some(handle) = guard(&self.worker).take() else {
            return;
        };
        let deadline = Instant::now() + self.timeouts.statement;
        while !handle.is_finished() && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(20));
        }
        if handle.is_finished() {
            let _ = handle.join();
        } else {
            tracing::warn!("history: the recorder thread is still in a call; leaving it");
        }
    }
}

struct Worker {
    target: HistoryTarget,
    timeouts: Timeouts,
    machine: String,
    store: Option<History>,
    spool: Arc<Mutex<Spool>>,
    status: Arc<Status>,
    /// Ends neither recorded nor spooled (the spool's disk failed too).
    held: Vec<SpoolRecord>,
    interrupted_closed: bool,
    next_open: Instant,
    wait: Duration,
    /// Spooled runs the history does not know (reported once, kept in the spool).
    unknown: Vec<i64>,
    /// The error last logged, while the history fails (each new one is logged once).
    failing: Option<String>,
    opened_once: bool,
    /// When the integrity was last checked.
    checked: Instant,
}

impl Worker {
    fn run(mut self, rx: &Receiver<Op>, opened: &mpsc::SyncSender<()>) {
        self.open();
        let _ = opened.send(());
        loop {
            let idle = if self.store.is_none() || self.pending() > 0 {
                Duration::from_millis(250)
            } else {
                Duration::from_secs(5)
            };
            match rx.recv_timeout(idle) {
                Ok(Op::Begin {
                    run,
                    started,
                    reply,
                }) => {
                    let r = self.begin(&run, &started);
                    if let Ok(id) = r {
                        if reply.send(Ok(id)).is_err() {
                            // The start was refused meanwhile (too slow): it never ran.
                            self.discard(id);
                        }
                    } else {
                        let _ = reply.send(r);
                    }
                }
                Ok(Op::Finish { record, reply }) => {
                    let kept = self.finish(record);
                    let _ = reply.send(kept);
                }
                Ok(Op::Hold(record)) => {
                    if !self.held.iter().any(|r| r.id == record.id) {
                        self.held.push(record);
                    }
                }
                Ok(Op::Quit) | Err(RecvTimeoutError::Disconnected) => break,
                Err(RecvTimeoutError::Timeout) => {}
            }
            if self.store.is_none() && Instant::now() >= self.next_open {
                self.open();
            } else if self.store.is_some() && self.checked.elapsed() >= CHECK_EVERY {
                self.check();
            }
            if self.store.is_some() && self.pending() > 0 {
                self.replay();
            }
            self.publish();
        }
    }

    fn pending(&self) -> usize {
        guard(&self.spool).len() + self.held.len()
    }

    fn publish(&self) {
        self.status.pending.store(self.pending(), Ordering::Release);
    }

    /// Opens the store; on success replays the spool, then (once) closes the runs an
    /// earlier gateway left `running`.
    fn open(&mut self) {
        match History::open_with(&self.target, &self.timeouts) {
            Ok(h) => {
                self.store = Some(h);
                if !std::mem::replace(&mut self.opened_once, true) {
                    tracing::info!(at = %self.target.display(), "history");
                }
                self.check();
                self.replay();
                if self.store.is_some() && !self.interrupted_closed {
                    self.close_interrupted();
                }
                if self.store.is_some() {
                    self.status.up.store(true, Ordering::Release);
                }
            }
            Err(e) => self.down(e.to_string()),
        }
        self.publish();
    }

    /// The integrity check: a history that fails it is down (its file corrupted: the
    /// spool keeps the ends of runs, starts are refused until it reads whole again).
    fn check(&mut self) {
        self.checked = Instant::now();
        let Some(h) = self.store.as_mut() else { return };
        if let Err(e) = h.check() {
            self.down(e.to_string());
        }
    }

    /// A write went through: the history works (again).
    fn works(&mut self) {
        if let Some(e) = self.failing.take() {
            tracing::info!(at = %self.target.display(), "history works again (after: {e})");
        }
        self.wait = REOPEN_FIRST;
    }

    fn close_interrupted(&mut self) {
        let Some(h) = self.store.as_mut() else { return };
        match h.close_interrupted(&self.machine) {
            Ok(n) => {
                self.interrupted_closed = true;
                self.works();
                if n > 0 {
                    tracing::warn!(
                        runs = n,
                        "history: runs interrupted by an earlier stop of the gateway"
                    );
                }
            }
            Err(e) => self.down(e.to_string()),
        }
    }

    /// The store failed: drop it, refuse starts, open it again later (a wait that
    /// doubles while it keeps failing). Each new error is logged once.
    fn down(&mut self, error: String) {
        self.store = None;
        self.status.up.store(false, Ordering::Release);
        if self.failing.as_ref() != Some(&error) {
            tracing::error!(
                retry_in_ms = self.wait.as_millis() as u64,
                "{error}; starts are refused (history unavailable) until it works again"
            );
            self.failing = Some(error.clone());
        }
        *guard(&self.status.last_error) = error;
        self.next_open = Instant::now() + self.wait;
        self.wait = (self.wait * 2).min(REOPEN_MAX);
    }

    fn begin(&mut self, run: &NewRun, started: &str) -> Result<i64, String> {
        let Some(h) = self.store.as_mut() else {
            return Err(format!(
                "history {} unavailable: {}",
                self.target.display(),
                guard(&self.status.last_error)
            ));
        };
        match h.begin_at(run, started) {
            Ok(id) => {
                self.works();
                Ok(id)
            }
            Err(e) => {
                let text = e.to_string();
                self.down(text.clone());
                Err(text)
            }
        }
    }

    fn discard(&mut self, id: i64) {
        tracing::warn!(
            run = id,
            "history: removing the row of a start refused as too slow"
        );
        if let Some(h) = self.store.as_mut() {
            if let Err(e) = h.discard(id) {
                // Left `running`: the next start of the gateway marks it interrupted.
                self.down(e.to_string());
            }
        }
    }

    /// The end of a run: into the history (three tries), else into the spool.
    fn finish(&mut self, record: SpoolRecord) -> Kept {
        let mut last = String::new();
        for attempt in 0..FINISH_ATTEMPTS {
            if attempt > 0 {
                std::thread::sleep(RETRY_PAUSE * attempt);
                if self.store.is_none() {
                    self.open();
                }
            }
            let Some(h) = self.store.as_mut() else {
                last = guard(&self.status.last_error).clone();
                continue;
            };
            match h.finish_record(&record) {
                Ok(()) => {
                    self.works();
                    return Kept::Recorded;
                }
                Err(e) => {
                    last = e.to_string();
                    self.down(last.clone());
                }
            }
        }
        let appended = guard(&self.spool).append(record.clone());
        match appended {
            Ok(()) => {
                tracing::warn!(
                    run = record.id,
                    "the end of the run is kept in the spool until the history takes it ({last})"
                );
                self.publish();
                Kept::Spooled
            }
            Err(e) => {
                tracing::error!(
                    run = record.id,
                    "{e}; the end of the run is held in memory only"
                );
                if !self.held.iter().any(|r| r.id == record.id) {
                    self.held.push(record);
                }
                self.publish();
                Kept::NotKept(format!("{last}; {e}"))
            }
        }
    }

    /// Writes the spooled (and held) ends into the history; stops at the first
    /// failure. A held end the history does not take yet is spooled if it can be.
    fn replay(&mut self) {
        let records: Vec<SpoolRecord> = guard(&self.spool)
            .records()
            .iter()
            .filter(|r| r.history == self.target.display())
            .cloned()
            .collect();
        let mut done = Vec::new();
        for r in records.iter().chain(self.held.clone().iter()) {
            if self.unknown.contains(&r.id) {
                continue;
            }
            let Some(h) = self.store.as_mut() else { break };
            match h.finish_record(r) {
                Ok(()) => {
                    self.works();
                    tracing::info!(run = r.id, status = %r.rows.status, "history: spooled end of the run recorded");
                    done.push((r.history.clone(), r.id));
                }
                Err(e) if e.kind() == HistoryErrorKind::NoRun => {
                    // Not the store's failure: this run's start is not in it (a
                    // history restored from before it). Kept, said once.
                    tracing::error!(
                        run = r.id,
                        "{e}; its end stays in the spool {}",
                        guard(&self.spool).path().display()
                    );
                    self.unknown.push(r.id);
                }
                Err(e) => {
                    self.down(e.to_string());
                    break;
                }
            }
        }
        self.held
            .retain(|r| !done.iter().any(|(h, id)| *h == r.history && *id == r.id));
        if !done.is_empty() {
            if let Err(e) = guard(&self.spool).remove(&done) {
                // They stay in the spool: replaying them again changes nothing.
                tracing::error!("{e}");
            }
        }
        // Held ends the history did not take: onto disk, if it has room now.
        let mut still = Vec::new();
        for r in std::mem::take(&mut self.held) {
            if guard(&self.spool).append(r.clone()).is_err() {
                still.push(r);
            }
        }
        self.held = still;
        self.publish();
    }
}
