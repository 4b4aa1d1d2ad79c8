//! A real touch probe on the simulated machine: pre-travel that depends on the
//! direction (a kinematic seat's three lobes, another pre-travel along the stylus), a
//! ball centre off the spindle axis and a length error. Uncalibrated, cycles 431 and
//! 444 are off by what the physics says (computed here from the scenario's definition
//! of the stylus, independently of the simulator's code).

use cycles::probe_table::probes_file::ProbeCalibrations;
use cycles::program::Program;
use cycles::results::{ProgramReport, Status};
use cycles::runner::{run_program, RunOptions};
use hal::Machine;
use probebridge_tests::conformance::{Backend, CanInproc};
use probebridge_tests::conformance_modbus::open_tcp;
use probebridge_tests::world_machine::WorldMachine;
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
    let mut confirm = |_: &cycles::confirmation::Confirmation| true;
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

// ---------------------------------------------------------------------------------
// Cycle 460 calibrates the probe; 431, 444 and 451 then use its probe table row.

/// Cycle 460 on the sphere of radius `radius` whose centre is at tool-axis coordinate
/// `centre_z` (Q434, row 0 of the preset table at the machine origin), from the probe
/// put SET_UP above its pole in machine coordinates.
fn block_460(centre: V, radius: f64, q455: u32) -> String {
    block_460_from(centre, radius, q455, [0.0, 0.0], 1)
}

/// [`block_460`] with the probe put `off` (X, Y) mm off the sphere centre, and Q301
/// (1: to the clearance height between points; 0: around at the measuring height).
fn block_460_from(centre: V, radius: f64, q455: u32, off: [f64; 2], q301: u32) -> String {
    format!(
        "L Z+200 R0 FMAX M91\nL X{:+} Y{:+} R0 FMAX M91\nL Z{:+} R0 FMAX M91\n\
TCH PROBE 460 CALIBRATION OF TS ON A SPHERE ~\n  Q407={radius:+} ;RADIUS OF CALIB. SPHERE ~\n\
  Q320=+0 ;SET-UP CLEARANCE ~\n  Q301={q301:+} ;MOVE TO CLEARANCE ~\n  Q423=+8 ;NO. OF PROBE POINTS ~\n\
  Q380=+0 ;REFERENCE ANGLE ~\n  Q433=+1 ;CALIBRATE LENGTH ~\n  Q434={:+} ;DATUM FOR LENGTH ~\n\
  Q455={q455:+} ;NO. OF POINTS IN 3D CAL.\nL Z+200 R0 FMAX M91\n",
        centre[0] + off[0],
        centre[1] + off[1],
        centre[2] + radius + REAL.ball + 2.0 + 1.0,
        centre[2]
    )
}

/// What 460 must find for the stylus: R the mean lateral effective radius, the offset,
/// and L the effective length (the length error less the axial pre-travel's excess over
/// the lateral one, which L absorbs so that the pole reads R: see the probe table's doc).
fn truth_460(s: &Stylus) -> [(&'static str, f64); 4] {
    [
        ("R", s.ball - s.pretravel),
        ("CAL_OF1", s.offset[0]),
        ("CAL_OF2", s.offset[1]),
        ("L", s.length - (s.axial - s.pretravel)),
    ]
}

fn world_run(
    program: &str,
    cfg: &cycles::CyclesConfig,
    sc: &sim::Scenario,
    tag: &str,
) -> ProgramReport {
    let mut m = WorldMachine::new(sc);
    run_on(program, cfg, &mut m, tag)
}

/// With lobing of 4 µm, a 0.003 mm offset and a length error, and no noise, cycle 460
/// recovers R, CAL_OF1/2 and L to 0.2 µm, reports each with its uncertainty and writes
/// them to the probe table row.
#[test]
fn cycle_460_recovers_radius_offset_and_length() {
    let sc = sphere_scenario(&REAL, REAL.ball);
    let cfg = cycles_config(&sc);
    let report = world_run(
        &program(&[block_460(SPHERE_CENTRE, SPHERE_RADIUS, 0)]),
        &cfg,
        &sc,
        "460",
    );
    assert!(report.completed(), "{}", report.to_json());
    let c = &report.cycles[0];
    assert_eq!(c.cycle, 460);
    for (name, want) in truth_460(&REAL) {
        let got = c.q[name];
        println!(
            "460 {name} {got:+.7} mm, the stylus {want:+.7} mm, u {:?}",
            c.u.get(name)
        );
        assert!(
            (got - want).abs() <= 2e-4,
            "{name} = {got}, the stylus has {want}"
        );
        assert!(
            c.u.get(name).is_some_and(|u| u.is_finite()),
            "{name}: {:?}",
            c.u
        );
    }
    let cal = c.calibration.as_ref().expect("460's report");
    assert!(cal.offset_measured && cal.length_measured, "{cal:?}");
    assert_eq!(cal.before.r, REAL.ball);
    let rows = ProbeCalibrations::load(&cfg.calibrations.path, &cfg.probes).unwrap();
    let row = rows.row("TOUCH_PROBE").expect("the row written");
    assert_eq!(
        (row.r, row.cal_of1, row.cal_of2, row.l),
        (c.q["R"], c.q["CAL_OF1"], c.q["CAL_OF2"], c.q["L"])
    );
    let json = report.to_json();
    assert!(
        json.contains("\"calibration\"") && json.contains("\"CAL_OF1\""),
        "{json}"
    );
}

/// The operator puts the probe over the sphere but not on its centre: 3 mm off, and
/// nearly as far as the cycle allows (half of Q407 + R: 11.5 mm here), in five
/// directions, with Q301 = 1 and 0. Cycle 460 touches the sphere only while probing
/// (the world's machine brakes and fails a positioning move that touches it), and
/// finds what it finds from a centred start.
#[test]
fn cycle_460_from_a_start_off_the_sphere_centre_touches_it_only_when_probing() {
    use cycles::cycle460::measure::START_REACH;
    let sc = sphere_scenario(&REAL, REAL.ball);
    let cfg = cycles_config(&sc);
    let reach = START_REACH * (SPHERE_RADIUS + REAL.ball);
    let mut runs = 0;
    for distance in [3.0, 0.98 * reach] {
        for az in [0.0f64, 90.0, 120.0, 180.0, 270.0] {
            for q301 in [1, 0] {
                let off = [
                    distance * az.to_radians().cos(),
                    distance * az.to_radians().sin(),
                ];
                let block = block_460_from(SPHERE_CENTRE, SPHERE_RADIUS, 0, off, q301);
                let tag = format!("460-off-{runs}");
                let report = world_run(&program(&[block]), &cfg, &sc, &tag);
                let case = format!("{distance:.2} mm off at {az}°, Q301={q301}");
                assert!(report.completed(), "{case}: {}", report.to_text());
                let c = &report.cycles[0];
                for (name, want) in truth_460(&REAL) {
                    assert!(
                        (c.q[name] - want).abs() <= 2e-4,
                        "{case}: {name} = {}, the stylus has {want}",
                        c.q[name]
                    );
                }
                runs += 1;
            }
        }
    }
    assert_eq!(runs, 20);
}

/// The world's machine without an orientable spindle (`Machine::orient_spindle`'s
/// default).
struct FixedSpindle(WorldMachine);

impl Machine for FixedSpindle {
    type Error = hal::MachineError;

    fn axes(&self) -> u8 {
        self.0.axes()
    }

    fn positions(&mut self) -> Result<hal::AxisPositions, hal::MachineError> {
        self.0.positions()
    }

    fn move_to(&mut self, target: &hal::AxisPositions, feed: f64) -> Result<(), hal::MachineError> {
        self.0.move_to(target, feed)
    }

    fn probe(&mut self, mv: &hal::ProbeMove) -> Result<hal::Contact, hal::MachineError> {
        self.0.probe(mv)
    }

    fn set_run(&mut self, run_id: u64) {
        self.0.set_run(run_id);
    }

    fn clock_ns(&mut self) -> u64 {
        self.0.clock_ns()
    }
}

/// A machine whose spindle cannot be oriented: the offset cannot be separated from
/// the sphere's position; R and L are still calibrated, the offset is kept, and the
/// report says why.
#[test]
fn without_an_orientable_spindle_the_offset_is_kept_and_said() {
    let sc = sphere_scenario(&REAL, REAL.ball);
    let cfg = cycles_config(&sc);
    let mut m = FixedSpindle(WorldMachine::new(&sc));
    let report = run_on(
        &program(&[block_460(SPHERE_CENTRE, SPHERE_RADIUS, 0)]),
        &cfg,
        &mut m,
        "460-fixed",
    );
    assert!(report.completed(), "{}", report.to_json());
    let c = &report.cycles[0];
    assert_eq!((c.q["CAL_OF1"], c.q["CAL_OF2"]), (0.0, 0.0));
    assert!(!c.u.contains_key("CAL_OF1"), "{:?}", c.u);
    let cal = c.calibration.as_ref().unwrap();
    assert!(!cal.offset_measured);
    assert!(
        cal.notes.iter().any(|n| n.contains("cannot be separated")),
        "{:?}",
        cal.notes
    );
    assert!(
        report.to_text().contains("cannot be separated"),
        "{}",
        report.to_text()
    );
    for (name, want) in [truth_460(&REAL)[0], truth_460(&REAL)[3]] {
        assert!(
            (c.q[name] - want).abs() <= 2e-4,
            "{name} = {}, the stylus has {want}",
            c.q[name]
        );
    }
}

/// 460 on a machine whose spindle orients (`bus`: how), on the scenario's stylus: it
/// completes, measures the offset and the length, finds each column to 0.2 µm, and
/// reports the offset's uncertainty.
fn run_460_with_an_orientable_spindle<M: Machine<Error = hal::MachineError>>(
    m: &mut M,
    cfg: &cycles::CyclesConfig,
    bus: &str,
) {
    let report = run_on(
        &program(&[block_460(SPHERE_CENTRE, SPHERE_RADIUS, 0)]),
        cfg,
        m,
        &format!("460-{bus}"),
    );
    assert!(report.completed(), "{}", report.to_json());
    let c = &report.cycles[0];
    let cal = c.calibration.as_ref().expect("460's report");
    assert!(cal.offset_measured && cal.length_measured, "{cal:?}");
    for (name, want) in truth_460(&REAL) {
        let got = c.q[name];
        println!("460 over {bus} {name} {got:+.7} mm, the stylus {want:+.7} mm");
        assert!(
            (got - want).abs() <= 2e-4,
            "{name} = {got}, the stylus has {want}"
        );
    }
    assert!(
        c.u.contains_key("CAL_OF1") && c.u.contains_key("CAL_OF2"),
        "{:?}",
        c.u
    );
}

/// Over Modbus, a PLC with command 5 (orient spindle, `[bus] spindle_orientation`)
/// turns the stylus with the spindle: 460 separates the offset as on the world's
/// machine, through the mailbox and the simulated PLC's oriented stop.
#[test]
fn over_modbus_command_5_orients_the_spindle_and_460_finds_the_offset() {
    let sc = sphere_scenario(&REAL, REAL.ball);
    let mut m = open_tcp(&sc, |b| b.spindle_orientation = true);
    run_460_with_an_orientable_spindle(&mut m, &cycles_config(&sc), "Modbus");
    // The PLC left the spindle at 0°, where the cycle started.
    assert_eq!(m.plc.with_program(|p| p.spindle_deg()), 0.0);
}

/// Over CANopen, the spindle's own drive (`[spindle]` of table-ac: CiA 402 profile
/// position on node 6) turns the stylus: 460 separates the offset as on the world's
/// machine, through the master's oriented stops (new set-point, acknowledge, target
/// reached) and the simulated spindle drive.
#[test]
fn over_canopen_the_spindle_drive_orients_and_460_finds_the_offset() {
    let sc = sphere_scenario(&REAL, REAL.ball);
    assert!(sc.machine.spindle.is_some(), "table-ac has a spindle drive");
    let mut m = CanInproc::open(&sc);
    run_460_with_an_orientable_spindle(&mut m, &cycles_config(&sc), "CANopen");
    // The spindle drive stands at 0° again, where the cycle started.
    drop(m.machine);
    let sim = m.keep.stop().expect("the simulation ran");
    assert_eq!(sim.spindle_deg(), Some(0.0));
}

/// A bridge configured for command 5 against a PLC whose program lacks it: the PLC
/// rejects the first orientation, which comes before any move; the cycle fails naming
/// the command and the key, nothing moved and no probe row is written.
#[test]
fn over_modbus_a_plc_without_command_5_fails_460_before_anything_moves() {
    let sc = sphere_scenario(&REAL, REAL.ball);
    let cfg = cycles_config(&sc);
    let mut m = open_tcp(&sc, |b| b.spindle_orientation = true);
    m.plc.with_program(|p| p.knobs.no_orient_spindle = true);
    let text = program(&[block_460(SPHERE_CENTRE, SPHERE_RADIUS, 0)]);
    // The positioning blocks before the cycle run; the cycle itself must not move.
    let report = run_on(&text, &cfg, &mut m, "460-modbus-rejected");
    let c = report
        .cycles
        .iter()
        .find(|c| c.cycle == 460)
        .expect("the 460 block ran");
    assert_eq!(c.status, Status::Error, "{}", report.to_json());
    let why = c.message.clone().unwrap_or_default();
    assert!(
        why.contains("command 5") && why.contains("spindle_orientation = false"),
        "{why}"
    );
    let start = [
        SPHERE_CENTRE[0],
        SPHERE_CENTRE[1],
        SPHERE_CENTRE[2] + SPHERE_RADIUS + REAL.ball + 3.0,
    ];
    let here = m.positions().unwrap().xyz();
    for i in 0..3 {
        assert!(
            (here[i] - start[i]).abs() < 1e-6,
            "moved to {here:?} from {start:?}"
        );
    }
    assert!(
        !cfg.calibrations.path.exists(),
        "a probe row was written: {}",
        cfg.calibrations.path.display()
    );
}

/// After 460 with a 3D calibration (8 directions per ring: the three lobes resolved),
/// 444 lands within 0.3 µm of the sphere in the same program (the row is the probe's
/// from the next cycle on), and 431 on a face with the written row, where uncalibrated
/// they are off by micrometres (the tests above).
#[test]
fn after_460_431_and_444_land_on_the_truth() {
    let sc = sphere_scenario(&REAL, REAL.ball);
    let cfg = cycles_config(&sc);
    let points = sphere_points();
    let mut blocks = vec![block_460(SPHERE_CENTRE, SPHERE_RADIUS, 8)];
    blocks.extend(points.iter().map(|(p, n)| block_444(*p, *n)));
    let report = world_run(&program(&blocks), &cfg, &sc, "460-444");
    assert!(report.completed(), "{}", report.to_json());
    for (c, (_, n)) in report.cycles[1..].iter().zip(&points) {
        let got = c.q["Q164"];
        println!("444 after 460, normal {n:?}: Q164 {got:+.7} mm");
        assert!(got.abs() <= 3e-4, "normal {n:?}: Q164 = {got}");
    }

    let plane = scenario(&format!(
        "machine = \"table-ac\"\n{}[[plane]]\npoint = [0.0, 0.0, 10.0]\nnormal = [0.0, 0.0, 1.0]\n",
        REAL.probe_section(REAL.ball)
    ));
    let mut cfg431 = cycles_config(&plane);
    cfg431.use_calibrations(&cfg.calibrations.path).unwrap();
    let pts = [[0.0, 0.0, 10.0], [40.0, 5.0, 10.0], [5.0, 35.0, 10.0]];
    let report = world_run(&program(&[block_431(pts)]), &cfg431, &plane, "460-431");
    assert!(report.completed(), "{}", report.to_json());
    let c = &report.cycles[0];
    for k in ["Q173", "Q174", "Q175"] {
        println!("431 after 460: {k} {:+.7} mm", c.q[k]);
        assert!((c.q[k] - 10.0).abs() <= 3e-4, "{k} = {}", c.q[k]);
    }
}

/// 451 on the A/C table with the real stylus, calibrated by 460 first in the same
/// program: the injected location errors are recovered to 1e-4.
#[test]
fn cycle_451_with_the_calibrated_probe_recovers_the_errors() {
    let centre = [50.0, -30.0, 80.0];
    let sc = scenario(&format!(
        "machine = \"table-ac\"\nseed = 1\n{}[truth]\nEX0C = 0.012\nEY0C = -0.008\nEA0C = 0.004\nEB0A = 0.005\n\
[[sphere]]\ncenter = [{}, {}, {}]\nradius = 12.5\n",
        REAL.probe_section(REAL.ball),
        centre[0],
        centre[1],
        centre[2]
    ));
    let cfg = cycles_config(&sc);
    let z = centre[2] + 12.5 + REAL.ball + 2.0 + 5.0;
    let b451 = format!(
        "L X{:+} Y{:+} Z{z:+} R0 FMAX\nTCH PROBE 451 MEASURE KINEMATICS ~\n  Q406=+2 ~\n  Q407=+12.5 ~\n  Q320=+0 ~\n  Q408=+0 ~\n  Q253=+750 ~\n  Q380=+0 ~\n\
  Q411=-90 ~\n  Q412=+90 ~\n  Q413=+0 ~\n  Q414=+4 ~\n  Q415=+0 ~\n  Q416=+0 ~\n  Q417=+0 ~\n  Q418=+0 ~\n\
  Q419=+90 ~\n  Q420=+270 ~\n  Q421=+0 ~\n  Q422=+3 ~\n  Q423=+4 ~\n  Q431=+1 ~\n  Q432=+0\n",
        centre[0], centre[1]
    );
    let program = program(&[block_460(centre, 12.5, 8), b451]);
    let parsed = Program::parse(&program, &cfg).unwrap_or_else(|e| panic!("{e}"));
    let dir = std::env::temp_dir().join(format!("pb-calib-451-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut confirm = |_: &cycles::confirmation::Confirmation| true;
    let mut progress = |_| {};
    let mut opts = RunOptions {
        out_dir: dir.clone(),
        confirm: &mut confirm,
        progress: &mut progress,
        kinematics: Some(dir.join("kinematics.toml")),
        estimator: None,
    };
    let mut m = WorldMachine::new(&sc);
    let report = run_program(&parsed, &mut m, &cfg, &mut opts);
    assert!(report.completed(), "{}", report.to_json());
    let k = report.cycles[1].kinematics.as_ref().expect("451's report");
    for name in ["EX0C", "EY0C", "EA0C", "EB0A"] {
        let truth = sc.truth.get(name).unwrap();
        let got = k.errors_after[name];
        println!("451 after 460: {name} {got:+.7}, injected {truth:+.7}");
        assert!(
            (got - truth).abs() <= 1e-4,
            "{name}: identified {got} vs injected {truth}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
