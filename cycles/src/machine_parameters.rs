//! The measuring cycles' machine parameters: `[cycles]` of the machine TOML
//! (`maxDevCalBall`, `maxModification`, and `[cycles.predef]` for PREDEF). Read and
//! validated here, not by hal, which accepts the section unread.

use crate::probe_axis::ProbeAxis;
use serde::Deserialize;
use std::collections::BTreeMap;

#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MachineParameters {
    /// Largest allowed difference between fitted and nominal calibration sphere
    /// radius (cycle 451), mm.
    #[serde(default = "default_max_dev_cal_ball", rename = "maxDevCalBall")]
    pub max_dev_cal_ball: f64,
    /// Largest kinematics correction written without confirmation, mm / deg.
    #[serde(default = "default_max_modification", rename = "maxModification")]
    pub max_modification: f64,
    /// Values of parameters given as `PREDEF` in a program, by Q number ("Q320").
    #[serde(default)]
    pub predef: BTreeMap<String, f64>,
    /// The directions the spindle can take on this machine: the tool axes a `TOOL
    /// CALL` may name (a vertical spindle: `["Z"]`, the default; a horizontal one along
    /// Y: `["Y"]`; a universal head: both). A probe called along any other axis would
    /// come at the workpiece from a side the stylus does not point to.
    #[serde(default = "default_tool_axes")]
    pub tool_axes: Vec<ProbeAxis>,
    /// The machine's reference point M92 refers to, machine X/Y/Z in mm (a tool change
    /// position set by the machine builder); none: M92 is refused.
    #[serde(default)]
    pub m92_reference: Option<[f64; 3]>,
    /// The most jumps (FN 9..12, CALL LBL, repeats) a program may make in one run: a
    /// program that loops forever is stopped with an error after them.
    #[serde(default = "default_max_jumps")]
    pub max_jumps: u64,
    /// The texts of `FN 14: ERROR = n`, by number (`[cycles.errors]`, `1001 = "..."`).
    #[serde(default)]
    pub errors: BTreeMap<String, String>,
    /// `mStrobeRotAxPos` (204803): the M function with which the PLC positions the
    /// rotary axes (an indexing table), -1 (the default) when the NC positions them.
    /// Set, cycle 451 starts only with every rotary axis at 0 deg and confirmed so,
    /// measures no backlash (Q432), and turns the rotary axes alone, each target angle
    /// in Q120 (A), Q121 (B), Q122 (C) as the TNC hands it to the PLC.
    #[serde(default = "default_strobe_rot_ax_pos", rename = "mStrobeRotAxPos")]
    pub strobe_rot_ax_pos: i64,
}

fn default_max_dev_cal_ball() -> f64 {
    0.1
}
fn default_max_modification() -> f64 {
    0.5
}
fn default_tool_axes() -> Vec<ProbeAxis> {
    vec![ProbeAxis::Z]
}
fn default_max_jumps() -> u64 {
    100_000
}
fn default_strobe_rot_ax_pos() -> i64 {
    -1
}

impl Default for MachineParameters {
    fn default() -> Self {
        Self {
            max_dev_cal_ball: default_max_dev_cal_ball(),
            max_modification: default_max_modification(),
            predef: BTreeMap::new(),
            tool_axes: default_tool_axes(),
            m92_reference: None,
            max_jumps: default_max_jumps(),
            errors: BTreeMap::new(),
            strobe_rot_ax_pos: default_strobe_rot_ax_pos(),
        }
    }
}

/// The plausible range of `maxDevCalBall` (mm) and `maxModification` (mm, deg): a
/// sphere or a correction off by more than 10 is a broken set-up, not a tolerance.
pub const TOLERANCE_RANGE: (f64, f64) = (1e-6, 10.0);

impl MachineParameters {
    /// The M function that positions the rotary axes (`mStrobeRotAxPos`), if one does.
    pub fn rotary_m_function(&self) -> Option<u32> {
        u32::try_from(self.strobe_rot_ax_pos).ok()
    }

    /// The first value out of range, as (key, reason). PREDEF values are checked
    /// against the parameter tables ([`crate::params`]).
    pub fn invalid_field(&self) -> Option<(String, String)> {
        let (lo, hi) = TOLERANCE_RANGE;
        for (key, v) in [
            ("cycles.maxDevCalBall", self.max_dev_cal_ball),
            ("cycles.maxModification", self.max_modification),
        ] {
            if !(lo..=hi).contains(&v) {
                return Some((key.to_string(), format!("{v} is outside {lo} .. {hi}")));
            }
        }
        for (name, &v) in &self.predef {
            let key = format!("cycles.predef.{name}");
            let Some(spec) = crate::params::predef_spec(name) else {
                return Some((
                    key,
                    format!(
                        "{name} is not a parameter any cycle takes as PREDEF (known: {})",
                        crate::params::predef_names().join(", ")
                    ),
                ));
            };
            if let crate::params::Kind::Number { min, max, .. } = spec.kind {
                if !(min..=max).contains(&v) {
                    return Some((key, format!("{v} is outside {min} .. {max}")));
                }
            }
        }
        if !(1..=100_000_000).contains(&self.max_jumps) {
            return Some((
                "cycles.max_jumps".to_string(),
                format!("{} is outside 1 .. 100000000", self.max_jumps),
            ));
        }
        for key in self.errors.keys() {
            if !key.parse::<u32>().is_ok_and(|n| n <= 65535) {
                return Some((
                    format!("cycles.errors.{key}"),
                    "not an FN 14 error number 0..65535".to_string(),
                ));
            }
        }
        if !(-1..=9999).contains(&self.strobe_rot_ax_pos) {
            return Some((
                "cycles.mStrobeRotAxPos".to_string(),
                format!(
                    "{} is not an M function number 0..9999 (or -1: the NC positions the rotary axes)",
                    self.strobe_rot_ax_pos
                ),
            ));
        }
        if self.tool_axes.is_empty() {
            return Some((
                "cycles.tool_axes".to_string(),
                "must name at least one tool axis (\"X\", \"Y\" or \"Z\")".to_string(),
            ));
        }
        if let Some(p) = self
            .m92_reference
            .filter(|p| p.iter().any(|v| !v.is_finite()))
        {
            return Some((
                "cycles.m92_reference".to_string(),
                format!("{p:?}: must be three finite numbers X, Y, Z (mm)"),
            ));
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> MachineParameters {
        toml::from_str(text).unwrap()
    }

    /// Found by the fuzz target machine-toml: `maxDevCalBall = inf` and PREDEF values
    /// of `inf` or `nan` were accepted.
    #[test]
    fn non_finite_values_are_refused_with_their_key() {
        for (text, key) in [
            ("maxDevCalBall = inf", "cycles.maxDevCalBall"),
            ("maxModification = nan", "cycles.maxModification"),
            ("maxModification = -inf", "cycles.maxModification"),
            ("[predef]\nQ320 = inf", "cycles.predef.Q320"),
            ("[predef]\nQ260 = 10.0\nQ320 = nan", "cycles.predef.Q320"),
        ] {
            let bad = parse(text).invalid_field();
            assert_eq!(bad.as_ref().map(|(k, _)| k.as_str()), Some(key), "{text}");
        }
        assert_eq!(parse("[predef]\nQ320 = 2.0").invalid_field(), None);
    }
}
