//! Why a cycle stopped while running (validation problems are
//! [`crate::diagnostic::Diagnostic`]s and never get this far).

use hal::ErrorKind;

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

    /// The machine error kind, if the machine caused it.
    pub fn kind(&self) -> Option<ErrorKind> {
        match self {
            CycleError::Machine { kind, .. } => Some(*kind),
            _ => None,
        }
    }
}
