//! The machine's true kinematic chain: the nominal chain of
//! [`hal::config::KinematicsConfig`] with the ISO 230-7 location errors and the
//! zero-position errors of the scenario's [`Truth`].
//!
//! # Convention (the cycles' model must implement exactly the same)
//!
//! Units: mm, angles in degrees in all inputs (converted to rad internally).
//! `Rx`, `Ry`, `Rz` are right-handed rotations about +X, +Y, +Z.
//!
//! A rotary axis `k` is a line and an angle offset:
//! - point on the line: `q = pivot_k + o_k`, where `pivot_k` is the configured pivot
//!   and the position errors give `o_A = (0, EY0A, EZ0A)`, `o_B = (EX0B, 0, EZ0B)`,
//!   `o_C = (EX0C, EY0C, 0)`;
//! - direction (unit): `d_A = Ry(EB0A) Rz(EC0A) x̂`, `d_B = Rz(EC0B) Rx(EA0B) ŷ`,
//!   `d_C = Rx(EA0C) Ry(EB0C) ẑ`;
//! - angle: `θ = commanded + zero error` (`EA0A`, `EB0B`, `EC0C`), where "commanded"
//!   is the mechanical angle (what the encoder reads, after backlash and Hirth grid,
//!   which [`crate::world::World`] applies before calling in here).
//!
//! `T_k(θ) p = q + Rot(d, θ) (p - q)` (Rodrigues: right-handed rotation by `θ`
//! about the line through `q` with direction `d`).
//!
//! Chains, exactly as on `KinematicsConfig`:
//! - table (`table` listed from the bed outward): a point `p` fixed to the table is at
//!   `T_t1(a1) · … · T_tn(an) · p` in machine coordinates (the outermost axis acts first);
//! - head (`head` listed from the machine frame toward the tool, pivots relative to the
//!   ball centre with all axes at 0): the ball centre in machine coordinates is
//!   `XYZ + T_h1(b1) · … · T_hm(bm) · 0`;
//! - the ball centre in table coordinates is `(T_t1 · … · T_tn)⁻¹ · ball_machine`.
//!
//! With every rotary angle at 0 and no zero errors each `T_k` is the identity whatever
//! the position and orientation errors, so machine, table and program coordinates
//! coincide there. A zero error (`EC0C`, ...) turns the axis even at 0.

use crate::scenario::{RotaryTruth, Truth};
use hal::config::MachineConfig;
use hal::{Axis, AxisPositions};
use nalgebra::{Isometry3, Rotation3, Translation3, Unit, UnitQuaternion, Vector3};

/// One rotary axis as it really is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RotaryJoint {
    pub axis: Axis,
    /// A point on the true axis line: pivot + position errors, mm.
    pub point: Vector3<f64>,
    /// True direction of the axis (unit).
    pub direction: Unit<Vector3<f64>>,
    /// Zero-position error, deg, added to the angle.
    pub zero: f64,
}

impl RotaryJoint {
    /// The joint of `axis` (A, B or C) through `pivot` with the errors of `truth`.
    pub fn new(axis: Axis, pivot: Vector3<f64>, truth: &RotaryTruth) -> Self {
        let [o0, o1] = truth.orientation.map(f64::to_radians);
        let rot = |v: Unit<Vector3<f64>>, a: f64| Rotation3::from_axis_angle(&v, a);
        let (x, y, z) = (Vector3::x_axis(), Vector3::y_axis(), Vector3::z_axis());
        let d = match axis {
            Axis::A => rot(y, o0) * rot(z, o1) * x.into_inner(),
            Axis::B => rot(z, o0) * rot(x, o1) * y.into_inner(),
            Axis::C => rot(x, o0) * rot(y, o1) * z.into_inner(),
            _ => panic!("{axis} is not a rotary axis"),
        };
        Self {
            axis,
            point: pivot + truth.offset(axis),
            direction: Unit::new_normalize(d),
            zero: truth.zero,
        }
    }

    /// `T(angle)`: rotation by `angle + zero` (deg) about the true line.
    pub fn transform(&self, angle_deg: f64) -> Isometry3<f64> {
        let r =
            UnitQuaternion::from_axis_angle(&self.direction, (angle_deg + self.zero).to_radians());
        Isometry3::from_parts(Translation3::from(self.point - r * self.point), r)
    }
}

/// Rotary axes on one side of the chain, in configuration order. Fixed size so the
/// per-step evaluation allocates nothing.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Chain {
    joints: [Option<RotaryJoint>; 3],
}

impl Chain {
    fn new(axes: &[Axis], cfg: &MachineConfig, truth: &Truth) -> Self {
        let mut joints = [None; 3];
        for (slot, &axis) in joints.iter_mut().zip(axes) {
            let p = cfg.kinematics.pivot.get(&axis).copied().unwrap_or_default();
            let t = truth.axis(axis).copied().unwrap_or_default();
            *slot = Some(RotaryJoint::new(axis, Vector3::new(p[0], p[1], p[2]), &t));
        }
        Self { joints }
    }

    /// `T_1(a1) · … · T_n(an)`; an angle missing from `axes` reads 0.
    fn compose(&self, axes: &AxisPositions) -> Isometry3<f64> {
        self.joints
            .iter()
            .flatten()
            .fold(Isometry3::identity(), |acc, j| {
                acc * j.transform(axes.get(j.axis).unwrap_or(0.0))
            })
    }

    fn iter(&self) -> impl Iterator<Item = &RotaryJoint> {
        self.joints.iter().flatten()
    }
}

/// Forward transform of the machine with its true errors. Angles given to it are the
/// mechanical ones (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrueKinematics {
    table: Chain,
    head: Chain,
}

impl TrueKinematics {
    /// Truth of axes outside the machine's chains is ignored (the scenario refuses it).
    pub fn new(cfg: &MachineConfig, truth: &Truth) -> Self {
        Self {
            table: Chain::new(&cfg.kinematics.table, cfg, truth),
            head: Chain::new(&cfg.kinematics.head, cfg, truth),
        }
    }

    /// The nominal chain (no errors).
    pub fn nominal(cfg: &MachineConfig) -> Self {
        Self::new(cfg, &Truth::default())
    }

    /// Table-side joints, bed first.
    pub fn table_joints(&self) -> impl Iterator<Item = &RotaryJoint> {
        self.table.iter()
    }

    /// Head-side joints, machine frame first.
    pub fn head_joints(&self) -> impl Iterator<Item = &RotaryJoint> {
        self.head.iter()
    }

    /// The joint of `axis`, on either side.
    pub fn joint(&self, axis: Axis) -> Option<&RotaryJoint> {
        self.table_joints()
            .chain(self.head_joints())
            .find(|j| j.axis == axis)
    }

    /// Table to machine: `T_t1 · … · T_tn`.
    pub fn table_transform(&self, axes: &AxisPositions) -> Isometry3<f64> {
        self.table.compose(axes)
    }

    /// Ball centre in machine coordinates: `XYZ + T_h1 · … · T_hm · 0`.
    pub fn ball_centre_in_machine(&self, axes: &AxisPositions) -> Vector3<f64> {
        let [x, y, z] = axes.xyz();
        let head = self.head.compose(axes);
        Vector3::new(x, y, z) + head.translation.vector
    }

    /// Head to machine: `T_h1 · … · T_hm` (the rotation the head gives the tool).
    pub fn head_transform(&self, axes: &AxisPositions) -> Isometry3<f64> {
        self.head.compose(axes)
    }

    /// A point fixed to the head, `v` from the ball centre of the ideal stylus with
    /// the head at 0, in machine coordinates: `XYZ + T_h1 · … · T_hm · v`.
    pub fn head_point_in_machine(&self, axes: &AxisPositions, v: &Vector3<f64>) -> Vector3<f64> {
        let [x, y, z] = axes.xyz();
        let head = self.head.compose(axes);
        Vector3::new(x, y, z) + head.transform_point(&(*v).into()).coords
    }

    /// Ball centre in table coordinates (where the artefacts are).
    pub fn ball_centre_in_table(&self, axes: &AxisPositions) -> Vector3<f64> {
        self.machine_to_table(axes, self.ball_centre_in_machine(axes))
    }

    /// A point fixed to the table, in machine coordinates.
    pub fn table_to_machine(&self, axes: &AxisPositions, p_table: Vector3<f64>) -> Vector3<f64> {
        self.table_transform(axes)
            .transform_point(&p_table.into())
            .coords
    }

    /// Inverse of [`TrueKinematics::table_to_machine`].
    pub fn machine_to_table(&self, axes: &AxisPositions, p_machine: Vector3<f64>) -> Vector3<f64> {
        self.table_transform(axes)
            .inverse_transform_point(&p_machine.into())
            .coords
    }
}
