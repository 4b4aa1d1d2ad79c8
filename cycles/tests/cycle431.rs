//! Cycle 431 on planes of known tilt (closed form), collinear points, Q281.

mod common;

use common::{rx, ry, rz, MockMachine, Surface};
use nalgebra::Vector3;
use probebridge_cycles::plane::plane_angles;
use probebridge_cycles::{Program, Status};

fn program(points: [Vector3<f64>; 3], q260: f64, q281: u8) -> Program {
    let [a, b, c] = points;
    let text = format!(
        "0 BEGIN PGM PLANE MM\n1 TOOL CALL \"TOUCH_PROBE\" Z\n2 TCH PROBE 431 MEASURE PLANE ~\n\
         Q263={:+} ~\nQ264={:+} ~\nQ294={:+} ~\nQ265={:+} ~\nQ266={:+} ~\nQ295={:+} ~\n\
         Q296={:+} ~\nQ297={:+} ~\nQ298={:+} ~\nQ320=+0 ~\nQ260={q260:+} ~\nQ281=+{q281}\n3 END PGM PLANE MM\n",
        a.x, a.y, a.z, b.x, b.y, b.z, c.x, c.y, c.z
    );
    Program::parse(&text, &common::config()).unwrap_or_else(|e| panic!("{e}\n{text}"))
}

#[test]
fn known_tilts_give_spatial_and_projection_angles() {
    let tilts = [
        (0.0, 0.0, 0.0),
        (10.0, 0.0, 0.0),
        (0.0, -7.5, 0.0),
        (0.0, 0.0, 30.0),
        (5.0, 8.0, -20.0),
        (-12.0, 3.0, 135.0),
        (20.0, -15.0, -170.0),
    ];
    for (a, b, c) in tilts {
        let r = rz(c) * ry(b) * rx(a);
        let (x, y, z) = (
            r.column(0).into_owned(),
            r.column(1).into_owned(),
            r.column(2).into_owned(),
        );
        let origin = Vector3::new(12.0, -7.0, 10.0);
        let truth = [origin, origin + x * 40.0, origin + y * 30.0];
        // Nominal probe-axis coordinates 0.7 mm off the real surface: measurement
        // must follow the surface, not the nominal.
        let nominal = truth.map(|p| p + Vector3::new(0.0, 0.0, 0.7));
        let prog = program(nominal, 100.0, 0);
        let mut m = MockMachine::new(vec![Surface::Plane {
            point: origin,
            normal: z,
        }]);
        let (report, _) = common::run(&prog, &mut m, &common::temp_dir("431-tilt"), true);
        let res = &report.cycles[0];
        assert_eq!(res.status, Status::Ok, "{:?}", res.message);
        let q = &res.q;
        let case = format!("A {a} B {b} C {c}");
        for (name, want) in [("Q170", a), ("Q171", b), ("Q172", c)] {
            assert!(
                (q[name] - want).abs() < 1e-6,
                "{case}: {name} {} != {want}",
                q[name]
            );
        }
        let q158 = (-z.y).atan2(z.z).to_degrees();
        let q159 = z.x.atan2(z.z).to_degrees();
        assert!((q["Q158"] - q158).abs() < 1e-6, "{case}: Q158");
        assert!((q["Q159"] - q159).abs() < 1e-6, "{case}: Q159");
        // Ball centre at the trigger minus R: the centre sits R along the plane
        // normal off the surface, i.e. R / n_z above it on the probe axis.
        for (name, p) in ["Q173", "Q174", "Q175"].into_iter().zip(truth) {
            let want = p.z + 3.0 / z.z - 3.0;
            assert!(
                (q[name] - want).abs() < 1e-9,
                "{case}: {name} {} != {want}",
                q[name]
            );
        }
        // Rz(SPC) * Ry(SPB) * Rx(SPA) turns (0, 0, 1) into the plane normal.
        let n = rz(q["Q172"]) * ry(q["Q171"]) * rx(q["Q170"]) * Vector3::z();
        assert!((n - z).norm() < 1e-9, "{case}: {n:?} vs {z:?}");
        // Probed downward along -Z from nominal + R + SET_UP + Q320.
        assert_eq!(m.probes.len(), 3);
        for mv in &m.probes {
            assert_eq!(mv.direction, [0.0, 0.0, -1.0]);
            assert!((mv.max_distance - (3.0 + 2.0 + 0.0 + 10.0)).abs() < 1e-12);
        }
    }
}

#[test]
fn horizontal_plane_gives_zero_angles_and_sequence_uses_safe_height() {
    let pts = [
        Vector3::new(0.0, 0.0, 10.0),
        Vector3::new(50.0, 0.0, 10.0),
        Vector3::new(0.0, 40.0, 10.0),
    ];
    let prog = program(pts, 60.0, 0);
    let mut m = MockMachine::new(vec![Surface::Plane {
        point: pts[0],
        normal: Vector3::z(),
    }]);
    let (report, _) = common::run(&prog, &mut m, &common::temp_dir("431-flat"), true);
    let q = &report.cycles[0].q;
    for k in ["Q158", "Q159", "Q170", "Q171", "Q172"] {
        assert!(q[k].abs() < 1e-12, "{k} {}", q[k]);
    }
    // Per point: safe height, over the point, down to the start; after: safe height.
    let moves: Vec<[f64; 3]> = m.moves.iter().map(|(t, _)| *t).collect();
    assert_eq!(moves.len(), 10, "{moves:?}");
    assert_eq!(moves[0][2], 60.0);
    assert_eq!(moves[1], [0.0, 0.0, 60.0]);
    assert_eq!(moves[2], [0.0, 0.0, 15.0]);
    assert_eq!(moves[3][2], 60.0);
    assert_eq!(moves[4], [50.0, 0.0, 60.0]);
    assert_eq!(moves[5], [50.0, 0.0, 15.0]);
    assert_eq!(moves[9], [0.0, 40.0, 60.0]);
}

#[test]
fn collinear_measured_points_are_an_error() {
    // Nominal points not on a line, but the real surface z = 0 puts the measured ones
    // on the X axis.
    let pts = [
        Vector3::new(0.0, 0.0, 0.0),
        Vector3::new(20.0, 0.0, 5.0),
        Vector3::new(40.0, 0.0, 0.0),
    ];
    let prog = program(pts, 100.0, 1);
    let mut m = MockMachine::new(vec![Surface::Plane {
        point: Vector3::zeros(),
        normal: Vector3::z(),
    }]);
    let dir = common::temp_dir("431-collinear");
    let (report, _) = common::run(&prog, &mut m, &dir, true);
    let r = &report.cycles[0];
    assert_eq!(r.status, Status::Error);
    assert!(
        r.message.as_deref().unwrap().contains("lie on a line"),
        "{:?}",
        r.message
    );
    assert!(r.q.is_empty());
    assert!(
        !dir.join("TCHPR431.TXT").exists(),
        "no protocol for a failed cycle"
    );
    // And the maths alone.
    let p = |x, y, z| Vector3::new(x, y, z);
    assert!(plane_angles(p(0.0, 0.0, 0.0), p(1.0, 1.0, 1.0), p(3.0, 3.0, 3.0)).is_err());
    assert!(plane_angles(p(0.0, 0.0, 0.0), p(0.0, 0.0, 0.0), p(3.0, 1.0, 0.0)).is_err());
    assert!(plane_angles(p(0.0, 0.0, 0.0), p(1.0, 0.0, 0.0), p(0.0, 1.0, 0.0)).is_ok());
}

#[test]
fn collinear_nominal_points_are_refused_before_anything_moves() {
    let text =
        "1 TOOL CALL \"TOUCH_PROBE\" Z\n2 TCH PROBE 431 P ~\nQ263=+0 ~\nQ264=+0 ~\nQ294=+0 ~\n\
        Q265=+10 ~\nQ266=+10 ~\nQ295=+10 ~\nQ296=+20 ~\nQ297=+20 ~\nQ298=+20 ~\nQ260=+50";
    let e = Program::parse(text, &common::config()).unwrap_err();
    assert_eq!(e.0.len(), 1);
    assert_eq!(e.0[0].line, 3);
    assert!(e.0[0].message.contains("lie on a line"));
}

#[test]
fn q281_protocol_modes() {
    let pts = [
        Vector3::new(0.0, 0.0, 10.0),
        Vector3::new(50.0, 0.0, 10.0),
        Vector3::new(0.0, 40.0, 10.0),
    ];
    let surface = || {
        vec![Surface::Plane {
            point: Vector3::new(0.0, 0.0, 10.0),
            normal: Vector3::z(),
        }]
    };

    // 0: nothing written, nothing shown.
    let dir = common::temp_dir("431-q281-0");
    let mut m = MockMachine::new(surface());
    let (report, shown) = common::run(&program(pts, 100.0, 0), &mut m, &dir, true);
    assert!(shown.is_empty() && report.protocols.is_empty() && !dir.join("TCHPR431.TXT").exists());

    // 1: TCHPR431.TXT in the output folder.
    let dir = common::temp_dir("431-q281-1");
    let mut m = MockMachine::new(surface());
    let (report, shown) = common::run(&program(pts, 100.0, 1), &mut m, &dir, true);
    assert!(shown.is_empty());
    assert_eq!(report.protocols, vec![dir.join("TCHPR431.TXT")]);
    let text = std::fs::read_to_string(dir.join("TCHPR431.TXT")).unwrap();
    assert!(
        text.contains("Q170 = +0.0000") && text.contains("Q173"),
        "{text}"
    );

    // 2: shown; confirmed goes on, refused stops the program.
    for confirm in [true, false] {
        let dir = common::temp_dir("431-q281-2");
        let mut m = MockMachine::new(surface());
        let (report, shown) = common::run(&program(pts, 100.0, 2), &mut m, &dir, confirm);
        assert_eq!(shown.len(), 1);
        assert!(shown[0].contains("TCHPR431 MEASURE PLANE"));
        assert_eq!(report.cycles[0].status, Status::Ok);
        assert_eq!(report.stopped.is_some(), !confirm);
        assert!(!dir.join("TCHPR431.TXT").exists());
    }
}

#[test]
fn safe_height_below_the_start_moves_nothing() {
    let pts = [
        Vector3::new(0.0, 0.0, 10.0),
        Vector3::new(50.0, 0.0, 10.0),
        Vector3::new(0.0, 40.0, 10.0),
    ];
    // Start = 10 + R 3 + SET_UP 2 = 15 > Q260 = 12.
    let mut m = MockMachine::new(vec![]);
    let (report, _) = common::run(
        &program(pts, 12.0, 0),
        &mut m,
        &common::temp_dir("431-low"),
        true,
    );
    assert_eq!(report.cycles[0].status, Status::Error);
    assert!(
        report.cycles[0]
            .message
            .as_deref()
            .unwrap()
            .contains("Q260=12"),
        "{:?}",
        report.cycles[0].message
    );
    assert_eq!(m.motion_count(), 0);
}
