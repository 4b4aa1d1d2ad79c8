//! The machine's active kinematics corrections on disk.
//!
//! The nominal chain lives in the machine configuration; what cycle 451 measures and
//! corrects (ISO 230-7 location errors and zero errors of the rotary axes) lives in a
//! small TOML file beside it, `<machine>.kinematics.toml`:
//!
//! ```toml
//! machine = "table-ac"
//! [errors]
//! EX0C = 0.0123
//! EB0A = -0.0041
//! ```
//!
//! Every write is atomic (temporary file, fsync, rename, fsync of the folder) and keeps
//! the version it replaces as `<file>.prev`, so a power cut never leaves a half-written
//! model and the operator can always go back one step. Cycle 450 ([`crate::cycle450`])
//! keeps its saves beside it.

use crate::iso230_7::error_names;
use hal::config::MachineConfig;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The largest position error (EX0C, EY0A, ...) a kinematics file may hold, mm: a
/// location error is a deviation from the nominal chain, never a structure size.
pub const PLAUSIBLE_MM: f64 = 10.0;
/// The largest orientation error (EA0C, EB0A, ...) a kinematics file may hold, deg.
pub const PLAUSIBLE_DEG: f64 = 10.0;

/// What went wrong with a kinematics file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum KinematicsFileErrorKind {
    Read,
    /// Not TOML of the expected form.
    Syntax,
    /// Written for another machine.
    OtherMachine,
    /// An error name that is not one of the machine's rotary axes.
    UnknownError,
    /// A value that is not a finite number.
    NotANumber,
    /// A value beyond what a machine's location error can be
    /// ([`PLAUSIBLE_MM`], [`PLAUSIBLE_DEG`]): a typo or a unit mix-up.
    Implausible,
    /// Cycle 450: nothing saved under the designation.
    NothingSaved,
    Write,
}

#[derive(Debug, thiserror::Error)]
pub enum KinematicsFileError {
    #[error("cannot read {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Invalid {
        path: PathBuf,
        kind: KinematicsFileErrorKind,
        message: String,
    },
    #[error("cannot write {path}: {source}")]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
}

impl KinematicsFileError {
    pub fn kind(&self) -> KinematicsFileErrorKind {
        match self {
            KinematicsFileError::Read { .. } => KinematicsFileErrorKind::Read,
            KinematicsFileError::Invalid { kind, .. } => *kind,
            KinematicsFileError::Write { .. } => KinematicsFileErrorKind::Write,
        }
    }
}

#[derive(Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct FileFormat {
    machine: String,
    #[serde(default)]
    errors: BTreeMap<String, f64>,
}

/// The active kinematics corrections of a machine, by ISO name, mm / deg.
#[derive(Clone, Debug, PartialEq)]
pub struct ActiveKinematics {
    pub machine: String,
    pub errors: BTreeMap<String, f64>,
    pub path: PathBuf,
}

impl ActiveKinematics {
    /// `<dir of cfg.path>/<cfg.name>.kinematics.toml`.
    pub fn default_path(cfg: &MachineConfig) -> PathBuf {
        let dir = cfg.path.parent().unwrap_or(Path::new("."));
        dir.join(format!("{}.kinematics.toml", cfg.name))
    }

    /// Reads `path`; an absent file is the nominal chain (all errors 0). Names must be
    /// errors of rotary axes the machine has, values finite.
    pub fn load(path: &Path, cfg: &MachineConfig) -> Result<Self, KinematicsFileError> {
        let text = match std::fs::read_to_string(path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Ok(Self {
                    machine: cfg.name.clone(),
                    errors: BTreeMap::new(),
                    path: path.to_path_buf(),
                })
            }
            Err(source) => {
                return Err(KinematicsFileError::Read {
                    path: path.to_path_buf(),
                    source,
                })
            }
        };
        Self::parse(&text, path, cfg)
    }

    /// Parses and validates `text` as [`ActiveKinematics::load`] does; `path` names the
    /// source in errors.
    pub fn parse(
        text: &str,
        path: &Path,
        cfg: &MachineConfig,
    ) -> Result<Self, KinematicsFileError> {
        use KinematicsFileErrorKind as K;
        let invalid = |kind, message: String| KinematicsFileError::Invalid {
            path: path.to_path_buf(),
            kind,
            message,
        };
        let f: FileFormat = toml::from_str(text).map_err(|e| invalid(K::Syntax, e.to_string()))?;
        if f.machine != cfg.name {
            return Err(invalid(
                K::OtherMachine,
                format!(
                    "written for machine {:?}, but the machine is {:?}",
                    f.machine, cfg.name
                ),
            ));
        }
        for (name, v) in &f.errors {
            let known = cfg
                .axes
                .iter()
                .filter(|a| a.name.is_rotary())
                .any(|a| error_names(a.name).contains(&name.as_str()));
            if !known {
                return Err(invalid(
                    K::UnknownError,
                    format!(
                        "errors.{name}: not an error of a rotary axis of machine {}",
                        cfg.name
                    ),
                ));
            }
            if !v.is_finite() {
                return Err(invalid(
                    K::NotANumber,
                    format!("errors.{name}: {v} is not a number"),
                ));
            }
            // EX/EY/EZ are positions (mm), EA/EB/EC orientations (deg).
            let (bound, unit) = if matches!(name.get(..2), Some("EA" | "EB" | "EC")) {
                (PLAUSIBLE_DEG, "deg")
            } else {
                (PLAUSIBLE_MM, "mm")
            };
            if v.abs() > bound {
                return Err(invalid(
                    K::Implausible,
                    format!(
                        "errors.{name}: {v} is beyond the plausible range -{bound} .. +{bound} {unit} of a location error"
                    ),
                ));
            }
        }
        Ok(Self {
            machine: f.machine,
            errors: f.errors,
            path: path.to_path_buf(),
        })
    }

    /// The value of `name` (0 when absent).
    pub fn error(&self, name: &str) -> f64 {
        self.errors.get(name).copied().unwrap_or(0.0)
    }

    pub(crate) fn render(&self) -> String {
        let f = FileFormat {
            machine: self.machine.clone(),
            errors: self.errors.clone(),
        };
        format!(
            "# Active kinematics corrections of machine {}: ISO 230-7 location errors and\n\
             # zero errors of the rotary axes (mm, deg), written by probebridge.\n{}",
            self.machine,
            toml::to_string(&f).unwrap_or_default()
        )
    }

    /// Writes atomically, keeping the replaced version as `<path>.prev`. Writes nothing
    /// (and keeps the file byte for byte) when the errors equal what is on disk.
    pub fn write(&self) -> Result<(), KinematicsFileError> {
        if let Ok(text) = std::fs::read_to_string(&self.path) {
            if let Ok(FileFormat { errors, machine }) = toml::from_str::<FileFormat>(&text) {
                if errors == self.errors && machine == self.machine {
                    return Ok(());
                }
            }
        }
        // The target is checked before `.prev` is taken: a symlink or device at the
        // path is refused without reading through it.
        hal::atomic_write::write_atomic_keeping_previous(&self.path, self.render().as_bytes())
            .map_err(|e| KinematicsFileError::Write {
                path: e.path.clone(),
                source: e.to_io(),
            })
    }
}

#[cfg(test)]
pub(crate) fn prev_path(path: &Path) -> PathBuf {
    hal::atomic_write::previous_path(path)
}

pub(crate) fn write_error(path: &Path) -> impl Fn(std::io::Error) -> KinematicsFileError + '_ {
    move |source| KinematicsFileError::Write {
        path: path.to_path_buf(),
        source,
    }
}

/// Through [`hal::atomic_write`]: temporary file in the same folder, fsync, rename over
/// `path`, fsync the folder; a symlink, device or FIFO at `path` is refused, and
/// temporaries a killed write left are removed.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), KinematicsFileError> {
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).map_err(write_error(dir))?;
    hal::atomic_write::write_atomic(path, bytes).map_err(|e| KinematicsFileError::Write {
        path: path.to_path_buf(),
        source: e.to_io(),
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// The table-ac machine, as if its configuration were in `dir`.
    pub(crate) fn cfg(dir: &Path) -> MachineConfig {
        let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/machines/table-ac.toml");
        let text = std::fs::read_to_string(src).unwrap();
        MachineConfig::parse(&text, &dir.join("table-ac.toml")).unwrap()
    }

    /// An empty folder for one test.
    pub(crate) fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("pb-kin-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn absent_file_is_nominal_and_write_keeps_previous() {
        let d = tmp("write");
        let c = cfg(&d);
        let path = ActiveKinematics::default_path(&c);
        assert_eq!(path, d.join("table-ac.kinematics.toml"));
        let mut k = ActiveKinematics::load(&path, &c).unwrap();
        assert!(k.errors.is_empty());
        k.errors.insert("EX0C".into(), 0.012);
        k.write().unwrap();
        assert!(!prev_path(&path).exists(), "nothing to keep the first time");
        let first = std::fs::read(&path).unwrap();
        k.errors.insert("EB0A".into(), -0.003);
        k.write().unwrap();
        assert_eq!(std::fs::read(prev_path(&path)).unwrap(), first);
        let back = ActiveKinematics::load(&path, &c).unwrap();
        assert_eq!(back.error("EB0A"), -0.003);
        assert_eq!(back.error("EX0C"), 0.012);
        assert_eq!(back.error("EY0C"), 0.0);
        // Unchanged errors: the file stays byte for byte.
        let before = std::fs::read(&path).unwrap();
        let modified = std::fs::metadata(&path).unwrap().modified().unwrap();
        back.write().unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), before);
        assert_eq!(
            std::fs::metadata(&path).unwrap().modified().unwrap(),
            modified
        );
    }

    #[test]
    fn bad_files_are_refused_with_the_reason() {
        let d = tmp("bad");
        let c = cfg(&d);
        let path = d.join("k.toml");
        std::fs::write(&path, "machine = \"table-ac\"\n[errors]\nEX0B = 0.1\n").unwrap();
        let e = ActiveKinematics::load(&path, &c).unwrap_err();
        assert_eq!(e.kind(), KinematicsFileErrorKind::UnknownError, "{e}");
        assert!(e.to_string().contains("errors.EX0B"), "names the key: {e}");
        std::fs::write(&path, "machine = \"other\"\n").unwrap();
        let e = ActiveKinematics::load(&path, &c).unwrap_err();
        assert_eq!(e.kind(), KinematicsFileErrorKind::OtherMachine, "{e}");
        std::fs::write(&path, "machine = \"table-ac\"\nerror = 1\n").unwrap();
        let e = ActiveKinematics::load(&path, &c).unwrap_err();
        assert_eq!(e.kind(), KinematicsFileErrorKind::Syntax, "{e}");
        for (name, v) in [("EX0C", "1e300"), ("EA0C", "-45.0")] {
            std::fs::write(
                &path,
                format!("machine = \"table-ac\"\n[errors]\n{name} = {v}\n"),
            )
            .unwrap();
            let e = ActiveKinematics::load(&path, &c).unwrap_err();
            assert_eq!(e.kind(), KinematicsFileErrorKind::Implausible, "{e}");
            assert!(e.to_string().contains(&format!("errors.{name}")), "{e}");
        }
    }

    /// A process that ran and is gone: its pid names a stale temporary.
    fn dead_pid() -> u32 {
        let mut c = std::process::Command::new("true").spawn().unwrap();
        c.wait().unwrap();
        c.id()
    }

    #[test]
    fn a_write_removes_temporaries_of_killed_writes_and_refuses_a_symlink() {
        let d = tmp("safe");
        let c = cfg(&d);
        let path = ActiveKinematics::default_path(&c);
        let stale = d.join(format!(".table-ac.kinematics.toml.tmp{}", dead_pid()));
        std::fs::write(&stale, "half a file").unwrap();
        let mut k = ActiveKinematics::load(&path, &c).unwrap();
        k.errors.insert("EX0C".into(), 0.012);
        k.write().unwrap();
        assert!(!stale.exists(), "the killed write's temporary is cleaned");

        let target = d.join("elsewhere.toml");
        std::fs::write(&target, "keep").unwrap();
        let link = d.join("link.kinematics.toml");
        std::os::unix::fs::symlink(&target, &link).unwrap();
        k.path = link.clone();
        k.errors.insert("EB0A".into(), -0.003);
        let e = k.write().unwrap_err();
        assert_eq!(e.kind(), KinematicsFileErrorKind::Write, "{e}");
        assert!(e.to_string().contains("symbolic link"), "{e}");
        assert!(std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "keep");
        assert!(!prev_path(&link).exists(), "nothing read through the link");
    }
}
