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

/// The first non-finite number in the `Debug` form of an accepted value (strings
/// skipped): a number that is not one must be refused where it enters.
pub(crate) fn non_finite(v: &impl std::fmt::Debug) -> Option<String> {
    let debug = format!("{v:?}");
    let mut quoted = false;
    let mut escaped = false;
    let mut start = 0;
    for (i, c) in debug.char_indices().chain([(debug.len(), ' ')]) {
        if quoted {
            match (escaped, c) {
                (false, '\\') => escaped = true,
                (false, '"') => quoted = false,
                _ => escaped = false,
            }
            start = i + c.len_utf8();
            continue;
        }
        if c.is_ascii_alphanumeric() || c == '_' {
            continue;
        }
        if matches!(&debug[start..i], "NaN" | "inf") {
            let mut from = start.saturating_sub(120);
            while !debug.is_char_boundary(from) {
                from -= 1;
            }
            return Some(debug[from..i].to_string());
        }
        quoted = c == '"';
        start = i + c.len_utf8();
    }
    None
}

/// Panics when `r` is accepted with a non-finite number; the message's first line
/// names the field (the identifier before the last `: ` of the context).
pub(crate) fn accepted_finite<T: std::fmt::Debug, E>(r: &Result<T, E>, what: &str) {
    if let Some(at) = r.as_ref().ok().and_then(non_finite) {
        let field = at
            .rsplit_once(": ")
            .map(|(before, _)| before)
            .and_then(|b| {
                b.rsplit(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                    .next()
            })
            .unwrap_or("?");
        panic!("{what} accepted with a non-finite number in field {field}\n...{at}");
    }
}
