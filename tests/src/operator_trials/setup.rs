//! From a [`Case`] to what runs: the scenario (the machine's truth and the real
//! probe), the machine configuration with its state folder, the NC program as the
//! operator typed it, whether the case stays within what docs/cycles.md promises
//! (the reach, the tolerances), and the truth each result is held against.

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
        451 => cycle451(case, &mut s, &ms, clear, probe.dist, &mut pre),
        460 => cycle460(case, &mut s, &ms, clear, probe.dist, calib_centre),
        431 => cycle431(case, &mut s, &ms, clear, calib_centre, &mut pre),
        _ => cycle444(case, &mut s, &ms, clear, calib_centre, &mut pre),
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

fn cycle451(
    case: &Case,
    s: &mut Setup,
    ms: &MachineSpec,
    clear: f64,
    dist: f64,
    pre: &mut Vec<String>,
) -> (Vec<String>, Truth) {
    let t = ms.tool;
    let inch = case.inch == 1.0;
    let true_centre = s.sc.spheres[0].center;
    let rs = SPHERE + BALL;
    let reach = cycles::cycle451::measure::LOCATE_REACH * rs;
    let typed = SPHERE * (1.0 + case.q407_err);
    let tol = s.cfg.parameters.max_dev_cal_ball;
    if (typed - SPHERE).abs() > tol {
        s.beyond.push(format!(
            "Q407 {:.4} mm off the sphere's radius (maxDevCalBall {tol})",
            typed - SPHERE
        ));
    }
    if case.stale_r.abs() > tol {
        s.beyond
            .push(format!("the probe table's R {:+.4} mm off", case.stale_r));
    }
    let rot = left_rotary(case, ms);
    let q431 = case.q431 as u8;
    let centre0 = [true_centre.x, true_centre.y, true_centre.z];
    let mut body = Vec::new();
    let q147;
    if q431 == 1 || q431 == 3 {
        let cc = to_cycle(t, sphere_at(&s.sc, &rot, true_centre));
        let height = clear + case.rise * dist;
        if case.off > 1.0 {
            s.beyond
                .push(format!("start {:.3} x the reach off the centre", case.off));
        }
        if case.rise > 1.0 {
            s.beyond
                .push(format!("start {:.3} mm above the pole", height));
        }
        let start = start_over(cc, rs, case.off * reach, case.off_dir, height);
        body.extend(approach(t, ms.safe, &rot, to_machine(t, start), inch));
        q147 = [0.0; 3];
    } else {
        let (sn, cs) = case.preset_dir.to_radians().sin_cos();
        let e = case.preset_err * reach;
        let err = to_machine(t, [e * cs, e * sn, case.preset_up]);
        if case.preset_err > 1.0 || case.preset_up.abs() > reach {
            s.beyond.push(format!(
                "the preset {:.3} mm off the sphere centre",
                e.hypot(case.preset_up)
            ));
        }
        let mut row = cycles::preset_table::Preset::origin(1);
        [row.x, row.y, row.z] = [0, 1, 2].map(|i| centre0[i] + err[i]);
        s.cfg.presets.rows.retain(|r| r.number != 1);
        s.cfg.presets.rows.push(row);
        pre.push("CYCL DEF 247 DATUM SETTING ~\n  Q339=+1 ;DATUM NUMBER".into());
        let away = to_machine(t, {
            let c = to_cycle(t, centre0);
            [c[0] + 70.0, c[1], c[2] + 60.0]
        });
        body.extend(approach(t, ms.safe, &rot, away, inch));
        q147 = [0, 1, 2].map(|i| -err[i]);
    }
    let (first, _, q, range, pts) = ms.first;
    let ax = |q: u32, r: [f64; 2], n: u32| {
        format!(
            "  Q{}={:+} ~\n  Q{}={:+} ~\n  Q{}=+0 ~\n  Q{}={:+} ~\n",
            q,
            r[0],
            q + 1,
            r[1],
            q + 2,
            q + 3,
            n
        )
    };
    let (with_first, with_c) = match case.axes as u8 {
        0 => (true, false),
        1 => (false, true),
        _ => (true, true),
    };
    let mut axes = String::new();
    for (qb, letter) in [(411, Axis::A), (415, Axis::B), (419, Axis::C)] {
        let on = (letter == first && with_first) || (letter == Axis::C && with_c);
        if !on {
            axes.push_str(&ax(qb, [0.0, 0.0], 0));
        } else if letter == Axis::C {
            axes.push_str(&ax(qb, ms.c.0, ms.c.1));
        } else {
            axes.push_str(&ax(q, range, pts));
        }
    }
    body.push(format!(
        "TCH PROBE 451 MEASURE KINEMATICS ~\n  Q406={:+} ;MODE ~\n  Q407={} ;SPHERE RADIUS ~\n  Q320={} ;SET-UP CLEARANCE ~\n  Q408={} ;RETR. HEIGHT ~\n  Q253={} ;F PRE-POSITIONING ~\n  Q380=+0 ;REFERENCE ANGLE ~\n{axes}  Q423={:+} ;NO. OF PROBE POINTS ~\n  Q431={:+} ;PRESET ~\n  Q432={:+} ;BACKLASH, ANG. RANGE",
        case.mode,
        len(typed, inch),
        len(case.q320, inch),
        len(case.q408, inch),
        feed(case.q253, inch),
        case.points,
        q431,
        case.q432
    ));
    let shift = stylus_shift(case);
    let head = !ms.first.1;
    let truth = Truth::Kinematics {
        check_errors: case.mode == 2.0,
        centre: centre0,
        check_preset: (q431 == 1 || q431 == 3) && case.mode != 0.0,
        q147,
        // A constant shift of every centre moves the fitted axes (the docs: an
        // uncalibrated stylus is not covered); the head turns it with B.
        allow_pos: if head { 2.0 * shift } else { shift },
        allow_preset: shift,
    };
    (body, truth)
}

fn cycle460(
    case: &Case,
    s: &mut Setup,
    ms: &MachineSpec,
    clear: f64,
    dist: f64,
    centre: Vector3<f64>,
) -> (Vec<String>, Truth) {
    let t = ms.tool;
    let inch = case.inch == 1.0;
    let rs = SPHERE + BALL;
    let reach = cycles::cycle460::measure::START_REACH * rs;
    let typed = SPHERE * (1.0 + case.q407_err);
    let tol = s.cfg.parameters.max_dev_cal_ball;
    if (typed - SPHERE).abs() > tol {
        s.beyond.push(format!(
            "Q407 {:.4} mm off the sphere's radius",
            typed - SPHERE
        ));
    }
    if case.off > 1.0 {
        s.beyond
            .push(format!("start {:.3} x the reach off the centre", case.off));
    }
    if case.rise > 1.0 {
        s.beyond.push(format!(
            "start {:.3} mm above the pole",
            clear + case.rise * dist
        ));
    }
    let rot = left_rotary(case, ms);
    let cc = to_cycle(t, sphere_at(&s.sc, &rot, centre));
    let start = start_over(
        cc,
        rs,
        case.off * reach,
        case.off_dir,
        clear + case.rise * dist,
    );
    let mut body = approach(t, ms.safe, &rot, to_machine(t, start), inch);
    body.push(block460(case, typed, case.q320, cc[2], inch));
    body.push(l91(&[(LETTERS[t], ms.safe)], inch));
    (
        body,
        Truth::Calibration(truth460(
            case,
            typed,
            s.sc.machine.spindle.is_some() || case.backend == 2.0,
        )),
    )
}

fn block460(case: &Case, typed: f64, q320: f64, q434: f64, inch: bool) -> String {
    format!(
        "TCH PROBE 460 CALIBRATION OF TS ON A SPHERE ~\n  Q407={} ;RADIUS OF CALIB. SPHERE ~\n  Q320={} ;SET-UP CLEARANCE ~\n  Q301={:+} ;MOVE TO CLEARANCE ~\n  Q423={:+} ;NO. OF PROBE POINTS ~\n  Q380=+0 ;REFERENCE ANGLE ~\n  Q433=+1 ;CALIBRATE LENGTH ~\n  Q434={} ;DATUM FOR LENGTH ~\n  Q455={:+} ;NO. OF POINTS IN 3D CAL.",
        len(typed, inch),
        len(q320, inch),
        case.q301,
        case.points,
        len(q434, inch),
        case.q455
    )
}

/// 460's columns: the stylus's truth, with the certificate's part of Q407 in R (the
/// docs: it goes in unseen, within maxDevCalBall), and the lobes where 3 or 4 points
/// cannot tell them from the circle.
fn truth460(case: &Case, typed: f64, oriented: bool) -> Vec<(&'static str, f64, f64)> {
    let axial = if case.axial.is_nan() {
        case.pretravel
    } else {
        case.axial
    };
    let aliased = if case.points <= 4.0 { case.lobing } else { 0.0 };
    let q407 = if (typed - SPHERE).abs() <= 0.1 {
        SPHERE - typed
    } else {
        0.0
    };
    let mut v = vec![
        ("R", BALL - case.pretravel + q407, aliased),
        ("L", case.len_err - (axial - case.pretravel), aliased),
    ];
    if oriented {
        v.push(("CAL_OF1", case.off1, aliased));
        v.push(("CAL_OF2", case.off2, aliased));
    }
    v
}

/// Cycle 460 on the calibration sphere before a 431 or 444 (nominal values, the drawn
/// Q455 and points), with its L blocks.
fn calibration_first(case: &Case, ms: &MachineSpec, centre: Vector3<f64>, pre: &mut Vec<String>) {
    let t = ms.tool;
    let inch = case.inch == 1.0;
    let cc = to_cycle(t, [centre.x, centre.y, centre.z]);
    let start = [cc[0], cc[1], cc[2] + SPHERE + BALL + 2.0];
    pre.extend(approach(t, ms.safe, &[], to_machine(t, start), inch));
    let mut nominal = case.clone();
    nominal.q301 = 1.0;
    nominal.points = 8.0;
    pre.push(block460(&nominal, SPHERE, 0.0, cc[2], inch));
    pre.push(l91(&[(LETTERS[t], ms.safe)], inch));
}

fn cycle431(
    case: &Case,
    s: &mut Setup,
    ms: &MachineSpec,
    clear: f64,
    calib: Vector3<f64>,
    pre: &mut Vec<String>,
) -> (Vec<String>, Truth) {
    let t = ms.tool;
    let inch = case.inch == 1.0;
    let n = unit([
        case.tilt2.to_radians().tan(),
        -case.tilt1.to_radians().tan(),
        1.0,
    ]);
    // The face 60 mm under the calibration sphere's centre, so that the sphere stands
    // clear of the face's material on every machine.
    let calib_c = to_cycle(t, [calib.x, calib.y, calib.z]);
    let face = [FACE_431[0], FACE_431[1], calib_c[2] - 60.0];
    let height = |x: f64, y: f64| face[2] - (n[0] * (x - face[0]) + n[1] * (y - face[1])) / n[2];
    let pm = to_machine(t, face);
    let nm = to_machine(t, n);
    s.sc.spheres.clear();
    s.sc.planes = sim::artefact::Plane::new(Vector3::from(pm), Vector3::from(nm))
        .into_iter()
        .collect();
    if case.calibrate == 1.0 {
        s.sc.spheres
            .extend(sim::artefact::Sphere::new(calib, SPHERE));
        calibration_first(case, ms, calib, pre);
    }
    let hs = [case.h1, case.h2, case.h3];
    let pts: Vec<[f64; 3]> = POINTS_431
        .iter()
        .zip(hs)
        .map(|(p, h)| [p[0], p[1], height(p[0], p[1]) + h])
        .collect();
    let top = pts.iter().map(|p| p[2]).fold(f64::MIN, f64::max) + BALL + clear;
    let calib_top = calib_c[2] + SPHERE + BALL + 0.2;
    let q260 = match (case.q260.is_nan(), case.calibrate == 1.0) {
        (true, true) => (top + 20.0).max(calib_top + 20.0),
        (true, false) => top + 20.0,
        _ => case.q260,
    };
    let lift = (1.0 / n[2] - 1.0) * BALL;
    // The start is SET_UP + Q320 + the table's R over the nominal point.
    let table_r = (BALL - case.pretravel + case.stale_r).max(0.05);
    let room = clear + table_r - BALL;
    for (i, h) in hs.iter().enumerate() {
        // Nominal under the face by more than that room: the start is in it.
        if -h > room - 0.3 - lift {
            s.beyond.push(format!(
                "point {} nominal {h:+.3} mm under the face, beyond SET_UP + Q320",
                i + 1
            ));
        }
    }
    if case.calibrate == 1.0 && q260 < calib_top {
        s.beyond.push(format!(
            "Q260 {q260:+.3} below the calibration sphere's top"
        ));
    }
    let mut body = vec![l91(&[(LETTERS[t], ms.safe)], inch)];
    let mut block = String::from("TCH PROBE 431 MEASURE PLANE ~\n");
    for (p, q) in pts
        .iter()
        .zip([[263, 264, 294], [265, 266, 295], [296, 297, 298]])
    {
        for k in 0..3 {
            block.push_str(&format!("  Q{}={} ~\n", q[k], len(p[k], inch)));
        }
    }
    block.push_str(&format!(
        "  Q320={} ;SET-UP CLEARANCE ~\n  Q260={} ;CLEARANCE HEIGHT ~\n  Q281=+0 ;MEASURING LOG",
        len(case.q320, inch),
        len(q260, inch)
    ));
    body.push(block);
    // Truth: the face's heights under the ball's centre (which the offset moves), the
    // ball's distance along the tool axis (tilted face), the length error; the angles
    // of the face itself.
    let calibrated = case.calibrate == 1.0;
    let p = pretravel(case, n);
    let mut v = Vec::new();
    for (i, q) in ["Q173", "Q174", "Q175"].into_iter().enumerate() {
        let [x, y] = POINTS_431[i];
        let want = if calibrated {
            height(x, y) + BALL * (1.0 / n[2] - 1.0)
        } else {
            height(x + case.off1, y + case.off2) + (BALL - p) / n[2] + case.len_err - table_r
        };
        v.push((q, want, if calibrated { stylus_shift(case) } else { 0.0 }));
    }
    v.push(("Q158", case.tilt1, 0.0));
    v.push(("Q159", case.tilt2, 0.0));
    (body, Truth::Plane(v))
}

fn cycle444(
    case: &Case,
    s: &mut Setup,
    ms: &MachineSpec,
    clear: f64,
    calib: Vector3<f64>,
    pre: &mut Vec<String>,
) -> (Vec<String>, Truth) {
    let t = ms.tool;
    let inch = case.inch == 1.0;
    let (c, r) = SPHERE_444;
    let (se, ce) = case.el.to_radians().sin_cos();
    let (sa, ca) = case.az.to_radians().sin_cos();
    let n = [ce * ca, ce * sa, se];
    let real = r + case.surf;
    s.sc.spheres = sim::artefact::Sphere::new(Vector3::from(to_machine(t, c)), real)
        .into_iter()
        .collect();
    s.sc.planes.clear();
    if case.calibrate == 1.0 {
        s.sc.spheres
            .extend(sim::artefact::Sphere::new(calib, SPHERE));
        calibration_first(case, ms, calib, pre);
    }
    let p = [0, 1, 2].map(|i| c[i] + r * n[i]);
    let top = c[2] + real + BALL;
    let calib_top = to_cycle(t, [calib.x, calib.y, calib.z])[2] + SPHERE + BALL + 0.2;
    let q260 = match (case.q260.is_nan(), case.calibrate == 1.0) {
        (true, true) => (top + clear + 20.0).max(calib_top + 20.0),
        (true, false) => top + clear + 20.0,
        _ => case.q260,
    };
    let table_r = (BALL - case.pretravel + case.stale_r).max(0.05);
    if case.surf > clear + table_r - BALL - 0.2 {
        s.beyond.push(format!(
            "the surface {:+.3} mm beyond the nominal point, within SET_UP + Q320",
            case.surf
        ));
    }
    let horizontal = (r + BALL + clear) * ce;
    if case.el < 0.0 && horizontal < real + BALL + 0.2 {
        s.beyond
            .push("the start below the equator, under the sphere's overhang".into());
    }
    if case.calibrate == 1.0 && q260 < calib_top {
        s.beyond.push(format!(
            "Q260 {q260:+.3} below the calibration sphere's top"
        ));
    }
    if q260 < top + 0.2 {
        s.beyond
            .push(format!("Q260 {q260:+.3} below the sphere's top"));
    }
    let mut body = vec![l91(&[(LETTERS[t], ms.safe)], inch)];
    body.push(format!(
        "TCH PROBE 444 PROBING 3D ~\n  Q263={} ~\n  Q264={} ~\n  Q294={} ~\n  Q581={:+.6} ~\n  Q582={:+.6} ~\n  Q583={:+.6} ~\n  Q320={} ~\n  Q260={} ~\n  QS400=\" \" ~\n  Q309=+0",
        len(p[0], inch),
        len(p[1], inch),
        len(p[2], inch),
        n[0],
        n[1],
        n[2],
        len(case.q320, inch),
        len(q260, inch)
    ));
    let shift = [case.off1, case.off2, -case.len_err];
    let (want, allow) = if case.calibrate == 1.0 {
        let axial = if case.axial.is_nan() {
            case.pretravel
        } else {
            case.axial
        };
        let resolved = case.q455 >= 7.0 && (s.sc.machine.spindle.is_some() || case.backend == 2.0);
        let allow = if resolved {
            0.0
        } else {
            0.25 * (axial - case.pretravel).abs() + case.lobing + case.off1.hypot(case.off2)
        };
        (case.surf, allow)
    } else {
        (
            case.surf + BALL - pretravel(case, n) - table_r - dot(shift, n),
            0.0,
        )
    };
    (body, Truth::Point(want, allow))
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
