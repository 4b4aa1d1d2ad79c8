//! A touch probe's calibration, as cycle 460 measures it on a calibration sphere: the
//! TNC's tchprobe.tp columns R, CAL_OF1, CAL_OF2, CAL_ANG, the probe's length L, and
//! with 3D calibration the effective radius as a function of the direction. The
//! cycles 431, 444, 451 and 460 use it through [`Calibration`]:
//!
//! - the true ball centre is the machine's X/Y/Z (the nominal ball centre) plus
//!   [`Calibration::centre_shift`]: (CAL_OF1, CAL_OF2) in the working plane and L
//!   along the tool axis away from the spindle. A cycle that wants the ball at a point
//!   commands the point minus that shift, and a contact's ball centre is the latched
//!   position plus it;
//! - the surface point of a contact is that centre minus
//!   [`Calibration::radius_toward`] times the contact normal: R, plus the 3D table's
//!   deviation for that direction.
//!
//! L is the effective length: cycle 460 measures it at the sphere's pole with R, so it
//! absorbs a pre-travel along the stylus that differs from the one across it (a 3D
//! table then reads 0 at the pole).

use crate::probe_axis::ProbeAxis;
use nalgebra::{Matrix4, Vector3, Vector4};
use serde::{Deserialize, Serialize};

/// Elevations of the 3D calibration's rings above the working plane, deg: 15° apart
/// from 60° below the equator up to 75° above it; the pole (90°) is the last
/// direction. Below the equator the table is measured, not mirrored: L absorbs the
/// axial pre-travel's excess over the lateral one, which turns the effective radius's
/// error odd in the elevation (2 (axial - lateral) sin(elevation) if mirrored).
pub const RING_ELEVATIONS: [f64; 10] = [
    -60.0, -45.0, -30.0, -15.0, 0.0, 15.0, 30.0, 45.0, 60.0, 75.0,
];

/// The 3D calibration (the TNC's option 92): how much the effective radius differs
/// from R in each direction of the contact normal.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Table3d {
    /// Azimuth of each ring's first direction from the main axis of the working
    /// plane, deg (cycle 460's Q380).
    pub azimuth: f64,
    /// Elevation of each ring of directions above the working plane, deg, ascending,
    /// from the lowest measured (0, the equator, in a table of the upper half only;
    /// -60 in one of cycle 460 now) to below 90 (the pole is `pole`).
    pub elevations: Vec<f64>,
    /// Per ring: effective radius minus R at the azimuths `azimuth` + k·360°/n
    /// (k = 0..n; n the same on every ring), mm.
    pub deviations: Vec<Vec<f64>>,
    /// Effective radius minus R along the stylus (the pole), mm.
    pub pole: f64,
}

impl Table3d {
    /// The first thing wrong with the table, as (key, reason).
    pub fn invalid_field(&self) -> Option<(&'static str, String)> {
        if !(self.azimuth.is_finite() && (0.0..=360.0).contains(&self.azimuth)) {
            return Some((
                "3d.azimuth",
                format!("{} is outside 0 .. 360 deg", self.azimuth),
            ));
        }
        let e = &self.elevations;
        if !e.contains(&0.0) || e[0] > 0.0 {
            return Some((
                "3d.elevations",
                "must hold 0 (the equator), and start there or below it".into(),
            ));
        }
        if e.windows(2).any(|w| w[1] <= w[0]) || e.iter().any(|x| !(-90.0..90.0).contains(x)) {
            return Some((
                "3d.elevations",
                format!("{e:?} must ascend within -90 .. 90 deg (the pole is `pole`)"),
            ));
        }
        if self.deviations.len() != e.len() {
            return Some((
                "3d.deviations",
                format!(
                    "{} rings for {} elevations; one ring per elevation",
                    self.deviations.len(),
                    e.len()
                ),
            ));
        }
        let n = self.deviations[0].len();
        if n < 3 || self.deviations.iter().any(|r| r.len() != n) {
            return Some((
                "3d.deviations",
                "every ring needs the same number of directions, at least 3".into(),
            ));
        }
        let all = self.deviations.iter().flatten().chain([&self.pole]);
        if let Some(v) = all
            .into_iter()
            .find(|v| !(v.is_finite() && v.abs() <= MAX_DEVIATION))
        {
            return Some((
                "3d.deviations",
                format!("{v} is outside ±{MAX_DEVIATION} mm"),
            ));
        }
        None
    }

    /// The lowest elevation of a contact normal the table covers, deg: its lowest
    /// ring.
    pub fn lowest_elevation(&self) -> f64 {
        self.elevations.first().copied().unwrap_or(0.0)
    }

    /// The elevation of a contact normal `u` (unit, (main, minor, tool)), deg.
    pub fn elevation(u: [f64; 3]) -> f64 {
        u[2].clamp(-1.0, 1.0).asin().to_degrees()
    }

    /// Whether the table knows the effective radius for the contact normal `u`: from
    /// its lowest ring up to the pole (a normal a hair below, 1e-6°, counts as on it).
    pub fn covers(&self, u: [f64; 3]) -> bool {
        Self::elevation(u) >= self.lowest_elevation() - 1e-6
    }

    /// Effective radius minus R for a contact normal `u` (unit, in (main, minor,
    /// tool) of the working plane; the ball pushed along it). Around a ring: the
    /// trigonometric polynomial through its n values (exact for lobes of up to
    /// (n-1)/2 per turn: a kinematic seat's three need n >= 7); between rings and up to
    /// the pole: linear in the elevation. Below the lowest ring ([`Self::covers`] is
    /// false: the caller refuses such a direction, as cycle 444 does) it reads the
    /// lowest ring's value.
    pub fn deviation(&self, u: [f64; 3]) -> f64 {
        let elevation = Self::elevation(u);
        let azimuth = u[1].atan2(u[0]) - self.azimuth.to_radians();
        let e = &self.elevations;
        let j = e.iter().rposition(|x| *x <= elevation).unwrap_or(0);
        let here = trigonometric(&self.deviations[j], azimuth);
        let (upper, next) = match e.get(j + 1) {
            Some(x) => (*x, trigonometric(&self.deviations[j + 1], azimuth)),
            None => (90.0, self.pole),
        };
        let t = ((elevation - e[j]) / (upper - e[j])).clamp(0.0, 1.0);
        here + t * (next - here)
    }
}

/// Largest deviation a 3D table may hold, mm: a probe whose effective radius varies by
/// more is broken, not calibrated.
pub const MAX_DEVIATION: f64 = 0.5;

/// The trigonometric polynomial through `f` sampled at k·2π/n, evaluated at `x` rad.
fn trigonometric(f: &[f64], x: f64) -> f64 {
    let n = f.len();
    let step = std::f64::consts::TAU / n as f64;
    let mut value = f.iter().sum::<f64>() / n as f64;
    for m in 1..=(n - 1) / 2 {
        let (mut a, mut b) = (0.0, 0.0);
        for (k, v) in f.iter().enumerate() {
            let (s, c) = (m as f64 * k as f64 * step).sin_cos();
            a += v * c;
            b += v * s;
        }
        let (s, c) = (m as f64 * x).sin_cos();
        value += 2.0 / n as f64 * (a * c + b * s);
    }
    if n.is_multiple_of(2) {
        // The Nyquist term: cos(n x / 2) with the alternating sum.
        let alt: f64 = f
            .iter()
            .enumerate()
            .map(|(k, v)| if k % 2 == 0 { *v } else { -*v })
            .sum();
        value += alt / n as f64 * (n as f64 / 2.0 * x).cos();
    }
    value
}

/// A probe's calibration; see the module doc.
#[derive(Clone, Debug, PartialEq)]
pub struct Calibration {
    /// R: effective ball radius across the stylus, mm.
    pub r: f64,
    /// CAL_OF1, CAL_OF2: the ball centre off the spindle axis along the main and the
    /// minor axis of the working plane, with the spindle at CAL_ANG, mm.
    pub offset: [f64; 2],
    /// CAL_ANG: the spindle angle the probe was calibrated at, deg.
    pub cal_ang: f64,
    /// L: how much further from the spindle than the machine's gauge point the ball
    /// centre lies, along the tool axis, mm (effective; see the module doc).
    pub l: f64,
    pub table_3d: Option<Table3d>,
}

impl Calibration {
    /// A probe as the probe table gives it: ball radius `r`, nothing else known.
    pub fn nominal(r: f64) -> Self {
        Self {
            r,
            offset: [0.0, 0.0],
            cal_ang: 0.0,
            l: 0.0,
            table_3d: None,
        }
    }

    /// The true ball centre minus the machine's X/Y/Z, machine frame, mm (the spindle
    /// at CAL_ANG, the head's rotary axes at 0).
    pub fn centre_shift(&self, axis: ProbeAxis) -> [f64; 3] {
        axis.to_machine([self.offset[0], self.offset[1], -self.l])
    }

    /// The effective ball radius for a contact normal `u` (machine frame, unit: the
    /// direction the contact pushes the ball, against the probing direction), mm.
    pub fn radius_toward(&self, axis: ProbeAxis, u: [f64; 3]) -> f64 {
        self.r
            + self
                .table_3d
                .as_ref()
                .map_or(0.0, |t| t.deviation(axis.to_cycle(u)))
    }

    /// A sphere fitted (free radius) through latched ball centres, corrected for this
    /// calibration: `centre` and `radius` of the fit, `directions` the probing
    /// direction of each contact. A contact probed along `d` sat the deviation δ of
    /// the effective radius toward `u = -d` farther out than a ball of radius R would;
    /// to first order the fit moved by the least-squares (Δc, Δr) of
    /// `u·Δc + Δr = δ`, which is taken off; then the stylus shift is added. Returns
    /// the true ball-centre sphere (centre, radius).
    pub fn correct_sphere(
        &self,
        axis: ProbeAxis,
        centre: [f64; 3],
        radius: f64,
        directions: &[[f64; 3]],
    ) -> ([f64; 3], f64) {
        let shift = Vector3::from(self.centre_shift(axis));
        let mut c = Vector3::from(centre);
        let mut r = radius;
        if self.table_3d.is_some() {
            let mut ata = Matrix4::zeros();
            let mut atb = Vector4::zeros();
            for d in directions {
                let u = -Vector3::from(*d).normalize();
                let row = Vector4::new(u.x, u.y, u.z, 1.0);
                let delta = self.radius_toward(axis, u.into()) - self.r;
                ata += row * row.transpose();
                atb += row * delta;
            }
            if let Some(x) = ata.lu().solve(&atb) {
                c -= Vector3::new(x[0], x[1], x[2]);
                r -= x[3];
            }
        }
        ((c + shift).into(), r)
    }

    /// The first field out of range, as (key, reason).
    pub fn invalid_field(&self) -> Option<(&'static str, String)> {
        let (lo, hi) = RADIUS_MM;
        if !(lo..=hi).contains(&self.r) {
            return Some(("R", format!("{} is outside {lo} .. {hi} mm", self.r)));
        }
        for (k, v) in [("CAL_OF1", self.offset[0]), ("CAL_OF2", self.offset[1])] {
            if !(v.is_finite() && v.abs() <= MAX_OFFSET) {
                return Some((k, format!("{v} is outside ±{MAX_OFFSET} mm")));
            }
        }
        if !(0.0..360.0).contains(&self.cal_ang) {
            return Some((
                "CAL_ANG",
                format!("{} is outside 0 .. 360 deg", self.cal_ang),
            ));
        }
        if !(self.l.is_finite() && self.l.abs() <= MAX_LENGTH) {
            return Some(("L", format!("{} is outside ±{MAX_LENGTH} mm", self.l)));
        }
        self.table_3d.as_ref().and_then(Table3d::invalid_field)
    }
}

/// The plausible range of a stylus ball radius, mm (a row's R and `[[probe]]`'s).
pub const RADIUS_MM: (f64, f64) = (0.01, 50.0);

/// Largest centre offset a row may hold, mm.
pub const MAX_OFFSET: f64 = 5.0;
/// Largest length correction a row may hold, mm.
pub const MAX_LENGTH: f64 = 50.0;
