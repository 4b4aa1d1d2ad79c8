//! The fuzz targets, one per parser or decoder (or family of small codecs).

mod canopen;
mod config;
mod frames;
mod modbus;
mod program;

use crate::driver::Target;

/// Every target, in the order `all` runs them.
pub fn all() -> Vec<Target> {
    let mut v = Vec::new();
    v.extend(program::targets());
    v.extend(config::targets());
    v.extend(canopen::targets());
    v.extend(modbus::targets());
    v
}

pub fn find(name: &str) -> Option<Target> {
    all().into_iter().find(|t| t.name == name)
}

/// Input bytes as text: invalid UTF-8 replaced (the parsers take `&str`; files are
/// read as UTF-8 and refused before parsing otherwise).
pub(crate) fn text(data: &[u8]) -> std::borrow::Cow<'_, str> {
    String::from_utf8_lossy(data)
}
