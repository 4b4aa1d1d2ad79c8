//! The plane through three measured points and its angles (cycle 431), exactly as
//! spec.md fixes them: frame X' = unit(P2-P1), Z' = unit((P2-P1) x (P3-P1)),
//! Y' = Z' x X'; R = [X' Y' Z'] = Rz(SPC) * Ry(SPB) * Rx(SPA).

use nalgebra::{Matrix3, Vector3};

/// sin of the angle between P2-P1 and P3-P1 below which the points count as on a line.
pub const COLLINEAR_SIN: f64 = 1e-6;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneAngles {
    /// Q170, Q171, Q172: spatial angles A, B, C for PLANE SPATIAL, degrees.
    pub spa: f64,
    pub spb: f64,
    pub spc: f64,
    /// Q158: projection angle of the A axis (normal projected into YZ), degrees.
    pub proj_a: f64,
    /// Q159: projection angle of the B axis (normal projected into ZX), degrees.
    pub proj_b: f64,
    /// Z' (unit).
    pub normal: Vector3<f64>,
    /// R = [X' Y' Z'].
    pub frame: Matrix3<f64>,
}

#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("the three measured points lie on a line (or coincide); they do not define a plane")]
pub struct CollinearPoints;

pub fn plane_angles(
    p1: Vector3<f64>,
    p2: Vector3<f64>,
    p3: Vector3<f64>,
) -> Result<PlaneAngles, CollinearPoints> {
    let a = p2 - p1;
    let b = p3 - p1;
    let cross = a.cross(&b);
    let scale = a.norm() * b.norm();
    if scale == 0.0 || cross.norm() <= COLLINEAR_SIN * scale {
        return Err(CollinearPoints);
    }
    let x = a.normalize();
    let z = cross.normalize();
    let y = z.cross(&x);
    let r = Matrix3::from_columns(&[x, y, z]);
    // asin is only defined on [-1, 1]; rounding can leave |R[2][0]| a hair above 1.
    let spb = (-r[(2, 0)]).clamp(-1.0, 1.0).asin();
    let spa = r[(2, 1)].atan2(r[(2, 2)]);
    let spc = r[(1, 0)].atan2(r[(0, 0)]);
    Ok(PlaneAngles {
        spa: spa.to_degrees(),
        spb: spb.to_degrees(),
        spc: spc.to_degrees(),
        proj_a: (-z.y).atan2(z.z).to_degrees(),
        proj_b: z.x.atan2(z.z).to_degrees(),
        normal: z,
        frame: r,
    })
}

/// Rz(c) * Ry(b) * Rx(a), angles in degrees (PLANE SPATIAL about machine-fixed axes,
/// A first).
pub fn spatial_rotation(spa: f64, spb: f64, spc: f64) -> Matrix3<f64> {
    let (sa, ca) = spa.to_radians().sin_cos();
    let (sb, cb) = spb.to_radians().sin_cos();
    let (sc, cc) = spc.to_radians().sin_cos();
    let rx = Matrix3::new(1.0, 0.0, 0.0, 0.0, ca, -sa, 0.0, sa, ca);
    let ry = Matrix3::new(cb, 0.0, sb, 0.0, 1.0, 0.0, -sb, 0.0, cb);
    let rz = Matrix3::new(cc, -sc, 0.0, sc, cc, 0.0, 0.0, 0.0, 1.0);
    rz * ry * rx
}
