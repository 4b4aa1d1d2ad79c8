//! `probebridge estimator`: the estimator process.

use crate::estimator::{run_estimator_with, EstimatorOptions};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

/// Receive-time records kept without reallocating unless `--record-capacity` says.
pub const DEFAULT_RECORD_CAPACITY: usize = 1 << 16;

pub fn run(
    service: &str,
    verbose: bool,
    record_times: Option<PathBuf>,
    record_capacity: Option<usize>,
) -> Result<(), String> {
    let stop = AtomicBool::new(false);
    let options = EstimatorOptions {
        verbose,
        handle_signals: true,
        record_times,
        record_capacity: record_capacity.unwrap_or(DEFAULT_RECORD_CAPACITY),
    };
    run_estimator_with(service, &options, &stop, std::io::stderr()).map_err(|e| e.to_string())
}
