//! Cycle 451 through `probebridge run` as a user runs it: the estimator process is
//! started, the spheres are fitted and the identification solved there, and the
//! results are checked against the scenario's injected errors and against an
//! independent computation of spec.md's formulas.

#[path = "../../tests/src/spec451.rs"]
#[allow(dead_code)]
mod spec451;

mod common;
#[path = "common/table_ac_case.rs"]
mod table_ac_case;

use common::*;
use spec451::*;
use std::path::{Path, PathBuf};
use table_ac_case::table_ac_case;

fn machine(name: &str) -> hal::config::MachineConfig {
    hal::config::MachineConfig::load(&configs().join(format!("machines/{name}.toml"))).unwrap()
}

/// A scenario written here with every location error of A and C injected, noise 0.
const SCENARIO: &str = r#"
seed = 11
[probe]
ball_radius = 3.0
noise = 0.0
pretravel = 0.0
[truth]
EY0A = -0.014
EZ0A = 0.009
EB0A = -0.006
EC0A = 0.003
EX0C = 0.021
EY0C = -0.017
EA0C = 0.005
EB0C = -0.004
[[sphere]]
center = [-40.0, 45.0, 70.0]
radius = 12.5
"#;

const PROGRAM: &str = "0 BEGIN PGM K MM
1 TOOL CALL \"TOUCH_PROBE\" Z
2 L Z+150 R0 FMAX
3 L X-40 Y+45 R0 FMAX
4 L Z+92.5 R0 FMAX
5 TCH PROBE 451 MEASURE KINEMATICS ~
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
    Q419=+60 ~
    Q420=+300 ~
    Q421=+0 ~
    Q422=+5 ~
    Q423=+4 ;NO. OF PROBE POINTS ~
    Q431=+1 ;PRESET ~
    Q432=+0 ;BACKLASH, ANG. RANGE
6 END PGM K MM
";

/// A folder `tag` with the hand-written scenario (on table-ac) and the program:
/// (folder, scenario, program).
fn hand_written_case(tag: &str) -> (PathBuf, PathBuf, PathBuf) {
    table_ac_case(tag, SCENARIO, PROGRAM)
}

/// Must show: on a scenario written by hand (noise 0), `probebridge run` recovers every
/// injected error, and Q141..Q146 / QS144..QS146 match spec.md's formulas computed
/// independently; the estimator process did the fitting and the identification.
#[test]
fn run_451_recovers_hand_written_errors_in_the_estimator_process() {
    let (dir, scenario, program) = hand_written_case("mode2");
    let kin = dir.join("table-ac.kinematics.toml");
    let (out, v) = run_program(
        &program,
        &scenario,
        &dir,
        &["--kinematics", kin.to_str().unwrap()],
    );
    assert!(out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("started the estimator process"), "{stderr}");
    let v = v.unwrap();
    let c = &v["cycles"][0];
    assert_eq!(c["status"], "ok", "{c}");
    assert!(
        c["kinematics"]["estimator"]
            .as_str()
            .unwrap()
            .starts_with("estimator process"),
        "{}",
        c["kinematics"]["estimator"]
    );
    let after = errors_of(&c["kinematics"]["errors_after"]);
    for (name, truth) in [
        ("EY0A", -0.014),
        ("EZ0A", 0.009),
        ("EB0A", -0.006),
        ("EC0A", 0.003),
        ("EX0C", 0.021),
        ("EY0C", -0.017),
        ("EA0C", 0.005),
        ("EB0C", -0.004),
    ] {
        assert!(
            (after[name] - truth).abs() < 1e-4,
            "{name}: {} vs {truth}",
            after[name]
        );
    }
    check_results_against_spec(c, &machine("table-ac"));
    // Every measuring position with all its angles, centre and radius.
    let positions = c["kinematics"]["axes"][1]["positions"].as_array().unwrap();
    assert_eq!(positions.len(), 6);
    for p in positions {
        assert!(p["angles"]["A"].is_number() && p["angles"]["C"].is_number());
        assert!((p["radius"].as_f64().unwrap() - 12.5).abs() < 1e-4);
        assert!(p["centre"][2].is_number());
    }
    // Written, with the protocol next to the program.
    assert_eq!(c["kinematics"]["written"], true);
    let k = std::fs::read_to_string(&kin).unwrap();
    assert!(k.contains("EB0C") && k.contains("EY0A"), "{k}");
    let html = std::fs::read_to_string(dir.join("TCHPRAUTO.html")).unwrap();
    assert!(html.contains("<title>EYC</title>") && html.contains("<title>EZA</title>"));
}

/// The shipped check program on the demo scenario: mode 0 leaves the kinematics file
/// byte for byte, exit 0, the dispersion of the injected errors shows.
#[test]
fn run_451_check_program_changes_nothing() {
    let dir = tmpdir("check");
    let kin = dir.join("k.toml");
    let text = "machine = \"table-ac\"\n[errors]\nEY0C = 0.001 # by hand\n";
    std::fs::write(&kin, text).unwrap();
    let (out, v) = run_program(
        &configs().join("programs/451-check.h"),
        &configs().join("scenarios/demo-sphere.toml"),
        &dir,
        &["--kinematics", kin.to_str().unwrap()],
    );
    assert!(out.status.success());
    assert_eq!(std::fs::read_to_string(&kin).unwrap(), text);
    let v = v.unwrap();
    let c = &v["cycles"][0];
    assert!(c["q"]["Q143"].as_f64().unwrap() > 0.005, "{c}");
    assert_eq!(c["q"]["Q142"], -1.0);
    assert_eq!(
        c["qs"]["QS145"],
        "-1.0000000 -1.0000000 -1.0000000 -1.0000000"
    );
    // Q431=1: the preset at the located sphere centre, the reference centre.
    assert!(c["q"]["Q147"].as_f64().unwrap().abs() < 1e-6, "{c}");
    check_results_against_spec(c, &machine("table-ac"));
    assert!(dir.join("TCHPRAUTO.html").exists());
}

/// `check` runs what `run` refuses before the first move, without a bus: cycle 451's
/// plan against the machine (software limits, Hirth axes, mode 3) and the active
/// kinematics file. The shipped program passes; each variant fails with its reason.
#[test]
fn check_refuses_what_run_would_refuse_before_moving() {
    let dir = tmpdir("check451");
    let program = configs().join("programs/451-check.h");
    let text = std::fs::read_to_string(&program).unwrap();
    let scenario = configs().join("scenarios/demo-sphere.toml");
    let check = |file: &Path, kin: Option<&Path>| {
        let mut cmd = bin();
        cmd.args([
            "check",
            file.to_str().unwrap(),
            "--scenario",
            scenario.to_str().unwrap(),
        ]);
        if let Some(k) = kin {
            cmd.args(["--kinematics", k.to_str().unwrap()]);
        }
        let out = cmd.output().expect("run probebridge");
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let (code, stderr) = check(&program, None);
    assert_eq!(code, Some(0), "{stderr}");

    // A +130 deg end angle, beyond A's software limit of +120.
    let wide = dir.join("wide.h");
    std::fs::write(&wide, text.replace("Q412=+90 ", "Q412=+130")).unwrap();
    let (code, stderr) = check(&wide, None);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(
        stderr.contains("block 19 (cycle 451)") && stderr.contains("outside the software limits"),
        "{stderr}"
    );

    // Mode 3 measuring A alone: nothing nearer the bed can take up A's datum.
    let mode3 = dir.join("mode3.h");
    let only_a = text
        .replace("Q406=+0 ", "Q406=+3 ")
        .replace("Q422=+3 ", "Q422=+0 ");
    std::fs::write(&mode3, only_a).unwrap();
    let (code, stderr) = check(&mode3, None);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("Q406=3"), "{stderr}");

    // A kinematics file of another machine.
    let kin = dir.join("other.toml");
    std::fs::write(&kin, "machine = \"head-b-table-c\"\n[errors]\n").unwrap();
    let (code, stderr) = check(&program, Some(&kin));
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("active kinematics"), "{stderr}");
    // Nothing was written beside the program or the kinematics file.
    assert!(!dir.join("other.toml.prev").exists());
}

/// The estimator child killed mid-run (SIGKILL after the first contact): the bridge
/// starts it again, sends it the sphere's contacts again and repeats the request; the
/// run completes with the results of an undisturbed run and says what happened.
#[test]
fn run_451_restarts_a_killed_estimator_and_gives_the_same_results() {
    use std::io::{BufRead, BufReader};
    use std::process::Stdio;
    let (dir, scenario, program) = hand_written_case("restart451");

    let clean = dir.join("clean");
    std::fs::create_dir_all(&clean).unwrap();
    let kin_clean = clean.join("k.toml");
    let (out, want) = run_program(
        &program,
        &scenario,
        &clean,
        &["--kinematics", kin_clean.to_str().unwrap()],
    );
    assert!(out.status.success());
    let want = want.unwrap();

    let killed = dir.join("killed");
    std::fs::create_dir_all(&killed).unwrap();
    let kin = killed.join("k.toml");
    let json = killed.join("r.json");
    let mut child = bin()
        .args(["run", program.to_str().unwrap()])
        .args(["--scenario", scenario.to_str().unwrap()])
        .args(["--out", killed.to_str().unwrap()])
        .args(["--json", json.to_str().unwrap()])
        .args([
            "--service",
            &format!("pb-cli-restart451-{}", std::process::id()),
        ])
        .args(["--kinematics", kin.to_str().unwrap()])
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .unwrap();
    let mut estimator: Option<i32> = None;
    let mut killed_it = false;
    let mut said = String::new();
    for line in BufReader::new(child.stderr.take().unwrap()).lines() {
        let line = line.unwrap();
        if let Some(rest) = line.split_once("started the estimator process (pid ") {
            estimator = rest.1.split(')').next().and_then(|p| p.parse().ok());
        }
        if !killed_it && line.contains("contact at") {
            let pid = estimator.expect("the estimator was started before the first contact");
            // SAFETY: SIGKILL to the estimator child of the run we started.
            assert_eq!(unsafe { libc::kill(pid, libc::SIGKILL) }, 0);
            killed_it = true;
        }
        said.push_str(&line);
        said.push('\n');
    }
    let status = child.wait().unwrap();
    assert!(killed_it, "{said}");
    assert!(status.success(), "{said}");
    assert!(
        said.contains("died during") && said.contains("restarted it (pid"),
        "{said}"
    );
    let got: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let (w, g) = (&want["cycles"][0], &got["cycles"][0]);
    assert_eq!(g["status"], "ok", "{g}");
    assert_eq!(w["q"], g["q"]);
    assert_eq!(w["qs"], g["qs"]);
    assert_eq!(
        w["kinematics"]["errors_after"],
        g["kinematics"]["errors_after"]
    );
    assert_eq!(g["kinematics"]["written"], true);
    assert_eq!(
        std::fs::read_to_string(&kin_clean).unwrap(),
        std::fs::read_to_string(&kin).unwrap()
    );
}
