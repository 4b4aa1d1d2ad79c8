//! `probebridge check PROGRAM`: parse and validate a program against the machine's
//! configuration (probe table, PREDEF values) and run every check `run` makes before
//! the first move (cycle 451's plan against the machine and its active kinematics; the
//! moves of `L` blocks and cycles 431 and 444 against the motion guard); nothing moves
//! and no bus is opened. Warnings (block numbers out of order, a length measured in mm
//! used by an INCH program) are said on stderr and do not refuse the program.

use crate::machine_state::machine_files;
use crate::session::options::MachineOptions;
use crate::session::{cycles_config_with_presets, resolve_machine};
use cycles::parser::parse_program;
use cycles::runner::{assumed_start, check_complete, preflight_program_from, program_warnings};
use cycles::CyclesConfig;
use hal::AxisPositions;
use std::path::Path;

/// Exit status 0 when valid, 2 with every error listed.
pub fn run(
    program: &Path,
    machine: &MachineOptions,
    kinematics: Option<&Path>,
    presets: Option<&Path>,
    state_dir: Option<&Path>,
) -> Result<u8, String> {
    let (cfg, scenario) = resolve_machine(machine).map_err(|e| e.to_string())?;
    // The files `run` would use; `check` writes nothing (no seeding).
    let files = machine_files(&cfg, state_dir, presets, kinematics, false)?;
    for n in &files.notes {
        tell!("state: {n}");
    }
    let mut cycles_cfg = cycles_config_with_presets(&cfg, scenario.as_ref(), Some(&files.presets))
        .map_err(|e| e.to_string())?;
    cycles_cfg
        .use_calibrations(&files.probes)
        .map_err(|e| e.to_string())?;
    let text = cycles::parser::read_program_text(program)
        .map_err(|e| format!("cannot read {}: {e}", program.display()))?;
    // With a scenario the axes start where the simulator starts them, as `run` will
    // find them; a real machine's are not known here ([`assumed_start`]).
    let start = match &scenario {
        Some(sc) => assumed_start(&cfg).merged(&sim::machine::SimMachine::start_positions(sc)),
        None => assumed_start(&cfg),
    };
    // What does not stop the program, said before its errors or its "ok".
    if let Ok(parsed) = parse_program(&text, &cycles_cfg) {
        super::tell_errors(program, &program_warnings(&parsed, &cycles_cfg));
    }
    let errors = check_text_from(&text, &cycles_cfg, &files.kinematics, &start);
    if errors.is_empty() {
        say!("{}: ok (machine {})", program.display(), cfg.name);
        return Ok(0);
    }
    super::tell_errors(program, &errors);
    tell!(
        "{}: {} error(s); nothing was run",
        program.display(),
        errors.len()
    );
    Ok(2)
}

/// Every error `check` reports for program `text` on a machine (`cycles_cfg`, its
/// active kinematics file at `kinematics`): the parser's, then, for valid text, a
/// missing BEGIN/END PGM and what `run` refuses before the first move. Empty: ok.
/// (The fuzz target `check` runs this on mutated programs.)
pub fn check_text(text: &str, cycles_cfg: &CyclesConfig, kinematics: &Path) -> Vec<String> {
    let start = assumed_start(&cycles_cfg.machine);
    check_text_from(text, cycles_cfg, kinematics, &start)
}

/// [`check_text`] with the axes at `start` before the program's first block.
pub fn check_text_from(
    text: &str,
    cycles_cfg: &CyclesConfig,
    kinematics: &Path,
    start: &AxisPositions,
) -> Vec<String> {
    match parse_program(text, cycles_cfg) {
        Err(invalid) => invalid.0.iter().map(|d| d.to_string()).collect(),
        // Valid text: now what only the machine can tell, as `run` checks it.
        Ok(parsed) => check_complete(&parsed)
            .and_then(|()| {
                let axes = cycles_cfg.machine.axis_mask();
                preflight_program_from(&parsed, axes, cycles_cfg, kinematics, start)
                    .map_err(|e| e.to_string())
            })
            .err()
            .into_iter()
            .collect(),
    }
}
