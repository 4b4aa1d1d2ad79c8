//! `probebridge serve` on the simulator with a pymodbus "PLC" (`tests/gateway/plc.py`,
//! written from the register map in docs/gateway.md): programs 431, 444, 451 and 460
//! started by number give the results of `probebridge run --json` (and their
//! uncertainties; 460's probe table row in the calibration block) to the registers'
//! precision; refusal while busy, abort mid-cycle, acknowledge after an error, FN 14
//! as error kind 31 with its number, QR kept across a restart, the start confirming a
//! 451 on an M-function table, a second connection refused, PLC heartbeat loss,
//! SIGTERM and SIGHUP mid-cycle, a second SIGTERM during a slow stop, the lock and
//! iceoryx2's root in the unit's runtime folder.
//!
//! Python with pymodbus: `PROBEBRIDGE_PYTHON`, else `/opt/probebridge-venv/bin/python`
//! (`scripts/install-test-peers`). Skipped with a line saying why where neither is
//! there, never in CI.

mod common;
#[path = "common/pymodbus_venv.rs"]
mod pymodbus_venv;
use pymodbus_venv::python;
#[path = "common/serve.rs"]
mod serve;
use serve::{copy_programs, Serve};

use common::*;
use std::ffi::OsStr;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};

impl Serve {
    /// Serves `scenario` with the programs `(number, shipped program)` in a folder of
    /// its own; `plc` adds keys to the `[plc]` section.
    fn start(name: &str, scenario: &str, programs: &[(u16, &str)], plc: &str) -> Self {
        let dir = tmpdir(&format!("serve-{name}"));
        Self::start_in(dir, name, scenario, programs, plc, &[])
    }

    /// As [`Serve::start`], with `machine` added to the `[machine]` section.
    fn start_with_machine(
        name: &str,
        scenario: &str,
        programs: &[(u16, &str)],
        machine: &str,
    ) -> Self {
        let dir = tmpdir(&format!("serve-{name}"));
        Self::start_at(dir, name, scenario, programs, (machine, ""), &[])
    }

    /// Starts in `dir` (again, after a restart: same configuration and history), with
    /// `envs` added to its environment.
    fn start_in(
        dir: PathBuf,
        name: &str,
        scenario: &str,
        programs: &[(u16, &str)],
        plc: &str,
        envs: &[(&str, &OsStr)],
    ) -> Self {
        Self::start_at(dir, name, scenario, programs, ("", plc), envs)
    }

    /// `extra`: keys added to the `[machine]` and the `[plc]` section.
    fn start_at(
        dir: PathBuf,
        name: &str,
        scenario: &str,
        programs: &[(u16, &str)],
        extra: (&str, &str),
        envs: &[(&str, &OsStr)],
    ) -> Self {
        let (machine, plc) = extra;
        copy_programs(&dir, programs);
        let scenario = configs().join("scenarios").join(scenario);
        let config = dir.join("gateway.toml");
        std::fs::write(
            &config,
            format!(
                "[machine]\nscenario = {:?}\nservice = \"pbserve-{name}-{}\"\nkinematics = {:?}\n{machine}\
                 [programs]\nfolder = \"programs\"\n[history]\nsqlite = {:?}\n{HISTORY_TIMEOUT}\
                 [plc]\nlisten = \"127.0.0.1:0\"\n{plc}",
                scenario.to_str().unwrap(),
                std::process::id(),
                dir.join("kinematics.toml").to_str().unwrap(),
                dir.join("history.sqlite").to_str().unwrap(),
            ),
        )
        .unwrap();
        let mut cmd = bin();
        cmd.envs(envs.iter().copied());
        Self::spawn(cmd, &dir, &config)
    }

    /// `probebridge history --db ... --json`.
    fn history(&self) -> Vec<serde_json::Value> {
        history_json(&self.dir.join("history.sqlite"))
    }
}

fn history_json(db: &Path) -> Vec<serde_json::Value> {
    let out = run(bin()
        .args(["history", "--db", db.to_str().unwrap(), "--json"])
        .args(["--since", "2000-01-01"]));
    assert!(out.status.success());
    serde_json::from_slice::<serde_json::Value>(&out.stdout)
        .unwrap()
        .as_array()
        .unwrap()
        .clone()
}

/// The last successful cycle of `probebridge run --json` of the same program, with
/// the whole run's machine time (`run_machine_time_s`: every cycle's).
fn run_json(program: &str, scenario: &str, name: &str) -> serde_json::Value {
    let dir = tmpdir(&format!("serve-ref-{name}"));
    let kin = dir.join("kinematics.toml");
    let db = dir.join("history.sqlite");
    let (out, json) = run_program(
        &configs().join("programs").join(program),
        &configs().join("scenarios").join(scenario),
        &dir,
        &[
            "--yes",
            "--kinematics",
            kin.to_str().unwrap(),
            "--history",
            db.to_str().unwrap(),
        ],
    );
    assert!(out.status.success());
    // `run --history` records the run as `serve` does.
    let h = history_json(&db);
    assert_eq!(h.len(), 1);
    assert_eq!(
        (h[0]["source"].as_str(), h[0]["status"].as_str()),
        (Some("run"), Some("done"))
    );
    let json = json.unwrap();
    let cycles = json["cycles"].as_array().unwrap();
    let mut last = cycles
        .iter()
        .rev()
        .find(|c| c["status"] == "ok")
        .unwrap()
        .clone();
    let total: f64 = cycles
        .iter()
        .map(|c| c["machine_time_s"].as_f64().unwrap())
        .sum();
    last["run_machine_time_s"] = total.into();
    last
}

/// Cycle 460's probe table row and its uncertainties in the calibration block equal
/// the run's to float32's precision; no result slot holds anything. Any other cycle:
/// the calibration block is empty.
fn assert_same_calibration(plc: &serde_json::Value, run: &serde_json::Value) {
    let cal = plc["cal"].as_object().unwrap();
    let cal_u = plc["cal_u"].as_object().unwrap();
    if run["cycle"] != 460 {
        assert!(
            cal.is_empty() && cal_u.is_empty(),
            "a calibration row: {plc}"
        );
        return;
    }
    assert_eq!(plc["cycle"], 460);
    for k in ["R", "CAL_OF1", "CAL_OF2", "L"] {
        let v = run["q"][k].as_f64().unwrap();
        let g = cal[k]
            .as_f64()
            .unwrap_or_else(|| panic!("{k} missing: {plc}"));
        assert!(
            (g - v).abs() <= 1e-6 * v.abs().max(1.0),
            "{k}: register {g}, run {v}"
        );
    }
    let want_u = run["u"].as_object().unwrap();
    assert!(!want_u.is_empty(), "460 reports uncertainties: {run}");
    assert_eq!(
        cal_u.len(),
        want_u.len(),
        "u of exactly the measured columns: {plc}"
    );
    for (k, v) in want_u {
        let (g, v) = (cal_u[k].as_f64().unwrap(), v.as_f64().unwrap());
        assert!(
            (g - v).abs() <= 1e-6 * v.abs().max(1e-3),
            "u of {k}: register {g}, run {v}"
        );
    }
    assert!(plc["real"].as_object().unwrap().is_empty(), "{plc}");
    assert!(plc["u"].as_object().unwrap().is_empty(), "{plc}");
}

/// The machine time block: its parts add up to the total, which is within 5 % of
/// what `run` reported for the same program's cycles on the simulator.
fn assert_same_machine_time(plc: &serde_json::Value, run: &serde_json::Value) {
    let Some(t) = plc.get("time") else {
        return;
    };
    let part = |k: &str| t[k].as_f64().unwrap_or_else(|| panic!("{k}: {t}"));
    let total = part("total");
    let sum: f64 = ["positioning", "rotary", "probing", "standing"]
        .iter()
        .map(|k| part(k))
        .sum();
    assert!((total - sum).abs() <= 1e-3 * total.max(1.0), "{t}");
    let m = run["run_machine_time_s"].as_f64().unwrap();
    assert!(
        (total - m).abs() <= (0.05 * m).max(0.05),
        "machine time: register {total} s, run {m} s"
    );
}

/// Every Q result (and 451's errors by ISO name) equals the run's, to float32's
/// precision and to the DINT's scale of 1e4.
fn assert_same_results(plc: &serde_json::Value, run: &serde_json::Value) {
    assert_same_calibration(plc, run);
    assert_same_machine_time(plc, run);
    if run["cycle"] == 460 {
        return;
    }
    let mut expected: Vec<(String, f64)> = run["q"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(k, v)| (k.clone(), v.as_f64().unwrap()))
        .collect();
    if let Some(k) = run.get("kinematics") {
        for when in ["before", "after"] {
            for (n, v) in k[format!("errors_{when}")].as_object().unwrap() {
                expected.push((format!("{when}.{n}"), v.as_f64().unwrap()));
            }
        }
    }
    assert_eq!(plc["cycle"], run["cycle"]);
    assert!(!expected.is_empty());
    for (name, v) in &expected {
        let real = plc["real"][name]
            .as_f64()
            .unwrap_or_else(|| panic!("{name} missing"));
        assert!(
            (real - v).abs() <= 1e-6 * v.abs().max(1.0),
            "{name}: register {real}, run {v}"
        );
        let dint = plc["dint"][name].as_i64().unwrap();
        assert!(
            (dint as f64 - v * 1e4).abs() <= 0.5 + 1e-6,
            "{name}: DINT {dint}, run {v}"
        );
    }
    assert_eq!(
        plc["real"].as_object().unwrap().len(),
        expected.len(),
        "no extra results: {plc}"
    );
    // The uncertainty block: every u of the run in its slot, nothing else.
    let mut u: Vec<(String, f64)> = run
        .get("u")
        .and_then(|u| u.as_object())
        .into_iter()
        .flatten()
        .map(|(k, v)| (k.clone(), v.as_f64().unwrap()))
        .collect();
    if let Some(k) = run.get("kinematics").and_then(|k| k.get("errors_u")) {
        for (n, v) in k.as_object().unwrap() {
            u.push((format!("after.{n}"), v.as_f64().unwrap()));
        }
    }
    assert!(!u.is_empty(), "the run reports uncertainties: {run}");
    for (name, v) in &u {
        let got = plc["u"][name]
            .as_f64()
            .unwrap_or_else(|| panic!("u of {name} missing: {plc}"));
        assert!(
            (got - v).abs() <= 1e-6 * v.abs().max(1e-3),
            "u of {name}: register {got}, run {v}"
        );
    }
    assert_eq!(
        plc["u"].as_object().unwrap().len(),
        u.len(),
        "no extra u: {plc}"
    );
}

#[test]
fn programs_started_by_number_give_the_results_of_run() {
    let Some(py) = python() else { return };
    for (number, program, scenario) in [
        (431, "431-plane.h", "tilted-plane.toml"),
        (444, "444-freeform.h", "freeform.toml"),
        (451, "451-check.h", "demo-sphere.toml"),
        (460, "460-calibrate.h", "demo-sphere.toml"),
    ] {
        let name = format!("results-{number}");
        let serve = Serve::start(&name, scenario, &[(number, program)], "");
        let got = serve.plc(&py, &["run", &number.to_string()]);
        let want = run_json(program, scenario, &name);
        assert_same_results(&got, &want);
        // The history has the run: request, program, status, every Q result of every
        // cycle, 451's errors by ISO name, the measuring logs.
        let h = serve.history();
        assert_eq!(h.len(), 1, "{h:?}");
        let r = &h[0];
        assert_eq!(r["status"], "done");
        assert_eq!(r["program_number"], number);
        assert_eq!(r["request_seq"], 1);
        // The request's parameters 1..8 as the PLC wrote them (plc.py's PARAMS).
        assert_eq!(
            r["parameters"],
            serde_json::json!([1.5, -2.25, 0.0, 0.0, 0.0, 0.0, 0.0, 1000.125])
        );
        assert!(!r["protocols"].as_array().unwrap().is_empty(), "{r}");
        let results = r["results"].as_array().unwrap();
        for (q, v) in want["q"].as_object().unwrap() {
            assert!(
                results
                    .iter()
                    .any(|x| x["name"] == *q && x["value"] == *v && x["cycle"] == want["cycle"]),
                "{q} in the history"
            );
        }
        if number == 451 {
            let iso = r["iso_errors"].as_array().unwrap();
            assert_eq!(iso.len(), 10, "A and C, 5 each: {iso:?}");
            let ey0c = iso.iter().find(|e| e["name"] == "EY0C").unwrap();
            assert_eq!(
                ey0c["after"], want["kinematics"]["errors_after"]["EY0C"],
                "{ey0c}"
            );
        }
    }
}

/// The machine's state is read again at each start, as a new `probebridge run` reads
/// it: a preset row rewritten since the service started (by a 451 with Q431, or by the
/// operator) is the one the next program runs with, and a table that cannot be read
/// refuses the start ("the machine is not up", the file named in the log) before
/// anything moves or is recorded.
#[test]
fn each_start_runs_with_the_machine_state_its_files_hold_then() {
    let Some(py) = python() else { return };
    let dir = tmpdir("serve-state-reread");
    let state = dir.join("state");
    let serve = Serve::start_in(
        dir.clone(),
        "state-reread",
        "plane-z10.toml",
        &[(431, "431-plane.h")],
        "",
        &[("STATE_DIRECTORY", state.as_os_str())],
    );
    let q175 = |out: &serde_json::Value| out["real"]["Q175"].as_f64().unwrap();
    let first = serve.plc(&py, &["run", "431"]);
    // The plane z = 10 under preset row 0 at the origin.
    assert!((q175(&first) - 10.0).abs() < 1e-3, "{first}");
    let presets = state.join("table-ac").join("table-ac.presets.toml");
    assert!(
        presets.is_file(),
        "the state was seeded: {}",
        presets.display()
    );
    // Row 0 moved down by 1.5 mm while the service runs.
    std::fs::write(
        &presets,
        "machine = \"table-ac\"\nactive = 0\n\n[[preset]]\nnumber = 0\nX = 0.0\nY = 0.0\nZ = -1.5\n",
    )
    .unwrap();
    let second = serve.plc(&py, &["run", "431"]);
    assert!((q175(&second) - 11.5).abs() < 1e-3, "{second}");
    // A table whose active row does not exist: refused, nothing recorded.
    std::fs::write(&presets, "machine = \"table-ac\"\nactive = 7\n").unwrap();
    let st = serve.plc_script(&py, "history_plc.py", &["start", "431"]);
    assert_eq!(st["ack_code"], 1 | 0x8000, "{st}");
    assert_eq!(st["reason"], 8, "the machine is not up: {st}");
    assert_eq!(serve.history().len(), 2);
    let log = serve.log();
    assert!(
        log.contains("the machine's state cannot be read") && log.contains("table-ac.presets.toml"),
        "{log}"
    );
}

#[test]
fn start_while_busy_is_refused_and_abort_stops_mid_cycle() {
    let Some(py) = python() else { return };
    let serve = Serve::start(
        "busy",
        "demo-sphere.toml",
        &[(451, "451-check.h"), (431, "431-plane.h")],
        "",
    );
    let out = serve.plc(&py, &["busy_abort", "451", "431", "451"]);
    assert!(out["aborted_at_point"].as_u64().unwrap() < 42, "{out}");
    assert!(serve.log().contains("Aborted(Request)"), "{}", serve.log());
    // After the abort the same machine measures again: 451 done with its results.
    assert_eq!(out["after"]["cycle"], 451, "{out}");
    assert!(out["after"]["real"]["after.EY0C"].is_number(), "{out}");
    let h = serve.history();
    assert_eq!(h.len(), 2, "{h:?}");
    let mut statuses: Vec<&str> = h.iter().map(|r| r["status"].as_str().unwrap()).collect();
    statuses.sort_unstable();
    assert_eq!(statuses, ["aborted", "done"], "{h:?}");
}

#[test]
fn an_error_must_be_acknowledged() {
    let Some(py) = python() else { return };
    // The freeform program probes where demo-sphere has nothing: the probe does not
    // trigger.
    let serve = Serve::start(
        "ackerr",
        "demo-sphere.toml",
        &[(444, "444-freeform.h"), (451, "451-check.h")],
        "",
    );
    serve.plc(&py, &["ack_error", "444", "451"]);
}

/// A program that stops itself with `FN 14: ERROR = n` (issue 27): the PLC sees a
/// failed run with error kind 31 and n in the error code register, and the history
/// keeps the run as an error.
#[test]
fn fn14_is_a_failed_run_with_its_number() {
    let Some(py) = python() else { return };
    let serve = Serve::start("fn14", "demo-sphere.toml", &[], "");
    // Read at the start, as every program is: nothing moves before the FN 14.
    std::fs::write(
        serve.dir.join("programs/777.h"),
        "0 BEGIN PGM E MM\n1 Q1 = 2\n2 FN 11: IF +Q1 GT +1 GOTO LBL 9\n3 M30\n\
         4 LBL 9\n5 FN 14: ERROR = 1234\n6 END PGM E MM\n",
    )
    .unwrap();
    let got = serve.plc(&py, &["program_error", "777"]);
    assert_eq!(got["error_kind"], 31, "{got}\n{}", serve.log());
    assert_eq!(got["error_code"], 1234, "{got}");
    let h = serve.history();
    assert_eq!(h.len(), 1, "{h:?}");
    assert_eq!(h[0]["status"], "error", "{h:?}");
}

/// `[cycles] mStrobeRotAxPos` (issue 27): the seeds want the start of a 451 with the
/// rotary axes at 0 deg confirmed; on the gateway the PLC's start request is that
/// confirmation, so a start without the confirm flag measures.
#[test]
fn with_m_strobe_rot_ax_pos_the_plcs_start_confirms_451() {
    let Some(py) = python() else { return };
    let files = tmpdir("serve-m203-files");
    // The machine's name and its shipped preset table (the state's seed) beside it.
    let machine = files.join("table-ac.toml");
    std::fs::copy(
        configs().join("machines/table-ac.presets.toml"),
        files.join("table-ac.presets.toml"),
    )
    .unwrap();
    let shipped = std::fs::read_to_string(configs().join("machines/table-ac.toml")).unwrap();
    assert!(
        shipped.contains("\n[cycles]\n"),
        "table-ac has a [cycles] table"
    );
    std::fs::write(
        &machine,
        shipped.replace("\n[cycles]\n", "\n[cycles]\nmStrobeRotAxPos = 203\n"),
    )
    .unwrap();
    let scenario = files.join("demo-sphere-m203.toml");
    let demo = std::fs::read_to_string(configs().join("scenarios/demo-sphere.toml")).unwrap();
    assert!(demo.contains("\nmachine = \"table-ac\"\n"), "{demo}");
    std::fs::write(
        &scenario,
        demo.replace(
            "\nmachine = \"table-ac\"\n",
            &format!("\nmachine = {:?}\n", machine.to_str().unwrap()),
        ),
    )
    .unwrap();
    let serve = Serve::start("m203", scenario.to_str().unwrap(), &[], "");
    // 451-check with a retraction height (the PLC turns the table with the probe
    // clear) and C alone, to keep it short.
    let program = std::fs::read_to_string(configs().join("programs/451-check.h"))
        .unwrap()
        .replace("Q408=+50 ", "Q408=+150 ")
        .replace("Q411=-90 ", "Q411=+0 ")
        .replace("Q412=+90 ", "Q412=+0 ")
        .replace("Q414=+3 ", "Q414=+0 ");
    std::fs::write(serve.dir.join("programs/451.h"), program).unwrap();
    let got = serve.plc(&py, &["run_unconfirmed", "451"]);
    assert_eq!(got["state"], 2, "done: {got}\n{}", serve.log());
    let log = serve.log();
    assert!(
        log.contains("confirmed=true") && log.contains("mStrobeRotAxPos:"),
        "{log}"
    );
}

/// QR parameters are kept with the machine's state across runs and restarts of the
/// gateway (issue 27): a program sets QR1, the service restarts on the same state, the
/// next program finds it and counts it on, and the one after finds the count.
#[test]
fn qr_parameters_are_kept_across_a_restart_of_the_gateway() {
    let Some(py) = python() else { return };
    let dir = tmpdir("serve-qr");
    let state = dir.join("state");
    let envs = [("STATE_DIRECTORY", state.as_os_str())];
    let mut serve = Serve::start_in(dir.clone(), "qr", "demo-sphere.toml", &[], "", &envs);
    std::fs::write(
        dir.join("programs/101.h"),
        "0 BEGIN PGM S MM\n1 QR1 = 41\n2 END PGM S MM\n",
    )
    .unwrap();
    // Done when QR1 was 41 before it, else FN 14 with 1 (undefined: another error).
    std::fs::write(
        dir.join("programs/102.h"),
        "0 BEGIN PGM C MM\n1 QR1 = QR1 + 1\n2 FN 10: IF +QR1 NE +42 GOTO LBL 9\n3 M30\n\
         4 LBL 9\n5 FN 14: ERROR = 1\n6 END PGM C MM\n",
    )
    .unwrap();
    let got = serve.plc(&py, &["run_unconfirmed", "101"]);
    assert_eq!(got["state"], 2, "{got}\n{}", serve.log());
    assert!(serve.stop().success());
    let serve = Serve::start_in(dir.clone(), "qr", "demo-sphere.toml", &[], "", &envs);
    let got = serve.plc(&py, &["run_unconfirmed", "102"]);
    assert_eq!(
        got["state"],
        2,
        "QR1 kept across the restart: {got}\n{}",
        serve.log()
    );
    // Counted on and kept again: 43 now, so the same program stops through FN 14.
    let got = serve.plc(&py, &["program_error", "102"]);
    assert_eq!(
        (&got["error_kind"], &got["error_code"]),
        (&31.into(), &1.into()),
        "{got}"
    );
}

#[test]
fn a_second_connection_cannot_write_and_the_map_is_guarded() {
    let Some(py) = python() else { return };
    let serve = Serve::start("second", "demo-sphere.toml", &[], "");
    serve.plc(&py, &["second_connection"]);
}

#[test]
fn plc_heartbeat_loss_aborts_the_motion() {
    let Some(py) = python() else { return };
    let serve = Serve::start(
        "heartbeat",
        "demo-sphere.toml",
        &[(451, "451-check.h")],
        "heartbeat_timeout_ms = 300\n",
    );
    serve.plc(&py, &["heartbeat_loss", "451"]);
    assert!(
        serve.log().contains("PLC heartbeat stale"),
        "{}",
        serve.log()
    );
}

#[test]
fn sigterm_mid_cycle_aborts_and_exits_0() {
    let Some(py) = python() else { return };
    let mut serve = Serve::start(
        "sigterm",
        "demo-sphere.toml",
        &[(451, "451-check.h")],
        "heartbeat_timeout_ms = 0\n",
    );
    serve.plc(&py, &["start_busy", "451"]);
    let status = serve.stop();
    assert_eq!(status.code(), Some(0), "{}", serve.log());
    let log = serve.log();
    assert!(log.contains("Aborted(Shutdown)"), "{log}");
    assert!(
        log.contains("state=\"aborted\"") || log.contains("state=aborted"),
        "{log}"
    );
    assert_eq!(serve.history()[0]["status"], "aborted");
}

#[test]
fn sighup_mid_cycle_is_a_stop_like_sigterm() {
    let Some(py) = python() else { return };
    let mut serve = Serve::start(
        "sighup",
        "demo-sphere.toml",
        &[(451, "451-check.h")],
        "heartbeat_timeout_ms = 0\n",
    );
    serve.plc(&py, &["start_busy", "451"]);
    let status = serve.signal(libc::SIGHUP);
    assert_eq!(status.code(), Some(0), "{status:?}\n{}", serve.log());
    let log = serve.log();
    assert!(log.contains("stopping on SIGHUP"), "{log}");
    assert!(log.contains("Aborted(Shutdown)"), "{log}");
    assert_eq!(serve.history()[0]["status"], "aborted");
}

/// A package upgrade's restart: SIGUSR1 mid-cycle lets the measurement end as it would
/// (recorded done, not aborted), then the service exits 75 for systemd to start it
/// again (`RestartForceExitStatus=75`).
#[test]
fn sigusr1_mid_cycle_restarts_after_the_measurement() {
    let Some(py) = python() else { return };
    let mut serve = Serve::start(
        "sigusr1",
        "demo-sphere.toml",
        &[(451, "451-check.h")],
        "heartbeat_timeout_ms = 0\n",
    );
    serve.plc(&py, &["start_busy", "451"]);
    let status = serve.signal(libc::SIGUSR1);
    assert_eq!(status.code(), Some(75), "{status:?}\n{}", serve.log());
    let log = serve.log();
    assert!(log.contains("after the running measurement"), "{log}");
    assert!(log.contains("restarting as asked (SIGUSR1)"), "{log}");
    assert!(!log.contains("Aborted("), "{log}");
    let h = serve.history();
    assert_eq!(h.len(), 1, "{h:?}");
    assert_eq!(h[0]["status"], "done", "{h:?}");
}

/// Waits (polling the log, up to 60 s) until it holds `text`.
fn wait_for_log(serve: &Serve, text: &str) {
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    while !serve.log().contains(text) {
        assert!(
            std::time::Instant::now() < deadline,
            "no {text:?} in:\n{}",
            serve.log()
        );
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
}

#[test]
fn a_second_sigterm_during_a_slow_stop_exits_at_once() {
    let Some(py) = python() else { return };
    let scenario = "plane-z10.toml";
    let (mut plc, addr) = sim_plc("127.0.0.1:0", scenario);
    let mut serve = Serve::start_with_machine(
        "sigterm2",
        scenario,
        &[(431, "431-plane.h")],
        &format!("modbus = {addr:?}\n"),
    );
    serve.plc(&py, &["start_busy", "431"]);
    // The machine's PLC stops answering: braking and closing wait for its replies, so
    // the stop is slow.
    // SAFETY: kill(2) on our own child's pid.
    unsafe { libc::kill(plc.id() as i32, libc::SIGSTOP) };
    // SAFETY: as above.
    unsafe { libc::kill(serve.child.id() as i32, libc::SIGTERM) };
    // The service logs "stopping" with the signal's number once it took the first.
    wait_for_log(&serve, &format!("signal={}", libc::SIGTERM));
    let status = serve.signal(libc::SIGTERM);
    assert_eq!(status.code(), Some(128 + libc::SIGTERM), "{}", serve.log());
    // SAFETY: as above.
    unsafe { libc::kill(plc.id() as i32, libc::SIGCONT) };
    let _ = plc.kill();
    let _ = plc.wait();
}

#[test]
fn the_lock_and_the_iceoryx2_root_are_in_the_units_runtime_directory() {
    let Some(py) = python() else { return };
    let dir = tmpdir("serve-rundir");
    let (run, tmp) = (dir.join("run"), dir.join("tmp"));
    std::fs::create_dir_all(&run).unwrap();
    std::fs::create_dir_all(&tmp).unwrap();
    // A local user holds the lock the service would take in the shared temporary
    // folder: under systemd it is not the service's lock.
    let service = format!("pbserve-rundir-{}", std::process::id());
    let squatted =
        std::fs::File::create(tmp.join(format!("probebridge-service-{service}.lock"))).unwrap();
    // SAFETY: flock on a descriptor this test owns.
    assert_eq!(
        unsafe { libc::flock(std::os::fd::AsRawFd::as_raw_fd(&squatted), libc::LOCK_EX) },
        0
    );
    let serve = Serve::start_in(
        dir.clone(),
        "rundir",
        "tilted-plane.toml",
        &[(431, "431-plane.h")],
        "",
        &[
            ("RUNTIME_DIRECTORY", run.as_os_str()),
            ("TMPDIR", tmp.as_os_str()),
        ],
    );
    assert!(
        run.join(format!("probebridge-service-{service}.lock"))
            .is_file(),
        "{}",
        serve.log()
    );
    // The service and its estimator child meet under this root (a 431 needs none,
    // but the service asks the child for a ping before it says it is ready).
    assert!(run.join("iceoryx2").is_dir());
    let got = serve.plc(&py, &["run", "431"]);
    assert_eq!(got["cycle"], 431);
    let in_tmp: Vec<_> = std::fs::read_dir(&tmp)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(
        in_tmp.len(),
        1,
        "only the squatter's file in TMPDIR: {in_tmp:?}"
    );
    drop(squatted);
}

#[test]
fn kill_9_mid_451_leaves_the_run_interrupted_and_restarts_idle() {
    let Some(py) = python() else { return };
    let programs = [(451, "451-check.h")];
    let plc = "heartbeat_timeout_ms = 0\n";
    let mut serve = Serve::start("kill9", "demo-sphere.toml", &programs, plc);
    serve.plc(&py, &["start_busy", "451"]);
    serve.child.kill().unwrap();
    serve.child.wait().unwrap();
    let dir = serve.dir.clone();
    drop(serve);
    let serve = Serve::start_in(dir, "kill9", "demo-sphere.toml", &programs, plc, &[]);
    let st = serve.plc(&py, &["state"]);
    assert_eq!(st["state"], 0, "idle after the restart, never done: {st}");
    let h = serve.history();
    assert_eq!(h.len(), 1);
    assert_eq!(h[0]["status"], "interrupted");
    assert!(h[0]["results"].as_array().unwrap().is_empty());
}

/// `probebridge sim --modbus ADDR`: the machine's PLC in a process of its own; the
/// address it serves on.
fn sim_plc(addr: &str, scenario: &str) -> (Child, String) {
    let mut child = bin()
        .args(["sim", "--modbus", addr, "--scenario"])
        .arg(configs().join("scenarios").join(scenario))
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let Some(at) = line.trim().strip_prefix("modbus tcp ") else {
        let _ = child.kill();
        panic!("simulated PLC did not come up: {line:?}");
    };
    (child, at.to_string())
}

#[test]
fn a_lost_plc_clears_machine_ok_and_the_gateway_opens_it_again() {
    let Some(py) = python() else { return };
    let scenario = "plane-z10.toml";
    let (mut plc, addr) = sim_plc("127.0.0.1:0", scenario);
    let serve = Serve::start_with_machine(
        "reconnect",
        scenario,
        &[(431, "431-plane.h")],
        &format!("modbus = {addr:?}\n"),
    );
    let first = serve.plc(&py, &["run", "431"]);
    assert_eq!(first["cycle"], 431, "{first}");
    // The PLC dies: the bit drops and starts are refused, "machine not ok".
    plc.kill().unwrap();
    plc.wait().unwrap();
    serve.plc(&py, &["machine_lost", "431"]);
    // The gateway keeps trying (and says so) while the PLC is away.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    while !serve.log().contains("cannot open the machine: ") {
        assert!(std::time::Instant::now() < deadline, "{}", serve.log());
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    // It comes back on the same address: the gateway connects again by itself.
    let (mut plc, again) = sim_plc(&addr, scenario);
    assert_eq!(again, addr);
    let after = serve.plc(&py, &["machine_back", "431"]);
    for q in ["Q158", "Q159"] {
        let (a, b) = (after["real"][q].as_f64(), first["real"][q].as_f64());
        assert!(
            a.zip(b).is_some_and(|(a, b)| (a - b).abs() < 1e-4),
            "{q}: {after} vs {first}"
        );
    }
    let log = serve.log();
    assert!(log.contains("machine not ok"), "{log}");
    assert!(log.contains("opening the machine again"), "{log}");
    assert!(log.contains("machine ok again"), "{log}");
    let _ = plc.kill();
    let _ = plc.wait();
}

#[test]
fn a_bad_config_names_the_key_and_nothing_starts() {
    let dir = tmpdir("serve-badcfg");
    let config = dir.join("gateway.toml");
    std::fs::write(
        &config,
        "[machine]\nscenario = \"x.toml\"\n[programs]\nfolder = \".\"\n[history]\nenabled = false\n[plc]\nword_order = \"BADC\"\n",
    )
    .unwrap();
    let out = run(bin().args(["serve", "--config", config.to_str().unwrap()]));
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("gateway.toml") && err.contains("plc.word_order"),
        "{err}"
    );
}

#[test]
fn systemd_sees_ready_watchdog_and_status() {
    let Some(py) = python() else { return };
    let dir = tmpdir("serve-notify");
    let socket = dir.join("notify.sock");
    let listener = std::os::unix::net::UnixDatagram::bind(&socket).unwrap();
    listener
        .set_read_timeout(Some(std::time::Duration::from_secs(60)))
        .unwrap();
    let serve = Serve::start_in(
        dir,
        "notify",
        "tilted-plane.toml",
        &[(431, "431-plane.h")],
        "",
        &[
            ("NOTIFY_SOCKET", socket.as_os_str()),
            ("WATCHDOG_USEC", OsStr::new("200000")),
        ],
    );
    let mut seen = String::new();
    let mut buf = [0u8; 512];
    while !(seen.contains("READY=1") && seen.contains("WATCHDOG=1")) {
        let n = listener.recv(&mut buf).expect("a notification within 60 s");
        seen.push_str(&String::from_utf8_lossy(&buf[..n]));
        seen.push('\n');
    }
    assert!(seen.contains("STATUS="), "{seen}");
    // And a PLC gets results from it.
    let got = serve.plc(&py, &["run", "431"]);
    assert_eq!(got["cycle"], 431);
}
