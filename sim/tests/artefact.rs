//! Exact segment contacts with plane, sphere and cylinder.

use nalgebra::Vector3;
use probebridge_sim::artefact::{Artefact, ArtefactSet, Cylinder, Plane, Sphere, Surface};

const EPS: f64 = 1e-9;

fn v(x: f64, y: f64, z: f64) -> Vector3<f64> {
    Vector3::new(x, y, z)
}

fn at(c0: &Vector3<f64>, c1: &Vector3<f64>, t: f64) -> Vector3<f64> {
    c0 + (c1 - c0) * t
}

/// The solved `t` puts the point at distance `r`, and an instant before it was farther.
fn check_entry<S: Surface>(
    s: &S,
    c0: Vector3<f64>,
    c1: Vector3<f64>,
    r: f64,
    expect: Vector3<f64>,
) {
    let t = s.first_entry(&c0, &c1, r).expect("no contact");
    let p = at(&c0, &c1, t);
    assert!(
        (p - expect).norm() < EPS,
        "contact at {p} instead of {expect}"
    );
    assert!((s.distance(&p) - r).abs() < EPS);
    assert_eq!(s.first_reach(&c0, &c1, r), Some(t));
    if t > 1e-6 {
        assert!(s.distance(&at(&c0, &c1, t - 1e-6)) > r);
    }
}

#[test]
fn plane_contacts_from_several_directions() {
    let plane = Plane::new(v(1.0, 2.0, 10.0), v(0.0, 0.0, 2.0)).unwrap();
    assert!((plane.distance(&v(7.0, -3.0, 13.0)) - 3.0).abs() < EPS);
    assert!(plane.distance(&v(0.0, 0.0, 5.0)) < 0.0, "material below");
    // Perpendicular, oblique, and starting exactly on the contact distance.
    check_entry(
        &plane,
        v(0.0, 0.0, 20.0),
        v(0.0, 0.0, 0.0),
        3.0,
        v(0.0, 0.0, 13.0),
    );
    check_entry(
        &plane,
        v(-5.0, 4.0, 23.0),
        v(5.0, -4.0, 3.0),
        3.0,
        v(0.0, 0.0, 13.0),
    );
    check_entry(
        &plane,
        v(1.0, 1.0, 13.0),
        v(1.0, 1.0, 12.0),
        3.0,
        v(1.0, 1.0, 13.0),
    );
    // Parallel, moving away, or stopping short: no entry.
    assert_eq!(
        plane.first_entry(&v(0.0, 0.0, 20.0), &v(9.0, 0.0, 20.0), 3.0),
        None
    );
    assert_eq!(
        plane.first_entry(&v(0.0, 0.0, 12.0), &v(0.0, 0.0, 20.0), 3.0),
        None
    );
    assert_eq!(
        plane.first_entry(&v(0.0, 0.0, 20.0), &v(0.0, 0.0, 13.5), 3.0),
        None
    );
    // Leaving the contact zone is a reach but not an entry.
    let t = plane
        .first_reach(&v(0.0, 0.0, 12.0), &v(0.0, 0.0, 14.0), 3.0)
        .unwrap();
    assert!((t - 0.5).abs() < EPS);

    // A tilted plane, approached along its normal and sideways.
    let n = v(1.0, -2.0, 2.0) / 3.0;
    let plane = Plane::new(v(5.0, 5.0, 5.0), n * 7.0).unwrap();
    let foot = v(5.0, 5.0, 5.0);
    check_entry(
        &plane,
        foot + n * 10.0,
        foot - n * 10.0,
        2.5,
        foot + n * 2.5,
    );
    let side = v(0.0, 1.0, 1.0); // perpendicular to n
                                 // Reaches 2.5 three quarters of the way: sideways offset -7.5 + 0.75 * 15 = 3.75.
    check_entry(
        &plane,
        foot + n * 10.0 - side * 7.5,
        foot + side * 7.5,
        2.5,
        foot + n * 2.5 + side * 3.75,
    );
}

#[test]
fn sphere_contacts_from_several_directions() {
    let c = v(50.0, -30.0, 80.0);
    let s = Sphere::new(c, 12.5).unwrap();
    let r = 3.0;
    for dir in [
        v(0.0, 0.0, 1.0),
        v(1.0, 0.0, 0.0),
        v(0.0, -1.0, 0.0),
        v(-1.0, 1.0, 0.5).normalize(),
        v(0.3, -0.2, -0.9).normalize(),
    ] {
        check_entry(&s, c + dir * 40.0, c, r, c + dir * 15.5);
        // Stop short of the sphere: nothing.
        assert_eq!(s.first_entry(&(c + dir * 40.0), &(c + dir * 15.6), r), None);
    }
    // Off-centre line: chord at height h from the centre touches where |p - c| = 15.5.
    let h = 9.0;
    let c0 = c + v(-40.0, h, 0.0);
    let c1 = c + v(40.0, h, 0.0);
    let x = -(15.5f64 * 15.5 - h * h).sqrt();
    check_entry(&s, c0, c1, r, c + v(x, h, 0.0));
    // Passing by at more than R + r: no contact.
    assert_eq!(
        s.first_entry(&(c + v(-40.0, 15.6, 0.0)), &(c + v(40.0, 15.6, 0.0)), r),
        None
    );
    // Grazing exactly is not an entry.
    let (g0, g1) = (c + v(-40.0, 15.5, 0.0), c + v(40.0, 15.5, 0.0));
    assert_eq!(s.first_entry(&g0, &g1, r), None);
    // From inside the contact zone the first reach is the exit.
    let t = s.first_reach(&c, &(c + v(0.0, 0.0, 31.0)), r).unwrap();
    assert!((t - 0.5).abs() < EPS);
    assert_eq!(s.first_entry(&c, &(c + v(0.0, 0.0, 31.0)), r), None);
}

#[test]
fn cylinder_contacts_from_several_directions() {
    let axis_point = v(60.0, 0.0, 20.0);
    let cyl = Cylinder::new(axis_point, v(0.0, 3.0, 0.0), 15.0).unwrap();
    let r = 3.0;
    for (dir, y) in [
        (v(0.0, 0.0, 1.0), 0.0),
        (v(1.0, 0.0, 0.0), 17.0),
        (v(-1.0, 0.0, 0.0), -250.0),
        (v(1.0, 0.0, 1.0).normalize(), 3.5),
    ] {
        let foot = axis_point + v(0.0, y, 0.0);
        check_entry(&cyl, foot + dir * 50.0, foot, r, foot + dir * 18.0);
    }
    // A path with an axial component: only the radial part matters.
    let foot = axis_point + v(0.0, 10.0, 0.0);
    let c0 = foot + v(0.0, -30.0, 48.0);
    let c1 = foot + v(0.0, 10.0, -32.0);
    // z goes 48 -> -32 over t in [0,1]; radial distance 18 at z = 18: t = 30/80.
    let t = 30.0 / 80.0;
    check_entry(&cyl, c0, c1, r, at(&c0, &c1, t));
    // Moving along the axis: never reaches.
    assert_eq!(
        cyl.first_entry(&(foot + v(0.0, 0.0, 30.0)), &(foot + v(0.0, 99.0, 30.0)), r),
        None
    );
    assert!((cyl.distance(&(foot + v(0.0, 0.0, 15.0)))).abs() < EPS);
}

#[test]
fn set_takes_the_earliest_entry_and_nearest_surface() {
    let set = ArtefactSet::new(vec![
        Artefact::Plane(Plane::new(v(0.0, 0.0, 0.0), v(0.0, 0.0, 1.0)).unwrap()),
        Artefact::Sphere(Sphere::new(v(0.0, 0.0, 30.0), 10.0).unwrap()),
    ]);
    // Coming down onto the sphere's pole: the sphere comes first.
    let t = set
        .first_entry(&v(0.0, 0.0, 60.0), &v(0.0, 0.0, 0.0), 3.0)
        .unwrap();
    assert!((t - (60.0 - 43.0) / 60.0).abs() < EPS);
    assert!(
        (set.distance(&v(0.0, 0.0, 25.0)) + 5.0).abs() < EPS,
        "inside sphere"
    );
    assert_eq!(
        ArtefactSet::default().distance(&v(0.0, 0.0, 0.0)),
        f64::INFINITY
    );
    assert!(Plane::new(v(0.0, 0.0, 0.0), v(0.0, 0.0, 0.0)).is_none());
    assert!(Sphere::new(v(0.0, 0.0, 0.0), 0.0).is_none());
    assert!(Cylinder::new(v(0.0, 0.0, 0.0), v(0.0, 0.0, 0.0), 1.0).is_none());
}
