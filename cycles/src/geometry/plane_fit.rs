//! Least-squares plane through points: the normal is the eigenvector of the smallest
//! eigenvalue of the point scatter (orthogonal distances, not z-on-xy regression, so
//! steep planes fit as well as flat ones).

use nalgebra::{Matrix3, Vector3};

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneFit {
    /// A point on the plane (the centroid of the points).
    pub point: Vector3<f64>,
    /// Unit normal; its sign is chosen so that its largest component is positive.
    pub normal: Vector3<f64>,
    /// Root mean square of the signed distances to the plane.
    pub rms: f64,
    pub max_residual: f64,
}

#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PlaneFitError {
    #[error("plane fit needs at least 3 points, got {0}")]
    TooFewPoints(usize),
    #[error("plane fit: point {0} is not finite")]
    NotFinite(usize),
    #[error("plane fit: points are collinear or coincide; they do not determine a plane")]
    Collinear,
}

/// Ratio of the two larger scatter eigenvalues below which points count as collinear.
const COLLINEAR_LIMIT: f64 = 1e-12;

pub fn fit_plane(points: &[Vector3<f64>]) -> Result<PlaneFit, PlaneFitError> {
    if points.len() < 3 {
        return Err(PlaneFitError::TooFewPoints(points.len()));
    }
    if let Some(i) = points.iter().position(|p| !p.iter().all(|v| v.is_finite())) {
        return Err(PlaneFitError::NotFinite(i));
    }
    let n = points.len() as f64;
    let mean = points.iter().sum::<Vector3<f64>>() / n;
    let scatter = points.iter().fold(Matrix3::zeros(), |m, p| {
        m + (p - mean) * (p - mean).transpose()
    });
    let eig = scatter.symmetric_eigen();
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
    let (mid, big) = (eig.eigenvalues[order[1]], eig.eigenvalues[order[2]]);
    if big <= 0.0 || mid <= COLLINEAR_LIMIT * big {
        return Err(PlaneFitError::Collinear);
    }
    let mut normal: Vector3<f64> = eig.eigenvectors.column(order[0]).into_owned().normalize();
    let imax = normal.iamax();
    if normal[imax] < 0.0 {
        normal = -normal;
    }
    let (sum2, max) = points
        .iter()
        .map(|p| (p - mean).dot(&normal))
        .fold((0.0, 0.0f64), |(s, m), d| (s + d * d, m.max(d.abs())));
    Ok(PlaneFit {
        point: mean,
        normal,
        rms: (sum2 / n).sqrt(),
        max_residual: max,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tilted_plane_is_recovered_and_lines_are_refused() {
        let n = Vector3::new(0.1, -0.2, 1.0).normalize();
        let u = n.cross(&Vector3::x()).normalize();
        let v = n.cross(&u);
        let o = Vector3::new(5.0, 6.0, 7.0);
        let pts: Vec<_> = (0..12)
            .map(|i| o + u * (i as f64 * 3.0 - 10.0) + v * ((i * i % 7) as f64 - 3.0))
            .collect();
        let fit = fit_plane(&pts).unwrap();
        assert!((fit.normal - n).norm() < 1e-12 && fit.rms < 1e-12);
        assert!((fit.point - o).dot(&n).abs() < 1e-12);
        let line: Vec<_> = (0..5).map(|i| o + u * i as f64).collect();
        assert_eq!(fit_plane(&line), Err(PlaneFitError::Collinear));
        assert_eq!(fit_plane(&pts[..2]), Err(PlaneFitError::TooFewPoints(2)));
    }
}
