//! Runs the measuring cycles of a validated program in order over a [`Machine`]. A cycle
//! error, a Q309 stop or a refused confirmation ends the program; later cycles do not
//! run.

use crate::cycle::{CycleContext, MeasuringCycle};
use crate::cycles_config::CyclesConfig;
use crate::datum::Datum;
use crate::error::{CycleError, CycleErrorKind};
use crate::kinematics::{Estimator, LocalEstimator};
use crate::kinematics_file::ActiveKinematics;
use crate::linear::{parse_linear, LinearMove, MoveFeed};
use crate::machine_time::TimedMachine;
use crate::parser::resolve_deferred;
use crate::probe_table::probes_file::ProbeCalibrations;
use crate::program::{CycleCall, CycleKind, Program, Statement};
use crate::program_flow::{start_params, substitute_params, Flow, FlowStop, Step};
use crate::progress::{ProgressEvent, ProgressSink};
use crate::q_params::{load_remanent, remanent_path, save_remanent, QParams};
use crate::results::{CycleOutput, CycleResult, ErrorStop, ProgramReport, Status};
use hal::config::MachineConfig;
use hal::machine::Error as _;
use hal::motion_guard::MotionGuard;
use hal::{AxisPositions, Machine};
use std::path::PathBuf;

mod misplaced;
mod preflight;

use misplaced::{datum_note, misplaced, misplaced_note};
use preflight::{check_cycle_moves, check_linear_move, preflight_cycle};

pub use preflight::{
    assumed_start, check_complete, nothing_moved, preflight_program, preflight_program_from,
    program_warnings, rapid, CycleTime, PlannedTime, Preflight, PreflightKind,
};

pub struct RunOptions<'a> {
    /// Where protocols are written (the TNC writes them next to the program).
    pub out_dir: PathBuf,
    /// Asks a question (the 431 protocol with Q281=2, a large 451 correction, rotary
    /// axes an M function positions) and returns whether to go on.
    pub confirm: &'a mut dyn FnMut(&crate::confirmation::Confirmation) -> bool,
    pub progress: &'a mut ProgressSink<'a>,
    /// The machine's active kinematics file (cycles 450, 451); `None`: the default
    /// beside the machine configuration.
    pub kinematics: Option<PathBuf>,
    /// Where cycle 451 fits its spheres and solves its identification (the bridge's
    /// estimator process); `None`: in this process ([`LocalEstimator`]).
    pub estimator: Option<&'a mut dyn Estimator>,
}

impl RunOptions<'_> {
    pub fn kinematics_path(&self, cfg: &MachineConfig) -> PathBuf {
        self.kinematics
            .clone()
            .unwrap_or_else(|| ActiveKinematics::default_path(cfg))
    }
}

pub fn run_program<M: Machine>(
    program: &Program,
    machine: &mut M,
    cfg: &CyclesConfig,
    opts: &mut RunOptions,
) -> ProgramReport {
    let kinematics = opts.kinematics_path(&cfg.machine);
    // Planned from where the machine stands (as `check` plans from where it assumes
    // the axes, [`assumed_start`]).
    let start = machine
        .positions()
        .unwrap_or_else(|_| assumed_start(&cfg.machine));
    let (mut report, mut params, qr_path) =
        match before_start(program, machine.axes(), cfg, &kinematics, &start) {
            Ok(started) => started,
            Err(refused) => return *refused,
        };
    let rapid = rapid(&cfg.machine);
    let mut local = LocalEstimator;
    let estimator: &mut dyn Estimator = match opts.estimator.as_deref_mut() {
        Some(e) => e,
        None => &mut local,
    };
    let mut ctx = CycleContext {
        cfg,
        kinematics,
        estimator,
        confirm: &mut *opts.confirm,
        progress: &mut *opts.progress,
        out_dir: &opts.out_dir,
        program: program.path.as_deref(),
        probing3d: Vec::new(),
        datum: Datum::new(cfg.presets.clone()),
        machine_time: None,
    };
    let guard = MotionGuard::new(&cfg.machine);
    let mut flow = Flow::new(cfg.parameters.max_jumps);
    // The probe table rows as cycle 460 last wrote them in this run.
    let mut calibrations: Option<ProbeCalibrations> = None;
    loop {
        let index = match flow.advance(program, &mut params) {
            Ok(Step::Act(i)) => i,
            Ok(Step::End) => break,
            Err(stop) => {
                flow_stopped(stop, program, cfg, &mut report);
                break;
            }
        };
        let block = &program.blocks[index];
        let resolved;
        let call = match &block.statement {
            Statement::Cycle(call) => &**call,
            Statement::Deferred(d) => {
                // Its values are known now: resolved and checked as `check` checks a
                // cycle, before it moves.
                let here = machine
                    .positions()
                    .unwrap_or_else(|_| assumed_start(&cfg.machine));
                let checked = resolve_at_run(d, &params, cfg, machine.axes(), &ctx, &guard, here);
                match checked {
                    Ok(call) => {
                        resolved = call;
                        &resolved
                    }
                    Err(e) => {
                        report.stopped = Some(e);
                        break;
                    }
                }
            }
            Statement::Datum(d) => {
                if let Err(e) = ctx.datum.apply(d) {
                    report.stopped = Some(format!("line {}: {e}", block.line));
                    break;
                }
                continue;
            }
            Statement::Other(code) => {
                let number = block.number.unwrap_or(block.line as u32);
                let moved = linear_target(code, &params, program, &ctx.datum, cfg);
                let mv = match moved {
                    Ok(Some(mv)) => mv,
                    Ok(None) => continue,
                    Err(e) => {
                        report.stopped = Some(format!("block {number} (line {}): {e}", block.line));
                        break;
                    }
                };
                let feed = match mv.feed {
                    MoveFeed::Rapid => rapid,
                    MoveFeed::Feed(f) => f,
                };
                (ctx.progress)(ProgressEvent::Move {
                    block: number,
                    target: mv.target,
                    feed,
                });
                if let Err(e) = machine.move_to(&mv.target, feed) {
                    report.aborted = e.kind() == hal::ErrorKind::Aborted;
                    let note = misplaced_note(e.kind(), &mv, &ctx.datum);
                    report.stopped =
                        Some(format!("block {number} (line {}): {e}{note}", block.line));
                    break;
                }
                continue;
            }
            _ => continue,
        };
        let recalibrated = with_row(call, &calibrations);
        let call = recalibrated.as_ref().unwrap_or(call);
        let result = run_cycle(call, machine, &mut ctx, &mut report);
        if result.status == Status::Ok {
            after_cycle(call, cfg, &ctx.kinematics, &mut calibrations, &mut report);
        }
        if result.status == Status::Ok {
            // What the cycle measured is the program's to read (Q141.., QS146, ...).
            params.set_results(&result.q, &result.qs);
        }
        report.cycles.push(result);
        if report.stopped.is_some() {
            break;
        }
    }
    report.parameters = params.written();
    keep_remanent(&params, &qr_path, &mut report);
    report
}

/// What a cycle that succeeded leaves for the rest of the run: after 460 its probe
/// table row is the probe's from the next cycle on (read back from the file); after
/// 450's restore, the earlier 451 results say what the kinematics file is now.
fn after_cycle(
    call: &CycleCall,
    cfg: &CyclesConfig,
    kinematics: &std::path::Path,
    calibrations: &mut Option<ProbeCalibrations>,
    report: &mut ProgramReport,
) {
    match &call.kind {
        CycleKind::CalibrateProbe(_) => {
            match ProbeCalibrations::load(&cfg.calibrations.path, &cfg.probes) {
                Ok(rows) => *calibrations = Some(rows),
                Err(e) => {
                    report.stopped = Some(format!(
                        "block {}: the probe table row written by cycle 460 cannot be read back: {e}",
                        call.head.block
                    ));
                }
            }
        }
        CycleKind::SaveKinematics(p) if p.mode == crate::cycle450::SaveMode::Restore => {
            note_restore(report, kinematics, &cfg.machine, call.head.block);
        }
        _ => {}
    }
}

/// `call` with its probe's calibration from `rows` (the probe table after a cycle 460
/// of this run), `None` when there are none for its probe.
fn with_row(call: &CycleCall, rows: &Option<ProbeCalibrations>) -> Option<CycleCall> {
    let row = rows.as_ref()?.row(&call.head.tool.probe.name)?;
    let mut call = call.clone();
    call.head.tool.probe.calibration = Some(row.calibration());
    Some(call)
}

/// After cycle 450 restored `path`: each earlier 451 result that wrote it says what the
/// file is now, back as it was before that 451, or not.
fn note_restore(
    report: &mut ProgramReport,
    path: &std::path::Path,
    cfg: &MachineConfig,
    block: u32,
) {
    let Ok(now) = ActiveKinematics::load(path, cfg) else {
        return;
    };
    for k in report
        .cycles
        .iter_mut()
        .filter_map(|c| c.kinematics.as_mut())
    {
        if !k.written || k.kinematics_file != path {
            continue;
        }
        let back = k.errors_before.iter().all(|(n, v)| now.error(n) == *v)
            && now.errors.keys().all(|n| k.errors_before.contains_key(n));
        k.restored = Some(if back {
            format!("restored by cycle 450 (block {block}): the file is back as it was before this cycle")
        } else {
            format!("cycle 450 (block {block}) restored a saved version that differs from the one before this cycle")
        });
    }
}

/// What `run` checks before the first move (as `check`), and the parameters it starts
/// with (the QR values kept beside the preset table): the report so far, the
/// parameters, the QR file; or the report of the refusal (nothing moved).
fn before_start(
    program: &Program,
    machine_axes: u8,
    cfg: &CyclesConfig,
    kinematics: &std::path::Path,
    start: &AxisPositions,
) -> Result<(ProgramReport, QParams, PathBuf), Box<ProgramReport>> {
    let mut report = ProgramReport::default();
    match preflight_program_from(program, machine_axes, cfg, kinematics, start) {
        Ok(_) => {}
        Err(Preflight::Cycle {
            block,
            cycle,
            message,
            ..
        }) => {
            report.stopped = Some(format!("block {block}: {message}"));
            report
                .cycles
                .push(CycleResult::error(block, cycle, message));
            return Err(Box::new(report));
        }
        Err(e @ (Preflight::Positioning { .. } | Preflight::Program { .. })) => {
            report.stopped = Some(nothing_moved(e));
            return Err(Box::new(report));
        }
    }
    let qr_path = remanent_path(&cfg.presets.path);
    match load_remanent(&qr_path) {
        Ok(r) => Ok((report, start_params(&r), qr_path)),
        Err(e) => {
            report.stopped = Some(nothing_moved(e));
            Err(Box::new(report))
        }
    }
}

/// Writes the QR values when the run set one; a failure is said in `stopped`.
fn keep_remanent(params: &QParams, qr_path: &std::path::Path, report: &mut ProgramReport) {
    if !params.remanent_written() {
        return;
    }
    if let Err(e) = save_remanent(qr_path, &params.remanent()) {
        let why = format!("{e}");
        report.stopped = Some(match report.stopped.take() {
            Some(s) => format!("{s}; {why}"),
            None => why,
        });
    }
}

/// A cycle block with Q-parameter values, resolved with the values they have now and
/// checked as `check` checks a cycle, before it moves.
fn resolve_at_run(
    d: &crate::program::DeferredCycle,
    params: &QParams,
    cfg: &CyclesConfig,
    machine_axes: u8,
    ctx: &CycleContext<'_>,
    guard: &MotionGuard,
    here: AxisPositions,
) -> Result<CycleCall, String> {
    let call = resolve_deferred(d, params, cfg).map_err(|e| format!("line {}: {e}", d.line))?;
    // The plan's datum and positions are the ones the cycle will start from; what the
    // cycle itself then changes, it changes when it runs.
    let (mut datum, mut here) = (ctx.datum.clone(), here);
    preflight_cycle(&call, machine_axes, cfg, &ctx.kinematics)
        .and_then(|()| check_cycle_moves(&call, cfg, &ctx.kinematics, &mut datum, &mut here, guard))
        .map_err(|e| e.to_string())?;
    Ok(call)
}

/// Reports why the program flow stopped: FN 14 with its number and text, or a block
/// that cannot be carried out, at its line.
fn flow_stopped(stop: FlowStop, program: &Program, cfg: &CyclesConfig, report: &mut ProgramReport) {
    match stop {
        FlowStop::Error { line, number } => {
            let text = cfg.parameters.errors.get(&number.to_string()).cloned();
            let shown = text.as_ref().map_or(String::new(), |t| format!(": {t}"));
            report.stopped = Some(format!("line {line}: FN 14: ERROR = {number}{shown}"));
            report.error = Some(ErrorStop { line, number, text });
        }
        FlowStop::Fault { line, message, .. } => {
            report.stopped = Some(format!("line {line}: {message}"));
        }
        // Only `check` has parameters without a value.
        FlowStop::Undecided { index, .. } => {
            let line = program.blocks[index].line;
            report.stopped = Some(format!("line {line}: the condition has no value"));
        }
    }
}

/// The move of an `L` block (`None` for any other block) with its parameters' values,
/// in machine coordinates, checked as `check` checks constant ones: values from
/// parameters are known only now, before the move.
fn linear_target(
    code: &str,
    params: &QParams,
    program: &Program,
    datum: &Datum,
    cfg: &CyclesConfig,
) -> Result<Option<LinearMove>, String> {
    let code = substitute_params(code, params).map_err(|e| e.to_string())?;
    match parse_linear(&code, program.unit) {
        Some(Ok(mut mv)) => {
            // Program coordinates: relative to the active preset plus shift, or
            // machine coordinates (M91) / the reference point (M92).
            mv.target = mv
                .machine_target(datum, cfg.parameters.m92_reference)
                .map_err(|e| e.to_string())?;
            check_linear_move(&mv, &cfg.machine)
                .map(|()| Some(mv))
                .map_err(|e| e.to_string())
        }
        Some(Err(e)) => Err(e.to_string()),
        None => Ok(None),
    }
}

/// Runs one cycle and reports it: its start, its result, the logs it wrote, why the
/// program stops after it.
fn run_cycle<M: Machine>(
    call: &CycleCall,
    machine: &mut M,
    ctx: &mut CycleContext<'_>,
    report: &mut ProgramReport,
) -> CycleResult {
    let head = &call.head;
    (ctx.progress)(ProgressEvent::CycleStarted {
        block: head.block,
        cycle: head.cycle,
        line: head.line,
    });
    // Timed on the machine's own clock, whatever the outcome: the machine was held.
    let mut timed = TimedMachine::new(machine);
    ctx.machine_time = Some(timed.ledger());
    let outcome: Result<CycleOutput, CycleError> = match &call.kind {
        CycleKind::MeasurePlane(p) => p.run(head, &mut timed, ctx),
        CycleKind::Probing3d(p) => p.run(head, &mut timed, ctx),
        CycleKind::SaveKinematics(p) => p.run(head, &mut timed, ctx),
        CycleKind::MeasureKinematics(p) => p.run(head, &mut timed, ctx),
        CycleKind::CalibrateProbe(p) => p.run(head, &mut timed, ctx),
    };
    let split = timed.split();
    ctx.machine_time = None;
    let result = match outcome {
        Ok(out) => {
            for path in out.logs {
                (ctx.progress)(ProgressEvent::MeasuringLog {
                    block: head.block,
                    path: path.clone(),
                });
                if !report.protocols.contains(&path) {
                    report.protocols.push(path);
                }
            }
            if let Some(m) = &out.stop {
                report.stopped = Some(format!("block {}: {m}", head.block));
            }
            CycleResult {
                block: head.block,
                cycle: head.cycle,
                q: out.q,
                qs: out.qs,
                status: Status::Ok,
                message: out.stop,
                u: out.u,
                kinematics: out.kinematics,
                calibration: out.calibration,
                machine_time_s: None,
                machine_time_split_s: None,
            }
        }
        Err(e) if e.kind() == CycleErrorKind::Machine(hal::ErrorKind::Aborted) => {
            let message = e.to_string();
            report.aborted = true;
            report.stopped = Some(format!(
                "block {}: cycle {} aborted: {message}",
                head.block, head.cycle
            ));
            CycleResult::aborted(head.block, head.cycle, message)
        }
        Err(e) => {
            let mut message = e.to_string();
            if misplaced(e.kind()) {
                message.push_str(&datum_note(&ctx.datum));
            }
            report.stopped = Some(format!(
                "block {}: cycle {} failed: {message}",
                head.block, head.cycle
            ));
            CycleResult::error(head.block, head.cycle, message)
        }
    };
    let result = result.timed(split);
    (ctx.progress)(ProgressEvent::CycleFinished {
        block: head.block,
        cycle: head.cycle,
        status: result.status,
    });
    result
}
