//! Runs the measuring cycles of a validated program in order over a [`Machine`]. A cycle
//! error, a Q309 stop or a refused confirmation ends the program; later cycles do not
//! run.

use crate::cycle::{CycleContext, MeasuringCycle};
use crate::cycle451;
use crate::cycle451::PlanErrorKind;
use crate::cycles_config::CyclesConfig;
use crate::datum::Datum;
use crate::error::{CycleError, CycleErrorKind};
use crate::formula::EvalErrorKind;
use crate::kinematics::{Estimator, LocalEstimator};
use crate::kinematics_file::ActiveKinematics;
use crate::linear::{
    parse_linear, Coordinates, LinearBlockError, LinearBlockErrorKind, LinearMove, MoveFeed,
};
use crate::parser::resolve_deferred;
use crate::planned_move::{check_planned, PlannedMove};
use crate::program::{CycleCall, CycleKind, Program, Statement};
use crate::program_flow::{
    start_params, substitute_params, CheckWalk, Flow, FlowFaultKind, FlowStop, Step,
};
use crate::progress::{ProgressEvent, ProgressSink};
use crate::q_params::{load_remanent, remanent_path, save_remanent, QParams};
use crate::results::{CycleOutput, CycleResult, ErrorStop, ProgramReport, Status};
use hal::config::MachineConfig;
use hal::machine::Error as _;
use hal::motion_guard::MotionGuard;
use hal::{Axis, AxisPositions, Machine};
use std::path::PathBuf;

pub struct RunOptions<'a> {
    /// Where protocols are written (the TNC writes them next to the program).
    pub out_dir: PathBuf,
    /// Shows a text (the 431 protocol with Q281=2) and returns whether to go on.
    pub confirm: &'a mut dyn FnMut(&str) -> bool,
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

/// Why a program cannot start on this machine.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum PreflightKind {
    /// Cycle 451 cannot be planned on this machine.
    Plan(PlanErrorKind),
    /// The active kinematics file cannot be read.
    ActiveKinematics,
    /// The probe of a TOOL CALL is not in the probe table.
    ProbeNotInTable,
    /// The machine lacks a linear axis.
    MissingAxis,
    /// A positioning block (L) cannot run.
    Positioning(LinearBlockErrorKind),
    /// A move of a probing cycle (431, 444) the machine would refuse: a point outside
    /// the software limits, a feed the axes cannot run, a safe height below a start.
    Moves,
    /// A Q-parameter block that cannot be carried out (an undefined parameter, a
    /// division by zero, a program that loops, ...).
    Program(FlowFaultKind),
    /// The QR parameters kept beside the preset table cannot be read.
    Remanent,
}

/// Checks, before anything moves, what only the machine and its configuration can
/// tell: the probe of each cycle is still in the probe table, the machine has X, Y, Z,
/// and this build can run the cycle.
fn preflight(
    call: &CycleCall,
    machine_axes: u8,
    cfg: &CyclesConfig,
    kinematics: &std::path::Path,
) -> Result<(), (PreflightKind, String)> {
    let tool = &call.head.tool;
    match &call.kind {
        CycleKind::MeasurePlane(_) | CycleKind::Probing3d(_) => {}
        // Works on files only: no probe, no motion.
        CycleKind::SaveKinematics(_) => return Ok(()),
        CycleKind::MeasureKinematics(p) => {
            cycle451::plan(p, &tool.probe, &cfg.machine)
                .map_err(|e| (PreflightKind::Plan(e.kind()), format!("{e}; nothing moved")))?;
            ActiveKinematics::load(kinematics, &cfg.machine).map_err(|e| {
                (
                    PreflightKind::ActiveKinematics,
                    format!("active kinematics: {e}; nothing moved"),
                )
            })?;
        }
    }
    if cfg.probe(&tool.probe.name).is_none() {
        return Err((
            PreflightKind::ProbeNotInTable,
            format!(
                "probe \"{}\" (TOOL CALL line {}) is not in the probe table of machine {}",
                tool.probe.name, tool.line, cfg.machine.name
            ),
        ));
    }
    for a in Axis::LINEAR {
        if machine_axes & (1 << a.index()) == 0 {
            return Err((
                PreflightKind::MissingAxis,
                format!("the machine has no {a} axis"),
            ));
        }
    }
    Ok(())
}

/// Why a program cannot start on this machine.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum Preflight {
    /// A cycle's demands the machine, its configuration or its kinematics file cannot
    /// meet.
    #[error("line {line}, block {block} (cycle {cycle}): {message}")]
    Cycle {
        block: u32,
        cycle: u16,
        /// 1-based first line of the cycle block.
        line: usize,
        kind: PreflightKind,
        message: String,
    },
    /// A positioning block (L) that cannot be carried out.
    #[error("line {line}: {error}")]
    Positioning {
        line: usize,
        error: LinearBlockError,
    },
    /// A Q-parameter block (or the QR file, line 0) that cannot be carried out.
    #[error("line {line}: {message}")]
    Program {
        line: usize,
        kind: PreflightKind,
        message: String,
    },
}

impl Preflight {
    pub fn kind(&self) -> PreflightKind {
        match self {
            Preflight::Cycle { kind, .. } => *kind,
            Preflight::Positioning { error, .. } => PreflightKind::Positioning(error.kind()),
            Preflight::Program { kind, .. } => *kind,
        }
    }
}

/// Everything `run_program` checks before the first move, without a machine: `check`
/// runs it on the configuration's axes, `run` on the connected machine's. The axes
/// start where [`assumed_start`] puts them (`run` starts from where the machine stands,
/// [`preflight_program_from`]).
pub fn preflight_program(
    program: &Program,
    machine_axes: u8,
    cfg: &CyclesConfig,
    kinematics: &std::path::Path,
) -> Result<(), Preflight> {
    let start = assumed_start(&cfg.machine);
    preflight_program_from(program, machine_axes, cfg, kinematics, &start)
}

/// Where `check` assumes the axes stand before the program's first block: every axis
/// at 0 (or the software limit nearest to it). The program's `L` blocks move them from
/// there, so a program that pre-positions the probe is planned exactly as `run` will
/// move it.
pub fn assumed_start(machine: &MachineConfig) -> AxisPositions {
    let mut p = AxisPositions::new();
    for a in &machine.axes {
        p.set(a.name, 0.0f64.clamp(a.min, a.max));
    }
    p
}

/// [`preflight_program`] with the axes at `start` before the first block.
pub fn preflight_program_from(
    program: &Program,
    machine_axes: u8,
    cfg: &CyclesConfig,
    kinematics: &std::path::Path,
    start: &AxisPositions,
) -> Result<(), Preflight> {
    for call in program.cycles() {
        preflight_cycle(call, machine_axes, cfg, kinematics)?;
    }
    // The moves themselves, in the order the program runs them (its jumps, calls and
    // repeats followed, the parameters it computes from constants known) with the
    // datum as the program changes it and every axis where the blocks before leave it:
    // `L` targets, the probing cycles' points, and every move of cycle 451 (planned by
    // running its sequence on a dry-run machine), in machine coordinates.
    let guard = MotionGuard::new(&cfg.machine);
    let params = start_params(
        &load_remanent(&remanent_path(&cfg.presets.path)).map_err(|e| Preflight::Program {
            line: 0,
            kind: PreflightKind::Remanent,
            message: e.to_string(),
        })?,
    );
    let mut walk = CheckWalk::new(
        program,
        params,
        Datum::new(cfg.presets.clone()),
        assumed_start(&cfg.machine).merged(start),
        cfg.parameters.max_jumps,
    );
    while let Some(block) = walk.next_block().map_err(|f| Preflight::Program {
        line: f.line,
        kind: PreflightKind::Program(f.kind),
        message: f.message,
    })? {
        let (datum, params, here) = walk.state();
        let mut path_ends = false;
        match &block.statement {
            // `run` stops at a preset row that does not exist, with the same message;
            // nothing after it moves.
            Statement::Datum(d) if datum.apply(d).is_err() => path_ends = true,
            Statement::Other(code) => {
                // A value measured by a cycle is known only when the program runs:
                // `run` checks that move then, before it moves.
                let code = match substitute_params(code, params) {
                    Ok(c) => c,
                    Err(e) if e.kind == EvalErrorKind::Measured => continue,
                    Err(e) => {
                        return Err(Preflight::Program {
                            line: block.line,
                            kind: PreflightKind::Program(FlowFaultKind::Eval(e.kind)),
                            message: e.message,
                        })
                    }
                };
                let checked = parse_linear(&code, program.unit).map(|r| {
                    r.and_then(|mut mv| {
                        mv.target = mv.machine_target(datum, cfg.parameters.m92_reference)?;
                        check_linear_move(&mv, &cfg.machine).map(|()| mv)
                    })
                });
                match checked {
                    Some(Err(error)) => {
                        return Err(Preflight::Positioning {
                            line: block.line,
                            error,
                        })
                    }
                    Some(Ok(mv)) => *here = here.merged(&mv.target),
                    None => {}
                }
            }
            Statement::Cycle(call) => {
                check_cycle_moves(call, cfg, kinematics, datum, here, &guard)?;
            }
            Statement::Deferred(d) => match resolve_deferred(d, params, cfg) {
                // A value measured by a cycle: `run` resolves and checks the block
                // then, before it moves.
                Err(e) if e.kind == EvalErrorKind::Measured => {}
                Err(e) => {
                    return Err(Preflight::Program {
                        line: d.line,
                        kind: PreflightKind::Program(FlowFaultKind::Eval(e.kind)),
                        message: e.message,
                    })
                }
                Ok(call) => {
                    preflight_cycle(&call, machine_axes, cfg, kinematics)?;
                    check_cycle_moves(&call, cfg, kinematics, datum, here, &guard)?;
                }
            },
            _ => {}
        }
        if path_ends {
            walk.end_path();
        }
    }
    Ok(())
}

/// [`preflight`] of one cycle, as a [`Preflight`] error.
fn preflight_cycle(
    call: &CycleCall,
    machine_axes: u8,
    cfg: &CyclesConfig,
    kinematics: &std::path::Path,
) -> Result<(), Preflight> {
    preflight(call, machine_axes, cfg, kinematics).map_err(|(kind, message)| Preflight::Cycle {
        block: call.head.block,
        cycle: call.head.cycle,
        line: call.head.line,
        kind,
        message,
    })
}

/// The moves a cycle plans, from the datum and the axes where the program's path
/// leaves them, against the motion guard: the probing cycles' points, and every move of
/// cycle 451 (its sequence run on a dry-run machine). Leaves `here` where the cycle
/// leaves the axes, and, for 451 with Q431 = 1/3 in modes 1..3, the active preset at
/// the sphere centre it sets.
fn check_cycle_moves(
    call: &CycleCall,
    cfg: &CyclesConfig,
    kinematics: &std::path::Path,
    datum: &mut Datum,
    here: &mut AxisPositions,
    guard: &MotionGuard,
) -> Result<(), Preflight> {
    let origin = datum.origin();
    let refused = |kind: PreflightKind, message: String| Preflight::Cycle {
        block: call.head.block,
        cycle: call.head.cycle,
        line: call.head.line,
        kind,
        message,
    };
    let moves = match &call.kind {
        CycleKind::MeasurePlane(p) => p
            .planned_moves(&call.head, origin)
            .map_err(|e| e.to_string()),
        CycleKind::Probing3d(p) => p
            .planned_moves(&call.head, origin)
            .map_err(|e| e.to_string()),
        CycleKind::MeasureKinematics(p) => {
            let planned =
                cycle451::dry_run::plan_moves(p, &call.head, cfg, kinematics, datum, here)
                    .map_err(|e| {
                        let mut message = e.to_string();
                        if !message.ends_with("nothing moved") {
                            message.push_str("; nothing moved");
                        }
                        refused(PreflightKind::Plan(e.kind()), message)
                    })?;
            *here = planned.end;
            // Q431 = 1/3 in modes 1..3: later blocks are relative to the preset the
            // cycle writes at the sphere centre.
            if (p.preset == 1 || p.preset == 3) && p.mode.writes() {
                let row = [0, 1, 2].map(|i| planned.preset[i] - datum.shift[i]);
                datum.presets.set_active_xyz(row);
            }
            Ok(Vec::new())
        }
        CycleKind::SaveKinematics(_) => Ok(Vec::new()),
    };
    let moves = moves
        .and_then(|m| check_planned(&m, guard).map(|()| m))
        .map_err(|message| refused(PreflightKind::Moves, message))?;
    for m in &moves {
        if let PlannedMove::Position { target, .. } = m {
            *here = here.merged(target);
        }
    }
    Ok(())
}

/// A program file as `check` and `run` take it: BEGIN PGM and END PGM present (an
/// empty, whitespace-only or cut-off file does nothing and must not pass as ok).
/// Program text built in code (tests, embedding) may leave them out.
pub fn check_complete(program: &Program) -> Result<(), String> {
    let has = |f: fn(&Statement) -> bool| program.blocks.iter().any(|b| f(&b.statement));
    if !has(|s| matches!(s, Statement::BeginPgm { .. })) {
        return Err("no BEGIN PGM: an empty or cut-off program; nothing moved".into());
    }
    if !has(|s| matches!(s, Statement::EndPgm { .. })) {
        return Err("no END PGM: a cut-off program; nothing moved".into());
    }
    Ok(())
}

/// What the machine would refuse of an `L` block, found before anything moves: a
/// target outside the software limits, a feed outside the motion guard's range.
fn check_linear_move(mv: &LinearMove, machine: &MachineConfig) -> Result<(), LinearBlockError> {
    for (axis, v) in mv.target.iter() {
        if let Some(a) = machine.axes.iter().find(|a| a.name == axis) {
            if !(a.min..=a.max).contains(&v) {
                return Err(LinearBlockError::new(
                    LinearBlockErrorKind::SoftwareLimit,
                    format!(
                        "L block: {axis}{v:+.4} is outside the software limits {:+.4} .. {:+.4}",
                        a.min, a.max
                    ),
                ));
            }
        }
    }
    if let MoveFeed::Feed(f) = mv.feed {
        let fastest = machine.axes.iter().map(|a| a.max_feed).fold(0.0, f64::max);
        if !(hal::motion_guard::MIN_FEED..=fastest).contains(&f) {
            return Err(LinearBlockError::new(
                LinearBlockErrorKind::Feed,
                format!(
                    "L block: F{f}: the feed must be between {} and the machine's fastest max_feed {fastest} mm/min",
                    hal::motion_guard::MIN_FEED
                ),
            ));
        }
    }
    Ok(())
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
    // Rapid positioning: as fast as the slowest axis on the path allows.
    let rapid = cfg
        .machine
        .axes
        .iter()
        .map(|a| a.max_feed)
        .fold(0.0, f64::max);
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
    };
    let guard = MotionGuard::new(&cfg.machine);
    let mut flow = Flow::new(cfg.parameters.max_jumps);
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
        let result = run_cycle(call, machine, &mut ctx, &mut report);
        if let (CycleKind::SaveKinematics(p), Status::Ok) = (&call.kind, result.status) {
            if p.mode == crate::cycle450::SaveMode::Restore {
                note_restore(&mut report, &ctx.kinematics, &cfg.machine, call.head.block);
            }
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
        Ok(()) => {}
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
            report.stopped = Some(format!("{e}; nothing moved"));
            return Err(Box::new(report));
        }
    }
    let qr_path = remanent_path(&cfg.presets.path);
    match load_remanent(&qr_path) {
        Ok(r) => Ok((report, start_params(&r), qr_path)),
        Err(e) => {
            report.stopped = Some(format!("{e}; nothing moved"));
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

/// A failure that says the probe was not where the program assumed: no contact where
/// one was due, or one where none was.
fn misplaced(kind: CycleErrorKind) -> bool {
    use hal::ErrorKind as K;
    matches!(
        kind,
        CycleErrorKind::Machine(K::NotTriggered | K::AlreadyDeflected | K::ProbeCollision)
    )
}

/// [`datum_note`] for an `L` move in program coordinates that failed because the probe
/// was not where the program assumed; empty otherwise.
fn misplaced_note(kind: hal::ErrorKind, mv: &LinearMove, datum: &Datum) -> String {
    if misplaced(CycleErrorKind::Machine(kind)) && mv.coordinates == Coordinates::Datum {
        datum_note(datum)
    } else {
        String::new()
    }
}

/// "; the active preset is row N (X.. Y.. Z..)": where the program's coordinates
/// pointed, for a failure that may come from a preset set elsewhere.
fn datum_note(datum: &Datum) -> String {
    let row = datum.presets.active_row();
    let shift = if datum.shift == [0.0; 3] {
        String::new()
    } else {
        format!(
            ", plus the datum shift X{:+.4} Y{:+.4} Z{:+.4}",
            datum.shift[0], datum.shift[1], datum.shift[2]
        )
    };
    format!(
        " (the program's coordinates were relative to preset row {} of {}: X{:+.4} Y{:+.4} Z{:+.4}{shift}; M91 blocks are machine coordinates)",
        row.number,
        datum.presets.path.display(),
        row.x,
        row.y,
        row.z
    )
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
    let outcome: Result<CycleOutput, CycleError> = match &call.kind {
        CycleKind::MeasurePlane(p) => p.run(head, machine, ctx),
        CycleKind::Probing3d(p) => p.run(head, machine, ctx),
        CycleKind::SaveKinematics(p) => p.run(head, machine, ctx),
        CycleKind::MeasureKinematics(p) => p.run(head, machine, ctx),
    };
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
                kinematics: out.kinematics,
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
    (ctx.progress)(ProgressEvent::CycleFinished {
        block: head.block,
        cycle: head.cycle,
        status: result.status,
    });
    result
}
