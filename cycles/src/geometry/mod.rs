//! Small least-squares fits on measured points (nalgebra fixed-size types).

pub mod plane_fit;
pub mod sphere_fit;

pub use plane_fit::{fit_plane, PlaneFit, PlaneFitError};
pub use sphere_fit::{fit_sphere, FitError, SphereFit};
