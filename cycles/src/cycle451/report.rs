//! What cycle 451 reports (`"kinematics"` in `--json`, and its measuring log): every
//! measuring position, its sphere, the errors before and after.

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// One sphere measurement (all rounds).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SphereRecord {
    /// Latched rotary angles (mean over the contacts) by axis name.
    pub angles: BTreeMap<String, f64>,
    /// Fitted centre of the latched X/Y/Z positions, mm.
    pub centre: [f64; 3],
    /// Fitted sphere radius (ball radius subtracted), mm.
    pub radius: f64,
    /// RMS residual of the fit, mm.
    pub rms: f64,
    /// Run id of each round (the last one counts).
    pub run_ids: Vec<u64>,
    /// "above" or "below" when approached for the backlash measurement.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub approach: Option<String>,
}

/// One measuring position of an axis in the result.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PositionReport {
    /// The 0 deg reference.
    pub reference: bool,
    /// All rotary angles (latched), deg.
    pub angles: BTreeMap<String, f64>,
    /// Measured sphere centre (mean of both approaches with Q432), mm.
    pub centre: [f64; 3],
    /// Fitted sphere radius, mm.
    pub radius: f64,
    /// `d_k` with the active kinematics and with the optimised ones, mm.
    pub deviation_before: [f64; 3],
    pub deviation_after: [f64; 3],
    pub measurements: Vec<SphereRecord>,
}

/// One measured axis in the result.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AxisReport {
    pub axis: String,
    pub start: f64,
    pub end: f64,
    pub points: u32,
    pub hirth: f64,
    /// The configured pivot of the axis (nominal chain), mm.
    pub pivot: [f64; 3],
    /// Radius of the circle the measured centre describes about the axis, mm.
    pub circle_radius: f64,
    /// Mean backlash, deg (None: not measured or not computable, see `notes`).
    pub backlash: Option<f64>,
    pub dispersion_before: f64,
    pub max_before: f64,
    pub dispersion_after: f64,
    pub max_after: f64,
    /// Angular positioning error (tangential deviation over the circle radius) after
    /// optimisation: mean and standard deviation about 0, deg.
    pub positioning_error_mean: f64,
    pub positioning_error_std: f64,
    /// The axis's errors by ISO name (location errors and zero error).
    pub errors_before: BTreeMap<String, f64>,
    pub errors_after: BTreeMap<String, f64>,
    /// The standard uncertainty (k = 1) of each identified error in `errors_after`
    /// (the errors the optimisation was free to change), mm or deg.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub errors_u: BTreeMap<String, f64>,
    pub positions: Vec<PositionReport>,
}

/// The extra result of a 451 cycle (`"kinematics"` in `--json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct KinematicsReport {
    pub mode: u8,
    pub machine: String,
    pub kinematics_file: PathBuf,
    pub estimator: String,
    pub probe: String,
    /// The corrected errors were written to the kinematics file.
    pub written: bool,
    /// Incidence angles of the machine's rotary axes, deg.
    pub incidence: BTreeMap<String, f64>,
    /// Active preset (machine X/Y/Z) before and after the cycle, and the shift.
    pub preset_before: [f64; 3],
    pub preset_after: [f64; 3],
    pub preset_shift: [f64; 3],
    /// The preset row was set (Q431 = 1..3 in modes 1..3); mode 0 sets none.
    #[serde(default)]
    pub preset_set: bool,
    /// What happened to the preset, in words ("Q431=1: preset not set (mode 0); the
    /// sphere centre measured at X.. Y.. Z..").
    #[serde(default)]
    pub preset: String,
    /// Set when a later cycle 450 restored the kinematics file: what the file is then.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub restored: Option<String>,
    /// Q147..Q149.
    pub offset_error: [f64; 3],
    /// All errors of the machine's rotary axes, by ISO name.
    pub errors_before: BTreeMap<String, f64>,
    pub errors_after: BTreeMap<String, f64>,
    /// The standard uncertainty (k = 1) of each identified error, mm or deg.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub errors_u: BTreeMap<String, f64>,
    pub axes: Vec<AxisReport>,
    pub notes: Vec<String>,
    /// The machine time up to the measuring log (its "Machine time" row); the cycle's
    /// own result carries the whole time (`machine_time_s`), so it is not repeated.
    #[serde(skip)]
    pub machine_time: Option<crate::machine_time::TimeSplit>,
}

impl KinematicsReport {
    /// A few lines for the text result: per axis the dispersion and the errors before
    /// and after optimisation, and what happened to the kinematics file.
    pub fn summary(&self) -> String {
        let mut s = String::new();
        for a in &self.axes {
            s.push_str(&format!(
                "  axis {}: dispersion {:.6} -> {:.6} mm, max deviation {:.6} -> {:.6} mm{}\n",
                a.axis,
                a.dispersion_before,
                a.dispersion_after,
                a.max_before,
                a.max_after,
                a.backlash
                    .map_or_else(String::new, |b| format!(", backlash {b:+.5} deg"))
            ));
            for (name, before) in &a.errors_before {
                let after = a.errors_after.get(name).copied().unwrap_or(0.0);
                let u = a
                    .errors_u
                    .get(name)
                    .map_or_else(String::new, |u| format!(" ± {u:.6}"));
                s.push_str(&format!(
                    "    {name} {before:+.6} -> {after:+.6}{u}{}\n",
                    if after != *before { " *" } else { "" }
                ));
            }
        }
        s.push_str(&format!("  {}\n", self.preset));
        s.push_str(&format!(
            "  kinematics {}: {}\n",
            self.kinematics_file.display(),
            match (&self.restored, self.written) {
                (Some(r), _) => format!("corrected errors written, then {r}"),
                (None, true) => "corrected errors written".to_string(),
                (None, false) => "not changed".to_string(),
            }
        ));
        s
    }
}

/// What Q431 = 1..3 did with the preset: set (modes 1..3, once the cycle succeeded),
/// or, in mode 0, only measured (mode 0 writes nothing).
pub(crate) fn preset_words(mode_writes: bool) -> &'static str {
    if mode_writes {
        "preset set to the sphere centre"
    } else {
        "preset not set (mode 0); the sphere centre measured at"
    }
}
