//! Step 6: the write-back. Modes 1..3 write the corrected errors to the active
//! kinematics file, only after everything else succeeded (the measuring log is written
//! after it and states its real outcome), and a correction beyond `maxModification` only when the operator confirms.

use super::measuring_log::{write_kinematics_log, KINEMATICS_LOG};
use super::report::KinematicsReport;
use crate::confirmation::{ConfirmKind, Confirmation};
use crate::cycle::CycleContext;
use crate::error::CycleError;
use crate::kinematics::identification::{IdentificationResult, Mode};
use crate::kinematics::model::ErrorSet;
use crate::kinematics_file::ActiveKinematics;
use crate::measuring_log::timestamp_utc;
use std::path::PathBuf;

/// What the cycle does with the identified errors.
pub(super) struct WriteBack {
    /// (slot, before, after) of every error that changed.
    pub changes: Vec<(usize, f64, f64)>,
    /// The changes are written.
    pub accept: bool,
    /// The program stops (a large correction was not confirmed).
    pub stop: Option<String>,
}

impl WriteBack {
    /// Decides: mode 0 writes nothing; beyond `max_modification` the operator decides.
    pub fn decide(
        block: u32,
        mode: Mode,
        result: &IdentificationResult,
        max_modification: f64,
        ctx: &mut CycleContext<'_>,
    ) -> Self {
        let changes: Vec<(usize, f64, f64)> = (0..result.before.0.len())
            .filter(|&i| result.after.0[i] != result.before.0[i])
            .map(|i| (i, result.before.0[i], result.after.0[i]))
            .collect();
        let mut stop = None;
        let mut accept = mode.writes() && !changes.is_empty();
        let largest = changes
            .iter()
            .map(|(_, b, a)| (a - b).abs())
            .fold(0.0, f64::max);
        let limit = max_modification;
        if accept && largest > limit {
            let mut text = format!(
                "Cycle 451 (block {block}): the correction exceeds maxModification = {limit} (mm / deg):\n"
            );
            for (i, b, a) in &changes {
                let (_, part) = ErrorSet::describe(*i);
                text.push_str(&format!(
                    "  {:<5} {b:+.6} -> {a:+.6} {} ({:+.6})\n",
                    ErrorSet::name(*i),
                    part.unit(),
                    a - b
                ));
            }
            let file = ctx.kinematics.display().to_string();
            text.push_str(&format!("Accept and write it to {file}?"));
            if !(ctx.confirm)(&Confirmation::new(ConfirmKind::KinematicsCorrection, text)) {
                accept = false;
                stop = Some(format!(
                    "the kinematics correction (largest change {largest:.6} > maxModification {limit}) was not confirmed; {file} was not changed"
                ));
            }
        }
        WriteBack {
            changes,
            accept,
            stop,
        }
    }

    /// Writes (when accepted) the corrected kinematics over `active`, then the
    /// measuring log stating what really happened to the file; marks the report
    /// written. Returns the log's path; a failed write-back fails the cycle after the
    /// log has said so.
    pub fn write(
        &self,
        block: u32,
        report: &mut KinematicsReport,
        active: &ActiveKinematics,
        ctx: &mut CycleContext<'_>,
    ) -> Result<PathBuf, CycleError> {
        let file = ctx.kinematics.display().to_string();
        let mut failed = None;
        let mut outcome = None;
        if self.accept {
            let kept_previous = ctx.kinematics.is_file();
            let mut new = active.clone();
            for (i, _, a) in &self.changes {
                new.errors.insert(ErrorSet::name(*i).to_string(), *a);
            }
            match new.write() {
                Ok(()) => {
                    report.written = true;
                    let text = if kept_previous {
                        format!("written to {file} (previous version kept as .prev)")
                    } else {
                        format!("written to {file}")
                    };
                    ctx.note(block, format!("corrected kinematics {text}"));
                    outcome = Some(text);
                }
                Err(e) => {
                    outcome = Some(format!("NOT written: {e}; {file} is unchanged"));
                    failed = Some(CycleError::Plan(format!(
                        "writing the corrected kinematics: {e}"
                    )));
                }
            }
        }
        let log = write_kinematics_log(
            ctx.out_dir,
            report,
            ctx.program,
            &timestamp_utc(),
            outcome.as_deref(),
        )
        .map_err(|e| CycleError::MeasuringLog {
            path: ctx.out_dir.join(KINEMATICS_LOG).display().to_string(),
            message: e.source.to_string(),
        })?;
        match failed {
            Some(e) => Err(e),
            None => Ok(log),
        }
    }
}
