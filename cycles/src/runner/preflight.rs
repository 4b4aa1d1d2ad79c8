//! What `check` and `run` check before the first move: the machine, its configuration
//! and kinematics file can run each cycle, and every move the program will make (its
//! `L` blocks and its cycles' moves, planned in the datum and from the axes where the
//! blocks before leave them) stays inside what the machine allows.

use crate::cycle451;
use crate::cycle451::PlanErrorKind;
use crate::cycles_config::CyclesConfig;
use crate::datum::Datum;
use crate::formula::EvalErrorKind;
use crate::kinematics_file::ActiveKinematics;
use crate::linear::{parse_linear, LinearBlockError, LinearBlockErrorKind, LinearMove, MoveFeed};
use crate::machine_time::{MotionModel, Prediction};
use crate::parser::resolve_deferred;
use crate::planned_move::{check_planned, PlannedMove};
use crate::program::{CycleCall, CycleKind, Program, Statement};
use crate::program_flow::{start_params, substitute_params, CheckWalk, FlowFaultKind};
use crate::q_params::{load_remanent, remanent_path};
use hal::config::MachineConfig;
use hal::motion_guard::MotionGuard;
use hal::{Axis, AxisPositions};

/// A refusal before the first move, saying "nothing moved" once: many machine and
/// cycle messages say it already, and a refusal that passes one on must not say it
/// again.
pub fn nothing_moved(message: impl std::fmt::Display) -> String {
    let message = message.to_string();
    if message.contains("nothing moved") {
        message
    } else {
        format!("{message}; nothing moved")
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
    /// A move of a probing cycle (431, 444, 460) the machine would refuse: a point outside
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
        CycleKind::MeasurePlane(_) | CycleKind::Probing3d(_) | CycleKind::CalibrateProbe(_) => {}
        // Works on files only: no probe, no motion.
        CycleKind::SaveKinematics(_) => return Ok(()),
        CycleKind::MeasureKinematics(p) => {
            cycle451::plan(p, &tool.probe, &cfg.machine)
                .map_err(|e| (PreflightKind::Plan(e.kind()), nothing_moved(e)))?;
            ActiveKinematics::load(kinematics, &cfg.machine).map_err(|e| {
                (
                    PreflightKind::ActiveKinematics,
                    nothing_moved(format!("active kinematics: {e}")),
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

/// The machine time `check` predicts for a program from its plan: each cycle's, in
/// the order the program runs them, and the whole program's (its `L` moves included).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlannedTime {
    pub cycles: Vec<CycleTime>,
    pub program: Prediction,
    /// Why the prediction is not the whole run, if it is not: a value only a cycle
    /// measures decides a move, a cycle's parameters or the way through the program.
    pub partial: Option<String>,
}

/// One cycle of [`PlannedTime`]; `time` is `None` when its parameters are measured.
#[derive(Clone, Debug, PartialEq)]
pub struct CycleTime {
    pub block: u32,
    pub cycle: u16,
    pub line: usize,
    pub time: Option<Prediction>,
}

/// Everything `run_program` checks before the first move, without a machine: `check`
/// runs it on the configuration's axes, `run` on the connected machine's. The axes
/// start where [`assumed_start`] puts them (`run` starts from where the machine stands,
/// [`preflight_program_from`]). What passes comes with the machine time the plan
/// predicts.
pub fn preflight_program(
    program: &Program,
    machine_axes: u8,
    cfg: &CyclesConfig,
    kinematics: &std::path::Path,
) -> Result<PlannedTime, Preflight> {
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
) -> Result<PlannedTime, Preflight> {
    for call in program.cycles() {
        preflight_cycle(call, machine_axes, cfg, kinematics)?;
    }
    // The moves themselves, in the order the program runs them (its jumps, calls and
    // repeats followed, the parameters it computes from constants known) with the
    // datum as the program changes it and every axis where the blocks before leave it:
    // `L` targets, the probing cycles' points, and every move of cycles 451 and 460 (planned
    // by running their sequences on the planner's machine), in machine coordinates.
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
        crate::cycle451::rotary_m_function::written_params(cfg),
    );
    let motion = MotionModel::new(&cfg.machine);
    let mut time = PlannedTime::default();
    while let Some(block) = walk.next_block().map_err(|f| Preflight::Program {
        line: f.line,
        kind: PreflightKind::Program(f.kind),
        message: f.message,
    })? {
        // The time is the first way's: each condition on a measured value not taken.
        let first_way = walk.path() == 0;
        let (datum, params, here) = walk.state();
        let mut path_ends = false;
        match &block.statement {
            // `run` stops at a preset row that does not exist, with the same message;
            // nothing after it moves.
            Statement::Datum(d) if datum.apply(d).is_err() => path_ends = true,
            Statement::Other(code) => match l_block(code, block.line, params, datum, program, cfg)?
            {
                LBlock::Move(mv) => {
                    if first_way {
                        let feed = match mv.feed {
                            MoveFeed::Rapid => rapid(&cfg.machine),
                            MoveFeed::Feed(f) => f,
                        };
                        time.program.add_move(&motion, here, &mv.target, feed);
                    }
                    *here = here.merged(&mv.target)
                }
                LBlock::Measured => {
                    time.partial.get_or_insert_with(|| {
                        format!(
                            "the L block at line {} moves to a measured value",
                            block.line
                        )
                    });
                }
                LBlock::NotL => {}
            },
            Statement::Cycle(call) => {
                let t = check_cycle_moves(call, cfg, kinematics, datum, here, &guard)?;
                if first_way {
                    time.add(call, Some(t));
                }
            }
            Statement::Deferred(d) => match resolve_deferred(d, params, cfg) {
                // A value measured by a cycle: `run` resolves and checks the block
                // then, before it moves.
                Err(e) if e.kind == EvalErrorKind::Measured => {
                    if first_way {
                        time.cycles.push(CycleTime {
                            block: d.block,
                            cycle: d.cycle,
                            line: d.line,
                            time: None,
                        });
                        time.partial.get_or_insert_with(|| {
                            format!(
                                "cycle {} at line {} has measured parameters",
                                d.cycle, d.line
                            )
                        });
                    }
                }
                Err(e) => {
                    return Err(Preflight::Program {
                        line: d.line,
                        kind: PreflightKind::Program(FlowFaultKind::Eval(e.kind)),
                        message: e.message,
                    })
                }
                Ok(call) => {
                    preflight_cycle(&call, machine_axes, cfg, kinematics)?;
                    let t = check_cycle_moves(&call, cfg, kinematics, datum, here, &guard)?;
                    if first_way {
                        time.add(&call, Some(t));
                    }
                }
            },
            _ => {}
        }
        if path_ends {
            walk.end_path();
        }
    }
    if walk.path() > 0 {
        time.partial.get_or_insert_with(|| {
            "the way through the program depends on measured values: predicted where each such condition does not jump".into()
        });
    }
    Ok(time)
}

/// What `check` makes of a block that is not a cycle: an `L` move in machine
/// coordinates, checked as `run` checks it.
enum LBlock {
    Move(LinearMove),
    /// It moves to a value a cycle measures: `run` checks that move then, before it
    /// moves.
    Measured,
    NotL,
}

fn l_block(
    code: &str,
    line: usize,
    params: &crate::q_params::QParams,
    datum: &Datum,
    program: &Program,
    cfg: &CyclesConfig,
) -> Result<LBlock, Preflight> {
    let code = match substitute_params(code, params) {
        Ok(c) => c,
        Err(e) if e.kind == EvalErrorKind::Measured => return Ok(LBlock::Measured),
        Err(e) => {
            return Err(Preflight::Program {
                line,
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
        Some(Err(error)) => Err(Preflight::Positioning { line, error }),
        Some(Ok(mv)) => Ok(LBlock::Move(mv)),
        None => Ok(LBlock::NotL),
    }
}

impl PlannedTime {
    fn add(&mut self, call: &CycleCall, time: Option<Prediction>) {
        if let Some(t) = &time {
            self.program = self.program.plus(t);
        }
        self.cycles.push(CycleTime {
            block: call.head.block,
            cycle: call.head.cycle,
            line: call.head.line,
            time,
        });
    }
}

/// Rapid positioning (`FMAX`): as fast as the fastest axis's `max_feed` (the path's
/// own axes then limit it), as `run` commands it.
pub fn rapid(machine: &MachineConfig) -> f64 {
    machine.axes.iter().map(|a| a.max_feed).fold(0.0, f64::max)
}

/// What `check` and `run` say about a program that does not stop it: block numbers out
/// of order or repeated, and, in an INCH program, a length a cycle measured (in mm)
/// used as a length in an `L` block or a cycle parameter, followed as the program
/// runs (its jumps both ways where they depend on a measured value, its calls and
/// repeats) through the assignments that compute from it. Each at its line, once,
/// sorted by line. What the program cannot do is [`preflight_program`]'s.
pub fn program_warnings(program: &Program, cfg: &CyclesConfig) -> Vec<crate::Diagnostic> {
    let mut out = crate::program_warnings::block_number_warnings(program);
    if program.unit == crate::length_unit::LengthUnit::Inch {
        // An unreadable QR file is preflight_program's error; the walk needs no values
        // of it to follow the measured results.
        let remanent = load_remanent(&remanent_path(&cfg.presets.path)).unwrap_or_default();
        let mut walk = CheckWalk::new(
            program,
            start_params(&remanent),
            Datum::new(cfg.presets.clone()),
            assumed_start(&cfg.machine),
            cfg.parameters.max_jumps,
            crate::cycle451::rotary_m_function::written_params(cfg),
        );
        // A block that cannot be carried out ends the walk: preflight_program says so.
        while let Ok(Some(block)) = walk.next_block() {
            let (_, params, _) = walk.state();
            out.extend(crate::program_warnings::mm_in_inch_warnings(
                program, block, params,
            ));
        }
    }
    out.sort_by(|a, b| (a.line, &a.message).cmp(&(b.line, &b.message)));
    out.dedup();
    out
}

/// [`preflight`] of one cycle, as a [`Preflight`] error.
pub(super) fn preflight_cycle(
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
/// leaves them, against the motion guard: the probing cycles' points (431, 444), and
/// every move of cycles 451 and 460 (their sequences run on the planner's machine,
/// [`crate::plan`], for every sphere the block allows). Leaves `here` where the cycle
/// leaves the axes, and, for 451 with Q431 = 1/3 in modes 1..3, the active preset at
/// the sphere centre it sets. Returns the machine time the cycle's moves will take.
pub(super) fn check_cycle_moves(
    call: &CycleCall,
    cfg: &CyclesConfig,
    kinematics: &std::path::Path,
    datum: &mut Datum,
    here: &mut AxisPositions,
    guard: &MotionGuard,
) -> Result<Prediction, Preflight> {
    let origin = datum.origin();
    let mut time = Prediction::default();
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
            .planned_moves(&call.head, origin, here)
            .map_err(|e| e.to_string()),
        CycleKind::MeasureKinematics(p) => {
            let planned =
                cycle451::dry_run::plan_moves(p, &call.head, cfg, kinematics, datum, here)
                    .map_err(|e| refused(PreflightKind::Plan(e.kind()), nothing_moved(e)))?;
            *here = planned.end;
            time = planned.time;
            // Q431 = 1/3 in modes 1..3: later blocks are relative to the preset the
            // cycle writes at the sphere centre.
            if (p.preset == 1 || p.preset == 3) && p.mode.writes() {
                let row = [0, 1, 2].map(|i| planned.preset[i] - datum.shift[i]);
                datum.presets.set_active_xyz(row);
            }
            Ok(Vec::new())
        }
        CycleKind::SaveKinematics(_) => Ok(Vec::new()),
        // Planned from where the axes stand: the probe over the sphere, as the
        // operator puts it before the block.
        CycleKind::CalibrateProbe(p) => {
            (*here, time) = crate::cycle460::plan::plan_moves(p, &call.head, cfg, datum, here)
                .map_err(|message| refused(PreflightKind::Moves, message))?;
            Ok(Vec::new())
        }
    };
    let moves = moves
        .and_then(|m| check_planned(&m, guard).map(|()| m))
        .map_err(|message| refused(PreflightKind::Moves, message))?;
    let motion = MotionModel::new(&cfg.machine);
    let mut probed_along = [0.0; 3];
    for m in &moves {
        match m {
            PlannedMove::Position { target, feed, .. } => {
                time.add_move(&motion, here, target, *feed);
                *here = here.merged(target);
            }
            PlannedMove::Probe {
                from, mv, nominal, ..
            } => {
                time.add_probe(&motion, mv.direction, mv.feed, *nominal, mv.max_distance);
                let d = mv.direction;
                let at = [0, 1, 2].map(|i| from[i] + d[i] * nominal);
                *here = here.merged(&AxisPositions::linear(at));
                probed_along = d;
            }
            // From the nominal contact, as the time is predicted for it.
            PlannedMove::Retract { distance, feed, .. } => {
                let p = here.xyz();
                let target =
                    AxisPositions::linear([0, 1, 2].map(|i| p[i] - probed_along[i] * distance));
                time.add_move(&motion, here, &target, *feed);
                *here = here.merged(&target);
            }
        }
    }
    Ok(time)
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
pub(super) fn check_linear_move(
    mv: &LinearMove,
    machine: &MachineConfig,
) -> Result<(), LinearBlockError> {
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
        if !(hal::config::bounds::MIN_FEED..=fastest).contains(&f) {
            return Err(LinearBlockError::new(
                LinearBlockErrorKind::Feed,
                format!(
                    "L block: F{f}: the feed must be between {} and the machine's fastest max_feed {fastest} mm/min",
                    hal::config::bounds::MIN_FEED
                ),
            ));
        }
    }
    Ok(())
}
