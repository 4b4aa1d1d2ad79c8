//! Clearance heights that would cut through what is measured are refused at the block,
//! before anything moves: cycle 451's Q408 below the sphere's top plus the ball and
//! SET_UP, cycle 444's Q260 below the start of its point. Each on both sides of the
//! limit, with several spheres, probes, normals and datums.

mod common;

use common::{MockMachine, Surface};
use nalgebra::Vector3;
use probebridge_cycles::runner::preflight_program;
use probebridge_cycles::{CyclesConfig, Program, Status};
use std::path::PathBuf;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// configs/programs/451-check.h measuring C alone (C turns the sphere about Z, its
/// height stays), with Q407 and Q408 set.
fn program451(cfg: &CyclesConfig, q407: f64, q408: f64) -> Program {
    let text = std::fs::read_to_string(root().join("configs/programs/451-check.h")).unwrap();
    let text = text
        .replacen("Q407=+12.5", &format!("Q407={q407:+}"), 1)
        .replacen("Q408=+50", &format!("Q408={q408:+}"), 1)
        .replacen("Q414=+3", "Q414=+0", 1);
    Program::parse(&text, cfg).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn q408_below_the_sphere_top_plus_ball_and_set_up_is_refused_naming_the_lowest() {
    let dir = common::temp_dir("q408");
    let kinematics = dir.join("k.toml");
    for (q407, radius, set_up) in [(12.5, 3.0, 2.0), (7.25, 1.5, 0.8), (30.0, 2.5, 4.0)] {
        let mut cfg = CyclesConfig::load(&root().join("configs/machines/table-ac.toml")).unwrap();
        cfg.probes[0].radius = radius;
        cfg.probes[0].set_up = set_up;
        let lowest = q407 + radius + set_up;
        let check = |q408: f64| {
            preflight_program(&program451(&cfg, q407, q408), 0b111, &cfg, &kinematics)
                .map_err(|e| e.to_string())
        };
        for q408 in [1.0, lowest * 0.5, lowest - 0.01] {
            let e = check(q408).unwrap_err();
            assert!(
                e.contains(&format!("(cycle 451): Q408={q408}: "))
                    && e.contains(&format!("the lowest Q408 that clears it is {lowest:.4}")),
                "{e}"
            );
        }
        for q408 in [lowest, lowest + 0.01, lowest + 40.0] {
            check(q408).unwrap_or_else(|e| panic!("Q408={q408}: {e}"));
        }
        // Q408 = 0: no retraction height, nothing to clear.
        check(0.0).unwrap();
    }
}

fn block444(nominal: [f64; 3], normal: [f64; 3], q320: f64, q260: f64) -> String {
    format!(
        "5 TCH PROBE 444 PROBING 3D ~\n  Q263={:+} ~\n  Q264={:+} ~\n  Q294={:+} ~\n  Q581={:+} ~\n  Q582={:+} ~\n  Q583={:+} ~\n  Q320={q320:+} ~\n  Q260={q260:+} ~\n  QS400=\" \" ~\n  Q309=+0\n",
        nominal[0], nominal[1], nominal[2], normal[0], normal[1], normal[2]
    )
}

/// A program with a datum shift of `shift` (program coordinates relative to it) and
/// `block` (a 444 or a 431).
fn shifted_program(shift: [f64; 3], block: &str) -> Program {
    let text = format!(
        "0 BEGIN PGM P MM\n1 TOOL CALL \"TOUCH_PROBE\" Z\n2 TRANS DATUM AXIS X{:+} Y{:+} Z{:+}\n{block}99 END PGM P MM\n",
        shift[0], shift[1], shift[2]
    );
    Program::parse(&text, &common::config()).unwrap_or_else(|e| panic!("{e}\n{text}"))
}

/// 444's Q260 must clear what the block says is material: the start of the point
/// (else the probe comes up to it through the part) and the probed point itself by
/// R + SET_UP (on a face whose normal is not the tool axis the material rises to the
/// point's height). Both sides of the limit, with normals along the tool axis, oblique
/// and in the working plane, and a datum shift.
#[test]
fn q260_below_the_start_of_the_444_point_is_refused_before_anything_moves() {
    let cfg = common::config();
    // TOUCH_PROBE: R 3, SET_UP 2.
    for (nominal, normal, q320, shift) in [
        ([0.0, 0.0, 10.0], [0.0, 0.0, 1.0], 0.0, [0.0; 3]),
        ([12.0, -4.0, -3.5], [0.0, 0.6, 0.8], 1.5, [5.0, 5.0, 40.0]),
        ([-20.0, 7.0, 22.0], [1.0, 0.0, 0.0], 3.0, [0.0, 0.0, -15.0]),
        ([3.0, 9.0, -7.0], [-0.9, 0.2, 0.3], 0.5, [1.0, -2.0, 3.0]),
    ] {
        let n = Vector3::from(normal).normalize();
        let start = Vector3::from(nominal) + n * (3.0 + 2.0 + q320);
        let lowest = f64::max(start.z, nominal[2] + 3.0 + 2.0);
        for q260 in [lowest - 0.01, lowest - 15.0, -50.0] {
            let prog = shifted_program(shift, &block444(nominal, normal, q320, q260));
            let e = preflight_program(&prog, 0b111, &cfg, std::path::Path::new("k.toml"))
                .unwrap_err()
                .to_string();
            let why = if q260 < start.z {
                format!(
                    "Q260={q260} is below the start of the point ({:.4} =",
                    start.z
                )
            } else {
                format!("Q260={q260} does not clear the probed point")
            };
            assert!(
                e.contains(&why)
                    && e.contains(&format!("the lowest Q260 that clears is {lowest:.4}"))
                    && e.contains("block 5"),
                "{e}"
            );
            // `run` refuses the same, at the block, before its first move.
            let mut m = MockMachine::new(vec![Surface::Plane {
                point: Vector3::from(nominal) + Vector3::from(shift),
                normal: n,
            }]);
            let (report, _) = common::run(&prog, &mut m, &common::temp_dir("q260"), true);
            assert_eq!(m.motion_count(), 0, "Q260={q260}: something moved");
            assert_eq!(report.cycles[0].status, Status::Error);
            let stopped = report.stopped.unwrap();
            assert!(
                stopped.contains(&e[e.find("Q260=").unwrap()..]),
                "{stopped} / {e}"
            );
        }
        for q260 in [lowest, lowest + 0.01, lowest + 100.0] {
            let prog = shifted_program(shift, &block444(nominal, normal, q320, q260));
            preflight_program(&prog, 0b111, &cfg, std::path::Path::new("k.toml"))
                .unwrap_or_else(|e| panic!("Q260={q260}: {e}"));
            let mut m = MockMachine::new(vec![Surface::Plane {
                point: Vector3::from(nominal) + Vector3::from(shift),
                normal: n,
            }]);
            let (report, _) = common::run(&prog, &mut m, &common::temp_dir("q260-ok"), true);
            assert_eq!(
                report.cycles[0].status,
                Status::Ok,
                "Q260={q260}: {:?}",
                report.stopped
            );
        }
    }
}

/// Cycle 431's Q260 must lie above the start of every one of its three points; a
/// lower one is refused at the block by `check` and `run` alike, before anything
/// moves, with the lowest Q260 that clears all three. That is the highest start, not
/// the start of the first point found below Q260: a Q260 raised only to that one
/// would be refused again at a higher point. Points at different heights, with a
/// Q320 and a datum shift.
#[test]
fn q260_of_431_below_a_start_is_refused_naming_the_lowest_that_clears_all_three() {
    let cfg = common::config();
    // TOUCH_PROBE: R 3, SET_UP 2. (heights of points 1..3, Q320, shift).
    for (z, q320, shift) in [
        ([2.0, 9.5, 4.25], 0.0, [0.0; 3]),
        ([-6.0, -11.0, -3.5], 1.5, [4.0, -3.0, 30.0]),
        ([7.75, 1.0, 0.5], 0.25, [-8.0, 6.0, -12.0]),
    ] {
        let xy = [[0.0, 0.0], [40.0, 0.0], [0.0, 40.0]];
        let p = |i: usize| Vector3::new(xy[i][0], xy[i][1], z[i]);
        let lowest = z.iter().copied().fold(f64::NEG_INFINITY, f64::max) + 3.0 + 2.0 + q320;
        let normal = (p(1) - p(0)).cross(&(p(2) - p(0))).normalize();
        let block = |q260: f64| {
            let q: Vec<String> = (0..3)
                .map(|i| format!("{:+}", xy[i][0]))
                .chain((0..3).map(|i| format!("{:+}", xy[i][1])))
                .chain(z.iter().map(|v| format!("{v:+}")))
                .collect();
            format!(
                "5 TCH PROBE 431 MEASURE PLANE ~\n  Q263={} ~\n  Q264={} ~\n  Q294={} ~\n  Q265={} ~\n  Q266={} ~\n  Q295={} ~\n  Q296={} ~\n  Q297={} ~\n  Q298={} ~\n  Q320={q320:+} ~\n  Q260={q260:+} ~\n  Q281=+0\n",
                q[0], q[3], q[6], q[1], q[4], q[7], q[2], q[5], q[8]
            )
        };
        let machine = || {
            MockMachine::new(vec![Surface::Plane {
                point: p(0) + Vector3::from(shift),
                normal,
            }])
        };
        // Just below the highest start (above the lower ones), and far below.
        for q260 in [lowest - 0.01, lowest - 23.0] {
            let prog = shifted_program(shift, &block(q260));
            let e = preflight_program(&prog, 0b111, &cfg, std::path::Path::new("k.toml"))
                .unwrap_err()
                .to_string();
            assert!(
                e.contains(&format!("Q260={q260} is below the start of point"))
                    && e.contains(&format!("the lowest Q260 that clears is {lowest:.4}"))
                    && e.contains("block 5"),
                "{e}"
            );
            let mut m = machine();
            let (report, _) = common::run(&prog, &mut m, &common::temp_dir("q260-431"), true);
            assert_eq!(m.motion_count(), 0, "Q260={q260}: something moved");
            let stopped = report.stopped.unwrap();
            assert!(
                stopped.contains(&e[e.find("Q260=").unwrap()..]),
                "{stopped} / {e}"
            );
        }
        // The value the message names runs, and so does a little more.
        for q260 in [lowest, lowest + 0.01] {
            let prog = shifted_program(shift, &block(q260));
            preflight_program(&prog, 0b111, &cfg, std::path::Path::new("k.toml"))
                .unwrap_or_else(|e| panic!("Q260={q260}: {e}"));
            let mut m = machine();
            let (report, _) = common::run(&prog, &mut m, &common::temp_dir("q260-431-ok"), true);
            assert_eq!(
                report.cycles[0].status,
                Status::Ok,
                "Q260={q260}: {:?}",
                report.stopped
            );
        }
    }
}
