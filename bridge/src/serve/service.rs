//! The measurement service: the one place every face reaches the machine through. It
//! keeps the rules every face follows ([`Measurement`]: one measurement at a time, the
//! first start wins, abort, acknowledge, progress), hands starts to the machine thread,
//! holds the stop request, the current run, the last results (written once, read by
//! every face), the history's "not yet recorded" state and the gateway's heartbeat.
//! The faces adapt to it: the PLC face ([`super::plc_registers`]) draws its registers from
//! it, the OPC UA face its nodes, the web face its status page. It knows no face's
//! encoding, and does no I/O: a start is prepared on the machine thread
//! ([`super::prepare`]), which answers it with [`Service::prepared`].

use super::measurement::{
    Action, Command, Face, Measurement, Origin, Start, StartId, State, Status,
};
use super::outcome::{AbortReason, Outcome, Refusal};
use super::results::ResultValues;
use crate::history::recorder::Recorder;
use cycles::machine_time::TimeSplit;
use hal::AbortFlag;
use std::collections::{BTreeMap, VecDeque};
use std::sync::mpsc::{Receiver, Sender, SyncSender};
use std::time::SystemTime;

/// A run as the faces show it: the program, who started it, when it started and
/// ended, how.
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

/// The results of the last run, as every face reads them: the sequence of the request
/// they answer ([`super::measurement::NO_REQUEST`] from a start until its run ends, and
/// for runs no PLC request started), the values (none unless it ended done) and how
/// long it held the machine.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RunResults {
    pub seq: u16,
    pub values: ResultValues,
    pub machine_time: Option<TimeSplit>,
}

/// A start for the machine thread to prepare (see [`super::prepare`]) and run.
pub struct StartRequest {
    pub start: Start,
    /// Who asked (the OPC UA user; "PLC"), for the log.
    pub who: String,
    id: StartId,
    /// Where the answer goes, for a face that waits for it (OPC UA's methods).
    reply: SyncSender<Result<(), Refusal>>,
}

/// The answer to a start being prepared: wait for it without the service's lock, or
/// look for it by its id ([`Service::last_answer`]).
pub struct Pending {
    id: StartId,
    answer: Receiver<Result<(), Refusal>>,
}

impl Pending {
    pub fn id(&self) -> StartId {
        self.id
    }

    /// The start taken, or why it was refused (the machine thread gone: machine not
    /// ready).
    pub fn wait(self) -> Result<(), Refusal> {
        self.answer.recv().unwrap_or(Err(Refusal::MachineNotReady))
    }
}

pub enum ToMachine {
    Start(Box<StartRequest>),
    Quit,
}

/// State transitions kept for the OPC UA face; the oldest go first beyond it.
const MAX_TRANSITIONS: usize = 64;

pub struct Service {
    rules: Measurement,
    jobs: Sender<ToMachine>,
    /// The machine's stop request (hal's, which brakes a move under way); re-armed when
    /// the measurement it cut short has ended.
    abort: AbortFlag,
    /// Why the running measurement was aborted (the first reason wins).
    abort_reason: Option<AbortReason>,
    /// The flag's generation of the running measurement: a late abort of a finished
    /// one does not hit the next.
    job_generation: u64,
    /// Where runs are recorded (none: history off).
    history: Option<Recorder>,
    /// The current or last run (none yet).
    run: Option<RunInfo>,
    results: RunResults,
    /// Counts the changes of `results` (a face that draws them knows when to again).
    results_generation: u64,
    /// The last results of each cycle number.
    by_cycle: BTreeMap<u16, CycleResults>,
    /// The last start handed to the machine thread.
    last_start: StartId,
    /// The last start answered, and how.
    last_answer: Option<(StartId, Result<(), Refusal>)>,
    /// Counts the service's ticks: the faces show it as the gateway's heartbeat.
    heartbeat: u16,
    /// Ticks on every change of what the faces show (the OPC UA face waits on it).
    changed: tokio::sync::watch::Sender<u64>,
    /// The states passed through since the OPC UA face last looked (a run on the
    /// simulator can start and end before it looks): at most [`MAX_TRANSITIONS`].
    transitions: VecDeque<State>,
    last_state: State,
}

/// How a face's request reads in the log.
fn by(origin: Origin) -> &'static str {
    match origin {
        Origin::Plc { .. } => "by the PLC",
        Origin::OpcUa => "over OPC UA",
    }
}

impl Service {
    pub fn new(jobs: Sender<ToMachine>) -> Self {
        Self {
            rules: Measurement::new(),
            jobs,
            abort: AbortFlag::fresh(),
            abort_reason: None,
            job_generation: 0,
            history: None,
            run: None,
            results: RunResults::default(),
            results_generation: 0,
            by_cycle: BTreeMap::new(),
            last_start: 0,
            last_answer: None,
            heartbeat: 0,
            changed: tokio::sync::watch::Sender::new(0),
            transitions: VecDeque::new(),
            last_state: State::Idle,
        }
    }

    /// Record every run here: a start is taken only once its `running` row is written.
    pub fn set_history(&mut self, history: Recorder) {
        self.history = Some(history);
        self.publish();
    }

    fn publish(&mut self) {
        if let Some(h) = &self.history {
            self.rules.set_not_recorded(h.pending() > 0);
        }
        let state = self.rules.state();
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

    /// A command of any face, by the same rules (one measurement at a time, the same
    /// refusals, the same abort flag); `Err` says why it was refused. A start is
    /// answered once prepared on the machine thread: wait on the [`Pending`] after the
    /// lock is released, or look for its id in [`Service::last_answer`].
    /// `well_formed`: see [`Measurement::decide`].
    pub fn command(
        &mut self,
        cmd: Command,
        origin: Origin,
        well_formed: bool,
        who: &str,
    ) -> Result<Option<Pending>, Refusal> {
        let answer = self.rules.decide(cmd, origin, well_formed);
        let pending = match answer {
            Ok(Some(Action::Prepare(start))) => Some(self.prepare(start, who)),
            Ok(Some(Action::Abort)) => {
                tracing::info!(?origin, who, "abort requested {}", by(origin));
                self.request_abort(AbortReason::Request);
                None
            }
            Ok(None) => {
                tracing::info!(?origin, command = ?cmd, who, "request taken");
                None
            }
            Err(r) => {
                tracing::info!(
                    ?origin,
                    command = ?cmd,
                    who,
                    reason = r as u16,
                    "request refused {} ({})",
                    by(origin),
                    r.describe()
                );
                None
            }
        };
        self.publish();
        answer.map(|_| pending)
    }

    /// Hands a start to the machine thread, which prepares it off the lock and answers
    /// with [`Service::prepared`].
    fn prepare(&mut self, start: Start, who: &str) -> Pending {
        // An abort from here on hits this run, not the last one.
        self.job_generation = self.abort.generation();
        self.last_start += 1;
        let (reply, answer) = std::sync::mpsc::sync_channel(1);
        let id = self.last_start;
        let request = StartRequest {
            start,
            who: who.to_string(),
            id,
            reply,
        };
        if let Err(e) = self.jobs.send(ToMachine::Start(Box::new(request))) {
            if let ToMachine::Start(request) = e.0 {
                tracing::error!("start refused: the machine thread has ended");
                self.prepared(&request, Err(Refusal::MachineNotReady));
            }
        }
        Pending { id, answer }
    }

    /// The machine thread prepared a start: it is taken (the old results stop
    /// matching any request, the state is busy) or refused; the face that asked hears
    /// of it. Whether the run is under way (the machine thread runs it).
    pub fn prepared(&mut self, request: &StartRequest, answer: Result<(), Refusal>) -> bool {
        let start = &request.start;
        let Some(taken) = self.rules.prepared(start, answer) else {
            tracing::error!(origin = ?start.origin, "a start that was not being prepared: dropped");
            let _ = request.reply.try_send(Err(Refusal::Busy));
            return false;
        };
        match answer {
            Ok(()) => {
                tracing::info!(
                    origin = ?start.origin,
                    program = start.program,
                    params = ?start.params,
                    who = %request.who,
                    "measurement started"
                );
                // The last run's results stop matching any start.
                self.results = RunResults::default();
                self.results_generation += 1;
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
        self.last_answer = Some((request.id, answer));
        let _ = request.reply.try_send(answer);
        self.publish();
        taken
    }

    /// The last start answered: its id and the answer.
    pub fn last_answer(&self) -> Option<(StartId, Result<(), Refusal>)> {
        self.last_answer
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

    /// The periodic tick: the gateway's heartbeat, the "results not yet recorded" state.
    pub fn tick(&mut self) {
        self.heartbeat = self.heartbeat.wrapping_add(1);
        self.publish();
    }

    /// The gateway's heartbeat: counts the ticks.
    pub fn heartbeat(&self) -> u16 {
        self.heartbeat
    }

    pub fn progress(&mut self, permille: u16, point: u16) {
        self.rules.progress(permille, point);
        self.publish();
    }

    /// The measurement ended (the machine is at rest): its outcome and results, and
    /// the stop request re-armed for the next one (not after a shutdown).
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
        let seq = self.rules.finish(outcome, cycle);
        self.results = RunResults {
            seq,
            values: if outcome == Outcome::Done {
                values.clone()
            } else {
                ResultValues::default()
            },
            // Whatever the outcome: the machine was held.
            machine_time: machine_time.copied(),
        };
        self.results_generation += 1;
        if let Some(r) = self.run.as_mut() {
            r.ended = Some(SystemTime::now());
            r.outcome = Some(outcome);
        }
        self.publish();
    }

    /// The results of each cycle of a run that ended done (before [`Service::finish`]).
    pub fn set_cycle_results(&mut self, cycles: Vec<(u16, ResultValues)>) {
        let at = SystemTime::now();
        for (cycle, values) in cycles {
            self.by_cycle.insert(cycle, CycleResults { at, values });
        }
    }

    /// The last run's results (cleared when a start is taken).
    pub fn results(&self) -> &RunResults {
        &self.results
    }

    /// Counts the changes of [`Service::results`].
    pub fn results_generation(&self) -> u64 {
        self.results_generation
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
        self.rules.set_machine_ok(ok);
        self.publish();
    }

    /// What every face shows of the measurement.
    pub fn status(&self) -> &Status {
        self.rules.status()
    }

    pub fn state(&self) -> State {
        self.rules.state()
    }

    pub fn machine_ok(&self) -> bool {
        self.rules.status().machine_ok
    }

    /// No measurement runs and none is being prepared: the service may stop without
    /// cutting one short (a restart for an upgrade waits for this).
    pub fn between_measurements(&self) -> bool {
        self.rules.between_measurements()
    }
}
