//! The path check: whether a straight move brings the ball onto a calibration sphere,
//! for any sphere of a set still possible. A set is every sphere whose centre lies in
//! a solid cylinder (the start's reach in the working plane times the range of heights
//! along the tool axis), with a ball-centre radius (Q407 + R) up to `touch`; one known
//! sphere is a cylinder of no size. The union of those spheres is the cylinder grown by
//! `touch`, a convex body: the ball comes onto one of them exactly where its centre
//! comes nearer than `touch` to the cylinder. So the path is checked against the whole
//! continuum of spheres, not against samples of it.

use crate::kinematics::model::{angles_of, Angles, KinematicModel};
use hal::{Axis, AxisPositions};
use nalgebra::Vector3;

/// Largest step, mm or deg, at which a path that turns a rotary axis is checked (the
/// sphere moves with the table on such a path; a straight linear path is checked
/// exactly).
pub const PATH_STEP: f64 = 0.2;
/// A ball centre closer to the sphere centre than Q407 + R by more than this is a
/// contact, mm (a probing contact leaves the ball exactly at Q407 + R).
pub const TOUCH_TOLERANCE: f64 = 1e-3;

/// One sphere: its centre in table coordinates (where the ball centre is at it with
/// the rotary axes at 0; machine coordinates where no model follows the table) and
/// Q407 + R, the ball centre's distance from it at a contact.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sphere {
    pub centre: Vector3<f64>,
    pub touch: f64,
}

/// Every sphere whose centre lies in a solid cylinder about the segment from `base`
/// along `axis` for `length` mm, at most `radial` off it, with Q407 + R up to `touch`
/// (table coordinates, as [`Sphere::centre`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SphereSet {
    pub base: Vector3<f64>,
    /// Unit vector.
    pub axis: Vector3<f64>,
    pub length: f64,
    pub radial: f64,
    pub touch: f64,
}

impl SphereSet {
    /// The set of one sphere.
    pub fn one(s: Sphere) -> Self {
        SphereSet {
            base: s.centre,
            axis: Vector3::z(),
            length: 0.0,
            radial: 0.0,
            touch: s.touch,
        }
    }

    /// Whether it holds more than one centre.
    pub fn is_one(&self) -> bool {
        self.length == 0.0 && self.radial == 0.0
    }

    /// Whether `s` is one of the set (within the touch tolerance).
    pub fn contains(&self, s: &Sphere) -> bool {
        self.gap_at(&self.base, &self.axis, &s.centre) <= TOUCH_TOLERANCE
            && s.touch <= self.touch + TOUCH_TOLERANCE
    }

    /// The cylinder's base and axis in machine coordinates with the rotary axes at `a`.
    fn placed(&self, model: Option<&KinematicModel>, a: &Angles) -> (Vector3<f64>, Vector3<f64>) {
        match model {
            None => (self.base, self.axis),
            Some(m) => {
                let base = m.predict(a, &self.base);
                (base, m.predict(a, &(self.base + self.axis)) - base)
            }
        }
    }

    /// Distance of `p` from the cylinder whose axis starts at `base` along `axis`.
    fn gap_at(&self, base: &Vector3<f64>, axis: &Vector3<f64>, p: &Vector3<f64>) -> f64 {
        let d = p - base;
        let z = d.dot(axis);
        let r = (d - axis * z).norm();
        let dz = (-z).max(z - self.length).max(0.0);
        let dr = (r - self.radial).max(0.0);
        (dz * dz + dr * dr).sqrt()
    }

    /// Distance of the ball centre at `p` (axis positions, X/Y/Z and rotary) from the
    /// nearest centre of the set.
    pub fn gap(&self, model: Option<&KinematicModel>, p: &AxisPositions) -> f64 {
        let (base, axis) = self.placed(model, &angles_of(p));
        self.gap_at(&base, &axis, &Vector3::from(p.xyz()))
    }

    /// Whether the ball at `p` is on or in a sphere of the set.
    pub fn touched_at(&self, model: Option<&KinematicModel>, p: &AxisPositions) -> bool {
        self.gap(model, p) < self.touch - TOUCH_TOLERANCE
    }
}

/// Where the straight move from `from` to `to` (every axis of `to`; the others stay)
/// first brings the ball onto a sphere of `set`, or `None` when it keeps off all of
/// them. A move of the linear axes alone is checked exactly: the ball's distance from
/// the (fixed) cylinder is convex along the path, and its minimum is found by golden
/// section; the point returned is that nearest one. A move that turns a rotary axis is
/// checked every [`PATH_STEP`] (mm or deg), the set following the table with `model`.
pub fn first_touch(
    set: &SphereSet,
    model: Option<&KinematicModel>,
    from: &AxisPositions,
    to: &AxisPositions,
) -> Option<AxisPositions> {
    let end = from.merged(to);
    let at = |f: f64| {
        let mut p = *from;
        for (axis, v) in end.iter() {
            let v0 = from.get(axis).unwrap_or(v);
            p.set(axis, v0 + (v - v0) * f);
        }
        p
    };
    let turns = Axis::ROTARY.iter().any(|a| {
        let (f, e) = (from.get(*a).unwrap_or(0.0), end.get(*a).unwrap_or(0.0));
        (f - e).abs() > 1e-12
    });
    if !turns {
        // Golden section on [0, 1] for the convex distance.
        let g = |f: f64| set.gap(model, &at(f));
        let r = (5f64.sqrt() - 1.0) / 2.0;
        let (mut lo, mut hi) = (0.0, 1.0);
        let (mut x1, mut x2) = (hi - r * (hi - lo), lo + r * (hi - lo));
        let (mut g1, mut g2) = (g(x1), g(x2));
        for _ in 0..80 {
            if g1 <= g2 {
                hi = x2;
                x2 = x1;
                g2 = g1;
                x1 = hi - r * (hi - lo);
                g1 = g(x1);
            } else {
                lo = x1;
                x1 = x2;
                g1 = g2;
                x2 = lo + r * (hi - lo);
                g2 = g(x2);
            }
        }
        let best = [0.0, (lo + hi) / 2.0, 1.0]
            .into_iter()
            .min_by(|a, b| g(*a).total_cmp(&g(*b)))
            .expect("three");
        return set.touched_at(model, &at(best)).then(|| at(best));
    }
    let span = Axis::ALL
        .iter()
        .filter_map(|a| Some((end.get(*a)? - from.get(*a)?).abs()))
        .fold(0.0, f64::max);
    let steps = ((span / PATH_STEP).ceil() as usize).clamp(1, 100_000);
    (1..=steps)
        .map(|i| at(i as f64 / steps as f64))
        .find(|p| set.touched_at(model, p))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn xyz(p: [f64; 3]) -> AxisPositions {
        AxisPositions::linear(p)
    }

    /// A sphere expected at the origin, Q407 + R = 15.5; the cycle's tolerance lets
    /// its centre stand up to 9.3 mm off in X/Y and from 2 mm below to 2 mm above.
    fn tolerance() -> SphereSet {
        SphereSet {
            base: Vector3::new(0.0, 0.0, -2.0),
            axis: Vector3::z(),
            length: 4.0,
            radial: 9.3,
            touch: 15.5,
        }
    }

    #[test]
    fn a_path_clear_of_the_nominal_sphere_but_not_of_one_within_the_tolerance_is_refused() {
        let nominal = SphereSet::one(Sphere {
            centre: Vector3::zeros(),
            touch: 15.5,
        });
        // Past the nominal sphere 17 mm off its centre, at its equator's height.
        let (a, b) = (xyz([-40.0, 17.0, 0.0]), xyz([40.0, 17.0, 0.0]));
        assert_eq!(first_touch(&nominal, None, &a, &b), None);
        // A sphere 9.3 mm off toward +Y (within the tolerance) is 7.7 mm from it.
        let hit = first_touch(&tolerance(), None, &a, &b).expect("refused");
        assert!(hit.xyz()[0].abs() < 1e-6 && hit.xyz()[1] == 17.0, "{hit:?}");
        // Nor does a path above it clear: 16 mm over the nominal pole, but the sphere
        // may stand 2 mm higher. 18 mm over it clears every one.
        let over = |z: f64| {
            first_touch(
                &tolerance(),
                None,
                &xyz([-40.0, 0.0, z]),
                &xyz([40.0, 0.0, z]),
            )
        };
        assert!(over(16.0).is_some());
        assert!(over(17.4).is_some());
        assert_eq!(over(17.6), None);
        // Out beyond the reach plus the sphere: 9.3 + 15.5 = 24.8 off the axis.
        let side = |y: f64| {
            first_touch(
                &tolerance(),
                None,
                &xyz([-40.0, y, -30.0]),
                &xyz([40.0, y, 30.0]),
            )
        };
        assert!(side(24.7).is_some());
        assert_eq!(side(24.9), None);
        // A single sphere is one set of its own, and holds itself.
        assert!(tolerance().contains(&Sphere {
            centre: Vector3::new(6.0, -7.0, 1.9),
            touch: 15.5
        }));
        assert!(!tolerance().contains(&Sphere {
            centre: Vector3::new(6.0, -7.5, 1.9),
            touch: 15.5
        }));
    }

    #[test]
    fn a_turn_is_checked_with_the_sphere_following_the_table() {
        use crate::kinematics::model::{ChainSpec, ErrorSet};
        use hal::config::MachineConfig;
        use std::path::Path;
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let text = std::fs::read_to_string(root.join("configs/machines/table-ac.toml")).unwrap();
        let cfg = MachineConfig::parse(&text, Path::new("table-ac.toml")).unwrap();
        let model = KinematicModel::new(&ChainSpec::of(&cfg), &ErrorSet::default());
        // A sphere on the table off the C axis: at C0 it is where it was put, and a
        // turn of C brings it under a probe that stands still elsewhere.
        let centre = model.table_point(&[0.0; 3], &Vector3::new(50.0, 0.0, 80.0));
        let set = SphereSet::one(Sphere {
            centre,
            touch: 15.5,
        });
        let from = xyz([-50.0, 0.0, 80.0])
            .with(Axis::A, 0.0)
            .with(Axis::C, 0.0);
        let at_c0 = model.predict(&[0.0; 3], &centre);
        assert!((at_c0 - Vector3::new(50.0, 0.0, 80.0)).norm() < 1e-9);
        let half = AxisPositions::new().with(Axis::C, 180.0);
        let hit = first_touch(&set, Some(&model), &from, &half).expect("the sphere comes round");
        let c = hit.get(Axis::C).unwrap();
        assert!(c > 0.0 && c < 180.0, "{c}");
        let quarter = AxisPositions::new().with(Axis::C, 90.0);
        assert_eq!(first_touch(&set, Some(&model), &from, &quarter), None);
    }
}
