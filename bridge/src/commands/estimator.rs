//! `probebridge estimator`: the estimator process.

use crate::estimator::{run_estimator_with, ArmedReceive, EstimatorOptions};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

/// Receive-time records kept without reallocating unless `--record-capacity` says.
pub const DEFAULT_RECORD_CAPACITY: usize = 1 << 16;

/// The options of `probebridge estimator`, parsed by clap straight into this.
#[derive(clap::Args, Clone, Debug)]
pub struct EstimatorArgs {
    #[arg(long, default_value = "probebridge")]
    pub service: String,
    /// One line per received contact.
    #[arg(long)]
    pub verbose: bool,
    /// Record when each contact arrived (CLOCK_MONOTONIC) and write the records to
    /// FILE at exit: `run_id sequence trigger_ns receive_ns publish_ns t1_ns` per line.
    #[arg(long, value_name = "FILE")]
    pub record_times: Option<PathBuf>,
    /// Records kept without reallocating.
    #[arg(long, value_name = "N")]
    pub record_capacity: Option<usize>,
    /// Poll for the contact during probing moves ("auto": where the machine has a
    /// CPU to spare) or always sleep until woken ("off").
    #[arg(long, value_enum, default_value_t = ArmedReceive::Auto)]
    pub armed_receive: ArmedReceive,
    /// Keep off this CPU (the one the real-time loop is pinned to, as `bench trigger`
    /// pins it). Default: the scheduler places the estimator.
    #[arg(long, value_name = "CPU")]
    pub avoid_cpu: Option<usize>,
}

pub fn run(args: EstimatorArgs) -> Result<(), String> {
    let stop = AtomicBool::new(false);
    let options = EstimatorOptions {
        verbose: args.verbose,
        handle_signals: true,
        record_times: args.record_times,
        record_capacity: args.record_capacity.unwrap_or(DEFAULT_RECORD_CAPACITY),
        armed_receive: args.armed_receive,
        avoid_cpu: args.avoid_cpu,
    };
    // One write per line: the bridge writes to the same stderr, and an unbuffered
    // writeln! is several writes that its lines could land between.
    let log = std::io::LineWriter::new(std::io::stderr());
    run_estimator_with(&args.service, &options, &stop, log).map_err(|e| e.to_string())
}
