//! ISO 230-7 identification of cycle 451: from the sphere centres measured at the
//! measuring positions of each axis, the location errors that explain them best.
//!
//! # The problem (spec.md, "Cycle 451")
//!
//! Per measured axis `g` with positions `k = 0..m` (`k = 0` the 0 deg reference): the
//! sphere's table point follows from the reference, `p_g = table_point(a_0, c_0)`, and
//! the deviation at `k` is `d_k = c_k - predict(a_k, p_g)` ([`deviations`]; `d_0 = 0`).
//! Statistics of an axis: dispersion `sqrt(sum |d_k|^2 / m)` (reference counted in
//! `m`), maximum `max |d_k|`.
//!
//! The optimisation minimises `F(e) = sum_g sum_k |d_k(e)|^2` over the free errors `e`
//! (all measured axes together: an axis at a non-zero incidence angle carries the errors
//! of the others into their measurements), by Gauss-Newton with a central-difference
//! Jacobian; each linear step is a least-squares solve with faer (column-pivoted QR).
//! Before the first step the column-scaled Jacobian's singular values (faer SVD) show
//! whether the measurements determine every free error; if not, the error names them.
//!
//! Free errors by mode ([`Mode`]): 0 and 1 the position errors of the measured axes
//! (mode 0 only reports what mode 1 would give); 2 their orientation and position
//! errors (solved together, then the positions once more with the orientations fixed:
//! "first the orientations, then the positions"); 3 as 2, then every orientation error
//! of a measured axis about the direction of a rotary axis nearer the bed in its chain
//! (`E{j}0{k}`) moves into that axis's zero error (`E{j}0{j}`), and the remaining
//! orientation and the position errors are solved again with it fixed.

use super::model::{rotary_slot, Angles, ChainSpec, ErrorPart, ErrorSet, KinematicModel};
use faer::prelude::*;
use faer::Mat;
use hal::Axis;
use nalgebra::Vector3;

/// Q406.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// 0: measure and report; change nothing.
    Check,
    /// 1: optimise the position errors.
    Position,
    /// 2: optimise orientation, then position errors.
    PositionAndAngle,
    /// 3: as 2, with orientation errors moved into the machine datum.
    MachineDatum,
}

impl Mode {
    pub fn from_q406(v: f64) -> Option<Self> {
        Some(match v as i64 {
            0 => Mode::Check,
            1 => Mode::Position,
            2 => Mode::PositionAndAngle,
            3 => Mode::MachineDatum,
            _ => return None,
        })
    }

    pub fn q406(self) -> u8 {
        match self {
            Mode::Check => 0,
            Mode::Position => 1,
            Mode::PositionAndAngle => 2,
            Mode::MachineDatum => 3,
        }
    }

    pub fn describe(self) -> &'static str {
        match self {
            Mode::Check => "0 = check",
            Mode::Position => "1 = optimise position",
            Mode::PositionAndAngle => "2 = optimise orientation and position",
            Mode::MachineDatum => "3 = optimise machine datum, orientation and position",
        }
    }

    /// Whether the cycle writes its result into the kinematics.
    pub fn writes(self) -> bool {
        self != Mode::Check
    }
}

/// One measuring position: the rotary angles (latched) and the measured sphere centre
/// (fitted centre of the latched X/Y/Z positions of its contacts).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeasuredPosition {
    pub angles: Angles,
    pub centre: [f64; 3],
}

/// The positions of one measured axis; `positions[0]` is its 0 deg reference.
#[derive(Clone, Debug, PartialEq)]
pub struct AxisMeasurement {
    pub axis: Axis,
    pub positions: Vec<MeasuredPosition>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct IdentificationInput {
    pub chain: ChainSpec,
    /// The active kinematics (the model the measurement is compared with).
    pub active: ErrorSet,
    pub mode: Mode,
    pub axes: Vec<AxisMeasurement>,
}

/// Statistics of one measured axis before (active kinematics) and after optimisation.
#[derive(Clone, Debug, PartialEq)]
pub struct AxisStatistics {
    pub axis: Axis,
    pub dispersion_before: f64,
    pub max_before: f64,
    pub dispersion_after: f64,
    pub max_after: f64,
    /// `d_k` per position (reference first, always 0), mm.
    pub deviations_before: Vec<[f64; 3]>,
    pub deviations_after: Vec<[f64; 3]>,
}

/// An orientation error moved into the zero error of an axis nearer the bed (mode 3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DatumTransfer {
    /// Slot of the orientation error (`E{j}0{k}`).
    pub from: usize,
    /// Slot of the zero error (`E{j}0{j}`).
    pub to: usize,
    /// deg.
    pub value: f64,
}

#[derive(Clone, Debug, PartialEq)]
pub struct IdentificationResult {
    pub before: ErrorSet,
    pub after: ErrorSet,
    /// Slots that the optimisation could change (all its steps).
    pub free: Vec<usize>,
    pub axes: Vec<AxisStatistics>,
    pub transfers: Vec<DatumTransfer>,
    /// Gauss-Newton iterations, all steps.
    pub iterations: u32,
    /// `F` before and after, mm^2.
    pub objective_before: f64,
    pub objective_after: f64,
}

impl IdentificationResult {
    pub fn axis(&self, axis: Axis) -> Option<&AxisStatistics> {
        self.axes.iter().find(|a| a.axis == axis)
    }
}

/// Which solve of the optimisation failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Step {
    Positions,
    OrientationsAndPositions,
    PositionsWithOrientationsFixed,
    AfterMachineDatum,
}

impl Step {
    pub const ALL: [Step; 4] = [
        Step::Positions,
        Step::OrientationsAndPositions,
        Step::PositionsWithOrientationsFixed,
        Step::AfterMachineDatum,
    ];
}

impl core::fmt::Display for Step {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Step::Positions => "position errors",
            Step::OrientationsAndPositions => "orientation and position errors",
            Step::PositionsWithOrientationsFixed => "position errors, orientations fixed",
            Step::AfterMachineDatum => "orientation and position errors after the machine datum",
        })
    }
}

/// What is wrong with the measurement of one axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeasurementProblem {
    /// The axis is in neither chain of the machine.
    NotInChain,
    /// Fewer than the reference and one position.
    TooFewPositions(usize),
    /// Position `k` has a non-finite angle or centre.
    NotFinite(usize),
    /// The axis is measured twice.
    Duplicate,
}

#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum IdentificationError {
    #[error("identification: no axis was measured")]
    NoAxes,
    #[error("identification: axis {axis}: {}", describe_problem(*problem))]
    BadMeasurement {
        axis: Axis,
        problem: MeasurementProblem,
    },
    #[error(
        "identification ({step}): the measuring positions do not determine {}; measure more positions over a wider range, or a sphere farther from the axis",
        slot_names(names)
    )]
    Undetermined { step: Step, names: Vec<usize> },
    #[error(
        "identification (mode 3): none of the measured axes ({}) has a rotary axis nearer the machine bed in its chain, whose machine datum could take up its orientation error",
        axes.iter().map(|a| a.name()).collect::<Vec<_>>().join(", ")
    )]
    NoMachineDatum { axes: Vec<Axis> },
    #[error(
        "identification ({step}): Gauss-Newton did not converge in {iterations} iterations (last step {last_step:e}); check that the sphere is clamped and clean, and measure more positions over a wider range"
    )]
    NotConverged {
        step: Step,
        iterations: u32,
        last_step: f64,
    },
    #[error("identification ({step}): the least-squares solver failed (singular value decomposition did not converge)")]
    Solver { step: Step },
}

fn describe_problem(p: MeasurementProblem) -> String {
    match p {
        MeasurementProblem::NotInChain => "not in the machine's kinematic chain".into(),
        MeasurementProblem::TooFewPositions(n) => {
            format!("{n} position(s); the 0 deg reference and at least one more are needed")
        }
        MeasurementProblem::NotFinite(k) => format!("position {k} is not a finite number"),
        MeasurementProblem::Duplicate => "measured twice".into(),
    }
}

fn slot_names(slots: &[usize]) -> String {
    slots
        .iter()
        .map(|&i| ErrorSet::name(i))
        .collect::<Vec<_>>()
        .join(", ")
}

/// `d_k` of one axis under `model` (reference first, exactly 0).
pub fn deviations(model: &KinematicModel, m: &AxisMeasurement) -> Vec<Vector3<f64>> {
    let Some(r) = m.positions.first() else {
        return Vec::new();
    };
    let p = model.table_point(&r.angles, &Vector3::from(r.centre));
    let mut d: Vec<Vector3<f64>> = m
        .positions
        .iter()
        .map(|x| Vector3::from(x.centre) - model.predict(&x.angles, &p))
        .collect();
    d[0] = Vector3::zeros();
    d
}

/// (dispersion, maximum) of deviations (the reference first): `sqrt(sum |d|^2 / m)`,
/// `max |d|`. With one measuring position besides the reference (Q414 = 1) the seeds
/// say the dispersion cannot be computed and is that position's spatial error `|d_1|`
/// (the reference is no second point).
pub fn statistics(d: &[Vector3<f64>]) -> (f64, f64) {
    if d.is_empty() {
        return (0.0, 0.0);
    }
    let max = d.iter().map(|v| v.norm()).fold(0.0, f64::max);
    if d.len() == 2 {
        return (d[1].norm(), max);
    }
    let sum: f64 = d.iter().map(|v| v.norm_squared()).sum();
    ((sum / d.len() as f64).sqrt(), max)
}

/// `F(e)`: the sum of `|d_k|^2` over every measured axis, mm^2.
pub fn objective(input: &IdentificationInput, errors: &ErrorSet) -> f64 {
    residuals(input, errors).iter().map(|r| r * r).sum()
}

pub(crate) fn residuals(input: &IdentificationInput, errors: &ErrorSet) -> Vec<f64> {
    let model = KinematicModel::new(&input.chain, errors);
    let mut r = Vec::new();
    for g in &input.axes {
        for d in deviations(&model, g).iter().skip(1) {
            r.extend_from_slice(&[d.x, d.y, d.z]);
        }
    }
    r
}

/// Orientation errors `E{j}0{k}` of the measured axes `k` about a rotary axis `j`
/// nearer the bed in the chain, as (orientation slot, zero slot of `j`).
pub fn machine_datum_targets(chain: &ChainSpec, measured: &[Axis]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    for &k in measured {
        for j in chain.nearer_bed(k) {
            let name = format!("E{}0{}", j.name(), k.name());
            let Some(from) = ErrorSet::index_of(&name) else {
                continue;
            };
            if out.iter().any(|(f, _)| *f == from) {
                continue;
            }
            out.push((from, ErrorSet::index(j, ErrorPart::Zero)));
        }
    }
    out
}

const MAX_ITERATIONS: u32 = 50;
/// Converged when no free error changes by more than this (mm or deg).
const STEP_TOLERANCE: f64 = 1e-12;
/// Central-difference step of the Jacobian (mm or deg).
const JACOBIAN_STEP: f64 = 1e-4;
/// Smallest singular value, relative to the largest, of the column-scaled Jacobian
/// for which the measurements still determine every free error.
const RANK_TOLERANCE: f64 = 1e-7;
/// The same ratio once Gauss-Newton has not converged: a direction this weak lets
/// micrometres of noise move the errors without end (a sphere a few micrometres off
/// the axis line), so those errors are reported as undetermined, not as a solver fault.
const WEAK_RANK_TOLERANCE: f64 = 1e-4;

pub(crate) fn jacobian(
    input: &IdentificationInput,
    e: &ErrorSet,
    free: &[usize],
    rows: usize,
) -> Mat<f64> {
    let mut j = Mat::<f64>::zeros(rows, free.len());
    for (c, &slot) in free.iter().enumerate() {
        let mut plus = *e;
        plus.0[slot] += JACOBIAN_STEP;
        let mut minus = *e;
        minus.0[slot] -= JACOBIAN_STEP;
        let (rp, rm) = (residuals(input, &plus), residuals(input, &minus));
        for r in 0..rows {
            j[(r, c)] = (rp[r] - rm[r]) / (2.0 * JACOBIAN_STEP);
        }
    }
    j
}

/// Which free errors the Jacobian leaves undetermined (empty when it has full rank).
fn undetermined(
    j: &Mat<f64>,
    free: &[usize],
    step: Step,
    tolerance: f64,
) -> Result<Vec<usize>, IdentificationError> {
    let (rows, cols) = (j.nrows(), j.ncols());
    let norms: Vec<f64> = (0..cols)
        .map(|c| (0..rows).map(|r| j[(r, c)] * j[(r, c)]).sum::<f64>().sqrt())
        .collect();
    let largest = norms.iter().copied().fold(0.0, f64::max);
    let mut out: Vec<usize> = (0..cols)
        .filter(|&c| norms[c] <= 1e-12 * largest.max(1.0))
        .map(|c| free[c])
        .collect();
    if !out.is_empty() {
        return Ok(out);
    }
    if rows < cols {
        return Ok(free.to_vec());
    }
    let scaled = Mat::<f64>::from_fn(rows, cols, |r, c| j[(r, c)] / norms[c]);
    let svd = scaled
        .thin_svd()
        .map_err(|_| IdentificationError::Solver { step })?;
    let s = svd.S().column_vector();
    let (s_max, s_min) = (s[0], s[cols - 1]);
    if s_min > tolerance * s_max {
        return Ok(out);
    }
    // The errors that take part in the null direction(s).
    let v = svd.V();
    for c in 0..cols {
        let involved = (0..cols)
            .filter(|&k| s[k] <= tolerance * s_max)
            .any(|k| v[(c, k)].abs() > 0.1);
        if involved {
            out.push(free[c]);
        }
    }
    Ok(out)
}

/// Gauss-Newton over the `free` slots from `start`; returns the optimum and the
/// iterations taken.
pub fn solve(
    input: &IdentificationInput,
    start: &ErrorSet,
    free: &[usize],
    step: Step,
) -> Result<(ErrorSet, u32), IdentificationError> {
    let mut e = *start;
    if free.is_empty() {
        return Ok((e, 0));
    }
    let mut last_step = f64::INFINITY;
    for it in 0..MAX_ITERATIONS {
        let r = residuals(input, &e);
        let rows = r.len();
        let j = jacobian(input, &e, free, rows);
        if it == 0 {
            let bad = undetermined(&j, free, step, RANK_TOLERANCE)?;
            if !bad.is_empty() {
                return Err(IdentificationError::Undetermined { step, names: bad });
            }
        }
        let rhs = Mat::<f64>::from_fn(rows, 1, |i, _| -r[i]);
        let delta = j.col_piv_qr().solve_lstsq(&rhs);
        last_step = 0.0;
        for (c, &slot) in free.iter().enumerate() {
            let d = delta[(c, 0)];
            if !d.is_finite() {
                return Err(IdentificationError::Solver { step });
            }
            e.0[slot] += d;
            last_step = last_step.max(d.abs());
        }
        if last_step <= STEP_TOLERANCE {
            return Ok((e, it + 1));
        }
    }
    let rows = residuals(input, &e).len();
    let weak = undetermined(
        &jacobian(input, &e, free, rows),
        free,
        step,
        WEAK_RANK_TOLERANCE,
    )?;
    if !weak.is_empty() {
        return Err(IdentificationError::Undetermined { step, names: weak });
    }
    Err(IdentificationError::NotConverged {
        step,
        iterations: MAX_ITERATIONS,
        last_step,
    })
}

fn check_input(input: &IdentificationInput) -> Result<(), IdentificationError> {
    if input.axes.is_empty() {
        return Err(IdentificationError::NoAxes);
    }
    for (i, g) in input.axes.iter().enumerate() {
        let bad = |problem| IdentificationError::BadMeasurement {
            axis: g.axis,
            problem,
        };
        if rotary_slot(g.axis).is_none() || input.chain.side(g.axis).is_none() {
            return Err(bad(MeasurementProblem::NotInChain));
        }
        if input.axes[..i].iter().any(|h| h.axis == g.axis) {
            return Err(bad(MeasurementProblem::Duplicate));
        }
        if g.positions.len() < 2 {
            return Err(bad(MeasurementProblem::TooFewPositions(g.positions.len())));
        }
        if let Some(k) = g.positions.iter().position(|p| {
            !(p.angles.iter().all(|v| v.is_finite()) && p.centre.iter().all(|v| v.is_finite()))
        }) {
            return Err(bad(MeasurementProblem::NotFinite(k)));
        }
    }
    Ok(())
}

/// The identification of [`Mode`] on the measured centres; see the module doc.
pub fn identify(input: &IdentificationInput) -> Result<IdentificationResult, IdentificationError> {
    check_input(input)?;
    let measured: Vec<Axis> = input.axes.iter().map(|g| g.axis).collect();
    let slots = |parts: &[ErrorPart]| -> Vec<usize> {
        measured
            .iter()
            .flat_map(|&a| parts.iter().map(move |&p| ErrorSet::index(a, p)))
            .collect()
    };
    let positions = slots(&[ErrorPart::Position(0), ErrorPart::Position(1)]);
    let all = slots(&[
        ErrorPart::Position(0),
        ErrorPart::Position(1),
        ErrorPart::Orientation(0),
        ErrorPart::Orientation(1),
    ]);
    let before = input.active;
    let mut transfers = Vec::new();
    let mut free = positions.clone();
    let (after, iterations) = match input.mode {
        Mode::Check | Mode::Position => solve(input, &before, &positions, Step::Positions)?,
        Mode::PositionAndAngle | Mode::MachineDatum => {
            let targets = if input.mode == Mode::MachineDatum {
                let t = machine_datum_targets(&input.chain, &measured);
                if t.is_empty() {
                    return Err(IdentificationError::NoMachineDatum { axes: measured });
                }
                t
            } else {
                Vec::new()
            };
            free = all.clone();
            let (e1, n1) = solve(input, &before, &all, Step::OrientationsAndPositions)?;
            if targets.is_empty() {
                let (e2, n2) = solve(input, &e1, &positions, Step::PositionsWithOrientationsFixed)?;
                (e2, n1 + n2)
            } else {
                let mut e2 = e1;
                for &(from, to) in &targets {
                    let value = e2.0[from];
                    e2.0[to] += value;
                    e2.0[from] = 0.0;
                    transfers.push(DatumTransfer { from, to, value });
                    free.push(to);
                }
                let rest: Vec<usize> = all
                    .iter()
                    .copied()
                    .filter(|s| !targets.iter().any(|(f, _)| f == s))
                    .collect();
                let (e3, n2) = solve(input, &e2, &rest, Step::AfterMachineDatum)?;
                (e3, n1 + n2)
            }
        }
    };
    let m_before = KinematicModel::new(&input.chain, &before);
    let m_after = KinematicModel::new(&input.chain, &after);
    let arr = |v: &Vector3<f64>| [v.x, v.y, v.z];
    let axes = input
        .axes
        .iter()
        .map(|g| {
            let db = deviations(&m_before, g);
            let da = deviations(&m_after, g);
            let (dispersion_before, max_before) = statistics(&db);
            let (dispersion_after, max_after) = statistics(&da);
            AxisStatistics {
                axis: g.axis,
                dispersion_before,
                max_before,
                dispersion_after,
                max_after,
                deviations_before: db.iter().map(arr).collect(),
                deviations_after: da.iter().map(arr).collect(),
            }
        })
        .collect();
    Ok(IdentificationResult {
        before,
        after,
        free,
        axes,
        transfers,
        iterations,
        objective_before: objective(input, &before),
        objective_after: objective(input, &after),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chain_ac() -> ChainSpec {
        ChainSpec {
            table: vec![(Axis::A, [0.0; 3]), (Axis::C, [0.0; 3])],
            head: vec![],
        }
    }

    /// Centres a machine with `truth` shows, for a sphere at `p` (table).
    fn measure(
        chain: &ChainSpec,
        truth: &ErrorSet,
        axis: Axis,
        angles: &[f64],
        p: Vector3<f64>,
    ) -> AxisMeasurement {
        let m = KinematicModel::new(chain, truth);
        let slot = rotary_slot(axis).unwrap();
        let positions = std::iter::once(0.0)
            .chain(angles.iter().copied())
            .map(|a| {
                let mut ang = [0.0; 3];
                ang[slot] = a;
                let c = m.predict(&ang, &p);
                MeasuredPosition {
                    angles: ang,
                    centre: [c.x, c.y, c.z],
                }
            })
            .collect();
        AxisMeasurement { axis, positions }
    }

    fn truth() -> ErrorSet {
        let mut t = ErrorSet::default();
        for (n, v) in [
            ("EY0A", 0.011),
            ("EZ0A", -0.007),
            ("EB0A", 0.005),
            ("EC0A", -0.003),
            ("EX0C", 0.012),
            ("EY0C", -0.008),
            ("EA0C", 0.004),
            ("EB0C", -0.006),
        ] {
            t.0[ErrorSet::index_of(n).unwrap()] = v;
        }
        t
    }

    fn input(mode: Mode) -> IdentificationInput {
        let chain = chain_ac();
        let t = truth();
        let p = Vector3::new(50.0, -30.0, 80.0);
        IdentificationInput {
            axes: vec![
                measure(&chain, &t, Axis::A, &[-90.0, -30.0, 30.0, 90.0], p),
                measure(&chain, &t, Axis::C, &[90.0, 180.0, 270.0], p),
            ],
            chain,
            active: ErrorSet::default(),
            mode,
        }
    }

    #[test]
    fn mode_2_recovers_every_location_error() {
        let r = identify(&input(Mode::PositionAndAngle)).unwrap();
        let t = truth();
        for i in 0..ERROR_COUNT_LOC {
            assert!(
                (r.after.0[i] - t.0[i]).abs() < 1e-9,
                "{}: {} vs {}",
                ErrorSet::name(i),
                r.after.0[i],
                t.0[i]
            );
        }
        assert!(r.objective_after < 1e-18, "{}", r.objective_after);
        for a in &r.axes {
            assert!(
                a.dispersion_before > 1e-3 && a.dispersion_after < 1e-9,
                "{a:?}"
            );
        }
    }

    const ERROR_COUNT_LOC: usize = 15;

    #[test]
    fn mode_1_changes_positions_only() {
        let r = identify(&input(Mode::Position)).unwrap();
        for i in 0..ERROR_COUNT_LOC {
            let (_, part) = ErrorSet::describe(i);
            if !matches!(part, ErrorPart::Position(_)) {
                assert_eq!(r.after.0[i], r.before.0[i], "{}", ErrorSet::name(i));
            }
        }
        assert!(r.objective_after < r.objective_before);
    }

    #[test]
    fn mode_3_moves_the_tilt_of_c_about_x_into_the_zero_of_a() {
        let r = identify(&input(Mode::MachineDatum)).unwrap();
        assert_eq!(r.after.by_name("EA0C"), 0.0);
        assert!(
            (r.after.by_name("EA0A") - 0.004).abs() < 1e-7,
            "{:?}",
            r.after
        );
        assert!(r.objective_after < 1e-12, "{}", r.objective_after);
        assert_eq!(r.transfers.len(), 1);
        // B-head/C-table: no axis nearer the bed in either chain.
        let chain = ChainSpec {
            table: vec![(Axis::C, [0.0; 3])],
            head: vec![(Axis::B, [0.0, 0.0, 250.0])],
        };
        assert!(machine_datum_targets(&chain, &[Axis::B, Axis::C]).is_empty());
    }

    #[test]
    fn a_sphere_on_the_axis_does_not_determine_its_orientation() {
        // On the axis line a tilt of the axis looks like a shift of it.
        let chain = chain_ac();
        let p = Vector3::new(0.0, 0.0, 80.0);
        let inp = IdentificationInput {
            axes: vec![measure(&chain, &truth(), Axis::C, &[90.0, 180.0, 270.0], p)],
            chain,
            active: ErrorSet::default(),
            mode: Mode::PositionAndAngle,
        };
        let e = identify(&inp).unwrap_err();
        assert!(
            matches!(&e, IdentificationError::Undetermined { names, .. } if names.len() == 4),
            "{e}"
        );
        assert!(e.to_string().contains("EX0C, EY0C, EA0C, EB0C"), "{e}");
        // Positions alone are determined: the sphere circles the true axis.
        let inp = IdentificationInput {
            mode: Mode::Position,
            ..inp
        };
        let r = identify(&inp).unwrap();
        assert!((r.after.by_name("EX0C") - (0.012 + 80.0 * (-0.006f64).to_radians())).abs() < 1e-5);
    }

    #[test]
    fn a_sphere_microns_off_the_axis_with_noise_is_undetermined_not_a_solver_fault() {
        // Found by a separate generated check: head-b-table-c, the sphere on C, noise
        // 0.5 um; the first rank test passes (the noise puts the sphere off the axis
        // line) and Gauss-Newton wanders. The operator must hear what to change.
        let chain = chain_ac();
        let p = Vector3::new(0.002, -0.001, 66.3);
        let mut m = measure(&chain, &truth(), Axis::C, &[80.0, 160.0, 240.0], p);
        let noise = [0.4e-3, -0.5e-3, 0.3e-3, -0.2e-3, 0.5e-3, -0.4e-3];
        for (k, pos) in m.positions.iter_mut().enumerate() {
            for (i, c) in pos.centre.iter_mut().enumerate() {
                *c += noise[(3 * k + i) % noise.len()];
            }
        }
        let inp = IdentificationInput {
            axes: vec![m],
            chain,
            active: ErrorSet::default(),
            mode: Mode::PositionAndAngle,
        };
        let e = identify(&inp).unwrap_err();
        assert!(
            matches!(&e, IdentificationError::Undetermined { .. }),
            "{e}"
        );
        assert!(
            e.to_string().contains("a sphere farther from the axis"),
            "{e}"
        );
    }
}
