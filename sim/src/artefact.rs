//! Measuring artefacts fixed to the table, in table coordinates (mm): a plane
//! (half-space), a solid sphere and a solid infinite cylinder.
//!
//! Every artefact gives the signed distance of a point to its surface (positive
//! outside the material, negative inside) and, for a point moving on a straight
//! segment `c(t) = c0 + t (c1 - c0)`, `t` in `[0, 1]`, the exact parameter at which
//! that distance reaches a given value (linear for the plane, quadratic for the
//! sphere and cylinder). The probe uses these with the ball centre and its trigger
//! distance, so the contact instant is solved, not sampled.

use nalgebra::{Unit, Vector3};

/// Roots just outside `[0, 1]` by rounding still count (then clamped), so that a
/// contact exactly at a segment end is not lost between two segments.
const T_EPS: f64 = 1e-12;

/// A surface the probe can touch.
pub trait Surface {
    /// Signed distance of `p` to the surface, mm: > 0 outside the material.
    fn distance(&self, p: &Vector3<f64>) -> f64;

    /// Smallest `t` in `[0, 1]` with `distance(c0 + t (c1 - c0)) == r`, `None` if the
    /// segment never reaches that distance.
    fn first_reach(&self, c0: &Vector3<f64>, c1: &Vector3<f64>, r: f64) -> Option<f64>;

    /// Smallest `t` in `[0, 1]` at which the distance falls through `r` (equals `r`
    /// while decreasing): the moment a point approaching the material comes closer
    /// than `r`. Grazing (tangent) touches and exits are not entries.
    fn first_entry(&self, c0: &Vector3<f64>, c1: &Vector3<f64>, r: f64) -> Option<f64>;

    /// Unit normal of the surface nearest to `p`, away from the material: the
    /// direction in which a ball centred at `p` is pushed by the contact.
    fn normal(&self, p: &Vector3<f64>) -> Vector3<f64>;
}

/// `v` as a unit vector; `fallback` where it has no direction (a point on an axis).
fn unit_or(v: Vector3<f64>, fallback: Vector3<f64>) -> Vector3<f64> {
    let n = v.norm();
    if n > 0.0 {
        v / n
    } else {
        fallback
    }
}

fn in_unit(t: f64) -> Option<f64> {
    (t.is_finite() && (-T_EPS..=1.0 + T_EPS).contains(&t)).then(|| t.clamp(0.0, 1.0))
}

/// Roots of `a t^2 + 2 b t + c = 0` with `a > 0`, smaller first; `None` without real
/// roots. Uses the cancellation-free form so contacts are exact to rounding.
fn quadratic_roots(a: f64, b: f64, c: f64) -> Option<(f64, f64)> {
    let disc = b * b - a * c;
    if disc < 0.0 {
        return None;
    }
    let s = disc.sqrt();
    let q = if b >= 0.0 { -(b + s) } else { -b + s };
    if q == 0.0 {
        // b == 0 and disc == 0: the double root t = 0.
        return Some((0.0, 0.0));
    }
    let (t1, t2) = (q / a, c / q);
    Some(if t1 <= t2 { (t1, t2) } else { (t2, t1) })
}

/// Segment against "distance of the projection `w(t) = w0 + t v` to an axis point
/// equals `rho`": shared by sphere (full 3D) and cylinder (projected on the normal
/// plane of its axis). Returns (smaller root, larger root, disc > 0).
fn radial_roots(w0: &Vector3<f64>, v: &Vector3<f64>, rho: f64) -> Option<(f64, f64, bool)> {
    if rho < 0.0 {
        return None;
    }
    let a = v.norm_squared();
    let n0 = w0.norm();
    // (|w0| - rho)(|w0| + rho) keeps precision when the start is near the surface.
    let c = (n0 - rho) * (n0 + rho);
    if a == 0.0 {
        return (c == 0.0).then_some((0.0, 0.0, false));
    }
    let b = w0.dot(v);
    let disc = b * b - a * c;
    quadratic_roots(a, b, c).map(|(t1, t2)| (t1, t2, disc > 0.0))
}

fn radial_first_reach(w0: &Vector3<f64>, v: &Vector3<f64>, rho: f64) -> Option<f64> {
    let (t1, t2, _) = radial_roots(w0, v, rho)?;
    in_unit(t1).or_else(|| in_unit(t2))
}

fn radial_first_entry(w0: &Vector3<f64>, v: &Vector3<f64>, rho: f64) -> Option<f64> {
    // |w|^2 - rho^2 is an upward parabola: it decreases through zero only at the
    // smaller root, and only when the roots are distinct.
    match radial_roots(w0, v, rho)? {
        (t1, _, true) => in_unit(t1),
        _ => None,
    }
}

/// Half-space bounded by a plane; the material lies on the side opposite the normal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    pub point: Vector3<f64>,
    /// Unit normal, pointing away from the material.
    pub normal: Unit<Vector3<f64>>,
}

impl Plane {
    /// `None` when `normal` is zero or not finite.
    pub fn new(point: Vector3<f64>, normal: Vector3<f64>) -> Option<Self> {
        let normal = Unit::try_new(normal, 1e-12)?;
        (point.iter().all(|v| v.is_finite()) && normal.iter().all(|v| v.is_finite()))
            .then_some(Self { point, normal })
    }
}

impl Surface for Plane {
    fn distance(&self, p: &Vector3<f64>) -> f64 {
        (p - self.point).dot(&self.normal)
    }

    fn first_reach(&self, c0: &Vector3<f64>, c1: &Vector3<f64>, r: f64) -> Option<f64> {
        let (s0, s1) = (self.distance(c0), self.distance(c1));
        if s0 == r {
            return Some(0.0);
        }
        if s1 == s0 {
            return None;
        }
        in_unit((r - s0) / (s1 - s0))
    }

    fn first_entry(&self, c0: &Vector3<f64>, c1: &Vector3<f64>, r: f64) -> Option<f64> {
        let (s0, s1) = (self.distance(c0), self.distance(c1));
        if s1 >= s0 {
            return None;
        }
        in_unit((r - s0) / (s1 - s0))
    }

    fn normal(&self, _p: &Vector3<f64>) -> Vector3<f64> {
        self.normal.into_inner()
    }
}

/// Solid sphere.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sphere {
    pub center: Vector3<f64>,
    pub radius: f64,
}

impl Sphere {
    /// `None` unless the radius is > 0 and everything is finite.
    pub fn new(center: Vector3<f64>, radius: f64) -> Option<Self> {
        (center.iter().all(|v| v.is_finite()) && radius.is_finite() && radius > 0.0)
            .then_some(Self { center, radius })
    }
}

impl Surface for Sphere {
    fn distance(&self, p: &Vector3<f64>) -> f64 {
        (p - self.center).norm() - self.radius
    }

    fn first_reach(&self, c0: &Vector3<f64>, c1: &Vector3<f64>, r: f64) -> Option<f64> {
        radial_first_reach(&(c0 - self.center), &(c1 - c0), self.radius + r)
    }

    fn first_entry(&self, c0: &Vector3<f64>, c1: &Vector3<f64>, r: f64) -> Option<f64> {
        radial_first_entry(&(c0 - self.center), &(c1 - c0), self.radius + r)
    }

    fn normal(&self, p: &Vector3<f64>) -> Vector3<f64> {
        unit_or(p - self.center, Vector3::z())
    }
}

/// Solid cylinder of infinite length, probed from outside.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cylinder {
    /// A point on the axis.
    pub point: Vector3<f64>,
    /// Unit direction of the axis.
    pub direction: Unit<Vector3<f64>>,
    pub radius: f64,
}

impl Cylinder {
    /// `None` when the direction is zero, the radius is not > 0, or a value is not finite.
    pub fn new(point: Vector3<f64>, direction: Vector3<f64>, radius: f64) -> Option<Self> {
        let direction = Unit::try_new(direction, 1e-12)?;
        (point.iter().all(|v| v.is_finite())
            && direction.iter().all(|v| v.is_finite())
            && radius.is_finite()
            && radius > 0.0)
            .then_some(Self {
                point,
                direction,
                radius,
            })
    }

    /// Component of `v` perpendicular to the axis.
    fn perpendicular(&self, v: &Vector3<f64>) -> Vector3<f64> {
        v - self.direction.into_inner() * v.dot(&self.direction)
    }
}

impl Surface for Cylinder {
    fn distance(&self, p: &Vector3<f64>) -> f64 {
        self.perpendicular(&(p - self.point)).norm() - self.radius
    }

    fn first_reach(&self, c0: &Vector3<f64>, c1: &Vector3<f64>, r: f64) -> Option<f64> {
        let w0 = self.perpendicular(&(c0 - self.point));
        radial_first_reach(&w0, &self.perpendicular(&(c1 - c0)), self.radius + r)
    }

    fn first_entry(&self, c0: &Vector3<f64>, c1: &Vector3<f64>, r: f64) -> Option<f64> {
        let w0 = self.perpendicular(&(c0 - self.point));
        radial_first_entry(&w0, &self.perpendicular(&(c1 - c0)), self.radius + r)
    }

    fn normal(&self, p: &Vector3<f64>) -> Vector3<f64> {
        unit_or(self.perpendicular(&(p - self.point)), Vector3::z())
    }
}

/// Any of the artefacts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Artefact {
    Plane(Plane),
    Sphere(Sphere),
    Cylinder(Cylinder),
}

impl Surface for Artefact {
    fn distance(&self, p: &Vector3<f64>) -> f64 {
        match self {
            Artefact::Plane(a) => a.distance(p),
            Artefact::Sphere(a) => a.distance(p),
            Artefact::Cylinder(a) => a.distance(p),
        }
    }

    fn first_reach(&self, c0: &Vector3<f64>, c1: &Vector3<f64>, r: f64) -> Option<f64> {
        match self {
            Artefact::Plane(a) => a.first_reach(c0, c1, r),
            Artefact::Sphere(a) => a.first_reach(c0, c1, r),
            Artefact::Cylinder(a) => a.first_reach(c0, c1, r),
        }
    }

    fn first_entry(&self, c0: &Vector3<f64>, c1: &Vector3<f64>, r: f64) -> Option<f64> {
        match self {
            Artefact::Plane(a) => a.first_entry(c0, c1, r),
            Artefact::Sphere(a) => a.first_entry(c0, c1, r),
            Artefact::Cylinder(a) => a.first_entry(c0, c1, r),
        }
    }

    fn normal(&self, p: &Vector3<f64>) -> Vector3<f64> {
        match self {
            Artefact::Plane(a) => a.normal(p),
            Artefact::Sphere(a) => a.normal(p),
            Artefact::Cylinder(a) => a.normal(p),
        }
    }
}

/// All artefacts of a scenario: the union of their material.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ArtefactSet {
    items: Vec<Artefact>,
}

impl ArtefactSet {
    pub fn new(items: Vec<Artefact>) -> Self {
        Self { items }
    }

    pub fn items(&self) -> &[Artefact] {
        &self.items
    }

    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }
}

impl Surface for ArtefactSet {
    /// Distance to the nearest surface (+inf without artefacts). Inside the union of
    /// the material the smallest value is the most negative one, which is what the
    /// probe needs ("closer than r to some surface or inside").
    fn distance(&self, p: &Vector3<f64>) -> f64 {
        self.items
            .iter()
            .map(|a| a.distance(p))
            .fold(f64::INFINITY, f64::min)
    }

    fn first_reach(&self, c0: &Vector3<f64>, c1: &Vector3<f64>, r: f64) -> Option<f64> {
        self.items
            .iter()
            .filter_map(|a| a.first_reach(c0, c1, r))
            .reduce(f64::min)
    }

    fn first_entry(&self, c0: &Vector3<f64>, c1: &Vector3<f64>, r: f64) -> Option<f64> {
        self.items
            .iter()
            .filter_map(|a| a.first_entry(c0, c1, r))
            .reduce(f64::min)
    }

    /// The normal of the nearest artefact (+Z without artefacts).
    fn normal(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.items
            .iter()
            .map(|a| (a.distance(p), a))
            .min_by(|x, y| x.0.total_cmp(&y.0))
            .map_or(Vector3::z(), |(_, a)| a.normal(p))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quadratic_is_exact_near_tangent_and_zero() {
        // (t - 0.25)(t - 0.75) = t^2 - t + 0.1875
        let (a, b) = quadratic_roots(1.0, -0.5, 0.1875).unwrap();
        assert!((a - 0.25).abs() < 1e-15 && (b - 0.75).abs() < 1e-15);
        assert_eq!(quadratic_roots(1.0, 0.0, 0.0), Some((0.0, 0.0)));
        assert_eq!(quadratic_roots(1.0, 0.0, 1.0), None);
    }
}
