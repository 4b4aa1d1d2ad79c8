//! Machine time: how long a cycle kept the machine, split by what the axes did, as
//! measured on the machine's own clock ([`hal::Machine::clock_ns`]) by
//! [`TimedMachine`], and as predicted before anything moves from the same moves by
//! [`MotionModel`] (with the plan's lower bound beside it).

mod model;
mod timed;

pub use model::{MotionModel, Prediction};
pub use timed::{TimeLedger, TimedMachine};

use hal::AxisPositions;
use serde::{Deserialize, Serialize};

/// Linear travel below this is no positioning move (mm).
const MOVED: f64 = 1e-6;

/// Does a move from `from` to `to` move a linear axis (a positioning move), or only
/// rotary ones? A linear axis `from` does not know counts as moved: the measured and
/// the predicted time book a move alike.
fn moves_linear(from: Option<&AxisPositions>, to: &AxisPositions) -> bool {
    to.iter().any(|(a, v)| {
        a.index() < 3
            && from
                .and_then(|f| f.get(a))
                .is_none_or(|f| (v - f).abs() >= MOVED)
    })
}

/// Where a cycle's machine time went, s. `standing` is what no move accounts for:
/// settling, arming the probes, reading positions, waiting for the estimator.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TimeSplit {
    /// Moves of the linear axes (rotary axes turning with them included).
    pub positioning: f64,
    /// Moves of the rotary axes alone, and spindle orientation.
    pub rotary: f64,
    /// Probing moves, from their start to the axes standing after the contact.
    pub probing: f64,
    pub standing: f64,
}

impl TimeSplit {
    pub fn total(&self) -> f64 {
        self.positioning + self.rotary + self.probing + self.standing
    }

    /// `self + other`, part by part.
    pub fn plus(&self, other: &TimeSplit) -> TimeSplit {
        TimeSplit {
            positioning: self.positioning + other.positioning,
            rotary: self.rotary + other.rotary,
            probing: self.probing + other.probing,
            standing: self.standing + other.standing,
        }
    }
}

impl std::fmt::Display for TimeSplit {
    /// "84.2 s (positioning 30.1 s, rotary 12.0 s, probing 40.0 s, standing 2.1 s)".
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{:.1} s (positioning {:.1} s, rotary {:.1} s, probing {:.1} s, standing {:.1} s)",
            self.total(),
            self.positioning,
            self.rotary,
            self.probing,
            self.standing
        )
    }
}
