//! Cycle 460 from the command line, as an operator calibrates the probe before 451:
//! `check` plans its moves, `run` measures and writes the probe table row into the
//! machine's state directory (never `configs/`), prints the row with its standard
//! uncertainties and puts the result into `--json` and the history; a second run starts
//! from that row.
//! The stylus of `stylus-offset.toml` sits 3 µm / -2 µm off the spindle axis; table-ac's
//! spindle drive (CiA 402 profile position on the CANopen bus) turns it to 0° and 180°,
//! so 460 finds the offset from the command line as from the library.

#[allow(
    dead_code,
    reason = "each test binary uses a part of the shared helpers"
)]
mod common;

use common::configs;
use std::path::Path;
use std::process::Command;

fn probebridge(state: &Path) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_probebridge"));
    c.env("XDG_STATE_HOME", state).env_remove("STATE_DIRECTORY");
    c
}

fn said(out: &std::process::Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

#[test]
fn check_then_run_460_writes_the_probe_row_into_the_state() {
    let tmp = common::tmpdir("460");
    let state = tmp.join("state");
    let program = configs().join("programs/460-calibrate.h");
    let scenario = configs().join("scenarios/stylus-offset.toml");
    let shipped_row = configs().join("machines/table-ac.probes.toml");
    assert!(!shipped_row.exists(), "a probe table in configs/");

    let out = common::run(
        probebridge(&state)
            .args(["check", program.to_str().unwrap()])
            .args(["--scenario", scenario.to_str().unwrap()]),
    );
    assert!(out.status.success(), "{}", said(&out));

    let row = state.join("probebridge/table-ac/table-ac.probes.toml");
    let db = tmp.join("history.sqlite");
    let mut texts = Vec::new();
    let mut reported = Vec::new();
    for pass in 1..=2 {
        let json = tmp.join(format!("r{pass}.json"));
        let out = common::run(
            probebridge(&state)
                .args(["run", program.to_str().unwrap()])
                .args(["--scenario", scenario.to_str().unwrap()])
                .args(["--json", json.to_str().unwrap(), "--yes"])
                .args(["--out", tmp.to_str().unwrap()])
                .args(["--history", db.to_str().unwrap()])
                .args([
                    "--service",
                    &format!("pb-460-{}-{pass}", std::process::id()),
                ]),
        );
        let text = said(&out);
        assert!(out.status.success(), "run {pass}:\n{text}");
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        let c = &v["cycles"][0];
        assert_eq!(c["cycle"], 460, "{v}");
        assert_eq!(c["status"], "ok", "{v}");
        // The scenario's stylus: ball R 3, no length error, centre 3 µm / -2 µm off.
        let q = |k: &str| c["q"][k].as_f64().unwrap();
        assert!((q("R") - 3.0).abs() < 1e-4, "{v}");
        assert!(q("L").abs() < 1e-4, "{v}");
        assert!((q("CAL_OF1") - 0.003).abs() < 1e-4, "{v}");
        assert!((q("CAL_OF2") + 0.002).abs() < 1e-4, "{v}");
        for k in ["R", "L", "CAL_OF1", "CAL_OF2"] {
            assert!(c["u"][k].as_f64().is_some_and(f64::is_finite), "{k}: {v}");
        }
        let cal = &c["calibration"];
        assert_eq!(cal["offset_measured"], true, "{cal}");
        assert_eq!(cal["file"], row.display().to_string(), "{cal}");
        assert!(!text.contains("cannot be separated"), "{text}");
        assert!(text.contains("R ") && text.contains(" ± "), "{text}");
        assert!(
            text.contains(&format!("written: {}", row.display())),
            "{text}"
        );
        assert!(tmp.join("TCHPR460.TXT").is_file());
        texts.push(std::fs::read_to_string(&row).unwrap());
        reported.push((c["q"].clone(), c["u"].clone()));
        if pass == 2 {
            // The second run started from the first's row, and measured the same stylus
            // again (its contacts, probed with the first's offset, differ in the last
            // bits).
            let first = &reported[0].0;
            for k in ["R", "CAL_OF1", "CAL_OF2", "L"] {
                assert_eq!(cal["before"][k], first[k], "{k}: {cal}");
                let again = cal["after"][k].as_f64().unwrap();
                assert!(
                    (again - first[k].as_f64().unwrap()).abs() < 1e-9,
                    "{k}: {cal}"
                );
            }
        }
    }
    assert!(texts[0].contains("name = \"TOUCH_PROBE\""), "{}", texts[0]);

    // The history holds each run's row as the run reported it, with its uncertainties.
    let out =
        common::run(probebridge(&state).args(["history", "--db", db.to_str().unwrap(), "--json"]));
    assert!(out.status.success(), "{}", said(&out));
    let runs: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let runs = runs.as_array().unwrap();
    assert_eq!(runs.len(), 2, "{runs:?}");
    for (q, u) in &reported {
        let kept = runs.iter().any(|r| {
            let results = r["results"].as_array().unwrap();
            ["R", "CAL_OF1", "CAL_OF2", "L"].iter().all(|k| {
                results.iter().any(|x| {
                    x["cycle"] == 460
                        && x["name"] == *k
                        && x["value"] == q[k]
                        && x["u"] == u.get(k).cloned().unwrap_or(serde_json::Value::Null)
                })
            })
        });
        assert!(
            kept,
            "no run in the history with R, CAL_OF1, CAL_OF2, L = {q} ± {u}: {runs:?}"
        );
    }
    assert!(!shipped_row.exists(), "460 wrote into configs/");
}

/// A 460 block whose start is too close to the software limit: `check` refuses it at
/// the block, before anything moves, naming the limit.
#[test]
fn check_refuses_a_460_whose_moves_leave_the_limits() {
    let tmp = common::tmpdir("460-limits");
    let text = std::fs::read_to_string(configs().join("programs/460-calibrate.h"))
        .unwrap()
        .replace("L X+50 Y-30 R0 FMAX M91", "L X+395 Y-30 R0 FMAX M91");
    let program = tmp.join("far.h");
    std::fs::write(&program, text).unwrap();
    let out = probebridge(&tmp.join("state"))
        .args(["check", program.to_str().unwrap()])
        .args([
            "--scenario",
            configs()
                .join("scenarios/demo-sphere.toml")
                .to_str()
                .unwrap(),
        ])
        .output()
        .unwrap();
    let text = said(&out);
    assert_eq!(out.status.code(), Some(2), "{text}");
    assert!(
        text.contains("cycle 460") && text.contains("software limits"),
        "{text}"
    );
}
