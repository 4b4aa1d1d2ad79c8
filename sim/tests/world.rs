//! Probe physics in the world: exact latch instants, pre-travel, noise, backlash,
//! deflected at start, rotary moves.

mod common;

use common::{pos, scenario};
use hal::{Axis, AxisPositions};
use nalgebra::Vector3;
use probebridge_sim::backlash::Backlash;
use probebridge_sim::probe::Probe;
use probebridge_sim::scenario::ProbeTruth;
use probebridge_sim::World;

const PLANE: &str = "[[plane]]\npoint = [0.0, 0.0, 10.0]\nnormal = [0.0, 0.0, 1.0]\n";

fn probe_section(pretravel: f64, noise: f64) -> String {
    format!("seed = 42\n[probe]\nball_radius = 3.0\npretravel = {pretravel}\nnoise = {noise}\n")
}

fn z(v: f64) -> AxisPositions {
    pos([5.0, -5.0, v], &[(Axis::A, 0.0), (Axis::C, 0.0)])
}

/// Moves down from z0 to z1 in one step; the z of the latch.
fn probe_down(world: &mut World, z0: f64, z1: f64) -> Option<f64> {
    world.step(&z(z0), &z(z1)).map(|f| z0 + f * (z1 - z0))
}

#[test]
fn plane_latch_is_exact_and_pretravel_shifts_it_by_p() {
    let mut ideal = World::new(&scenario("table-ac", &(probe_section(0.0, 0.0) + PLANE)));
    let at = probe_down(&mut ideal, 20.0, 0.0).unwrap();
    assert!((at - 13.0).abs() < 1e-9, "{at}");
    let p = 0.037;
    let mut w = World::new(&scenario("table-ac", &(probe_section(p, 0.0) + PLANE)));
    let at_p = probe_down(&mut w, 20.0, 0.0).unwrap();
    assert!((at - at_p - p).abs() < 1e-9, "{at} vs {at_p}");
}

#[test]
fn contact_split_over_many_steps_latches_once_at_the_same_place() {
    let mut w = World::new(&scenario("table-ac", &(probe_section(0.0, 0.0) + PLANE)));
    let mut edges = vec![];
    let (mut zz, dz) = (14.0, -0.0137);
    while zz > 12.0 {
        if let Some(f) = w.step(&z(zz), &z(zz + dz)) {
            edges.push(zz + f * dz);
        }
        zz += dz;
    }
    assert_eq!(edges.len(), 1);
    assert!((edges[0] - 13.0).abs() < 1e-9);
    assert!(w.deflected(&z(zz)));
    assert!(w.penetration(&z(zz)) > 0.9);
    // Retract and come back: released and latched again.
    assert_eq!(w.step(&z(zz), &z(20.0)), None);
    assert!(!w.deflected(&z(20.0)));
    assert_eq!(w.penetration(&z(20.0)), 0.0);
    let again = probe_down(&mut w, 20.0, 0.0).unwrap();
    assert!((again - 13.0).abs() < 1e-9);
}

#[test]
fn sphere_latch_from_several_directions() {
    let body =
        probe_section(0.0, 0.0) + "[[sphere]]\ncenter = [50.0, -30.0, 80.0]\nradius = 12.5\n";
    let c = Vector3::new(50.0, -30.0, 80.0);
    for dir in [
        Vector3::new(0.0, 0.0, 1.0),
        Vector3::new(1.0, 0.0, 0.0),
        Vector3::new(0.0, -1.0, 0.0),
        Vector3::new(-1.0, 1.0, 1.0).normalize(),
    ] {
        let mut w = World::new(&scenario("table-ac", &body));
        let start = c + dir * 30.0;
        let end = c + dir * 10.0;
        let p = |v: Vector3<f64>| pos([v.x, v.y, v.z], &[(Axis::A, 0.0), (Axis::C, 0.0)]);
        let f = w.step(&p(start), &p(end)).unwrap();
        let hit = start + (end - start) * f;
        assert!(((hit - c).norm() - 15.5).abs() < 1e-9);
    }
}

#[test]
fn deflected_at_start_gives_no_edge() {
    let mut w = World::new(&scenario("table-ac", &(probe_section(0.0, 0.0) + PLANE)));
    assert!(w.deflected(&z(12.0)));
    assert!(!w.deflected(&z(13.5)));
    assert_eq!(w.step(&z(12.0), &z(11.0)), None);
    assert!(w.deflected(&z(11.0)));
    assert!((w.penetration(&z(11.0)) - 2.0).abs() < 1e-12);
}

#[test]
fn a_jump_into_the_material_between_steps_rises_at_zero() {
    let mut w = World::new(&scenario("table-ac", &(probe_section(0.0, 0.0) + PLANE)));
    assert_eq!(w.step(&z(30.0), &z(25.0)), None);
    assert_eq!(w.step(&z(12.0), &z(11.5)), Some(0.0));
}

#[test]
fn noise_is_reproducible_with_the_right_sigma() {
    let truth = ProbeTruth {
        noise: 0.002,
        ..ProbeTruth::ideal(3.0)
    };
    let draws = |seed| {
        let mut p = Probe::new(&truth, seed);
        (0..10_000).map(|_| p.draw_noise()).collect::<Vec<f64>>()
    };
    let a = draws(7);
    assert_eq!(a, draws(7));
    assert_ne!(a, draws(8));
    let mean = a.iter().sum::<f64>() / a.len() as f64;
    let sd = (a.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (a.len() - 1) as f64).sqrt();
    assert!(mean.abs() < 0.0001, "{mean}");
    assert!((sd / 0.002 - 1.0).abs() < 0.03, "{sd}");
    // Without noise nothing is drawn.
    let mut p = Probe::new(
        &ProbeTruth {
            noise: 0.0,
            ..truth
        },
        7,
    );
    assert_eq!(p.draw_noise(), 0.0);
}

#[test]
fn contacts_scatter_by_the_noise_one_draw_per_contact() {
    let sigma = 0.003;
    let run = || {
        let mut w = World::new(&scenario("table-ac", &(probe_section(0.0, sigma) + PLANE)));
        (0..2000)
            .map(|_| {
                let at = probe_down(&mut w, 20.0, 0.0).expect("contact");
                assert_eq!(w.step(&z(0.0), &z(20.0)), None, "retract re-triggered");
                at
            })
            .collect::<Vec<f64>>()
    };
    let a = run();
    assert_eq!(a, run(), "same seed, same contacts");
    let mean = a.iter().sum::<f64>() / a.len() as f64;
    let sd = (a.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (a.len() - 1) as f64).sqrt();
    assert!((mean - 13.0).abs() < 0.0004, "{mean}");
    assert!((sd / sigma - 1.0).abs() < 0.08, "{sd}");
}

#[test]
fn slow_retract_with_noise_never_retriggers() {
    let mut w = World::new(&scenario("table-ac", &(probe_section(0.0, 0.01) + PLANE)));
    let mut contacts = 0;
    for _ in 0..50 {
        contacts += probe_down(&mut w, 13.1, 12.9).is_some() as usize;
        // Steps far below sigma: a release followed by a larger draw is common here.
        for i in 0..200 {
            let zz = 12.9 + i as f64 * 0.001;
            assert_eq!(w.step(&z(zz), &z(zz + 0.001)), None);
        }
    }
    assert_eq!(contacts, 50);
}

#[test]
fn backlash_dead_band() {
    let mut b = Backlash::new(0.2);
    assert_eq!(b.update(10.0), 10.0);
    assert!(
        (b.update(10.5) - 10.4).abs() < 1e-12,
        "trails by b/2 going up"
    );
    assert!(
        (b.update(10.35) - 10.4).abs() < 1e-12,
        "inside the band: stays"
    );
    assert!((b.update(10.3) - 10.4).abs() < 1e-12);
    assert!(
        (b.update(10.0) - 10.1).abs() < 1e-12,
        "trails by b/2 going down"
    );
    assert!((b.mechanical(12.0) - 11.9).abs() < 1e-12);
    assert!(
        (b.state().unwrap() - 10.1).abs() < 1e-12,
        "mechanical() changes nothing"
    );
}

#[test]
fn backlash_in_the_world_shifts_the_sphere_by_the_band() {
    let body = probe_section(0.0, 0.0)
        + "[truth]\nbacklash_C = 0.02\n[[sphere]]\ncenter = [100.0, 0.0, 50.0]\nradius = 12.5\n";
    let mut w = World::new(&scenario("table-ac", &body));
    let at = |c: f64| pos([0.0, 0.0, 0.0], &[(Axis::A, 0.0), (Axis::C, c)]);
    w.step(&at(0.0), &at(0.0));
    // Approach 30 deg from above, then from below.
    w.step(&at(0.0), &at(30.5));
    w.step(&at(30.5), &at(30.0));
    let from_above = w
        .kinematics()
        .table_to_machine(&w.mechanical(&at(30.0)), Vector3::new(100.0, 0.0, 50.0));
    w.step(&at(30.0), &at(29.5));
    w.step(&at(29.5), &at(30.0));
    let from_below = w
        .kinematics()
        .table_to_machine(&w.mechanical(&at(30.0)), Vector3::new(100.0, 0.0, 50.0));
    let angle = (from_above - from_below).norm() / 100.0;
    assert!(
        (angle.to_degrees() - 0.02).abs() < 1e-6,
        "{}",
        angle.to_degrees()
    );
    // The encoder positions stay what was commanded: mechanical C differs by b/2.
    assert!((w.mechanical(&at(30.0)).get(Axis::C).unwrap() - 29.99).abs() < 1e-12);
}

#[test]
fn hirth_grid_snaps_the_physical_angle() {
    let body = probe_section(0.0, 0.0) + "[truth]\nhirth_C = 1.0\n";
    let w = World::new(&scenario("table-ac", &body));
    let m = w.mechanical(&pos([0.0; 3], &[(Axis::C, 30.4)]));
    assert_eq!(m.get(Axis::C), Some(30.0));
}

#[test]
fn rotary_move_latches_where_the_sphere_reaches_the_ball() {
    // Sphere at radius 100 on the C table; the ball waits at machine (x, y) beside it.
    let body = probe_section(0.0, 0.0)
        + "[truth]\nEX0C = 0.01\n[[sphere]]\ncenter = [100.0, 0.0, 50.0]\nradius = 12.5\n";
    let mut w = World::new(&scenario("table-ac", &body));
    let ball = [
        100.0 * 20f64.to_radians().cos(),
        100.0 * 20f64.to_radians().sin(),
        50.0,
    ];
    let at = |c: f64| pos(ball, &[(Axis::A, 0.0), (Axis::C, c)]);
    let f = w.step(&at(0.0), &at(25.0)).unwrap();
    let c = 25.0 * f;
    // At the latch angle the centre is at R from the sphere (chord error only).
    let d = (w.ball_centre_in_table(&at(c)) - Vector3::new(100.0, 0.0, 50.0)).norm();
    assert!((d - 15.5).abs() < 1e-7, "{d}");
    assert!(w.deflected(&at(25.0)));
}

#[test]
fn a_latch_inside_a_step_matches_stepping_finely() {
    let body =
        probe_section(0.0, 0.0) + "[[sphere]]\ncenter = [50.0, -30.0, 80.0]\nradius = 12.5\n";
    let sc = scenario("table-ac", &body);
    let from = pos(
        [50.0 + 20.0, -30.0, 80.0 + 6.0],
        &[(Axis::A, 0.0), (Axis::C, 0.0)],
    );
    let to = pos([50.0, -30.0, 80.0 + 6.0], &[(Axis::A, 0.0), (Axis::C, 0.0)]);
    let f = World::new(&sc).step(&from, &to).unwrap();
    let x = 70.0 - 20.0 * f;
    assert!(((x - 50.0).powi(2) + 36.0 - 15.5 * 15.5).abs() < 1e-9);
}
