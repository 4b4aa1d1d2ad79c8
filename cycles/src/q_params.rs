//! The TNC's Q parameters: `Q` (global), `QL` (local to the program), `QR` (remanent:
//! kept with the machine's state across runs and restarts, in a file beside the preset
//! table) and `QS` (strings). [`QParams`] holds the values of one run; the measuring
//! cycles write their results into it, the program's formulas read and write it.

use hal::atomic_write::{write_atomic, WriteError};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};
use std::fmt;
use std::path::{Path, PathBuf};

/// The four kinds of parameter, with the TNC's numbering ranges.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum QKind {
    Q,
    QL,
    QR,
    QS,
}

impl QKind {
    pub fn prefix(self) -> &'static str {
        match self {
            QKind::Q => "Q",
            QKind::QL => "QL",
            QKind::QR => "QR",
            QKind::QS => "QS",
        }
    }

    /// The highest number of the kind (the TNC's: Q0..Q1999, QL0..QL499, QR0..QR499,
    /// QS0..QS1999).
    pub fn max(self) -> u32 {
        match self {
            QKind::Q | QKind::QS => 1999,
            QKind::QL | QKind::QR => 499,
        }
    }
}

/// A parameter name: `Q141`, `QL0`, `QR5`, `QS146`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct QName {
    pub kind: QKind,
    pub number: u32,
}

impl fmt::Display for QName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}{}", self.kind.prefix(), self.number)
    }
}

impl QName {
    pub fn new(kind: QKind, number: u32) -> Self {
        Self { kind, number }
    }

    pub fn is_text(self) -> bool {
        self.kind == QKind::QS
    }

    /// A name at the start of `s` (case-insensitive) and the bytes it takes; `Err` when
    /// it looks like a parameter but its number is out of the kind's range.
    pub fn parse_prefix(s: &str) -> Option<Result<(QName, usize), String>> {
        let b = s.as_bytes();
        if b.first().map(u8::to_ascii_uppercase) != Some(b'Q') {
            return None;
        }
        let (kind, mut i) = match b.get(1).map(u8::to_ascii_uppercase) {
            Some(b'L') => (QKind::QL, 2),
            Some(b'R') => (QKind::QR, 2),
            Some(b'S') => (QKind::QS, 2),
            _ => (QKind::Q, 1),
        };
        let start = i;
        while b.get(i).is_some_and(u8::is_ascii_digit) {
            i += 1;
        }
        if i == start {
            return None;
        }
        // `Q1A` is no name.
        if b.get(i)
            .is_some_and(|c| c.is_ascii_alphanumeric() || *c == b'_')
        {
            return None;
        }
        let digits = &s[start..i];
        Some(match digits.parse::<u32>() {
            Ok(n) if n <= kind.max() => Ok((QName::new(kind, n), i)),
            _ => Err(format!(
                "{}{digits}: no such parameter ({}0..{}{})",
                kind.prefix(),
                kind.prefix(),
                kind.prefix(),
                kind.max()
            )),
        })
    }

    /// The whole of `s` as a name.
    pub fn parse(s: &str) -> Option<QName> {
        match QName::parse_prefix(s.trim())? {
            Ok((n, len)) if len == s.trim().len() => Some(n),
            _ => None,
        }
    }
}

/// A parameter's value: a number (mm, deg, or none) or a string (QS).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum QValue {
    Number(f64),
    Text(String),
}

impl fmt::Display for QValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            QValue::Number(v) => write!(f, "{v:+.4}"),
            QValue::Text(t) => write!(f, "\"{t}\""),
        }
    }
}

/// The longest string a QS parameter holds (the TNC's).
pub const MAX_TEXT: usize = 255;

/// The parameters of one run: every value, and which ones this run wrote.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct QParams {
    values: BTreeMap<QName, QValue>,
    written: BTreeSet<QName>,
    /// `check` only: set by a measuring cycle, known when the program runs.
    measured: BTreeSet<QName>,
    /// `check` only: hold a length a cycle measured, in mm whatever the program's unit
    /// (its result, or a value computed from one: [`crate::program_flow`]).
    in_mm: BTreeSet<QName>,
}

impl QParams {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn get(&self, name: QName) -> Option<&QValue> {
        self.values.get(&name)
    }

    /// Sets `name` (this run wrote it).
    pub fn set(&mut self, name: QName, value: QValue) {
        self.measured.remove(&name);
        self.in_mm.remove(&name);
        self.values.insert(name, value);
        self.written.insert(name);
    }

    /// `check`: `name` will hold a measured result (or a value computed from one).
    pub fn mark_measured(&mut self, name: QName) {
        self.values.remove(&name);
        self.in_mm.remove(&name);
        self.measured.insert(name);
    }

    /// `check`: `name` holds a length measured in mm (set after its value).
    pub fn mark_mm(&mut self, name: QName) {
        self.in_mm.insert(name);
    }

    /// Whether `name` holds a length measured in mm ([`QParams::mark_mm`]).
    pub fn is_mm(&self, name: QName) -> bool {
        self.in_mm.contains(&name)
    }

    pub fn is_measured(&self, name: QName) -> bool {
        self.measured.contains(&name)
    }

    /// Sets `name` without counting it as written by the run (remanent values read at
    /// the start).
    pub fn preset(&mut self, name: QName, value: QValue) {
        self.values.insert(name, value);
    }

    /// The results a cycle reports (`"Q141"`, `"QS146"`), as parameters.
    pub fn set_results(&mut self, q: &BTreeMap<String, f64>, qs: &BTreeMap<String, String>) {
        for (k, v) in q {
            if let Some(n) = QName::parse(k) {
                self.set(n, QValue::Number(*v));
            }
        }
        for (k, v) in qs {
            if let Some(n) = QName::parse(k) {
                self.set(n, QValue::Text(v.clone()));
            }
        }
    }

    /// Every parameter this run wrote, by name, with its final value.
    pub fn written(&self) -> BTreeMap<String, QValue> {
        self.written
            .iter()
            .filter_map(|n| Some((n.to_string(), self.values.get(n)?.clone())))
            .collect()
    }

    /// The QR values (to be kept).
    pub fn remanent(&self) -> BTreeMap<String, QValue> {
        self.values
            .iter()
            .filter(|(n, _)| n.kind == QKind::QR)
            .map(|(n, v)| (n.to_string(), v.clone()))
            .collect()
    }

    /// Whether this run wrote a QR parameter.
    pub fn remanent_written(&self) -> bool {
        self.written.iter().any(|n| n.kind == QKind::QR)
    }
}

/// The parameters a cycle writes when it succeeds (what the program may read after
/// it): cycle 451 Q141..Q149 and QS144..QS146, 431 Q158, Q159, Q170..Q175, 444
/// Q151..Q153, Q161..Q164, Q183; 450 none.
pub fn results_of(cycle: u16) -> Vec<QName> {
    let q = |n| QName::new(QKind::Q, n);
    match cycle {
        451 => (141..=149)
            .map(q)
            .chain((144..=146).map(|n| QName::new(QKind::QS, n)))
            .collect(),
        431 => [158, 159].into_iter().chain(170..=175).map(q).collect(),
        444 => (151..=153).chain(161..=164).chain([183]).map(q).collect(),
        _ => Vec::new(),
    }
}

/// The results of a cycle that are lengths: in mm whatever the program's unit (the
/// seeds: the control logs and reports the measuring results in mm only). 451
/// Q147..Q149, 431 Q173..Q175, 444 Q151..Q153 and Q161..Q164; the angles, counts and
/// statuses are not lengths.
pub fn length_results_of(cycle: u16) -> Vec<QName> {
    let q = |n| QName::new(QKind::Q, n);
    match cycle {
        451 => (147..=149).map(q).collect(),
        431 => (173..=175).map(q).collect(),
        444 => (151..=153).chain(161..=164).map(q).collect(),
        _ => Vec::new(),
    }
}

/// The file of the remanent QR parameters, beside the preset table
/// (`<machine>.presets.toml` -> `<machine>.qr.toml`), so that it moves with the machine's
/// state.
pub fn remanent_path(preset_table: &Path) -> PathBuf {
    let name = preset_table
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let stem = name
        .strip_suffix(".presets.toml")
        .or_else(|| name.strip_suffix(".toml"))
        .unwrap_or(&name);
    preset_table.with_file_name(format!("{stem}.qr.toml"))
}

/// Why the QR file cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum RemanentError {
    #[error("cannot read the QR parameters {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("the QR parameters {path} are not valid: {reason}")]
    Invalid { path: PathBuf, reason: String },
    #[error("cannot write the QR parameters: {0}")]
    Write(#[from] WriteError),
}

/// Reads the QR values kept by earlier runs (none when the file does not exist).
pub fn load_remanent(path: &Path) -> Result<BTreeMap<QName, f64>, RemanentError> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(BTreeMap::new()),
        Err(source) => {
            return Err(RemanentError::Read {
                path: path.to_path_buf(),
                source,
            })
        }
    };
    let invalid = |reason: String| RemanentError::Invalid {
        path: path.to_path_buf(),
        reason,
    };
    let table: BTreeMap<String, f64> = toml::from_str(&text).map_err(|e| invalid(e.to_string()))?;
    let mut out = BTreeMap::new();
    for (k, v) in table {
        let name = QName::parse(&k)
            .filter(|n| n.kind == QKind::QR)
            .ok_or_else(|| invalid(format!("{k}: not a QR parameter (QR0..QR499)")))?;
        if !v.is_finite() {
            return Err(invalid(format!("{k} = {v}: not a finite number")));
        }
        out.insert(name, v);
    }
    Ok(out)
}

/// Writes the QR values atomically (`QR1 = 1.5`, one a line).
pub fn save_remanent(path: &Path, values: &BTreeMap<String, QValue>) -> Result<(), RemanentError> {
    let mut text = String::from("# QR parameters kept across runs (probebridge)\n");
    for (k, v) in values {
        if let QValue::Number(v) = v {
            text.push_str(&format!("{k} = {v:?}\n"));
        }
    }
    write_atomic(path, text.as_bytes())?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names() {
        assert_eq!(QName::parse("Q141"), Some(QName::new(QKind::Q, 141)));
        assert_eq!(QName::parse("ql0"), Some(QName::new(QKind::QL, 0)));
        assert_eq!(QName::parse("QR499"), Some(QName::new(QKind::QR, 499)));
        assert_eq!(
            QName::parse("QS146").map(|n| n.to_string()).as_deref(),
            Some("QS146")
        );
        for bad in ["Q", "QL", "Q1A", "QX1", "QR500", "Q2000", "1"] {
            assert_eq!(QName::parse(bad), None, "{bad}");
        }
        assert!(matches!(QName::parse_prefix("QR500 "), Some(Err(_))));
    }

    #[test]
    fn remanent_file_beside_the_preset_table() {
        assert_eq!(
            remanent_path(Path::new("/m/table-ac.presets.toml")),
            Path::new("/m/table-ac.qr.toml")
        );
        assert_eq!(
            remanent_path(Path::new("/s/p.toml")),
            Path::new("/s/p.qr.toml")
        );
    }
}
