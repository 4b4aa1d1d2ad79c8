//! Reading a configuration file (machine, scenario, gateway): at most
//! [`MAX_CONFIG_BYTES`], UTF-8; and the errors a configuration file gives.

use std::path::{Path, PathBuf};

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

/// The largest configuration file read (bytes): a machine, scenario or gateway file is
/// a few kB; more is the wrong file (`/dev/zero`, a log), refused at once instead of
/// read forever.
pub const MAX_CONFIG_BYTES: u64 = 1 << 20;

/// Reads a configuration file as text: at most [`MAX_CONFIG_BYTES`], UTF-8.
pub fn read_config_text(path: &Path) -> std::io::Result<String> {
    use std::io::Read;
    let mut bytes = Vec::new();
    std::fs::File::open(path)?
        .take(MAX_CONFIG_BYTES + 1)
        .read_to_end(&mut bytes)?;
    if bytes.len() as u64 > MAX_CONFIG_BYTES {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("larger than {MAX_CONFIG_BYTES} bytes: not a configuration file"),
        ));
    }
    String::from_utf8(bytes).map_err(|e| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("not UTF-8 text (byte {})", e.utf8_error().valid_up_to()),
        )
    })
}
