//! The real stylus in the world: the three lobes and the axial pre-travel set where a
//! contact latches, the offset and the length move the ball centre, and both turn
//! with the spindle. Expected values from the scenario keys' definition.

mod common;

use common::{pos, scenario};
use hal::{Axis, AxisPositions};
use probebridge_sim::World;

const STYLUS: &str = "[probe]\nball_radius = 3.0\npretravel = 0.005\npretravel_axial = 0.008\nlobing = 0.004\nlobing_phase = 20.0\noffset = [0.003, -0.001]\nlength_error = 0.002\n";

fn at(x: f64, y: f64, z: f64) -> AxisPositions {
    pos([x, y, z], &[(Axis::A, 0.0), (Axis::C, 0.0)])
}

/// Probes along `dir` (unit, in X/Y/Z) from `from` over `len` mm in one step; the axes
/// at the latch.
fn probe(w: &mut World, from: [f64; 3], dir: [f64; 3], len: f64) -> [f64; 3] {
    let to = [0, 1, 2].map(|i| from[i] + dir[i] * len);
    let f = w
        .step(&at(from[0], from[1], from[2]), &at(to[0], to[1], to[2]))
        .expect("the probe triggers");
    [0, 1, 2].map(|i| from[i] + dir[i] * len * f)
}

/// A vertical face at X = 0 (material at X < 0) probed along -X: the contact pushes
/// the ball along +X (azimuth 0); with the spindle at `spindle` the stylus's lobes
/// and offset have turned by it.
fn lateral_latch(spindle: f64) -> f64 {
    let sc = scenario(
        "table-ac",
        &format!("{STYLUS}[[plane]]\npoint = [0.0, 0.0, 0.0]\nnormal = [1.0, 0.0, 0.0]\n"),
    );
    let mut w = World::new(&sc);
    w.orient_spindle(spindle);
    probe(&mut w, [10.0, 0.0, 50.0], [-1.0, 0.0, 0.0], 10.0)[0]
}

#[test]
fn lobes_and_offset_set_the_lateral_latch_and_turn_with_the_spindle() {
    for spindle in [0.0f64, 90.0, 180.0, 33.0] {
        // In the stylus frame the contact pushes along azimuth -spindle.
        let az = (-spindle).to_radians();
        let lobe = 0.004 * (3.0 * (az - 20f64.to_radians())).cos();
        let offset_x = {
            let (s, c) = spindle.to_radians().sin_cos();
            0.003 * c - (-0.001) * s
        };
        // The true centre sits R - p(u) off the face; the axes are the centre less the offset.
        let want = 3.0 - (0.005 + lobe) - offset_x;
        let got = lateral_latch(spindle);
        assert!(
            (got - want).abs() < 1e-9,
            "spindle {spindle}°: latched at X {got}, the stylus's definition gives {want}"
        );
    }
}

#[test]
fn axial_pretravel_and_length_set_the_latch_along_the_stylus() {
    let sc = scenario(
        "table-ac",
        &format!("{STYLUS}[[plane]]\npoint = [0.0, 0.0, 10.0]\nnormal = [0.0, 0.0, 1.0]\n"),
    );
    let mut w = World::new(&sc);
    let z = probe(&mut w, [5.0, -5.0, 20.0], [0.0, 0.0, -1.0], 10.0)[2];
    // Centre at 10 + R - p_ax; the ball lies 0.002 below the axes' Z.
    let want = 10.0 + 3.0 - 0.008 + 0.002;
    assert!((z - want).abs() < 1e-9, "{z} vs {want}");
}

#[test]
fn a_sphere_probed_in_a_tilted_direction_blends_axial_and_lateral() {
    let sc = scenario(
        "table-ac",
        &format!("{STYLUS}[[sphere]]\ncenter = [0.0, 0.0, 0.0]\nradius = 10.0\n"),
    );
    let mut w = World::new(&sc);
    // Toward the centre from the direction u = (0.6, 0, 0.8): s² = 0.64, azimuth 0.
    let u = [0.6, 0.0, 0.8];
    let shift = [0.003, -0.001, -0.002];
    // Aim the true centre at the sphere centre: the axes go along -u from 20 u - shift.
    let from = [0, 1, 2].map(|i| 20.0 * u[i] - shift[i]);
    let c = probe(&mut w, from, [-0.6, 0.0, -0.8], 10.0);
    let true_centre = [0, 1, 2].map(|i| c[i] + shift[i]);
    let dist = true_centre.iter().map(|v| v * v).sum::<f64>().sqrt();
    let lobe = 0.004 * (3.0 * (0.0 - 20f64.to_radians())).cos();
    let p = 0.64 * 0.008 + 0.36 * (0.005 + lobe);
    let want = 10.0 + 3.0 - p;
    assert!((dist - want).abs() < 1e-9, "{dist} vs {want}");
}

#[test]
fn keys_out_of_range_are_refused_with_the_key() {
    for (text, key) in [
        (
            "[probe]\nball_radius = 3.0\npretravel = 0.001\nlobing = 0.002\n",
            "probe.lobing",
        ),
        (
            "[probe]\nball_radius = 3.0\noffset = [2.0, 0.0]\n",
            "probe.offset[0]",
        ),
        (
            "[probe]\nball_radius = 3.0\nlength_error = 9.0\n",
            "probe.length_error",
        ),
        ("[probe]\nball_radius = 3.0\naxis = \"W\"\n", "probe.axis"),
        (
            "[probe]\nball_radius = 3.0\npretravel_axial = -0.1\n",
            "probe.pretravel_axial",
        ),
    ] {
        let e = common::scenario_error(text);
        assert!(e.contains(key), "{text}: {e}");
    }
}
