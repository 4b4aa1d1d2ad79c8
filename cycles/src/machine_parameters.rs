//! The measuring cycles' machine parameters: `[cycles]` of the machine TOML
//! (`maxDevCalBall`, `maxModification`, and `[cycles.predef]` for PREDEF). Read and
//! validated here, not by hal, which accepts the section unread.

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
}

fn default_max_dev_cal_ball() -> f64 {
    0.1
}
fn default_max_modification() -> f64 {
    0.5
}

impl Default for MachineParameters {
    fn default() -> Self {
        Self {
            max_dev_cal_ball: default_max_dev_cal_ball(),
            max_modification: default_max_modification(),
            predef: BTreeMap::new(),
        }
    }
}

impl MachineParameters {
    /// The first value out of range, as (key, reason). Non-finite numbers (TOML's
    /// `inf` and `nan`) are refused here, where they enter.
    pub fn invalid_field(&self) -> Option<(String, &'static str)> {
        for (key, v) in [
            ("cycles.maxDevCalBall", self.max_dev_cal_ball),
            ("cycles.maxModification", self.max_modification),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Some((key.to_string(), "must be a number > 0"));
            }
        }
        self.predef
            .iter()
            .find(|(_, v)| !v.is_finite())
            .map(|(q, _)| (format!("cycles.predef.{q}"), "must be a finite number"))
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
