//! Helpers of `probebridge bench`: latency statistics and the benchmark's machine.

pub mod timer_wakeup;
pub mod wakeup;

use serde_json::{json, Value};

/// Order statistics of a set of latencies (ns in, µs out).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Summary {
    pub count: usize,
    pub min_us: f64,
    pub p50_us: f64,
    pub p90_us: f64,
    pub p99_us: f64,
    pub p999_us: f64,
    pub max_us: f64,
    pub mean_us: f64,
}

/// Nearest-rank percentile of sorted values: the smallest value with at least `p` %
/// of the values at or below it.
pub fn percentile(sorted: &[u64], p: f64) -> u64 {
    if sorted.is_empty() {
        return 0;
    }
    // The tolerance keeps 99.9 % of 1000 at rank 999 despite binary floating point
    // (0.999 * 1000 = 999.0000000000001).
    let rank = ((p / 100.0) * sorted.len() as f64 - 1e-9).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}

impl Summary {
    /// `None` for an empty set.
    pub fn of(values_ns: &[u64]) -> Option<Self> {
        if values_ns.is_empty() {
            return None;
        }
        let mut v = values_ns.to_vec();
        v.sort_unstable();
        let us = |ns: u64| ns as f64 / 1000.0;
        Some(Self {
            count: v.len(),
            min_us: us(v[0]),
            p50_us: us(percentile(&v, 50.0)),
            p90_us: us(percentile(&v, 90.0)),
            p99_us: us(percentile(&v, 99.0)),
            p999_us: us(percentile(&v, 99.9)),
            max_us: us(v[v.len() - 1]),
            mean_us: us(v.iter().sum::<u64>() / v.len() as u64),
        })
    }

    pub fn to_json(self) -> Value {
        json!({
            "count": self.count,
            "min": self.min_us,
            "p50": self.p50_us,
            "p90": self.p90_us,
            "p99": self.p99_us,
            "p99_9": self.p999_us,
            "max": self.max_us,
            "mean": self.mean_us,
        })
    }

    /// One table row: `count min p50 p90 p99 p99.9 max`.
    pub fn row(&self) -> String {
        format!(
            "{:>8} {:>8.1} {:>8.1} {:>8.1} {:>8.1} {:>8.1} {:>9.1}",
            self.count,
            self.min_us,
            self.p50_us,
            self.p90_us,
            self.p99_us,
            self.p999_us,
            self.max_us
        )
    }

    pub const HEADER: &'static str =
        "   count   min us   p50 us   p90 us   p99 us p99.9 us    max us";
}

/// The benchmark's scenario: the table-ac machine (five drives latching together) with
/// a flat face z = 0 and an ideal probe of R 3 mm.
pub const SCENARIO: &str = r#"
machine = "table-ac"
seed = 1
[probe]
ball_radius = 3.0
noise = 0.0
pretravel = 0.0
[[plane]]
point = [0.0, 0.0, 0.0]
normal = [0.0, 0.0, 1.0]
"#;

/// Ball centre height where the ball touches the face.
pub const TOUCH_Z: f64 = 3.0;
/// The probing move starts this far above the touch: the contact comes within the
/// first few cycles of the move, and the retract is as short.
pub const GAP: f64 = 0.001;
/// Probing feed, mm/min, and the longest probing path, mm.
pub const FEED: f64 = 600.0;
pub const DISTANCE: f64 = 0.05;
/// Acceleration of the benchmark's axes, mm/s² (deg/s²).
pub const ACCELERATION: f64 = 50_000.0;
/// Where the probing moves start (X, Y).
pub const START_XY: [f64; 2] = [10.0, 10.0];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_are_nearest_rank() {
        let v: Vec<u64> = (1..=1000).collect();
        assert_eq!(percentile(&v, 50.0), 500);
        assert_eq!(percentile(&v, 99.0), 990);
        assert_eq!(percentile(&v, 99.9), 999);
        assert_eq!(percentile(&v, 100.0), 1000);
        assert_eq!(percentile(&v, 0.0), 1);
        assert_eq!(percentile(&[7], 99.9), 7);
        let s = Summary::of(&[3000, 1000, 2000]).unwrap();
        assert_eq!(
            (s.min_us, s.p50_us, s.max_us, s.mean_us),
            (1.0, 2.0, 3.0, 2.0)
        );
        assert!(Summary::of(&[]).is_none());
    }
}
