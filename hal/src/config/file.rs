//! Reading a configuration file (machine, scenario, gateway): at most
//! [`MAX_CONFIG_BYTES`], UTF-8; and [`MachineConfig::load`], the machine file read,
//! parsed and validated.

use super::{ConfigError, MachineConfig};
use std::path::Path;

impl MachineConfig {
    /// Reads the machine file at `path`, then [`MachineConfig::parse`]s it.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = read_config_text(path).map_err(|source| ConfigError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(&text, path)
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
