//! The standard uncertainty (k = 1) of cycle 460's R, CAL_OF1, CAL_OF2 and L, by
//! [`crate::uncertainty`]: each equator ring is a circle fit (centre and radius in the
//! working plane), the rings' residuals pooled into one σ of a contact (with the
//! probe's repeatability as the floor). Then, by propagation:
//!
//! - R is the mean of the rings' radii: `u²(R) = Σ u²(r_k) / m²`;
//! - the offset is half the difference of the centres at 0° and 180°:
//!   `u²(CAL_OF1) = (u²(x_0) + u²(x_180)) / 4`, likewise CAL_OF2;
//! - L is the pole contact less R: `u²(L) = σ² + u²(R)` (one contact, and R).
//!
//! The sphere's own form error and Q407's tolerance are not in it: no fit sees them.

use super::measure::{EquatorRing, Probed};
use crate::uncertainty::{fit_uncertainty, Fit, ResidualSum, UncertaintyError};
use nalgebra::{DMatrix, Vector3};
use std::collections::BTreeMap;

/// One ring's circle: the Jacobian of `|p_i - c| - r` by (cx, cy, r), the residuals.
fn circle_fit(ring: &EquatorRing, frame: &[Vector3<f64>; 3]) -> (DMatrix<f64>, Vec<f64>) {
    let c = [frame[0].dot(&ring.centre), frame[1].dot(&ring.centre)];
    let n = ring.contacts.len();
    let mut j = DMatrix::zeros(n, 3);
    let mut residuals = Vec::with_capacity(n);
    for (i, p) in ring.contacts.iter().enumerate() {
        let (dx, dy) = (frame[0].dot(p) - c[0], frame[1].dot(p) - c[1]);
        let d = dx.hypot(dy);
        j[(i, 0)] = -dx / d;
        j[(i, 1)] = -dy / d;
        j[(i, 2)] = -1.0;
        residuals.push(d - ring.radius);
    }
    (j, residuals)
}

/// The standard uncertainty of each column the cycle measured, by its name in the
/// probe table (R; CAL_OF1, CAL_OF2 when the spindle was oriented; L with Q433 = 1).
/// `repeatability`: the probe's stated one, 1 σ, mm.
pub fn row_uncertainty(
    probed: &Probed,
    frame: &[Vector3<f64>; 3],
    repeatability: f64,
    length_measured: bool,
) -> Result<BTreeMap<String, f64>, UncertaintyError> {
    let fits: Vec<(DMatrix<f64>, Vec<f64>)> = probed
        .equator
        .iter()
        .map(|r| circle_fit(r, frame))
        .collect();
    let sums: Vec<ResidualSum> = fits
        .iter()
        .map(|(j, r)| ResidualSum {
            sum_squares: r.iter().map(|x| x * x).sum(),
            dof: (r.len() as f64 - j.ncols() as f64).max(0.0),
        })
        .collect();
    let mut rings = Vec::with_capacity(fits.len());
    for (k, (j, r)) in fits.iter().enumerate() {
        let others = sums
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != k)
            .fold(ResidualSum::default(), |a, (_, s)| a.pooled(*s));
        let what = format!(
            "cycle 460 equator at spindle {}°",
            probed.equator[k].spindle
        );
        let mut fit = Fit::new(&what, j, r, repeatability);
        fit.pooled = Some(others);
        rings.push(fit_uncertainty(&fit)?);
    }
    let var = |k: usize, i: usize| rings[k].covariance[(i, i)].max(0.0);
    let m = rings.len() as f64;
    let var_r = (0..rings.len()).map(|k| var(k, 2)).sum::<f64>() / (m * m);
    let mut u = BTreeMap::new();
    u.insert("R".to_string(), var_r.sqrt());
    if let [_, _] = &rings[..] {
        for (i, name) in ["CAL_OF1", "CAL_OF2"].into_iter().enumerate() {
            u.insert(name.to_string(), ((var(0, i) + var(1, i)) / 4.0).sqrt());
        }
    }
    if length_measured {
        let sigma = rings.first().map_or(repeatability, |r| r.sigma.value);
        u.insert("L".to_string(), (sigma * sigma + var_r).sqrt());
    }
    Ok(u)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ring(spindle: f64, centre: [f64; 2], radius: f64, n: usize, wobble: f64) -> EquatorRing {
        let contacts = (0..n)
            .map(|k| {
                let a = k as f64 * std::f64::consts::TAU / n as f64;
                let r = radius + if k % 2 == 0 { wobble } else { -wobble };
                Vector3::new(centre[0] + r * a.cos(), centre[1] + r * a.sin(), 50.0)
            })
            .collect();
        EquatorRing {
            spindle,
            contacts,
            centre: Vector3::new(centre[0], centre[1], 50.0),
            radius,
        }
    }

    fn probed(equator: Vec<EquatorRing>) -> Probed {
        Probed {
            equator,
            equator_height: 50.0,
            pole: Vector3::new(0.0, 0.0, 65.5),
            contacts_3d: Vec::new(),
            oriented: true,
        }
    }

    const FRAME: [Vector3<f64>; 3] = [
        Vector3::new(1.0, 0.0, 0.0),
        Vector3::new(0.0, 1.0, 0.0),
        Vector3::new(0.0, 0.0, 1.0),
    ];

    /// On exact circles only the repeatability is left (5 points a ring: 4 degrees of
    /// freedom pooled, below the floor's 8): each circle of 5 evenly spread points has
    /// u²(r) = σ²/5 and u²(cx) = 2σ²/5.
    #[test]
    fn exact_rings_give_the_repeatability_floor_propagated() {
        let p = probed(vec![
            ring(0.0, [1.0, 2.0], 15.5, 5, 0.0),
            ring(180.0, [1.006, 2.0], 15.5, 5, 0.0),
        ]);
        let sigma: f64 = 0.0005;
        let u = row_uncertainty(&p, &FRAME, sigma, true).unwrap();
        let ur = (sigma * sigma / 10.0).sqrt();
        assert!((u["R"] - ur).abs() < 1e-12, "{u:?}");
        let uc = (sigma * sigma / 5.0).sqrt();
        assert!((u["CAL_OF1"] - uc).abs() < 1e-12, "{u:?}");
        assert!((u["CAL_OF2"] - uc).abs() < 1e-12, "{u:?}");
        assert!((u["L"] - (sigma * sigma + ur * ur).sqrt()).abs() < 1e-12);
    }

    /// Residuals larger than the repeatability set σ; one ring (no orientable spindle)
    /// gives no offset uncertainty, and Q433 = 0 none for L.
    #[test]
    fn residuals_scale_it_and_unmeasured_columns_have_none() {
        let p = probed(vec![ring(0.0, [0.0, 0.0], 15.5, 8, 0.002)]);
        let u = row_uncertainty(&p, &FRAME, 0.0005, false).unwrap();
        assert_eq!(u.keys().collect::<Vec<_>>(), ["R"]);
        // The alternating ±2 µm is orthogonal to a circle's parameters: s = 2 µm
        // sqrt(8/5), above the floor.
        let s = 0.002 * (8.0f64 / 5.0).sqrt();
        assert!((u["R"] - s / 8f64.sqrt()).abs() < 1e-9, "{u:?}");
    }
}
