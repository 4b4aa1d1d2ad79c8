//! The stylus of a real kinematic touch probe, beyond the ideal ball of the probe
//! table: where its ball centre really is (off the spindle axis, longer or shorter than
//! the table says), and how far it deflects before the signal switches, depending on
//! the direction in which the contact pushes the ball (the lobing of a kinematic seat).
//!
//! Frames: the tool frame has the axes (main, minor, tool) of the TNC's working plane
//! for the probe's tool axis (Z: X Y Z; X: Y Z X; Y: Z X Y), with the tool axis
//! pointing from the ball toward the spindle; the stylus frame is the tool frame turned
//! with the spindle (by its orientation angle, right-handed about the tool axis).
//!
//! Pre-travel: a contact that pushes the ball along the unit vector `u` (the surface
//! normal at the contact, away from the material) in the stylus frame, with `s` its
//! component along the stylus and `θ` its azimuth from the main axis, deflects
//! `p(u) = s² p_ax + (1 - s²) (p + A cos(3 (θ - φ)))` before the signal switches: `p`
//! the mean pre-travel across the stylus, `p_ax` the pre-travel along it, `A` the
//! amplitude of the three lobes of the kinematic seat, `φ` the azimuth of the first
//! lobe. An isotropic probe (`A = 0`, `p_ax = p`) is the probe of the ideal model.

use crate::scenario::ProbeTruth;
use hal::Axis;
use nalgebra::{Matrix3, Rotation3, Vector3};

/// The real stylus; see the module doc.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stylus {
    /// Tool frame to machine frame (head at 0): columns main, minor, tool.
    frame: Rotation3<f64>,
    /// Ball centre off the spindle axis at spindle 0°, tool frame (main, minor, 0), mm.
    offset: Vector3<f64>,
    /// The ball centre lies this much further from the spindle than the table says, mm.
    length_error: f64,
    /// `p`, `p_ax`, `A`, mm; `φ`, rad.
    pretravel: f64,
    pretravel_axial: f64,
    lobing: f64,
    lobing_phase: f64,
}

impl Stylus {
    pub fn new(truth: &ProbeTruth) -> Self {
        let [main, minor, tool] = tool_frame_axes(truth.axis);
        let frame = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[main, minor, tool]));
        Self {
            frame,
            offset: Vector3::new(truth.offset[0], truth.offset[1], 0.0),
            length_error: truth.length_error,
            pretravel: truth.pretravel,
            pretravel_axial: truth.pretravel_axial.unwrap_or(truth.pretravel),
            lobing: truth.lobing,
            lobing_phase: truth.lobing_phase.to_radians(),
        }
    }

    /// Whether the pre-travel is the same in every direction.
    pub fn is_isotropic(&self) -> bool {
        self.lobing == 0.0 && self.pretravel_axial == self.pretravel
    }

    fn spindle(&self, spindle_deg: f64) -> Rotation3<f64> {
        Rotation3::from_axis_angle(&Vector3::z_axis(), spindle_deg.to_radians())
    }

    /// The ball centre relative to the machine's gauge point (the ball centre of the
    /// ideal stylus), with the head at 0 and the spindle at `spindle_deg`, machine
    /// frame, mm.
    pub fn centre(&self, spindle_deg: f64) -> Vector3<f64> {
        self.frame * (self.spindle(spindle_deg) * self.offset - Vector3::z() * self.length_error)
    }

    /// The rotation that takes a vector of the machine frame (head at 0) into the
    /// stylus frame with the spindle at `spindle_deg`.
    pub fn from_tool_frame(&self, spindle_deg: f64) -> Rotation3<f64> {
        (self.frame * self.spindle(spindle_deg)).inverse()
    }

    /// Pre-travel beyond the mean lateral one, `p(u) - p`, for a contact pushing the
    /// ball along `u` (stylus frame), mm. 0 for an isotropic probe.
    pub fn extra_pretravel(&self, u: &Vector3<f64>) -> f64 {
        if self.is_isotropic() {
            return 0.0;
        }
        let n = u.norm();
        if n == 0.0 {
            return 0.0;
        }
        let s = (u.z / n).clamp(-1.0, 1.0);
        let s2 = s * s;
        let lateral = if u.x == 0.0 && u.y == 0.0 {
            0.0
        } else {
            self.lobing * (3.0 * (u.y.atan2(u.x) - self.lobing_phase)).cos()
        };
        s2 * (self.pretravel_axial - self.pretravel) + (1.0 - s2) * lateral
    }
}

/// Unit vectors of (main, minor, tool) in machine coordinates for a tool axis, as the
/// TNC lays out its working planes: Z: X Y Z, X: Y Z X, Y: Z X Y.
pub fn tool_frame_axes(tool: Axis) -> [Vector3<f64>; 3] {
    let (x, y, z) = (Vector3::x(), Vector3::y(), Vector3::z());
    match tool {
        Axis::X => [y, z, x],
        Axis::Y => [z, x, y],
        _ => [x, y, z],
    }
}
