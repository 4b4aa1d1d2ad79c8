//! The standard uncertainty (k = 1) of cycle 460's R, CAL_OF1, CAL_OF2 and L, by
//! [`crate::uncertainty`]: each equator ring is a circle fit (centre and radius in the
//! working plane) with the three lobes of a kinematic seat modelled in it where the
//! ring resolves them (`ring_fit`), the rings' residuals pooled into one σ of a
//! contact (with the probe's repeatability as the floor). Then, by propagation:
//!
//! - R is the mean of the rings' radii: `u²(R) = Σ u²(r_k) / m²`;
//! - the offset is half the difference of the centres at 0° and 180°:
//!   `u²(CAL_OF1) = (u²(x_0) + u²(x_180)) / 4`, likewise CAL_OF2;
//! - L is the pole contact less R: `u²(L) = σ_p² + u²(R)` (one contact, and R). The
//!   pole contact has no residual of its own: `σ_p` is the rings' `s` where it has
//!   [`MIN_DOF`] degrees of freedom, else the probe's repeatability, as for cycle
//!   444's one point. (The floor `max(s, repeatability)` of a fit with few degrees
//!   of freedom is biased high, about 11 % at the 6 of two 8-point rings; the fit's
//!   own parameters carry that as the spec's floor, a single contact need not.)
//!
//! The sphere's own form error and Q407's tolerance are not in it: no fit sees them.

use super::measure::{EquatorRing, Probed};
use crate::uncertainty::{fit_uncertainty, Fit, ResidualSum, UncertaintyError, MIN_DOF};
use nalgebra::{DMatrix, DVector, Vector3};
use std::collections::BTreeMap;

/// A column whose part outside the columns before it is below this fraction of its
/// length is not resolved by the ring's points: it aliases onto them. On evenly spread
/// points a lobe column is either orthogonal to the others or aliased onto them, up to
/// the contacts' angles about the found centre turning by the offset over the radius
/// (1e-4 of a radian): a wide margin either way.
const ALIASED: f64 = 0.1;

/// The part of `col` outside the span of `basis` (orthonormal columns).
fn outside(basis: &[DVector<f64>], col: &DVector<f64>) -> DVector<f64> {
    basis.iter().fold(col.clone(), |v, b| &v - b * b.dot(&v))
}

/// One ring's fit: the Jacobian of `|p_i - c| - r - a cos 3θ_i - b sin 3θ_i` by
/// (cx, cy, r, a, b), and its residuals.
///
/// The pre-travel of a kinematic seat has three lobes: the contacts' distances from the
/// centre carry `cos 3θ`, `sin 3θ` (the sphere is round). Left out of the model they
/// would count as scatter of the contacts and inflate u several-fold. A lobe column is
/// fitted where the ring's points resolve it (not aliased onto the circle's columns nor
/// onto the other lobe column: 3 and 4 points cannot see the lobes, 6 see one of the two
/// columns) and a degree of freedom is left to estimate the scatter by (5 points
/// would have none: there the lobes stay in the residuals). On the cycle's evenly
/// spread points a resolved lobe column is orthogonal to the circle's, so fitting it
/// leaves the circle ([`super::evaluate::fit_circle`], whose centre and radius the
/// cycle reports) where it is: the residuals here are the circle's less the lobes'
/// least-squares part, one linear step from the circle's optimum.
fn ring_fit(ring: &EquatorRing, frame: &[Vector3<f64>; 3]) -> (DMatrix<f64>, Vec<f64>) {
    let c = [frame[0].dot(&ring.centre), frame[1].dot(&ring.centre)];
    let n = ring.contacts.len();
    let mut cols = vec![DVector::zeros(n), DVector::zeros(n), DVector::zeros(n)];
    let mut lobes = [DVector::zeros(n), DVector::zeros(n)];
    let mut r0 = DVector::zeros(n);
    for (i, p) in ring.contacts.iter().enumerate() {
        let (dx, dy) = (frame[0].dot(p) - c[0], frame[1].dot(p) - c[1]);
        let d = dx.hypot(dy);
        cols[0][i] = -dx / d;
        cols[1][i] = -dy / d;
        cols[2][i] = -1.0;
        let (s3, c3) = (3.0 * dy.atan2(dx)).sin_cos();
        lobes[0][i] = -c3;
        lobes[1][i] = -s3;
        r0[i] = d - ring.radius;
    }
    let mut basis: Vec<DVector<f64>> = Vec::new();
    for col in &cols {
        let v = outside(&basis, col);
        if v.norm() > ALIASED * col.norm() {
            basis.push(v.normalize());
        }
    }
    // Against the pair's mean length (|cos 3θ|² + |sin 3θ|² = n): a column that is
    // nearly 0 on these points (sin 3θ on 6 points from 0°) is not resolved either.
    let lobe_length = (n as f64 / 2.0).sqrt();
    let mut resolved = Vec::new();
    for col in lobes {
        let v = outside(&basis, &col);
        if v.norm() > ALIASED * lobe_length {
            basis.push(v.normalize());
            resolved.push(col);
        }
    }
    let residuals = if !resolved.is_empty() && n > cols.len() + resolved.len() {
        cols.extend(resolved);
        // (I - H) r0: the whole model's residuals, one linear step from the circle's
        // optimum (where r0 is orthogonal to the circle's columns: the lobes' part goes).
        outside(&basis, &r0)
    } else {
        r0
    };
    (
        DMatrix::from_columns(&cols),
        residuals.iter().copied().collect(),
    )
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
    let fits: Vec<(DMatrix<f64>, Vec<f64>)> =
        probed.equator.iter().map(|r| ring_fit(r, frame)).collect();
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
        let sigma = rings
            .first()
            .filter(|r| r.sigma.dof >= MIN_DOF)
            .map_or(repeatability, |r| r.sigma.value);
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
        // The alternating ±2 µm is orthogonal to a circle's and the lobes' parameters
        // (8 points: 3 degrees of freedom left): s = 2 µm sqrt(8/3), above the floor.
        let s = 0.002 * (8.0f64 / 3.0).sqrt();
        assert!((u["R"] - s / 8f64.sqrt()).abs() < 1e-9, "{u:?}");
    }

    /// The pole contact of L: with the rings' 6 degrees of freedom their large `s`
    /// sets R's u, but the one pole contact takes the repeatability; with 14 (two
    /// rings of 12 points) the rings' `s` is sound and sets it too.
    #[test]
    fn the_pole_contact_takes_the_rings_s_only_with_enough_degrees_of_freedom() {
        let rep: f64 = 0.0005;
        let few = probed(vec![
            ring(0.0, [0.0, 0.0], 15.5, 8, 0.002),
            ring(180.0, [0.006, 0.0], 15.5, 8, 0.002),
        ]);
        let u = row_uncertainty(&few, &FRAME, rep, true).unwrap();
        let s = 0.002 * (16.0f64 / 6.0).sqrt();
        assert!((u["R"] - s / 16f64.sqrt()).abs() < 1e-9, "{u:?}");
        assert!(
            (u["L"] - (rep * rep + u["R"] * u["R"]).sqrt()).abs() < 1e-12,
            "{u:?}"
        );
        let many = probed(vec![
            ring(0.0, [0.0, 0.0], 15.5, 12, 0.002),
            ring(180.0, [0.006, 0.0], 15.5, 12, 0.002),
        ]);
        let u = row_uncertainty(&many, &FRAME, rep, true).unwrap();
        // 12 points a ring, 5 parameters: 7 each, 14 pooled.
        let s = 0.002 * (24.0f64 / 14.0).sqrt();
        assert!((u["R"] - s / 24f64.sqrt()).abs() < 1e-9, "{u:?}");
        assert!(
            (u["L"] - (s * s + u["R"] * u["R"]).sqrt()).abs() < 1e-9,
            "{u:?}"
        );
    }

    /// A ring of `n` contacts from azimuth `start` whose distances from `centre` carry
    /// three lobes of `amplitude` (first maximum at `phase`), fitted as the cycle does.
    fn lobed(spindle: f64, n: usize, start: f64, amplitude: f64, phase: f64) -> EquatorRing {
        let (centre, radius) = ([1.0, 2.0], 15.5);
        let contacts: Vec<Vector3<f64>> = (0..n)
            .map(|k| {
                let a = (start + k as f64 * 360.0 / n as f64).to_radians();
                let r = radius + amplitude * (3.0 * (a - phase.to_radians())).cos();
                Vector3::new(centre[0] + r * a.cos(), centre[1] + r * a.sin(), 50.0)
            })
            .collect();
        let plane: Vec<[f64; 2]> = contacts.iter().map(|c| [c.x, c.y]).collect();
        let (c, r) = super::super::evaluate::fit_circle(&plane).unwrap();
        EquatorRing {
            spindle,
            contacts,
            centre: Vector3::new(c[0], c[1], 50.0),
            radius: r,
        }
    }

    /// 4 µm of lobing on 8 points a ring (turned over with the spindle at 180°): the
    /// circle is exact (the lobes are orthogonal to it), and so is u: the lobes are
    /// modelled, not scatter, and only the repeatability's floor is left, as on exact
    /// circles (u²(r) = σ²/8, u²(cx) = σ²/4).
    #[test]
    fn lobes_are_modelled_not_counted_as_scatter() {
        let p = probed(vec![
            lobed(0.0, 8, 0.0, 0.004, 10.0),
            lobed(180.0, 8, 0.0, -0.004, 10.0),
        ]);
        for ring in &p.equator {
            assert!((ring.radius - 15.5).abs() < 1e-12, "{ring:?}");
            assert!((ring.centre - Vector3::new(1.0, 2.0, 50.0)).norm() < 1e-12);
        }
        let sigma: f64 = 0.0005;
        let u = row_uncertainty(&p, &FRAME, sigma, true).unwrap();
        let ur = (sigma * sigma / 16.0).sqrt();
        assert!((u["R"] - ur).abs() < 1e-12, "{u:?}");
        let uc = (sigma * sigma / 8.0).sqrt();
        assert!((u["CAL_OF1"] - uc).abs() < 1e-12, "{u:?}");
        assert!((u["CAL_OF2"] - uc).abs() < 1e-12, "{u:?}");
        assert!((u["L"] - (sigma * sigma + ur * ur).sqrt()).abs() < 1e-12);
    }

    /// Which rings resolve the lobes: 3 and 4 points alias them onto the circle, 5
    /// would leave no degree of freedom (the lobes stay in the residuals), 6 resolve
    /// one column of the two (both are ±1 alternating there), 7 and 8 both.
    #[test]
    fn the_lobes_are_fitted_where_the_ring_resolves_them() {
        for (n, start, columns) in [
            (3, 0.0, 3),
            (4, 0.0, 3),
            (5, 0.0, 3),
            (6, 0.0, 4),
            (6, 10.0, 4),
            (7, 0.0, 5),
            (8, 25.0, 5),
        ] {
            let ring = lobed(0.0, n, start, 0.004, 10.0);
            let (j, r) = ring_fit(&ring, &FRAME);
            assert_eq!(j.ncols(), columns, "{n} points from {start}°");
            let rms = (r.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt();
            if columns > 3 {
                assert!(rms < 1e-9, "{n} points: lobes left in the residuals {r:?}");
            } else if n == 5 {
                assert!(rms > 1e-3, "{n} points: {r:?}");
            }
        }
    }
}
