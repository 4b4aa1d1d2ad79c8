//! Cycles 431 and 444 on the simulated machine over CANopen, checked against an
//! independent computation of spec.md's formulas (written here with plain arrays, not
//! with the cycles crate's geometry) and against the scenario's true geometry.

use cycles::program::Program;
use cycles::results::{ProgramReport, Status};
use cycles::runner::{run_program, RunOptions};
use probebridge_tests::conformance::{Backend, CanInproc};
use probebridge_tests::{cycles_config, scenario};

fn run(program: &str, sc: &sim::Scenario) -> ProgramReport {
    let cfg = cycles_config(sc);
    let program = Program::parse(program, &cfg).unwrap_or_else(|e| panic!("{e}"));
    let mut m = CanInproc::open(sc);
    let out = std::env::temp_dir().join(format!("pb-sil-{}", std::process::id()));
    std::fs::create_dir_all(&out).unwrap();
    let mut confirm = |_: &cycles::confirmation::Confirmation| true;
    let mut progress = |_| {};
    let mut opts = RunOptions {
        out_dir: out,
        confirm: &mut confirm,
        progress: &mut progress,
        kinematics: None,
        estimator: None,
    };
    run_program(&program, &mut m, &cfg, &mut opts)
}

type V = [f64; 3];
fn sub(a: V, b: V) -> V {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn cross(a: V, b: V) -> V {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn unit(a: V) -> V {
    let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    [a[0] / n, a[1] / n, a[2] / n]
}
fn deg(r: f64) -> f64 {
    r.to_degrees()
}

/// spec.md, cycle 431: (SPA, SPB, SPC, Q158, Q159) from three measured points.
fn spec_431(p1: V, p2: V, p3: V) -> [f64; 5] {
    let x = unit(sub(p2, p1));
    let z = unit(cross(sub(p2, p1), sub(p3, p1)));
    let y = cross(z, x);
    // R = [X' Y' Z'] by columns: R[row][col].
    let r = |row: usize, col: usize| [x, y, z][col][row];
    let spb = deg((-r(2, 0)).asin());
    let spa = deg(r(2, 1).atan2(r(2, 2)));
    let spc = deg(r(1, 0).atan2(r(0, 0)));
    [
        spa,
        spb,
        spc,
        deg((-z[1]).atan2(z[2])),
        deg(z[0].atan2(z[2])),
    ]
}

/// Rz(c) Ry(b) Rx(a) applied to (0, 0, 1).
fn rotate_z_axis(a: f64, b: f64, c: f64) -> V {
    let (sa, ca) = a.to_radians().sin_cos();
    let (sb, cb) = b.to_radians().sin_cos();
    let (sc, cc) = c.to_radians().sin_cos();
    // Rx(a) z = (0, -sa, ca); Ry(b) then Rz(c).
    let v = [0.0, -sa, ca];
    let v = [cb * v[0] + sb * v[2], v[1], -sb * v[0] + cb * v[2]];
    [cc * v[0] - sc * v[1], sc * v[0] + cc * v[1], v[2]]
}

/// The machines of the tests with the tool axis each one's spindle has.
const TOOL_AXES: [(&str, char); 3] = [
    ("table-ac", 'Z'),
    ("horizontal-y-table-ac", 'Y'),
    ("horizontal-x-head-b-table-c", 'X'),
];

/// Where the probe starts: back along the spindle, clear of the table.
fn home(axis: char) -> String {
    match axis {
        'X' => "home = [350.0, 0.0, 0.0]\n".into(),
        'Y' => "home = [0.0, 250.0, 0.0]\n".into(),
        _ => String::new(),
    }
}

/// (main, minor, tool) to machine X, Y, Z for a tool axis, as the TNC lays out its
/// working planes (written here independently): Z: X Y Z, X: Y Z X, Y: Z X Y.
fn to_machine(axis: char, c: V) -> V {
    match axis {
        'Z' => c,
        'X' => [c[2], c[0], c[1]],
        'Y' => [c[1], c[2], c[0]],
        _ => panic!("tool axis {axis}"),
    }
}

fn program_431(pts: [[f64; 3]; 3], q260: f64, axis: char) -> String {
    format!(
        "0 BEGIN PGM SIL431 MM\n1 TOOL CALL \"TOUCH_PROBE\" {axis}\n2 TCH PROBE 431 MESSEN EBENE ~\n  Q263={:+} ;1. PUNKT 1. ACHSE ~\n  Q264={:+} ;1. PUNKT 2. ACHSE ~\n  Q294={:+} ;1. PUNKT 3. ACHSE ~\n  Q265={:+} ;2. PUNKT 1. ACHSE ~\n  Q266={:+} ;2. PUNKT 2. ACHSE ~\n  Q295={:+} ;2. PUNKT 3. ACHSE ~\n  Q296={:+} ;3. PUNKT 1. ACHSE ~\n  Q297={:+} ;3. PUNKT 2. ACHSE ~\n  Q298={:+} ;3. PUNKT 3. ACHSE ~\n  Q320=+2 ;SICHERHEITS-ABST. ~\n  Q260={q260:+} ;SICHERE HOEHE ~\n  Q281=+0 ;MESSPROTOKOLL\n3 END PGM SIL431 MM\n",
        pts[0][0], pts[0][1], pts[0][2], pts[1][0], pts[1][1], pts[1][2], pts[2][0], pts[2][1], pts[2][2]
    )
}

/// With every tool axis: the plane is given in (main, minor, tool) coordinates and
/// put on the machine turned accordingly; the cycle's results are in those
/// coordinates and must be the same for all three.
#[test]
fn cycle_431_on_tilted_planes_matches_spec_and_truth() {
    for (machine, axis) in TOOL_AXES {
        cycle_431_on_tilted_planes(machine, axis);
    }
}

fn cycle_431_on_tilted_planes(machine: &str, axis: char) {
    // Plane normals written by hand: through (20, 10, 15).
    for normal in [[0.05, -0.12, 1.0], [-0.2, 0.03, 1.0], [0.0, 0.0, 1.0]] {
        let (point, normal_m) = (
            to_machine(axis, [20.0, 10.0, 15.0]),
            to_machine(axis, normal),
        );
        let sc = scenario(&format!(
            "machine = \"{machine}\"\n{}[probe]\nball_radius = 2.0\n[[plane]]\npoint = [{}, {}, {}]\nnormal = [{}, {}, {}]\n",
            home(axis),
            point[0], point[1], point[2], normal_m[0], normal_m[1], normal_m[2]
        ));
        let n = unit(normal);
        let height = |x: f64, y: f64| 15.0 - (n[0] * (x - 20.0) + n[1] * (y - 10.0)) / n[2];
        let xy = [[0.0, 0.0], [60.0, 5.0], [10.0, 55.0]];
        let pts = xy.map(|p| [p[0], p[1], height(p[0], p[1])]);
        let report = run(&program_431(pts, 60.0, axis), &sc);
        let c = &report.cycles[0];
        assert_eq!(c.status, Status::Ok, "tool axis {axis}: {:?}", c.message);
        let q = |k: &str| c.q[k];
        // Independent computation from the measured points the cycle reports.
        let measured = [
            [xy[0][0], xy[0][1], q("Q173")],
            [xy[1][0], xy[1][1], q("Q174")],
            [xy[2][0], xy[2][1], q("Q175")],
        ];
        let want = spec_431(measured[0], measured[1], measured[2]);
        for (i, k) in ["Q170", "Q171", "Q172", "Q158", "Q159"].iter().enumerate() {
            assert!(
                (q(k) - want[i]).abs() < 1e-6,
                "tool axis {axis}: {k} = {} but spec gives {}",
                q(k),
                want[i]
            );
        }
        // Against the truth: the plane's own projection angles.
        assert!(
            (q("Q158") - deg((-n[1]).atan2(n[2]))).abs() < 1e-6,
            "tool axis {axis}: Q158 {}",
            q("Q158")
        );
        assert!(
            (q("Q159") - deg(n[0].atan2(n[2]))).abs() < 1e-6,
            "tool axis {axis}: Q159 {}",
            q("Q159")
        );
        // Rotating (0, 0, 1) by the spatial angles reproduces the plane normal.
        let r = rotate_z_axis(q("Q170"), q("Q171"), q("Q172"));
        for i in 0..3 {
            assert!(
                (r[i] - n[i]).abs() < 2e-8,
                "tool axis {axis}: normal {r:?} vs {n:?}"
            );
        }
    }
}

fn block_444(p: V, n: V, tol: &str, q309: u8) -> String {
    format!(
        "TCH PROBE 444 ANTASTEN 3D ~\n  Q263={:+} ;1. PUNKT 1. ACHSE ~\n  Q264={:+} ;1. PUNKT 2. ACHSE ~\n  Q294={:+} ;1. PUNKT 3. ACHSE ~\n  Q581={:+} ;NORMALE 1. ACHSE ~\n  Q582={:+} ;NORMALE 2. ACHSE ~\n  Q583={:+} ;NORMALE 3. ACHSE ~\n  Q320=+1 ;SICHERHEITS-ABST. ~\n  Q260=+120 ;SICHERE HOEHE ~\n  QS400=\"{tol}\" ;TOLERANZ ~\n  Q309=+{q309} ;FEHLERREAKTION\n",
        p[0], p[1], p[2], n[0], n[1], n[2]
    )
}

fn program_444(blocks: &[String]) -> String {
    program_444_along(blocks, 'Z')
}

fn program_444_along(blocks: &[String], axis: char) -> String {
    let mut s = format!("BEGIN PGM SIL444 MM\nTOOL CALL \"TOUCH_PROBE\" {axis}\n");
    for b in blocks {
        s.push_str(b);
    }
    s.push_str("END PGM SIL444 MM\n");
    s
}

/// Status of spec.md for a deviation and a QS400 string.
fn spec_status(dev: f64, tol: &str) -> f64 {
    let (upper, lower) = match tol {
        "0.4-0.1" => (0.4, -0.1),
        "0.4" => (0.4, 0.0),
        "-0.1" => (0.0, -0.1),
        "1-1" => (1.0, -1.0),
        _ => return -1.0,
    };
    if dev > upper {
        1.0
    } else if dev < lower {
        2.0
    } else {
        0.0
    }
}

/// A sphere larger or smaller than the nominal surface by a known offset: Q164 is the
/// offset, Q151..Q163 follow from the contact, Q183 from every QS400 example; with
/// every tool axis (points, normals and results in (main, minor, tool) coordinates).
#[test]
fn cycle_444_known_offsets_and_every_tolerance_example() {
    for (machine, axis) in TOOL_AXES {
        cycle_444_known_offsets(machine, axis);
    }
}

fn cycle_444_known_offsets(machine: &str, axis: char) {
    let (centre, nominal_r) = ([30.0, -20.0, 40.0], 20.0);
    let tolerances = ["0.4-0.1", "0.4", "-0.1", "1-1", " ", "0", "0.1+0.1"];
    for offset in [0.05, 0.5, -0.05, -0.2] {
        let centre_m = to_machine(axis, centre);
        let sc = scenario(&format!(
            "machine = \"{machine}\"\n{}[probe]\nball_radius = 3.0\n[[sphere]]\ncenter = [{}, {}, {}]\nradius = {}\n",
            home(axis),
            centre_m[0],
            centre_m[1],
            centre_m[2],
            nominal_r + offset
        ));
        // Points on the nominal sphere, normals pointing out of the material.
        let dirs = [
            [0.0, 0.0, 1.0],
            [0.6, 0.0, 0.8],
            [0.0, -0.6, 0.8],
            [-0.48, 0.36, 0.8],
        ];
        let mut blocks = Vec::new();
        let mut nominal = Vec::new();
        for (i, tol) in tolerances.iter().enumerate() {
            let n = unit(dirs[i % dirs.len()]);
            let p = [
                centre[0] + nominal_r * n[0],
                centre[1] + nominal_r * n[1],
                centre[2] + nominal_r * n[2],
            ];
            blocks.push(block_444(p, n, tol, 0));
            nominal.push((p, n, *tol));
        }
        let report = run(&program_444_along(&blocks, axis), &sc);
        assert_eq!(
            report.cycles.len(),
            tolerances.len(),
            "{:?}",
            report.stopped
        );
        for (c, (p, n, tol)) in report.cycles.iter().zip(nominal) {
            assert_eq!(c.status, Status::Ok, "tool axis {axis}: {:?}", c.message);
            let q = |k: &str| c.q[k];
            let actual = [q("Q151"), q("Q152"), q("Q153")];
            let want_actual = [
                centre[0] + (nominal_r + offset) * n[0],
                centre[1] + (nominal_r + offset) * n[1],
                centre[2] + (nominal_r + offset) * n[2],
            ];
            for i in 0..3 {
                assert!(
                    (actual[i] - want_actual[i]).abs() < 1e-6,
                    "tool axis {axis}: actual {actual:?} vs {want_actual:?}"
                );
                let dev = ["Q161", "Q162", "Q163"][i];
                assert!((q(dev) - (actual[i] - p[i])).abs() < 1e-9);
            }
            let d = sub(actual, p);
            let q164 = d[0] * n[0] + d[1] * n[1] + d[2] * n[2];
            assert!((q("Q164") - q164).abs() < 1e-9);
            assert!(
                (q("Q164") - offset).abs() < 1e-6,
                "tool axis {axis}: Q164 {} for offset {offset}",
                q("Q164")
            );
            assert_eq!(
                q("Q183"),
                spec_status(offset, tol),
                "QS400 {tol:?}, offset {offset}"
            );
        }
    }
}

/// Q309 = 1 stops on any tolerance violation, Q309 = 2 only below nominal; a stop ends
/// the program and later cycles do not run.
#[test]
fn q309_stops_exactly_when_the_spec_says() {
    let sc = scenario(
        "machine = \"table-ac\"\n[probe]\nball_radius = 3.0\n[[plane]]\npoint = [0.0, 0.0, 10.0]\nnormal = [0.0, 0.0, 1.0]\n",
    );
    let up = [0.0, 0.0, 1.0];
    // The plane is at 10: a nominal of 10.05 is 0.05 under, 9.5 is 0.5 over.
    let cases: [(f64, &str, u8, bool); 8] = [
        (10.05, "0.4-0.1", 1, false), // -0.05: in tolerance
        (9.5, "0.4-0.1", 1, true),    // +0.5: rework
        (10.2, "0.4-0.1", 1, true),   // -0.2: scrap
        (9.5, "0.4-0.1", 2, false),   // above nominal: no stop with 2
        (10.05, "0.4-0.1", 2, true),  // below nominal, in tolerance: stop with 2
        (10.2, " ", 2, true),         // below nominal without tolerance: stop with 2
        (9.5, " ", 1, false),         // no tolerance: nothing to violate
        (10.2, "1-1", 0, false),      // Q309 = 0 never stops
    ];
    for (z, tol, q309, stops) in cases {
        let blocks = [
            block_444([5.0, 5.0, z], up, tol, q309),
            block_444([15.0, 5.0, 10.0], up, " ", 0),
        ];
        let report = run(&program_444(&blocks), &sc);
        let what = format!("nominal Z {z}, QS400 {tol:?}, Q309 {q309}");
        assert_eq!(
            report.stopped.is_some(),
            stops,
            "{what}: {:?}",
            report.stopped
        );
        assert_eq!(report.cycles.len(), if stops { 1 } else { 2 }, "{what}");
        assert!(
            (report.cycles[0].q["Q164"] - (10.0 - z)).abs() < 1e-6,
            "{what}"
        );
    }
}
