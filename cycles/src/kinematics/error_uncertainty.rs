//! The standard uncertainty (k = 1) of the ISO 230-7 errors cycle 451 identified.
//!
//! The observations are the probed points: each contact's trigger scatters along its
//! probing direction with the probe's repeatability `σ`. A sphere fit (pole and Q423
//! points, free radius) turns them into a centre whose covariance is `σ² C`, `C` the
//! centre block of that fit's `(JᵀJ)⁻¹` ([`CentreNoise`]). The identification's
//! residuals are deviations `d_k = c_k − predict(a_k, p(c_0))`: each shares the
//! reference centre `c_0` with the others of its axis, so they are correlated,
//! `cov(d) = σ² B C Bᵀ` with `B = ∂d/∂c`. [`crate::uncertainty::fit_uncertainty`]
//! takes that as `Ω` (the sandwich form), with the sphere fits' own residual sums
//! pooled into the estimate of `σ`, and the repeatability as its floor.
//!
//! Which errors: the free ones of the identification's last step. In mode 3 an
//! orientation error moved into a machine datum is 0 by definition and gets none; the
//! zero error that took it up is free.

use super::identification::{jacobian, residuals, IdentificationInput, IdentificationResult};
use super::model::ErrorSet;
use crate::uncertainty::{fit_uncertainty, Fit, Problem, ResidualSum, UncertaintyError};
use nalgebra::{DMatrix, Matrix3, Vector3};
use std::collections::BTreeMap;

/// What the probe's scatter does to one measured centre.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CentreNoise {
    /// The centre's covariance per `σ²` (of one contact), machine X/Y/Z.
    pub shape: Matrix3<f64>,
    /// The sphere fit's residual sum of squares and degrees of freedom, mm².
    pub residual: ResidualSum,
}

impl CentreNoise {
    /// A sphere probed at its pole along `tool` (unit) and at `points` points evenly
    /// spaced around its equator, radially, with a free radius: the centre's
    /// covariance per `σ²` is `2/N` across the tool axis and `1 + 1/N` along it (the
    /// pole gives centre plus radius, the equator the radius), whatever the start
    /// angle of the points.
    pub fn pole_and_equator(tool: Vector3<f64>, points: u32, rms: f64) -> Self {
        let n = f64::from(points.max(3));
        let t = tool.normalize();
        let shape = Matrix3::identity() * (2.0 / n) + t * t.transpose() * (1.0 - 1.0 / n);
        let observations = n + 1.0;
        CentreNoise {
            shape,
            residual: ResidualSum {
                sum_squares: rms * rms * observations,
                dof: observations - 4.0,
            },
        }
    }

    /// The mean of several measurements of the same centre (both approaches of Q432).
    pub fn mean(of: &[CentreNoise]) -> Self {
        let k = of.len().max(1) as f64;
        CentreNoise {
            shape: of.iter().map(|c| c.shape).sum::<Matrix3<f64>>() / (k * k),
            residual: of
                .iter()
                .fold(ResidualSum::default(), |s, c| s.pooled(c.residual)),
        }
    }
}

/// Central-difference step for `∂d/∂c`, mm (the deviations are close to linear in the
/// centres).
const CENTRE_STEP: f64 = 1e-3;

/// The standard uncertainty of every identified error, by slot ([`ErrorSet`]), in its
/// unit (mm, deg). `noise[g][k]`: the centre of position `k` of `input.axes[g]`;
/// `repeatability`: the probe's, 1 σ, mm.
pub fn error_uncertainty(
    input: &IdentificationInput,
    result: &IdentificationResult,
    noise: &[Vec<CentreNoise>],
    repeatability: f64,
) -> Result<BTreeMap<usize, f64>, UncertaintyError> {
    let what = "cycle 451's identified errors";
    let free: Vec<usize> = result
        .free
        .iter()
        .copied()
        .filter(|s| !result.transfers.iter().any(|t| t.from == *s))
        .collect();
    if free.is_empty() {
        return Ok(BTreeMap::new());
    }
    if noise.len() != input.axes.len()
        || noise
            .iter()
            .zip(&input.axes)
            .any(|(n, g)| n.len() != g.positions.len())
    {
        return Err(UncertaintyError::new(
            what,
            Problem::Inconsistent("the centre noise does not match the measured positions"),
        ));
    }
    let r = residuals(input, &result.after);
    let rows = r.len();
    let jf = jacobian(input, &result.after, &free, rows);
    let j = DMatrix::from_fn(rows, free.len(), |i, c| jf[(i, c)]);
    // B = ∂d/∂c, a column per centre coordinate; then Ω = B C Bᵀ.
    let cols = 3 * noise.iter().map(Vec::len).sum::<usize>();
    let mut b = DMatrix::<f64>::zeros(rows, cols);
    let mut c = DMatrix::<f64>::zeros(cols, cols);
    let mut col = 0;
    let mut pooled = ResidualSum::default();
    for (g, axis) in input.axes.iter().enumerate() {
        for (k, cn) in noise[g].iter().enumerate().take(axis.positions.len()) {
            pooled = pooled.pooled(cn.residual);
            for i in 0..3 {
                for m in 0..3 {
                    c[(col + i, col + m)] = cn.shape[(i, m)];
                }
                let (mut plus, mut minus) = (input.clone(), input.clone());
                plus.axes[g].positions[k].centre[i] += CENTRE_STEP;
                minus.axes[g].positions[k].centre[i] -= CENTRE_STEP;
                let (rp, rm) = (
                    residuals(&plus, &result.after),
                    residuals(&minus, &result.after),
                );
                for row in 0..rows {
                    b[(row, col + i)] = (rp[row] - rm[row]) / (2.0 * CENTRE_STEP);
                }
            }
            col += 3;
        }
    }
    let omega = &b * c * b.transpose();
    let fit = Fit {
        residual_covariance: Some(&omega),
        pooled: Some(pooled),
        ..Fit::new(what, &j, &r, repeatability)
    };
    let u = fit_uncertainty(&fit)?.u();
    Ok(free.into_iter().zip(u).collect())
}

/// The uncertainties by ISO name, for the report.
pub fn by_name(u: &BTreeMap<usize, f64>) -> BTreeMap<String, f64> {
    u.iter()
        .map(|(&slot, &v)| (ErrorSet::name(slot).to_string(), v))
        .collect()
}
