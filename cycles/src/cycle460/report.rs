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
    /// The standard uncertainty (k = 1) of the columns measured (R; CAL_OF1/2 with an
    /// oriented spindle; L with Q433 = 1), mm ([`super::uncertainty`]).
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub u: std::collections::BTreeMap<String, f64>,
}

impl CalibrationReport {
    /// The row before and after, the uncertainties, and what was kept and why, for the
    /// text report.
    pub fn summary(&self) -> String {
        let mut s = format!("  probe table row \"{}\" ({}):\n", self.probe, self.file);
        let (b, a) = (&self.before, &self.after);
        for (name, x, y) in [
            ("R", b.r, a.r),
            ("CAL_OF1", b.cal_of1, a.cal_of1),
            ("CAL_OF2", b.cal_of2, a.cal_of2),
            ("L", b.l, a.l),
        ] {
            let kept = match name {
                "CAL_OF1" | "CAL_OF2" => !self.offset_measured,
                "L" => !self.length_measured,
                _ => false,
            };
            let u = match self.u.get(name) {
                _ if kept => " (kept)".to_string(),
                Some(u) => format!(" ± {u:.6}"),
                None => String::new(),
            };
            s.push_str(&format!("    {name:<8} {x:+.6} -> {y:+.6}{u}\n"));
        }
        if let Some(m) = self.max_deviation_3d {
            s.push_str(&format!(
                "    3D table: {} directions per ring, largest |effective radius - R| {m:.6}\n",
                self.points_3d
            ));
        }
        for n in &self.notes {
            s.push_str(&format!("    note: {n}\n"));
        }
        s
    }
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
