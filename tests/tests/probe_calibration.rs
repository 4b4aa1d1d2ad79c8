//! A real touch probe on the simulated machine: pre-travel that depends on the
//! direction (a kinematic seat's three lobes, another pre-travel along the stylus), a
//! ball centre off the spindle axis and a length error. Uncalibrated, cycles 431 and
//! 444 are off by what the physics says (computed here from the scenario's definition
//! of the stylus, independently of the simulator's code).

use cycles::program::Program;
use cycles::results::{ProgramReport, Status};
use cycles::runner::{run_program, RunOptions};
use hal::Machine;
use probebridge_tests::conformance::{Backend, CanInproc};
use probebridge_tests::{cycles_config, scenario};

type V = [f64; 3];

fn dot(a: V, b: V) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn unit(a: V) -> V {
    let n = dot(a, a).sqrt();
    [a[0] / n, a[1] / n, a[2] / n]
}

/// The stylus of the tests (tool axis Z, spindle at 0°), mm and deg.
#[derive(Clone, Copy)]
struct Stylus {
    ball: f64,
    pretravel: f64,
    axial: f64,
    lobing: f64,
    phase: f64,
    offset: [f64; 2],
    length: f64,
}

const REAL: Stylus = Stylus {
    ball: 3.0,
    pretravel: 0.005,
    axial: 0.007,
    lobing: 0.004,
    phase: 10.0,
    offset: [0.003, -0.002],
    length: 0.004,
};

impl Stylus {
    fn probe_section(&self, table_radius: f64) -> String {
        format!(
            "[probe]\nball_radius = {}\npretravel = {}\npretravel_axial = {}\nlobing = {}\nlobing_phase = {}\noffset = [{}, {}]\nlength_error = {}\ntable_radius = {table_radius}\n",
            self.ball, self.pretravel, self.axial, self.lobing, self.phase, self.offset[0], self.offset[1], self.length
        )
    }

    /// Pre-travel for a contact pushing the ball along `u` (unit): the blend of the
    /// axial and the lobed lateral pre-travel by the squared components.
    fn pretravel(&self, u: V) -> f64 {
        let s2 = u[2] * u[2];
        let azimuth = u[1].atan2(u[0]);
        let lateral =
            self.pretravel + self.lobing * (3.0 * (azimuth - self.phase.to_radians())).cos();
        s2 * self.axial + (1.0 - s2) * lateral
    }

    /// True ball centre minus the machine's X/Y/Z.
    fn shift(&self) -> V {
        [self.offset[0], self.offset[1], -self.length]
    }

    /// What an uncalibrated cycle reports along the surface normal `n` of a contact,
    /// minus the truth, with `table_radius` in the probe table: the ball centre at
    /// the trigger lies R - p(n) from the surface, and the axes are off it by the shift.
    fn uncalibrated_error(&self, n: V, table_radius: f64) -> f64 {
        self.ball - self.pretravel(n) - table_radius - dot(self.shift(), n)
    }
}

fn run_on<M: Machine<Error = hal::MachineError>>(
    program: &str,
    cfg: &cycles::CyclesConfig,
    m: &mut M,
    tag: &str,
) -> ProgramReport {
    let program = Program::parse(program, cfg).unwrap_or_else(|e| panic!("{e}"));
    let out = std::env::temp_dir().join(format!("pb-calib-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&out).unwrap();
    let mut confirm = |_: &str| true;
    let mut progress = |_| {};
    let mut opts = RunOptions {
        out_dir: out,
        confirm: &mut confirm,
        progress: &mut progress,
        kinematics: None,
        estimator: None,
    };
    run_program(&program, m, cfg, &mut opts)
}

fn block_444(p: V, n: V) -> String {
    format!(
        "TCH PROBE 444 PROBING 3D ~\n  Q263={:+} ;1ST POINT 1ST AXIS ~\n  Q264={:+} ;1ST POINT 2ND AXIS ~\n  Q294={:+} ;1ST POINT 3RD AXIS ~\n  Q581={:+} ;SURFACE NORMAL MAIN AXIS ~\n  Q582={:+} ;SURFACE NORMAL MINOR AXIS ~\n  Q583={:+} ;SURFACE NORMAL TOOL AXIS ~\n  Q320=+1 ;SET-UP CLEARANCE ~\n  Q260=+120 ;CLEARANCE HEIGHT ~\n  QS400=\" \" ;TOLERANCE ~\n  Q309=+0 ;ERROR REACTION\n",
        p[0], p[1], p[2], n[0], n[1], n[2]
    )
}

const SPHERE_CENTRE: V = [30.0, -20.0, 40.0];
const SPHERE_RADIUS: f64 = 20.0;

/// Points on the sphere of the 444 tests, with their normals.
fn sphere_points() -> Vec<(V, V)> {
    [
        [0.0, 0.0, 1.0],
        [0.6, 0.0, 0.8],
        [0.0, -0.6, 0.8],
        [-0.48, 0.36, 0.8],
        [0.28, 0.96, 0.0],
    ]
    .into_iter()
    .map(|d| {
        let n = unit(d);
        let c = SPHERE_CENTRE;
        let r = SPHERE_RADIUS;
        ([c[0] + r * n[0], c[1] + r * n[1], c[2] + r * n[2]], n)
    })
    .collect()
}

fn program(blocks: &[String]) -> String {
    let mut s = "BEGIN PGM CALIB MM\nTOOL CALL \"TOUCH_PROBE\" Z\n".to_string();
    for b in blocks {
        s.push_str(b);
    }
    s.push_str("END PGM CALIB MM\n");
    s
}

fn sphere_scenario(stylus: &Stylus, table_radius: f64) -> sim::Scenario {
    let c = SPHERE_CENTRE;
    scenario(&format!(
        "machine = \"table-ac\"\n{}[[sphere]]\ncenter = [{}, {}, {}]\nradius = {SPHERE_RADIUS}\n",
        stylus.probe_section(table_radius),
        c[0],
        c[1],
        c[2]
    ))
}

/// Uncalibrated (the probe table holds the mean lateral effective radius R - p),
/// every point of 444 is off along its normal by what the stylus does there: lobes,
/// axial pre-travel, offset and length; micrometres.
#[test]
fn uncalibrated_444_is_off_by_the_physics_of_the_stylus() {
    let table_radius = REAL.ball - REAL.pretravel;
    let sc = sphere_scenario(&REAL, table_radius);
    let points = sphere_points();
    let blocks: Vec<String> = points.iter().map(|(p, n)| block_444(*p, *n)).collect();
    let cfg = cycles_config(&sc);
    let mut m = CanInproc::open(&sc);
    let report = run_on(&program(&blocks), &cfg, &mut m, "444-uncal");
    let mut largest: f64 = 0.0;
    for (c, (_, n)) in report.cycles.iter().zip(&points) {
        assert_eq!(c.status, Status::Ok, "{:?}", c.message);
        let want = REAL.uncalibrated_error(*n, table_radius);
        let got = c.q["Q164"];
        println!("444 normal {n:?}: Q164 {got:+.7} mm, the physics {want:+.7} mm");
        assert!(
            (got - want).abs() < 2e-5,
            "normal {n:?}: Q164 = {got} but the stylus's physics gives {want}"
        );
        largest = largest.max(want.abs());
    }
    assert!(
        largest > 0.003,
        "the test's stylus errs by {largest} mm only"
    );
}

fn block_431(pts: [V; 3]) -> String {
    format!(
        "TCH PROBE 431 MEASURE PLANE ~\n  Q263={:+} ~\n  Q264={:+} ~\n  Q294={:+} ~\n  Q265={:+} ~\n  Q266={:+} ~\n  Q295={:+} ~\n  Q296={:+} ~\n  Q297={:+} ~\n  Q298={:+} ~\n  Q320=+2 ~\n  Q260=+60 ~\n  Q281=+0\n",
        pts[0][0], pts[0][1], pts[0][2], pts[1][0], pts[1][1], pts[1][2], pts[2][0], pts[2][1], pts[2][2]
    )
}

/// On a flat face at Z 10, 431's measured heights Q173..Q175 are off by the axial
/// pre-travel's difference to the table's R and the length error.
#[test]
fn uncalibrated_431_heights_are_off_by_the_physics_of_the_stylus() {
    let table_radius = REAL.ball - REAL.pretravel;
    let sc = scenario(&format!(
        "machine = \"table-ac\"\n{}[[plane]]\npoint = [0.0, 0.0, 10.0]\nnormal = [0.0, 0.0, 1.0]\n",
        REAL.probe_section(table_radius)
    ));
    let pts = [[0.0, 0.0, 10.0], [40.0, 5.0, 10.0], [5.0, 35.0, 10.0]];
    let cfg = cycles_config(&sc);
    let mut m = CanInproc::open(&sc);
    let report = run_on(&program(&[block_431(pts)]), &cfg, &mut m, "431-uncal");
    let c = &report.cycles[0];
    assert_eq!(c.status, Status::Ok, "{:?}", c.message);
    let want = 10.0 + REAL.uncalibrated_error([0.0, 0.0, 1.0], table_radius);
    for k in ["Q173", "Q174", "Q175"] {
        println!("431 {k} {:+.7} mm, the physics {want:+.7} mm", c.q[k]);
        assert!(
            (c.q[k] - want).abs() < 2e-5,
            "{k} = {} but the physics gives {want}",
            c.q[k]
        );
    }
    assert!(
        (want - 10.0).abs() > 0.0004,
        "off by {} mm only",
        want - 10.0
    );
}
