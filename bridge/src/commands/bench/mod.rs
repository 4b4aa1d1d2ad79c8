//! The benchmark commands: `bench trigger` over CANopen ([`trigger`]) and over
//! Modbus TCP ([`modbus`]), `bench cycles` (the examples' machine time, [`cycles`]), and what both runs share (their scratch folder, the
//! estimator's receive times). The measuring tools themselves (order statistics,
//! the host's wake-up floor, the benchmark machine) are in [`crate::bench`].

pub mod cycles;
pub mod modbus;
pub mod trigger;

use crate::estimator::{ReceiveTime, ReceiveTimes};
use crate::ipc::EstimatorChild;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Where the run keeps its files and names its services.
pub(crate) struct Workspace {
    pub(crate) prefix: String,
    pub(crate) dir: PathBuf,
    pub(crate) times_file: PathBuf,
    pub(crate) estimator_log: PathBuf,
}

impl Workspace {
    /// A scratch folder named `prefix` (also the iceoryx2 service prefix) for the
    /// estimator's receive times and its log.
    pub(crate) fn new(prefix: String) -> Result<Self, String> {
        let dir = std::env::temp_dir().join(&prefix);
        std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        Ok(Self {
            prefix,
            times_file: dir.join("receive-times.txt"),
            estimator_log: dir.join("estimator.log"),
            dir,
        })
    }
}

/// Stops the estimator and reads the receive times it recorded.
pub(crate) fn collect_records(
    mut estimator: EstimatorChild,
    ws: &Workspace,
) -> Result<Vec<ReceiveTime>, String> {
    let estimator_log = &ws.estimator_log;
    // Let the estimator write its records and exit.
    let _ = estimator.client().shutdown(Duration::from_secs(5));
    let deadline = Instant::now() + Duration::from_secs(30);
    while estimator.try_wait().map_err(|e| e.to_string())?.is_none() {
        if Instant::now() > deadline {
            return Err(format!(
                "the estimator did not exit; its log: {}",
                estimator_log.display()
            ));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    drop(estimator);
    let records = ReceiveTimes::read(&ws.times_file)
        .map_err(|e| format!("{e} (estimator log: {})", estimator_log.display()))?;
    Ok(records)
}
