//! Helpers shared by the sim integration tests.
#![allow(dead_code)]

use hal::config::MachineConfig;
use hal::{Axis, AxisPositions};
use probebridge_sim::Scenario;
use std::path::{Path, PathBuf};

pub fn configs_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs")
}

pub fn machine(name: &str) -> MachineConfig {
    MachineConfig::load(&configs_dir().join("machines").join(format!("{name}.toml"))).unwrap()
}

/// A scenario on `machine` from the body below its `machine = ...` line.
pub fn scenario(machine_name: &str, body: &str) -> Scenario {
    let text = format!("machine = \"{machine_name}\"\n{body}");
    Scenario::parse_with_machine(&text, Path::new("test.toml"), machine(machine_name))
        .unwrap_or_else(|e| panic!("{e}"))
}

/// Scenario error text for a table-ac scenario body.
pub fn scenario_error(body: &str) -> String {
    let text = format!("machine = \"table-ac\"\n{body}");
    Scenario::parse_with_machine(&text, Path::new("bad.toml"), machine("table-ac"))
        .map(|_| ())
        .unwrap_err()
        .to_string()
}

/// X, Y, Z plus rotary values.
pub fn pos(xyz: [f64; 3], rot: &[(Axis, f64)]) -> AxisPositions {
    rot.iter()
        .fold(AxisPositions::linear(xyz), |p, &(a, v)| p.with(a, v))
}
