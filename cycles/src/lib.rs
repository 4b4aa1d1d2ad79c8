//! probebridge-cycles: NC programs with HEIDENHAIN touch-probe cycles, their parameter
//! tables and validation, the cycles run over [`hal::Machine`], geometry fits, results
//! and protocols.
//!
//! - [`Program::parse`] / [`Program::load`] / [`parser::check_program`]: read and
//!   validate a program against a [`hal::config::MachineConfig`] (all errors, with
//!   lines);
//! - [`run_program`]: run its cycles ([`cycle431`], [`cycle444`], [`cycle451`], 450 in
//!   [`kinematics_file`]) and `L` positioning blocks ([`linear`]) over a machine;
//! - [`kinematics`]: cycle 451's kinematic model, measuring positions and ISO 230-7
//!   identification, and the [`kinematics::Estimator`] it runs in;
//! - [`ProgramReport`]: the results (JSON and text); [`protocol`]: TXT/HTML protocols;
//! - [`geometry`]: sphere and plane fits.

pub mod cycle431;
pub mod cycle444;
pub mod cycle451;
pub mod error;
pub mod geometry;
pub mod kinematics;
pub mod kinematics_file;
pub mod linear;
pub mod params;
pub mod parser;
pub mod plane;
mod positioning;
pub mod program;
pub mod protocol;
pub mod protocol451;
pub mod results;
pub mod runner;
pub mod tolerance;

pub use error::CycleError;
pub use geometry::{fit_plane, fit_sphere, FitError, PlaneFit, SphereFit};
pub use parser::{check_program, parse_program};
pub use program::{CycleCall, Diagnostic, Program, ProgramError, ProgramErrors};
pub use results::{CycleResult, ProgramReport, Status};
pub use runner::{run_program, ProgressEvent, RunOptions};
