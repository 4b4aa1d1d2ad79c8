//! The receive times the estimator records for `probebridge bench trigger`.

use std::io::Write;

/// Receive times recorded by the estimator: per sample, taken on CLOCK_MONOTONIC right
/// after the sample was taken from the subscriber (after the wake-up). The file has
/// one line per sample: `run_id sequence trigger_ns receive_ns publish_ns t1_ns`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ReceiveTime {
    pub run_id: u64,
    pub sequence: u64,
    /// The sample's `trigger_ns`, `receive_ns` and `publish_ns` as published.
    pub trigger_ns: u64,
    pub receive_ns: u64,
    pub publish_ns: u64,
    /// When the estimator had it.
    pub t1_ns: u64,
}

/// Reading and writing the receive-time file of [`EstimatorOptions::record_times`](super::EstimatorOptions::record_times).
pub struct ReceiveTimes;

impl ReceiveTimes {
    /// Written whole through [`hal::atomic_write`], or not at all.
    pub fn write(path: &std::path::Path, times: &[ReceiveTime]) -> std::io::Result<()> {
        let mut out = Vec::with_capacity(times.len() * 64);
        for t in times {
            writeln!(
                out,
                "{} {} {} {} {} {}",
                t.run_id, t.sequence, t.trigger_ns, t.receive_ns, t.publish_ns, t.t1_ns
            )?;
        }
        hal::atomic_write::write_atomic(path, &out).map_err(|e| e.to_io())
    }

    pub fn read(path: &std::path::Path) -> Result<Vec<ReceiveTime>, String> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
        text.lines()
            .enumerate()
            .map(|(i, line)| {
                let v: Vec<u64> = line
                    .split_whitespace()
                    .map(str::parse)
                    .collect::<Result<_, _>>()
                    .map_err(|e| format!("{} line {}: {e}", path.display(), i + 1))?;
                match v[..] {
                    [run_id, sequence, trigger_ns, receive_ns, publish_ns, t1_ns] => {
                        Ok(ReceiveTime {
                            run_id,
                            sequence,
                            trigger_ns,
                            receive_ns,
                            publish_ns,
                            t1_ns,
                        })
                    }
                    _ => Err(format!(
                        "{} line {}: expected 6 numbers",
                        path.display(),
                        i + 1
                    )),
                }
            })
            .collect()
    }
}
