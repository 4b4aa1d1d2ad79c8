//! Cycle 460's maths: from the ball centres at the contacts to R, the centre offset,
//! L and the 3D table. Everything in machine coordinates (mm); "in the plane" means
//! the (main, minor) components of the working plane.
//!
//! - Equator: the ball centres of one ring lie on a circle of radius Q407 + R about
//!   the sphere centre, shifted by minus the stylus offset of that spindle angle; a
//!   least-squares circle gives both. With the spindle at 0° and 180° the offset turns
//!   over: offset = (c180 - c0) / 2, sphere centre = (c0 + c180) / 2.
//! - The ring's height is the sphere's equator as the first pole contact estimated it;
//!   a height error ε shrinks the circle to sqrt(r² - ε²), which is undone once the
//!   pole has been probed over the true centre.
//! - L: the pole contact's ball centre along the tool axis minus Q434 (the sphere
//!   centre, active datum), Q407 and R.
//! - 3D: each contact's true ball centre (latched centre plus offset and length) lies
//!   Q407 plus the effective radius in that direction from the sphere centre.

use crate::probe_table::calibration::Table3d;
use nalgebra::{Matrix3, Vector2, Vector3};

/// The circle fit's Gauss-Newton stops when a step moves centre and radius by less
/// than this, mm; it must within [`CIRCLE_FIT_ITERATIONS`] or the fit is an error.
pub const CIRCLE_FIT_TOLERANCE: f64 = 1e-10;
/// The most Gauss-Newton steps of a circle fit (on a ring it converges in a handful).
pub const CIRCLE_FIT_ITERATIONS: usize = 50;

/// Least-squares circle (geometric distances) through points of a plane: an algebraic
/// fit, refined by Gauss-Newton to [`CIRCLE_FIT_TOLERANCE`]. Returns (centre, radius),
/// or why not (a fit that did not converge says so).
pub fn fit_circle(points: &[[f64; 2]]) -> Result<([f64; 2], f64), String> {
    if points.len() < 3 {
        return Err(format!("a circle needs 3 points, got {}", points.len()));
    }
    let n = points.len() as f64;
    let mean = points
        .iter()
        .fold(Vector2::zeros(), |a, p| a + Vector2::new(p[0], p[1]))
        / n;
    let q: Vec<Vector2<f64>> = points
        .iter()
        .map(|p| Vector2::new(p[0], p[1]) - mean)
        .collect();
    // Algebraic: x² + y² + D x + E y + F = 0 in least squares.
    let mut a = Matrix3::zeros();
    let mut b = Vector3::zeros();
    for p in &q {
        let row = Vector3::new(p.x, p.y, 1.0);
        let rhs = -(p.x * p.x + p.y * p.y);
        a += row * row.transpose();
        b += row * rhs;
    }
    let s = a
        .lu()
        .solve(&b)
        .ok_or("the points lie on a line; they give no circle")?;
    let mut c = Vector2::new(-s.x / 2.0, -s.y / 2.0);
    let mut r = (c.norm_squared() - s.z).max(0.0).sqrt();
    let mut last = f64::INFINITY;
    for _ in 0..CIRCLE_FIT_ITERATIONS {
        let mut jtj = Matrix3::zeros();
        let mut jtr = Vector3::zeros();
        for p in &q {
            let d = p - c;
            let dist = d.norm();
            if dist == 0.0 {
                return Err("a point lies at the circle's centre".into());
            }
            let j = Vector3::new(-d.x / dist, -d.y / dist, -1.0);
            let res = dist - r;
            jtj += j * j.transpose();
            jtr += j * res;
        }
        let step = jtj
            .lu()
            .solve(&(-jtr))
            .ok_or("the circle fit is degenerate")?;
        c += Vector2::new(step.x, step.y);
        r += step.z;
        last = step.norm();
        if last < CIRCLE_FIT_TOLERANCE {
            return Ok(([c.x + mean.x, c.y + mean.y], r));
        }
    }
    Err(format!(
        "the circle fit did not converge: its last step was {last:.3e} mm after {CIRCLE_FIT_ITERATIONS} iterations (tolerance {CIRCLE_FIT_TOLERANCE:e} mm)"
    ))
}

/// The unit direction of azimuth `az` and elevation `el` (deg) in the working plane
/// of (main, minor, tool) unit vectors `frame` (machine coordinates).
pub fn direction(frame: &[Vector3<f64>; 3], az_deg: f64, el_deg: f64) -> Vector3<f64> {
    let (sa, ca) = az_deg.to_radians().sin_cos();
    let (se, ce) = el_deg.to_radians().sin_cos();
    (frame[0] * ca + frame[1] * sa) * ce + frame[2] * se
}

/// One contact of the 3D calibration: its ring and direction index, and its true
/// ball centre (latched plus offset and length).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Contact3d {
    pub ring: usize,
    pub k: usize,
    pub centre: Vector3<f64>,
}

/// The 3D table from the contacts: effective radius minus R for every ring and
/// direction, the pole 0 (R and L are calibrated to make it so).
pub fn table_3d(
    elevations: &[f64],
    per_ring: usize,
    azimuth: f64,
    contacts: &[Contact3d],
    sphere_centre: Vector3<f64>,
    sphere_radius: f64,
    r: f64,
) -> Table3d {
    let mut deviations = vec![vec![0.0; per_ring]; elevations.len()];
    for c in contacts {
        deviations[c.ring][c.k] = (c.centre - sphere_centre).norm() - sphere_radius - r;
    }
    Table3d {
        azimuth,
        elevations: elevations.to_vec(),
        deviations,
        pole: 0.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn circle_fit_is_exact_on_a_circle_and_off_centre_points() {
        let pts: Vec<[f64; 2]> = (0..5)
            .map(|k| {
                let a = 0.3 + k as f64 * 1.1;
                [12.0 + 7.5 * a.cos(), -3.0 + 7.5 * a.sin()]
            })
            .collect();
        let (c, r) = fit_circle(&pts).unwrap();
        assert!(
            (c[0] - 12.0).abs() < 1e-12 && (c[1] + 3.0).abs() < 1e-12,
            "{c:?}"
        );
        assert!((r - 7.5).abs() < 1e-12, "{r}");
        assert!(fit_circle(&[[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]]).is_err());
    }
}
