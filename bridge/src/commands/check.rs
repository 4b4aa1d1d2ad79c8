//! `probebridge check PROGRAM`: parse and validate a program against the machine's
//! configuration (probe table, PREDEF values); nothing moves.

use crate::session::{resolve_machine, MachineOptions};
use cycles::parser::check_program;
use std::path::Path;

/// Exit status 0 when valid, 2 with every error listed.
pub fn run(program: &Path, machine: &MachineOptions) -> Result<u8, String> {
    let (cfg, _) = resolve_machine(machine).map_err(|e| e.to_string())?;
    let text = std::fs::read_to_string(program)
        .map_err(|e| format!("cannot read {}: {e}", program.display()))?;
    let diagnostics = check_program(&text, &cfg);
    if diagnostics.is_empty() {
        println!("{}: ok (machine {})", program.display(), cfg.name);
        return Ok(0);
    }
    for d in &diagnostics {
        eprintln!("{}: {d}", program.display());
    }
    eprintln!(
        "{}: {} error(s); nothing was run",
        program.display(),
        diagnostics.len()
    );
    Ok(2)
}
