//! Cycle 451 MEASURE KINEMATICS on the simulated machines over CANopen (master and
//! simulated CiA 402 drives on the in-process bus), checked against the scenarios'
//! injected truth and against an independent computation of spec.md's formulas
//! written here with plain arrays (its own kinematic chain, its own Gauss-Newton).

use cycles::confirmation::{ConfirmKind, Confirmation};
use cycles::program::Program;
use cycles::results::{CycleResult, ProgramReport, Status};
use cycles::runner::{run_program, RunOptions};
use probebridge_tests::conformance::{Backend, CanInproc};
use probebridge_tests::spec451::*;
use probebridge_tests::{configs_dir, cycles_config, machine_config, scenario};

use std::path::{Path, PathBuf};

// ---------------------------------------------------------------------------------
// Running a program.

struct Run {
    report: ProgramReport,
    confirmations: Vec<Confirmation>,
}

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("pb-451-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn run_with(
    program: &str,
    sc: &sim::Scenario,
    cfg: &cycles::CyclesConfig,
    dir: &Path,
    answer: bool,
) -> Run {
    let program = Program::parse(program, cfg).unwrap_or_else(|e| panic!("{e}"));
    let mut m = CanInproc::open(sc);
    let mut confirmations = Vec::new();
    let mut confirm = |c: &Confirmation| {
        confirmations.push(c.clone());
        answer
    };
    let mut progress = |_| {};
    let mut opts = RunOptions {
        out_dir: dir.to_path_buf(),
        confirm: &mut confirm,
        progress: &mut progress,
        kinematics: Some(dir.join("kinematics.toml")),
        estimator: None,
    };
    let report = run_program(&program, &mut m, cfg, &mut opts);
    Run {
        report,
        confirmations,
    }
}

fn run(program: &str, sc: &sim::Scenario, dir: &Path) -> Run {
    run_with(program, sc, &cycles_config(sc), dir, true)
}

/// Per rotary axis: (start, end, incidence, points).
#[derive(Clone, Copy)]
struct Ax(f64, f64, f64, u32);
const NONE: Ax = Ax(0.0, 0.0, 0.0, 0);

struct P451 {
    mode: u8,
    radius: f64,
    q408: f64,
    a: Ax,
    b: Ax,
    c: Ax,
    points: u32,
    preset: u8,
    backlash: f64,
}

impl Default for P451 {
    fn default() -> Self {
        P451 {
            mode: 2,
            radius: 12.5,
            q408: 0.0,
            a: NONE,
            b: NONE,
            c: NONE,
            points: 4,
            // The probe is put over the sphere: the cycle locates it from there.
            preset: 1,
            backlash: 0.0,
        }
    }
}

/// The probe put 5 mm above the pole of the sphere at `centre`, then cycle 451.
fn program(p: &P451, centre: [f64; 3]) -> String {
    let z = centre[2] + p.radius + 3.0 + 2.0 + 5.0;
    format!(
        "0 BEGIN PGM K451 MM\n1 TOOL CALL \"TOUCH_PROBE\" Z\n2 L X{:+} Y{:+} Z{z:+} R0 FMAX\n\
3 TCH PROBE 451 MEASURE KINEMATICS ~\n  Q406={:+} ;MODE ~\n  Q407={:+} ;SPHERE RADIUS ~\n\
  Q320=+0 ;SET-UP CLEARANCE ~\n  Q408={:+} ;RETR. HEIGHT ~\n  Q253=+750 ;F PRE-POSITIONING ~\n\
  Q380=+0 ;REFERENCE ANGLE ~\n\
  Q411={:+} ~\n  Q412={:+} ~\n  Q413={:+} ~\n  Q414={:+} ~\n\
  Q415={:+} ~\n  Q416={:+} ~\n  Q417={:+} ~\n  Q418={:+} ~\n\
  Q419={:+} ~\n  Q420={:+} ~\n  Q421={:+} ~\n  Q422={:+} ~\n\
  Q423={:+} ;NO. OF PROBE POINTS ~\n  Q431={:+} ;PRESET ~\n  Q432={:+} ;BACKLASH, ANG. RANGE\n\
4 END PGM K451 MM\n",
        centre[0],
        centre[1],
        p.mode,
        p.radius,
        p.q408,
        p.a.0,
        p.a.1,
        p.a.2,
        p.a.3,
        p.b.0,
        p.b.1,
        p.b.2,
        p.b.3,
        p.c.0,
        p.c.1,
        p.c.2,
        p.c.3,
        p.points,
        p.preset,
        p.backlash
    )
}

fn demo_sphere() -> sim::Scenario {
    sim::Scenario::load(
        &configs_dir().join("scenarios/demo-sphere.toml"),
        Some(&configs_dir().join("machines")),
    )
    .unwrap()
}

fn head_b_table_c() -> sim::Scenario {
    sim::Scenario::load(
        &configs_dir().join("scenarios/head-b-table-c.toml"),
        Some(&configs_dir().join("machines")),
    )
    .unwrap()
}

fn only_cycle(r: &Run) -> &CycleResult {
    assert_eq!(r.report.cycles.len(), 1, "{:#?}", r.report);
    &r.report.cycles[0]
}

/// The one cycle of the run, which must have succeeded.
fn ok_cycle(r: &Run) -> &CycleResult {
    let c = only_cycle(r);
    assert_eq!(c.status, Status::Ok, "{:?}", c.message);
    c
}

fn json(r: &Run) -> serde_json::Value {
    let v: serde_json::Value = serde_json::from_str(&r.report.to_json()).unwrap();
    v["cycles"][0].clone()
}

fn all_location_errors(axes: &[char]) -> Vec<String> {
    axes.iter().flat_map(|a| qs_names(*a)).collect()
}

// ---------------------------------------------------------------------------------
// The tests.

#[test]
fn table_ac_mode_2_recovers_the_injected_errors_and_matches_spec() {
    let sc = demo_sphere();
    let dir = temp_dir("ac-mode2");
    let p = P451 {
        a: Ax(-90.0, 90.0, 0.0, 4),
        c: Ax(90.0, 270.0, 0.0, 3),
        ..P451::default()
    };
    let r = run(&program(&p, [50.0, -30.0, 80.0]), &sc, &dir);
    ok_cycle(&r);
    let v = json(&r);
    let after = errors_of(&v["kinematics"]["errors_after"]);
    for name in all_location_errors(&['A', 'C']) {
        let truth = sc.truth.get(&name).unwrap();
        assert!(
            (after[&name] - truth).abs() < 1e-4,
            "{name}: identified {} vs injected {truth}",
            after[&name]
        );
    }
    check_results_against_spec(&v, &machine_config(&sc));
    // Positions of A: 0 (reference), -90, -30, 30, 90 (latched), C at its incidence 0.
    let a = &v["kinematics"]["axes"][0];
    let angles: Vec<(f64, f64)> = a["positions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            (
                p["angles"]["A"].as_f64().unwrap(),
                p["angles"]["C"].as_f64().unwrap(),
            )
        })
        .collect();
    for (got, want) in angles.iter().zip([0.0, -90.0, -30.0, 30.0, 90.0]) {
        assert!(
            (got.0 - want).abs() < 1e-5 && got.1.abs() < 1e-5,
            "{angles:?}"
        );
    }
    assert!(r
        .report
        .protocols
        .iter()
        .any(|p| p.ends_with("TCHPRAUTO.html")));
    let html = std::fs::read_to_string(dir.join("TCHPRAUTO.html")).unwrap();
    for plot in ["EXA", "EYA", "EZA", "EXC", "EYC", "EZC"] {
        assert!(html.contains(&format!("<title>{plot}</title>")), "{plot}");
    }
    assert_eq!(html.matches("<svg").count(), 6);
    assert!(html.contains("stroke=\"red\"") && html.contains("stroke=\"green\""));
    // Mode 2 wrote them.
    let written = std::fs::read_to_string(dir.join("kinematics.toml")).unwrap();
    assert!(written.contains("EX0C"), "{written}");
}

#[test]
fn head_b_table_c_mode_2_recovers_the_injected_errors_and_matches_spec() {
    let sc = head_b_table_c();
    let dir = temp_dir("bc-mode2");
    let p = P451 {
        b: Ax(-60.0, 60.0, 0.0, 4),
        c: Ax(90.0, 270.0, 0.0, 3),
        ..P451::default()
    };
    let r = run(&program(&p, [40.0, 25.0, 60.0]), &sc, &dir);
    ok_cycle(&r);
    let v = json(&r);
    let after = errors_of(&v["kinematics"]["errors_after"]);
    for name in all_location_errors(&['B', 'C']) {
        let truth = sc.truth.get(&name).unwrap();
        assert!(
            (after[&name] - truth).abs() < 1e-4,
            "{name}: identified {} vs injected {truth}",
            after[&name]
        );
    }
    check_results_against_spec(&v, &machine_config(&sc));
}

#[test]
fn with_noise_the_result_is_the_least_squares_optimum() {
    let text = std::fs::read_to_string(configs_dir().join("scenarios/demo-sphere.toml"))
        .unwrap()
        .replace("noise = 0.0", "noise = 0.0015");
    let sc = scenario(&text);
    let cfg = machine_config(&sc);
    let dir = temp_dir("noise");
    let p = P451 {
        a: Ax(-90.0, 90.0, 0.0, 4),
        c: Ax(60.0, 300.0, 0.0, 5),
        ..P451::default()
    };
    let r = run(&program(&p, [50.0, -30.0, 80.0]), &sc, &dir);
    ok_cycle(&r);
    let v = json(&r);
    let ch = chain_of(&cfg);
    let ms = measured(&v);
    let after = errors_of(&v["kinematics"]["errors_after"]);
    let f_cycle = spec_objective(&ch, &after, &ms);
    let (e_ind, f_ind) = independent_optimum(&ch, &ms, &all_location_errors(&['A', 'C']));
    assert!(f_cycle > 1e-8, "the noise shows: {f_cycle}");
    assert!(
        f_ind >= f_cycle * (1.0 - 1e-9) - 1e-15,
        "the independent solver found a better residual: {f_ind} < {f_cycle}"
    );
    for (name, v) in &e_ind {
        assert!(
            (after[name] - v).abs() < 1e-6,
            "{name}: {} vs {v}",
            after[name]
        );
    }
    // Nudging any identified error makes the objective worse.
    for name in all_location_errors(&['A', 'C']) {
        for h in [1e-4, -1e-4] {
            let mut e = after.clone();
            *e.get_mut(&name).unwrap() += h;
            assert!(spec_objective(&ch, &e, &ms) > f_cycle, "{name} {h}");
        }
    }
    check_results_against_spec(&v, &cfg);
}

const HAND_WRITTEN: &str =
    "machine = \"table-ac\"\n\n# set by hand\n[errors]\nEB0A = 0.001\nEX0C = 0.002\n";

#[test]
fn mode_0_leaves_the_kinematics_file_byte_for_byte() {
    let sc = demo_sphere();
    let dir = temp_dir("mode0");
    std::fs::write(dir.join("kinematics.toml"), HAND_WRITTEN).unwrap();
    let p = P451 {
        mode: 0,
        c: Ax(90.0, 270.0, 0.0, 3),
        points: 3,
        ..P451::default()
    };
    let r = run(&program(&p, [50.0, -30.0, 80.0]), &sc, &dir);
    let c = ok_cycle(&r);
    assert_eq!(
        std::fs::read_to_string(dir.join("kinematics.toml")).unwrap(),
        HAND_WRITTEN
    );
    assert!(!dir.join("kinematics.toml.prev").exists());
    let v = json(&r);
    assert_eq!(v["kinematics"]["written"], false);
    // It reports what position optimisation would give, starting from the file.
    assert_eq!(v["kinematics"]["errors_before"]["EX0C"], 0.002);
    assert!((v["kinematics"]["errors_after"]["EX0C"].as_f64().unwrap() - 0.012).abs() < 2e-3);
    assert!(c.q["Q146"] < c.q["Q143"]);
    check_results_against_spec(&v, &machine_config(&sc));
}

#[test]
fn mode_1_changes_positions_only() {
    let sc = demo_sphere();
    let dir = temp_dir("mode1");
    std::fs::write(dir.join("kinematics.toml"), HAND_WRITTEN).unwrap();
    let p = P451 {
        mode: 1,
        a: Ax(-90.0, 90.0, 0.0, 2),
        c: Ax(90.0, 270.0, 0.0, 3),
        points: 3,
        ..P451::default()
    };
    let r = run(&program(&p, [50.0, -30.0, 80.0]), &sc, &dir);
    ok_cycle(&r);
    let cfg = machine_config(&sc);
    let path = dir.join("kinematics.toml");
    let k = cycles::kinematics_file::ActiveKinematics::load(&path, &cfg).unwrap();
    assert_eq!(
        std::fs::read_to_string(dir.join("kinematics.toml.prev")).unwrap(),
        HAND_WRITTEN
    );
    for name in ["EB0A", "EC0A", "EA0C", "EB0C", "EA0A", "EC0C"] {
        let before = if name == "EB0A" { 0.001 } else { 0.0 };
        assert_eq!(k.error(name), before, "{name} must not change in mode 1");
    }
    assert_ne!(k.error("EX0C"), 0.002);
    assert!(
        (k.error("EX0C") - 0.012).abs() < 2e-3,
        "{}",
        k.error("EX0C")
    );
    assert!(k.errors.contains_key("EY0A") || k.errors.contains_key("EZ0A"));
}

#[test]
fn a_sphere_of_the_wrong_radius_aborts_with_nothing_written() {
    let text = std::fs::read_to_string(configs_dir().join("scenarios/demo-sphere.toml"))
        .unwrap()
        .replace("radius = 12.5", "radius = 12.0");
    let sc = scenario(&text);
    let dir = temp_dir("radius");
    std::fs::write(dir.join("kinematics.toml"), HAND_WRITTEN).unwrap();
    let p = P451 {
        mode: 1,
        c: Ax(90.0, 270.0, 0.0, 3),
        ..P451::default()
    };
    let r = run(&program(&p, [50.0, -30.0, 80.0]), &sc, &dir);
    let c = only_cycle(&r);
    assert_eq!(c.status, Status::Error);
    let m = c.message.as_deref().unwrap();
    assert!(m.contains("maxDevCalBall") && m.contains("12.0000"), "{m}");
    assert!(!r.report.completed());
    assert_eq!(
        std::fs::read_to_string(dir.join("kinematics.toml")).unwrap(),
        HAND_WRITTEN
    );
    assert!(!dir.join("kinematics.toml.prev").exists());
    assert!(!dir.join("TCHPRAUTO.html").exists());
}

#[test]
fn injected_backlash_is_measured_within_ten_percent() {
    let text = std::fs::read_to_string(configs_dir().join("scenarios/demo-sphere.toml"))
        .unwrap()
        .replace("[truth]", "[truth]\nbacklash_C = 0.02");
    let sc = scenario(&text);
    let dir = temp_dir("backlash");
    let p = P451 {
        mode: 0,
        c: Ax(90.0, 270.0, 0.0, 3),
        points: 3,
        backlash: 0.5,
        preset: 3,
        ..P451::default()
    };
    let r = run(&program(&p, [50.0, -30.0, 80.0]), &sc, &dir);
    ok_cycle(&r);
    let v = json(&r);
    // Q431=3: preset at the sphere centre before (so Q147..Q149 are about 0) and after.
    for (i, want) in [50.0, -30.0, 80.0].into_iter().enumerate() {
        let shift = v["kinematics"]["preset_shift"][i].as_f64().unwrap();
        assert!((shift - want).abs() < 0.05, "preset shift {i}: {shift}");
        let q = v["q"][format!("Q{}", 147 + i)].as_f64().unwrap();
        assert!(q.abs() < 0.05, "Q{}: {q}", 147 + i);
    }
    let a = &v["kinematics"]["axes"][0];
    let b = a["backlash"].as_f64().unwrap();
    assert!(
        (b - 0.02).abs() < 0.002,
        "measured backlash {b} deg, injected 0.02"
    );
    // Every position was approached from both sides.
    for p in a["positions"].as_array().unwrap() {
        let sides: Vec<&str> = p["measurements"]
            .as_array()
            .unwrap()
            .iter()
            .map(|m| m["approach"].as_str().unwrap())
            .collect();
        assert_eq!(sides, ["above", "below"]);
    }
}

#[test]
fn no_backlash_on_a_measuring_circle_below_1_mm() {
    let text = std::fs::read_to_string(configs_dir().join("scenarios/demo-sphere.toml"))
        .unwrap()
        .replace("[truth]", "[truth]\nbacklash_C = 0.02")
        .replace("center = [50.0, -30.0, 80.0]", "center = [0.6, 0.0, 80.0]");
    let sc = scenario(&text);
    let dir = temp_dir("backlash-small");
    let p = P451 {
        mode: 0,
        c: Ax(90.0, 270.0, 0.0, 3),
        points: 3,
        backlash: 0.5,
        ..P451::default()
    };
    let r = run(&program(&p, [0.6, 0.0, 80.0]), &sc, &dir);
    ok_cycle(&r);
    let v = json(&r);
    let a = &v["kinematics"]["axes"][0];
    assert!(a["circle_radius"].as_f64().unwrap() < 1.0);
    assert!(a["backlash"].is_null(), "{}", a["backlash"]);
    let notes = v["kinematics"]["notes"].to_string();
    assert!(notes.contains("no backlash computed"), "{notes}");
}

#[test]
fn a_correction_beyond_max_modification_needs_confirmation() {
    let text = std::fs::read_to_string(configs_dir().join("scenarios/demo-sphere.toml"))
        .unwrap()
        .replace("EX0C = 0.012", "EX0C = 0.7");
    let sc = scenario(&text);
    let p = P451 {
        mode: 1,
        c: Ax(90.0, 270.0, 0.0, 3),
        points: 3,
        ..P451::default()
    };
    let cfg = cycles_config(&sc);
    // Refused: nothing written, the program stops.
    let dir = temp_dir("maxmod-no");
    let r = run_with(&program(&p, [50.0, -30.0, 80.0]), &sc, &cfg, &dir, false);
    let c = only_cycle(&r);
    assert_eq!(r.confirmations.len(), 1);
    let asked = &r.confirmations[0];
    assert_eq!(asked.kind, ConfirmKind::KinematicsCorrection);
    assert!(asked.text.contains("maxModification") && asked.text.contains("EX0C"));
    assert!(c.message.as_deref().unwrap().contains("not confirmed"));
    assert!(!r.report.completed());
    assert!(!dir.join("kinematics.toml").exists());
    // Confirmed: written.
    let dir = temp_dir("maxmod-yes");
    let r = run_with(&program(&p, [50.0, -30.0, 80.0]), &sc, &cfg, &dir, true);
    assert!(r.report.completed(), "{:?}", r.report.stopped);
    let k =
        cycles::kinematics_file::ActiveKinematics::load(&dir.join("kinematics.toml"), &cfg.machine)
            .unwrap();
    assert!((k.error("EX0C") - 0.7).abs() < 2e-3, "{}", k.error("EX0C"));
}

#[test]
fn mode_3_moves_the_tilt_of_c_into_the_machine_datum_of_a() {
    let sc = demo_sphere();
    let dir = temp_dir("mode3");
    let p = P451 {
        mode: 3,
        a: Ax(-90.0, 90.0, 0.0, 3),
        c: Ax(90.0, 270.0, 0.0, 3),
        points: 3,
        ..P451::default()
    };
    let r = run(&program(&p, [50.0, -30.0, 80.0]), &sc, &dir);
    ok_cycle(&r);
    let cfg = machine_config(&sc);
    let k = cycles::kinematics_file::ActiveKinematics::load(&dir.join("kinematics.toml"), &cfg)
        .unwrap();
    assert_eq!(k.error("EA0C"), 0.0);
    assert!(
        (k.error("EA0A") - 0.004).abs() < 1e-4,
        "{}",
        k.error("EA0A")
    );
    assert!((k.error("EB0A") - 0.005).abs() < 1e-4);
    let v = json(&r);
    assert!(v["q"]["Q146"].as_f64().unwrap() < 1e-4);

    // The B head and C table have no axis nearer the bed in either chain: refused
    // before anything moves.
    let sc = head_b_table_c();
    let dir = temp_dir("mode3-bc");
    let p = P451 {
        mode: 3,
        b: Ax(-60.0, 60.0, 0.0, 2),
        c: Ax(90.0, 270.0, 0.0, 2),
        ..P451::default()
    };
    let r = run(&program(&p, [40.0, 25.0, 60.0]), &sc, &dir);
    let c = only_cycle(&r);
    assert_eq!(c.status, Status::Error);
    assert!(
        c.message.as_deref().unwrap().contains("Q406=3"),
        "{:?}",
        c.message
    );
    assert!(!dir.join("kinematics.toml").exists());
}

#[test]
fn hirth_axis_positions_on_the_grid_and_q408_0_refused() {
    let text = std::fs::read_to_string(configs_dir().join("scenarios/demo-sphere.toml"))
        .unwrap()
        .replace("[truth]", "[truth]\nhirth_C = 3.0");
    let sc = scenario(&text);
    let mut cfg = cycles_config(&sc);
    cfg.machine
        .axes
        .iter_mut()
        .find(|a| a.name == hal::Axis::C)
        .unwrap()
        .hirth = 3.0;
    let mut p = P451 {
        mode: 0,
        c: Ax(-30.0, 90.0, 0.0, 4),
        points: 3,
        ..P451::default()
    };
    // Q408 = 0 with a Hirth axis: refused, nothing moved.
    let dir = temp_dir("hirth-0");
    let r = run_with(&program(&p, [50.0, -30.0, 80.0]), &sc, &cfg, &dir, true);
    let c = only_cycle(&r);
    assert_eq!(c.status, Status::Error);
    assert!(
        c.message.as_deref().unwrap().contains("Q408=0"),
        "{:?}",
        c.message
    );
    // With a retraction height: the seed's positions -30, 9, 51, 90.
    p.q408 = 150.0;
    let dir = temp_dir("hirth");
    let r = run_with(&program(&p, [50.0, -30.0, 80.0]), &sc, &cfg, &dir, true);
    ok_cycle(&r);
    let v = json(&r);
    let got: Vec<f64> = v["kinematics"]["axes"][0]["positions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["angles"]["C"].as_f64().unwrap())
        .collect();
    for (g, w) in got.iter().zip([0.0, -30.0, 9.0, 51.0, 90.0]) {
        assert!((g - w).abs() < 1e-5, "{got:?}");
    }
    assert_eq!(got.len(), 5);
}

#[test]
fn parameter_ranges_are_checked_before_anything_moves() {
    let sc = demo_sphere();
    let cfg = cycles_config(&sc);
    let good = P451 {
        c: Ax(90.0, 270.0, 0.0, 3),
        ..P451::default()
    };
    let text = program(&good, [50.0, -30.0, 80.0]);
    assert!(Program::parse(&text, &cfg).is_ok());
    for (param, bad) in [
        ("Q406", "Q406=+4"),
        ("Q407", "Q407=+0"),
        ("Q423", "Q423=+9"),
        ("Q432", "Q432=+3.5"),
        ("Q422", "Q422=+13"),
        ("Q431", "Q431=+4"),
        ("Q380", "Q380=+361"),
    ] {
        let prefix = bad.split('=').next().unwrap();
        let changed: String = text
            .lines()
            .map(|l| {
                if l.trim_start().starts_with(&format!("{prefix}=")) {
                    let rest = l.split_once(' ').map_or("", |x| x.1);
                    format!("  {bad} {rest}")
                } else {
                    l.to_string()
                }
            })
            .collect::<Vec<_>>()
            .join("\n");
        let e = Program::parse(&changed, &cfg).unwrap_err().to_string();
        assert!(e.contains(param), "{bad}: {e}");
    }
}

// ---------------------------------------------------------------------------------
// Presets (Q431) and cycle 247.

/// The 451 block of `p` alone, without the pre-positioning `L` block.
fn cycle_block(p: &P451) -> String {
    let text = program(p, [0.0, 0.0, 0.0]);
    let start = text.find("3 TCH PROBE 451").unwrap();
    let end = text.find("4 END PGM").unwrap();
    text[start..end].to_string()
}

/// "N sphere(s) measured" from the report's notes.
fn spheres_measured(v: &serde_json::Value) -> usize {
    let notes = v["kinematics"]["notes"].as_array().unwrap();
    notes
        .iter()
        .find_map(|n| {
            n.as_str()?
                .strip_suffix(" sphere(s) measured")?
                .parse()
                .ok()
        })
        .unwrap_or_else(|| panic!("no sphere count in {notes:?}"))
}

#[test]
fn q431_0_finds_the_sphere_at_the_preset_of_cycle_247_from_100_mm_away() {
    let sc = demo_sphere();
    let mut cfg = cycles_config(&sc);
    let mut row = cycles::preset_table::Preset::origin(1);
    [row.x, row.y, row.z] = [50.0, -30.0, 80.0];
    cfg.presets.rows.push(row);
    let p = P451 {
        preset: 0,
        a: Ax(-90.0, 90.0, 0.0, 4),
        c: Ax(90.0, 270.0, 0.0, 3),
        ..P451::default()
    };
    // No L block over the sphere: the start is 100 mm from it, in the preset's
    // coordinates after cycle 247.
    let text = format!(
        "0 BEGIN PGM K451 MM\n1 TOOL CALL \"TOUCH_PROBE\" Z\n\
2 CYCL DEF 247 DATUM SETTING ~\n  Q339=+1 ;DATUM NUMBER\n\
3 L X+0 Y+100 Z+30 R0 FMAX\n{}4 END PGM K451 MM\n",
        cycle_block(&p)
    );
    let dir = temp_dir("q431-0");
    let r = run_with(&text, &sc, &cfg, &dir, true);
    ok_cycle(&r);
    let v = json(&r);
    let after = errors_of(&v["kinematics"]["errors_after"]);
    // The pre-positioned program (Q431 = 1) on the same scenario.
    let pre = P451 { preset: 1, ..p };
    let dir_pre = temp_dir("q431-0-pre");
    let r_pre = run(&program(&pre, [50.0, -30.0, 80.0]), &sc, &dir_pre);
    ok_cycle(&r_pre);
    let v_pre = json(&r_pre);
    let after_pre = errors_of(&v_pre["kinematics"]["errors_after"]);
    for name in all_location_errors(&['A', 'C']) {
        let truth = sc.truth.get(&name).unwrap();
        assert!(
            (after[&name] - truth).abs() < 1e-4,
            "{name}: identified {} vs injected {truth}",
            after[&name]
        );
        assert!((after[&name] - after_pre[&name]).abs() < 1e-4, "{name}");
    }
    check_results_against_spec(&v, &machine_config(&sc));
    // Relative to preset 1, the sphere centre: Q147..Q149 about 0.
    for q in ["Q147", "Q148", "Q149"] {
        assert!(
            v["q"][q].as_f64().unwrap().abs() < 1e-6,
            "{q}: {}",
            v["q"][q]
        );
    }
    // A: reference + 4 positions, C: reference + 3; no locating sphere with Q431 = 0,
    // and with Q431 = 1 the locating sphere is A's reference (9, not 10 as before).
    assert_eq!(spheres_measured(&v), 9);
    assert_eq!(spheres_measured(&v_pre), 9);
    // Q431 = 0 writes no preset.
    assert!(!cfg.presets.path.exists());
}

#[test]
fn q431_3_writes_the_preset_row_at_the_sphere_centre() {
    let sc = demo_sphere();
    let cfg = cycles_config(&sc);
    let p = P451 {
        preset: 3,
        c: Ax(90.0, 270.0, 0.0, 3),
        ..P451::default()
    };
    // Mode 0: neither the preset nor the kinematics.
    let dir = temp_dir("q431-3-check");
    let check = P451 { mode: 0, ..p };
    let r = run_with(&program(&check, [50.0, -30.0, 80.0]), &sc, &cfg, &dir, true);
    ok_cycle(&r);
    assert!(!cfg.presets.path.exists());
    assert!(!dir.join("kinematics.toml").exists());

    let dir = temp_dir("q431-3");
    let r = run_with(&program(&p, [50.0, -30.0, 80.0]), &sc, &cfg, &dir, true);
    ok_cycle(&r);
    let v = json(&r);
    let table = cycles::preset_table::PresetTable::load(&cfg.presets.path, &cfg.machine).unwrap();
    let row = table.active_row().xyz();
    for (i, want) in [50.0, -30.0, 80.0].into_iter().enumerate() {
        assert!((row[i] - want).abs() < 1e-6, "preset row {i}: {}", row[i]);
        let shift = v["kinematics"]["preset_shift"][i].as_f64().unwrap();
        assert!((shift - want).abs() < 1e-6, "shift {i}: {shift}");
        // Q147..Q149: the reference centre relative to the preset active then.
        let q = v["q"][format!("Q{}", 147 + i)].as_f64().unwrap();
        let reference = v["kinematics"]["preset_after"][i].as_f64().unwrap();
        assert!(
            (q - (reference - row[i])).abs() < 1e-9 && q.abs() < 1e-6,
            "Q{}: {q}",
            147 + i
        );
    }
    assert_eq!(spheres_measured(&v), 4);
}

/// The shipped examples of presets and cycle 450 run on demo-sphere.toml.
#[test]
fn the_preset_and_save_restore_examples_run() {
    let sc = demo_sphere();
    let read =
        |name: &str| std::fs::read_to_string(configs_dir().join("programs").join(name)).unwrap();
    // The shipped preset table (row 1: the sphere centre), in a temporary copy.
    let mut cfg = cycles_config(&sc);
    let shipped = configs_dir().join("machines/table-ac.presets.toml");
    let path = cfg.presets.path.clone();
    cfg.presets = cycles::preset_table::PresetTable::load(&shipped, &cfg.machine).unwrap();
    cfg.presets.path = path;

    // Q431 = 0 after cycle 247: from 100 mm away, Q147..Q149 relative to preset 1.
    let dir = temp_dir("example-247");
    let r = run_with(&read("451-preset-247.h"), &sc, &cfg, &dir, true);
    ok_cycle(&r);
    let v = json(&r);
    for q in ["Q147", "Q148", "Q149"] {
        assert!(
            v["q"][q].as_f64().unwrap().abs() < 1e-6,
            "{q}: {}",
            v["q"][q]
        );
    }
    assert!(!cfg.presets.path.exists(), "mode 0 writes no preset");

    // Q431 = 3, mode 1: the row cycle 247 activated (1) is written with the sphere
    // centre; row 0 stays at the origin.
    let dir = temp_dir("example-q431-3");
    let r = run_with(&read("451-preset-set.h"), &sc, &cfg, &dir, true);
    ok_cycle(&r);
    let table = cycles::preset_table::PresetTable::load(&cfg.presets.path, &cfg.machine).unwrap();
    let row1 = table.row(1).unwrap();
    for (got, want) in row1.xyz().iter().zip([50.0, -30.0, 80.0]) {
        assert!((got - want).abs() < 1e-6, "{row1:?}");
    }
    assert_eq!(table.row(0), cfg.presets.row(0), "only row 1 changes");

    // 450 saves, 451 mode 1 changes, 450 restores: the file as it was, byte for byte.
    let dir = temp_dir("example-450");
    let kin = dir.join("kinematics.toml");
    // As probebridge writes it (a restore writes that form).
    let before = cycles::kinematics_file::ActiveKinematics {
        machine: "table-ac".into(),
        errors: [("EB0A".to_string(), 0.001), ("EX0C".to_string(), 0.002)].into(),
        path: kin.clone(),
    };
    before.write().unwrap();
    let text = std::fs::read_to_string(&kin).unwrap();
    let r = run_with(&read("450-save-restore.h"), &sc, &cfg, &dir, true);
    assert!(r.report.completed(), "{:?}", r.report.stopped);
    assert_eq!(r.report.cycles.len(), 3);
    let k451 = r.report.cycles[1].kinematics.as_ref().unwrap();
    assert!(k451.written, "451 changed the kinematics in between");
    assert_eq!(std::fs::read_to_string(&kin).unwrap(), text);
}

// ---------------------------------------------------------------------------------
// Tool axis X and Y (TOOL CALL ... X|Y) on machines whose spindle lies that way.

/// `p` with the tool axis `axis`: the probe comes back along the spindle, over the
/// sphere at `centre` in the working plane, then 5 mm off the pole along the tool axis.
fn program_along(p: &P451, centre: [f64; 3], axis: char) -> String {
    let t = match axis {
        'X' => 0,
        'Y' => 1,
        'Z' => 2,
        _ => panic!("tool axis {axis}"),
    };
    let names = ['X', 'Y', 'Z'];
    let plane: Vec<String> = (0..3)
        .filter(|&i| i != t)
        .map(|i| format!("{}{:+}", names[i], centre[i]))
        .collect();
    let pole = centre[t] + p.radius + 3.0 + 2.0 + 5.0;
    format!(
        "0 BEGIN PGM K451 MM\n1 TOOL CALL \"TOUCH_PROBE\" {axis}\n2 L {axis}{:+} R0 FMAX\n\
         3 L {} R0 FMAX\n4 L {axis}{pole:+} R0 FMAX\n{}5 END PGM K451 MM\n",
        pole + 100.0,
        plane.join(" "),
        cycle_block(p)
    )
}

fn load_scenario(name: &str) -> sim::Scenario {
    sim::Scenario::load(
        &configs_dir().join("scenarios").join(name),
        Some(&configs_dir().join("machines")),
    )
    .unwrap()
}

/// The run succeeded, identified the injected location errors of `axes` to 1e-4 and
/// agrees with the independent computation of the spec; its JSON.
fn assert_recovers(r: &Run, sc: &sim::Scenario, axes: &[char]) -> serde_json::Value {
    ok_cycle(r);
    let v = json(r);
    let after = errors_of(&v["kinematics"]["errors_after"]);
    for name in all_location_errors(axes) {
        let truth = sc.truth.get(&name).unwrap();
        assert!(
            (after[&name] - truth).abs() < 1e-4,
            "{name}: identified {} vs injected {truth}",
            after[&name]
        );
    }
    check_results_against_spec(&v, &machine_config(sc));
    v
}

/// Tool axis Y on the A/C table machine with a horizontal spindle: the same sphere and
/// errors as demo-sphere.toml, recovered to 1e-4 and matching the spec; pre-positioned
/// (Q431 = 1) and from the preset of cycle 247 (Q431 = 0) alike.
#[test]
fn tool_axis_y_on_a_horizontal_spindle_recovers_the_injected_errors() {
    let sc = load_scenario("horizontal-y-sphere.toml");
    let p = P451 {
        a: Ax(-90.0, 90.0, 0.0, 4),
        c: Ax(90.0, 270.0, 0.0, 3),
        ..P451::default()
    };
    let centre = [50.0, -30.0, 80.0];
    let dir = temp_dir("tool-y");
    let mut directions = Vec::new();
    let text = program_along(&p, centre, 'Y');
    let r = {
        let cfg = cycles_config(&sc);
        let program = Program::parse(&text, &cfg).unwrap_or_else(|e| panic!("{e}"));
        let mut m = CanInproc::open(&sc);
        let mut confirm = |_: &Confirmation| true;
        let mut progress = |ev| {
            if let cycles::progress::ProgressEvent::Probe { direction, .. } = ev {
                directions.push(direction);
            }
        };
        let mut opts = RunOptions {
            out_dir: dir.clone(),
            confirm: &mut confirm,
            progress: &mut progress,
            kinematics: Some(dir.join("kinematics.toml")),
            estimator: None,
        };
        Run {
            report: run_program(&program, &mut m, &cfg, &mut opts),
            confirmations: Vec::new(),
        }
    };
    let v = assert_recovers(&r, &sc, &['A', 'C']);
    // Locating the sphere: along -Y; then its first pass, four points in the ZX
    // plane (at A = C = 0), the first (Q380 = 0) on the main axis Z; then the second
    // pass: the pole along -Y and the four points again.
    let along = |d: [f64; 3], want: [f64; 3]| (0..3).all(|i| (d[i] - want[i]).abs() < 1e-12);
    assert!(along(directions[0], [0.0, -1.0, 0.0]), "{directions:?}");
    for first in [1, 6] {
        assert!(along(directions[first], [0.0, 0.0, -1.0]), "{directions:?}");
        assert!(
            directions[first..first + 4]
                .iter()
                .all(|d| d[1].abs() < 1e-12),
            "{directions:?}"
        );
    }
    assert!(along(directions[5], [0.0, -1.0, 0.0]), "{directions:?}");
    // Q431 = 0: cycle 247 activates the sphere centre, the start 100 mm away in X.
    let mut cfg = cycles_config(&sc);
    let mut row = cycles::preset_table::Preset::origin(1);
    [row.x, row.y, row.z] = centre;
    cfg.presets.rows.push(row);
    let text = format!(
        "0 BEGIN PGM K451 MM\n1 TOOL CALL \"TOUCH_PROBE\" Y\n\
2 CYCL DEF 247 DATUM SETTING ~\n  Q339=+1 ;DATUM NUMBER\n\
3 L Y+40 R0 FMAX\n4 L X+100 Z+0 R0 FMAX\n{}5 END PGM K451 MM\n",
        cycle_block(&P451 { preset: 0, ..p })
    );
    let dir = temp_dir("tool-y-247");
    let r0 = run_with(&text, &sc, &cfg, &dir, true);
    let v0 = assert_recovers(&r0, &sc, &['A', 'C']);
    for q in ["Q147", "Q148", "Q149"] {
        assert!(
            v0["q"][q].as_f64().unwrap().abs() < 1e-6,
            "{q}: {}",
            v0["q"][q]
        );
    }
    assert_eq!(spheres_measured(&v), 9);
    assert_eq!(spheres_measured(&v0), 9);
}

/// Tool axis X in a B swivel head: the probe direction turns with B in the XZ plane.
/// Q431 = 3 sets the active preset row at the sphere centre (1e-6 mm, noise 0) and the
/// injected errors of both axes are recovered to 1e-4, matching the spec.
#[test]
fn tool_axis_x_in_a_swivel_head_recovers_the_errors_and_sets_the_preset() {
    let sc = load_scenario("horizontal-x-head-b-table-c.toml");
    let cfg = cycles_config(&sc);
    let p = P451 {
        b: Ax(-60.0, 60.0, 0.0, 4),
        c: Ax(90.0, 270.0, 0.0, 3),
        preset: 3,
        ..P451::default()
    };
    let centre = [40.0, 25.0, 60.0];
    let dir = temp_dir("tool-x");
    let r = run_with(&program_along(&p, centre, 'X'), &sc, &cfg, &dir, true);
    let v = assert_recovers(&r, &sc, &['B', 'C']);
    let table = cycles::preset_table::PresetTable::load(&cfg.presets.path, &cfg.machine).unwrap();
    for (got, want) in table.active_row().xyz().iter().zip(centre) {
        assert!((got - want).abs() < 1e-6, "{:?}", table.active_row());
    }
    assert_eq!(spheres_measured(&v), 9);
}

/// A machine whose spindle lies along Y refuses a 451 program written for a vertical
/// spindle: at the TOOL CALL's line, before anything moves.
#[test]
fn a_tool_axis_the_machine_has_no_spindle_for_is_refused() {
    let sc = load_scenario("horizontal-y-sphere.toml");
    let cfg = cycles_config(&sc);
    let text = program(&P451::default(), [50.0, -30.0, 80.0]);
    let e = Program::parse(&text, &cfg).unwrap_err().to_string();
    assert!(
        e.contains("line 2: TOOL CALL: tool axis Z: machine horizontal-y-table-ac has no spindle along Z; its [cycles] tool_axes are Y"),
        "{e}"
    );
}

// ---------------------------------------------------------------------------------
// Rotary axes positioned by an M function (`[cycles] mStrobeRotAxPos`).

/// The seeds: with the rotary axes positioned by an M function, 451 starts only with
/// every rotary axis at 0 deg and only once that is confirmed (collision danger);
/// otherwise it stops before it moves or asks anything further.
#[test]
fn with_m_strobe_rot_ax_pos_451_starts_only_at_0_deg_and_confirmed() {
    let sc = demo_sphere();
    let mut cfg = cycles_config(&sc);
    cfg.parameters.strobe_rot_ax_pos = 203;
    let p = P451 {
        mode: 0,
        q408: 150.0,
        c: Ax(90.0, 270.0, 0.0, 3),
        points: 3,
        ..P451::default()
    };
    let at_zero = program(&p, [50.0, -30.0, 80.0]);
    // C turned to 10 deg before the cycle: refused, naming the axis and its angle,
    // before the operator is even asked.
    let turned = at_zero
        .replace("\n3 TCH PROBE 451", "\n3 L C+10 R0 FMAX\n4 TCH PROBE 451")
        .replace("\n4 END PGM", "\n5 END PGM");
    let dir = temp_dir("m203-turned");
    let r = run_with(&turned, &sc, &cfg, &dir, true);
    let c = only_cycle(&r);
    assert_eq!(c.status, Status::Error, "{:?}", c.message);
    let said = c.message.as_deref().unwrap();
    assert!(
        said.contains("every rotary axis at 0 deg")
            && said.contains("C is at +10.0000 deg")
            && said.contains("nothing moved"),
        "{said}"
    );
    assert!(r.confirmations.is_empty(), "{:?}", r.confirmations);
    assert!(!r.report.completed());
    // At 0 deg, but the operator does not confirm: stopped, asked exactly once.
    let dir = temp_dir("m203-unconfirmed");
    let r = run_with(&at_zero, &sc, &cfg, &dir, false);
    let c = only_cycle(&r);
    assert_eq!(c.status, Status::Error, "{:?}", c.message);
    assert!(
        c.message
            .as_deref()
            .unwrap()
            .contains("was not confirmed; nothing moved"),
        "{:?}",
        c.message
    );
    assert_eq!(r.confirmations.len(), 1, "{:?}", r.confirmations);
    assert!(
        r.confirmations[0].kind == ConfirmKind::RotaryAtZero
            && r.confirmations[0].text.contains("collision"),
        "{}",
        r.confirmations[0]
    );
    // Confirmed: it measures.
    let dir = temp_dir("m203-confirmed");
    let r = run_with(&at_zero, &sc, &cfg, &dir, true);
    ok_cycle(&r);
    assert_eq!(spheres_measured(&json(&r)), 4);
}
