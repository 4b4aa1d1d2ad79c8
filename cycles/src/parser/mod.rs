//! Reads NC programs as the TNC stores them (`.h`, conversational) and ISO blocks:
//! groups lines into blocks (`~` continues a block, `;` starts a comment), recognises
//! BEGIN/END PGM, TOOL CALL and the measuring cycles, and validates every cycle
//! parameter against its table. All problems of a program are collected, each with
//! its line, so `check` shows them at once.

mod block;
mod datum;
mod dispatch;
mod frame;
mod lexer;
mod params;
mod state;

use crate::cycles_config::CyclesConfig;
use crate::diagnostic::{Diagnostic, ProgramErrors};
use crate::length_unit::LengthUnit;
use crate::program::{Block, CycleCall, DeferredCycle, Program, ProgramError, Statement};
use block::group;
use dispatch::statement;
use state::{err, State};
use std::path::Path;

impl Program {
    /// Parses and validates program text against a machine (probe table, PREDEF).
    pub fn parse(text: &str, cfg: &CyclesConfig) -> Result<Program, ProgramErrors> {
        parse_program(text, cfg)
    }

    /// Reads, parses and validates a `.h` file.
    pub fn load(path: &Path, cfg: &CyclesConfig) -> Result<Program, ProgramError> {
        let text = read_program_text(path).map_err(|source| ProgramError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        let mut program = Program::parse(&text, cfg).map_err(|errors| ProgramError::Invalid {
            path: path.to_path_buf(),
            errors,
        })?;
        program.path = Some(path.to_path_buf());
        Ok(program)
    }
}

/// The largest program file read (bytes): a measuring program is a few kB; more is
/// the wrong file (`/dev/zero`, a log), refused at once instead of read forever.
pub const MAX_PROGRAM_BYTES: u64 = 1 << 20;

/// Reads a program file: at most [`MAX_PROGRAM_BYTES`], UTF-8, a leading byte-order
/// mark (as Windows editors write) dropped.
pub fn read_program_text(path: &Path) -> std::io::Result<String> {
    use std::io::Read;
    let mut bytes = Vec::new();
    std::fs::File::open(path)?
        .take(MAX_PROGRAM_BYTES + 1)
        .read_to_end(&mut bytes)?;
    if bytes.len() as u64 > MAX_PROGRAM_BYTES {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("larger than {MAX_PROGRAM_BYTES} bytes: not a measuring program"),
        ));
    }
    let text = String::from_utf8(bytes).map_err(|e| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("not UTF-8 text (byte {})", e.utf8_error().valid_up_to()),
        )
    })?;
    Ok(match text.strip_prefix('\u{feff}') {
        Some(rest) => rest.to_string(),
        None => text,
    })
}

/// Parses and validates `text`; `Err` holds every problem found.
pub fn parse_program(text: &str, cfg: &CyclesConfig) -> Result<Program, ProgramErrors> {
    let (program, diagnostics) = analyse(text, cfg);
    if diagnostics.is_empty() {
        Ok(program)
    } else {
        Err(ProgramErrors(diagnostics))
    }
}

/// Every problem of `text`, sorted by line; empty when the program is valid.
pub fn check_program(text: &str, cfg: &CyclesConfig) -> Vec<Diagnostic> {
    analyse(text, cfg).1
}

fn analyse(text: &str, cfg: &CyclesConfig) -> (Program, Vec<Diagnostic>) {
    let mut diags = Vec::new();
    let raw_blocks = group(text, &mut diags);
    let mut st = State {
        unit: LengthUnit::Mm,
        name: None,
        begin_seen: false,
        end_line: None,
        tool: None,
        cycle7: false,
        turn_mode: None,
    };
    let mut blocks = Vec::new();
    for (index, rb) in raw_blocks.iter().enumerate() {
        let line = rb.head.no;
        if let Some(end) = st.end_line {
            diags.push(Diagnostic {
                line,
                message: format!("block after END PGM (line {end})"),
            });
            continue;
        }
        let mut statement = statement(rb, index, &mut st, cfg, &mut diags);
        let cycle = match &statement {
            Statement::Cycle(call) => Some(call.head.cycle),
            Statement::Deferred(d) => Some(d.cycle),
            _ => None,
        };
        if let (Some(cycle), Some(turn)) = (cycle, st.turn_mode) {
            if matches!(cycle, 431 | 444 | 451 | 460) {
                err(
                    &mut diags,
                    line,
                    format!(
                        "cycle {cycle}: refused after FUNCTION MODE TURN (line {turn}): the touch-probe cycles run in milling mode only (FUNCTION MODE MILL first)"
                    ),
                );
            }
        }
        if let Statement::Deferred(d) = &mut statement {
            // Its text, read again with the parameters' values when it runs.
            d.source = text
                .lines()
                .skip(d.line - 1)
                .take(d.last_line + 1 - d.line)
                .collect::<Vec<_>>()
                .join("\n");
        }
        blocks.push(Block {
            line,
            number: rb.head.number,
            statement,
        });
    }
    diags.extend(crate::program_flow::check_labels(&blocks));
    if st.begin_seen && st.end_line.is_none() {
        diags.push(Diagnostic {
            line: text.lines().count().max(1),
            message: format!(
                "END PGM {} missing at the end of the program",
                st.name.as_deref().unwrap_or("")
            ),
        });
    }
    diags.sort_by_key(|d| d.line);
    let program = Program {
        name: st.name,
        unit: st.unit,
        path: None,
        blocks,
    };
    (program, diags)
}

/// A cycle block whose parameters take Q-parameter values, resolved with `env`: the
/// block read and validated again as written, each `Qnnn=+Qm` with Qm's value, so that
/// ranges and the cycle's own checks apply as to any block. `Err` says why (at its
/// line), or that a value is a measured result `check` does not know.
pub fn resolve_deferred(
    d: &DeferredCycle,
    env: &dyn crate::formula::Env,
    cfg: &CyclesConfig,
) -> Result<CycleCall, crate::formula::EvalError> {
    let text = crate::program_flow::substitute_cycle_values(&d.source, env)?;
    // Blank lines keep the block's lines where they are in the program.
    let padded = format!("{}{text}", "\n".repeat(d.line - 1));
    let mut diags = Vec::new();
    let blocks = group(&padded, &mut diags);
    let mut st = State {
        unit: d.unit,
        name: None,
        begin_seen: false,
        end_line: None,
        tool: Some(d.tool.clone()),
        cycle7: false,
        // The program's own walk refused the cycle after FUNCTION MODE TURN.
        turn_mode: None,
    };
    let statement = blocks
        .first()
        .map(|rb| statement(rb, 1, &mut st, cfg, &mut diags));
    match statement {
        Some(Statement::Cycle(call)) if diags.is_empty() => Ok(*call),
        _ => Err(crate::formula::EvalError {
            kind: crate::formula::EvalErrorKind::Domain,
            message: diags
                .iter()
                .map(|d| d.message.clone())
                .collect::<Vec<_>>()
                .join("; "),
        }),
    }
}
