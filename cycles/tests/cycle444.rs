//! Cycle 444 on analytic surfaces: Q151..Q164 and Q183 in closed form, Q309.

mod common;

use common::{MockMachine, Surface};
use nalgebra::Vector3;
use probebridge_cycles::{Program, Status};

fn block(n: u32, p: [f64; 3], normal: [f64; 3], tol: &str, q309: u8) -> String {
    format!(
        "{n} TCH PROBE 444 PROBING 3D ~\n  Q263={:+} ~\n  Q264={:+} ~\n  Q294={:+} ~\n  Q581={:+} ~\n  Q582={:+} ~\n  Q583={:+} ~\n  Q320=+1 ~\n  Q260=+200 ~\n  QS400=\"{tol}\" ~\n  Q309=+{q309}\n",
        p[0], p[1], p[2], normal[0], normal[1], normal[2]
    )
}

fn program(blocks: &[String]) -> Program {
    let text = format!(
        "0 BEGIN PGM P MM\n1 TOOL CALL \"TOUCH_PROBE\" Z\n{}99 END PGM P MM\n",
        blocks.concat()
    );
    Program::parse(&text, &common::config()).unwrap_or_else(|e| panic!("{e}\n{text}"))
}

/// A plane through P + delta*n with normal n: Q164 must be delta.
fn offset_plane(p: [f64; 3], normal: [f64; 3], delta: f64) -> Surface {
    let n = Vector3::from(normal).normalize();
    Surface::Plane {
        point: Vector3::from(p) + n * delta,
        normal: n,
    }
}

#[test]
fn deviations_along_oblique_normals() {
    let cases = [
        ([10.0, 20.0, 5.0], [0.0, 0.0, 1.0], 0.3),
        ([10.0, 20.0, 5.0], [1.0, 0.0, 0.0], -0.2),
        ([-30.0, 4.0, 12.0], [1.0, 1.0, 1.0], 0.123456),
        ([0.0, 0.0, 0.0], [-2.0, 0.5, 3.0], -0.75),
        ([5.0, -5.0, 40.0], [0.0, -7.0, 1.0], 1.5),
    ];
    for (p, normal, delta) in cases {
        let prog = program(&[block(10, p, normal, " ", 0)]);
        let mut m = MockMachine::new(vec![offset_plane(p, normal, delta)]);
        let (report, _) = common::run(&prog, &mut m, &common::temp_dir("444-oblique"), true);
        let r = &report.cycles[0];
        assert_eq!(r.status, Status::Ok, "{:?}", r.message);
        let q = &r.q;
        assert!(
            (q["Q164"] - delta).abs() < 1e-6,
            "{p:?} {normal:?}: {}",
            q["Q164"]
        );
        let n = Vector3::from(normal).normalize();
        // The nearest surface point along the normal is P + delta*n.
        let a = Vector3::from(p) + n * delta;
        for (i, (qa, qd)) in [("Q151", "Q161"), ("Q152", "Q162"), ("Q153", "Q163")]
            .into_iter()
            .enumerate()
        {
            assert!((q[qa] - a[i]).abs() < 1e-6, "{qa}");
            assert!((q[qd] - delta * n[i]).abs() < 1e-6, "{qd}");
        }
        assert_eq!(q["Q183"], -1.0);
        // Probing toward the point against the normal, at most R+SET_UP+Q320+DIST.
        let mv = m.probes[0];
        assert!((Vector3::from(mv.direction) + n).norm() < 1e-12);
        assert!((mv.max_distance - (3.0 + 2.0 + 1.0 + 10.0)).abs() < 1e-12);
        assert!((mv.feed - 100.0).abs() < 1e-12);
    }
}

#[test]
fn sequence_safe_height_preposition_probe_retract_safe_height() {
    let p = [10.0, 20.0, 5.0];
    let n = [0.0, 0.6, 0.8];
    let prog = program(&[block(10, p, n, " ", 0)]);
    let mut m = MockMachine::new(vec![offset_plane(p, n, 0.0)]);
    m.pos = [100.0, 100.0, 50.0];
    let (report, _) = common::run(&prog, &mut m, &common::temp_dir("444-seq"), true);
    assert_eq!(report.cycles[0].status, Status::Ok);
    let start = Vector3::from(p) + Vector3::from(n) * (3.0 + 2.0 + 1.0);
    let contact = Vector3::from(p) + Vector3::from(n) * 3.0;
    let retract = contact + Vector3::from(n) * 5.0;
    let moves: Vec<[f64; 3]> = m.moves.iter().map(|(t, _)| *t).collect();
    let close = |a: [f64; 3], b: [f64; 3]| (Vector3::from(a) - Vector3::from(b)).norm() < 1e-9;
    let expected = [
        [100.0, 100.0, 200.0],
        [start.x, start.y, 200.0],
        start.into(),
        retract.into(),
        [retract.x, retract.y, 200.0],
    ];
    assert_eq!(moves.len(), expected.len(), "{moves:?}");
    for (got, want) in moves.iter().zip(expected) {
        assert!(close(*got, want), "{got:?} != {want:?}");
    }
    assert!(
        m.moves.iter().all(|(_, f)| *f == 3000.0),
        "positioning at FMAX"
    );
}

#[test]
fn sphere_and_cylinder_points() {
    let c = Vector3::new(0.0, 0.0, 20.0);
    let n = Vector3::new(1.0, 2.0, 2.0) / 3.0;
    let delta = -0.05;
    // Nominal on a sphere of radius 25.05: the real one (25) is 0.05 undersize.
    let p = c + n * (25.0 - delta);
    let prog = program(&[block(10, p.into(), n.into(), "0.1-0.1", 0)]);
    let mut m = MockMachine::new(vec![Surface::Sphere {
        centre: c,
        radius: 25.0,
    }]);
    let (report, _) = common::run(&prog, &mut m, &common::temp_dir("444-sphere"), true);
    let q = &report.cycles[0].q;
    assert!((q["Q164"] - delta).abs() < 1e-6, "{}", q["Q164"]);
    assert_eq!(q["Q183"], 0.0);

    // Cylinder about Y through (0, 0, 0), radius 30; point on the side, normal radial.
    let axis = Vector3::new(0.0, 1.0, 0.0);
    let radial = Vector3::new(0.6, 0.0, 0.8);
    let p = radial * 29.8 + axis * 7.0;
    let prog = program(&[block(10, p.into(), radial.into(), "0.1", 0)]);
    let mut m = MockMachine::new(vec![Surface::Cylinder {
        point: Vector3::zeros(),
        axis,
        radius: 30.0,
    }]);
    let (report, _) = common::run(&prog, &mut m, &common::temp_dir("444-cyl"), true);
    let q = &report.cycles[0].q;
    assert!((q["Q164"] - 0.2).abs() < 1e-6);
    assert_eq!(q["Q183"], 1.0, "0.2 above an upper limit of 0.1: rework");
}

#[test]
fn q183_for_every_tolerance_example() {
    let cases: [(&str, &[(f64, f64)]); 7] = [
        (
            "0.4-0.1",
            &[(0.2, 0.0), (0.4, 0.0), (-0.1, 0.0), (0.5, 1.0), (-0.2, 2.0)],
        ),
        ("0.4", &[(0.2, 0.0), (0.0, 0.0), (0.5, 1.0), (-0.05, 2.0)]),
        (
            "-0.1",
            &[(-0.05, 0.0), (0.0, 0.0), (0.05, 1.0), (-0.2, 2.0)],
        ),
        ("1-1", &[(0.5, 0.0), (-0.99, 0.0), (1.5, 1.0), (-1.5, 2.0)]),
        (" ", &[(0.5, -1.0), (-5.0, -1.0)]),
        ("0", &[(0.5, -1.0), (-0.5, -1.0)]),
        ("0.1+0.1", &[(0.05, -1.0), (-3.0, -1.0)]),
    ];
    let p = [0.0, 0.0, 10.0];
    let n = [0.0, 0.0, 1.0];
    for (tol, deltas) in cases {
        for &(delta, status) in deltas {
            let prog = program(&[block(10, p, n, tol, 0)]);
            let mut m = MockMachine::new(vec![offset_plane(p, n, delta)]);
            let (report, _) = common::run(&prog, &mut m, &common::temp_dir("444-tol"), true);
            let q = &report.cycles[0].q;
            assert_eq!(
                q["Q183"], status,
                "QS400=\"{tol}\" delta {delta}: Q164 {}",
                q["Q164"]
            );
        }
    }
}

#[test]
fn q309_stops_exactly_when_the_spec_says() {
    let p = [0.0, 0.0, 10.0];
    let n = [0.0, 0.0, 1.0];
    // (QS400, Q309, delta, stops)
    let cases = [
        ("0.4-0.1", 0, 0.5, false),
        ("0.4-0.1", 0, -0.5, false),
        ("0.4-0.1", 1, 0.2, false),
        ("0.4-0.1", 1, 0.5, true),
        ("0.4-0.1", 1, -0.5, true),
        (" ", 1, -3.0, false),
        ("0.4-0.1", 2, 0.5, false),
        ("0.4-0.1", 2, -0.05, true),
        ("0.4-0.1", 2, -0.5, true),
        ("0.4-0.1", 2, 0.0, false),
        (" ", 2, -0.05, true),
        (" ", 2, 0.05, false),
    ];
    for (tol, q309, delta, stops) in cases {
        let second = [40.0, 0.0, 10.0];
        let prog = program(&[block(10, p, n, tol, q309), block(11, second, n, " ", 0)]);
        let mut m = MockMachine::new(vec![offset_plane(p, n, delta)]);
        // The second point sits on its own exact surface patch (same plane, far away
        // enough that the first one's offset does not matter).
        m.surfaces = vec![Surface::Plane {
            point: Vector3::new(0.0, 0.0, 10.0 + delta),
            normal: Vector3::z(),
        }];
        let (report, _) = common::run(&prog, &mut m, &common::temp_dir("444-q309"), true);
        let case = format!("QS400=\"{tol}\" Q309={q309} delta {delta}");
        assert_eq!(report.cycles[0].status, Status::Ok, "{case}");
        if stops {
            assert_eq!(
                report.cycles.len(),
                1,
                "{case}: the next cycle must not run"
            );
            assert_eq!(m.probes.len(), 1, "{case}");
            let msg = report.cycles[0].message.as_deref().unwrap();
            assert!(msg.contains("Q309"), "{case}: {msg}");
            assert!(
                report.stopped.as_deref().unwrap().contains("block 10"),
                "{case}"
            );
        } else {
            assert_eq!(report.cycles.len(), 2, "{case}");
            assert!(
                report.stopped.is_none() && report.cycles[0].message.is_none(),
                "{case}"
            );
        }
    }
}

#[test]
fn horizontal_probe_axis_maps_main_minor_tool() {
    // TOOL CALL ... X: main = Y, minor = Z, tool = X.
    let text =
        "1 TOOL CALL \"TOUCH_PROBE\" X\n2 TCH PROBE 444 P ~\nQ263=+10 ~\nQ264=+20 ~\nQ294=+30 ~\n\
        Q581=+0 ~\nQ582=+0 ~\nQ583=+1 ~\nQ260=+100";
    let prog = Program::parse(text, &common::config()).unwrap();
    // Tool-axis normal = machine +X; the point is at machine (30, 10, 20).
    let mut m = MockMachine::new(vec![Surface::Plane {
        point: Vector3::new(30.25, 0.0, 0.0),
        normal: Vector3::x(),
    }]);
    let (report, _) = common::run(&prog, &mut m, &common::temp_dir("444-x"), true);
    let q = &report.cycles[0].q;
    assert!((q["Q164"] - 0.25).abs() < 1e-9);
    assert!(
        (q["Q151"] - 10.0).abs() < 1e-9
            && (q["Q152"] - 20.0).abs() < 1e-9
            && (q["Q153"] - 30.25).abs() < 1e-9
    );
    assert_eq!(m.probes[0].direction, [-1.0, 0.0, 0.0]);
    assert_eq!(m.moves[0].0[0], 100.0, "safe height along X");
}

#[test]
fn html_protocol_has_directions_limits_and_colours() {
    let p = [0.0, 0.0, 10.0];
    let n = [0.0, 0.0, 1.0];
    let dir = common::temp_dir("444-html");
    let prog = program(&[
        block(10, p, n, "0.4-0.1", 0),
        block(11, [30.0, 0.0, 10.0], n, "0.4-0.1", 0),
    ]);
    let mut m = MockMachine::new(vec![offset_plane(p, n, -0.3)]);
    let (report, _) = common::run(&prog, &mut m, &dir, true);
    assert_eq!(report.protocols, vec![dir.join("TCHPR444.html")]);
    let html = std::fs::read_to_string(dir.join("TCHPR444.html")).unwrap();
    assert_eq!(html.matches("<h2>Block").count(), 2, "both points");
    assert!(html.contains("background:red"), "scrap is red");
    assert!(
        html.contains("<td>-16.0000</td>"),
        "direction: length = probing path 16"
    );
    assert!(
        html.contains("<td>+10.4000</td><td>+9.9000</td>"),
        "limits along Z"
    );
    assert!(html.contains("Q164 = -0.3000"));
}
