//! Step 4: the ISO 230-7 identification of the measured sphere centres
//! ([`crate::kinematics::identification`]), by the estimator.

use super::measure::{arr, Measured, Sphere};
use super::plan::KinematicsPlan;
use crate::error::CycleError;
use crate::kinematics::error_uncertainty::{error_uncertainty, CentreNoise};
use crate::kinematics::identification::{
    AxisMeasurement, IdentificationInput, IdentificationResult, MeasuredPosition,
};
use crate::kinematics::model::{Angles, ErrorSet, KinematicModel};
use crate::kinematics::Estimator;
use crate::probe_axis::ProbeAxis;
use nalgebra::Vector3;
use std::collections::BTreeMap;

/// Mean angles, centre and radius of the spheres of one position (both approaches with
/// Q432, else the one).
pub(super) fn mean_of(spheres: &[Sphere]) -> (Angles, Vector3<f64>, f64) {
    let n = spheres.len() as f64;
    let mut a = [0.0; 3];
    let mut c = Vector3::zeros();
    let mut r = 0.0;
    for s in spheres {
        for (x, y) in a.iter_mut().zip(s.angles) {
            *x += y / n;
        }
        c += s.centre / n;
        r += s.radius / n;
    }
    (a, c, r)
}

/// What the estimator is given: per measured axis the mean centre of every position.
pub(super) fn input(
    plan: &KinematicsPlan,
    active: ErrorSet,
    measured: &Measured,
) -> IdentificationInput {
    IdentificationInput {
        chain: plan.chain.clone(),
        active,
        mode: plan.params.mode,
        axes: measured
            .iter()
            .map(|(gi, positions)| AxisMeasurement {
                axis: plan.axes[*gi].axis,
                positions: positions
                    .iter()
                    .map(|(_, s)| {
                        let (angles, c, _) = mean_of(s);
                        MeasuredPosition {
                            angles,
                            centre: arr(&c),
                        }
                    })
                    .collect(),
            })
            .collect(),
    }
}

/// Solves the identification in the estimator.
pub(super) fn identify(
    estimator: &mut dyn Estimator,
    input: &IdentificationInput,
) -> Result<IdentificationResult, CycleError> {
    estimator
        .identify(input)
        .map_err(|e| CycleError::Geometry(e.to_string()))
}

/// The standard uncertainty (k = 1) of every identified error, by slot: the probe's
/// scatter through each sphere fit (pole along the tool axis at the position's angles,
/// Q423 points around the equator) and the identification
/// ([`crate::kinematics::error_uncertainty`]).
pub(super) fn uncertainty(
    plan: &KinematicsPlan,
    model: &KinematicModel,
    (tool, repeatability): (ProbeAxis, f64),
    measured: &Measured,
    input: &IdentificationInput,
    result: &IdentificationResult,
) -> Result<BTreeMap<usize, f64>, CycleError> {
    let mut unit = Vector3::zeros();
    unit[tool.tool_index()] = 1.0;
    let noise: Vec<Vec<CentreNoise>> = measured
        .iter()
        .map(|(_, positions)| {
            positions
                .iter()
                .map(|(_, spheres)| {
                    let each: Vec<CentreNoise> = spheres
                        .iter()
                        .map(|s| {
                            let n = model.tool_vector(&s.angles, unit);
                            CentreNoise::pole_and_equator(n, plan.params.points, s.record.rms)
                        })
                        .collect();
                    CentreNoise::mean(&each)
                })
                .collect()
        })
        .collect();
    error_uncertainty(input, result, &noise, repeatability)
        .map_err(|e| CycleError::Geometry(e.to_string()))
}
