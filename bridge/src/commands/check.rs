//! `probebridge check PROGRAM`: parse and validate a program against the machine's
//! configuration (probe table, PREDEF values) and run every check `run` makes before
//! the first move (cycle 451's plan against the machine and its active kinematics; the
//! moves of `L` blocks and cycles 431 and 444 against the motion guard); nothing moves
//! and no bus is opened. Warnings (block numbers out of order, a length measured in mm
//! used by an INCH program) are said on stderr and do not refuse the program. A valid
//! program comes with the machine time its plan predicts, cycle by cycle, and the
//! plan's lower bound (`--json`: `predicted_machine_time_s`).

use crate::machine_state::machine_files;
use crate::session::options::MachineOptions;
use crate::session::{cycles_config_with_presets, resolve_machine};
use cycles::machine_time::Prediction;
use cycles::parser::parse_program;
use cycles::runner::{
    assumed_start, check_complete, preflight_program_from, program_warnings, PlannedTime,
};
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
    json: bool,
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
    let errors = match plan_text_from(&text, &cycles_cfg, &files.kinematics, &start) {
        Ok(time) => {
            if json {
                say!("{}", time_json(program, &cfg.name, &time));
            } else {
                say!("{}: ok (machine {})", program.display(), cfg.name);
                say!("{}", time_text(&time));
            }
            return Ok(0);
        }
        Err(errors) => errors,
    };
    if json {
        let doc = serde_json::json!({
            "program": program.display().to_string(),
            "machine": cfg.name,
            "ok": false,
            "errors": errors,
        });
        say!(
            "{}",
            serde_json::to_string_pretty(&doc).expect("strings serialise")
        );
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
    plan_text_from(text, cycles_cfg, kinematics, start)
        .err()
        .unwrap_or_default()
}

/// [`check_text_from`]'s checks; a valid program's predicted machine time.
pub fn plan_text_from(
    text: &str,
    cycles_cfg: &CyclesConfig,
    kinematics: &Path,
    start: &AxisPositions,
) -> Result<PlannedTime, Vec<String>> {
    match parse_program(text, cycles_cfg) {
        Err(invalid) => Err(invalid.0.iter().map(|d| d.to_string()).collect()),
        // Valid text: now what only the machine can tell, as `run` checks it.
        Ok(parsed) => check_complete(&parsed)
            .and_then(|()| {
                let axes = cycles_cfg.machine.axis_mask();
                preflight_program_from(&parsed, axes, cycles_cfg, kinematics, start)
                    .map_err(|e| e.to_string())
            })
            .map_err(|e| vec![e]),
    }
}

/// "predicted machine time 84.2 s (...), lower bound 61.0 s, 1.38 x".
fn predicted(p: &Prediction) -> String {
    let total = p.split.total();
    let ratio = if p.lower_bound_s > 0.0 {
        format!(", {:.2} x", total / p.lower_bound_s)
    } else {
        String::new()
    };
    format!(
        "predicted machine time {}, lower bound {:.1} s{ratio}",
        p.split, p.lower_bound_s
    )
}

/// One line per cycle and one for the program.
fn time_text(time: &PlannedTime) -> String {
    let mut out = String::new();
    for c in &time.cycles {
        let what = match &c.time {
            Some(p) => predicted(p),
            None => "machine time not predicted: its parameters are measured by the program".into(),
        };
        out.push_str(&format!(
            "  block {} cycle {} (line {}): {what}\n",
            c.block, c.cycle, c.line
        ));
    }
    out.push_str(&format!("  program: {}", predicted(&time.program)));
    if let Some(why) = &time.partial {
        out.push_str(&format!(" (partial: {why})"));
    }
    out
}

/// `check --json` of a valid program.
fn time_json(program: &Path, machine: &str, time: &PlannedTime) -> String {
    let cycles: Vec<_> = time
        .cycles
        .iter()
        .map(|c| {
            let mut v = serde_json::json!({
                "block": c.block,
                "cycle": c.cycle,
                "line": c.line,
            });
            if let Some(p) = &c.time {
                v["predicted_machine_time_s"] = p.split.total().into();
                v["predicted_machine_time_split_s"] =
                    serde_json::to_value(p.split).expect("numbers");
                v["lower_bound_s"] = p.lower_bound_s.into();
            }
            v
        })
        .collect();
    let doc = serde_json::json!({
        "program": program.display().to_string(),
        "machine": machine,
        "ok": true,
        "cycles": cycles,
        "predicted_machine_time_s": time.program.split.total(),
        "predicted_machine_time_split_s": time.program.split,
        "lower_bound_s": time.program.lower_bound_s,
        "partial": time.partial,
    });
    serde_json::to_string_pretty(&doc).expect("numbers and strings serialise")
}
