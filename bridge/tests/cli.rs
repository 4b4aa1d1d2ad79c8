//! The `probebridge` binary as a user runs it.

mod common;

use common::*;
use std::path::Path;

/// A plane `z = z0` in a scenario written by hand, probed from above with ball radius
/// R: the JSON contact has Z = z0 + R within 1e-6 mm.
#[test]
fn probe_reports_plane_height_plus_ball_radius() {
    let dir = tmpdir("probe");
    for (z0, r) in [(12.0, 3.0), (-40.25, 1.0), (3.3333333, 2.5)] {
        let scenario = dir.join(format!("plane-{z0}.toml"));
        std::fs::write(
            &scenario,
            format!(
                "machine = \"{}\"\nseed = 3\n[probe]\nball_radius = {r}\n[[plane]]\npoint = [5.0, 5.0, {z0}]\nnormal = [0.0, 0.0, 1.0]\n",
                configs().join("machines/table-ac.toml").display()
            ),
        )
        .unwrap();
        let json = dir.join(format!("contact-{z0}.json"));
        let out = run(bin().args([
            "probe",
            "--scenario",
            scenario.to_str().unwrap(),
            "--start",
            &format!("10,-20,{}", z0 + r + 4.0),
            "--dir",
            "0,0,-1",
            "--dist",
            "10",
            "--feed",
            "150",
            "--service",
            &format!("pb-cli-{}-{z0}", std::process::id()),
            "--json",
            json.to_str().unwrap(),
        ]));
        assert!(out.status.success());
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        let z = v["contact"]["Z"].as_f64().unwrap();
        assert!((z - (z0 + r)).abs() < 1e-6, "Z = {z}, want {}", z0 + r);
        assert!((v["contact"]["X"].as_f64().unwrap() - 10.0).abs() < 1e-6);
        assert!(v["contact"]["C"].is_number() && v["contact"]["A"].is_number());
        assert!(v["trigger_ns"].as_u64().unwrap() > 0);
    }
}

#[test]
fn probe_without_contact_fails_with_a_clear_message_and_writes_nothing() {
    let dir = tmpdir("miss");
    let json = dir.join("contact.json");
    let out = run(bin().args([
        "probe",
        "--scenario",
        configs().join("scenarios/plane-z10.toml").to_str().unwrap(),
        "--start",
        "0,0,40",
        "--dir",
        "0,0,-1",
        "--dist",
        "5",
        "--feed",
        "300",
        "--service",
        &format!("pb-cli-miss-{}", std::process::id()),
        "--json",
        json.to_str().unwrap(),
    ]));
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("probe did not trigger") && err.contains("5.000 mm"),
        "{err}"
    );
    assert!(!json.exists());
}

#[test]
fn bad_arguments_and_scenarios_are_refused_before_anything_moves() {
    let out = run(bin().args([
        "probe", "--start", "0,0", "--dir", "0,0,-1", "--dist", "5", "--feed", "100",
    ]));
    assert!(!out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("--start \"0,0\": expected three numbers")
    );

    let dir = tmpdir("bad");
    let scenario = dir.join("bad.toml");
    std::fs::write(
        &scenario,
        "machine = \"table-ac\"\n[probe]\nball_radius = 3.0\nnoize = 0.1\n",
    )
    .unwrap();
    let out = run(bin().args([
        "probe",
        "--scenario",
        scenario.to_str().unwrap(),
        "--start",
        "0,0,50",
        "--dir",
        "0,0,-1",
        "--dist",
        "5",
        "--feed",
        "100",
    ]));
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad.toml") && err.contains("noize"), "{err}");
}

/// The README's first command, with `--keep`: contacts printed and the estimator's
/// sphere within 1 µm, the 451 errors with their u, no estimator detail, and the
/// temporary folder kept where it says. (Without `--keep` the folder is removed:
/// docs_check runs the README's line in a temporary folder of its own and finds it
/// empty afterwards.)
#[test]
fn demo_fits_the_sphere_within_a_micrometre() {
    let out = run(bin().args(["demo", "--keep"]));
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        text.matches("X+").count() + text.matches("X-").count(),
        5,
        "{text}"
    );
    let line = text
        .lines()
        .find(|l| l.contains("centre off by"))
        .unwrap_or_else(|| panic!("no fit in:\n{text}"));
    let nums: Vec<f64> = line
        .split(" by ")
        .skip(1)
        .filter_map(|s| s.split(" mm").next()?.trim().parse().ok())
        .collect();
    assert_eq!(nums.len(), 2, "{line}");
    assert!(nums[0] < 1e-3 && nums[1] < 1e-3, "{line}");
    // Then cycle 451 mode 1 on A and C: EX0C (injected 0.012 mm) corrected in a
    // temporary kinematics file, with its standard uncertainty, the protocol written.
    assert!(
        text.contains("cycle 451 MEASURE KINEMATICS, mode 1"),
        "{text}"
    );
    let ex0c = text
        .lines()
        .find(|l| l.trim_start().starts_with("EX0C"))
        .unwrap_or_else(|| panic!("no EX0C in:\n{text}"));
    let v: Vec<&str> = ex0c.split_whitespace().skip(1).take(5).collect();
    let num = |i: usize| -> f64 { v[i].parse().unwrap_or_else(|e| panic!("{ex0c}: {e}")) };
    assert_eq!(v[2], "±", "{ex0c}");
    assert!(
        num(0) == 0.0 && (num(1) - 0.012).abs() < 1e-4 && num(3) > 0.0 && num(4) == 0.012,
        "{ex0c}"
    );
    // The estimator's own lines and the QS strings only with --verbose.
    for detail in ["estimator:", "armed windows", "QS14"] {
        assert!(
            !text.contains(detail) && !err.contains(detail),
            "{detail} without --verbose:\n{text}\n{err}"
        );
    }
    let protocol = text
        .lines()
        .find_map(|l| l.trim().strip_prefix("protocol: "))
        .unwrap_or_else(|| panic!("no protocol in:\n{text}"));
    assert!(protocol.ends_with("TCHPRAUTO.html") && !protocol.contains("configs/"));
    assert!(text.contains("corrected errors written"), "{text}");
    let kept = text
        .lines()
        .find_map(|l| l.strip_prefix("the demo's files are kept in "))
        .and_then(|l| l.strip_suffix(" (--keep)"))
        .unwrap_or_else(|| panic!("no kept folder in:\n{text}"));
    assert!(
        Path::new(protocol).starts_with(kept),
        "{protocol} in {kept}"
    );
    assert!(Path::new(protocol).exists(), "{protocol}");
    std::fs::remove_dir_all(kept).unwrap();
}

fn q(v: &serde_json::Value, cycle: usize, key: &str) -> f64 {
    v["cycles"][cycle]["q"][key]
        .as_f64()
        .unwrap_or_else(|| panic!("no {key} in {v}"))
}

/// The manual's 444 example, checked and run: a face 0.25 mm proud of the nominal
/// point gives Q151 = Q164 = +0.25 and Q183 = 0 with QS400 "1-1".
#[test]
fn check_and_run_the_seed_444_example() {
    let program = configs().join("programs/444-seed.h");
    let out = run(bin().args(["check", program.to_str().unwrap()]));
    assert!(out.status.success());

    let dir = tmpdir("seed444");
    let (out, v) = run_program(
        &program,
        &configs().join("scenarios/seed-444.toml"),
        &dir,
        &[],
    );
    assert!(out.status.success());
    let v = v.unwrap();
    assert_eq!(v["cycles"][0]["block"], 11);
    assert_eq!(v["cycles"][0]["cycle"], 444);
    assert_eq!(v["cycles"][0]["status"], "ok");
    assert!(v["cycles"][0]["message"].is_null());
    for (k, want) in [
        ("Q151", 0.25),
        ("Q152", 0.0),
        ("Q153", 0.0),
        ("Q161", 0.25),
        ("Q164", 0.25),
        ("Q183", 0.0),
    ] {
        assert!((q(&v, 0, k) - want).abs() < 1e-6, "{k} = {}", q(&v, 0, k));
    }
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("Q164") && stdout.contains("+0.2500"),
        "{stdout}"
    );
}

/// 431 on the shipped tilted plane: the projection angles of its true normal.
#[test]
fn run_431_on_the_tilted_plane() {
    let dir = tmpdir("p431");
    let (out, v) = run_program(
        &configs().join("programs/431-plane.h"),
        &configs().join("scenarios/tilted-plane.toml"),
        &dir,
        &[],
    );
    assert!(out.status.success());
    let v = v.unwrap();
    assert!((q(&v, 0, "Q158") - 5.0).abs() < 1e-6, "{v}");
    assert!((q(&v, 0, "Q159") + 3.0).abs() < 1e-6, "{v}");
    assert!(dir.join("TCHPR431.TXT").exists());
}

/// `--bus-faults`: the same 431 with 1 % of the frames lost between the master and
/// the simulated drives gives the same angles, and says the faults were on; a bad
/// specification is refused before anything opens.
#[test]
fn run_431_with_injected_bus_faults() {
    let dir = tmpdir("p431faults");
    let (out, v) = run_program(
        &configs().join("programs/431-plane.h"),
        &configs().join("scenarios/tilted-plane.toml"),
        &dir,
        &["--bus-faults", "drop=0.01,seed=3"],
    );
    assert!(out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("bus faults injected (seed 3)"), "{stderr}");
    let v = v.unwrap();
    assert!((q(&v, 0, "Q158") - 5.0).abs() < 1e-6, "{v}");
    assert!((q(&v, 0, "Q159") + 3.0).abs() < 1e-6, "{v}");

    let out = bin()
        .args(["run", "x.h", "--bus-faults", "drop=0.7,duplicate=0.7"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("--bus-faults") && stderr.contains("add up to"),
        "{stderr}"
    );
}

/// Out-of-range values are refused with the line and the range; nothing runs and
/// nothing is written.
#[test]
fn out_of_range_values_are_refused_before_any_motion() {
    let dir = tmpdir("range");
    let program = dir.join("bad.h");
    let text = std::fs::read_to_string(configs().join("programs/431-plane.h"))
        .unwrap()
        .replace(
            "Q263=+0        ;1ST POINT 1ST AXIS",
            "Q263=+123456   ;1ST POINT 1ST AXIS",
        )
        .replace(
            "Q281=+1        ;MEASURING LOG",
            "Q281=+3        ;MEASURING LOG",
        );
    std::fs::write(&program, text).unwrap();
    let out = run(bin().args(["check", program.to_str().unwrap()]));
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("line 8: Q263=+123456") && err.contains("99999.9999"),
        "{err}"
    );
    assert!(
        err.contains("line 19: Q281=+3") && err.contains("0..2"),
        "{err}"
    );

    let json = dir.join("r.json");
    let out = run(bin().args([
        "run",
        program.to_str().unwrap(),
        "--out",
        dir.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]));
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("nothing moved"));
    assert!(!json.exists() && !dir.join("TCHPR431.TXT").exists());
}
