//! Axis names and fixed-size position sets (no allocation: used on the hot path).

use serde::{Deserialize, Serialize};

/// Most axes a machine (and a [`crate::ContactSample`]) carries.
pub const MAX_AXES: usize = 6;

/// Machine axes as the TNC names them: three linear (mm), three rotary (deg).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum Axis {
    X,
    Y,
    Z,
    A,
    B,
    C,
}

impl Axis {
    pub const ALL: [Axis; MAX_AXES] = [Axis::X, Axis::Y, Axis::Z, Axis::A, Axis::B, Axis::C];
    pub const LINEAR: [Axis; 3] = [Axis::X, Axis::Y, Axis::Z];
    pub const ROTARY: [Axis; 3] = [Axis::A, Axis::B, Axis::C];

    /// Index into position arrays: X=0 .. C=5.
    pub const fn index(self) -> usize {
        self as usize
    }

    pub const fn from_index(i: usize) -> Option<Axis> {
        match i {
            0 => Some(Axis::X),
            1 => Some(Axis::Y),
            2 => Some(Axis::Z),
            3 => Some(Axis::A),
            4 => Some(Axis::B),
            5 => Some(Axis::C),
            _ => None,
        }
    }

    pub const fn is_rotary(self) -> bool {
        self.index() >= 3
    }

    pub const fn name(self) -> &'static str {
        match self {
            Axis::X => "X",
            Axis::Y => "Y",
            Axis::Z => "Z",
            Axis::A => "A",
            Axis::B => "B",
            Axis::C => "C",
        }
    }

    /// Parses "X".."C" (either case).
    pub fn from_name(s: &str) -> Option<Axis> {
        match s.trim() {
            "X" | "x" => Some(Axis::X),
            "Y" | "y" => Some(Axis::Y),
            "Z" | "z" => Some(Axis::Z),
            "A" | "a" => Some(Axis::A),
            "B" | "b" => Some(Axis::B),
            "C" | "c" => Some(Axis::C),
            _ => None,
        }
    }
}

impl core::fmt::Display for Axis {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// Positions of up to six axes (mm for X/Y/Z, deg for A/B/C) with a mask of which
/// are present. `Copy` and fixed size so the real-time loop can pass it around freely.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AxisPositions {
    values: [f64; MAX_AXES],
    mask: u8,
}

impl AxisPositions {
    pub const fn new() -> Self {
        Self {
            values: [0.0; MAX_AXES],
            mask: 0,
        }
    }

    /// From raw arrays as carried in a [`crate::ContactSample`].
    pub const fn from_raw(values: [f64; MAX_AXES], mask: u8) -> Self {
        Self { values, mask }
    }

    /// X, Y, Z present with these values; no rotary axes.
    pub fn linear(xyz: [f64; 3]) -> Self {
        let mut p = Self::new();
        for (axis, v) in Axis::LINEAR.into_iter().zip(xyz) {
            p.set(axis, v);
        }
        p
    }

    pub fn with(mut self, axis: Axis, value: f64) -> Self {
        self.set(axis, value);
        self
    }

    pub fn get(&self, axis: Axis) -> Option<f64> {
        self.contains(axis).then(|| self.values[axis.index()])
    }

    pub fn set(&mut self, axis: Axis, value: f64) {
        self.values[axis.index()] = value;
        self.mask |= 1 << axis.index();
    }

    pub fn remove(&mut self, axis: Axis) {
        self.values[axis.index()] = 0.0;
        self.mask &= !(1 << axis.index());
    }

    pub const fn contains(&self, axis: Axis) -> bool {
        self.mask & (1 << axis.index()) != 0
    }

    pub const fn mask(&self) -> u8 {
        self.mask
    }

    /// All six values; absent axes read 0.
    pub const fn raw(&self) -> [f64; MAX_AXES] {
        self.values
    }

    /// X, Y, Z (absent ones read 0).
    pub fn xyz(&self) -> [f64; 3] {
        [self.values[0], self.values[1], self.values[2]]
    }

    /// Present axes with their values, X first.
    pub fn iter(&self) -> impl Iterator<Item = (Axis, f64)> + '_ {
        Axis::ALL
            .into_iter()
            .filter(|a| self.contains(*a))
            .map(|a| (a, self.values[a.index()]))
    }

    /// Values of `other` override ours where `other` has them.
    pub fn merged(mut self, other: &AxisPositions) -> Self {
        for (a, v) in other.iter() {
            self.set(a, v);
        }
        self
    }
}

impl core::fmt::Display for AxisPositions {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let mut first = true;
        for (a, v) in self.iter() {
            if !first {
                f.write_str(" ")?;
            }
            first = false;
            write!(f, "{a}{v:+.6}")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mask_tracks_present_axes() {
        let p = AxisPositions::linear([1.0, 2.0, 3.0]).with(Axis::C, 90.0);
        assert_eq!(p.get(Axis::C), Some(90.0));
        assert_eq!(p.get(Axis::A), None);
        assert_eq!(p.mask(), 0b10_0111);
        assert_eq!(
            p.to_string(),
            "X+1.000000 Y+2.000000 Z+3.000000 C+90.000000"
        );
    }
}
