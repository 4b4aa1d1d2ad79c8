//! Cycle 460's parameters, as HEIDENHAIN documents them for CALIBRATION OF TS ON A
//! SPHERE: their table (input ranges, defaults) is [`crate::params::CYCLE_460`]; here
//! the typed parameters and the checks the table cannot make.

use crate::cycle_block::{Param, ParamReader};
use crate::diagnostic::Diagnostic;
use crate::length_unit::LengthUnit;
use std::collections::BTreeMap;

// The table sits with the other cycles' in [`crate::params`] (its `TABLES`).
pub use crate::params::{CYCLE_460, MAX_POINTS_3D};

/// Validated parameters of cycle 460.
#[derive(Clone, Debug, PartialEq)]
pub struct CalibrationParams {
    /// Q407: the exact radius of the calibration sphere, mm.
    pub sphere_radius: f64,
    /// Q320, added to the probe's SET_UP.
    pub clearance: f64,
    /// Q301: 1 moves to the clearance height between points, 0 at measuring height.
    pub to_clearance_height: bool,
    /// Q423: points around the equator (3..8).
    pub points: usize,
    /// Q380: azimuth of the first point from the working plane's main axis, deg.
    pub reference_angle: f64,
    /// Q433: also calibrate the length.
    pub calibrate_length: bool,
    /// Q434: the sphere centre's tool-axis coordinate (active datum), mm; the
    /// length's reference.
    pub length_datum: f64,
    /// Q455: directions per ring of the 3D calibration; 0: none.
    pub points_3d: usize,
}

impl CalibrationParams {
    /// Checks what the table cannot: a 3D calibration needs at least 3 directions per
    /// ring (a kinematic seat's three lobes need 7).
    pub fn from_params(
        params: &BTreeMap<String, Param>,
        _unit: LengthUnit,
    ) -> Result<Self, Vec<Diagnostic>> {
        let mut r = ParamReader::new(params);
        let sphere_radius = r.number("Q407");
        let clearance = r.number("Q320");
        let to_clearance_height = r.number("Q301") == 1.0;
        let points = r.number("Q423") as usize;
        let reference_angle = r.number("Q380");
        let calibrate_length = r.number("Q433") == 1.0;
        let length_datum = r.number("Q434");
        let points_3d = r.number("Q455") as usize;
        if (1..3).contains(&points_3d) {
            r.problem(
                r.line("Q455"),
                format!(
                    "Q455={points_3d}: a 3D calibration needs at least 3 directions per ring (0: none; 7 or more resolve a kinematic probe's three lobes)"
                ),
            );
        }
        r.finish(CalibrationParams {
            sphere_radius,
            clearance,
            to_clearance_height,
            points,
            reference_angle,
            calibrate_length,
            length_datum,
            points_3d,
        })
    }
}
