//! The machine thread: it opens the machine once, keeps the estimator process running
//! (restarting it when it dies), and runs one measurement at a time through the same
//! `cycles::runner::run_program` as `probebridge run`.

use super::config::GatewayConfig;
use super::gateway::{lock, Shared};
use super::machine_link::MachineLink;
use super::outcome::{
    machine_error_kind, Outcome, Refusal, ERROR_KIND_CYCLE, ERROR_KIND_NOT_KEPT, ERROR_KIND_PROGRAM,
};
use super::prepare::{Job, Preparer};
use super::results::{last_results, machine_time, of_cycle};
use super::service::{StartRequest, ToMachine};
use crate::history::recorder::{Kept, Recorder};
use crate::ipc::{EstimatorChild, IpcEstimator};
use crate::session::Session;
use cycles::confirmation::{ConfirmKind, Confirmation};
use cycles::progress::ProgressEvent;
use cycles::results::Status;
use cycles::runner::{run_program, RunOptions};
use hal::{AxisPositions, Contact, Machine, MachineError, ProbeMove};
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender};
use std::time::Duration;

const ESTIMATOR_TIMEOUT: Duration = Duration::from_secs(10);
/// How often the machine's health is asked between measurements.
const HEALTH_PERIOD: Duration = Duration::from_millis(500);

/// What the machine thread says when it has opened the machine: its notes, or why not.
pub type Ready = Result<Vec<String>, String>;

/// Starts [`run`] on a thread of its own: its handle, and where it says whether the
/// machine came up.
pub fn spawn(
    cfg: GatewayConfig,
    cycles: cycles::CyclesConfig,
    shared: Shared,
    jobs: Receiver<ToMachine>,
    history: Option<Recorder>,
) -> Result<(std::thread::JoinHandle<()>, Receiver<Ready>), String> {
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    let handle = std::thread::Builder::new()
        .name("probebridge-machine".into())
        .spawn(move || run(&cfg, &cycles, &shared, &jobs, &ready_tx, history.as_ref()))
        .map_err(|e| e.to_string())?;
    Ok((handle, ready_rx))
}

/// Runs on its own thread until `Quit` (or the sender goes away). Says on `ready`
/// whether the machine came up. Prepares each start (the gateway's lock is not held
/// meanwhile; see [`super::prepare`]), then runs it; ends of runs go to `history`.
pub fn run(
    cfg: &GatewayConfig,
    cycles: &cycles::CyclesConfig,
    shared: &Shared,
    jobs: &Receiver<ToMachine>,
    ready: &Sender<Ready>,
    history: Option<&Recorder>,
) {
    let mut opts = cfg.machine_options();
    // A move under way brakes on the PLC's abort, a stale heartbeat or SIGTERM.
    opts.abort = Some(lock(shared).service.abort_flag());
    let session = match Session::open(&opts) {
        Ok(s) => s,
        Err(e) => {
            let _ = ready.send(Err(format!("cannot open the machine: {e}")));
            return;
        }
    };
    let mut estimator = spawn_estimator(&opts.service, cfg.estimator.armed_receive);
    let _ = ready.send(Ok(session.notes.clone()));
    let mut link = MachineLink::Up(Box::new(session));
    loop {
        match jobs.recv_timeout(HEALTH_PERIOD) {
            Ok(ToMachine::Start(request)) => {
                supervise(&mut estimator, &opts.service, cfg.estimator.armed_receive);
                let preparer = Preparer {
                    programs: &cfg.programs.folder,
                    cycles,
                    history,
                };
                let ctx = Measure {
                    cfg,
                    shared,
                    history,
                };
                start(ctx, &preparer, &mut link, &estimator, &request);
                link.supervise(shared, &opts);
            }
            Ok(ToMachine::Quit) | Err(RecvTimeoutError::Disconnected) => break,
            Err(RecvTimeoutError::Timeout) => {
                supervise(&mut estimator, &opts.service, cfg.estimator.armed_receive);
                link.supervise(shared, &opts);
            }
        }
    }
    tracing::info!("machine thread: closing the machine");
}

/// Prepares a start and, once taken, runs it; a machine lost since the start was
/// asked refuses it ("machine not ok", nothing written).
fn start(
    ctx: Measure,
    preparer: &Preparer,
    link: &mut MachineLink,
    estimator: &Option<EstimatorChild>,
    request: &StartRequest,
) {
    let Some(session) = link.session() else {
        lock(ctx.shared)
            .service
            .prepared(request, Err(Refusal::MachineNotReady));
        return;
    };
    match preparer.prepare(&request.start) {
        Ok(job) => {
            if lock(ctx.shared).service.prepared(request, Ok(())) {
                measure(ctx, session, estimator.as_ref(), &job);
            }
        }
        Err(r) => {
            lock(ctx.shared).service.prepared(request, Err(r));
        }
    }
}

struct Measure<'a> {
    cfg: &'a GatewayConfig,
    shared: &'a Shared,
    history: Option<&'a Recorder>,
}

fn spawn_estimator(service: &str, armed: crate::estimator::ArmedReceive) -> Option<EstimatorChild> {
    match EstimatorChild::spawn_receiving(service, armed, crate::ipc::START_TIMEOUT) {
        Ok(c) => {
            tracing::info!(pid = c.id(), service, "estimator process started");
            Some(c)
        }
        Err(e) => {
            tracing::error!(
                "cannot start the estimator process: {e}; cycle 451 computes in the gateway"
            );
            None
        }
    }
}

/// Restarts the estimator process when it has died.
fn supervise(
    estimator: &mut Option<EstimatorChild>,
    service: &str,
    armed: crate::estimator::ArmedReceive,
) {
    let dead = match estimator.as_mut().map(EstimatorChild::try_wait) {
        Some(Ok(None)) => false,
        Some(Ok(Some(status))) => {
            tracing::warn!("estimator process exited ({status}); restarting it");
            true
        }
        Some(Err(e)) => {
            tracing::warn!("estimator process: {e}; restarting it");
            true
        }
        None => true,
    };
    if dead {
        *estimator = None;
        *estimator = spawn_estimator(service, armed);
    }
}

fn measure(ctx: Measure, session: &mut Session, estimator: Option<&EstimatorChild>, job: &Job) {
    let Measure {
        cfg,
        shared,
        history,
    } = ctx;
    let total = job.program.cycles().count().max(1);
    let (mut started, mut points) = (0usize, 0u16);
    let mut progress = |ev: ProgressEvent| {
        match ev {
            ProgressEvent::CycleStarted { block, cycle, .. } => {
                started += 1;
                tracing::info!(block, cycle, "cycle started");
            }
            ProgressEvent::Contact { .. } => points = points.saturating_add(1),
            ProgressEvent::MeasuringLog { path, .. } => {
                tracing::info!(path = %path.display(), "measuring log written");
            }
            _ => return,
        }
        let permille = (started.saturating_sub(1) * 1000 / total) as u16;
        lock(shared).service.progress(permille, points);
    };
    let confirm_all = job.start.confirm;
    let mut confirm = |asked: &Confirmation| {
        // The rotary axes at 0 deg before a 451 on a machine whose PLC positions them
        // (mStrobeRotAxPos): the PLC's start request is that confirmation.
        let confirmed = confirm_all || asked.kind == ConfirmKind::RotaryAtZero;
        tracing::info!(confirmed, kind = ?asked.kind, "confirmation asked: {asked}");
        confirmed
    };
    let out_dir = cfg
        .programs
        .out
        .clone()
        .unwrap_or_else(|| cfg.programs.folder.clone());
    let mut opts = RunOptions {
        out_dir,
        confirm: &mut confirm,
        progress: &mut progress,
        kinematics: cfg.machine.kinematics.clone(),
        estimator: None,
    };
    let mut ipc = estimator.map(|e| IpcEstimator::new(e.client(), ESTIMATOR_TIMEOUT));
    if let Some(e) = ipc.as_mut() {
        opts.estimator = Some(e);
    }
    let mut machine = ErrorNote {
        inner: &mut *session.machine,
        last_error: None,
    };
    let report = run_program(&job.program, &mut machine, &job.cycles, &mut opts);
    let reason = lock(shared).service.abort_reason();
    let mut outcome = match reason {
        Some(r) => Outcome::Aborted(r),
        None if report.completed() => Outcome::Done,
        // FN 14: the program's own error number.
        None if report.error.is_some() => Outcome::Error {
            kind: ERROR_KIND_PROGRAM,
            code: report
                .error
                .as_ref()
                .map_or(0, |e| u16::try_from(e.number).unwrap_or(u16::MAX)),
        },
        None => match machine.last_error {
            Some((kind, code)) => Outcome::Error {
                kind: machine_error_kind(kind),
                code: code.unwrap_or(0),
            },
            None => Outcome::Error {
                kind: ERROR_KIND_CYCLE,
                code: 0,
            },
        },
    };
    let (cycle, values) = last_results(&report);
    tracing::info!(
        origin = ?job.start.origin,
        program = job.start.program,
        outcome = ?outcome,
        stopped = report.stopped.as_deref().unwrap_or(""),
        "measurement finished"
    );
    // The PLC hears of the end only once it is kept: in the history, or in the spool.
    if let (Some(h), Some(id)) = (history, job.record) {
        match h.finish(id, outcome.history_status(), &report) {
            Kept::Recorded => {}
            Kept::Spooled => tracing::warn!(
                origin = ?job.start.origin,
                "results not yet recorded: the end of the run is in the spool"
            ),
            Kept::NotKept(e) => {
                tracing::error!(
                    origin = ?job.start.origin,
                    "the end of the run could not be kept ({e}): reported as an error, without results"
                );
                outcome = Outcome::Error {
                    kind: ERROR_KIND_NOT_KEPT,
                    code: 0,
                };
            }
        }
    }
    let mut gateway = lock(shared);
    let service = &mut gateway.service;
    if outcome == Outcome::Done {
        service.set_cycle_results(
            report
                .cycles
                .iter()
                .filter(|c| c.status == Status::Ok)
                .map(|c| (c.cycle, of_cycle(c)))
                .collect(),
        );
    }
    service.finish(outcome, cycle, &values, machine_time(&report).as_ref());
}

/// The machine as the cycles drive it, remembering the last error a motion returned
/// (kind, device code) for the PLC's error registers.
struct ErrorNote<'a, M: ?Sized> {
    inner: &'a mut M,
    last_error: Option<(hal::ErrorKind, Option<u16>)>,
}

impl<M: Machine<Error = MachineError> + ?Sized> ErrorNote<'_, M> {
    fn note<T>(&mut self, r: Result<T, MachineError>) -> Result<T, MachineError> {
        if let Err(e) = &r {
            self.last_error = Some((e.kind, e.code));
        }
        r
    }
}

impl<M: Machine<Error = MachineError> + ?Sized> Machine for ErrorNote<'_, M> {
    type Error = MachineError;
    fn axes(&self) -> u8 {
        self.inner.axes()
    }
    fn positions(&mut self) -> Result<AxisPositions, MachineError> {
        let r = self.inner.positions();
        self.note(r)
    }
    fn move_to(&mut self, target: &AxisPositions, feed: f64) -> Result<(), MachineError> {
        let r = self.inner.move_to(target, feed);
        self.note(r)
    }
    fn probe(&mut self, mv: &ProbeMove) -> Result<Contact, MachineError> {
        let r = self.inner.probe(mv);
        self.note(r)
    }
    fn set_run(&mut self, run_id: u64) {
        self.inner.set_run(run_id);
    }
    fn clock_ns(&mut self) -> u64 {
        self.inner.clock_ns()
    }
    fn health(&mut self) -> Result<(), MachineError> {
        self.inner.health()
    }
    fn orient_spindle(&mut self, angle_deg: f64) -> Result<bool, MachineError> {
        self.inner.orient_spindle(angle_deg)
    }
}
