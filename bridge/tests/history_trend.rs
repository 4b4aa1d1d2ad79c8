//! The calibration history over five cycle 451 runs on the demo sphere with drifting
//! injected errors (EX0C, EY0C grow from run to run): `probebridge history` lists them,
//! `history --html` draws the trend page, and headless Chromium renders it (screenshot,
//! the SVG elements in its DOM, no page errors).
//!
//! Chromium: `PROBEBRIDGE_CHROMIUM`, else `chromium` on the PATH
//! (`scripts/install-test-peers` installs Debian's). Skipped with a line saying why
//! where it is missing, never in CI.

mod common;

use common::*;
use std::path::{Path, PathBuf};
use std::process::Command;

fn chromium() -> Option<PathBuf> {
    let p = std::env::var_os("PROBEBRIDGE_CHROMIUM")
        .map_or_else(|| PathBuf::from("chromium"), PathBuf::from);
    if Command::new(&p)
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success())
    {
        return Some(p);
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "no chromium in CI; scripts/install-test-peers installs it"
    );
    eprintln!("SKIPPED: no chromium (run scripts/install-test-peers)");
    None
}

/// demo-sphere.toml with the C axis's location errors grown by `i` steps.
fn drifted_scenario(dir: &Path, i: usize) -> PathBuf {
    let text = std::fs::read_to_string(configs().join("scenarios/demo-sphere.toml")).unwrap();
    let ex = 0.012 + 0.004 * i as f64;
    let ey = -0.008 - 0.002 * i as f64;
    let text = text
        .replace("EX0C = 0.012", &format!("EX0C = {ex}"))
        .replace("EY0C = -0.008", &format!("EY0C = {ey}"));
    let path = dir.join(format!("drift-{i}.toml"));
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn five_drifting_451_runs_make_a_trend_page_a_browser_renders() {
    let dir = tmpdir("history-trend");
    let db = dir.join("history.sqlite");
    for i in 0..5 {
        let scenario = drifted_scenario(&dir, i);
        let run_dir = dir.join(format!("run{i}"));
        std::fs::create_dir_all(&run_dir).unwrap();
        let kin = run_dir.join("kinematics.toml");
        let (out, _) = run_program(
            &configs().join("programs/451-check.h"),
            &scenario,
            &run_dir,
            &[
                "--yes",
                "--kinematics",
                kin.to_str().unwrap(),
                "--history",
                db.to_str().unwrap(),
            ],
        );
        assert!(out.status.success());
    }
    let out = run(bin().args([
        "history",
        "--db",
        db.to_str().unwrap(),
        "--machine",
        "table-ac",
    ]));
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert_eq!(text.lines().count(), 5, "{text}");
    let out = run(bin().args(["history", "--db", db.to_str().unwrap(), "--json"]));
    let runs: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let ex0c: Vec<f64> = runs
        .as_array()
        .unwrap()
        .iter()
        .map(|r| {
            r["iso_errors"]
                .as_array()
                .unwrap()
                .iter()
                .find(|e| e["name"] == "EX0C")
                .unwrap()["after"]
                .as_f64()
                .unwrap()
        })
        .collect();
    assert!(
        ex0c.windows(2).all(|w| w[1] > w[0]),
        "the identified EX0C follows the drift: {ex0c:?}"
    );
    let page = dir.join("trend.html");
    let out = run(bin().args([
        "history",
        "--db",
        db.to_str().unwrap(),
        "--html",
        page.to_str().unwrap(),
    ]));
    assert!(out.status.success());
    let Some(chrome) = chromium() else { return };
    let profile = dir.join("chromium-profile");
    let common_flags = [
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-background-networking",
        "--disable-component-update",
        "--no-first-run",
        "--disable-sync",
        "--enable-logging=stderr",
        "--v=0",
    ];
    let url = format!("file://{}", page.display());
    let shot = dir.join("trend.png");
    let out = Command::new(&chrome)
        .args(common_flags)
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg(format!("--screenshot={}", shot.display()))
        .arg("--window-size=1400,1600")
        .arg(&url)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let png = std::fs::read(&shot).unwrap();
    assert!(
        png.len() > 10_000 && png.starts_with(b"\x89PNG"),
        "screenshot"
    );
    let out = Command::new(&chrome)
        .args(common_flags)
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg("--dump-dom")
        .arg(&url)
        .output()
        .unwrap();
    assert!(out.status.success());
    let dom = String::from_utf8_lossy(&out.stdout);
    // The browser's DOM: one chart per error of A and C (5 + 5) and per axis (2),
    // a point per run in each.
    assert_eq!(dom.matches("<svg").count(), 12, "{dom}");
    assert_eq!(dom.matches("<circle").count(), 12 * 5);
    assert_eq!(dom.matches("class=\"band\"").count(), 10);
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(
        !log.lines()
            .any(|l| l.contains("CONSOLE") || l.contains("Uncaught")),
        "the page logged: {log}"
    );
    if let Some(keep) = std::env::var_os("PROBEBRIDGE_TREND_SCREENSHOT") {
        std::fs::copy(&shot, keep).unwrap();
    }
}
