//! The true kinematic chain and its error convention.

mod common;

use common::{machine, pos};
use hal::Axis;
use nalgebra::Vector3;
use probebridge_sim::kinematics::TrueKinematics;
use probebridge_sim::scenario::Truth;

const EPS: f64 = 1e-9;

fn v(x: f64, y: f64, z: f64) -> Vector3<f64> {
    Vector3::new(x, y, z)
}

fn close(a: Vector3<f64>, b: Vector3<f64>) {
    assert!((a - b).norm() < EPS, "{a} != {b}");
}

fn truth(pairs: &[(&str, f64)]) -> Truth {
    let mut t = Truth::default();
    for (k, val) in pairs {
        assert!(t.set(k, *val), "{k}");
    }
    t
}

#[test]
fn zero_errors_identity_at_zero() {
    for name in ["table-ac", "head-b-table-c"] {
        let k = TrueKinematics::nominal(&machine(name));
        let axes = pos(
            [12.0, -7.0, 33.0],
            &[(Axis::A, 0.0), (Axis::B, 0.0), (Axis::C, 0.0)],
        );
        close(k.ball_centre_in_table(&axes), v(12.0, -7.0, 33.0));
        close(
            k.table_to_machine(&axes, v(1.0, 2.0, 3.0)),
            v(1.0, 2.0, 3.0),
        );
    }
    // Location errors alone do not move anything at all-zero angles either.
    let t = truth(&[
        ("EX0C", 0.3),
        ("EY0C", -0.2),
        ("EA0C", 0.1),
        ("EB0A", 0.2),
        ("EZ0A", 1.0),
    ]);
    let k = TrueKinematics::new(&machine("table-ac"), &t);
    let axes = pos([12.0, -7.0, 33.0], &[(Axis::A, 0.0), (Axis::C, 0.0)]);
    close(k.ball_centre_in_table(&axes), v(12.0, -7.0, 33.0));
}

#[test]
fn c90_turns_x_into_y_on_table_ac() {
    let k = TrueKinematics::nominal(&machine("table-ac"));
    let axes = pos([0.0; 3], &[(Axis::A, 0.0), (Axis::C, 90.0)]);
    close(
        k.table_to_machine(&axes, v(10.0, 0.0, 0.0)),
        v(0.0, 10.0, 0.0),
    );
    close(
        k.machine_to_table(&axes, v(0.0, 10.0, 0.0)),
        v(10.0, 0.0, 0.0),
    );
    // The ball at machine (0, 10, 0) is at table (10, 0, 0).
    close(
        k.ball_centre_in_table(&pos([0.0, 10.0, 0.0], &[(Axis::C, 90.0)])),
        v(10.0, 0.0, 0.0),
    );
}

#[test]
fn table_chain_order_is_bed_first() {
    // machine = T_A(90) T_C(90) p: C turns (10,0,0) to (0,10,0), then A lifts it to (0,0,10).
    let k = TrueKinematics::nominal(&machine("table-ac"));
    let axes = pos([0.0; 3], &[(Axis::A, 90.0), (Axis::C, 90.0)]);
    close(
        k.table_to_machine(&axes, v(10.0, 0.0, 0.0)),
        v(0.0, 0.0, 10.0),
    );
    let p = v(3.0, -4.0, 5.0);
    close(k.machine_to_table(&axes, k.table_to_machine(&axes, p)), p);
}

#[test]
fn head_chain_pivots_relative_to_the_ball() {
    // B pivots 250 above the ball: at B = 90 the ball swings to (-250, 0, 250) relative.
    let k = TrueKinematics::nominal(&machine("head-b-table-c"));
    let axes = pos([10.0, 20.0, 30.0], &[(Axis::B, 90.0), (Axis::C, 0.0)]);
    close(
        k.ball_centre_in_machine(&axes),
        v(10.0 - 250.0, 20.0, 30.0 + 250.0),
    );
    let axes = axes.with(Axis::C, 90.0);
    close(k.ball_centre_in_table(&axes), v(20.0, 240.0, 280.0));
}

#[test]
fn ex0c_is_recovered_as_the_circle_centre() {
    let (ex, ey) = (0.037, -0.021);
    let t = truth(&[("EX0C", ex), ("EY0C", ey)]);
    let k = TrueKinematics::new(&machine("table-ac"), &t);
    let p = v(100.0, 20.0, 50.0);
    let pts: Vec<_> = [0.0, 90.0, 180.0, 270.0]
        .iter()
        .map(|&c| k.table_to_machine(&pos([0.0; 3], &[(Axis::A, 0.0), (Axis::C, c)]), p))
        .collect();
    let centre = pts.iter().sum::<Vector3<f64>>() / 4.0;
    close(centre, v(ex, ey, 50.0));
    // Equal radii about that centre: a circle, not an ellipse.
    let r0 = (pts[0] - centre).norm();
    for q in &pts {
        assert!(((q - centre).norm() - r0).abs() < EPS);
    }
    // The nominal model sees a shift of 2*EX0C between C=0 and C=180 for the same point.
    let nominal = TrueKinematics::nominal(&machine("table-ac"));
    let c180 = pos([0.0; 3], &[(Axis::C, 180.0)]);
    close(
        k.table_to_machine(&c180, p) - nominal.table_to_machine(&c180, p),
        v(2.0 * ex, 2.0 * ey, 0.0),
    );
}

#[test]
fn orientation_errors_follow_the_qs_order() {
    let (a, b, c) = (0.7f64, -0.4f64, 1.1f64);
    let (ra, rb, rc) = (a.to_radians(), b.to_radians(), c.to_radians());
    let cases = [
        // A: d = Ry(EB0A) Rz(EC0A) x
        (
            Axis::A,
            "EB0A",
            b,
            "EC0A",
            c,
            v(rb.cos() * rc.cos(), rc.sin(), -rb.sin() * rc.cos()),
        ),
        // B: d = Rz(EC0B) Rx(EA0B) y
        (
            Axis::B,
            "EC0B",
            c,
            "EA0B",
            a,
            v(-rc.sin() * ra.cos(), rc.cos() * ra.cos(), ra.sin()),
        ),
        // C: d = Rx(EA0C) Ry(EB0C) z
        (
            Axis::C,
            "EA0C",
            a,
            "EB0C",
            b,
            v(rb.sin(), -ra.sin() * rb.cos(), ra.cos() * rb.cos()),
        ),
    ];
    for (axis, k0, v0, k1, v1, expect) in cases {
        let cfg = machine(if axis == Axis::B {
            "head-b-table-c"
        } else {
            "table-ac"
        });
        let k = TrueKinematics::new(&cfg, &truth(&[(k0, v0), (k1, v1)]));
        let j = k.joint(axis).unwrap();
        close(j.direction.into_inner(), expect);
        // The true axis line stays fixed when the axis turns.
        let on_line = j.point + j.direction.into_inner() * 80.0;
        let turned = j.transform(37.0) * nalgebra::Point3::from(on_line);
        close(turned.coords, on_line);
    }
}

#[test]
fn zero_error_turns_the_table_at_zero() {
    let t = truth(&[("EC0C", 0.5)]);
    let k = TrueKinematics::new(&machine("table-ac"), &t);
    let p = v(100.0, 0.0, 0.0);
    let r = 0.5f64.to_radians();
    close(
        k.table_to_machine(&pos([0.0; 3], &[(Axis::A, 0.0), (Axis::C, 0.0)]), p),
        v(100.0 * r.cos(), 100.0 * r.sin(), 0.0),
    );
    // Same as the nominal table at C = 0.5.
    let nominal = TrueKinematics::nominal(&machine("table-ac"));
    close(
        k.table_to_machine(&pos([0.0; 3], &[(Axis::C, 30.0)]), p),
        nominal.table_to_machine(&pos([0.0; 3], &[(Axis::C, 30.5)]), p),
    );
}

#[test]
fn head_position_error_moves_the_pivot() {
    // B line through (EX0B, 0, 250 + EZ0B): at B = 180 the ball lands at 2 * pivot.
    let t = truth(&[("EX0B", 0.02), ("EZ0B", -0.01)]);
    let k = TrueKinematics::new(&machine("head-b-table-c"), &t);
    let c = k.ball_centre_in_machine(&pos([0.0; 3], &[(Axis::B, 180.0)]));
    close(c, v(0.04, 0.0, 2.0 * (250.0 - 0.01)));
}
