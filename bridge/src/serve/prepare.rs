//! A start prepared on the machine thread, never under the gateway's lock: the machine's
//! state read again from its files, the program `NNN.h` resolved and checked, the run
//! written as `running` into the history. Each of these may take seconds (a slow
//! disk, a locked or distant history); meanwhile the faces go on answering, and the
//! start is "starting" (other starts are refused as busy).

use super::measurement::{Origin, Start};
use super::outcome::Refusal;
use crate::history::recorder::Recorder;
use crate::history::NewRun;
use cycles::program::{Program, ProgramError};
use cycles::CyclesConfig;
use std::path::Path;

/// A measurement for the machine thread: a start, prepared.
pub struct Job {
    pub start: Start,
    pub program: Program,
    /// The run's row in the history (written before the start was taken).
    pub record: Option<i64>,
    /// The cycles' configuration with the machine's state as its files held it when
    /// the start was taken (the last run's preset or calibration included).
    pub cycles: CyclesConfig,
}

/// What a start is prepared with: the program folder, the cycles' configuration the
/// service started with, the history (none: off).
pub struct Preparer<'a> {
    pub programs: &'a Path,
    pub cycles: &'a CyclesConfig,
    pub history: Option<&'a Recorder>,
}

impl Preparer<'_> {
    /// The machine's state read again, the program resolved, the `running` row
    /// written: the job, or why the start is refused (nothing moved).
    pub fn prepare(&self, start: &Start) -> Result<Job, Refusal> {
        let cycles = state_now(self.cycles)?;
        let program = resolve_program(self.programs, &cycles, start.program)?;
        // The run is in the history as `running` before the start is taken.
        let record = match self.history {
            Some(h) => Some(begin_run(h, &cycles, start, &program)?),
            None => None,
        };
        Ok(Job {
            start: *start,
            program,
            record,
            cycles,
        })
    }
}

/// Writes the `running` row of a start; a failure refuses it ("history unavailable").
/// The history's source is "serve" for the PLC's starts (with its request sequence),
/// "opcua" for OPC UA's.
fn begin_run(
    history: &Recorder,
    cfg: &CyclesConfig,
    start: &Start,
    program: &Program,
) -> Result<i64, Refusal> {
    let (source, request_seq) = match start.origin {
        Origin::Plc { seq } => ("serve", Some(seq)),
        Origin::OpcUa => ("opcua", None),
    };
    history
        .begin(NewRun {
            machine: cfg.machine.name.clone(),
            source: source.into(),
            request_seq,
            program_number: Some(start.program),
            program: program.path.clone().unwrap_or_default(),
            max_modification: Some(cfg.parameters.max_modification),
            parameters: start.params.iter().map(|&p| f64::from(p)).collect(),
        })
        .map_err(|e| {
            tracing::error!(origin = ?start.origin, "start refused: {e}");
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
pub fn resolve_program(folder: &Path, cfg: &CyclesConfig, number: u16) -> Result<Program, Refusal> {
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
