//! The example programs in configs/programs validate against the table-ac machine and
//! give the scenario's expected results on the analytic mock of the same geometry.

mod common;

use common::{MockMachine, Surface};
use nalgebra::Vector3;
use probebridge_cycles::CyclesConfig;
use probebridge_cycles::{Program, Status};
use std::path::PathBuf;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn machine() -> CyclesConfig {
    CyclesConfig::load(&root().join("configs/machines/table-ac.toml")).unwrap()
}

fn load(name: &str) -> Program {
    Program::load(&root().join("configs/programs").join(name), &machine())
        .unwrap_or_else(|e| panic!("{e}"))
}

fn run(p: &Program, m: &mut MockMachine) -> probebridge_cycles::ProgramReport {
    let mut confirm = |_: &probebridge_cycles::confirmation::Confirmation| true;
    let mut progress = |_| {};
    let mut opts = probebridge_cycles::RunOptions {
        out_dir: common::temp_dir("programs"),
        confirm: &mut confirm,
        progress: &mut progress,
        kinematics: None,
        estimator: None,
    };
    probebridge_cycles::run_program(p, m, &machine(), &mut opts)
}

#[test]
fn seed_program_validates() {
    let p = load("444-seed.h");
    assert_eq!(p.name.as_deref(), Some("444-seed"));
    assert_eq!(p.cycles().count(), 1);
}

#[test]
fn plane_program_on_the_tilted_plane() {
    let p = load("431-plane.h");
    let normal = Vector3::new(-0.05240777928304121, -0.08748866352592401, 1.0).normalize();
    let mut m = MockMachine::new(vec![Surface::Plane {
        point: Vector3::new(20.0, 10.0, 15.0),
        normal,
    }]);
    let report = run(&p, &mut m);
    assert!(report.completed(), "{report:?}");
    let q = &report.cycles[0].q;
    assert!((q["Q158"] - 5.0).abs() < 1e-6, "{}", q["Q158"]);
    assert!((q["Q159"] + 3.0).abs() < 1e-6, "{}", q["Q159"]);
    // And on plane-z10.
    let mut m = MockMachine::new(vec![Surface::Plane {
        point: Vector3::new(0.0, 0.0, 10.0),
        normal: Vector3::z(),
    }]);
    let report = run(&p, &mut m);
    assert!(report.completed());
    assert!(
        report.cycles[0].q["Q158"].abs() < 1e-12
            && (report.cycles[0].q["Q173"] - 10.0).abs() < 1e-12
    );
}

#[test]
fn freeform_program_on_its_artefacts() {
    let p = load("444-freeform.h");
    let mut m = MockMachine::new(vec![
        Surface::Plane {
            point: Vector3::zeros(),
            normal: Vector3::z(),
        },
        Surface::Sphere {
            centre: Vector3::new(-60.0, 40.0, 30.0),
            radius: 25.0,
        },
        Surface::Cylinder {
            point: Vector3::new(60.0, 0.0, 20.0),
            axis: Vector3::y(),
            radius: 15.0,
        },
    ]);
    let report = run(&p, &mut m);
    assert!(report.completed(), "{}", report.to_text());
    assert_eq!(report.cycles.len(), 7);
    for c in &report.cycles {
        assert_eq!(c.status, Status::Ok);
        assert!(
            c.q["Q164"].abs() < 1e-4,
            "block {}: {}",
            c.block,
            c.q["Q164"]
        );
        assert_eq!(c.q["Q183"], 0.0);
    }
}
