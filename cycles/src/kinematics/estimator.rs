//! Where cycle 451's maths runs. The cycle measures; an [`Estimator`] fits the spheres
//! and solves the identification. [`LocalEstimator`] calls the maths in this process
//! (tests, fallback); the bridge's estimator process answers the same questions over
//! iceoryx2 with the contacts it received from the real-time loop under the run id of
//! each sphere measurement (see `Machine::set_run`).

use super::identification::{
    identify, IdentificationError, IdentificationInput, IdentificationResult,
};
use crate::geometry::sphere_fit::{fit_sphere, FitError, SphereFit};
use hal::Contact;
use nalgebra::Vector3;

#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum EstimatorError {
    #[error("{0}")]
    Fit(#[from] FitError),
    #[error("{0}")]
    Identification(#[from] IdentificationError),
    /// The estimator could not be asked or did not answer (IPC).
    #[error("estimator {estimator}: {message}")]
    Transport { estimator: String, message: String },
}

pub trait Estimator {
    /// Which estimator this is, for messages and the protocol.
    fn name(&self) -> String;

    /// The sphere through the X/Y/Z positions of the contacts of run `run_id` (the
    /// contacts are those the cycle received; an estimator process uses the samples it
    /// received for that run). Radius: artefact plus stylus ball.
    fn fit_sphere(
        &mut self,
        run_id: u64,
        contacts: &[Contact],
    ) -> Result<SphereFit, EstimatorError>;

    /// The ISO 230-7 identification of cycle 451.
    fn identify(
        &mut self,
        input: &IdentificationInput,
    ) -> Result<IdentificationResult, EstimatorError>;
}

/// The maths in this process.
#[derive(Clone, Copy, Debug, Default)]
pub struct LocalEstimator;

impl Estimator for LocalEstimator {
    fn name(&self) -> String {
        "in-process".into()
    }

    fn fit_sphere(
        &mut self,
        _run_id: u64,
        contacts: &[Contact],
    ) -> Result<SphereFit, EstimatorError> {
        let points: Vec<Vector3<f64>> = contacts
            .iter()
            .map(|c| Vector3::from(c.positions.xyz()))
            .collect();
        Ok(fit_sphere(&points)?)
    }

    fn identify(
        &mut self,
        input: &IdentificationInput,
    ) -> Result<IdentificationResult, EstimatorError> {
        Ok(identify(input)?)
    }
}
