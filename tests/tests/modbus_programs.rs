//! The NC programs of `configs/programs` give the same results over Modbus (the
//! simulated PLC capturing with `hw_latch`, on TCP loopback) as over CANopen (the
//! simulated CiA 402 drives on the in-process bus): every Q result to 1e-6. The pairs
//! of program and scenario are those of the vcan cases (tests/vcan/cases).

use probebridge_tests::conformance::{Backend, CanInproc};
use probebridge_tests::conformance_modbus::{open_tcp, ModbusTcp};
use probebridge_tests::{configs_dir, run_shipped_program};

fn same_results(program: &str, scenario: &str) {
    let sc = sim::Scenario::load(
        &configs_dir().join("scenarios").join(scenario),
        Some(&configs_dir().join("machines")),
    )
    .unwrap();
    let can = run_shipped_program(&mut CanInproc::open(&sc), program, &sc, "can");
    let modbus = run_shipped_program(&mut ModbusTcp::open(&sc), program, &sc, "modbus");
    assert!(can.completed(), "{program} on CANopen: {}", can.to_json());
    assert!(
        modbus.completed(),
        "{program} over Modbus: {}",
        modbus.to_json()
    );
    assert_eq!(can.cycles.len(), modbus.cycles.len());
    let mut compared = 0;
    let mut worst: f64 = 0.0;
    for (c, m) in can.cycles.iter().zip(&modbus.cycles) {
        assert_eq!((c.block, c.cycle), (m.block, m.cycle));
        assert_eq!(
            c.q.keys().collect::<Vec<_>>(),
            m.q.keys().collect::<Vec<_>>()
        );
        for (k, v) in &c.q {
            let w = m.q[k];
            assert!(
                (v - w).abs() <= 1e-6,
                "{program} cycle {} {k}: CANopen {v:.9}, Modbus {w:.9}",
                c.cycle
            );
            worst = worst.max((v - w).abs());
            compared += 1;
        }
    }
    assert!(compared > 0, "{program}: no Q results to compare");
    println!(
        "{program} on {scenario}: {compared} Q values, largest difference CANopen vs Modbus {worst:.3e}"
    );
}

#[test]
fn cycle_431_plane_tilted() {
    same_results("431-plane.h", "tilted-plane.toml");
}

#[test]
fn cycle_431_plane_flat() {
    same_results("431-plane.h", "plane-z10.toml");
}

#[test]
fn cycle_444_freeform() {
    same_results("444-freeform.h", "freeform.toml");
}

#[test]
fn cycle_444_seed() {
    same_results("444-seed.h", "seed-444.toml");
}

#[test]
fn cycle_451_check() {
    same_results("451-check.h", "demo-sphere.toml");
}

#[test]
fn cycle_451_optimise() {
    same_results("451-optimise.h", "demo-sphere.toml");
}

/// Cycle 460's probe-table row is compared, every column measured on a stylus off the
/// spindle axis (stylus-offset.toml, as the vcan case): over CANopen table-ac's spindle
/// drive orients the spindle (profile position), over Modbus the PLC's command 5.
#[test]
fn cycle_460_calibrate() {
    let sc = sim::Scenario::load(
        &configs_dir().join("scenarios").join("stylus-offset.toml"),
        Some(&configs_dir().join("machines")),
    )
    .unwrap();
    let program = "460-calibrate.h";
    let can = run_shipped_program(&mut CanInproc::open(&sc), program, &sc, "can");
    let modbus = run_shipped_program(
        &mut open_tcp(&sc, |b| b.spindle_orientation = true),
        program,
        &sc,
        "modbus",
    );
    let row = |r: &cycles::results::ProgramReport, bus: &str| {
        assert!(r.completed(), "{program} on {bus}: {}", r.to_json());
        let c = r
            .cycles
            .iter()
            .find_map(|c| c.calibration.as_ref())
            .unwrap_or_else(|| panic!("{program} on {bus}: no calibration: {}", r.to_json()));
        assert!(c.length_measured && c.offset_measured, "{bus}: {c:?}");
        assert!(
            (c.after.cal_of1 - 0.003).abs() < 1e-4 && (c.after.cal_of2 + 0.002).abs() < 1e-4,
            "{bus}: {c:?}"
        );
        let a = &c.after;
        [a.r, a.cal_of1, a.cal_of2, a.cal_ang, a.l]
    };
    let (c, m) = (row(&can, "CANopen"), row(&modbus, "Modbus"));
    for (name, (v, w)) in ["R", "CAL_OF1", "CAL_OF2", "CAL_ANG", "L"]
        .iter()
        .zip(c.iter().zip(&m))
    {
        assert!(
            (v - w).abs() <= 1e-6,
            "{program} {name}: CANopen {v:.9}, Modbus {w:.9}"
        );
    }
    println!("{program}: R, CAL_OF1, CAL_OF2, CAL_ANG, L: CANopen {c:?}, Modbus {m:?}");
}
