//! `[kinematics]`: the machine's nominal kinematic chain.

use crate::axis::Axis;
use serde::Deserialize;
use std::collections::BTreeMap;

/// The nominal kinematic chain.
///
/// Conventions (shared by the simulator and the cycles' model):
/// - With every rotary axis at 0, machine, table and program coordinates coincide.
/// - A rotary axis turns right-handed about its nominal direction (A: +X, B: +Y,
///   C: +Z) through its pivot point, by its angle.
/// - Table side: `table` lists the rotary axes from the machine bed outward (the last
///   one carries the workpiece). A point `p` fixed to the table is, in machine
///   coordinates, `T_first(a1) * ... * T_last(an) * p`.
/// - Head side: `head` lists rotary axes from the machine frame toward the tool. The
///   stylus ball centre is `XYZ + T_first(h1) * ... * T_last(hn) * 0`, each pivot given
///   relative to the ball centre with all axes at 0 (so at 0 the ball centre is XYZ).
#[derive(Clone, Debug, Deserialize, PartialEq, Default)]
#[serde(deny_unknown_fields)]
pub struct KinematicsConfig {
    #[serde(default)]
    pub table: Vec<Axis>,
    #[serde(default)]
    pub head: Vec<Axis>,
    /// A point on each rotary axis's line (see above), mm.
    #[serde(default)]
    pub pivot: BTreeMap<Axis, [f64; 3]>,
}
