//! A stop signal during `run`: the move under way is braked through the master, the
//! cycle ends as "aborted" in the JSON, the drives are disabled on the bus (the last
//! controlword of every drive is Shutdown 0x0006) before the process exits, and the
//! exit status is 128 + signal.

#[allow(
    dead_code,
    reason = "each test binary uses a part of the shared helpers"
)]
mod common;
use common::{bin, configs, tmpdir};
use std::io::{BufRead, BufReader, Read};
use std::process::Stdio;

/// Starts `probebridge run 451-check.h` (virtual clock: a loaded test machine cannot
/// starve its heartbeats) with a candump log, waits on its
/// stderr for the first contact of cycle 451, sends `signals`, and returns the exit
/// status, everything it wrote on stderr, the JSON and the candump log.
fn run_451_and_signal(
    name: &str,
    signals: &[libc::c_int],
) -> (Option<i32>, String, String, String) {
    let dir = tmpdir(name);
    let json = dir.join("r.json");
    let log = dir.join("bus.log");
    let mut child = bin()
        .args([
            "run",
            configs().join("programs/451-check.h").to_str().unwrap(),
        ])
        .args([
            "--scenario",
            configs()
                .join("scenarios/demo-sphere.toml")
                .to_str()
                .unwrap(),
        ])
        .args(["--out", dir.to_str().unwrap()])
        .args(["--json", json.to_str().unwrap()])
        .args(["--candump", log.to_str().unwrap()])
        .args([
            "--service",
            &format!("pb-sig-{name}-{}", std::process::id()),
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start probebridge run");
    let mut stderr = BufReader::new(child.stderr.take().unwrap());
    let mut said = String::new();
    let mut line = String::new();
    let mut in_451 = false;
    loop {
        line.clear();
        if stderr.read_line(&mut line).unwrap() == 0 {
            panic!("run ended before the first contact of cycle 451:\n{said}");
        }
        said.push_str(&line);
        in_451 |= line.contains("cycle 451");
        if in_451 && line.contains("contact at") {
            break;
        }
    }
    let pid = libc::pid_t::try_from(child.id()).unwrap();
    for &signal in signals {
        // SAFETY: signalling our own child.
        assert_eq!(unsafe { libc::kill(pid, signal) }, 0);
    }
    stderr.read_to_string(&mut said).unwrap();
    let status = child.wait().unwrap();
    let json = std::fs::read_to_string(&json).unwrap_or_default();
    let log = std::fs::read_to_string(&log).unwrap_or_default();
    (status.code(), said, json, log)
}

/// The controlword of the last RPDO1 (COB-ID 0x200 + node) each node got, from a
/// candump log (`(t) iface ID#DATA`).
fn last_controlwords(log: &str) -> std::collections::BTreeMap<u16, u16> {
    let mut last = std::collections::BTreeMap::new();
    for l in log.lines() {
        let Some(frame) = l.split_whitespace().nth(2) else {
            continue;
        };
        let Some((id, data)) = frame.split_once('#') else {
            continue;
        };
        let id = u16::from_str_radix(id, 16).unwrap();
        if (0x201..=0x27F).contains(&id) && data.len() >= 4 {
            let lo = u16::from_str_radix(&data[0..2], 16).unwrap();
            let hi = u16::from_str_radix(&data[2..4], 16).unwrap();
            last.insert(id - 0x200, lo | hi << 8);
        }
    }
    last
}

#[test]
fn sigterm_mid_451_brakes_disables_the_drives_and_reports_aborted() {
    let (code, said, json, log) = run_451_and_signal("term", &[libc::SIGTERM]);
    assert_eq!(code, Some(143), "exit status 128 + SIGTERM:\n{said}");
    let v: serde_json::Value = serde_json::from_str(&json)
        .unwrap_or_else(|e| panic!("the JSON ({e}):\n{json}\nstderr:\n{said}"));
    assert_eq!(v["aborted"], true, "{v}");
    let c451 = v["cycles"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["cycle"] == 451)
        .expect("cycle 451 in the report");
    assert_eq!(c451["status"], "aborted", "{v}");
    // table-ac: X, Y, Z, A, C on nodes 1..5 and the spindle on 6, each disabled last.
    let cw = last_controlwords(&log);
    assert_eq!(cw.len(), 6, "{cw:?}");
    for (node, word) in &cw {
        assert_eq!(*word, 0x0006, "node {node}: last controlword 0x{word:04X}");
    }
    assert!(said.contains("aborted"), "{said}");
}

#[test]
fn sigint_exits_130_with_the_result_written() {
    let (code, said, json, _) = run_451_and_signal("int", &[libc::SIGINT]);
    assert_eq!(code, Some(130), "{said}");
    assert!(json.contains("\"aborted\""), "{json}");
}

/// Issue 34: two signals at once (`timeout -s INT` signals the process and then its
/// group) are one stop request: the orderly end runs and writes the aborted result,
/// and the drives are disabled; the exit status is 128 + whichever signal the process
/// handled first. Two different signals, so that the kernel cannot merge them into one
/// (two SIGINTs pending at once are delivered once): the old handler exited at once on
/// the second and wrote nothing.
#[test]
fn two_signals_at_once_still_write_the_aborted_result() {
    let (code, said, json, log) = run_451_and_signal("twice", &[libc::SIGINT, libc::SIGTERM]);
    assert!(matches!(code, Some(130 | 143)), "{code:?}: {said}");
    let v: serde_json::Value = serde_json::from_str(&json)
        .unwrap_or_else(|e| panic!("the JSON ({e}):\n{json}\nstderr:\n{said}"));
    assert_eq!(v["aborted"], true, "{v}");
    let cw = last_controlwords(&log);
    assert_eq!(cw.len(), 6, "{cw:?}");
    for (node, word) in &cw {
        assert_eq!(*word, 0x0006, "node {node}: last controlword 0x{word:04X}");
    }
}
