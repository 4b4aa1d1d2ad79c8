//! What the faces (PLC, OPC UA, web) and the machine thread share: the register map,
//! the handshake, the connection that owns the writes, the starts handed to the
//! machine thread, and what the OPC UA face shows of the runs. Nothing here does I/O
//! under the lock: a start is prepared on the machine thread ([`super::prepare`]).

use super::handshake::{
    AbortReason, Action, Command, Face, Handshake, Outcome, Refusal, Start, State, NO_REQUEST,
};
use super::ownership::{Ownership, Takeover};
use super::register_map::{MapException, RegisterMap};
use super::results::ResultValues;
use crate::history::recorder::Recorder;
use cycles::machine_time::TimeSplit;
use hal::AbortFlag;
use std::collections::BTreeMap;
use std::net::IpAddr;
use std::sync::mpsc::{Receiver, Sender, SyncSender};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Instant, SystemTime};

/// A command of the OPC UA face (it has no request block): start, abort or acknowledge.
#[derive(Clone, Debug, PartialEq)]
pub struct FaceCommand {
    pub command: Command,
    /// Who asked (the OPC UA user), for the log.
    pub who: String,
}

/// A run as the OPC UA face shows it: the program, who started it, when it started
/// and ended, how.
#[derive(Clone, Debug, PartialEq)]
pub struct RunInfo {
    pub program: u16,
    pub face: Face,
    pub started: SystemTime,
    pub ended: Option<SystemTime>,
    pub outcome: Option<Outcome>,
}

/// The last results of one cycle number (431, 444, 451, 460): when, and the values by
/// name.
#[derive(Clone, Debug, PartialEq)]
pub struct CycleResults {
    pub at: SystemTime,
    pub values: ResultValues,
}

/// A start for the machine thread to prepare (see [`super::prepare`]) and run.
pub struct StartRequest {
    pub start: Start,
    /// Who asked (the OPC UA user; "PLC"), for the log.
    pub who: String,
    /// Where the answer goes, for a face that waits for it (OPC UA's methods).
    reply: Option<SyncSender<Result<(), Refusal>>>,
}

/// The answer to a start being prepared: wait for it without the faces' lock.
pub struct Pending(Receiver<Result<(), Refusal>>);

impl Pending {
    /// The start taken, or why it was refused (the machine thread gone: machine not
    /// ready).
    pub fn wait(self) -> Result<(), Refusal> {
        self.0.recv().unwrap_or(Err(Refusal::MachineNotReady))
    }
}

pub enum ToMachine {
    Start(Box<StartRequest>),
    Quit,
}

/// Why a write was not taken.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WriteRefusal {
    /// Another connection owns the writes.
    Busy,
    Map(MapException),
}

pub struct Core {
    pub map: RegisterMap,
    pub hs: Handshake,
    jobs: Sender<ToMachine>,
    /// The machine's stop request (hal's, which brakes a move under way); re-armed when
    /// the measurement it cut short has ended.
    abort: AbortFlag,
    /// Why the running measurement was aborted (the first reason wins).
    abort_reason: Option<AbortReason>,
    /// The flag's generation of the running measurement: a late abort of a finished
    /// one does not hit the next.
    job_generation: u64,
    owner: Ownership,
    heartbeat: u16,
    /// Where runs are recorded (none: history off).
    history: Option<Recorder>,
    /// The current or last run (none yet).
    run: Option<RunInfo>,
    /// The last results of each cycle number.
    by_cycle: BTreeMap<u16, CycleResults>,
    /// Ticks on every change of what the faces show (the OPC UA face waits on it).
    changed: tokio::sync::watch::Sender<u64>,
    /// The states passed through since the OPC UA face last looked (a run on the
    /// simulator can start and end before it looks): at most [`MAX_TRANSITIONS`].
    transitions: std::collections::VecDeque<State>,
    last_state: State,
}

/// State transitions kept for the OPC UA face; the oldest go first beyond it.
const MAX_TRANSITIONS: usize = 64;

pub type Shared = Arc<Mutex<Core>>;

pub fn lock(shared: &Shared) -> MutexGuard<'_, Core> {
    shared.lock().unwrap_or_else(|e| e.into_inner())
}

impl Core {
    pub fn new(map: RegisterMap, hs: Handshake, owner: Ownership, jobs: Sender<ToMachine>) -> Self {
        let mut c = Self {
            map,
            hs,
            jobs,
            abort: AbortFlag::fresh(),
            abort_reason: None,
            job_generation: 0,
            owner,
            heartbeat: 0,
            history: None,
            run: None,
            by_cycle: BTreeMap::new(),
            changed: tokio::sync::watch::Sender::new(0),
            transitions: std::collections::VecDeque::new(),
            last_state: State::Idle,
        };
        c.publish();
        c
    }

    /// Record every run here: a start is taken only once its `running` row is written.
    pub fn set_history(&mut self, history: Recorder) {
        self.history = Some(history);
    }

    fn publish(&mut self) {
        if let Some(h) = &self.history {
            self.hs.set_not_recorded(h.pending() > 0);
        }
        self.map.set_state(self.hs.view());
        let state = self.hs.state();
        if state != self.last_state {
            if self.transitions.len() >= MAX_TRANSITIONS {
                self.transitions.pop_front();
            }
            self.transitions.push_back(state);
            self.last_state = state;
        }
        self.changed.send_modify(|n| *n = n.wrapping_add(1));
    }

    /// The states passed through since the last call, oldest first.
    pub fn take_transitions(&mut self) -> Vec<State> {
        self.transitions.drain(..).collect()
    }

    /// A receiver that sees each change of what the faces show.
    pub fn watch(&self) -> tokio::sync::watch::Receiver<u64> {
        self.changed.subscribe()
    }

    /// A write of connection `conn` from `ip`: the first connection that writes owns
    /// the request block while it talks (see [`Ownership`]). A refused write changes
    /// nothing, the owner included.
    pub fn write(
        &mut self,
        conn: u64,
        ip: IpAddr,
        addr: u16,
        values: &[u16],
    ) -> Result<(), WriteRefusal> {
        let now = Instant::now();
        let mut claim = self.owner.clone();
        let takeover = claim.claim(conn, ip, now).map_err(|_| WriteRefusal::Busy)?;
        self.map.write(addr, values).map_err(WriteRefusal::Map)?;
        self.owner = claim;
        match takeover {
            Some(Takeover::Silent { from, silent }) => tracing::info!(
                connection = conn,
                %ip,
                "PLC face: connection {conn} takes the request block over from connection \
                 {from}, silent for {} ms",
                silent.as_millis()
            ),
            Some(Takeover::SameAddress { from }) => tracing::info!(
                connection = conn,
                %ip,
                "PLC face: connection {conn} takes the request block over from connection \
                 {from} of the same address (the PLC connected again)"
            ),
            None => {}
        }
        self.on_request(now);
        Ok(())
    }

    /// Connection `conn` sent a request (any): an owner stays the owner.
    pub fn heard(&mut self, conn: u64) {
        self.owner.heard(conn, Instant::now());
    }

    /// The address of the connection that owns the request block, if one does.
    pub fn owner_ip(&self) -> Option<IpAddr> {
        self.owner.owner_ip()
    }

    pub fn disconnected(&mut self, conn: u64) {
        self.owner.disconnected(conn);
    }

    fn on_request(&mut self, now: Instant) {
        let req = self.map.request();
        let action = self.hs.on_request(&req, now);
        if self.hs.view().reason != 0 && self.hs.view().ack_seq == req.seq && action.is_none() {
            tracing::info!(
                seq = req.seq,
                code = req.code,
                reason = self.hs.view().reason,
                "request refused"
            );
        }
        match action {
            Some(Action::Prepare(start)) => {
                self.prepare(start, "PLC".into(), None);
            }
            Some(Action::Abort) => {
                tracing::info!(seq = req.seq, "abort requested by the PLC");
                self.request_abort(AbortReason::Request);
            }
            None => {}
        }
        self.publish();
    }

    /// Hands a start to the machine thread, which prepares it off this lock and
    /// answers with [`Core::prepared`].
    fn prepare(
        &mut self,
        start: Start,
        who: String,
        reply: Option<SyncSender<Result<(), Refusal>>>,
    ) {
        // An abort from here on hits this run, not the last one.
        self.job_generation = self.abort.generation();
        let request = StartRequest { start, who, reply };
        if let Err(e) = self.jobs.send(ToMachine::Start(Box::new(request))) {
            let ToMachine::Start(request) = e.0 else {
                return;
            };
            tracing::error!("start refused: the machine thread has ended");
            let _ = self.prepared(&request, Err(Refusal::MachineNotReady));
        }
    }

    /// The machine thread prepared a start: it is taken (the old results stop
    /// matching any request, the state is busy) or refused; the face that waits hears
    /// of it. Whether the run is under way (the machine thread runs it).
    pub fn prepared(&mut self, request: &StartRequest, answer: Result<(), Refusal>) -> bool {
        let start = &request.start;
        let taken = self.hs.prepared(start, answer, Instant::now());
        match answer {
            Ok(()) if !taken => {
                tracing::error!(
                    origin = ?start.origin,
                    "a start that was not being prepared: dropped"
                );
            }
            Ok(()) => {
                tracing::info!(
                    origin = ?start.origin,
                    program = start.program,
                    params = ?start.params,
                    who = %request.who,
                    "measurement started"
                );
                // The last run's results stop matching any start.
                self.map.set_results(NO_REQUEST, &BTreeMap::new());
                self.map.set_machine_time(NO_REQUEST, None);
                self.run = Some(RunInfo {
                    program: start.program,
                    face: start.face(),
                    started: SystemTime::now(),
                    ended: None,
                    outcome: None,
                });
            }
            Err(r) => tracing::info!(
                origin = ?start.origin,
                program = start.program,
                who = %request.who,
                reason = r as u16,
                "start refused ({})",
                r.describe()
            ),
        }
        if let Some(reply) = &request.reply {
            let _ = reply.try_send(answer.and(if taken { Ok(()) } else { Err(Refusal::Busy) }));
        }
        self.publish();
        taken
    }

    fn end_run(&mut self, outcome: Outcome) {
        if let Some(r) = self.run.as_mut() {
            r.ended = Some(SystemTime::now());
            r.outcome = Some(outcome);
        }
    }

    /// A command of the OPC UA face, by the PLC's rules (one measurement at a time,
    /// the same refusals, the same abort flag); `Err` says why it was refused. A start
    /// is answered once prepared: wait on the [`Pending`] after the lock is released.
    pub fn command(&mut self, cmd: &FaceCommand) -> Result<Option<Pending>, Refusal> {
        let answer = self.hs.command(cmd.command);
        match &answer {
            Ok(Some(Action::Prepare(_))) => {}
            Ok(_) => tracing::info!(
                command = ?cmd.command,
                who = %cmd.who,
                "OPC UA face: request taken"
            ),
            Err(r) => tracing::info!(
                command = ?cmd.command,
                who = %cmd.who,
                reason = *r as u16,
                "OPC UA face: request refused ({})",
                r.describe()
            ),
        }
        let pending = match answer? {
            Some(Action::Prepare(start)) => {
                let (tx, rx) = std::sync::mpsc::sync_channel(1);
                self.prepare(start, cmd.who.clone(), Some(tx));
                Some(Pending(rx))
            }
            Some(Action::Abort) => {
                tracing::info!(who = %cmd.who, "abort requested over OPC UA");
                self.request_abort(AbortReason::Request);
                None
            }
            None => None,
        };
        self.publish();
        Ok(pending)
    }

    /// Aborts the running measurement (the first reason wins). A shutdown also stops
    /// whatever would start after it.
    pub fn request_abort(&mut self, reason: AbortReason) {
        let raised = match reason {
            AbortReason::Shutdown => {
                self.abort.raise();
                true
            }
            AbortReason::Request | AbortReason::PlcHeartbeat => {
                self.abort.raise_in(self.job_generation)
            }
        };
        if raised && self.abort_reason.is_none() {
            self.abort_reason = Some(reason);
        }
    }

    /// The stop request the machine is opened with.
    pub fn abort_flag(&self) -> AbortFlag {
        self.abort
    }

    /// Why the running measurement was aborted, if it was.
    pub fn abort_reason(&self) -> Option<AbortReason> {
        self.abort_reason
    }

    /// The periodic tick: gateway heartbeat, PLC heartbeat supervision, the "results
    /// not yet recorded" bit.
    pub fn tick(&mut self, now: Instant) {
        self.heartbeat = self.heartbeat.wrapping_add(1);
        self.map.set_gateway_heartbeat(self.heartbeat);
        self.publish();
        if self.hs.heartbeat_lost(now) && self.abort_reason.is_none() {
            tracing::warn!("PLC heartbeat stale while busy: aborting the motion");
            self.request_abort(AbortReason::PlcHeartbeat);
        }
    }

    pub fn progress(&mut self, permille: u16, point: u16) {
        self.hs.progress(permille, point);
        self.publish();
    }

    /// The measurement ended (the machine is at rest): its outcome, and the stop
    /// request re-armed for the next one (not after a shutdown).
    pub fn finish(
        &mut self,
        outcome: Outcome,
        cycle: u16,
        values: &ResultValues,
        machine_time: Option<&TimeSplit>,
    ) {
        if self.abort_reason != Some(AbortReason::Shutdown) {
            self.abort.rearm();
            self.abort_reason = None;
        }
        let seq = self.hs.finish(outcome, cycle);
        let empty = BTreeMap::new();
        let values = if outcome == Outcome::Done {
            values
        } else {
            &empty
        };
        self.map.set_results(seq, values);
        // Whatever the outcome: the machine was held.
        self.map.set_machine_time(seq, machine_time);
        self.end_run(outcome);
        self.publish();
    }

    /// The results of each cycle of a run that ended done (before [`Core::finish`]).
    pub fn set_cycle_results(&mut self, cycles: Vec<(u16, ResultValues)>) {
        let at = SystemTime::now();
        for (cycle, values) in cycles {
            self.by_cycle.insert(cycle, CycleResults { at, values });
        }
    }

    /// The current or last run.
    pub fn run(&self) -> Option<&RunInfo> {
        self.run.as_ref()
    }

    /// The last results of each cycle number.
    pub fn cycle_results(&self) -> &BTreeMap<u16, CycleResults> {
        &self.by_cycle
    }

    pub fn set_machine_ok(&mut self, ok: bool) {
        self.hs.set_machine_ok(ok);
        self.publish();
    }

    pub fn state(&self) -> State {
        self.hs.state()
    }

    pub fn machine_ok(&self) -> bool {
        self.hs.machine_ok()
    }

    /// No measurement runs and none is being prepared: the service may stop without
    /// cutting one short (a restart for an upgrade waits for this).
    pub fn between_measurements(&self) -> bool {
        self.hs.state() != State::Busy && self.hs.starting().is_none()
    }
}
