//! The measuring logs the TNC writes next to the program (or in the run's output
//! folder): `TCHPR431.TXT` for cycle 431 ([`plane`]), `TCHPR444.html` for cycle 444
//! ([`probing3d`]); cycle 451's `TCHPRAUTO.html` is `crate::cycle451::measuring_log`,
//! cycle 460's `TCHPR460.TXT` `crate::cycle460::measuring_log`.
//! Here: what they share.

pub mod plane;
pub mod probing3d;

use crate::probe_axis::ProbeAxis;
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

/// `YYYY-MM-DD HH:MM:SS UTC` of now (no time-zone database on the gateway).
pub fn timestamp_utc() -> String {
    let secs = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let (days, rem) = ((secs / 86_400) as i64, secs % 86_400);
    // Civil date from days since 1970-01-01 (H. Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02} {:02}:{:02}:{:02} UTC",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

/// Machine axis names of (main, minor, tool) for a probe axis.
pub fn axis_names(axis: ProbeAxis) -> [&'static str; 3] {
    axis.indices().map(|i| hal::Axis::LINEAR[i].name())
}

/// Text for HTML.
pub fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The program as a log names it (`-` when unknown).
pub fn program_name(program: Option<&Path>) -> String {
    program.map_or_else(|| "-".to_string(), |p| p.display().to_string())
}

/// Writing a measuring log failed.
#[derive(Debug, thiserror::Error)]
#[error("measuring log {}: {source}", path.display())]
pub struct MeasuringLogError {
    pub path: PathBuf,
    pub source: std::io::Error,
}

impl MeasuringLogError {
    /// The operating system's reason (full disk, no permission, ...).
    pub fn kind(&self) -> std::io::ErrorKind {
        self.source.kind()
    }
}

/// Writes `text` to `dir/name` (creating `dir`) through [`hal::atomic_write`]: the
/// previous log stays whole until the new one is complete, and a symlink, device or
/// FIFO at the path is refused, not written through. The path written.
pub fn write(dir: &Path, name: &str, text: &str) -> Result<PathBuf, MeasuringLogError> {
    let path = dir.join(name);
    std::fs::create_dir_all(dir).map_err(|source| MeasuringLogError {
        path: path.clone(),
        source,
    })?;
    hal::atomic_write::write_atomic(&path, text.as_bytes()).map_err(|e| MeasuringLogError {
        path: path.clone(),
        source: e.to_io(),
    })?;
    Ok(path)
}
