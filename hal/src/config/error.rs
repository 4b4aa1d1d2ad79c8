//! The errors a configuration file gives (machine, scenario, gateway), apart from the
//! reading itself ([`super::file`]), so that what only uses a configuration's types
//! (the real-time loop) does not depend on a file reader.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("cannot read {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Parse { path: PathBuf, message: String },
    #[error("{path}: {key}: {message}")]
    Invalid {
        path: PathBuf,
        key: String,
        message: String,
    },
}

/// What kind of [`ConfigError`] (and of `sim`'s scenario errors, which wrap it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum ConfigErrorKind {
    /// The file could not be read.
    Read,
    /// Not TOML, or a key or value the format does not have.
    Parse,
    /// A value out of range or inconsistent with another.
    Invalid,
}

impl ConfigError {
    pub fn kind(&self) -> ConfigErrorKind {
        match self {
            ConfigError::Read { .. } => ConfigErrorKind::Read,
            ConfigError::Parse { .. } => ConfigErrorKind::Parse,
            ConfigError::Invalid { .. } => ConfigErrorKind::Invalid,
        }
    }
}
