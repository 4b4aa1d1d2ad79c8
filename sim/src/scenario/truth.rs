//! `[truth]`: the machine's true ISO 230-7 errors, per rotary axis.

use super::error::{check_abs, check_hirth, check_range, invalid, ScenarioError};
use hal::config::MachineConfig;
use hal::Axis;
use nalgebra::Vector3;
use std::collections::BTreeMap;
use std::path::Path;

/// The true errors of one rotary axis (ISO 230-7).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RotaryTruth {
    /// Position errors of the axis line, mm, in QS order
    /// (A: EY0A, EZ0A; B: EZ0B, EX0B; C: EX0C, EY0C).
    pub position: [f64; 2],
    /// Orientation errors of the axis direction, deg, in QS order
    /// (A: EB0A, EC0A; B: EC0B, EA0B; C: EA0C, EB0C).
    pub orientation: [f64; 2],
    /// Zero-position error (EA0A / EB0B / EC0C), deg: added to the mechanical angle.
    pub zero: f64,
    /// Width of the backlash dead band, deg.
    pub backlash: f64,
    /// Hirth grid, deg; `Some(0.0)` = none; `None` = the machine config's `hirth`.
    pub hirth: Option<f64>,
}

impl RotaryTruth {
    /// Position errors as the offset of the axis line from its pivot, mm
    /// (A: (0, EY0A, EZ0A); B: (EX0B, 0, EZ0B); C: (EX0C, EY0C, 0)).
    pub fn offset(&self, axis: Axis) -> Vector3<f64> {
        let [p0, p1] = self.position;
        match axis {
            Axis::A => Vector3::new(0.0, p0, p1),
            Axis::B => Vector3::new(p1, 0.0, p0),
            Axis::C => Vector3::new(p0, p1, 0.0),
            _ => Vector3::zeros(),
        }
    }

    /// The four location errors in the QS string order of spec.md.
    pub fn location_errors(&self) -> [f64; 4] {
        [
            self.position[0],
            self.position[1],
            self.orientation[0],
            self.orientation[1],
        ]
    }
}

/// Per-axis kinds of truth keys; `Truth::KEYS` maps every key name to one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Field {
    Position(usize),
    Orientation(usize),
    Zero,
    Backlash,
    Hirth,
}

/// The truth of all rotary axes; axes the machine lacks stay at zero.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Truth {
    pub a: RotaryTruth,
    pub b: RotaryTruth,
    pub c: RotaryTruth,
}

impl Truth {
    /// Every key `[truth]` accepts, with its axis.
    const KEYS: [(&'static str, Axis, Field); 21] = [
        ("EY0A", Axis::A, Field::Position(0)),
        ("EZ0A", Axis::A, Field::Position(1)),
        ("EB0A", Axis::A, Field::Orientation(0)),
        ("EC0A", Axis::A, Field::Orientation(1)),
        ("EZ0B", Axis::B, Field::Position(0)),
        ("EX0B", Axis::B, Field::Position(1)),
        ("EC0B", Axis::B, Field::Orientation(0)),
        ("EA0B", Axis::B, Field::Orientation(1)),
        ("EX0C", Axis::C, Field::Position(0)),
        ("EY0C", Axis::C, Field::Position(1)),
        ("EA0C", Axis::C, Field::Orientation(0)),
        ("EB0C", Axis::C, Field::Orientation(1)),
        ("EA0A", Axis::A, Field::Zero),
        ("EB0B", Axis::B, Field::Zero),
        ("EC0C", Axis::C, Field::Zero),
        ("backlash_A", Axis::A, Field::Backlash),
        ("backlash_B", Axis::B, Field::Backlash),
        ("backlash_C", Axis::C, Field::Backlash),
        ("hirth_A", Axis::A, Field::Hirth),
        ("hirth_B", Axis::B, Field::Hirth),
        ("hirth_C", Axis::C, Field::Hirth),
    ];

    pub fn axis(&self, axis: Axis) -> Option<&RotaryTruth> {
        match axis {
            Axis::A => Some(&self.a),
            Axis::B => Some(&self.b),
            Axis::C => Some(&self.c),
            _ => None,
        }
    }

    fn axis_mut(&mut self, axis: Axis) -> Option<&mut RotaryTruth> {
        match axis {
            Axis::A => Some(&mut self.a),
            Axis::B => Some(&mut self.b),
            Axis::C => Some(&mut self.c),
            _ => None,
        }
    }

    /// Value of a `[truth]` key by name ("EX0C", "backlash_C", ...); `hirth_*` reads
    /// 0 when absent. `None` for an unknown name.
    pub fn get(&self, key: &str) -> Option<f64> {
        let (_, axis, field) = Self::KEYS.iter().find(|(k, ..)| *k == key)?;
        let t = self.axis(*axis)?;
        Some(match field {
            Field::Position(i) => t.position[*i],
            Field::Orientation(i) => t.orientation[*i],
            Field::Zero => t.zero,
            Field::Backlash => t.backlash,
            Field::Hirth => t.hirth.unwrap_or(0.0),
        })
    }

    /// Sets a `[truth]` key by name; `false` for an unknown name.
    pub fn set(&mut self, key: &str, value: f64) -> bool {
        let Some((_, axis, field)) = Self::KEYS.iter().find(|(k, ..)| *k == key) else {
            return false;
        };
        let Some(t) = self.axis_mut(*axis) else {
            return false;
        };
        match field {
            Field::Position(i) => t.position[*i] = value,
            Field::Orientation(i) => t.orientation[*i] = value,
            Field::Zero => t.zero = value,
            Field::Backlash => t.backlash = value,
            Field::Hirth => t.hirth = Some(value),
        }
        true
    }

    /// The four location errors of `axis` in QS string order (zeros for X/Y/Z).
    pub fn location_errors(&self, axis: Axis) -> [f64; 4] {
        self.axis(axis)
            .map(RotaryTruth::location_errors)
            .unwrap_or_default()
    }

    fn accepted_keys() -> String {
        Self::KEYS
            .iter()
            .map(|(k, ..)| *k)
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// Largest accepted magnitudes of the truth values: beyond them a scenario is a typo,
/// not a machine (position mm, angles deg).
const MAX_POSITION_ERROR: f64 = 10.0;
const MAX_ANGLE_ERROR: f64 = 10.0;
/// Same range as Q432 (backlash measuring range).
const MAX_BACKLASH: f64 = 3.0;

/// `[truth]`: the machine's true errors, each on an axis the machine has.
pub(super) fn build_truth(
    raw: &BTreeMap<String, f64>,
    path: &Path,
    machine: &MachineConfig,
) -> Result<Truth, ScenarioError> {
    let bad = |key: &str, message: String| invalid(path, key, message);
    let mut truth = Truth::default();
    for (key, &value) in raw {
        let Some((_, axis, field)) = Truth::KEYS.iter().find(|(k, ..)| k == key) else {
            let hint = Truth::KEYS
                .iter()
                .find(|(k, ..)| k.eq_ignore_ascii_case(key))
                .map(|(k, ..)| format!(" (did you mean {k}?)"))
                .unwrap_or_default();
            return Err(bad(
                &format!("truth.{key}"),
                format!("unknown key{hint}; accepted: {}", Truth::accepted_keys()),
            ));
        };
        let key = format!("truth.{key}");
        if machine.axis(*axis).is_none() {
            return Err(bad(
                &key,
                format!("machine \"{}\" has no {axis} axis", machine.name),
            ));
        }
        match field {
            Field::Position(_) => check_abs(path, &key, value, MAX_POSITION_ERROR, "mm")?,
            Field::Orientation(_) | Field::Zero => {
                check_abs(path, &key, value, MAX_ANGLE_ERROR, "deg")?
            }
            Field::Backlash => check_range(path, &key, value, 0.0, MAX_BACKLASH, true)?,
            Field::Hirth => check_hirth(path, &key, value)?,
        }
        truth.set(&key["truth.".len()..], value);
    }
    Ok(truth)
}

/// Hirth grid of `axis` used by the physics: the truth's when given, else the
/// machine configuration's.
pub(crate) fn effective_hirth(machine: &MachineConfig, truth: &Truth, axis: Axis) -> f64 {
    truth
        .axis(axis)
        .and_then(|t| t.hirth)
        .or_else(|| machine.axis(axis).map(|a| a.hirth))
        .unwrap_or(0.0)
}
