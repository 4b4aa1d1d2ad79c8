//! A measuring case of its own for the CLI tests of cycle 451 (cli_451, cli_q_params):
//! a fresh folder with a scenario the test writes on the shipped table-ac machine, and
//! the program.

use crate::common::{configs, tmpdir};
use std::path::PathBuf;

/// A folder `tag` with `scenario.toml` (the shipped table-ac, then `scenario`: the
/// scenario's other keys) and `program` as `k.h`: (folder, scenario, program).
pub fn table_ac_case(tag: &str, scenario: &str, program: &str) -> (PathBuf, PathBuf, PathBuf) {
    let dir = tmpdir(tag);
    let scenario_path = dir.join("scenario.toml");
    std::fs::write(
        &scenario_path,
        format!(
            "machine = \"{}\"\n{scenario}",
            configs().join("machines/table-ac.toml").display()
        ),
    )
    .unwrap();
    let program_path = dir.join("k.h");
    std::fs::write(&program_path, program).unwrap();
    (dir, scenario_path, program_path)
}
