//! Cycle 450 SAVE KINEMATICS: saves, restores, shows or deletes the active kinematics
//! corrections under a designation (Q410 mode, Q409 designation). The saves are
//! `<file stem>.saved/<designation>.toml` beside the active kinematics file.

use crate::cycle::{CycleContext, MeasuringCycle};
use crate::cycle_block::{CycleBlock, Param, ParamReader};
use crate::diagnostic::Diagnostic;
use crate::error::CycleError;
use crate::kinematics_file::{
    write_atomic, write_error, ActiveKinematics, KinematicsFileError, KinematicsFileErrorKind,
};
use crate::length_unit::LengthUnit;
use crate::results::CycleOutput;
use hal::config::MachineConfig;
use hal::Machine;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The parameters of a 450 block.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SaveParams {
    /// Q410.
    pub mode: SaveMode,
    /// Q409.
    pub designation: u32,
}

impl SaveParams {
    /// Reads the validated table values (Q410 0..3, Q409 a whole number).
    pub fn from_params(
        params: &BTreeMap<String, Param>,
        _unit: LengthUnit,
    ) -> Result<Self, Vec<Diagnostic>> {
        let mut r = ParamReader::new(params);
        let q410 = r.number("Q410");
        let designation = r.number("Q409") as u32;
        let mode = SaveMode::from_q410(q410).unwrap_or_else(|| {
            r.problem(
                r.line("Q410"),
                format!("Q410={q410}: the mode must be 0..3"),
            );
            SaveMode::Show
        });
        r.finish(SaveParams { mode, designation })
    }
}

impl MeasuringCycle for SaveParams {
    /// Works on files only: nothing moves.
    fn run<M: Machine>(
        &self,
        call: &CycleBlock,
        _machine: &mut M,
        ctx: &mut CycleContext<'_>,
    ) -> Result<CycleOutput, CycleError> {
        let message = save_kinematics(
            self.mode,
            self.designation,
            &ctx.kinematics,
            &ctx.cfg.machine,
        )
        .map_err(|e| CycleError::Plan(e.to_string()))?;
        ctx.note(call.block, message);
        Ok(CycleOutput::default())
    }
}

/// Where cycle 450 keeps its saves for the kinematics file `active`.
pub fn saves_dir(active: &Path) -> PathBuf {
    let stem = active
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "kinematics".into());
    active.with_file_name(format!("{stem}.saved"))
}

fn save_path(active: &Path, designation: u32) -> PathBuf {
    saves_dir(active).join(format!("{designation}.toml"))
}

/// Cycle 450's Q410.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SaveMode {
    Save,
    Restore,
    Show,
    Delete,
}

impl SaveMode {
    pub fn from_q410(v: f64) -> Option<Self> {
        match v as i64 {
            0 => Some(Self::Save),
            1 => Some(Self::Restore),
            2 => Some(Self::Show),
            3 => Some(Self::Delete),
            _ => None,
        }
    }
}

/// Cycle 450 SAVE KINEMATICS on the kinematics file `active` of `cfg`. Returns what to
/// tell the operator. A restore validates the save against the machine before
/// replacing the active file atomically.
pub fn save_kinematics(
    mode: SaveMode,
    designation: u32,
    active: &Path,
    cfg: &MachineConfig,
) -> Result<String, KinematicsFileError> {
    let path = save_path(active, designation);
    let missing = |what: &str| KinematicsFileError::Invalid {
        path: path.clone(),
        kind: KinematicsFileErrorKind::NothingSaved,
        message: format!("nothing is saved under designation {designation}; nothing was {what}"),
    };
    match mode {
        SaveMode::Save => {
            let current = ActiveKinematics::load(active, cfg)?;
            let existed = path.exists();
            let mut saved = current.clone();
            saved.path = path.clone();
            write_atomic(&path, saved.render().as_bytes())?;
            Ok(format!(
                "active kinematics saved under {designation}{} ({})",
                if existed {
                    ", replacing the earlier save"
                } else {
                    ""
                },
                path.display()
            ))
        }
        SaveMode::Restore => {
            if !path.exists() {
                return Err(missing("restored"));
            }
            let mut saved = ActiveKinematics::load(&path, cfg)?;
            saved.path = active.to_path_buf();
            // Say what really happened: an identical file is not rewritten, and a
            // previous version is kept only when there was one.
            let current = ActiveKinematics::load(active, cfg).ok();
            if current.as_ref().is_some_and(|c| c.errors == saved.errors) && active.is_file() {
                return Ok(format!(
                    "kinematics {designation} is already active in {}; nothing written",
                    active.display()
                ));
            }
            let existed = active.is_file();
            saved.write()?;
            Ok(format!(
                "kinematics {designation} restored into {}{}",
                active.display(),
                if existed {
                    " (previous version kept as .prev)"
                } else {
                    ""
                }
            ))
        }
        SaveMode::Show => {
            let mut lines = Vec::new();
            let dir = saves_dir(active);
            let mut names: Vec<u32> = std::fs::read_dir(&dir)
                .map(|rd| {
                    rd.filter_map(|e| e.ok())
                        .filter_map(|e| e.path().file_stem()?.to_str()?.parse().ok())
                        .collect()
                })
                .unwrap_or_default();
            names.sort_unstable();
            if names.is_empty() {
                return Ok(format!("no kinematics saved in {}", dir.display()));
            }
            for n in names {
                let k = ActiveKinematics::load(&save_path(active, n), cfg)?;
                let errors: Vec<String> = k
                    .errors
                    .iter()
                    .map(|(k, v)| format!("{k}={v:+.6}"))
                    .collect();
                let mark = if n == designation { " <-" } else { "" };
                lines.push(format!(
                    "{n}: {}{mark}",
                    if errors.is_empty() {
                        "nominal".into()
                    } else {
                        errors.join(" ")
                    }
                ));
            }
            Ok(lines.join("\n"))
        }
        SaveMode::Delete => {
            if !path.exists() {
                return Err(missing("deleted"));
            }
            std::fs::remove_file(&path).map_err(write_error(&path))?;
            Ok(format!("saved kinematics {designation} deleted"))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics_file::prev_path;
    use crate::kinematics_file::tests::{cfg, tmp};

    #[test]
    fn cycle_450_save_show_restore_delete() {
        let d = tmp("450");
        let c = cfg(&d);
        let path = ActiveKinematics::default_path(&c);
        let mut k = ActiveKinematics::load(&path, &c).unwrap();
        k.errors.insert("EY0C".into(), 0.02);
        k.write().unwrap();
        save_kinematics(SaveMode::Save, 7, &path, &c).unwrap();
        k.errors.insert("EY0C".into(), 0.5);
        k.write().unwrap();
        let shown = save_kinematics(SaveMode::Show, 7, &path, &c).unwrap();
        assert!(shown.contains("7: EY0C=+0.020000 <-"), "{shown}");
        let said = save_kinematics(SaveMode::Restore, 7, &path, &c).unwrap();
        assert!(said.contains("kept as .prev"), "{said}");
        assert_eq!(
            ActiveKinematics::load(&path, &c).unwrap().error("EY0C"),
            0.02
        );
        // Restoring what is already active writes nothing and says so.
        let said = save_kinematics(SaveMode::Restore, 7, &path, &c).unwrap();
        assert!(
            said.contains("nothing written") && !said.contains(".prev"),
            "{said}"
        );
        // The version the restore replaced is kept.
        assert_eq!(
            ActiveKinematics::load(&prev_path(&path), &c)
                .unwrap()
                .error("EY0C"),
            0.5
        );
        save_kinematics(SaveMode::Delete, 7, &path, &c).unwrap();
        let e = save_kinematics(SaveMode::Restore, 7, &path, &c).unwrap_err();
        assert_eq!(e.kind(), KinematicsFileErrorKind::NothingSaved, "{e}");
        assert_eq!(
            ActiveKinematics::load(&path, &c).unwrap().error("EY0C"),
            0.02
        );
    }
}
