//! The QS400 tolerance of cycle 444 and the workpiece status Q183.
//!
//! Grammar (whitespace ignored): `[sign]a` or `[sign]a(+|-)b`, a and b unsigned decimals.
//! One value: the limit on its side of the nominal, the other limit is the nominal
//! (`"0.4"`: +0.4/0; `"-0.1"`: 0/-0.1). Two values: the larger is the upper, the smaller
//! the lower limit (`"0.4-0.1"`: +0.4/-0.1; `"1-1"`: +1/-1). Empty, `"0"` and a band of
//! zero width such as `"0.1+0.1"` mean no tolerance (the seed's examples).

use serde::Serialize;
use std::fmt;

/// mm; far below any probe's resolution, far above f64 rounding of machine coordinates.
pub const ON_LIMIT: f64 = 1e-9;

/// Limits along the surface normal relative to the nominal point, mm.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Tolerance {
    pub upper: f64,
    pub lower: f64,
}

/// What is wrong with a QS400 text.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum ToleranceErrorKind {
    /// No number at the start.
    NoFirstLimit,
    /// Something other than + or - between the two limits.
    NoSeparator,
    /// A sign without a number after it.
    NoSecondLimit,
    /// Text after the second limit.
    TrailingText,
}

impl ToleranceErrorKind {
    fn why(self) -> &'static str {
        match self {
            Self::NoFirstLimit => "no number at the start",
            Self::NoSeparator => "expected + or - between the two limits",
            Self::NoSecondLimit => "no number after the sign",
            Self::TrailingText => "text after the second limit",
        }
    }
}

#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("QS400=\"{text}\": malformed tolerance ({}); expected e.g. \"0.4-0.1\", \"0.4\", \"-0.1\", \"1-1\" or \" \"", kind.why())]
pub struct ToleranceError {
    pub text: String,
    pub kind: ToleranceErrorKind,
}

impl ToleranceError {
    pub fn kind(&self) -> ToleranceErrorKind {
        self.kind
    }
}

impl Tolerance {
    /// Parses QS400; `Ok(None)` is "no tolerance".
    pub fn parse(text: &str) -> Result<Option<Tolerance>, ToleranceError> {
        use ToleranceErrorKind as K;
        let err = |kind| ToleranceError {
            text: text.to_string(),
            kind,
        };
        let s: String = text.chars().filter(|c| !c.is_whitespace()).collect();
        if s.is_empty() {
            return Ok(None);
        }
        let (first_sign, rest) = split_sign(&s);
        let (a, rest) = split_number(rest).ok_or_else(|| err(K::NoFirstLimit))?;
        let a = first_sign * a;
        let (upper, lower) = if rest.is_empty() {
            (a.max(0.0), a.min(0.0))
        } else {
            let (sign, tail) = split_sign(rest);
            if tail.len() == rest.len() {
                return Err(err(K::NoSeparator));
            }
            let (b, tail) = split_number(tail).ok_or_else(|| err(K::NoSecondLimit))?;
            if !tail.is_empty() {
                return Err(err(K::TrailingText));
            }
            let b = sign * b;
            (a.max(b), a.min(b))
        };
        if upper == lower {
            return Ok(None);
        }
        Ok(Some(Tolerance { upper, lower }))
    }

    /// Both limits times `factor` (inch programs).
    pub fn scaled(self, factor: f64) -> Tolerance {
        Tolerance {
            upper: self.upper * factor,
            lower: self.lower * factor,
        }
    }

    /// Status of a deviation along the normal (Q164). Limits are inclusive; a
    /// deviation within [`ON_LIMIT`] of a limit counts as on it, so that the rounding
    /// of C - R*n does not turn a point on the limit into rework or scrap.
    pub fn status(&self, deviation: f64) -> WorkpieceStatus {
        if deviation > self.upper + ON_LIMIT {
            WorkpieceStatus::Rework
        } else if deviation < self.lower - ON_LIMIT {
            WorkpieceStatus::Scrap
        } else {
            WorkpieceStatus::Good
        }
    }
}

fn split_sign(s: &str) -> (f64, &str) {
    match s.as_bytes().first() {
        Some(b'+') => (1.0, &s[1..]),
        Some(b'-') => (-1.0, &s[1..]),
        _ => (1.0, s),
    }
}

/// An unsigned decimal at the start of `s`: `12`, `12.`, `12.5`, `.5`.
fn split_number(s: &str) -> Option<(f64, &str)> {
    let end = s
        .char_indices()
        .find(|(_, c)| !(c.is_ascii_digit() || *c == '.'))
        .map_or(s.len(), |(i, _)| i);
    let digits = &s[..end];
    if digits.matches('.').count() > 1 || !digits.chars().any(|c| c.is_ascii_digit()) {
        return None;
    }
    Some((digits.parse().ok()?, &s[end..]))
}

/// Q183.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum WorkpieceStatus {
    /// No tolerance given.
    Undefined,
    Good,
    /// Material left (above the upper limit).
    Rework,
    /// Too much removed (below the lower limit).
    Scrap,
}

impl WorkpieceStatus {
    pub fn of(tolerance: Option<&Tolerance>, deviation: f64) -> Self {
        tolerance.map_or(WorkpieceStatus::Undefined, |t| t.status(deviation))
    }

    /// The Q183 value.
    pub fn q183(self) -> f64 {
        match self {
            WorkpieceStatus::Undefined => -1.0,
            WorkpieceStatus::Good => 0.0,
            WorkpieceStatus::Rework => 1.0,
            WorkpieceStatus::Scrap => 2.0,
        }
    }

    /// Protocol colour as the seed gives it.
    pub fn colour(self) -> &'static str {
        match self {
            WorkpieceStatus::Undefined => "black",
            WorkpieceStatus::Good => "green",
            WorkpieceStatus::Rework => "orange",
            WorkpieceStatus::Scrap => "red",
        }
    }
}

impl fmt::Display for WorkpieceStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            WorkpieceStatus::Undefined => "no tolerance",
            WorkpieceStatus::Good => "good",
            WorkpieceStatus::Rework => "rework",
            WorkpieceStatus::Scrap => "scrap",
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(s: &str) -> Option<(f64, f64)> {
        Tolerance::parse(s).unwrap().map(|t| (t.upper, t.lower))
    }

    #[test]
    fn every_example_of_the_seed() {
        assert_eq!(t("0.4-0.1"), Some((0.4, -0.1)));
        assert_eq!(t("0.4"), Some((0.4, 0.0)));
        assert_eq!(t("-0.1"), Some((0.0, -0.1)));
        assert_eq!(t("1-1"), Some((1.0, -1.0)));
        assert_eq!(t(" "), None);
        assert_eq!(t(""), None);
        assert_eq!(t("0"), None);
        assert_eq!(t("0.1+0.1"), None);
    }

    #[test]
    fn malformed_is_refused() {
        use ToleranceErrorKind as K;
        for (s, kind) in [
            ("abc", K::NoFirstLimit),
            ("0.4-", K::NoSecondLimit),
            ("1-2-3", K::TrailingText),
            ("0.4*0.1", K::NoSeparator),
            ("1..2", K::NoFirstLimit),
            ("-", K::NoFirstLimit),
        ] {
            assert_eq!(Tolerance::parse(s).unwrap_err().kind(), kind, "{s}");
        }
    }
}
