//! The calibration history over five cycle 451 runs on the demo sphere with drifting
//! injected errors (EX0C, EY0C grow from run to run): `probebridge history` lists them,
//! `history --html` draws the trend page, and headless Chromium renders it (screenshot,
//! the SVG elements in its DOM, no page errors).
//!
//! Chromium: `PROBEBRIDGE_CHROMIUM`, else `chromium` on the PATH
//! (`scripts/install-test-peers` installs Debian's). Skipped with a line saying why
//! where it is missing, never in CI.

#[path = "common/browser.rs"]
mod browser;
mod common;

use common::*;
use std::path::{Path, PathBuf};

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
    // The runs were made a minute apart; the history says they were a week apart, as
    // a weekly calibration check makes them.
    let c = rusqlite::Connection::open(&db).unwrap();
    for (week, day) in ["10-28", "11-04", "11-11", "11-18", "11-25"]
        .iter()
        .enumerate()
    {
        c.execute(
            "UPDATE runs SET started = ?1 WHERE id = ?2",
            rusqlite::params![format!("2026-{day}T07:30:00Z"), week as i64 + 1],
        )
        .unwrap();
    }
    drop(c);
    let page = dir.join("trend.html");
    let out = run(bin().args([
        "history",
        "--db",
        db.to_str().unwrap(),
        "--html",
        page.to_str().unwrap(),
    ]));
    assert!(out.status.success());
    let Some(browser) = browser::Browser::find(&dir.join("chromium-profile")) else {
        return;
    };
    let url = format!("file://{}", page.display());
    browser.screenshot(
        &url,
        &dir.join("trend.png"),
        "1100,1500",
        "PROBEBRIDGE_TREND_SCREENSHOT",
    );
    let page = browser.load(&url);
    assert!(
        page.console.is_empty(),
        "the page logged: {:?}",
        page.console
    );
    let dom = page.dom;
    // The browser's DOM: one chart per error of A and C (5 + 5) and per axis (2),
    // before and after optimisation per run in each, the unit on every y axis, a dated
    // time axis.
    assert_eq!(dom.matches("<svg class=\"trend\"").count(), 12, "{dom}");
    assert_eq!(dom.matches("class=\"pt after\"").count(), 12 * 5);
    assert_eq!(dom.matches("class=\"pt before\"").count(), 12 * 5);
    assert_eq!(
        dom.matches(" (µm)</text>").count() + dom.matches(" (arcsec)</text>").count(),
        12
    );
    assert_eq!(dom.matches("run start (UTC), 2026").count(), 12);
    assert!(!dom.contains(">-0<") && !dom.contains("-0.0 "));
    // The summary table has a row per chart; the headline names EX0C's drift (4 µm a
    // run: +16 µm over the five, +4 µm since the previous run).
    assert_eq!(
        dom.matches("<tr data-series=").count() + dom.matches("<tr class=").count(),
        12
    );
    let headline = &dom[dom.find("id=\"headline\"").unwrap()..];
    let headline = &headline[..headline.find("</p>").unwrap()];
    assert!(headline.contains("<b>EX0C</b>"), "{headline}");
}
