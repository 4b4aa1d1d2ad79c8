//! What cycle 460 reports: the probe's row before and after, the sphere, what was
//! measured and what was kept.

use crate::probe_table::calibration::Calibration;

/// What cycle 460 found, for its log, the JSON report and the history.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CalibrationReport {
    /// The probe's name (its row).
    pub probe: String,
    /// Q407.
    pub sphere_radius: f64,
    /// The row before and after.
    pub before: RowValues,
    pub after: RowValues,
    /// The sphere centre (true ball-centre frame), machine coordinates.
    pub sphere_centre: [f64; 3],
    /// Whether the spindle was oriented to 0° and 180° (else the offset was kept).
    pub offset_measured: bool,
    /// Whether Q433 calibrated the length (else it was kept).
    pub length_measured: bool,
    /// Directions of the 3D calibration (0: none).
    pub points_3d: usize,
    /// Largest |effective radius - R| of the 3D table, mm.
    pub max_deviation_3d: Option<f64>,
    /// Why something was kept, for the operator.
    pub notes: Vec<String>,
    /// Where the row was written.
    pub file: String,
}

/// The columns of a row, as reported.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RowValues {
    #[serde(rename = "R")]
    pub r: f64,
    #[serde(rename = "CAL_OF1")]
    pub cal_of1: f64,
    #[serde(rename = "CAL_OF2")]
    pub cal_of2: f64,
    #[serde(rename = "CAL_ANG")]
    pub cal_ang: f64,
    #[serde(rename = "L")]
    pub l: f64,
}

impl RowValues {
    pub fn of(c: &Calibration) -> Self {
        Self {
            r: c.r,
            cal_of1: c.offset[0],
            cal_of2: c.offset[1],
            cal_ang: c.cal_ang,
            l: c.l,
        }
    }
}
