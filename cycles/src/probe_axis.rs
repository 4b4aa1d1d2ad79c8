//! The probe (tool) axis of a `TOOL CALL` and the cycle coordinates it fixes.

use serde::Deserialize;
use std::fmt;

/// The probe (tool) axis chosen by `TOOL CALL ... Z|X|Y`; it fixes which machine axes
/// are the main, minor and tool axis of the cycle coordinates. In the machine TOML
/// (`[cycles] tool_axes`) it is written "X", "Y" or "Z".
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
pub enum ProbeAxis {
    X,
    Y,
    Z,
}

impl ProbeAxis {
    /// Machine XYZ indices of (main, minor, tool) axis: Z -> X Y Z, X -> Y Z X,
    /// Y -> Z X Y (the TNC's working planes for each tool axis, right-handed).
    pub fn indices(self) -> [usize; 3] {
        match self {
            ProbeAxis::Z => [0, 1, 2],
            ProbeAxis::X => [1, 2, 0],
            ProbeAxis::Y => [2, 0, 1],
        }
    }

    /// (main, minor, tool) coordinates to machine X, Y, Z.
    pub fn to_machine(self, v: [f64; 3]) -> [f64; 3] {
        let mut m = [0.0; 3];
        for (k, i) in self.indices().into_iter().enumerate() {
            m[i] = v[k];
        }
        m
    }

    /// Machine X, Y, Z to (main, minor, tool).
    pub fn to_cycle(self, m: [f64; 3]) -> [f64; 3] {
        self.indices().map(|i| m[i])
    }

    pub fn tool_index(self) -> usize {
        self.indices()[2]
    }

    pub fn axis(self) -> hal::Axis {
        match self {
            ProbeAxis::X => hal::Axis::X,
            ProbeAxis::Y => hal::Axis::Y,
            ProbeAxis::Z => hal::Axis::Z,
        }
    }

    pub fn from_name(s: &str) -> Option<Self> {
        match s {
            "X" | "x" => Some(ProbeAxis::X),
            "Y" | "y" => Some(ProbeAxis::Y),
            "Z" | "z" => Some(ProbeAxis::Z),
            _ => None,
        }
    }
}

impl fmt::Display for ProbeAxis {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.axis().name())
    }
}
