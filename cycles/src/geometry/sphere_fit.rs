//! Least-squares sphere with free radius: an algebraic fit gives the start, Gauss-Newton
//! on the geometric distances |p - c| - r refines it (the algebraic fit alone is biased
//! when the points cover only a cap of the sphere, as in cycle 451).

use nalgebra::{Matrix4, Vector3, Vector4};

/// Result of [`fit_sphere`]; lengths in the units of the points (mm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SphereFit {
    pub centre: Vector3<f64>,
    pub radius: f64,
    /// Root mean square of the geometric residuals |p - c| - r.
    pub rms: f64,
    /// Largest absolute geometric residual.
    pub max_residual: f64,
    /// Gauss-Newton iterations taken.
    pub iterations: usize,
}

#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum FitError {
    #[error("sphere fit needs at least 4 points, got {0}")]
    TooFewPoints(usize),
    #[error("sphere fit: point {0} is not finite")]
    NotFinite(usize),
    #[error("sphere fit: points are degenerate ({0}); they do not determine a sphere")]
    Degenerate(&'static str),
    #[error(
        "sphere fit did not converge: after {iterations} iterations the last step was {step:e} (relative)"
    )]
    NoConvergence { iterations: usize, step: f64 },
}

const MAX_ITERATIONS: usize = 50;
/// Relative step (to the point spread) below which Gauss-Newton has converged.
const STEP_TOLERANCE: f64 = 1e-13;
/// Smallest/largest eigenvalue of the point scatter below which points count as
/// coplanar (or collinear): such sets lie on infinitely many spheres.
const FLATNESS_LIMIT: f64 = 1e-12;

/// Fits a sphere with free radius to `points` (at least 4, not coplanar).
pub fn fit_sphere(points: &[Vector3<f64>]) -> Result<SphereFit, FitError> {
    if points.len() < 4 {
        return Err(FitError::TooFewPoints(points.len()));
    }
    if let Some(i) = points.iter().position(|p| !p.iter().all(|v| v.is_finite())) {
        return Err(FitError::NotFinite(i));
    }
    // Work in centred, scaled coordinates so the normal equations stay well
    // conditioned far from the origin.
    let n = points.len() as f64;
    let mean = points.iter().sum::<Vector3<f64>>() / n;
    let scale = (points
        .iter()
        .map(|p| (p - mean).norm_squared())
        .sum::<f64>()
        / n)
        .sqrt();
    if scale == 0.0 {
        return Err(FitError::Degenerate("all points coincide"));
    }
    let q: Vec<Vector3<f64>> = points.iter().map(|p| (p - mean) / scale).collect();

    let scatter = q
        .iter()
        .fold(nalgebra::Matrix3::zeros(), |m, p| m + p * p.transpose());
    let eig = scatter.symmetric_eigenvalues();
    let (lo, hi) = (eig.min(), eig.max());
    if lo <= FLATNESS_LIMIT * hi {
        return Err(FitError::Degenerate("points are coplanar or collinear"));
    }

    let (mut c, mut r) = algebraic_start(&q)?;
    let mut last_step = f64::INFINITY;
    for iteration in 1..=MAX_ITERATIONS {
        let mut jtj = Matrix4::<f64>::zeros();
        let mut jtr = Vector4::<f64>::zeros();
        for p in &q {
            let d = p - c;
            let dist = d.norm();
            if dist == 0.0 {
                return Err(FitError::Degenerate("a point coincides with the centre"));
            }
            let u = d / dist;
            // d(|p-c| - r)/d(c, r) = (-u, -1)
            let j = Vector4::new(-u.x, -u.y, -u.z, -1.0);
            jtj += j * j.transpose();
            jtr += j * (dist - r);
        }
        let step = jtj
            .cholesky()
            .ok_or(FitError::Degenerate("normal equations are singular"))?
            .solve(&(-jtr));
        c += step.xyz();
        r += step.w;
        last_step = step.norm();
        if last_step < STEP_TOLERANCE * (1.0 + r.abs()) {
            return Ok(finish(points, c * scale + mean, r * scale, iteration));
        }
    }
    Err(FitError::NoConvergence {
        iterations: MAX_ITERATIONS,
        step: last_step,
    })
}

/// |p|^2 + D x + E y + F z + G = 0, linear in (D, E, F, G).
fn algebraic_start(q: &[Vector3<f64>]) -> Result<(Vector3<f64>, f64), FitError> {
    let mut ata = Matrix4::<f64>::zeros();
    let mut atb = Vector4::<f64>::zeros();
    for p in q {
        let a = Vector4::new(p.x, p.y, p.z, 1.0);
        ata += a * a.transpose();
        atb += a * -p.norm_squared();
    }
    let sol = ata
        .lu()
        .solve(&atb)
        .ok_or(FitError::Degenerate("algebraic system is singular"))?;
    let c = -0.5 * sol.xyz();
    let r2 = c.norm_squared() - sol.w;
    if !(r2 > 0.0 && r2.is_finite()) {
        return Err(FitError::Degenerate("algebraic fit gives no real radius"));
    }
    Ok((c, r2.sqrt()))
}

fn finish(
    points: &[Vector3<f64>],
    centre: Vector3<f64>,
    radius: f64,
    iterations: usize,
) -> SphereFit {
    let residuals = points.iter().map(|p| (p - centre).norm() - radius);
    let (sum2, max) = residuals.fold((0.0, 0.0f64), |(s, m), e| (s + e * e, m.max(e.abs())));
    SphereFit {
        centre,
        radius,
        rms: (sum2 / points.len() as f64).sqrt(),
        max_residual: max,
        iterations,
    }
}
