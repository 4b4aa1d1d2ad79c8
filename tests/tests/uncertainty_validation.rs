//! The standard uncertainties the cycles report, validated, not asserted: many seeded
//! noisy simulations of a cycle 451, of a cycle 431 and of a cycle 460 (on a probe with
//! the three lobes of a kinematic seat), each run's reported `u` of
//! every quantity against the scatter of that quantity over the runs (their RMS `u`
//! within ±15 % of the empirical standard deviation) and the coverage of the truth by
//! ±2u (90..99 % of the runs). The truth is the same cycle run without noise on the
//! same scenario (what the noise moves; the scenario's injected errors are printed
//! beside it). The table is printed (`--nocapture`).
//!
//! The runs use the kinematic simulated machine (the world without its bus,
//! [`probebridge_tests::kinematic_machine`]; for 460, whose offset needs the spindle
//! oriented, [`probebridge_tests::world_machine`]): the same probe physics, hundreds of
//! times faster than the CANopen path. `RUNS` each, always on; `PB_UNCERTAINTY_RUNS=N`
//! runs more.

use cycles::program::Program;
use cycles::results::{ProgramReport, Status};
use cycles::runner::{run_program, RunOptions};
use hal::{Machine, MachineError};
use probebridge_tests::kinematic_machine::KinematicMachine;
use probebridge_tests::world_machine::WorldMachine;
use probebridge_tests::{cycles_config, scenario};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// Seeded runs per cycle.
const RUNS: usize = 200;
/// The probe's scatter, 1 σ along the probing direction, mm (and the probe table's
/// stated repeatability, 2 σ, twice that).
const NOISE: f64 = 0.001;

fn runs() -> usize {
    std::env::var("PB_UNCERTAINTY_RUNS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(RUNS)
        .max(RUNS)
}

fn run(program: &str, sc: &sim::Scenario, tag: &str) -> ProgramReport {
    run_on(program, sc, tag, &mut KinematicMachine::open(sc))
}

fn run_on<M: Machine<Error = MachineError>>(
    program: &str,
    sc: &sim::Scenario,
    tag: &str,
    m: &mut M,
) -> ProgramReport {
    let mut cfg = cycles_config(sc);
    for p in &mut cfg.probes {
        p.repeatability_2sigma = 2.0 * NOISE;
    }
    let program = Program::parse(program, &cfg).unwrap_or_else(|e| panic!("{e}"));
    let out: PathBuf = std::env::temp_dir().join(format!("pb-uncert-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&out).unwrap();
    let mut confirm = |_: &cycles::confirmation::Confirmation| true;
    let mut progress = |_| {};
    let mut opts = RunOptions {
        out_dir: out.clone(),
        confirm: &mut confirm,
        progress: &mut progress,
        kinematics: Some(out.join("kinematics.toml")),
        estimator: None,
    };
    let report = run_program(&program, m, &cfg, &mut opts);
    let _ = std::fs::remove_dir_all(&out);
    // The probe table row a 460 wrote (each run has its own folder).
    if let Some(dir) = cfg.calibrations.path.parent() {
        let _ = std::fs::remove_dir_all(dir);
    }
    assert!(
        report.cycles.iter().all(|c| c.status == Status::Ok),
        "{}",
        report.to_text()
    );
    report
}

/// Per quantity: (value, u) of every run.
type Samples = BTreeMap<String, Vec<(f64, f64)>>;

struct Row {
    name: String,
    unit: &'static str,
    truth: f64,
    rms_u: f64,
    std: f64,
    coverage: f64,
}

fn table(
    cycle: &str,
    samples: &Samples,
    truth: &BTreeMap<String, f64>,
    unit: &dyn Fn(&str) -> (&'static str, f64),
) -> Vec<Row> {
    let mut rows = Vec::new();
    for (name, s) in samples {
        let n = s.len() as f64;
        let t = truth[name];
        let mean = s.iter().map(|x| x.0).sum::<f64>() / n;
        let std = (s.iter().map(|x| (x.0 - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        let rms_u = (s.iter().map(|x| x.1 * x.1).sum::<f64>() / n).sqrt();
        let covered = s.iter().filter(|x| (x.0 - t).abs() <= 2.0 * x.1).count() as f64;
        let (label, scale) = unit(name);
        rows.push(Row {
            name: name.clone(),
            unit: label,
            truth: t * scale,
            rms_u: rms_u * scale,
            std: std * scale,
            coverage: covered / n,
        });
    }
    println!(
        "\ncycle {cycle}, {} seeded runs, probe noise {} µm (1 σ):",
        samples.values().next().map_or(0, Vec::len),
        NOISE * 1000.0
    );
    println!("| quantity | unit | truth (noise-free run) | RMS of reported u | empirical std | u / std | ±2u covers the truth |");
    println!("|---|---|---:|---:|---:|---:|---:|");
    for r in &rows {
        println!(
            "| {} | {} | {:+.4} | {:.4} | {:.4} | {:.2} | {:.1} % |",
            r.name,
            r.unit,
            r.truth,
            r.rms_u,
            r.std,
            r.rms_u / r.std,
            100.0 * r.coverage
        );
    }
    rows
}

fn check(rows: &[Row]) {
    for r in rows {
        // A quantity the probe's scatter does not reach (431's SPC depends only on
        // the nominal X/Y of the points): u and the scatter are both 0.
        if r.rms_u < 1e-6 && r.std < 1e-6 {
            continue;
        }
        let ratio = r.rms_u / r.std;
        assert!(
            (0.85..=1.15).contains(&ratio),
            "{}: reported u {:.5} vs empirical std {:.5} {} (ratio {ratio:.3})",
            r.name,
            r.rms_u,
            r.std,
            r.unit
        );
        assert!(
            (0.90..=0.99).contains(&r.coverage),
            "{}: ±2u covers the truth in {:.1} % of the runs",
            r.name,
            100.0 * r.coverage
        );
    }
}

// --------------------------------------------------------------------------------
// Cycle 451.

fn scenario_451(seed: u64, noise: f64) -> sim::Scenario {
    scenario(&format!(
        r#"
machine = "table-ac"
seed = {seed}
[probe]
ball_radius = 3.0
noise = {noise:?}
[truth]
EX0C = 0.012
EY0C = -0.008
EA0C = 0.004
EB0A = 0.005
EY0A = 0.006
[[sphere]]
center = [50.0, -30.0, 80.0]
radius = 12.5
"#
    ))
}

/// Mode 2, A -90..+90 in 4 positions, C +90..+270 in 3, Q423 = 4, the probe put over
/// the sphere (Q431 = 1 locates it).
const PROGRAM_451: &str = "0 BEGIN PGM U451 MM
1 TOOL CALL \"TOUCH_PROBE\" Z
2 L X+50 Y-30 Z+102.5 R0 FMAX
3 TCH PROBE 451 MEASURE KINEMATICS ~
  Q406=+2 ;MODE ~
  Q407=+12.5 ;SPHERE RADIUS ~
  Q320=+0 ;SET-UP CLEARANCE ~
  Q408=+0 ;RETR. HEIGHT ~
  Q253=+750 ;F PRE-POSITIONING ~
  Q380=+0 ;REFERENCE ANGLE ~
  Q411=-90 ~
  Q412=+90 ~
  Q413=+0 ~
  Q414=+4 ~
  Q415=+0 ~
  Q416=+0 ~
  Q417=+0 ~
  Q418=+0 ~
  Q419=+90 ~
  Q420=+270 ~
  Q421=+0 ~
  Q422=+3 ~
  Q423=+4 ;NO. OF PROBE POINTS ~
  Q431=+1 ;PRESET ~
  Q432=+0 ;BACKLASH, ANG. RANGE
4 END PGM U451 MM
";

/// The identified errors and their u of one run.
fn errors_451(report: &ProgramReport) -> BTreeMap<String, (f64, Option<f64>)> {
    let k = report.cycles[0]
        .kinematics
        .as_ref()
        .expect("cycle 451's report");
    k.errors_after
        .iter()
        .map(|(n, v)| (n.clone(), (*v, k.errors_u.get(n).copied())))
        .collect()
}

/// Positions in µm, orientations in arcsec.
fn unit_451(name: &str) -> (&'static str, f64) {
    match name.as_bytes().get(1) {
        Some(b'X' | b'Y' | b'Z') => ("µm", 1000.0),
        _ => ("arcsec", 3600.0),
    }
}

#[test]
fn cycle_451_reported_uncertainties_match_the_scatter_of_seeded_runs() {
    let truth: BTreeMap<String, f64> =
        errors_451(&run(PROGRAM_451, &scenario_451(1, 0.0), "451-truth"))
            .into_iter()
            .map(|(n, (v, _))| (n, v))
            .collect();
    let mut samples = Samples::new();
    for seed in 0..runs() {
        let report = run(PROGRAM_451, &scenario_451(1000 + seed as u64, NOISE), "451");
        for (name, (v, u)) in errors_451(&report) {
            // Errors the optimisation was not free to change carry no u.
            if let Some(u) = u {
                samples.entry(name).or_default().push((v, u));
            }
        }
    }
    assert_eq!(
        samples.len(),
        8,
        "mode 2 frees 4 errors each of A and C: {samples:?}"
    );
    let sc = scenario_451(1, 0.0);
    for name in samples.keys() {
        println!(
            "{name}: injected {:+.6}, noise-free run {:+.6}",
            sc.truth.get(name).unwrap_or(0.0),
            truth[name]
        );
    }
    check(&table("451", &samples, &truth, &unit_451));
}

// --------------------------------------------------------------------------------
// Cycle 431.

fn scenario_431(seed: u64, noise: f64) -> sim::Scenario {
    scenario(&format!(
        r#"
machine = "table-ac"
seed = {seed}
[probe]
ball_radius = 2.0
noise = {noise:?}
[[plane]]
point = [20.0, 10.0, 15.0]
normal = [0.05, -0.12, 1.0]
"#
    ))
}

fn program_431() -> String {
    let n = [0.05f64, -0.12, 1.0];
    let height = |x: f64, y: f64| 15.0 - (n[0] * (x - 20.0) + n[1] * (y - 10.0)) / n[2];
    let p = [[0.0, 0.0], [60.0, 5.0], [10.0, 55.0]].map(|p| [p[0], p[1], height(p[0], p[1])]);
    format!(
        "0 BEGIN PGM U431 MM\n1 TOOL CALL \"TOUCH_PROBE\" Z\n2 TCH PROBE 431 MEASURE PLANE ~\n  Q263={:+} ~\n  Q264={:+} ~\n  Q294={:+} ~\n  Q265={:+} ~\n  Q266={:+} ~\n  Q295={:+} ~\n  Q296={:+} ~\n  Q297={:+} ~\n  Q298={:+} ~\n  Q320=+2 ~\n  Q260=+60 ~\n  Q281=+0\n3 END PGM U431 MM\n",
        p[0][0], p[0][1], p[0][2], p[1][0], p[1][1], p[1][2], p[2][0], p[2][1], p[2][2]
    )
}

fn results_431(report: &ProgramReport) -> BTreeMap<String, (f64, f64)> {
    let c = &report.cycles[0];
    c.u.iter().map(|(n, u)| (n.clone(), (c.q[n], *u))).collect()
}

/// Angles in arcsec, coordinates in µm.
fn unit_431(name: &str) -> (&'static str, f64) {
    if ["Q173", "Q174", "Q175"].contains(&name) {
        ("µm", 1000.0)
    } else {
        ("arcsec", 3600.0)
    }
}

#[test]
fn cycle_431_reported_uncertainties_match_the_scatter_of_seeded_runs() {
    let program = program_431();
    let truth: BTreeMap<String, f64> =
        results_431(&run(&program, &scenario_431(1, 0.0), "431-truth"))
            .into_iter()
            .map(|(n, (v, _))| (n, v))
            .collect();
    let mut samples = Samples::new();
    for seed in 0..runs() {
        let report = run(&program, &scenario_431(1000 + seed as u64, NOISE), "431");
        for (name, (v, u)) in results_431(&report) {
            samples.entry(name).or_default().push((v, u));
        }
    }
    assert_eq!(
        samples.keys().map(String::as_str).collect::<Vec<_>>(),
        ["Q158", "Q159", "Q170", "Q171", "Q172", "Q173", "Q174", "Q175"]
    );
    check(&table("431", &samples, &truth, &unit_431));
}

// --------------------------------------------------------------------------------
// Cycle 460 on a probe with lobing.

/// The sphere of the 460 runs (machine coordinates, mm).
const SPHERE_460: ([f64; 3], f64) = ([30.0, -20.0, 40.0], 20.0);

/// A kinematic probe as its makers publish it: 4 µm of lobing (three lobes, the first
/// at 10°), another pre-travel along the stylus, the ball 3 µm/-2 µm off the spindle
/// axis and 4 µm longer than the table says; the table's R is the ball's.
fn scenario_460(seed: u64, noise: f64) -> sim::Scenario {
    let (c, r) = SPHERE_460;
    scenario(&format!(
        r#"
machine = "table-ac"
seed = {seed}
[probe]
ball_radius = 3.0
pretravel = 0.005
pretravel_axial = 0.007
lobing = 0.004
lobing_phase = 10.0
offset = [0.003, -0.002]
length_error = 0.004
table_radius = 3.0
noise = {noise:?}
[[sphere]]
center = [{}, {}, {}]
radius = {r}
"#,
        c[0], c[1], c[2]
    ))
}

/// Q423 = 8 points a ring (the three lobes resolved), the length against the sphere
/// centre's height, no 3D table; from the probe put over the pole in machine
/// coordinates (SET_UP 2 mm plus 1 mm above it).
fn program_460() -> String {
    let (c, r) = SPHERE_460;
    format!(
        "0 BEGIN PGM U460 MM\n1 TOOL CALL \"TOUCH_PROBE\" Z\n2 L Z+200 R0 FMAX M91\n3 L X{:+} Y{:+} R0 FMAX M91\n4 L Z{:+} R0 FMAX M91\n\
5 TCH PROBE 460 CALIBRATION OF TS ON A SPHERE ~\n  Q407={r:+} ~\n  Q320=+0 ~\n  Q301=+1 ~\n  Q423=+8 ~\n  Q380=+0 ~\n  Q433=+1 ~\n  Q434={:+} ~\n  Q455=+0\n\
6 L Z+200 R0 FMAX M91\n7 END PGM U460 MM\n",
        c[0],
        c[1],
        c[2] + r + 3.0 + 2.0 + 1.0,
        c[2]
    )
}

fn run_460(sc: &sim::Scenario, tag: &str) -> ProgramReport {
    run_on(&program_460(), sc, tag, &mut WorldMachine::new(sc))
}

fn results_460(report: &ProgramReport) -> BTreeMap<String, (f64, f64)> {
    let c = report
        .cycles
        .iter()
        .find(|c| c.cycle == 460)
        .expect("the 460 block ran");
    c.u.iter().map(|(n, u)| (n.clone(), (c.q[n], *u))).collect()
}

fn unit_460(_: &str) -> (&'static str, f64) {
    ("µm", 1000.0)
}

/// The lobes are modelled in the equator's circles, not counted as the contacts'
/// scatter: R, the offset and L are as uncertain as 460 says.
#[test]
fn cycle_460_reported_uncertainties_match_the_scatter_of_seeded_runs_with_lobing() {
    let truth: BTreeMap<String, f64> = results_460(&run_460(&scenario_460(1, 0.0), "460-truth"))
        .into_iter()
        .map(|(n, (v, _))| (n, v))
        .collect();
    println!("460 without noise (the stylus: R 2.995, CAL_OF1 0.003, CAL_OF2 -0.002, L 0.002 mm): {truth:?}");
    let mut samples = Samples::new();
    for seed in 0..runs() {
        let report = run_460(&scenario_460(1000 + seed as u64, NOISE), "460");
        for (name, (v, u)) in results_460(&report) {
            samples.entry(name).or_default().push((v, u));
        }
    }
    assert_eq!(
        samples.keys().map(String::as_str).collect::<Vec<_>>(),
        ["CAL_OF1", "CAL_OF2", "L", "R"]
    );
    check(&table("460", &samples, &truth, &unit_460));
}
