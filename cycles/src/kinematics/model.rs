//! The control's kinematic model: the nominal chain of a machine configuration with the
//! active ISO 230-7 corrections (location errors and zero errors of the rotary axes).
//!
//! # Convention
//!
//! The same as the simulator's (and as [`hal::config::KinematicsConfig`] fixes), written
//! here independently. Angles in degrees, lengths in mm. `Rx`, `Ry`, `Rz` turn
//! right-handed about +X, +Y, +Z.
//!
//! A rotary axis is a line and an angle offset:
//! - a point on the line: `q = pivot + o`, with the position errors
//!   `o_A = (0, EY0A, EZ0A)`, `o_B = (EX0B, 0, EZ0B)`, `o_C = (EX0C, EY0C, 0)`;
//! - its direction: `d_A = Ry(EB0A) Rz(EC0A) x̂`, `d_B = Rz(EC0B) Rx(EA0B) ŷ`,
//!   `d_C = Rx(EA0C) Ry(EB0C) ẑ`;
//! - its angle: `θ = commanded + zero error` (`EA0A`, `EB0B`, `EC0C`).
//!
//! `T(θ) p = q + Rot(d, θ) (p - q)`. Table chain (bed outward): a point `p` fixed to the
//! table is at `T_t1 · … · T_tn · p` in machine coordinates. Head chain (machine frame
//! toward the tool, pivots relative to the ball centre at all axes 0): the stylus ball
//! centre is `XYZ + T_h1 · … · T_hm · 0`.
//!
//! # What cycle 451 observes
//!
//! With the axes at angles `a`, the probe touches a sphere fixed to the table whose
//! centre is `p` in table coordinates when the linear axes stand at
//! `XYZ = T_table(a) p - h(a)` (`h(a) = T_head(a) · 0`, the ball's offset from XYZ):
//! the fitted centre of the latched X/Y/Z positions of its contacts.
//! [`KinematicModel::predict`] computes that, [`KinematicModel::table_point`] inverts it.

use crate::iso230_7::error_names;
use hal::config::MachineConfig;
use hal::{Axis, AxisPositions};
use nalgebra::{Isometry3, Point3, Rotation3, Translation3, Unit, UnitQuaternion, Vector3};
use std::collections::BTreeMap;

/// Angles of the rotary axes A, B, C in degrees (0 for an axis the machine lacks).
pub type Angles = [f64; 3];

/// Index of a rotary axis in [`Angles`] and in [`ErrorSet`] blocks (A 0, B 1, C 2).
pub fn rotary_slot(axis: Axis) -> Option<usize> {
    match axis {
        Axis::A => Some(0),
        Axis::B => Some(1),
        Axis::C => Some(2),
        _ => None,
    }
}

/// The rotary angles of `p` (absent axes read 0).
pub fn angles_of(p: &AxisPositions) -> Angles {
    Axis::ROTARY.map(|a| p.get(a).unwrap_or(0.0))
}

/// Which error of an axis a slot of [`ErrorSet`] holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ErrorPart {
    /// First and second position error (QS order: A EY0A, EZ0A; B EZ0B, EX0B; C EX0C, EY0C).
    Position(usize),
    /// First and second orientation error (A EB0A, EC0A; B EC0B, EA0B; C EA0C, EB0C).
    Orientation(usize),
    /// Zero-position error (EA0A, EB0B, EC0C).
    Zero,
}

impl ErrorPart {
    pub const ALL: [ErrorPart; 5] = [
        ErrorPart::Position(0),
        ErrorPart::Position(1),
        ErrorPart::Orientation(0),
        ErrorPart::Orientation(1),
        ErrorPart::Zero,
    ];

    fn offset(self) -> usize {
        match self {
            ErrorPart::Position(i) => i,
            ErrorPart::Orientation(i) => 2 + i,
            ErrorPart::Zero => 4,
        }
    }

    /// mm for position errors, deg otherwise.
    pub fn unit(self) -> &'static str {
        match self {
            ErrorPart::Position(_) => "mm",
            _ => "deg",
        }
    }
}

/// Number of errors the model knows: five per rotary axis.
pub const ERROR_COUNT: usize = 15;

/// All location and zero errors of A, B, C, by slot: `5 * rotary_slot(axis) + k` with
/// `k` in the order of [`crate::iso230_7::error_names`] (QS order, then zero).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ErrorSet(pub [f64; ERROR_COUNT]);

impl ErrorSet {
    /// Slot of (axis, kind).
    pub fn index(axis: Axis, kind: ErrorPart) -> usize {
        5 * rotary_slot(axis).expect("a rotary axis") + kind.offset()
    }

    /// Slot of an ISO name ("EX0C"), if it is one of the fifteen.
    pub fn index_of(name: &str) -> Option<usize> {
        Axis::ROTARY.iter().find_map(|&a| {
            error_names(a)
                .iter()
                .position(|n| *n == name)
                .map(|k| 5 * rotary_slot(a).expect("rotary") + k)
        })
    }

    /// ISO name of a slot.
    pub fn name(index: usize) -> &'static str {
        error_names(Axis::ROTARY[index / 5])[index % 5]
    }

    /// The axis and kind of a slot.
    pub fn describe(index: usize) -> (Axis, ErrorPart) {
        (Axis::ROTARY[index / 5], ErrorPart::ALL[index % 5])
    }

    pub fn get(&self, axis: Axis, kind: ErrorPart) -> f64 {
        self.0[Self::index(axis, kind)]
    }

    pub fn set(&mut self, axis: Axis, kind: ErrorPart, v: f64) {
        self.0[Self::index(axis, kind)] = v;
    }

    /// Value of an ISO name; 0 for an unknown one.
    pub fn by_name(&self, name: &str) -> f64 {
        Self::index_of(name).map_or(0.0, |i| self.0[i])
    }

    /// The five errors of one axis (QS order, then zero).
    pub fn axis(&self, axis: Axis) -> [f64; 5] {
        let s = 5 * rotary_slot(axis).expect("a rotary axis");
        [
            self.0[s],
            self.0[s + 1],
            self.0[s + 2],
            self.0[s + 3],
            self.0[s + 4],
        ]
    }

    /// The four location errors of one axis in QS order.
    pub fn location(&self, axis: Axis) -> [f64; 4] {
        let e = self.axis(axis);
        [e[0], e[1], e[2], e[3]]
    }

    /// From errors by ISO name (as the kinematics file holds them); other names are
    /// ignored (the file loader refuses them).
    pub fn from_map(map: &BTreeMap<String, f64>) -> Self {
        let mut s = Self::default();
        for (name, v) in map {
            if let Some(i) = Self::index_of(name) {
                s.0[i] = *v;
            }
        }
        s
    }

    /// Errors by ISO name: every error of the given axes (the rest are left out).
    pub fn to_map(&self, axes: &[Axis]) -> BTreeMap<String, f64> {
        let mut m = BTreeMap::new();
        for &a in axes {
            for (k, name) in error_names(a).iter().enumerate() {
                m.insert(
                    (*name).to_string(),
                    self.0[5 * rotary_slot(a).expect("rotary") + k],
                );
            }
        }
        m
    }
}

/// The nominal chain: rotary axes on the table side (bed outward) and on the head side
/// (machine frame toward the tool), each with its pivot.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ChainSpec {
    pub table: Vec<(Axis, [f64; 3])>,
    pub head: Vec<(Axis, [f64; 3])>,
}

/// Where a rotary axis sits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    Table,
    Head,
}

impl ChainSpec {
    pub fn of(cfg: &MachineConfig) -> Self {
        let k = &cfg.kinematics;
        let with_pivot = |list: &[Axis]| {
            list.iter()
                .map(|a| (*a, k.pivot.get(a).copied().unwrap_or_default()))
                .collect()
        };
        Self {
            table: with_pivot(&k.table),
            head: with_pivot(&k.head),
        }
    }

    pub fn side(&self, axis: Axis) -> Option<Side> {
        if self.table.iter().any(|(a, _)| *a == axis) {
            Some(Side::Table)
        } else if self.head.iter().any(|(a, _)| *a == axis) {
            Some(Side::Head)
        } else {
            None
        }
    }

    pub fn axes(&self) -> Vec<Axis> {
        self.table
            .iter()
            .chain(&self.head)
            .map(|(a, _)| *a)
            .collect()
    }

    /// Rotary axes nearer the machine bed than `axis` in its own chain (on the table
    /// side those before it; on the head side those between the machine frame and it),
    /// nearest first.
    pub fn nearer_bed(&self, axis: Axis) -> Vec<Axis> {
        for list in [&self.table, &self.head] {
            if let Some(i) = list.iter().position(|(a, _)| *a == axis) {
                return list[..i].iter().rev().map(|(a, _)| *a).collect();
            }
        }
        Vec::new()
    }
}

/// One rotary axis of the model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Joint {
    pub axis: Axis,
    /// A point on the axis line (pivot + position errors), mm.
    pub point: Vector3<f64>,
    /// Direction of the line (unit).
    pub direction: Unit<Vector3<f64>>,
    /// Zero error, deg.
    pub zero: f64,
}

fn rot(axis: Unit<Vector3<f64>>, deg: f64) -> Rotation3<f64> {
    Rotation3::from_axis_angle(&axis, deg.to_radians())
}

impl Joint {
    /// `axis` through `pivot` with its five errors `e` (QS order, then zero).
    pub fn new(axis: Axis, pivot: [f64; 3], e: [f64; 5]) -> Self {
        let (x, y, z) = (Vector3::x_axis(), Vector3::y_axis(), Vector3::z_axis());
        let (offset, direction) = match axis {
            Axis::A => (
                Vector3::new(0.0, e[0], e[1]),
                rot(y, e[2]) * rot(z, e[3]) * x.into_inner(),
            ),
            Axis::B => (
                Vector3::new(e[1], 0.0, e[0]),
                rot(z, e[2]) * rot(x, e[3]) * y.into_inner(),
            ),
            Axis::C => (
                Vector3::new(e[0], e[1], 0.0),
                rot(x, e[2]) * rot(y, e[3]) * z.into_inner(),
            ),
            _ => panic!("{axis} is not a rotary axis"),
        };
        Self {
            axis,
            point: Vector3::from(pivot) + offset,
            direction: Unit::new_normalize(direction),
            zero: e[4],
        }
    }

    /// `T(angle)`: the rotation by `angle + zero` (deg) about the line.
    pub fn transform(&self, angle: f64) -> Isometry3<f64> {
        let r = UnitQuaternion::from_axis_angle(&self.direction, (angle + self.zero).to_radians());
        Isometry3::from_parts(Translation3::from(self.point - r * self.point), r)
    }
}

/// The chain with its errors: forward transform and what cycle 451 observes.
#[derive(Clone, Debug, PartialEq)]
pub struct KinematicModel {
    pub table: Vec<Joint>,
    pub head: Vec<Joint>,
}

impl KinematicModel {
    pub fn new(chain: &ChainSpec, errors: &ErrorSet) -> Self {
        let joints = |list: &[(Axis, [f64; 3])]| {
            list.iter()
                .map(|(a, p)| Joint::new(*a, *p, errors.axis(*a)))
                .collect()
        };
        Self {
            table: joints(&chain.table),
            head: joints(&chain.head),
        }
    }

    /// The nominal chain (no errors).
    pub fn nominal(chain: &ChainSpec) -> Self {
        Self::new(chain, &ErrorSet::default())
    }

    fn compose(joints: &[Joint], angles: &Angles) -> Isometry3<f64> {
        joints.iter().fold(Isometry3::identity(), |acc, j| {
            acc * j.transform(angles[rotary_slot(j.axis).expect("rotary")])
        })
    }

    /// Table to machine coordinates: `T_t1 · … · T_tn`.
    pub fn table_transform(&self, angles: &Angles) -> Isometry3<f64> {
        Self::compose(&self.table, angles)
    }

    /// `T_h1 · … · T_hm` of the head.
    pub fn head_transform(&self, angles: &Angles) -> Isometry3<f64> {
        Self::compose(&self.head, angles)
    }

    /// Offset of the stylus ball centre from the X/Y/Z axis positions.
    pub fn ball_offset(&self, angles: &Angles) -> Vector3<f64> {
        self.head_transform(angles).translation.vector
    }

    /// `v` (a direction of the tool at all axes 0) turned with the head.
    pub fn tool_vector(&self, angles: &Angles, v: Vector3<f64>) -> Vector3<f64> {
        self.head_transform(angles).rotation * v
    }

    /// The X/Y/Z axis positions at which the ball centre is at `p_table` (a point in
    /// table coordinates) with the rotary axes at `angles`.
    pub fn predict(&self, angles: &Angles, p_table: &Vector3<f64>) -> Vector3<f64> {
        self.table_transform(angles)
            .transform_point(&Point3::from(*p_table))
            .coords
            - self.ball_offset(angles)
    }

    /// Inverse of [`KinematicModel::predict`]: the table point at which the ball
    /// centre is when the axes stand at `xyz` and `angles`.
    pub fn table_point(&self, angles: &Angles, xyz: &Vector3<f64>) -> Vector3<f64> {
        self.table_transform(angles)
            .inverse_transform_point(&Point3::from(xyz + self.ball_offset(angles)))
            .coords
    }

    /// Ball centre in machine coordinates with the axes at `xyz`, `angles`.
    pub fn ball_in_machine(&self, angles: &Angles, xyz: &Vector3<f64>) -> Vector3<f64> {
        xyz + self.ball_offset(angles)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chain_ac() -> ChainSpec {
        ChainSpec {
            table: vec![(Axis::A, [0.0; 3]), (Axis::C, [0.0; 3])],
            head: vec![],
        }
    }

    #[test]
    fn names_and_slots_agree_with_the_kinematics_file() {
        for i in 0..ERROR_COUNT {
            assert_eq!(ErrorSet::index_of(ErrorSet::name(i)), Some(i));
        }
        assert_eq!(ErrorSet::name(0), "EY0A");
        assert_eq!(ErrorSet::name(7), "EC0B");
        assert_eq!(ErrorSet::name(14), "EC0C");
        assert_eq!(
            ErrorSet::index(Axis::C, ErrorPart::Orientation(1)),
            ErrorSet::index_of("EB0C").unwrap()
        );
    }

    #[test]
    fn all_zero_angles_are_the_identity_whatever_the_location_errors() {
        let mut e = ErrorSet::default();
        for (i, v) in e.0.iter_mut().enumerate() {
            if i % 5 != 4 {
                *v = 0.01 * (i as f64 + 1.0);
            }
        }
        let m = KinematicModel::new(&chain_ac(), &e);
        let p = Vector3::new(50.0, -30.0, 80.0);
        assert!((m.predict(&[0.0; 3], &p) - p).norm() < 1e-12);
    }

    #[test]
    fn c_position_error_moves_the_rotation_centre() {
        let mut e = ErrorSet::default();
        e.set(Axis::C, ErrorPart::Position(0), 0.1); // EX0C
        let m = KinematicModel::new(&chain_ac(), &e);
        // C = 180 about the line x = 0.1: (50, 0, 0) -> (-49.8, 0, 0).
        let c = m.predict(&[0.0, 0.0, 180.0], &Vector3::new(50.0, 0.0, 0.0));
        assert!((c - Vector3::new(-49.8, 0.0, 0.0)).norm() < 1e-9, "{c}");
    }

    #[test]
    fn head_ball_swings_about_the_pivot() {
        let chain = ChainSpec {
            table: vec![(Axis::C, [0.0; 3])],
            head: vec![(Axis::B, [0.0, 0.0, 250.0])],
        };
        let m = KinematicModel::nominal(&chain);
        // B = +90 turns +Z into +X: the ball, 250 below the pivot, goes to -X.
        let h = m.ball_offset(&[0.0, 90.0, 0.0]);
        assert!((h - Vector3::new(-250.0, 0.0, 250.0)).norm() < 1e-9, "{h}");
        let t = m.tool_vector(&[0.0, 90.0, 0.0], Vector3::z());
        assert!((t - Vector3::x()).norm() < 1e-12);
        let p = Vector3::new(40.0, 25.0, 60.0);
        let xyz = m.predict(&[0.0, 30.0, 0.0], &p);
        assert!((m.table_point(&[0.0, 30.0, 0.0], &xyz) - p).norm() < 1e-12);
    }

    #[test]
    fn nearer_bed() {
        let c = chain_ac();
        assert_eq!(c.nearer_bed(Axis::C), vec![Axis::A]);
        assert!(c.nearer_bed(Axis::A).is_empty());
        let h = ChainSpec {
            table: vec![(Axis::C, [0.0; 3])],
            head: vec![(Axis::B, [0.0, 0.0, 250.0])],
        };
        assert!(h.nearer_bed(Axis::B).is_empty());
        assert!(h.nearer_bed(Axis::C).is_empty());
    }
}
