//! What is wrong with a scenario, naming the file, the key and why; and the range
//! checks every part of it uses.

use hal::config::ConfigError;
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// The scenario file itself: unreadable, not TOML, or a key out of range; the
    /// same errors as a machine configuration's, naming the scenario file.
    #[error(transparent)]
    File(#[from] ConfigError),
    /// The machine configuration the scenario names.
    #[error("{path}: machine: {source}")]
    Machine { path: PathBuf, source: ConfigError },
}

impl ScenarioError {
    /// The kind of the scenario's or its machine's error.
    pub fn kind(&self) -> hal::config::ConfigErrorKind {
        match self {
            ScenarioError::File(e) | ScenarioError::Machine { source: e, .. } => e.kind(),
        }
    }
}

pub(super) fn invalid(path: &Path, key: &str, message: String) -> ScenarioError {
    ConfigError::Invalid {
        path: path.to_path_buf(),
        key: key.to_string(),
        message,
    }
    .into()
}

/// `lo < v <= hi` (or `lo <= v` when `lo_inclusive`), finite.
pub(super) fn check_range(
    path: &Path,
    key: &str,
    v: f64,
    lo: f64,
    hi: f64,
    lo_inclusive: bool,
) -> Result<(), ScenarioError> {
    let ok = v.is_finite() && (if lo_inclusive { v >= lo } else { v > lo }) && v <= hi;
    if ok {
        return Ok(());
    }
    let lo_txt = if lo_inclusive { ">=" } else { ">" };
    Err(invalid(
        path,
        key,
        format!("{v} is out of range (must be {lo_txt} {lo} and <= {hi})"),
    ))
}

pub(super) fn check_abs(
    path: &Path,
    key: &str,
    v: f64,
    max: f64,
    unit: &str,
) -> Result<(), ScenarioError> {
    if v.is_finite() && v.abs() <= max {
        return Ok(());
    }
    Err(invalid(
        path,
        key,
        format!("{v} is out of range (|value| <= {max} {unit})"),
    ))
}

pub(super) fn check_hirth(path: &Path, key: &str, v: f64) -> Result<(), ScenarioError> {
    check_range(path, key, v, 0.0, 90.0, true)?;
    if v > 0.0 {
        let teeth = 360.0 / v;
        if (teeth - teeth.round()).abs() > 1e-9 {
            return Err(invalid(
                path,
                key,
                format!("a Hirth grid of {v} deg does not divide 360 deg"),
            ));
        }
    }
    Ok(())
}

pub(super) fn check_finite3(path: &Path, key: &str, v: [f64; 3]) -> Result<(), ScenarioError> {
    if v.iter().all(|x| x.is_finite()) {
        return Ok(());
    }
    Err(invalid(path, key, format!("{v:?} is not finite")))
}
