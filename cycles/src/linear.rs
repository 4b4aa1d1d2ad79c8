//! Straight positioning blocks between the cycles, `L X+50 Y-30 Z+97.5 R0 FMAX`: the
//! runner moves there, so that a program can pre-position the probe (cycle 451 starts
//! over the calibration sphere). Absolute coordinates of X, Y, Z, A, B, C, relative to
//! the datum (preset plus shift), or with M91 to the machine datum, with M92 to the
//! machine's reference point; `R0`; `F<feed>`, `FMAX`, `FAUTO`; the other M functions
//! as [`crate::m_function`] classifies them (the parser refuses the rest). Anything
//! else in an `L` block (incremental `IX`, radius compensation `RL`/`RR`, polar or
//! circular moves) is refused before anything moves.

use crate::length_unit::LengthUnit;
use crate::m_function;
use hal::{Axis, AxisPositions};

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MoveFeed {
    /// Rapid (FMAX, FAUTO, or no feed given).
    Rapid,
    /// mm/min (deg/min for rotary-only moves).
    Feed(f64),
}

/// What the coordinates of an `L` block refer to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Coordinates {
    /// The active datum: preset plus datum shift (no M91/M92).
    Datum,
    /// M91: the machine datum (machine coordinates).
    Machine,
    /// M92: the machine's reference point (`[cycles] m92_reference`).
    Reference,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinearMove {
    pub target: AxisPositions,
    pub feed: MoveFeed,
    pub coordinates: Coordinates,
}

impl LinearMove {
    /// The target in machine coordinates: through the datum, or as M91/M92 say (M92's
    /// point shifts X/Y/Z; rotary axes are machine angles with both).
    pub fn machine_target(
        &self,
        datum: &crate::datum::Datum,
        m92_reference: Option<[f64; 3]>,
    ) -> Result<AxisPositions, LinearBlockError> {
        match self.coordinates {
            Coordinates::Datum => Ok(datum.to_machine(&self.target)),
            Coordinates::Machine => Ok(self.target),
            Coordinates::Reference => {
                let Some(r) = m92_reference else {
                    return Err(LinearBlockError::new(
                        LinearBlockErrorKind::MFunction,
                        "L block: M92: the machine configuration names no reference point ([cycles] m92_reference)",
                    ));
                };
                let mut m = self.target;
                for (i, axis) in Axis::LINEAR.into_iter().enumerate() {
                    if let Some(v) = m.get(axis) {
                        m.set(axis, v + r[i]);
                    }
                }
                Ok(m)
            }
        }
    }
}

/// Why an `L` block cannot run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum LinearBlockErrorKind {
    /// `F` without a number > 0.
    Feed,
    /// A word that cannot run here (`IX`, `RL`, polar, ...).
    UnsupportedWord,
    /// An axis word without a number.
    Coordinate,
    /// The same axis twice.
    AxisTwice,
    /// No axis at all.
    NoCoordinate,
    /// A target outside the axis's software limits.
    SoftwareLimit,
    /// An M function that is refused ([`crate::m_function`]).
    MFunction,
}

/// An `L` block that cannot run; the message names the word.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{message}")]
pub struct LinearBlockError {
    kind: LinearBlockErrorKind,
    message: String,
}

impl LinearBlockError {
    pub(crate) fn new(kind: LinearBlockErrorKind, message: impl Into<String>) -> Self {
        Self {
            kind,
            message: message.into(),
        }
    }

    pub fn kind(&self) -> LinearBlockErrorKind {
        self.kind
    }
}

fn number(s: &str) -> Option<f64> {
    let v: f64 = s.parse().ok()?;
    v.is_finite().then_some(v)
}

/// `None` when `code` is not an `L` block; otherwise the move or why it cannot run.
pub fn parse_linear(code: &str, unit: LengthUnit) -> Option<Result<LinearMove, LinearBlockError>> {
    use LinearBlockErrorKind as K;
    let mut words = code.split_whitespace();
    if !words.next()?.eq_ignore_ascii_case("L") {
        return None;
    }
    let inch = unit == LengthUnit::Inch;
    let mut target = AxisPositions::new();
    let mut feed = MoveFeed::Rapid;
    let mut coordinates = Coordinates::Datum;
    for w in words {
        let u = w.to_ascii_uppercase();
        if u == "R0" || u == "FMAX" || u == "FAUTO" {
            continue;
        }
        if m_function::m_number(&u).is_some() {
            // M92 is checked against the machine where its point is known.
            match m_function::check_words(&u, true) {
                Ok(m) if m.m91 => coordinates = Coordinates::Machine,
                Ok(m) if m.m92 => coordinates = Coordinates::Reference,
                Ok(_) => {}
                Err(e) => {
                    return Some(Err(LinearBlockError::new(
                        K::MFunction,
                        format!("L block: {e}"),
                    )))
                }
            }
            continue;
        }
        if let Some(rest) = u.strip_prefix('F') {
            match number(rest) {
                Some(f) if f > 0.0 => {
                    feed = MoveFeed::Feed(if inch { f * 2.54 } else { f });
                    continue;
                }
                _ => {
                    return Some(Err(LinearBlockError::new(
                        K::Feed,
                        format!("L block: {w}: the feed must be a number > 0"),
                    )))
                }
            }
        }
        let Some(axis) = u.get(..1).and_then(Axis::from_name) else {
            return Some(Err(LinearBlockError::new(
                K::UnsupportedWord,
                format!("L block: {w}: only absolute X/Y/Z/A/B/C, R0, F and M words can run here"),
            )));
        };
        let Some(v) = number(&u[1..]) else {
            return Some(Err(LinearBlockError::new(
                K::Coordinate,
                format!("L block: {w}: not a coordinate"),
            )));
        };
        if target.contains(axis) {
            return Some(Err(LinearBlockError::new(
                K::AxisTwice,
                format!("L block: {axis} given twice"),
            )));
        }
        let v = if inch && !axis.is_rotary() {
            v * 25.4
        } else {
            v
        };
        target.set(axis, v);
    }
    if target.mask() == 0 {
        return Some(Err(LinearBlockError::new(
            K::NoCoordinate,
            "L block without a coordinate",
        )));
    }
    Some(Ok(LinearMove {
        target,
        feed,
        coordinates,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn positioning_blocks() {
        let m = parse_linear("L X+50 Y-30 Z+97.5 R0 FMAX", LengthUnit::Mm)
            .unwrap()
            .unwrap();
        assert_eq!(m.target.xyz(), [50.0, -30.0, 97.5]);
        assert_eq!(m.feed, MoveFeed::Rapid);
        let m = parse_linear("L C+90 F500 M3", LengthUnit::Mm)
            .unwrap()
            .unwrap();
        assert_eq!(m.target.get(Axis::C), Some(90.0));
        assert_eq!(m.feed, MoveFeed::Feed(500.0));
        let m = parse_linear("L Z+1 F10", LengthUnit::Inch)
            .unwrap()
            .unwrap();
        assert_eq!(m.target.get(Axis::Z), Some(25.4));
        assert!(parse_linear("CYCL DEF 200", LengthUnit::Mm).is_none());
        assert!(parse_linear("LBL 1", LengthUnit::Mm).is_none());
        use LinearBlockErrorKind as K;
        for (bad, kind) in [
            ("L IX+5", K::UnsupportedWord),
            ("L X+5 RL", K::UnsupportedWord),
            ("L", K::NoCoordinate),
            ("L X+1 X+2", K::AxisTwice),
            ("L Xabc", K::Coordinate),
            ("L X+1 F0", K::Feed),
        ] {
            let e = parse_linear(bad, LengthUnit::Mm).unwrap().unwrap_err();
            assert_eq!(e.kind(), kind, "{bad}: {e}");
        }
    }
}
