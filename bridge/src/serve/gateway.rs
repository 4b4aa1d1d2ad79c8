//! What the faces (PLC, OPC UA) and the machine thread share: the register map, the
//! handshake, the connection that owns the writes, the queue of one job to the machine
//! thread, and what the OPC UA face shows of the runs.

use super::handshake::{AbortReason, Action, Face, Handshake, Outcome, Refusal, State};
use super::ownership::{Ownership, Takeover};
use super::register_map::{MapException, RegisterMap};
use crate::history::recorder::Recorder;
use crate::history::NewRun;
use cycles::program::{Program, ProgramError};
use cycles::CyclesConfig;
use hal::AbortFlag;
use std::collections::BTreeMap;
use std::net::IpAddr;
use std::path::PathBuf;
use std::sync::mpsc::Sender;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Instant, SystemTime};

/// A measurement for the machine thread.
pub struct Job {
    pub seq: u16,
    pub number: u16,
    pub program: Program,
    pub confirm: bool,
    /// The request's parameters 1..8, recorded with the run.
    pub params: [f32; super::register_map::REQ_PARAM_COUNT],
    /// The run's row in the history (written before the start was taken).
    pub record: Option<i64>,
    /// The cycles' configuration with the machine's state as its files held it when
    /// the start was taken (the last run's preset or calibration included).
    pub cycles: CyclesConfig,
}

/// A command of the OPC UA face (it has no request block): start, abort or acknowledge.
#[derive(Clone, Debug, PartialEq)]
pub struct FaceCommand {
    pub code: u16,
    pub program: u16,
    pub params: [f32; super::register_map::REQ_PARAM_COUNT],
    pub confirm: bool,
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
    pub values: BTreeMap<String, f64>,
}

pub enum ToMachine {
    Run(Box<Job>),
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
    programs: PathBuf,
    cycles: CyclesConfig,
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
    pub fn new(
        map: RegisterMap,
        hs: Handshake,
        owner: Ownership,
        programs: PathBuf,
        cycles: CyclesConfig,
        jobs: Sender<ToMachine>,
    ) -> Self {
        let mut c = Self {
            map,
            hs,
            programs,
            cycles,
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
        let (folder, cfg, history) = (&self.programs, &self.cycles, &self.history);
        let action = self.hs.on_request(&req, now, |n| {
            let cfg = state_now(cfg)?;
            let program = resolve_program(folder, &cfg, n)?;
            // The run is in the history as `running` before the start is taken.
            let record = match history {
                Some(h) => Some(begin_run(
                    h,
                    &cfg,
                    RunOrigin::Plc { seq: req.seq },
                    n,
                    &req.params,
                    &program,
                )?),
                None => None,
            };
            Ok((program, record, cfg))
        });
        if self.hs.view().reason != 0 && self.hs.view().ack_seq == req.seq && action.is_none() {
            tracing::info!(
                seq = req.seq,
                code = req.code,
                reason = self.hs.view().reason,
                "request refused"
            );
        }
        match action {
            Some(Action::Start {
                seq,
                program: (program, record, cycles),
                confirm,
            }) => {
                tracing::info!(
                    seq,
                    program = req.program,
                    params = ?req.params,
                    "measurement started"
                );
                let job = Job {
                    seq,
                    number: req.program,
                    program,
                    confirm,
                    params: req.params,
                    record,
                    cycles,
                };
                self.start(job, Face::Plc);
            }
            Some(Action::Abort) => {
                tracing::info!(seq = req.seq, "abort requested by the PLC");
                self.request_abort(AbortReason::Request);
            }
            None => {}
        }
        self.publish();
    }

    /// Hands a taken start to the machine thread.
    fn start(&mut self, job: Job, face: Face) {
        self.job_generation = self.abort.generation();
        // The old results stop matching any request before the run starts.
        self.map
            .set_results(job.seq.wrapping_sub(1), &BTreeMap::new());
        self.run = Some(RunInfo {
            program: job.number,
            face,
            started: SystemTime::now(),
            ended: None,
            outcome: None,
        });
        if self.jobs.send(ToMachine::Run(Box::new(job))).is_err() {
            let outcome = Outcome::Error {
                kind: super::handshake::ERROR_KIND_CYCLE,
                code: 0,
            };
            self.hs.finish(outcome, 0);
            self.end_run(outcome);
        }
    }

    fn end_run(&mut self, outcome: Outcome) {
        if let Some(r) = self.run.as_mut() {
            r.ended = Some(SystemTime::now());
            r.outcome = Some(outcome);
        }
    }

    /// A command of the OPC UA face, by the PLC's rules (one measurement at a time,
    /// the same refusals, the same abort flag); `Err` says why it was refused.
    pub fn command(&mut self, cmd: &FaceCommand) -> Result<(), Refusal> {
        let now = Instant::now();
        let (folder, cfg, history) = (&self.programs, &self.cycles, &self.history);
        let answer = self
            .hs
            .command(cmd.code, cmd.program, cmd.params, cmd.confirm, now, |n| {
                let cfg = state_now(cfg)?;
                let program = resolve_program(folder, &cfg, n)?;
                let record = match history {
                    Some(h) => Some(begin_run(
                        h,
                        &cfg,
                        RunOrigin::OpcUa,
                        n,
                        &cmd.params,
                        &program,
                    )?),
                    None => None,
                };
                Ok((program, record, cfg))
            });
        match &answer {
            Ok(Some(Action::Start { .. })) => {}
            Ok(_) => tracing::info!(
                code = cmd.code,
                who = %cmd.who,
                "OPC UA face: request taken"
            ),
            Err(r) => tracing::info!(
                code = cmd.code,
                program = cmd.program,
                who = %cmd.who,
                reason = *r as u16,
                "OPC UA face: request refused ({})",
                r.describe()
            ),
        }
        let result = answer.as_ref().map(|_| ()).map_err(|r| *r);
        match answer {
            Ok(Some(Action::Start {
                seq,
                program: (program, record, cycles),
                confirm,
            })) => {
                tracing::info!(
                    program = cmd.program,
                    params = ?cmd.params,
                    who = %cmd.who,
                    "measurement started over OPC UA"
                );
                let job = Job {
                    seq,
                    number: cmd.program,
                    program,
                    confirm,
                    params: cmd.params,
                    record,
                    cycles,
                };
                self.start(job, Face::OpcUa);
            }
            Ok(Some(Action::Abort)) => {
                tracing::info!(who = %cmd.who, "abort requested over OPC UA");
                self.request_abort(AbortReason::Request);
            }
            Ok(None) | Err(_) => {}
        }
        self.publish();
        result
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
    pub fn finish(&mut self, outcome: Outcome, cycle: u16, values: &BTreeMap<String, f64>) {
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
        self.end_run(outcome);
        self.publish();
    }

    /// The results of each cycle of a run that ended done (before [`Core::finish`]).
    pub fn set_cycle_results(&mut self, cycles: Vec<(u16, BTreeMap<String, f64>)>) {
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
}

/// Which face a recorded run came from: the PLC's request sequence, or OPC UA.
#[derive(Clone, Copy, Debug)]
enum RunOrigin {
    Plc { seq: u16 },
    OpcUa,
}

/// Writes the `running` row of a start; a failure refuses it ("history unavailable").
/// The history's source is "serve" for the PLC's starts, "opcua" for OPC UA's.
fn begin_run(
    history: &Recorder,
    cfg: &CyclesConfig,
    origin: RunOrigin,
    number: u16,
    params: &[f32],
    program: &Program,
) -> Result<i64, Refusal> {
    let (source, request_seq) = match origin {
        RunOrigin::Plc { seq } => ("serve", Some(seq)),
        RunOrigin::OpcUa => ("opcua", None),
    };
    history
        .begin(NewRun {
            machine: cfg.machine.name.clone(),
            source: source.into(),
            request_seq,
            program_number: Some(number),
            program: program.path.clone().unwrap_or_default(),
            max_modification: Some(cfg.parameters.max_modification),
            parameters: params.iter().map(|&p| f64::from(p)).collect(),
        })
        .map_err(|e| {
            tracing::error!(?origin, "start refused: {e}");
            Refusal::HistoryUnavailable
        })
}

/// The cycles' configuration with the machine's state read again from its files; a
/// state that cannot be read refuses the start (the machine cannot run with it;
/// nothing moved), and the log says which file and why.
fn state_now(cfg: &CyclesConfig) -> Result<CyclesConfig, Refusal> {
    cfg.reread_state().map_err(|e| {
        tracing::error!("start refused: the machine's state cannot be read: {e}");
        Refusal::MachineNotReady
    })
}

/// Program number NNN is `NNN.h` in the program folder (at least three digits).
pub fn resolve_program(
    folder: &std::path::Path,
    cfg: &CyclesConfig,
    number: u16,
) -> Result<Program, Refusal> {
    let path = folder.join(format!("{number:03}.h"));
    if !path.is_file() {
        tracing::warn!("no program {}", path.display());
        return Err(Refusal::UnknownProgram);
    }
    match Program::load(&path, cfg) {
        Ok(p) => Ok(p),
        Err(ProgramError::Invalid { path, errors }) => {
            for d in &errors.0 {
                tracing::warn!("{}: {d}", path.display());
            }
            Err(Refusal::InvalidProgram)
        }
        // There but unreadable (not UTF-8, over 1 MiB, no permission): not a program
        // this gateway can run, which is reason 4, not "no such program".
        Err(ProgramError::Read { source, .. }) if source.kind() == std::io::ErrorKind::NotFound => {
            tracing::warn!("no program {}", path.display());
            Err(Refusal::UnknownProgram)
        }
        Err(e) => {
            tracing::warn!("{e}");
            Err(Refusal::InvalidProgram)
        }
    }
}
