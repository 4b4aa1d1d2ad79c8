//! Issue 27 through `probebridge run` and `check` as a user runs them: a real cycle 451
//! on the simulator, then the seed's SUBSTR/TONUMB evaluation of QS146 and a limit on
//! the measured dispersion that stops the program through FN 14 (or does not); one
//! measuring point gives that point's spatial error as the dispersion.

mod common;
#[path = "common/table_ac_case.rs"]
mod table_ac_case;

use common::*;
use std::path::{Path, PathBuf};
use table_ac_case::table_ac_case;

/// table-ac with errors of A and C injected, noise 0.
const SCENARIO: &str = r#"
seed = 5
[probe]
ball_radius = 3.0
noise = 0.0
pretravel = 0.0
[truth]
EY0A = -0.014
EZ0A = 0.009
EX0C = 0.021
EY0C = -0.017
EA0C = 0.005
EB0C = -0.004
[[sphere]]
center = [-40.0, 45.0, 70.0]
radius = 12.5
"#;

/// Cycle 451 in mode 0 with one measuring point on A (+90) and three on C, then the
/// seed's example as printed (blocks 11..18; the seed prints `:` for the comments' `;`
/// in blocks 14, 16 and 18, see docs/q-parameters.md), then FN 11 on Q143 against the
/// limit `limit`.
fn program(limit: &str) -> String {
    format!(
        "0 BEGIN PGM K MM
1 TOOL CALL \"TOUCH_PROBE\" Z
2 Q5 = {limit}
3 L Z+150 R0 FMAX
4 L X-40 Y+45 R0 FMAX
5 L Z+92.5 R0 FMAX
6 TCH PROBE 451 MEASURE KINEMATICS ~
    Q406=+0 ;MODE ~
    Q407=+12.5 ;SPHERE RADIUS ~
    Q320=+0 ;SET-UP CLEARANCE ~
    Q408=+0 ;RETR. HEIGHT ~
    Q253=+750 ;F PRE-POSITIONING ~
    Q380=+0 ;REFERENCE ANGLE ~
    Q411=+90 ~
    Q412=+90 ~
    Q413=+0 ~
    Q414=+1 ~
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
11 QS0 = SUBSTR ( SRC_QS146 BEG0 LEN10 ) ; QS146 から最初の結果 EX0C を読み出す
12 QL0 = TONUMB ( SRC_QS0 ) ;QS0 の英数字値を数値に変換して、QL0 に割り当てる
13 QS0 = SUBSTR ( SRC_QS146 BEG11 LEN10 ) ; QS146 から 2 番目の結果 EY0C を読み出す
14 QL1 = TONUMB ( SRC_QS0 ) ;QS0 の英数字値を数値に変換して、QL1 に割り当てる
15 QS0 = SUBSTR ( SRC_QS146 BEG22 LEN10 ) ; QS146 から 3 番目の結果 EA0C を読み出す
16 QL2 = TONUMB ( SRC_QS0 ) ;QS0 の英数字値を数値に変換して、QL2 に割り当てる
17 QS0 = SUBSTR ( SRC_QS146 BEG33 LEN10 ) ; QS146 から 4 番目の結果 EB0C を読み出す
18 QL3 = TONUMB ( SRC_QS0 ) ;QS0 の英数字値を数値に変換して、QL3 に割り当てる
19 Q10 = Q141 * 1000
20 FN 11: IF +Q143 GT +Q5 GOTO LBL 99
21 L Z+150 R0 FMAX
22 M30
23 LBL 99
24 L Z+150 R0 FMAX
25 FN 14: ERROR = 1001
26 END PGM K MM
"
    )
}

/// The case of `limit`: (folder, scenario, program).
fn case(tag: &str, limit: &str) -> (PathBuf, PathBuf, PathBuf) {
    table_ac_case(tag, SCENARIO, &program(limit))
}

fn run_case(
    dir: &Path,
    scenario: &Path,
    program: &Path,
) -> (std::process::Output, serde_json::Value) {
    let kin = dir.join("k.toml");
    let (out, v) = run_program(
        program,
        scenario,
        dir,
        &["--kinematics", kin.to_str().unwrap()],
    );
    (out, v.expect("run wrote its JSON"))
}

fn norm(v: &serde_json::Value) -> f64 {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap().powi(2))
        .sum::<f64>()
        .sqrt()
}

/// Must show: the seed's SUBSTR/TONUMB example after a real 451 run; a limit on the
/// dispersion that does not stop the program; Q414 = 1 gives the point's spatial error.
#[test]
fn seed_example_after_a_real_451_and_a_limit_that_holds() {
    let (dir, scenario, program) = case("q-seed", "+1");
    let (out, v) = run_case(&dir, &scenario, &program);
    assert!(out.status.success(), "{v}");
    let p = &v["parameters"];
    // Every result the cycle wrote is the program's, as written: Q141..Q149 and
    // QS144..QS146.
    for (kind, wanted) in [("q", 141..=149), ("qs", 144..=146)] {
        let written = v["cycles"][0][kind].as_object().unwrap();
        for n in wanted {
            let name = format!("{}{n}", kind.to_uppercase());
            assert!(
                written.contains_key(&name),
                "{name} written by 451: {written:?}"
            );
        }
        for (name, value) in written {
            assert_eq!(&p[name], value, "{name} in \"parameters\"");
        }
    }
    let qs146 = p["QS146"].as_str().unwrap();
    // QL0..QL3 are the four numbers of QS146 (EX0C EY0C EA0C EB0C), as printed.
    let fields: Vec<f64> = qs146
        .split_whitespace()
        .map(|f| f.parse().unwrap())
        .collect();
    assert_eq!(fields.len(), 4, "{qs146}");
    for (i, want) in fields.iter().enumerate() {
        assert_eq!(
            p[format!("QL{i}")].as_f64().unwrap(),
            *want,
            "QL{i} of {qs146}"
        );
    }
    assert_eq!(p["QS0"].as_str().unwrap(), &qs146[33..43]);
    // One measuring point on A: its spatial error, not divided by sqrt 2.
    let axes = v["cycles"][0]["kinematics"]["axes"].as_array().unwrap();
    let a = axes.iter().find(|a| a["axis"] == "A").unwrap();
    let positions = a["positions"].as_array().unwrap();
    assert_eq!(positions.len(), 2, "the reference and one point");
    let point_error = norm(&positions[1]["deviation_before"]);
    let q141 = p["Q141"].as_f64().unwrap();
    assert!(point_error > 1e-3, "{point_error}");
    assert!(
        (q141 - point_error).abs() < 1e-9,
        "Q141 {q141}, point {point_error}"
    );
    assert_eq!(a["dispersion_before"].as_f64().unwrap(), q141);
    assert!((p["Q10"].as_f64().unwrap() - q141 * 1000.0).abs() < 1e-9);
    assert!(v.get("error").is_none());
    // The protocol shows the same dispersion.
    let html = std::fs::read_to_string(dir.join("TCHPRAUTO.html")).unwrap();
    assert!(
        html.contains(&format!("{q141:.4}")),
        "Q141 {q141:.4} not in the protocol"
    );
}

/// Must show: a limit on the measured dispersion that stops the program through FN 14:
/// exit 1, the number in the output and the JSON.
#[test]
fn a_limit_on_the_dispersion_stops_the_program_through_fn14() {
    let (dir, scenario, program) = case("q-fn14", "+0.000001");
    let (out, v) = run_case(&dir, &scenario, &program);
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(v["error"]["number"], 1001, "{v}");
    assert_eq!(v["error"]["line"], 43);
    let text =
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    assert!(text.contains("FN 14: ERROR = 1001"), "{text}");
    // The cycle itself was fine; its results are the program's.
    assert_eq!(v["cycles"][0]["status"], "ok");
    assert!(v["parameters"]["Q143"].as_f64().unwrap() > 0.000001);
}

/// Must show: `check` refuses an L block whose Q value is outside the limits, at its
/// line, before anything moves; a move on a measured value is left to `run`.
#[test]
fn check_evaluates_parameters_before_anything_moves() {
    let dir = tmpdir("q-check");
    let bad = dir.join("bad.h");
    std::fs::write(
        &bad,
        "0 BEGIN PGM B MM\n1 Q20 = 1000\n2 L Z+Q20 R0 FMAX\n3 END PGM B MM\n",
    )
    .unwrap();
    let scenario = configs().join("scenarios/demo-sphere.toml");
    let out = run(bin()
        .args(["check", bad.to_str().unwrap()])
        .args(["--scenario", scenario.to_str().unwrap()])
        .args(["--presets", dir.join("p.toml").to_str().unwrap()]));
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("line 3") && err.contains("software limits"),
        "{err}"
    );
    // The shipped evaluation program passes: its moves on measured values wait.
    let out = run(bin()
        .args([
            "check",
            configs().join("programs/451-evaluate.h").to_str().unwrap(),
        ])
        .args(["--scenario", scenario.to_str().unwrap()])
        .args(["--presets", dir.join("p.toml").to_str().unwrap()]));
    assert!(out.status.success());
}

/// table-ac with `[cycles] mStrobeRotAxPos = 203` (the PLC positions A and C), in `dir`.
fn m_function_machine(dir: &Path) -> PathBuf {
    let shipped = std::fs::read_to_string(configs().join("machines/table-ac.toml")).unwrap();
    assert!(
        shipped.contains("\n[cycles]\n"),
        "table-ac has a [cycles] table"
    );
    let machine = dir.join("table-ac-m203.toml");
    std::fs::write(
        &machine,
        shipped.replace("\n[cycles]\n", "\n[cycles]\nmStrobeRotAxPos = 203\n"),
    )
    .unwrap();
    machine
}

/// The strobes of M203 the run printed, in order: (Q120, Q122) of each.
fn strobes(said: &str) -> Vec<(f64, f64)> {
    said.lines()
        .filter_map(|l| l.trim().strip_prefix("M203 (mStrobeRotAxPos): "))
        .map(|rest| {
            let words: Vec<&str> = rest.split(':').next().unwrap().split(' ').collect();
            let value = |q: &str| {
                words
                    .iter()
                    .find_map(|w| w.strip_prefix(&format!("{q}=")))
                    .unwrap_or_else(|| panic!("{q} in {rest}"))
                    .parse::<f64>()
                    .unwrap()
            };
            assert!(!rest.contains("Q121"), "table-ac has no B axis: {rest}");
            (value("Q120"), value("Q122"))
        })
        .collect()
}

/// Must show: with `mStrobeRotAxPos` the rotary turns of 451 are strobes of the M
/// function with the target angles in Q120 (A) and Q122 (C), in the order the cycle
/// measures (A+90, then C's reference and its three positions, back to the start); the
/// simulator carries out each positioning (the spheres are where they should be: the
/// same results as without the key); the program reads Q120/Q122 after the cycle, and
/// `--json` lists them.
#[test]
fn rotary_axes_positioned_by_an_m_function_write_q120_to_q122() {
    let retracted = program("+1").replace("Q408=+0 ;", "Q408=+100 ;");
    let (dir, scenario, plain) = table_ac_case("q-m203-plain", SCENARIO, &retracted);
    let plain = run_case(&dir, &scenario, &plain).1;
    // Without the key Q120 is nobody's: `check` refuses a program that reads it.
    assert!(plain["parameters"].get("Q120").is_none(), "{plain}");
    let body = retracted.replace("19 Q10 = Q141 * 1000", "19 Q10 = Q120 + Q122 + 7");
    let (dir, scenario, program) = table_ac_case("q-m203", SCENARIO, &body);
    let machine = m_function_machine(&dir);
    let text = std::fs::read_to_string(&scenario).unwrap();
    let first = text.lines().next().unwrap();
    std::fs::write(
        &scenario,
        text.replacen(first, &format!("machine = \"{}\"", machine.display()), 1),
    )
    .unwrap();
    let (out, v) = run_program(
        &program,
        &scenario,
        &dir,
        &[
            "--kinematics",
            dir.join("k.toml").to_str().unwrap(),
            "--yes",
        ],
    );
    let v = v.expect("run wrote its JSON");
    assert!(out.status.success(), "{v}");
    // The progress lines go to stderr.
    let said = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        strobes(&said),
        [
            (90.0, 0.0),
            (0.0, 0.0),
            (0.0, 90.0),
            (0.0, 180.0),
            (0.0, 270.0),
            (0.0, 0.0)
        ],
        "{said}"
    );
    // The PLC's positionings put the spheres where the NC's do: the same results.
    let p = &v["parameters"];
    assert_eq!(p["Q120"].as_f64(), Some(0.0), "{v}");
    assert_eq!(p["Q122"].as_f64(), Some(0.0), "{v}");
    assert!(p.get("Q121").is_none(), "{v}");
    assert_eq!(v["cycles"][0]["q"]["Q120"].as_f64(), Some(0.0), "{v}");
    assert_eq!(p["Q10"].as_f64(), Some(7.0), "{v}");
    for q in ["Q141", "Q143"] {
        let (a, b) = (
            p[q].as_f64().unwrap(),
            plain["parameters"][q].as_f64().unwrap(),
        );
        assert!((a - b).abs() < 1e-6, "{q}: {a} with M203, {b} without");
    }
}
