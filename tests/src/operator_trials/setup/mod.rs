//! From a [`Case`] to what runs: the scenario (the machine's truth and the real
//! probe), the machine configuration with its state folder, the NC program as the
//! operator typed it, whether the case stays within what docs/cycles.md promises
//! (the reach, the tolerances), and the truth each result is held against.

mod calibration;
mod kinematics;
mod plane;
mod point;

use super::draw::{Case, MACHINES};
use crate::configs_dir;
use cycles::CyclesConfig;
use hal::{Axis, AxisPositions};
use nalgebra::Vector3;
use std::path::{Path, PathBuf};

/// The probe's true ball radius in every case, mm.
pub const BALL: f64 = 3.0;
/// The calibration sphere's radius (451, 460), mm.
pub const SPHERE: f64 = 12.5;
/// Cycle 444's sphere: centre (cycle coordinates) and nominal radius, mm.
const SPHERE_444: ([f64; 3], f64) = ([-60.0, 40.0, 30.0], 20.0);
/// Cycle 431's face passes through this point (cycle coordinates; the tool-axis
/// coordinate is set 60 mm under the calibration sphere).
const FACE_431: [f64; 3] = [20.0, 10.0, 15.0];
/// Cycle 431's points in the working plane.
const POINTS_431: [[f64; 2]; 3] = [[0.0, 0.0], [60.0, 5.0], [10.0, 55.0]];

/// One shipped machine as the trials use it.
pub struct MachineSpec {
    pub scenario: &'static str,
    /// Index of the tool axis (0 X, 1 Y, 2 Z).
    pub tool: usize,
    /// The rotary axis other than C, whether it is in the table (else the head), its
    /// 451 parameters Q41x and its measured range (start, end, points).
    pub first: (Axis, bool, u32, [f64; 2], u32),
    /// C's measured range (start, end, points).
    pub c: ([f64; 2], u32),
    /// A tool-axis coordinate high above everything (machine coordinates).
    pub safe: f64,
}

pub fn spec(machine: usize) -> MachineSpec {
    match machine {
        0 => MachineSpec {
            scenario: "demo-sphere.toml",
            tool: 2,
            first: (Axis::A, true, 411, [-60.0, 60.0], 2),
            c: ([90.0, 270.0], 3),
            safe: 300.0,
        },
        1 => MachineSpec {
            scenario: "head-b-table-c.toml",
            tool: 2,
            first: (Axis::B, false, 415, [-50.0, 40.0], 2),
            c: ([90.0, 270.0], 3),
            safe: 300.0,
        },
        2 => MachineSpec {
            scenario: "horizontal-x-head-b-table-c.toml",
            tool: 0,
            first: (Axis::B, false, 415, [-50.0, 40.0], 2),
            c: ([120.0, 240.0], 2),
            safe: 350.0,
        },
        _ => MachineSpec {
            scenario: "horizontal-y-sphere.toml",
            tool: 1,
            first: (Axis::A, true, 411, [-45.0, 75.0], 2),
            c: ([90.0, 270.0], 2),
            safe: 250.0,
        },
    }
}

/// (main, minor, tool) to machine X, Y, Z for the tool axis `t`.
pub fn to_machine(t: usize, c: [f64; 3]) -> [f64; 3] {
    match t {
        0 => [c[2], c[0], c[1]],
        1 => [c[1], c[2], c[0]],
        _ => c,
    }
}

/// Machine X, Y, Z to (main, minor, tool) for the tool axis `t`.
pub fn to_cycle(t: usize, m: [f64; 3]) -> [f64; 3] {
    match t {
        0 => [m[1], m[2], m[0]],
        1 => [m[2], m[0], m[1]],
        _ => m,
    }
}

/// The truth a cycle's results are held against (I2), in the units of the results.
#[derive(Clone, Debug)]
pub enum Truth {
    /// 451: the scenario's injected errors (mode 2), the sphere centre at the rotary axes' 0
    /// (machine coordinates), the Q147..Q149 expected, and what the docs leave
    /// uncovered (an uncalibrated stylus): mm on positions, deg on angles.
    Kinematics {
        check_errors: bool,
        centre: [f64; 3],
        check_preset: bool,
        q147: [f64; 3],
        allow_pos: f64,
        allow_preset: f64,
    },
    /// 460: each column with what the docs leave in it unseen.
    Calibration(Vec<(&'static str, f64, f64)>),
    /// 431: Q-results with their truth and allowance.
    Plane(Vec<(&'static str, f64, f64)>),
    /// 444: Q164's truth and allowance.
    Point(f64, f64),
}

/// Everything one trial needs.
pub struct Setup {
    pub sc: sim::Scenario,
    pub cfg: CyclesConfig,
    pub text: String,
    /// Why the case is beyond what the docs promise (empty: within).
    pub beyond: Vec<String>,
    pub truth: Truth,
    pub cycle: u16,
    /// How often the program runs the cycle under test.
    pub runs: usize,
    /// The machine's state folder (presets, probe table, kinematics, QR).
    pub state: PathBuf,
    pub kinematics: PathBuf,
    /// Where protocols go (not machine state).
    pub out: PathBuf,
}

impl Drop for Setup {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(self.state.parent().unwrap_or(&self.state));
    }
}

/// A length as the program writes it.
fn len(v: f64, inch: bool) -> String {
    if inch {
        format!("{:+.7}", v / 25.4)
    } else {
        format!("{v:+.5}")
    }
}

/// `L` in machine coordinates (M91) to the given axes, rapid.
fn l91(axes: &[(char, f64)], inch: bool) -> String {
    let mut s = String::from("L");
    for (a, v) in axes {
        s.push_str(&format!(" {a}{}", len(*v, inch)));
    }
    s.push_str(" R0 FMAX M91");
    s
}

/// `L` to rotary angles (degrees in any unit).
fn l_rot(axes: &[(Axis, f64)]) -> Option<String> {
    let moved: Vec<String> = axes
        .iter()
        .filter(|(_, v)| *v != 0.0)
        .map(|(a, v)| format!("{}{v:+}", a.name()))
        .collect();
    (!moved.is_empty()).then(|| format!("L {} R0 FMAX", moved.join(" ")))
}

const LETTERS: [char; 3] = ['X', 'Y', 'Z'];

/// The L blocks that take the probe to `to` (machine coordinates) from anywhere: up
/// the tool axis to `safe`, turn the rotary axes, over, down.
fn approach(t: usize, safe: f64, rot: &[(Axis, f64)], to: [f64; 3], inch: bool) -> Vec<String> {
    let mut lines = vec![l91(&[(LETTERS[t], safe)], inch)];
    lines.extend(l_rot(rot));
    let plane: Vec<(char, f64)> = (0..3)
        .filter(|&i| i != t)
        .map(|i| (LETTERS[i], to[i]))
        .collect();
    lines.push(l91(&plane, inch));
    lines.push(l91(&[(LETTERS[t], to[t])], inch));
    lines
}

fn temp_state() -> (PathBuf, PathBuf, PathBuf) {
    use std::sync::atomic::{AtomicU64, Ordering};
    static N: AtomicU64 = AtomicU64::new(0);
    let root = std::env::temp_dir().join(format!(
        "pb-trials-{}-{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    ));
    let _ = std::fs::remove_dir_all(&root);
    let (state, out) = (root.join("state"), root.join("out"));
    std::fs::create_dir_all(&state).expect("temp state folder");
    std::fs::create_dir_all(&out).expect("temp out folder");
    (root, state, out)
}

/// The pre-travel the stylus has for a contact that pushes the ball along `n`
/// (cycle coordinates, unit): the sim's model written again here (stylus.rs: the
/// axial and lateral blended by the squared components, three lobes).
pub fn pretravel(c: &Case, n: [f64; 3]) -> f64 {
    let axial = if c.axial.is_nan() {
        c.pretravel
    } else {
        c.axial
    };
    let s2 = n[2] * n[2];
    let lateral = if n[0] == 0.0 && n[1] == 0.0 {
        c.pretravel
    } else {
        c.pretravel + c.lobing * (3.0 * (n[1].atan2(n[0]) - c.phase.to_radians())).cos()
    };
    s2 * axial + (1.0 - s2) * lateral
}

fn unit(v: [f64; 3]) -> [f64; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    [v[0] / n, v[1] / n, v[2] / n]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Builds the trial for `case`, or says why the case cannot be set up at all.
pub fn build(case: &Case) -> Result<Setup, String> {
    let machine = (case.machine as usize).min(3);
    let ms = spec(machine);
    let mut sc = sim::Scenario::load(
        &configs_dir().join("scenarios").join(ms.scenario),
        Some(&configs_dir().join("machines")),
    )
    .map_err(|e| e.to_string())?;
    debug_assert_eq!(sc.machine.name, MACHINES[machine]);
    let t = ms.tool;
    let axial = (!case.axial.is_nan()).then_some(case.axial);
    let effective = BALL - case.pretravel;
    sc.seed = case.seed as u64;
    sc.probe = sim::scenario::ProbeTruth {
        ball_radius: BALL,
        noise: case.noise,
        pretravel: case.pretravel,
        table_radius: Some((effective + case.stale_r).max(0.05)),
        axis: [Axis::X, Axis::Y, Axis::Z][t],
        pretravel_axial: axial,
        lobing: case.lobing.min(case.pretravel),
        lobing_phase: case.phase,
        offset: [case.off1, case.off2],
        length_error: case.len_err,
    };
    let calib_centre = sc.spheres.first().map(|s| s.center).ok_or("no sphere")?;
    let (root, state, out) = temp_state();
    let mut cfg = crate::cycles_config(&sc);
    let presets_name = format!("{}.presets.toml", sc.machine.name);
    cfg.presets.path = state.join(presets_name);
    cfg.calibrations.path = state.join(format!("{}.probes.toml", sc.machine.name));
    let kinematics = state.join("kinematics.toml");
    // The probe table states the repeatability the drawn noise gives (2 sigma), as
    // an operator states a probe's: u is scaled by it.
    for p in &mut cfg.probes {
        p.repeatability_2sigma = p.repeatability_2sigma.max(2.0 * case.noise);
    }
    let probe = cfg.probe("TOUCH_PROBE").ok_or("no TOUCH_PROBE")?.clone();
    let cycle = case.cycle as u16;
    let mut s = Setup {
        sc,
        cfg,
        text: String::new(),
        beyond: Vec::new(),
        truth: Truth::Point(0.0, 0.0),
        cycle,
        runs: if case.flow == 3.0 { 2 } else { 1 },
        state,
        kinematics,
        out,
    };
    let _ = &root;
    let clear = probe.set_up + case.q320;
    let mut pre: Vec<String> = Vec::new();
    let (body, truth) = match cycle {
        451 => kinematics::cycle451(case, &mut s, &ms, clear, probe.dist, &mut pre),
        460 => calibration::cycle460(case, &mut s, &ms, clear, probe.dist, calib_centre),
        431 => plane::cycle431(case, &mut s, &ms, clear, calib_centre, &mut pre),
        _ => point::cycle444(case, &mut s, &ms, clear, calib_centre, &mut pre),
    };
    s.truth = truth;
    s.text = program(case, t, &pre, &body);
    Ok(s)
}

/// The program around the cycle: `pre` (datum blocks, a calibration) first, then
/// `body` (positioning and the cycle) as the drawn flow puts it.
fn program(case: &Case, t: usize, pre: &[String], body: &[String]) -> String {
    let unit = if case.inch == 1.0 { "INCH" } else { "MM" };
    let mut lines = vec![
        format!("BEGIN PGM TRIAL {unit}"),
        format!("TOOL CALL \"TOUCH_PROBE\" {}", LETTERS[t]),
    ];
    lines.extend(pre.iter().cloned());
    let body = body.to_vec();
    match case.flow as u8 {
        1 => {
            lines.extend(["CALL LBL 1".into(), "M30".into(), "LBL 1".into()]);
            lines.extend(body);
            lines.push("LBL 0".into());
        }
        2 => {
            lines.extend(["CALL LBL 2".into(), "M30".into(), "LBL 1".into()]);
            lines.extend(body);
            lines.extend(["LBL 0", "LBL 2", "CALL LBL 1", "LBL 0"].map(String::from));
        }
        3 => {
            lines.push("LBL 1".into());
            lines.extend(body);
            lines.push("CALL LBL 1 REP 1".into());
        }
        4 => {
            lines.extend(
                [
                    "Q1 = 0",
                    "LBL 3",
                    "Q1 = Q1 + 1",
                    "FN 12: IF +Q1 LT +3 GOTO LBL 3",
                    "FN 9: IF +Q1 EQU +3 GOTO LBL 4",
                ]
                .map(String::from),
            );
            // Never runs: the jump above always skips it.
            lines.push(format!("L {}-99999 R0 FMAX M91", LETTERS[t]));
            lines.push("LBL 4".into());
            lines.extend(body);
        }
        _ => lines.extend(body),
    }
    lines.push(format!("END PGM TRIAL {unit}"));
    let mut text = lines.join("\n");
    text.push('\n');
    text
}

/// Rotary (table) axes as the operator left them.
fn left_rotary(case: &Case, ms: &MachineSpec) -> Vec<(Axis, f64)> {
    let (first, in_table, ..) = ms.first;
    vec![
        (first, if in_table { case.rot1 } else { 0.0 }),
        (Axis::C, case.rot2),
    ]
}

/// Where the true sphere centre `p` (table coordinates) is with the rotary axes at
/// `rot`, machine coordinates.
fn sphere_at(sc: &sim::Scenario, rot: &[(Axis, f64)], p: Vector3<f64>) -> [f64; 3] {
    let kin = sim::kinematics::TrueKinematics::new(&sc.machine, &sc.truth);
    let mut at = AxisPositions::new();
    for a in &sc.machine.axes {
        at.set(a.name, 0.0);
    }
    for (a, v) in rot {
        at.set(*a, *v);
    }
    let m = kin.table_to_machine(&at, p);
    [m.x, m.y, m.z]
}

/// The start over the sphere whose centre is `cc` (cycle coordinates): `off` x `reach`
/// off it in the plane, `height` above the pole, and never inside the sphere's
/// shadow (the L block down to it would touch the sphere).
fn start_over(cc: [f64; 3], rs: f64, off: f64, dir: f64, height: f64) -> [f64; 3] {
    let (sn, cs) = dir.to_radians().sin_cos();
    let d = off.abs();
    let above = if d < rs {
        (rs * rs - d * d).sqrt() + 0.2
    } else {
        0.2 - rs
    };
    let h = (rs + height).max(above);
    [cc[0] + off * cs, cc[1] + off * sn, cc[2] + h]
}

fn feed(v: f64, inch: bool) -> String {
    match v {
        -1.0 => "FMAX".into(),
        -2.0 => "FAUTO".into(),
        -3.0 => "PREDEF".into(),
        x if inch => format!("{:+.4}", x / 2.54),
        x => format!("{x:+.1}"),
    }
}

/// What the docs leave uncovered of an uncalibrated stylus in a location, mm: the
/// offset, the length error, the axial pre-travel's difference and the lobes.
fn stylus_shift(case: &Case) -> f64 {
    let axial = if case.axial.is_nan() {
        case.pretravel
    } else {
        case.axial
    };
    case.off1.hypot(case.off2)
        + case.len_err.abs()
        + (axial - case.pretravel).abs()
        + 2.0 * case.lobing
}

/// The R the cycle probes with: the probe table's, or after a 460 in the same
/// program the calibrated one (the mean lateral effective radius).
fn cycle_r(case: &Case) -> f64 {
    if case.calibrate == 1.0 {
        BALL - case.pretravel
    } else {
        (BALL - case.pretravel + case.stale_r).max(0.05)
    }
}

/// The state folder's files, name and bytes (I4).
pub fn snapshot(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut files: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(Result::ok)
                .filter(|e| e.path().is_file())
                .map(|e| {
                    (
                        e.file_name().to_string_lossy().into_owned(),
                        std::fs::read(e.path()).unwrap_or_default(),
                    )
                })
                .collect()
        })
        .unwrap_or_default();
    files.sort();
    files
}
