//! The CLI over Modbus: `probe`/`run` with `--modbus` (the built-in simulated PLC on
//! loopback), against `probebridge sim --modbus 127.0.0.1:0` in another process, with
//! a scenario whose machine's bus kind is "modbus", and a bad Modbus config refused
//! before anything starts.

mod common;

use common::*;
use std::io::{BufRead, BufReader};
use std::process::Stdio;

fn probe_json(dir: &std::path::Path, extra: &[&str]) -> serde_json::Value {
    let json = dir.join("c.json");
    let service = format!(
        "pb-cli-modbus-{}-{}",
        dir.file_name().unwrap().to_string_lossy(),
        std::process::id()
    );
    let out = run(bin()
        .args(["probe", "--start", "12.3,-4.5,20", "--dir", "0,0,-1"])
        .args(["--dist", "10", "--feed", "200", "--service", &service])
        .args(["--json", json.to_str().unwrap()])
        .args(extra));
    assert!(out.status.success());
    serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap()
}

fn assert_plane_contact(v: &serde_json::Value) {
    let c = &v["contact"];
    for (k, want) in [("X", 12.3), ("Y", -4.5), ("Z", 13.0)] {
        let got = c[k].as_f64().unwrap();
        assert!((got - want).abs() <= 1e-6, "{k} {got}, want {want}: {v}");
    }
}

#[test]
fn probe_over_modbus_on_the_built_in_plc() {
    let dir = tmpdir("modbus-probe");
    let sc = configs().join("scenarios/plane-z10.toml");
    let v = probe_json(&dir, &["--scenario", sc.to_str().unwrap(), "--modbus"]);
    assert_plane_contact(&v);
}

#[test]
fn probe_against_probebridge_sim_on_modbus_tcp() {
    let sc = configs().join("scenarios/plane-z10.toml");
    let mut sim = bin()
        .args([
            "sim",
            "--scenario",
            sc.to_str().unwrap(),
            "--modbus",
            "127.0.0.1:0",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // The first line names the port it got.
    let mut line = String::new();
    BufReader::new(sim.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let addr = line
        .trim()
        .strip_prefix("modbus tcp ")
        .unwrap_or_else(|| panic!("{line}"))
        .to_string();
    let dir = tmpdir("modbus-sim");
    let v = probe_json(
        &dir,
        &["--scenario", sc.to_str().unwrap(), "--modbus", &addr],
    );
    let _ = sim.kill();
    let _ = sim.wait();
    assert_plane_contact(&v);
}

#[test]
fn a_scenario_on_a_modbus_machine_runs_431_over_modbus() {
    let dir = tmpdir("modbus-431");
    let sc = dir.join("tilted-modbus.toml");
    let shipped = std::fs::read_to_string(configs().join("scenarios/tilted-plane.toml")).unwrap();
    assert!(shipped.contains("machine = \"table-ac\""));
    std::fs::write(
        &sc,
        shipped.replace("machine = \"table-ac\"", "machine = \"table-ac-modbus\""),
    )
    .unwrap();
    let (out, v) = run_program(&configs().join("programs/431-plane.h"), &sc, &dir, &[]);
    assert!(out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("simulated PLC on Modbus TCP 127.0.0.1:"),
        "{stderr}"
    );
    let v = v.unwrap();
    let q = |k: &str| v["cycles"][0]["q"][k].as_f64().unwrap();
    assert!((q("Q158") - 5.0).abs() < 1e-6, "{v}");
    assert!((q("Q159") + 3.0).abs() < 1e-6, "{v}");
}

#[test]
fn a_bad_modbus_bus_is_refused_with_file_key_and_reason() {
    let dir = tmpdir("modbus-bad");
    let machine = dir.join("m.toml");
    let text = std::fs::read_to_string(configs().join("machines/table-ac-modbus.toml")).unwrap();
    std::fs::write(&machine, text.replace("ring_slots = 4", "ring_slots = 0")).unwrap();
    let out = run(bin()
        .args([
            "probe", "--start", "0,0,50", "--dir", "0,0,-1", "--dist", "1", "--feed", "100",
        ])
        .args(["--machine", machine.to_str().unwrap()]));
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("m.toml")
            && stderr.contains("bus.ring_slots")
            && stderr.contains("at least one slot"),
        "{stderr}"
    );
}
