//! Writing result files through `hal::atomic_write`: complete or not at all, never
//! through a symlink, device or FIFO, and the path checked before anything moves.

use hal::atomic_write;
use std::path::Path;

pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), String> {
    atomic_write::write_atomic(path, bytes).map_err(|e| e.to_string())
}

pub fn write_json(path: &Path, value: &serde_json::Value) -> Result<(), String> {
    let mut text = serde_json::to_string_pretty(value).map_err(|e| e.to_string())?;
    text.push('\n');
    write_atomic(path, text.as_bytes())
}

/// Refuses, before the machine is opened, an output path that could not be written
/// at the end (missing folder, a device or symlink at the path, read-only folder), so
/// a measurement is never made only to lose its results.
pub fn check_output(path: Option<&Path>) -> Result<(), String> {
    match path {
        Some(p) => atomic_write::check_writable(p).map_err(|e| e.to_string()),
        None => Ok(()),
    }
}
