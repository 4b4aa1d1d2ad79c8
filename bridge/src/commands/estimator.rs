//! `probebridge estimator`: the estimator process.

use crate::estimator::{run_estimator_with, EstimatorOptions};
use std::sync::atomic::AtomicBool;

pub fn run(service: &str, verbose: bool) -> Result<(), String> {
    let stop = AtomicBool::new(false);
    let options = EstimatorOptions {
        verbose,
        handle_signals: true,
    };
    run_estimator_with(service, &options, &stop, std::io::stderr()).map_err(|e| e.to_string())
}
