//! Standard uncertainties (k = 1, as the GUM states them) of least-squares results:
//! the routine every fit of the cycles uses.
//!
//! A fit that minimises `|r(θ)|²` over its parameters `θ`, linearised at the optimum
//! with the Jacobian `J = ∂r/∂θ`, has the covariance
//!
//! ```text
//! cov(θ) = σ² (JᵀJ)⁻¹
//! ```
//!
//! where `σ` is the standard uncertainty of one observation (one probed point). `σ`
//! comes from the fit's own residuals, `s² = |r|² / ν` with `ν = n − p` degrees of
//! freedom, because they show the noise of this very measurement. With few degrees of
//! freedom `s` is itself unsure (with `ν = 1` it is often off by half), and with none
//! (three points on a plane, one point of cycle 444) there is no `s` at all: then the
//! probe's stated repeatability is the floor, `σ = max(s, repeatability)` for
//! `ν <` [`MIN_DOF`], and `σ = repeatability` for `ν = 0`.
//!
//! Residuals that share an observation are correlated (cycle 451's deviations are
//! differences to the measurement at the 0° reference). Their covariance is
//! `σ² Ω`; with `Ω` given ([`Fit::residual_covariance`]), the covariance of the
//! unweighted fit is the sandwich `σ² (JᵀJ)⁻¹ JᵀΩJ (JᵀJ)⁻¹`, and `s²` is `|r|²`
//! divided by `tr((I − H) Ω)` (`H = J(JᵀJ)⁻¹Jᵀ`), the expectation of `|r|²/σ²`.
//! Residual sums of other fits of the same observations (the sphere fits under 451's
//! centres) pool into `s` ([`Fit::pooled`]).
//!
//! Quantities derived from the parameters (angles of a plane, a point) follow by
//! linear propagation, `cov(f) = G cov(θ) Gᵀ` ([`Uncertainty::propagate`]).
//!
//! Not covered here, because no fit can see them: systematic effects common to every
//! observation (the form error of the artefact, temperature, an uncalibrated probe).

use nalgebra::{DMatrix, DVector};

/// Below this many degrees of freedom the probe's repeatability is a floor under the
/// residual estimate `s`: at 8 the relative standard deviation of `s` is 25 %.
pub const MIN_DOF: f64 = 8.0;

/// Column singular values below this, relative to the largest (columns scaled to unit
/// length), leave a parameter undetermined.
const RANK_TOLERANCE: f64 = 1e-10;

/// A residual sum of squares with its degrees of freedom, in the observations' unit.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ResidualSum {
    pub sum_squares: f64,
    pub dof: f64,
}

impl ResidualSum {
    /// Both sums together: one estimate of the same `σ`.
    pub fn pooled(self, other: ResidualSum) -> ResidualSum {
        ResidualSum {
            sum_squares: self.sum_squares + other.sum_squares,
            dof: self.dof + other.dof,
        }
    }

    /// `s = sqrt(sum / dof)`, `None` without degrees of freedom.
    pub fn s(&self) -> Option<f64> {
        (self.dof > 0.0).then(|| (self.sum_squares / self.dof).sqrt())
    }

    /// The `σ` of one observation: `s`, with `repeatability` as the floor below
    /// [`MIN_DOF`] degrees of freedom (see the module doc).
    pub fn sigma(&self, repeatability: f64) -> Sigma {
        let s = self.s();
        let (value, floor_applied) = match s {
            Some(s) if self.dof >= MIN_DOF => (s, false),
            Some(s) if s >= repeatability => (s, false),
            _ => (repeatability, true),
        };
        Sigma {
            value,
            residual: s,
            dof: self.dof,
            floor_applied,
        }
    }
}

/// The standard uncertainty of one observation a result was scaled with.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sigma {
    /// `σ`, in the observations' unit.
    pub value: f64,
    /// `s` from the residuals (`None`: no degrees of freedom).
    pub residual: Option<f64>,
    pub dof: f64,
    /// Whether the stated repeatability set `σ` (few degrees of freedom).
    pub floor_applied: bool,
}

/// A least-squares fit at its optimum, for [`fit_uncertainty`].
#[derive(Clone, Copy, Debug)]
pub struct Fit<'a> {
    /// What was fitted, for the errors ("cycle 431 plane", "sphere at C+90").
    pub what: &'a str,
    /// `∂r/∂θ`: a row per residual, a column per parameter.
    pub jacobian: &'a DMatrix<f64>,
    /// The residuals at the optimum.
    pub residuals: &'a [f64],
    /// The probe's stated repeatability, 1 σ, in the observations' unit.
    pub repeatability: f64,
    /// `Ω`: the residuals' covariance per `σ²` when they share observations; `None`:
    /// independent, `Ω = I`.
    pub residual_covariance: Option<&'a DMatrix<f64>>,
    /// Residual sums of other fits of the same observations, pooled into `s`.
    pub pooled: Option<ResidualSum>,
}

impl<'a> Fit<'a> {
    /// Independent residuals, nothing pooled.
    pub fn new(
        what: &'a str,
        jacobian: &'a DMatrix<f64>,
        residuals: &'a [f64],
        repeatability: f64,
    ) -> Self {
        Self {
            what,
            jacobian,
            residuals,
            repeatability,
            residual_covariance: None,
            pooled: None,
        }
    }
}

/// The covariance of a fit's parameters and the `σ` it was scaled with.
#[derive(Clone, Debug, PartialEq)]
pub struct Uncertainty {
    pub covariance: DMatrix<f64>,
    pub sigma: Sigma,
}

impl Uncertainty {
    /// Standard uncertainty of each parameter (k = 1).
    pub fn u(&self) -> Vec<f64> {
        (0..self.covariance.nrows())
            .map(|i| self.covariance[(i, i)].max(0.0).sqrt())
            .collect()
    }

    /// The covariance of `f(θ)` from its Jacobian `g = ∂f/∂θ` (a row per quantity).
    pub fn propagate(&self, what: &str, g: &DMatrix<f64>) -> Result<Uncertainty, UncertaintyError> {
        let p = self.covariance.nrows();
        if g.ncols() != p {
            return Err(UncertaintyError::new(
                what,
                Problem::Shape {
                    matrix: "the Jacobian of the derived quantities",
                    expected: (g.nrows(), p),
                    got: (g.nrows(), g.ncols()),
                },
            ));
        }
        check_finite(what, "the Jacobian of the derived quantities", g)?;
        Ok(Uncertainty {
            covariance: g * &self.covariance * g.transpose(),
            sigma: self.sigma,
        })
    }
}

/// What was wrong, in [`UncertaintyError`].
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum Problem {
    /// A matrix of the wrong size: (rows, columns).
    Shape {
        matrix: &'static str,
        expected: (usize, usize),
        got: (usize, usize),
    },
    /// A value at (row, column) of `matrix` is not finite.
    NotFinite {
        matrix: &'static str,
        row: usize,
        col: usize,
    },
    /// Fewer residuals than parameters.
    TooFewObservations { residuals: usize, parameters: usize },
    /// These parameter columns (0-based) are not determined by the observations.
    Undetermined(Vec<usize>),
    /// The repeatability is negative or not finite.
    Repeatability(f64),
    /// The inputs do not belong together (what does not match).
    Inconsistent(&'static str),
}

/// Where the uncertainty of a fit could not be computed, and why.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("uncertainty of {what}: {}", describe(problem))]
pub struct UncertaintyError {
    pub what: String,
    pub problem: Problem,
}

impl UncertaintyError {
    pub fn new(what: &str, problem: Problem) -> Self {
        Self {
            what: what.to_string(),
            problem,
        }
    }
}

fn describe(p: &Problem) -> String {
    match p {
        Problem::Shape {
            matrix,
            expected,
            got,
        } => format!(
            "{matrix} is {}x{}, {}x{} expected",
            got.0, got.1, expected.0, expected.1
        ),
        Problem::NotFinite { matrix, row, col } => {
            format!("{matrix} is not finite at row {row}, column {col}")
        }
        Problem::TooFewObservations {
            residuals,
            parameters,
        } => format!("{residuals} residual(s) cannot determine {parameters} parameter(s)"),
        Problem::Undetermined(cols) => format!(
            "the observations do not determine parameter(s) {} (columns of the Jacobian, from 0)",
            cols.iter()
                .map(ToString::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        ),
        Problem::Repeatability(v) => {
            format!("the probe's repeatability {v} is not a finite length >= 0")
        }
        Problem::Inconsistent(what) => (*what).to_string(),
    }
}

fn check_finite(
    what: &str,
    matrix: &'static str,
    m: &DMatrix<f64>,
) -> Result<(), UncertaintyError> {
    for c in 0..m.ncols() {
        for r in 0..m.nrows() {
            if !m[(r, c)].is_finite() {
                return Err(UncertaintyError::new(
                    what,
                    Problem::NotFinite {
                        matrix,
                        row: r,
                        col: c,
                    },
                ));
            }
        }
    }
    Ok(())
}

/// The covariance of a fit's parameters, `σ² (JᵀJ)⁻¹` (or the sandwich with `Ω`),
/// with `σ` from its residuals and the repeatability as the floor (module doc).
pub fn fit_uncertainty(fit: &Fit) -> Result<Uncertainty, UncertaintyError> {
    let what = fit.what;
    let j = fit.jacobian;
    let (n, p) = (j.nrows(), j.ncols());
    let err = |problem| Err(UncertaintyError::new(what, problem));
    if !(fit.repeatability.is_finite() && fit.repeatability >= 0.0) {
        return err(Problem::Repeatability(fit.repeatability));
    }
    if fit.residuals.len() != n {
        return err(Problem::Shape {
            matrix: "the residual vector",
            expected: (n, 1),
            got: (fit.residuals.len(), 1),
        });
    }
    if n < p {
        return err(Problem::TooFewObservations {
            residuals: n,
            parameters: p,
        });
    }
    check_finite(what, "the Jacobian", j)?;
    let r = DVector::from_column_slice(fit.residuals);
    check_finite(
        what,
        "the residual vector",
        &DMatrix::from_column_slice(n, 1, r.as_slice()),
    )?;
    if let Some(omega) = fit.residual_covariance {
        if omega.shape() != (n, n) {
            return err(Problem::Shape {
                matrix: "the residual covariance",
                expected: (n, n),
                got: omega.shape(),
            });
        }
        check_finite(what, "the residual covariance", omega)?;
    }
    // Columns scaled to unit length: parameters of different units (mm, deg) alike.
    let norms: Vec<f64> = (0..p).map(|c| j.column(c).norm()).collect();
    let largest = norms.iter().copied().fold(0.0, f64::max);
    let zero: Vec<usize> = (0..p)
        .filter(|&c| norms[c] <= 1e-300 || norms[c] <= 1e-14 * largest)
        .collect();
    if !zero.is_empty() {
        return err(Problem::Undetermined(zero));
    }
    let mut scaled = j.clone();
    for (c, norm) in norms.iter().enumerate() {
        scaled.column_mut(c).unscale_mut(*norm);
    }
    let svd = scaled.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        unreachable!("the SVD was asked for U and Vᵀ")
    };
    let s = &svd.singular_values;
    let s_max = s.max();
    if p > 0 {
        let bad: Vec<usize> = (0..p)
            .filter(|&k| s[k] <= RANK_TOLERANCE * s_max)
            .flat_map(|k| {
                let v_t = &v_t;
                (0..p).filter(move |&c| v_t[(k, c)].abs() > 0.1)
            })
            .collect();
        if !bad.is_empty() {
            let mut bad = bad;
            bad.sort_unstable();
            bad.dedup();
            return err(Problem::Undetermined(bad));
        }
    }
    // (JᵀJ)⁻¹Jᵀ = D⁻¹ V S⁻¹ Uᵀ.
    let mut m = DMatrix::<f64>::zeros(p, n);
    for k in 0..p {
        let uk = u.column(k);
        for c in 0..p {
            let f = v_t[(k, c)] / (s[k] * norms[c]);
            for row in 0..n {
                m[(c, row)] += f * uk[row];
            }
        }
    }
    let residual = r.norm_squared();
    let (shape, expected) = match fit.residual_covariance {
        None => (&m * m.transpose(), (n - p) as f64),
        Some(omega) => {
            // tr((I − H)Ω) = tr(Ω) − |Uᵀ Ω^½ …|: with H = U Uᵀ, tr(HΩ) = tr(Uᵀ Ω U).
            let ut_omega_u = u.transpose() * omega * &u;
            (
                &m * omega * m.transpose(),
                omega.trace() - ut_omega_u.trace(),
            )
        }
    };
    let mut sum = ResidualSum {
        sum_squares: residual,
        dof: expected.max(0.0),
    };
    if let Some(extra) = fit.pooled {
        sum = sum.pooled(extra);
    }
    // Rounding leaves about 1e-12 of an exact fit's degrees of freedom.
    if sum.dof < 1e-9 {
        sum.dof = 0.0;
    }
    let sigma = sum.sigma(fit.repeatability);
    Ok(Uncertainty {
        covariance: shape * (sigma.value * sigma.value),
        sigma,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A straight line `y = a + b x` through `ys` at x = 0, 1, ...
    fn line(ys: &[f64]) -> (DMatrix<f64>, Vec<f64>) {
        let n = ys.len();
        let j = DMatrix::from_fn(n, 2, |r, c| if c == 0 { -1.0 } else { -(r as f64) });
        let jt = j.transpose();
        let theta = (&jt * &j).try_inverse().unwrap() * &jt * -DVector::from_column_slice(ys);
        let r: Vec<f64> = (0..n)
            .map(|i| ys[i] - theta[0] - theta[1] * i as f64)
            .collect();
        (j, r)
    }

    #[test]
    fn a_line_has_the_textbook_covariance() {
        // Residuals +-0.1: s^2 = 4 * 0.01 / 2; var(b) = s^2 / sum (x - mean)^2 = 0.02 / 5.
        let ys = [0.1, 0.9, 2.1, 2.9];
        let (j, r) = line(&ys);
        let u = fit_uncertainty(&Fit::new("a line", &j, &r, 0.0)).unwrap();
        let s2 = r.iter().map(|v| v * v).sum::<f64>() / 2.0;
        assert!((u.sigma.value - s2.sqrt()).abs() < 1e-12, "{:?}", u.sigma);
        assert!((u.u()[1] - (s2 / 5.0).sqrt()).abs() < 1e-12, "{:?}", u.u());
        // var(a) = s^2 (1/n + mean^2 / Sxx) = s^2 (1/4 + 2.25/5).
        assert!((u.u()[0] - (s2 * (0.25 + 2.25 / 5.0)).sqrt()).abs() < 1e-12);
        assert!(!u.sigma.floor_applied);
        assert_eq!(u.sigma.dof, 2.0);
    }

    #[test]
    fn few_degrees_of_freedom_take_the_repeatability_as_the_floor() {
        // A perfect line with 2 dof: s = 0, the floor 0.001 carries it.
        let (j, r) = line(&[0.0, 1.0, 2.0, 3.0]);
        let u = fit_uncertainty(&Fit::new("a line", &j, &r, 0.001)).unwrap();
        assert!(u.sigma.floor_applied);
        assert_eq!(u.sigma.value, 0.001);
        assert!((u.u()[1] - 0.001 / 5f64.sqrt()).abs() < 1e-15);
        // Exactly determined: no s at all.
        let (j, r) = line(&[0.0, 1.0]);
        let u = fit_uncertainty(&Fit::new("two points", &j, &r, 0.002)).unwrap();
        assert_eq!(u.sigma.residual, None);
        assert_eq!(u.sigma.value, 0.002);
        // Many degrees of freedom: the residuals rule, even below the floor.
        let ys: Vec<f64> = (0..20)
            .map(|i| i as f64 + if i % 2 == 0 { 1e-4 } else { -1e-4 })
            .collect();
        let (j, r) = line(&ys);
        let u = fit_uncertainty(&Fit::new("a long line", &j, &r, 0.001)).unwrap();
        assert!(
            !u.sigma.floor_applied && u.sigma.value < 2e-4,
            "{:?}",
            u.sigma
        );
    }

    #[test]
    fn correlated_residuals_use_the_sandwich() {
        // The mean of 3 values, its residuals with Omega = I: the sandwich equals the
        // plain form; with Omega = 4 I the variance and the expected sum scale alike,
        // so u stays (the residuals say how large sigma is).
        let j = DMatrix::from_element(3, 1, -1.0);
        let r = [0.1, -0.2, 0.1];
        let plain = fit_uncertainty(&Fit::new("a mean", &j, &r, 0.0)).unwrap();
        let omega = DMatrix::<f64>::identity(3, 3) * 4.0;
        let fit = Fit {
            residual_covariance: Some(&omega),
            ..Fit::new("a mean", &j, &r, 0.0)
        };
        let sandwich = fit_uncertainty(&fit).unwrap();
        assert!((plain.u()[0] - sandwich.u()[0]).abs() < 1e-15);
        assert!(
            (sandwich.sigma.dof - 8.0).abs() < 1e-12,
            "{:?}",
            sandwich.sigma
        );
        // Noise common to every residual moves the mean but leaves no trace in the
        // residuals: no degrees of freedom, tr((I - H) 11^T) = 0, the floor holds.
        let common = DMatrix::from_element(3, 3, 1.0);
        let fit = Fit {
            residual_covariance: Some(&common),
            ..Fit::new("a mean", &j, &r, 0.005)
        };
        let u = fit_uncertainty(&fit).unwrap();
        assert_eq!(u.sigma.dof, 0.0);
        assert!((u.u()[0] - 0.005).abs() < 1e-15);
    }

    #[test]
    fn pooled_sums_add_degrees_of_freedom() {
        let (j, r) = line(&[0.0, 1.0, 2.0]);
        let fit = Fit {
            pooled: Some(ResidualSum {
                sum_squares: 9.0 * 0.002f64.powi(2),
                dof: 9.0,
            }),
            ..Fit::new("a line", &j, &r, 0.001)
        };
        let u = fit_uncertainty(&fit).unwrap();
        assert!((u.sigma.dof - 10.0).abs() < 1e-12);
        assert!((u.sigma.value - (0.002f64.powi(2) * 0.9).sqrt()).abs() < 1e-12);
    }

    #[test]
    fn propagation_of_a_sum_and_a_difference() {
        let cov = DMatrix::from_row_slice(2, 2, &[4.0, 1.0, 1.0, 9.0]);
        let u = Uncertainty {
            covariance: cov,
            sigma: ResidualSum::default().sigma(1.0),
        };
        let g = DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 1.0, -1.0]);
        let d = u.propagate("sum and difference", &g).unwrap();
        assert_eq!(d.u(), vec![15f64.sqrt(), 11f64.sqrt()]);
        let e = u
            .propagate("a wrong Jacobian", &DMatrix::zeros(1, 3))
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "uncertainty of a wrong Jacobian: the Jacobian of the derived quantities is 1x3, 1x2 expected"
        );
    }

    #[test]
    fn errors_say_which_fit_and_where() {
        let (j, r) = line(&[0.0, 1.0, 2.0]);
        let e =
            fit_uncertainty(&Fit::new("the plane of block 12", &j, &r[..2], 0.001)).unwrap_err();
        assert_eq!(
            e.to_string(),
            "uncertainty of the plane of block 12: the residual vector is 2x1, 3x1 expected"
        );
        let mut bad = j.clone();
        bad[(2, 1)] = f64::NAN;
        let e = fit_uncertainty(&Fit::new("a line", &bad, &r, 0.001)).unwrap_err();
        assert_eq!(
            e.to_string(),
            "uncertainty of a line: the Jacobian is not finite at row 2, column 1"
        );
        // Two equal columns: neither is determined.
        let twin = DMatrix::from_fn(3, 3, |r, c| if c == 1 { r as f64 } else { -1.0 });
        let e = fit_uncertainty(&Fit::new("twins", &twin, &r, 0.001)).unwrap_err();
        assert_eq!(e.problem, Problem::Undetermined(vec![0, 2]), "{e}");
        assert!(
            e.to_string().contains("do not determine parameter(s) 0, 2"),
            "{e}"
        );
        let e = fit_uncertainty(&Fit::new("a line", &j, &r, -1.0)).unwrap_err();
        assert!(matches!(e.problem, Problem::Repeatability(_)), "{e}");
        let one = DMatrix::from_element(1, 2, 1.0);
        let e = fit_uncertainty(&Fit::new("one point", &one, &[0.0], 0.001)).unwrap_err();
        assert_eq!(
            e.to_string(),
            "uncertainty of one point: 1 residual(s) cannot determine 2 parameter(s)"
        );
    }
}
