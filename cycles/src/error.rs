//! Why a cycle stopped while running (validation problems are
//! [`crate::diagnostic::Diagnostic`]s and never get this far).

use hal::ErrorKind;

/// What kind of problem stopped a cycle.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum CycleErrorKind {
    /// The machine refused or failed a move (its own kind).
    Machine(ErrorKind),
    Geometry,
    Plan,
    MeasuringLog,
}

#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CycleError {
    /// The machine refused or failed a move or a probing move.
    #[error("{step}: {message}")]
    Machine {
        step: String,
        kind: ErrorKind,
        message: String,
    },
    /// The measurement does not give a result (collinear points, ...).
    #[error("{0}")]
    Geometry(String),
    /// The cycle cannot run with this program and machine (nothing moved).
    #[error("{0}")]
    Plan(String),
    /// Writing a measuring log failed.
    #[error("protocol {path}: {message}")]
    MeasuringLog { path: String, message: String },
}

impl CycleError {
    pub fn machine<E: hal::machine::Error>(step: impl Into<String>, e: &E) -> Self {
        CycleError::Machine {
            step: step.into(),
            kind: e.kind(),
            message: e.to_string(),
        }
    }

    pub fn kind(&self) -> CycleErrorKind {
        match self {
            CycleError::Machine { kind, .. } => CycleErrorKind::Machine(*kind),
            CycleError::Geometry(_) => CycleErrorKind::Geometry,
            CycleError::Plan(_) => CycleErrorKind::Plan,
            CycleError::MeasuringLog { .. } => CycleErrorKind::MeasuringLog,
        }
    }
}
