//! Our Modbus backend against an independent PLC double (`tests/modbus/plc_double.py`,
//! pymodbus), written from docs/modbus.md's mailbox tables, not from our code: a probing
//! move onto its plane, and cycle 431 on the tilted plane of
//! `configs/scenarios/tilted-plane.toml`, with the double's word order CDAB.
//!
//! Python with pymodbus: `PROBEBRIDGE_PYTHON`, else `/opt/probebridge-venv/bin/python`
//! (`scripts/install-test-peers` makes that venv). Skipped with a line saying why where
//! neither is there, never in CI.

use cycles::program::Program;
use cycles::runner::{run_program, RunOptions};
use hal::config::BusConfig;
use hal::modbus::{ModbusBusConfig, ModbusMachine, ModbusOptions, WordOrder};
use hal::{Axis, AxisPositions, Machine, NullSink, ProbeMove};
use probebridge_tests::{configs_dir, machine_config};
#[path = "../../bridge/tests/common/pymodbus_venv.rs"]
mod pymodbus_venv;
use pymodbus_venv::python;
use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, ChildStdout, Command, Stdio};

struct Double(Child);

impl Drop for Double {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts the double on `plane` (point, normal) with ball radius `r`: its address.
fn start(py: &PathBuf, plane: [f64; 6], r: f64) -> (Double, String) {
    let (double, addr, _) = start_with(py, plane, r, &[]);
    (double, addr)
}

/// As [`start`], with more arguments; also the rest of its stdout.
fn start_with(
    py: &PathBuf,
    plane: [f64; 6],
    r: f64,
    extra: &[&str],
) -> (Double, String, BufReader<ChildStdout>) {
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("modbus/plc_double.py");
    let plane = plane.map(|v| v.to_string()).join(",");
    let mut child = Command::new(py)
        .arg(script)
        .args(["--plane", &plane, "--radius", &r.to_string()])
        .args(["--word-order", "CDAB"])
        .args(extra)
        .stdout(Stdio::piped())
        .spawn()
        .expect("start the PLC double");
    let mut line = String::new();
    let mut out = BufReader::new(child.stdout.take().unwrap());
    out.read_line(&mut line).unwrap();
    let addr = line
        .trim()
        .strip_prefix("modbus tcp ")
        .unwrap_or_else(|| panic!("PLC double said {line:?}"))
        .to_string();
    (Double(child), addr, out)
}

fn machine(sc: &sim::Scenario, addr: &str) -> (ModbusMachine, hal::config::MachineConfig) {
    machine_tuned(sc, addr, |_| {})
}

fn machine_tuned(
    sc: &sim::Scenario,
    addr: &str,
    tune: impl FnOnce(&mut ModbusBusConfig),
) -> (ModbusMachine, hal::config::MachineConfig) {
    let mut bus = ModbusBusConfig::tcp(addr);
    bus.word_order = WordOrder::CDAB;
    bus.timeout_ms = 1000;
    tune(&mut bus);
    let mut cfg = machine_config(sc);
    cfg.bus = BusConfig::Modbus(bus);
    let m = ModbusMachine::start(&cfg, NullSink, ModbusOptions::default()).unwrap();
    (m, cfg)
}

fn tilted() -> sim::Scenario {
    sim::Scenario::load(
        &configs_dir().join("scenarios/tilted-plane.toml"),
        Some(&configs_dir().join("machines")),
    )
    .unwrap()
}

#[test]
fn probing_move_against_the_pymodbus_double() {
    let Some(py) = python() else { return };
    let (_double, addr) = start(&py, [0.0, 0.0, 10.0, 0.0, 0.0, 1.0], 3.0);
    let (mut m, _) = machine(&tilted(), &addr);
    m.move_to(&AxisPositions::linear([12.3, -4.5, 20.0]), 3000.0)
        .unwrap();
    let c = m
        .probe(&ProbeMove {
            direction: [0.0, 0.0, -1.0],
            feed: 200.0,
            max_distance: 10.0,
        })
        .unwrap();
    for (a, want) in [(Axis::X, 12.3), (Axis::Y, -4.5), (Axis::Z, 13.0)] {
        let got = c.positions.get(a).unwrap();
        assert!((got - want).abs() <= 1e-6, "{a} {got}, want {want}");
    }
    assert_eq!(m.latch_acknowledged(), 1);
    // Back off and probe again: the double re-armed after our acknowledge.
    m.move_to(&AxisPositions::linear([0.0, 0.0, 20.0]), 3000.0)
        .unwrap();
    let c = m
        .probe(&ProbeMove {
            direction: [0.0, 0.0, -1.0],
            feed: 200.0,
            max_distance: 10.0,
        })
        .unwrap();
    assert!((c.positions.get(Axis::Z).unwrap() - 13.0).abs() <= 1e-6);
    assert_eq!(m.latch_acknowledged(), 2);
}

#[test]
fn cycle_431_against_the_pymodbus_double() {
    let Some(py) = python() else { return };
    let sc = tilted();
    let p = &sc.planes[0];
    let n = p.normal;
    let (_double, addr) = start(
        &py,
        [p.point[0], p.point[1], p.point[2], n[0], n[1], n[2]],
        3.0,
    );
    let (mut m, _) = machine(&sc, &addr);
    let cfg = probebridge_tests::cycles_config(&sc);
    let text = std::fs::read_to_string(configs_dir().join("programs/431-plane.h")).unwrap();
    let program = Program::parse(&text, &cfg).unwrap();
    let out = std::env::temp_dir().join(format!("pb-pymodbus-431-{}", std::process::id()));
    std::fs::create_dir_all(&out).unwrap();
    let mut confirm = |_: &cycles::confirmation::Confirmation| true;
    let mut progress = |_| {};
    let mut opts = RunOptions {
        out_dir: out.clone(),
        confirm: &mut confirm,
        progress: &mut progress,
        kinematics: Some(out.join("kinematics.toml")),
        estimator: None,
    };
    let report = run_program(&program, &mut m, &cfg, &mut opts);
    let _ = std::fs::remove_dir_all(&out);
    assert!(report.completed(), "{}", report.to_json());
    let q = &report.cycles[0].q;
    println!(
        "431 against the pymodbus double: Q158 {:.9} Q159 {:.9}",
        q["Q158"], q["Q159"]
    );
    assert!((q["Q158"] - 5.0).abs() < 1e-5, "{q:?}");
    assert!((q["Q159"] + 3.0).abs() < 1e-5, "{q:?}");
}

/// Command 5 as the double implements it from docs/modbus.md: the angle in 0.001° in
/// the first target's registers (word order CDAB here), done with result 0; a double
/// without the function rejects it, and the bridge says what to do.
#[test]
fn orient_spindle_against_the_pymodbus_double() {
    let Some(py) = python() else { return };
    let (_double, addr, mut out) =
        start_with(&py, [0.0, 0.0, 10.0, 0.0, 0.0, 1.0], 3.0, &["--spindle"]);
    let (mut m, _) = machine_tuned(&tilted(), &addr, |b| b.spindle_orientation = true);
    m.move_to(&AxisPositions::linear([0.0, 0.0, 20.0]), 3000.0)
        .unwrap();
    for (deg, said) in [
        (180.0, "orient 180000"),
        (-90.0, "orient 270000"),
        (0.0, "orient 0"),
    ] {
        assert!(m.orient_spindle(deg).unwrap(), "{deg}");
        let mut line = String::new();
        out.read_line(&mut line).unwrap();
        assert_eq!(line.trim(), said, "{deg}°");
    }

    let (_plain, addr) = start(&py, [0.0, 0.0, 10.0, 0.0, 0.0, 1.0], 3.0);
    let (mut m, _) = machine_tuned(&tilted(), &addr, |b| b.spindle_orientation = true);
    let e = m.orient_spindle(180.0).unwrap_err();
    assert!(
        e.to_string().contains("command 5")
            && e.to_string().contains("spindle_orientation = false"),
        "{e}"
    );
    // Configured without it, the bridge asks nothing and says it cannot orient.
    let (mut m, _) = machine(&tilted(), &addr);
    assert!(!m.orient_spindle(180.0).unwrap());
}
