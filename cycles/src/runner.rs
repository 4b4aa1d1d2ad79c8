//! Runs the measuring cycles of a validated program in order over a [`Machine`]. A cycle
//! error, a Q309 stop or a refused confirmation ends the program; later cycles do not
//! run.

use crate::cycle431::PlaneRecord;
use crate::cycle444::Probing3dRecord;
use crate::cycle451::KinematicsReport;
use crate::error::CycleError;
use crate::kinematics::{Estimator, LocalEstimator};
use crate::linear::{parse_linear, MoveFeed};
use crate::program::{CycleCall, CycleKind, Program, Statement};
use crate::protocol;
use crate::results::{CycleResult, ProgramReport, Status};
use crate::{cycle431, cycle444};
use hal::config::MachineConfig;
use hal::{Axis, AxisPositions, Machine};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// What the runner reports while it works (for a console or a UI).
#[derive(Clone, Debug, PartialEq)]
pub enum ProgressEvent {
    CycleStarted {
        block: u32,
        cycle: u16,
        line: usize,
    },
    Move {
        block: u32,
        target: AxisPositions,
        feed: f64,
    },
    Probe {
        block: u32,
        direction: [f64; 3],
        max_distance: f64,
    },
    /// Latched stylus ball centre, machine XYZ.
    Contact {
        block: u32,
        centre: [f64; 3],
    },
    Note {
        block: u32,
        text: String,
    },
    Protocol {
        block: u32,
        path: PathBuf,
    },
    CycleFinished {
        block: u32,
        cycle: u16,
        status: Status,
    },
}

pub struct RunOptions<'a> {
    /// Where protocols are written (the TNC writes them next to the program).
    pub out_dir: PathBuf,
    /// Shows a text (the 431 protocol with Q281=2) and returns whether to go on.
    pub confirm: &'a mut dyn FnMut(&str) -> bool,
    pub progress: &'a mut dyn FnMut(ProgressEvent),
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
            .unwrap_or_else(|| crate::kinematics_file::ActiveKinematics::default_path(cfg))
    }
}

/// Checks, before anything moves, what only the machine and its configuration can
/// tell: the probe of each cycle is still in the probe table, the machine has X, Y, Z,
/// and this build can run the cycle.
fn preflight(
    call: &CycleCall,
    machine_axes: u8,
    cfg: &MachineConfig,
    kinematics: &std::path::Path,
) -> Result<(), String> {
    match call.kind {
        CycleKind::MeasurePlane(_) | CycleKind::Probing3d(_) => {}
        // Works on files only: no probe, no motion.
        CycleKind::SaveKinematics => return Ok(()),
        CycleKind::MeasureKinematics => {
            crate::cycle451::plan(call, cfg).map_err(|e| format!("{e}; nothing moved"))?;
            crate::kinematics_file::ActiveKinematics::load(kinematics, cfg)
                .map_err(|e| format!("active kinematics: {e}; nothing moved"))?;
        }
    }
    if cfg.probe(&call.tool.probe.name).is_none() {
        return Err(format!(
            "probe \"{}\" (TOOL CALL line {}) is not in the probe table of machine {}",
            call.tool.probe.name, call.tool.line, cfg.name
        ));
    }
    for a in Axis::LINEAR {
        if machine_axes & (1 << a.index()) == 0 {
            return Err(format!("the machine has no {a} axis"));
        }
    }
    Ok(())
}

/// Why a program cannot start on this machine.
#[derive(Clone, Debug, PartialEq)]
pub enum Preflight {
    /// A cycle's demands the machine, its configuration or its kinematics file cannot
    /// meet.
    Cycle {
        block: u32,
        cycle: u16,
        message: String,
    },
    /// A positioning block (L) that cannot be carried out.
    Positioning { line: usize, message: String },
}

impl std::fmt::Display for Preflight {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Preflight::Cycle {
                block,
                cycle,
                message,
            } => write!(f, "block {block} (cycle {cycle}): {message}"),
            Preflight::Positioning { line, message } => write!(f, "line {line}: {message}"),
        }
    }
}

/// Everything `run_program` checks before the first move, without a machine: `check`
/// runs it on the configuration's axes, `run` on the connected machine's.
pub fn preflight_program(
    program: &Program,
    machine_axes: u8,
    cfg: &MachineConfig,
    kinematics: &std::path::Path,
) -> Result<(), Preflight> {
    for call in program.cycles() {
        preflight(call, machine_axes, cfg, kinematics).map_err(|message| Preflight::Cycle {
            block: call.block,
            cycle: call.cycle,
            message,
        })?;
    }
    for block in &program.blocks {
        if let Statement::Other(code) = &block.statement {
            if let Some(Err(message)) = parse_linear(code, program.unit) {
                return Err(Preflight::Positioning {
                    line: block.line,
                    message,
                });
            }
        }
    }
    Ok(())
}

pub fn run_program<M: Machine>(
    program: &Program,
    machine: &mut M,
    cfg: &MachineConfig,
    opts: &mut RunOptions,
) -> ProgramReport {
    let mut report = ProgramReport::default();
    let kinematics = opts.kinematics_path(cfg);
    match preflight_program(program, machine.axes(), cfg, &kinematics) {
        Ok(()) => {}
        Err(Preflight::Cycle {
            block,
            cycle,
            message,
        }) => {
            report.stopped = Some(format!("block {block}: {message}"));
            report
                .cycles
                .push(CycleResult::error(block, cycle, message));
            return report;
        }
        Err(e @ Preflight::Positioning { .. }) => {
            report.stopped = Some(format!("{e}; nothing moved"));
            return report;
        }
    }
    // Rapid positioning: as fast as the slowest axis on the path allows.
    let rapid = cfg.axes.iter().map(|a| a.max_feed).fold(0.0, f64::max);
    let program_path = program.path.as_deref();
    let mut points: Vec<Probing3dRecord> = Vec::new();
    for block in &program.blocks {
        let call = match &block.statement {
            Statement::Cycle(call) => &**call,
            Statement::Other(code) => {
                if let Some(Ok(mv)) = parse_linear(code, program.unit) {
                    let feed = match mv.feed {
                        MoveFeed::Rapid => rapid,
                        MoveFeed::Feed(f) => f,
                    };
                    let number = block.number.unwrap_or(block.line as u32);
                    (opts.progress)(ProgressEvent::Move {
                        block: number,
                        target: mv.target,
                        feed,
                    });
                    if let Err(e) = machine.move_to(&mv.target, feed) {
                        report.stopped = Some(format!("block {number} (line {}): {e}", block.line));
                        break;
                    }
                }
                continue;
            }
            _ => continue,
        };
        (opts.progress)(ProgressEvent::CycleStarted {
            block: call.block,
            cycle: call.cycle,
            line: call.line,
        });
        let outcome = run_cycle(
            call,
            machine,
            cfg,
            opts,
            program_path,
            &mut points,
            &mut report,
        );
        let result = match outcome {
            Ok(out) => {
                if let Some(m) = &out.stop {
                    report.stopped = Some(format!("block {}: {m}", call.block));
                }
                CycleResult {
                    block: call.block,
                    cycle: call.cycle,
                    q: out.q,
                    qs: out.qs,
                    status: Status::Ok,
                    message: out.stop,
                    kinematics: out.kinematics,
                }
            }
            Err(e) => {
                let message = e.to_string();
                report.stopped = Some(format!(
                    "block {}: cycle {} failed: {message}",
                    call.block, call.cycle
                ));
                CycleResult::error(call.block, call.cycle, message)
            }
        };
        (opts.progress)(ProgressEvent::CycleFinished {
            block: call.block,
            cycle: call.cycle,
            status: result.status,
        });
        report.cycles.push(result);
        if report.stopped.is_some() {
            break;
        }
    }
    report
}

/// What a cycle gives the report.
struct CycleOutput {
    q: BTreeMap<String, f64>,
    qs: BTreeMap<String, String>,
    /// The program stops after this cycle, with this message.
    stop: Option<String>,
    kinematics: Option<Box<KinematicsReport>>,
}

impl CycleOutput {
    fn new(q: BTreeMap<String, f64>, stop: Option<String>) -> Self {
        Self {
            q,
            qs: BTreeMap::new(),
            stop,
            kinematics: None,
        }
    }
}

type Outcome = Result<CycleOutput, CycleError>;

fn run_cycle<M: Machine>(
    call: &CycleCall,
    machine: &mut M,
    cfg: &MachineConfig,
    opts: &mut RunOptions,
    program_path: Option<&std::path::Path>,
    points: &mut Vec<Probing3dRecord>,
    report: &mut ProgramReport,
) -> Outcome {
    match &call.kind {
        CycleKind::MeasurePlane(p) => {
            let out = cycle431::run(call, p, machine, opts.progress)?;
            let stop = plane_protocol(call, p.protocol, &out.record, opts, program_path, report)?;
            Ok(CycleOutput::new(out.q, stop))
        }
        CycleKind::Probing3d(p) => {
            let out = cycle444::run(call, p, machine, opts.progress)?;
            points.push(out.record);
            // Rewritten after every point so it is complete even if a later cycle fails.
            let path = protocol::write_probing3d_protocol(&opts.out_dir, points, program_path)
                .map_err(|e| CycleError::Protocol {
                    path: opts
                        .out_dir
                        .join(protocol::PROBING_3D_PROTOCOL)
                        .display()
                        .to_string(),
                    message: e.to_string(),
                })?;
            note_protocol(call, path, opts, report);
            Ok(CycleOutput::new(out.q, out.stop))
        }
        CycleKind::SaveKinematics => {
            let message = save_kinematics_cycle(call, cfg, opts)?;
            (opts.progress)(ProgressEvent::Note {
                block: call.block,
                text: message.clone(),
            });
            Ok(CycleOutput::new(BTreeMap::new(), None))
        }
        CycleKind::MeasureKinematics => {
            let plan = crate::cycle451::plan(call, cfg).map_err(CycleError::Plan)?;
            let kinematics = opts.kinematics_path(cfg);
            let mut local = LocalEstimator;
            let estimator: &mut dyn Estimator = match opts.estimator.as_deref_mut() {
                Some(e) => e,
                None => &mut local,
            };
            let mut ctx = crate::cycle451::Context {
                cfg,
                kinematics,
                estimator,
                confirm: &mut *opts.confirm,
                progress: &mut *opts.progress,
                out_dir: &opts.out_dir,
                program: program_path,
            };
            let out = crate::cycle451::run(call, &plan, machine, &mut ctx)?;
            if let Some(path) = out.protocol {
                note_protocol(call, path, opts, report);
            }
            Ok(CycleOutput {
                q: out.q,
                qs: out.qs,
                stop: out.stop,
                kinematics: Some(Box::new(out.report)),
            })
        }
    }
}

/// Cycle 450 SAVE KINEMATICS (Q410 mode, Q409 designation) on the active kinematics
/// file.
fn save_kinematics_cycle(
    call: &CycleCall,
    cfg: &MachineConfig,
    opts: &RunOptions,
) -> Result<String, CycleError> {
    use crate::kinematics_file::{save_kinematics, SaveMode};
    // Both are required and range-checked by the parameter table.
    let mode = call
        .number("Q410")
        .and_then(SaveMode::from_q410)
        .ok_or_else(|| CycleError::Plan("Q410 must be 0..3".into()))?;
    let designation = call.number("Q409").unwrap_or(0.0) as u32;
    save_kinematics(mode, designation, &opts.kinematics_path(cfg), cfg)
        .map_err(|e| CycleError::Plan(e.to_string()))
}

fn note_protocol(
    call: &CycleCall,
    path: PathBuf,
    opts: &mut RunOptions,
    report: &mut ProgramReport,
) {
    (opts.progress)(ProgressEvent::Protocol {
        block: call.block,
        path: path.clone(),
    });
    if !report.protocols.contains(&path) {
        report.protocols.push(path);
    }
}

/// Q281: 1 writes TCHPR431.TXT; 2 shows it and goes on only when confirmed.
fn plane_protocol(
    call: &CycleCall,
    mode: u8,
    record: &PlaneRecord,
    opts: &mut RunOptions,
    program_path: Option<&std::path::Path>,
    report: &mut ProgramReport,
) -> Result<Option<String>, CycleError> {
    match mode {
        1 => {
            let path = protocol::write_plane_protocol(&opts.out_dir, record, program_path)
                .map_err(|e| CycleError::Protocol {
                    path: opts
                        .out_dir
                        .join(protocol::PLANE_PROTOCOL)
                        .display()
                        .to_string(),
                    message: e.to_string(),
                })?;
            note_protocol(call, path, opts, report);
            Ok(None)
        }
        2 => {
            let text =
                protocol::plane_protocol_text(record, program_path, &protocol::timestamp_utc());
            Ok((!(opts.confirm)(&text)).then(|| {
                "the cycle 431 protocol was not confirmed (Q281=2); program stopped".to_string()
            }))
        }
        _ => Ok(None),
    }
}
