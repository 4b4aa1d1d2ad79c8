//! Step 5: the results of the identification per measured axis (dispersion, circle
//! radius, backlash, angular positioning error, errors before and after) and the
//! result parameters Q141..Q149, QS144..QS146.

use super::identify::mean_of;
use super::measure::{arr, axis_map, PositionSpheres};
use super::plan::{AxisPlan, KinematicsPlan};
use super::report::{AxisReport, PositionReport};
use crate::error::CycleError;
use crate::kinematics::identification::{
    AxisStatistics, IdentificationInput, IdentificationResult,
};
use crate::kinematics::model::rotary_slot;
use crate::kinematics::model::{Angles, KinematicModel};
use crate::kinematics::qs_string;
use hal::Axis;
use nalgebra::Vector3;
use std::collections::BTreeMap;

/// Backlash is not computed on a measuring circle smaller than this, mm.
pub const MIN_BACKLASH_RADIUS: f64 = 1.0;

/// Radius of the circle the measured centre describes about `axis` at `a` (mm), and
/// the unit tangent (direction of increasing angle) of that circle.
fn circle(model: &KinematicModel, axis: Axis, a: &Angles, p: &Vector3<f64>) -> (f64, Vector3<f64>) {
    let s = rotary_slot(axis).expect("rotary");
    let h = 1e-3;
    let (mut ap, mut am) = (*a, *a);
    ap[s] += h;
    am[s] -= h;
    let v = (model.predict(&ap, p) - model.predict(&am, p)) / (2.0 * h); // mm per deg
    let r = v.norm().to_degrees();
    let t = if v.norm() > 0.0 { v / v.norm() } else { v };
    (r, t)
}

/// What the evaluation of one axis needs.
pub(super) struct Evaluation<'a> {
    pub plan: &'a KinematicsPlan,
    /// The model with the active kinematics.
    pub model: &'a KinematicModel,
    pub input: &'a IdentificationInput,
    pub result: &'a IdentificationResult,
}

impl Evaluation<'_> {
    /// The report of the measured axis `ap`; notes why a backlash was not computed.
    pub fn axis_report(
        &self,
        ap: &AxisPlan,
        positions: &PositionSpheres,
        notes: &mut Vec<String>,
    ) -> Result<AxisReport, CycleError> {
        let (plan, result) = (self.plan, self.result);
        let st = result.axis(ap.axis).ok_or_else(|| {
            CycleError::Geometry(format!(
                "the estimator returned no statistics for {}",
                ap.axis
            ))
        })?;
        let reference = &self
            .input
            .axes
            .iter()
            .find(|g| g.axis == ap.axis)
            .expect("measured")
            .positions[0];
        let p_ref = self
            .model
            .table_point(&reference.angles, &Vector3::from(reference.centre));
        let (circle_radius, _) = circle(self.model, ap.axis, &reference.angles, &p_ref);
        let backlash = self.backlash(ap, positions, circle_radius, &p_ref, notes);
        // Angular positioning error after optimisation, per position.
        let model_after = KinematicModel::new(&plan.chain, &result.after);
        let p_after = model_after.table_point(&reference.angles, &Vector3::from(reference.centre));
        let errs: Vec<f64> = positions
            .iter()
            .zip(&st.deviations_after)
            .map(|((_, s), d)| {
                let (a, _, _) = mean_of(s);
                let (r, t) = circle(&model_after, ap.axis, &a, &p_after);
                if r > 0.0 {
                    (Vector3::from(*d).dot(&t) / r).to_degrees()
                } else {
                    0.0
                }
            })
            .collect();
        let n = errs.len().max(1) as f64;
        let mean = errs.iter().sum::<f64>() / n;
        let std = (errs.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
        Ok(AxisReport {
            axis: ap.axis.name().to_string(),
            start: ap.range.start,
            end: ap.range.end,
            points: ap.range.points,
            hirth: ap.hirth,
            pivot: plan
                .chain
                .table
                .iter()
                .chain(&plan.chain.head)
                .find(|(a, _)| *a == ap.axis)
                .map_or([0.0; 3], |(_, p)| *p),
            circle_radius,
            backlash,
            dispersion_before: st.dispersion_before,
            max_before: st.max_before,
            dispersion_after: st.dispersion_after,
            max_after: st.max_after,
            positioning_error_mean: mean,
            positioning_error_std: std,
            errors_before: result.before.to_map(&[ap.axis]),
            errors_after: result.after.to_map(&[ap.axis]),
            errors_u: BTreeMap::new(),
            positions: self.positions(positions, st),
        })
    }

    /// Mean backlash of an axis measured with Q432: the tangential difference of the
    /// two approaches over the circle radius, deg.
    fn backlash(
        &self,
        ap: &AxisPlan,
        positions: &PositionSpheres,
        circle_radius: f64,
        p_ref: &Vector3<f64>,
        notes: &mut Vec<String>,
    ) -> Option<f64> {
        if !self.plan.backlash_measured(ap) {
            return None;
        }
        if circle_radius < MIN_BACKLASH_RADIUS {
            notes.push(format!(
                "{}: measuring circle radius {circle_radius:.3} mm < {MIN_BACKLASH_RADIUS} mm: no backlash computed",
                ap.axis
            ));
            return None;
        }
        let mut sum = 0.0;
        for (_, spheres) in positions {
            let (a, _, _) = mean_of(spheres);
            let (above, below) = if self.plan.params.backlash > 0.0 {
                (&spheres[0], &spheres[1])
            } else {
                (&spheres[1], &spheres[0])
            };
            let (r, t) = circle(self.model, ap.axis, &a, p_ref);
            sum += (above.centre - below.centre).dot(&t) / r.to_radians();
        }
        Some(sum / positions.len() as f64)
    }

    fn positions(&self, positions: &PositionSpheres, st: &AxisStatistics) -> Vec<PositionReport> {
        positions
            .iter()
            .enumerate()
            .map(|(k, (is_ref, spheres))| {
                let (a, c, r) = mean_of(spheres);
                PositionReport {
                    reference: *is_ref,
                    angles: axis_map(&self.plan.present, &a),
                    centre: arr(&c),
                    radius: r,
                    deviation_before: st.deviations_before[k],
                    deviation_after: st.deviations_after[k],
                    measurements: spheres.iter().map(|s| s.record.clone()).collect(),
                }
            })
            .collect()
    }

    /// Q141..Q146 (dispersion before and after, -1 for an axis not measured),
    /// QS144..QS146 (the location errors after), Q147..Q149 (`offset`).
    pub fn results(
        &self,
        axes: &[AxisReport],
        offset: &Vector3<f64>,
    ) -> (BTreeMap<String, f64>, BTreeMap<String, String>) {
        let mut q = BTreeMap::new();
        let mut qs = BTreeMap::new();
        for (i, axis) in Axis::ROTARY.into_iter().enumerate() {
            let st = axes.iter().find(|a| a.axis == axis.name());
            q.insert(
                format!("Q{}", 141 + i),
                st.map_or(-1.0, |a| a.dispersion_before),
            );
            q.insert(
                format!("Q{}", 144 + i),
                st.map_or(-1.0, |a| a.dispersion_after),
            );
            let values = if st.is_some() {
                self.result.after.location(axis)
            } else {
                [-1.0; 4]
            };
            qs.insert(format!("QS{}", 144 + i), qs_string(values));
        }
        for (i, v) in offset.iter().enumerate() {
            q.insert(format!("Q{}", 147 + i), *v);
        }
        (q, qs)
    }

    /// The sphere centre at the (first) reference, machine X/Y/Z (Q147..Q149 relative to
    /// the preset).
    pub fn reference_ball(&self) -> Vector3<f64> {
        let first_ref = &self.input.axes[0].positions[0];
        self.model
            .ball_in_machine(&first_ref.angles, &Vector3::from(first_ref.centre))
    }
}
