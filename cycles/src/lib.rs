//! probebridge-cycles: NC programs with HEIDENHAIN touch-probe cycles, their parameter
//! tables and validation, the cycles run over [`hal::Machine`], geometry fits, results
//! and measuring logs.
//!
//! See `ARCHITECTURE.md#cycles` in the repository root.
//!
//! - [`Program::parse`] / [`Program::load`] / [`parser::check_program`]: read and
//!   validate a program against a machine's probe table and PREDEF values
//!   ([`cycles_config::CyclesConfig`]: hal's [`hal::config::MachineConfig`] with the
//!   [`probe_table`] and the cycles' [`machine_parameters`] of the same file; all
//!   errors, with lines);
//! - [`run_program`]: run its cycles ([`cycle431`], [`cycle444`], [`cycle450`],
//!   [`cycle451`], each a [`cycle::MeasuringCycle`] with its typed parameters) and `L`
//!   positioning blocks ([`linear`]) over a machine, reporting [`ProgressEvent`]s;
//! - [`kinematics`]: cycle 451's kinematic model, measuring positions and ISO 230-7
//!   identification ([`iso230_7`] names the errors), and the
//!   [`kinematics::Estimator`] it runs in;
//! - [`ProgramReport`]: the results (JSON and text); [`measuring_log`]: the TNC's
//!   measuring logs (TCHPR431.TXT, TCHPR444.html; TCHPRAUTO.html is
//!   [`cycle451::measuring_log`]);
//! - [`geometry`]: sphere and plane fits;
//! - Q-parameter programming: [`q_params`] (Q, QL, QR, QS), [`formula`] (expressions
//!   and string functions), [`flow_block`] and [`program_flow`] (labels, jumps,
//!   subprograms, FN 14).

pub mod check_walk;
pub mod confirmation;
pub mod cycle;
pub mod cycle431;
pub mod cycle444;
pub mod cycle450;
pub mod cycle451;
pub mod cycle460;
pub mod cycle_block;
pub mod cycles_config;
pub mod datum;
pub mod diagnostic;
pub mod error;
pub mod flow_block;
pub mod formula;
pub mod geometry;
pub mod iso230_7;
pub mod kinematics;
pub mod kinematics_file;
pub mod length_unit;
pub mod linear;
pub mod m_function;
pub mod machine_parameters;
pub mod machine_time;
pub mod measuring_log;
pub mod params;
pub mod parser;
pub mod plan;
pub mod plane;
pub mod planned_move;
mod positioning;
pub mod preset_table;
pub mod probe_axis;
pub mod probe_table;
pub mod program;
pub mod program_flow;
pub mod program_warnings;
pub mod progress;
pub mod q_params;
pub mod results;
pub mod runner;
pub mod tolerance;
pub mod uncertainty;

pub use cycles_config::CyclesConfig;
pub use diagnostic::{Diagnostic, ProgramErrors};
pub use error::CycleError;
pub use geometry::{fit_plane, fit_sphere, FitError, PlaneFit, SphereFit};
pub use parser::{check_program, parse_program};
pub use program::{CycleCall, Program, ProgramError};
pub use progress::ProgressEvent;
pub use results::{CycleResult, ProgramReport, Status};
pub use runner::{run_program, RunOptions};
