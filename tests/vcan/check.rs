//! `vcan-check`: checks on the host what the vcan VM left in its results folder (the VM's
//! own exit status does not come back through vng).
//!
//! ```text
//! vcan-check --results target/vcan/results --reference target/vcan/reference
//! ```
//!
//! - every case of `tests/vcan/cases`: the exit status, the JSON against the host
//!   reference run (in-process bus; every number to 1e-6) and against the scenario's
//!   truth (`truth=probe`, `truth=431`, `QNNN=V`);
//! - every program in `configs/programs` is covered by a case, and is run twice in a row
//!   (a run case and an again= case on its machine state);
//! - the Machine conformance suite on SocketCAN ran and passed (and was not skipped);
//! - the third-party master (`canopen_master.py`, python-canopen against `probebridge
//!   sim`), our master against a python-canopen LocalNode (`vcan-foreign-master`) and
//!   that device's own view (`foreign_device.py`): each exited 0 and printed every one
//!   of its checks with `-> ok` (the lines are printed here, with their observed values);
//! - the candump log (`candump -L vcan0`) parses with `hal::can::candump::parse_log`;
//!   per case (split at the marker frames 7FF#NN the VM sends before each case): the
//!   NMT/SDO start-up sequence, the PDO mapping written over SDO, NMT start before the
//!   first SYNC, the TPDO2 latch frames (for `probe`: the latched values equal the
//!   reported contact to one increment), and a replay: the master's recorded frames fed
//!   into a fresh simulator of the case's scenario give exactly the drive frames that
//!   were recorded;
//! - `probebridge run` of 451 SIGKILLed mid-cycle (markers 7FF#FC/FB/FA): every drive
//!   sends EMCY 8130 within its 0x1016 time (VM slack) after the master's last
//!   heartbeat, logs the loss and answers a statusword out of Operation enabled;
//!   SIGTERMed (7FF#F9/F8/F7): exit 143, "aborted" in the JSON, every drive's last
//!   controlword Shutdown or quick stop and the NMT goodbye before the exit marker.
//!
//! Exit status 0 when everything holds, 1 with a list of every difference.

use hal::can::candump::parse_log;
use hal::can::record::sent_by_master;
use hal::can::CanFrame;
use hal::canopen::cob_id::{classify, CobKind};
use hal::canopen::object;
use hal::canopen::pdo::mapping_index;
use hal::cia402::touch_probe::TouchProbeStatus;
use hal::config::{CanOpenBusConfig, MachineConfig};
use hal::master::process_data::{self, ProcessData, Tpdo2};
use serde_json::Value;
use sim::machine::{SimClock, SimMachine};
use sim::Scenario;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

const TOL: f64 = 1e-6;
/// COB-ID of the marker frames that split the log per case (CiA 301 restricted range).
const MARKER: u16 = 0x7FF;
/// Marker data byte before the conformance suite.
const CONFORMANCE_MARKER: u8 = 0xFF;
/// Tests the conformance suite must have passed on SocketCAN.
const CONFORMANCE_TESTS: usize = 7;
/// Marker data bytes before the python-canopen master and the foreign device.
const PYTHON_MASTER_MARKER: u8 = 0xFD;
const FOREIGN_DEVICE_MARKER: u8 = 0xFE;

/// The programs of the VM step beside the cases: results file stem, the checks each
/// must print with `-> ok`.
const CHECKED_PROGRAMS: [(&str, &[&str]); 3] = [
    (
        "python-canopen",
        &[
            "nmt_boot_up_at_power_on",
            "sdo_expedited_upload_device_type",
            "sdo_identity_0x1018",
            "sdo_segmented_upload_0x1008",
            "sdo_supported_drive_modes_0x6502",
            "sdo_segmented_download_0x1006",
            "sdo_abort_read_only",
            "sdo_abort_no_sub_index",
            "sdo_abort_no_object",
            "sdo_abort_value_range",
            "sdo_abort_length_too_low",
            "heartbeat_period_without_sync",
            "nmt_stopped_answers_no_sdo",
            "nmt_states_in_heartbeat",
            "nmt_reset_communication",
            "pdo_remapping_read_back",
            "tpdo_type_3_every_third_sync",
            "tpdo_type_1_every_sync",
            "cia402_mode_csp",
            "cia402_walk_to_operation_enabled",
            "cia402_statusword_bits_4_and_12_in_csp",
            "cia402_statusword_by_sdo",
            "emcy_fault_0x8611",
            "cia402_fault_state",
            "cia402_fault_reset_to_operation_enabled",
            "heartbeat_consumer_0x1016",
            "spindle_supported_drive_modes_pp",
            "spindle_refuses_csp",
            "spindle_mode_pp",
            "spindle_operation_enabled",
            "spindle_pp_set_point_acknowledge",
            "spindle_pp_target_reached",
            "spindle_pp_halt",
        ],
    ),
    (
        "foreign-master",
        &[
            "foreign_startup_accepted",
            "foreign_downloads_read_back",
            "foreign_segmented_upload_0x1008",
            "foreign_expedited_upload_0x1018",
            "foreign_abort_no_object",
            "foreign_abort_no_sub_index",
            "foreign_abort_read_only",
            "foreign_abort_length",
            "foreign_sdo_after_aborts",
        ],
    ),
    (
        "foreign-device",
        &[
            "foreign_device_downloads_as_written",
            "foreign_device_pdo_mapping",
            "foreign_device_nmt_state",
        ],
    ),
];

#[derive(Debug)]
struct Expect {
    exit: i32,
    /// Tolerance of the `QNNN=V` expectations.
    tol: f64,
    truth_probe: bool,
    truth_431: bool,
    q: Vec<(String, f64)>,
    /// The program run must equal this one but for its name, comments and Q253.
    derived: Option<String>,
    /// Runs on the machine state case NAME left (the same example again).
    again: Option<String>,
    /// `on=host`: runs only as the host reference (in-process bus), not in the VM;
    /// its expectations are checked on the reference's results.
    host_only: bool,
}

#[derive(Debug)]
struct Case {
    number: usize,
    name: String,
    scenario: PathBuf,
    /// configs/machines, for the scenario's `machine = "..."`.
    machines: PathBuf,
    args: Vec<String>,
    expect: Expect,
}

impl Case {
    /// `probe` and `run` drive the machine; `check` only validates.
    fn moves(&self) -> bool {
        matches!(self.args.first().map(String::as_str), Some("probe" | "run"))
    }
}

fn parse_cases(configs: &Path, text: &str) -> Result<Vec<Case>, String> {
    let mut cases = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = t.split('|').map(str::trim).collect();
        if fields.len() != 4 {
            return Err(format!(
                "tests/vcan/cases line {}: expected NAME | SCENARIO | ARGS | EXPECT",
                i + 1
            ));
        }
        let mut expect = Expect {
            exit: 0,
            tol: TOL,
            truth_probe: false,
            truth_431: false,
            q: Vec::new(),
            derived: None,
            again: None,
            host_only: false,
        };
        for word in fields[3].split_whitespace() {
            let (k, v) = word.split_once('=').ok_or_else(|| {
                format!("tests/vcan/cases line {}: {word:?} is not KEY=VALUE", i + 1)
            })?;
            match (k, v) {
                ("exit", v) => {
                    expect.exit = v
                        .parse()
                        .map_err(|_| format!("line {}: exit={v:?}", i + 1))?
                }
                ("tol", v) => {
                    expect.tol = v
                        .parse()
                        .map_err(|_| format!("line {}: tol={v:?}", i + 1))?
                }
                ("derived", p) => expect.derived = Some(p.to_string()),
                ("again", n) => {
                    if !cases.iter().any(|c: &Case| c.name == n) {
                        return Err(format!(
                            "tests/vcan/cases line {}: again={n}: no case {n} before this one",
                            i + 1
                        ));
                    }
                    expect.again = Some(n.to_string())
                }
                ("on", "host") => expect.host_only = true,
                ("truth", "probe") => expect.truth_probe = true,
                ("truth", "431") => expect.truth_431 = true,
                // Q results, and cycle 460's probe table columns.
                (q, v) if q.starts_with('Q') || ["R", "CAL_OF1", "CAL_OF2", "L"].contains(&q) => {
                    expect.q.push((
                        q.to_string(),
                        v.parse()
                            .map_err(|_| format!("line {}: {q}={v:?} is not a number", i + 1))?,
                    ))
                }
                _ => {
                    return Err(format!(
                        "tests/vcan/cases line {}: unknown expectation {word:?}",
                        i + 1
                    ))
                }
            }
        }
        cases.push(Case {
            number: cases.len() + 1,
            name: fields[0].to_string(),
            scenario: configs.join(fields[1]),
            machines: configs.join("configs/machines"),
            args: fields[2].split_whitespace().map(String::from).collect(),
            expect,
        });
    }
    Ok(cases)
}

/// Collects failures instead of stopping at the first.
#[derive(Default)]
struct Report {
    failures: Vec<String>,
    checks: usize,
}

impl Report {
    fn check(&mut self, ok: bool, what: impl FnOnce() -> String) {
        self.checks += 1;
        if !ok {
            self.failures.push(what());
        }
    }
    fn fail(&mut self, what: String) {
        self.checks += 1;
        self.failures.push(what);
    }
}

fn read(path: &Path) -> Result<String, String> {
    std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))
}

fn read_json(path: &Path) -> Result<Value, String> {
    serde_json::from_str(&read(path)?).map_err(|e| format!("{}: {e}", path.display()))
}

fn tail(path: &Path, lines: usize) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let all: Vec<&str> = text.lines().collect();
    all[all.len().saturating_sub(lines)..].join("\n    ")
}

/// The lines of a case's stderr that say what became of its estimator process (a
/// result computed in-process instead says why).
fn estimator_lines(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let lines: Vec<&str> = text
        .lines()
        .filter(|l| l.starts_with("estimator:"))
        .collect();
    if lines.is_empty() {
        "(none)".into()
    } else {
        lines.join("\n    ")
    }
}

/// The results folders of the VM and of the host reference: a text naming a file of
/// the case (a preset table or kinematics file in RESULTS/NAME.state/) is compared
/// relative to its folder.
struct Folders<'a> {
    got: &'a str,
    want: &'a str,
}

impl Folders<'_> {
    fn same_text(&self, got: &str, want: &str) -> bool {
        got.replace(self.got, "RESULTS") == want.replace(self.want, "RESULTS")
    }
}

/// A cycle's machine time is the machine's own clock: on vcan0 the real-time SYNCs of
/// the VM (a longer period, late on an emulated CPU), on the reference the in-process
/// bus's virtual clock. Both must have it; the VM's may be longer, never shorter.
fn machine_time(path: &str, got: Option<&Value>, want: Option<&Value>, out: &mut Vec<String>) {
    match (got, want) {
        (Some(g), Some(w)) => {
            if let (Some(a), Some(b)) = (g.as_f64(), w.as_f64()) {
                if a < 0.95 * b {
                    out.push(format!(
                        "{path} = {a} s, shorter than the virtual clock's {b} s"
                    ));
                }
            }
        }
        (None, Some(_)) => out.push(format!("{path} missing (reference has it)")),
        (Some(_), None) => out.push(format!("{path} is not in the reference")),
        (None, None) => {}
    }
}

/// Every number of `got` equals `want` to [`TOL`], every text is the same but for the
/// results folder; keys that depend on the clock or the folder (`trigger_ns`,
/// `protocols`, the clock-based `run_id`s of the estimator's sample sets) are not
/// compared, the machine time as [`machine_time`] says.
fn compare_json(path: &str, got: &Value, want: &Value, dirs: &Folders, out: &mut Vec<String>) {
    match (got, want) {
        (Value::Object(g), Value::Object(w)) => {
            let keys: BTreeSet<&String> = g.keys().chain(w.keys()).collect();
            for k in keys {
                if matches!(
                    k.as_str(),
                    "trigger_ns" | "protocols" | "run_id" | "run_ids"
                ) {
                    continue;
                }
                if matches!(k.as_str(), "machine_time_s" | "machine_time_split_s") {
                    machine_time(&format!("{path}/{k}"), g.get(k), w.get(k), out);
                    continue;
                }
                match (g.get(k), w.get(k)) {
                    (Some(a), Some(b)) => compare_json(&format!("{path}/{k}"), a, b, dirs, out),
                    (None, _) => out.push(format!("{path}/{k} missing (reference has it)")),
                    (_, None) => out.push(format!("{path}/{k} is not in the reference")),
                }
            }
        }
        (Value::Array(g), Value::Array(w)) => {
            if g.len() != w.len() {
                out.push(format!(
                    "{path}: {} entries, reference {}",
                    g.len(),
                    w.len()
                ));
            }
            for (i, (a, b)) in g.iter().zip(w).enumerate() {
                compare_json(&format!("{path}/{i}"), a, b, dirs, out);
            }
        }
        (Value::Number(a), Value::Number(b)) => {
            let (a, b) = (
                a.as_f64().unwrap_or(f64::NAN),
                b.as_f64().unwrap_or(f64::NAN),
            );
            // NaN on either side is a difference too.
            let same = (a - b).abs() <= TOL;
            if !same {
                out.push(format!("{path} = {a} but the reference says {b}"));
            }
        }
        (Value::String(a), Value::String(b)) if dirs.same_text(a, b) => {}
        (a, b) if a == b => {}
        (a, b) => out.push(format!("{path} = {a} but the reference says {b}")),
    }
}

fn vec3_arg(args: &[String], option: &str) -> Option<[f64; 3]> {
    let i = args.iter().position(|a| a == option)?;
    let v: Vec<f64> = args
        .get(i + 1)?
        .split(',')
        .map(|s| s.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .ok()?;
    (v.len() == 3).then(|| [v[0], v[1], v[2]])
}

/// Where the ball centre touches the scenario's only plane, probing from `start`
/// along `dir`: distance R from the plane along the line.
fn probe_truth(sc: &Scenario, start: [f64; 3], dir: [f64; 3]) -> Result<[f64; 3], String> {
    if sc.planes.len() != 1 || !sc.spheres.is_empty() || !sc.cylinders.is_empty() {
        return Err("truth=probe needs a scenario with exactly one plane and nothing else".into());
    }
    if sc.probe.pretravel != 0.0 || sc.probe.noise != 0.0 {
        return Err("truth=probe needs pretravel = 0 and noise = 0".into());
    }
    let p = &sc.planes[0];
    let n = [p.normal.x, p.normal.y, p.normal.z];
    let q = [p.point.x, p.point.y, p.point.z];
    let len = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
    let d = dir.map(|v| v / len);
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let nd = dot(n, d);
    if nd.abs() < 1e-9 {
        return Err("the probing direction is parallel to the plane".into());
    }
    let rel = [start[0] - q[0], start[1] - q[1], start[2] - q[2]];
    let t = (sc.probe.ball_radius - dot(n, rel)) / nd;
    Ok([
        start[0] + t * d[0],
        start[1] + t * d[1],
        start[2] + t * d[2],
    ])
}

/// The lines of an NC program that matter when comparing a VM copy with its original:
/// without the program name, `;` comment lines and the Q253 (pre-positioning feed).
fn program_core(text: &str) -> Vec<String> {
    text.lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with(';'))
        .filter(|l| !l.contains(" PGM ") && !l.starts_with("Q253="))
        .map(String::from)
        .collect()
}

fn check_derived(case: &Case, root: &Path, r: &mut Report) {
    let Some(original) = &case.expect.derived else {
        return;
    };
    let name = &case.name;
    let Some(program) = case.args.iter().find(|a| a.ends_with(".h")) else {
        return r.fail(format!("{name}: derived= needs a program in ARGS"));
    };
    match (read(&root.join(program)), read(&root.join(original))) {
        (Ok(a), Ok(b)) => {
            let (a, b) = (program_core(&a), program_core(&b));
            let diff = a.iter().zip(&b).position(|(x, y)| x != y);
            r.check(diff.is_none() && a.len() == b.len(), || {
                let i = diff.unwrap_or(a.len().min(b.len()));
                format!(
                    "{name}: {program} has drifted from {original} (beyond name, comments and Q253): {:?} vs {:?}",
                    a.get(i),
                    b.get(i)
                )
            });
        }
        (a, b) => r.fail(format!(
            "{name}: {}",
            a.err().or(b.err()).unwrap_or_default()
        )),
    }
}

/// A second run in a row (again=FIRST): on the machine state the first run left.
fn check_again(case: &Case, results: &Path, r: &mut Report) {
    if let Some(first) = &case.expect.again {
        let state = results.join(format!("{first}.state"));
        r.check(state.is_dir(), || {
            format!(
                "{}: again={first}: no machine state {} to run on",
                case.name,
                state.display()
            )
        });
    }
}

fn check_case(case: &Case, results: &Path, reference: &Path, r: &mut Report) {
    let name = &case.name;
    let exit_file = results.join(format!("{name}.exit"));
    let Ok(exit) = read(&exit_file) else {
        r.fail(format!("{name}: did not run (no {})", exit_file.display()));
        return;
    };
    let exit: i32 = exit.trim().parse().unwrap_or(-1);
    r.check(exit == case.expect.exit, || {
        format!(
            "{name}: exit status {exit}, expected {}; its stderr ends with:\n    {}",
            case.expect.exit,
            tail(&results.join(format!("{name}.stderr")), 8)
        )
    });
    check_again(case, results, r);
    if !case.moves() {
        return; // `check`: the exit status is all it has
    }
    let got = match read_json(&results.join(format!("{name}.json"))) {
        Ok(v) => v,
        Err(e) => {
            r.fail(format!("{name}: no result JSON from the VM: {e}"));
            return;
        }
    };
    match read_json(&reference.join(format!("{name}.json"))) {
        Ok(want) => {
            let mut diffs = Vec::new();
            let (got_dir, want_dir) = (
                results.display().to_string(),
                reference.display().to_string(),
            );
            let dirs = Folders {
                got: &got_dir,
                want: &want_dir,
            };
            compare_json("", &got, &want, &dirs, &mut diffs);
            r.check(diffs.is_empty(), || {
                format!(
                    "{name}: on vcan0 the result differs from the in-process bus:\n    {}\n  \
                     its stderr on the estimator:\n    {}",
                    diffs.join("\n    "),
                    estimator_lines(&results.join(format!("{name}.stderr")))
                )
            });
        }
        Err(e) => r.fail(format!("{name}: no host reference: {e}")),
    }
    let sc = match Scenario::load(&case.scenario, Some(&case.machines)) {
        Ok(sc) => sc,
        Err(e) => {
            r.fail(format!("{name}: {e}"));
            return;
        }
    };
    if case.expect.truth_probe {
        let (Some(start), Some(dir)) = (
            vec3_arg(&case.args, "--start"),
            vec3_arg(&case.args, "--dir"),
        ) else {
            r.fail(format!("{name}: truth=probe needs --start and --dir"));
            return;
        };
        match probe_truth(&sc, start, dir) {
            Ok(want) => {
                for (i, axis) in ["X", "Y", "Z"].iter().enumerate() {
                    let v = got["contact"][axis].as_f64().unwrap_or(f64::NAN);
                    r.check((v - want[i]).abs() <= TOL, || {
                        format!(
                            "{name}: contact {axis} = {v:.9}, the scenario's truth is {:.9} (plane and R = {})",
                            want[i], sc.probe.ball_radius
                        )
                    });
                }
            }
            Err(e) => r.fail(format!("{name}: {e}")),
        }
    }
    let cycles = got["cycles"].as_array().cloned().unwrap_or_default();
    if case.args.first().is_some_and(|a| a == "run") {
        r.check(!cycles.is_empty(), || format!("{name}: no cycle results"));
        r.check(got.get("stopped").is_none_or(Value::is_null), || {
            format!("{name}: the program stopped: {}", got["stopped"])
        });
    }
    for c in &cycles {
        let block = &c["block"];
        let q = |k: &str| c["q"][k].as_f64().unwrap_or(f64::NAN);
        r.check(c["status"] == "ok", || {
            format!(
                "{name}: block {block}: status {} ({})",
                c["status"], c["message"]
            )
        });
        for (k, want) in &case.expect.q {
            let v = q(k);
            let tol = case.expect.tol;
            r.check((v - want).abs() <= tol, || {
                format!("{name}: block {block}: {k} = {v}, expected {want} (tolerance {tol:e})")
            });
        }
        if case.expect.truth_431 && c["cycle"] == 431 {
            if sc.planes.len() != 1 {
                r.fail(format!("{name}: truth=431 needs exactly one plane"));
                continue;
            }
            let n = &sc.planes[0].normal;
            for (k, want) in [
                ("Q158", (-n.y).atan2(n.z).to_degrees()),
                ("Q159", n.x.atan2(n.z).to_degrees()),
            ] {
                let v = q(k);
                r.check((v - want).abs() <= TOL, || {
                    format!("{name}: block {block}: {k} = {v}, the plane's true angle is {want}")
                });
            }
        }
    }
}

fn check_conformance(results: &Path, r: &mut Report) {
    let log = results.join("conformance.log");
    let exit = read(&results.join("conformance.exit")).unwrap_or_default();
    let text = read(&log).unwrap_or_default();
    let passed = text
        .lines()
        .filter_map(|l| l.strip_prefix("test result: ok. "))
        .filter_map(|l| l.split_whitespace().next()?.parse::<usize>().ok())
        .sum::<usize>();
    r.check(exit.trim() == "0", || {
        format!(
            "conformance suite on SocketCAN: exit status {:?}; its log ends with:\n    {}",
            exit.trim(),
            tail(&log, 30)
        )
    });
    r.check(!text.contains("SKIPPED"), || {
        "conformance suite on SocketCAN was skipped in the VM (PROBEBRIDGE_TEST_CAN not seen)"
            .into()
    });
    r.check(passed >= CONFORMANCE_TESTS, || {
        format!(
            "conformance suite on SocketCAN: {passed} tests passed, expected {CONFORMANCE_TESTS}"
        )
    });
}

/// A program of the VM step that prints `CHECK <name>: <observed> -> ok|FAIL` lines.
fn check_program(results: &Path, stem: &str, checks: &[&str], r: &mut Report) {
    let log = results.join(format!("{stem}.log"));
    let exit = read(&results.join(format!("{stem}.exit"))).unwrap_or_default();
    let text = read(&log).unwrap_or_default();
    println!("{stem}:");
    for l in text.lines().filter(|l| l.starts_with("CHECK ")) {
        println!("  {l}");
    }
    r.check(exit.trim() == "0", || {
        format!(
            "{stem}: exit status {:?}; its log ends with:\n    {}",
            exit.trim(),
            tail(&log, 30)
        )
    });
    for name in checks {
        let line = text
            .lines()
            .find(|l| l.strip_prefix("CHECK ").and_then(|l| l.split(':').next()) == Some(name));
        r.check(line.is_some_and(|l| l.ends_with("-> ok")), || match line {
            Some(l) => format!("{stem}: {l}"),
            None => format!("{stem}: check {name} did not run"),
        });
    }
}

/// Sent by the master whose node ID is `master` (its heartbeat included).
fn is_master_frame(f: &CanFrame, master: u8) -> bool {
    sent_by_master(f.cob_id(), Some(master))
}

fn is_drive_frame(f: &CanFrame, master: u8) -> bool {
    match classify(f.cob_id()) {
        CobKind::Emcy { .. } | CobKind::Tpdo { .. } | CobKind::SdoResponse { .. } => true,
        CobKind::Heartbeat { node } => node != master,
        _ => false,
    }
}

/// (node, index, sub) -> value of every expedited SDO download in `frames`.
fn sdo_downloads(frames: &[CanFrame]) -> BTreeMap<(u8, u16, u8), u32> {
    let mut out = BTreeMap::new();
    for f in frames {
        if let CobKind::SdoRequest { node } = classify(f.cob_id()) {
            let d = f.data();
            // Initiate download, expedited, size indicated: 001n 11 11 -> 0x23/27/2B/2F.
            if d.len() == 8 && d[0] & 0xE3 == 0x23 {
                let n = 4 - ((d[0] >> 2) & 0b11) as usize;
                let mut v = [0u8; 4];
                v[..n].copy_from_slice(&d[4..4 + n]);
                out.insert(
                    (node, u16::from_le_bytes([d[1], d[2]]), d[3]),
                    u32::from_le_bytes(v),
                );
            }
        }
    }
    out
}

/// One case's part of the candump log.
fn check_segment(case: &Case, frames: &[CanFrame], results: &Path, r: &mut Report) {
    let name = &case.name;
    let sc = match Scenario::load(&case.scenario, Some(&case.machines)) {
        Ok(sc) => sc,
        Err(e) => return r.fail(format!("{name}: {e}")),
    };
    let cfg = &sc.machine;
    let nodes: Vec<u8> = cfg.axes.iter().map(|a| a.canopen_node()).collect();
    let Some(bus) = cfg.canopen_bus() else {
        return r.fail(format!("{name}: the machine is not on CANopen"));
    };
    if frames.is_empty() {
        return r.fail(format!("candump {name}: no frames recorded for this case"));
    }

    check_startup(name, frames, &nodes, bus, r);
    check_latches(case, cfg, frames, results, r);
    check_replay(name, &sc, frames, r);
}

/// Start-up: NMT reset communication to all, every boot-up, the SDO configuration
/// (cycle period, heartbeat producer and consumer, mode, the PDO layout), NMT start,
/// then SYNC.
fn check_startup(
    name: &str,
    frames: &[CanFrame],
    nodes: &[u8],
    bus: &CanOpenBusConfig,
    r: &mut Report,
) {
    // Power-on: the simulator's boot-ups. Start-up: NMT reset communication to all,
    // every boot-up, SDO configuration, NMT start, then SYNC.
    let first = frames
        .iter()
        .find(|f| !(matches!(classify(f.cob_id()), CobKind::Heartbeat { .. }) && f.data() == [0]))
        .unwrap_or(&frames[0]);
    r.check(first.cob_id() == 0 && first.data() == [0x82, 0], || {
        format!(
            "candump {name}: the first frame after the power-on boot-ups is {:03X}#{:02X?}, expected the NMT reset 000#8200",
            first.cob_id(),
            first.data()
        )
    });
    let first_sdo = frames
        .iter()
        .position(|f| matches!(classify(f.cob_id()), CobKind::SdoRequest { .. }))
        .unwrap_or(frames.len());
    let booted: BTreeSet<u8> = frames[..first_sdo]
        .iter()
        .filter_map(|f| match classify(f.cob_id()) {
            CobKind::Heartbeat { node } if f.data() == [0] => Some(node),
            _ => None,
        })
        .collect();
    for n in nodes {
        r.check(booted.contains(n), || {
            format!(
                "candump {name}: no boot-up {:03X}#00 of node {n} before the first SDO",
                0x700 + u16::from(*n)
            )
        });
    }
    let start = frames
        .iter()
        .position(|f| f.cob_id() == 0 && f.data() == [0x01, 0]);
    let first_sync = frames
        .iter()
        .position(|f| classify(f.cob_id()) == CobKind::Sync);
    let last_sdo = frames
        .iter()
        .rposition(|f| matches!(classify(f.cob_id()), CobKind::SdoRequest { .. }));
    match (start, first_sync, last_sdo) {
        (Some(s), Some(y), Some(l)) => r.check(l < s && s < y, || {
            format!("candump {name}: NMT start (frame {s}) must come after the last SDO ({l}) and before the first SYNC ({y})")
        }),
        _ => r.fail(format!(
            "candump {name}: missing NMT start ({start:?}), SYNC ({first_sync:?}) or SDO ({last_sdo:?})"
        )),
    }
    let aborts = frames
        .iter()
        .filter(|f| matches!(classify(f.cob_id()), CobKind::SdoResponse { .. }))
        .filter(|f| f.data().first() == Some(&0x80))
        .count();
    r.check(aborts == 0, || {
        format!("candump {name}: {aborts} SDO abort(s) during start-up")
    });
    let writes = sdo_downloads(&frames[..start.unwrap_or(frames.len())]);
    let entry = |e: &hal::canopen::MapEntry| {
        (u32::from(e.index) << 16) | (u32::from(e.sub) << 8) | u32::from(e.bits)
    };
    for n in nodes {
        let mut want: Vec<((u16, u8), u32)> = vec![
            ((object::COMMUNICATION_CYCLE_PERIOD, 0), bus.sync_period_us),
            (
                (object::PRODUCER_HEARTBEAT_TIME, 0),
                u32::from(bus.heartbeat_producer_ms),
            ),
            ((object::MODES_OF_OPERATION, 0), 8),
        ];
        // The drives consume the master's heartbeat (node << 16 | 3 x its period).
        if bus.master_heartbeat_consumer_entry() != 0 {
            want.push((
                (object::CONSUMER_HEARTBEAT_TIME, 1),
                bus.master_heartbeat_consumer_entry(),
            ));
        }
        for l in &process_data::LAYOUT {
            let Ok(index) = mapping_index(l.direction, l.number) else {
                continue;
            };
            want.push(((index, 0), l.mapping.len() as u32));
            for (i, e) in l.mapping.iter().enumerate() {
                want.push(((index, i as u8 + 1), entry(e)));
            }
        }
        for ((index, sub), value) in want {
            let got = writes.get(&(*n, index, sub));
            r.check(got == Some(&value), || {
                format!(
                    "candump {name}: node {n}: SDO write {index:04X}:{sub:02X} = {got:08X?}, expected {value:08X}"
                )
            });
        }
    }
}

/// The TPDO2 latch frames of every node; for `probe`, the latched values are the
/// reported contact.
fn check_latches(
    case: &Case,
    cfg: &MachineConfig,
    frames: &[CanFrame],
    results: &Path,
    r: &mut Report,
) {
    let name = &case.name;
    let nodes: Vec<u8> = cfg.axes.iter().map(|a| a.canopen_node()).collect();
    // Touch-probe latch frames (TPDO2: status 0x60B9 + latched 0x60BA).
    let mut latches: BTreeMap<u8, Vec<i32>> = BTreeMap::new();
    for f in frames {
        if let CobKind::Tpdo {
            num: Tpdo2::NUMBER,
            node,
        } = classify(f.cob_id())
        {
            if let Ok(v) = Tpdo2::decode(f) {
                if v.touch_probe_status & TouchProbeStatus::POSITIVE_EDGE_STORED != 0 {
                    latches
                        .entry(node)
                        .or_default()
                        .push(v.probe1_positive_edge);
                }
            }
        }
    }
    for n in &nodes {
        r.check(latches.get(n).is_some_and(|l| !l.is_empty()), || {
            format!("candump {name}: no TPDO2 latch frame (edge stored) from node {n}")
        });
    }
    if case.args.first().is_some_and(|a| a == "probe") {
        // The one contact: the latched values on the bus are the reported contact.
        if let Ok(json) = read_json(&results.join(format!("{name}.json"))) {
            for a in &cfg.axes {
                let reported = json["contact"][a.name.name()].as_f64().unwrap_or(f64::NAN);
                let on_bus = latches
                    .get(&a.canopen_node())
                    .and_then(|l| l.last())
                    .map(|v| *v as f64 / a.increments_per_unit);
                r.check(
                    on_bus.is_some_and(|b| (b - reported).abs() <= 1.0 / a.increments_per_unit + 1e-12),
                    || format!("candump {name}: axis {} latched {on_bus:?} on the bus, the contact says {reported}", a.name),
                );
            }
        }
    }
}

/// Replay: the master's frames into a fresh simulator of the case's scenario give
/// exactly the drive frames that were recorded.
fn check_replay(name: &str, sc: &Scenario, frames: &[CanFrame], r: &mut Report) {
    // Replay: the master's frames into a fresh simulator, powered on and with its
    // timers polled after every frame as `probebridge sim` does, give the recorded
    // answers. Heartbeats (not boot-ups) run on the wall clock: left out on both sides.
    let master = sc.machine.canopen_bus().map_or(0, |b| b.master_node);
    let mut sim = SimMachine::new(sc);
    sim.set_clock(SimClock::Monotonic);
    let mut replayed = Vec::new();
    sim.power_on(&mut |a| replayed.push(*a));
    for f in frames.iter().filter(|f| is_master_frame(f, master)) {
        sim.on_frame(f, &mut |a| replayed.push(*a));
        sim.poll(&mut |a| replayed.push(*a));
    }
    let timed =
        |f: &CanFrame| matches!(classify(f.cob_id()), CobKind::Heartbeat { .. }) && f.data() != [0];
    replayed.retain(|f| !timed(f));
    let recorded: Vec<CanFrame> = frames
        .iter()
        .filter(|f| is_drive_frame(f, master) && !timed(f))
        .copied()
        .collect();
    // Each drive's own answers, all of them and in its own order. Which drive's frame
    // comes first within one SYNC cycle depends on when the emulated CPU polls the
    // simulator's timers (seen once in a run of 1888 checks: a TPDO1 of one drive
    // ahead of another's), not on the protocol; the totals must match too.
    let per_node = |v: &[CanFrame]| {
        let mut m: BTreeMap<u16, Vec<CanFrame>> = BTreeMap::new();
        for f in v {
            m.entry(f.cob_id() & 0x7F).or_default().push(*f);
        }
        m
    };
    r.check(recorded.len() == replayed.len(), || {
        format!(
            "candump {name}: replaying the {} recorded master frames into the simulator gives {} drive frames, {} were recorded",
            frames.iter().filter(|f| is_master_frame(f, master)).count(),
            replayed.len(),
            recorded.len()
        )
    });
    let (rec, rep) = (per_node(&recorded), per_node(&replayed));
    let nodes: BTreeSet<u16> = rec.keys().chain(rep.keys()).copied().collect();
    for node in nodes {
        let a = rec.get(&node).map_or(&[][..], Vec::as_slice);
        let b = rep.get(&node).map_or(&[][..], Vec::as_slice);
        let first_diff = a
            .iter()
            .zip(b)
            .position(|(x, y)| x != y)
            .or((a.len() != b.len()).then_some(a.len().min(b.len())));
        r.check(first_diff.is_none(), || {
            let i = first_diff.unwrap_or(0);
            let show = |v: &[CanFrame]| {
                v.iter()
                    .skip(i)
                    .take(3)
                    .map(|f| hal::can::candump::format_line(0, "-", f))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            format!(
                "candump {name}: node {node}: the replay gives {} of its frames, {} were recorded; first difference at its frame {i}: recorded [{}], replayed [{}]",
                b.len(),
                a.len(),
                show(a),
                show(b)
            )
        });
    }
}

fn check_candump(cases: &[Case], results: &Path, r: &mut Report) {
    let path = results.join("candump.log");
    let text = match read(&path) {
        Ok(t) => t,
        Err(e) => return r.fail(format!("candump: {e}")),
    };
    let log = match parse_log(&text) {
        Ok(l) => l,
        Err(e) => return r.fail(format!("candump: {}: {e}", path.display())),
    };
    r.check(log.iter().all(|(_, iface, _)| iface == "vcan0"), || {
        "candump: frames from an interface other than vcan0".into()
    });
    // (Timestamps are not checked: the kernel stamps frames per CPU, and timings in
    // the emulated VM mean nothing.)
    // Split at the markers.
    let mut segments: BTreeMap<u8, Vec<CanFrame>> = BTreeMap::new();
    let mut current: Option<u8> = None;
    for (_, _, f) in &log {
        if f.cob_id() == MARKER && f.data().len() == 1 {
            current = Some(f.data()[0]);
            segments.entry(f.data()[0]).or_default();
            continue;
        }
        if let Some(c) = current {
            segments.entry(c).or_default().push(*f);
        }
    }
    for case in cases.iter().filter(|c| c.moves() && !c.expect.host_only) {
        match segments.get(&(case.number as u8)) {
            Some(frames) => check_segment(case, frames, results, r),
            None => r.fail(format!(
                "candump: no marker 7FF#{:02X} for case {}",
                case.number, case.name
            )),
        }
    }
    for (marker, what) in [
        (PYTHON_MASTER_MARKER, "the python-canopen master"),
        (FOREIGN_DEVICE_MARKER, "the foreign device"),
    ] {
        r.check(segments.get(&marker).is_some_and(|f| f.len() > 100), || {
            format!(
                "candump: no marker 7FF#{marker:02X} (or almost no traffic after it) before {what}"
            )
        });
    }
    match segments.get(&CONFORMANCE_MARKER) {
        Some(frames) => {
            let sessions = frames
                .iter()
                .filter(|f| f.cob_id() == 0 && f.data() == [0x82, 0])
                .count();
            r.check(sessions >= CONFORMANCE_TESTS, || {
                format!("candump conformance: {sessions} NMT resets (machine start-ups), expected at least {CONFORMANCE_TESTS}")
            });
        }
        None => r.fail("candump: no marker 7FF#FF before the conformance suite".into()),
    }
    println!(
        "candump: {} frames parsed, {} case segments",
        log.len(),
        segments.len()
    );
}

/// Marker bytes of the signal runs of in-vm.sh (`signal_mid_451`): started, signal
/// sent, process exited.
const KILL_MARKERS: [u8; 3] = [0xFC, 0xFB, 0xFA];
const TERM_MARKERS: [u8; 3] = [0xF9, 0xF8, 0xF7];
/// Slack on the drives' 0x1016 time in the emulated VM: the drives' host looks at the
/// time at least every 50 ms (early by up to that), and the emulated CPUs stall (late).
const VM_EARLY_MS: f64 = 100.0;
const VM_LATE_MS: f64 = 1500.0;

type Log = [(u64, String, CanFrame)];

/// Index of the first marker frame 7FF#`byte`.
fn marker_at(log: &Log, byte: u8) -> Option<usize> {
    log.iter()
        .position(|(_, _, f)| f.cob_id() == MARKER && f.data() == [byte])
}

/// The signal runs: a SIGKILLed master noticed by the drives, a SIGTERMed one
/// disabling them before it exits.
fn check_signals(results: &Path, configs: &Path, r: &mut Report) {
    let sc = match Scenario::load(
        &configs.join("configs/scenarios/demo-sphere.toml"),
        Some(&configs.join("configs/machines")),
    ) {
        Ok(sc) => sc,
        Err(e) => return r.fail(format!("signals: {e}")),
    };
    let Some(bus) = sc.machine.canopen_bus() else {
        return r.fail("signals: demo-sphere's machine is not on CANopen".into());
    };
    // The axes' drives and the spindle's: each watches the master and is shut down.
    let nodes: Vec<u8> = sc
        .machine
        .axes
        .iter()
        .map(|a| a.canopen_node())
        .chain(sc.machine.spindle.as_ref().map(|s| s.node))
        .collect();
    let log = match read(&results.join("candump.log"))
        .and_then(|t| parse_log(&t).map_err(|e| format!("candump: {e}")))
    {
        Ok(l) => l,
        Err(e) => return r.fail(format!("signals: {e}")),
    };
    check_killed(results, &log, &nodes, bus, r);
    check_sigterm(results, &log, &nodes, r);
}

fn exit_status(results: &Path, name: &str) -> String {
    read(&results.join(format!("{name}.exit")))
        .map(|s| s.trim().to_string())
        .unwrap_or_else(|e| e)
}

/// SIGKILL mid-451: the master left the drives enabled; every drive sends EMCY 8130
/// after its 0x1016 time without the master's heartbeat, logs it, and answers a
/// statusword out of Operation enabled.
fn check_killed(results: &Path, log: &Log, nodes: &[u8], bus: &CanOpenBusConfig, r: &mut Report) {
    let exit = exit_status(results, "kill");
    r.check(exit == "137", || {
        format!("kill: exit status {exit}, expected 137 (SIGKILL)")
    });
    let [start, sent, exited] = KILL_MARKERS.map(|m| marker_at(log, m));
    let (Some(start), Some(sent), Some(exited)) = (start, sent, exited) else {
        return r.fail("kill: no markers 7FF#FC / FB / FA in the candump log".into());
    };
    let end = marker_at(log, TERM_MARKERS[0]).unwrap_or(log.len());
    let (before, after) = (&log[start..sent], &log[sent..end]);
    let master = bus.master_node;
    let consumer_ms = f64::from(bus.master_heartbeat_consumer_ms());
    // (Up to the exit marker: a frame the dying process sent may follow the marker of
    // the signal, which cansend puts on the bus after kill.)
    let last_heartbeat = log[start..exited]
        .iter()
        .rev()
        .find(|(_, _, f)| f.cob_id() == 0x700 + u16::from(master))
        .map(|(t, _, _)| *t);
    let Some(last_heartbeat) = last_heartbeat else {
        return r.fail(format!(
            "kill: no heartbeat of the master (node {master}) before the kill"
        ));
    };
    let strays = log[exited..end]
        .iter()
        .filter(|(_, _, f)| {
            is_master_frame(f, master)
                && f.cob_id() != MARKER
                && !matches!(classify(f.cob_id()), CobKind::SdoRequest { .. })
        })
        .count();
    r.check(strays == 0, || {
        format!("kill: {strays} master frame(s) after the killed process exited")
    });
    let sim_log = read(&results.join("kill.sim.log")).unwrap_or_default();
    for n in nodes {
        let tpdo1 = before.iter().rev().find_map(|(_, _, f)| {
            (f.cob_id() == process_data::Tpdo1::cob_id(*n))
                .then(|| process_data::Tpdo1::decode(f).ok())
                .flatten()
        });
        let cw = before.iter().rev().find_map(|(_, _, f)| {
            (f.cob_id() == process_data::Rpdo1::cob_id(*n))
                .then(|| process_data::Rpdo1::decode(f).ok())
                .flatten()
        });
        r.check(
            tpdo1.is_some_and(|p| p.statusword & 0x6F == 0x27)
                && cw.is_some_and(|p| p.controlword == 0x000F),
            || format!("kill: node {n} was not in Operation enabled when the master was killed: last TPDO1 {tpdo1:?}, RPDO1 {cw:?}"),
        );
        let emcy = after.iter().find(|(_, _, f)| {
            f.cob_id() == 0x80 + u16::from(*n) && f.data().get(..2) == Some(&[0x30, 0x81])
        });
        let Some((t, _, f)) = emcy else {
            r.fail(format!(
                "kill: node {n}: no EMCY 8130 after the master was killed"
            ));
            continue;
        };
        let delay_ms = t.saturating_sub(last_heartbeat) as f64 / 1e6;
        println!(
            "kill: node {n}: {} {delay_ms:.1} ms after the master's last heartbeat (0x1016 time {consumer_ms} ms)",
            hal::can::candump::format_line(*t, "vcan0", f)
        );
        r.check(
            delay_ms >= consumer_ms - VM_EARLY_MS && delay_ms <= consumer_ms + VM_LATE_MS,
            || format!("kill: node {n}: EMCY 8130 {delay_ms:.1} ms after the master's last heartbeat, outside the 0x1016 time {consumer_ms} ms (-{VM_EARLY_MS}/+{VM_LATE_MS} ms in the VM)"),
        );
        let answer = after.iter().rev().find(|(t2, _, f)| {
            t2 > t
                && f.cob_id() == 0x580 + u16::from(*n)
                && f.data().get(..4) == Some(&[0x4B, 0x41, 0x60, 0])
        });
        match answer {
            Some((ta, _, f)) => {
                let sw = u16::from_le_bytes([f.data()[4], f.data()[5]]);
                println!(
                    "kill: node {n}: {} statusword 0x{sw:04X}",
                    hal::can::candump::format_line(*ta, "vcan0", f)
                );
                r.check([0x40, 0x07].contains(&(sw & 0x6F)), || {
                    format!("kill: node {n}: statusword 0x{sw:04X} after the loss, expected Switch on disabled or Quick stop active")
                });
            }
            None => r.fail(format!(
                "kill: node {n}: no answer to the 0x6041 upload after the EMCY"
            )),
        }
        let line = sim_log
            .lines()
            .find(|l| l.contains(&format!("node {n}: heartbeat of node {master} lost")));
        match line {
            Some(l) => println!("kill: {l}"),
            None => r.fail(format!(
                "kill: kill.sim.log has no loss of node {master}'s heartbeat for node {n}"
            )),
        }
    }
}

/// SIGTERM mid-451: exit 143, "aborted" in the JSON, and on the bus, before the
/// process exited, every drive's last controlword Shutdown (0x0006) or a quick stop,
/// then the goodbye (NMT reset communication).
fn check_sigterm(results: &Path, log: &Log, nodes: &[u8], r: &mut Report) {
    let exit = exit_status(results, "sigterm");
    r.check(exit == "143", || {
        format!("sigterm: exit status {exit}, expected 143 (128 + SIGTERM)")
    });
    match read_json(&results.join("sigterm.json")) {
        Ok(v) => {
            let c451 = v["cycles"]
                .as_array()
                .and_then(|c| c.iter().find(|c| c["cycle"] == 451));
            r.check(
                v["aborted"] == true && c451.is_some_and(|c| c["status"] == "aborted"),
                || format!("sigterm: the JSON does not say aborted: aborted = {}, cycle 451 = {c451:?}", v["aborted"]),
            );
        }
        Err(e) => r.fail(format!("sigterm: {e}")),
    }
    let [start, _, exited] = TERM_MARKERS.map(|m| marker_at(log, m));
    let (Some(start), Some(exited)) = (start, exited) else {
        return r.fail("sigterm: no markers 7FF#F9 / F8 / F7 in the candump log".into());
    };
    let exit_t = log[exited].0;
    for n in nodes {
        let last = log[start..exited].iter().rev().find_map(|(t, _, f)| {
            (f.cob_id() == process_data::Rpdo1::cob_id(*n))
                .then(|| {
                    process_data::Rpdo1::decode(f)
                        .ok()
                        .map(|p| (*t, p.controlword))
                })
                .flatten()
        });
        let Some((t, cw)) = last else {
            r.fail(format!("sigterm: node {n}: no RPDO1 in the run"));
            continue;
        };
        // Shutdown 0x0006, or quick stop (bit 1 set, bit 2 clear).
        let disabled = cw & 0x0087 == 0x0006 || cw & 0x0086 == 0x0002;
        println!(
            "sigterm: node {n}: last controlword 0x{cw:04X}, {:.1} ms before the process exited",
            exit_t.saturating_sub(t) as f64 / 1e6
        );
        r.check(disabled, || {
            format!("sigterm: node {n}: the last controlword before the exit is 0x{cw:04X} (Shutdown or quick stop expected)")
        });
        // (The marker of the signal may reach the bus after the master's first
        // frames of the shutdown: cansend starts after kill.)
        let goodbye = log[start..exited]
            .iter()
            .any(|(_, _, f)| f.cob_id() == 0 && f.data() == [0x82, *n]);
        r.check(goodbye, || {
            format!("sigterm: node {n}: no NMT reset communication (the goodbye) before the exit")
        });
    }
}

const USAGE: &str = "usage: vcan-check --results DIR --reference DIR [--root DIR] [--configs DIR]
  --configs DIR: the folder holding configs/scenarios and configs/machines the cases ran
                 with (PROBEBRIDGE_VCAN_CONFIGS of run-cases.sh); default: the repository";

fn main() -> ExitCode {
    let mut results = None;
    let mut reference = None;
    let mut root = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
    let mut configs = None;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--results" => results = args.next().map(PathBuf::from),
            "--reference" => reference = args.next().map(PathBuf::from),
            "--root" => root = args.next().map(PathBuf::from).unwrap_or(root),
            "--configs" => configs = args.next().map(PathBuf::from),
            _ => {
                eprintln!("{USAGE}");
                return ExitCode::from(2);
            }
        }
    }
    let (Some(results), Some(reference)) = (results, reference) else {
        eprintln!("{USAGE}");
        return ExitCode::from(2);
    };
    let configs = configs.unwrap_or_else(|| root.clone());
    let mut r = Report::default();

    let cases = match read(&root.join("tests/vcan/cases")).and_then(|t| parse_cases(&configs, &t)) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("vcan-check: {e}");
            return ExitCode::FAILURE;
        }
    };

    // Every program that exists is run (or checked) in the VM.
    if let Ok(dir) = std::fs::read_dir(root.join("configs/programs")) {
        let mut programs: Vec<String> = dir
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".h"))
            .collect();
        programs.sort();
        for p in programs {
            let arg = format!("configs/programs/{p}");
            let covers =
                |c: &Case| c.args.contains(&arg) || c.expect.derived.as_ref() == Some(&arg);
            r.check(cases.iter().any(covers), || {
                format!("{arg} has no case in tests/vcan/cases: add one (run, or check for cycles that cannot run yet)")
            });
            // Every shipped example runs, and runs a second time in a row on the
            // machine state the first run left (issue 28: it runs again and again).
            let runs = |again: bool| {
                cases.iter().any(|c| {
                    covers(c)
                        && c.args.first().map(String::as_str) == Some("run")
                        && c.expect.again.is_some() == again
                })
            };
            r.check(runs(false) && runs(true), || {
                format!("{arg}: tests/vcan/cases must run it (run) and run it again on that run's machine state (again=)")
            });
        }
    }

    if !results.join("vm.done").exists() {
        r.fail(format!(
            "the VM did not finish its script (no {}); vm.log ends with:\n    {}",
            results.join("vm.done").display(),
            tail(&results.join("vm.log"), 30)
        ));
    }
    for case in &cases {
        check_derived(case, &root, &mut r);
        if case.expect.host_only {
            // Not run in the VM: its expectations hold on the host reference.
            check_case(case, &reference, &reference, &mut r);
        } else {
            check_case(case, &results, &reference, &mut r);
        }
    }
    check_conformance(&results, &mut r);
    for (stem, checks) in CHECKED_PROGRAMS {
        check_program(&results, stem, checks, &mut r);
    }
    check_candump(&cases, &results, &mut r);
    check_signals(&results, &configs, &mut r);

    if r.failures.is_empty() {
        println!(
            "vcan-check: all {} checks passed ({} cases, conformance suite, python-canopen master, foreign device, candump replay, SIGKILL and SIGTERM mid-451)",
            r.checks,
            cases.len()
        );
        ExitCode::SUCCESS
    } else {
        eprintln!(
            "vcan-check: {} of {} checks FAILED:",
            r.failures.len(),
            r.checks
        );
        for f in &r.failures {
            eprintln!("  - {f}");
        }
        ExitCode::FAILURE
    }
}
