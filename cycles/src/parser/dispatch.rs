//! Which kind of block a block is, and where it goes to be read: program frame, tool
//! call, cycles, datum blocks, Q-parameter programming, L blocks and M functions.

use super::block::RawBlock;
use super::datum::{cycl_def, datum_setting, shift_words, trans_datum};
use super::frame::{check_end, iso_pgm, iso_tool_call, pgm_name_unit, tool_call};
use super::lexer::{iso_cycle_number, upper_words};
use super::params::cycle;
use super::state::{err, State};
use crate::cycles_config::CyclesConfig;
use crate::datum::DatumBlock;
use crate::diagnostic::Diagnostic;
use crate::m_function::{self, FunctionBlock};
use crate::params;
use crate::program::Statement;

pub(super) fn statement(
    rb: &RawBlock,
    index: usize,
    st: &mut State,
    cfg: &CyclesConfig,
    diags: &mut Vec<Diagnostic>,
) -> Statement {
    let code = rb.head.code;
    let line = rb.head.no;
    let words = upper_words(code);
    let w = |i: usize| words.get(i).map(String::as_str);
    let other = || Statement::Other(code.to_string());
    let after_cycle7 = std::mem::take(&mut st.cycle7);

    match (w(0), w(1)) {
        (Some("CYCL"), Some("DEF")) => cycl_def(rb, after_cycle7, st, cfg, diags),
        (Some("TRANS"), Some("DATUM")) => trans_datum(code, line, st.unit, diags),
        (Some("FUNCTION"), _) => {
            match m_function::function_block(code) {
                Ok(FunctionBlock::ModeMill) => st.turn_mode = None,
                Ok(FunctionBlock::ModeTurn) => st.turn_mode = Some(line),
                Err(e) => err(diags, line, e),
            }
            other()
        }
        (Some("BEGIN"), Some("PGM")) => {
            let Some((name, unit)) = pgm_name_unit(code, line, diags) else {
                return other();
            };
            if index != 0 {
                err(diags, line, "BEGIN PGM must be the first block");
            }
            st.begin_seen = true;
            st.name = Some(name.clone());
            st.unit = unit;
            Statement::BeginPgm { name, unit }
        }
        (Some("END"), Some("PGM")) => {
            let Some((name, unit)) = pgm_name_unit(code, line, diags) else {
                return other();
            };
            check_end(st, &name, unit, line, diags);
            st.end_line = Some(line);
            Statement::EndPgm { name, unit }
        }
        (Some("TOOL"), Some("CALL")) => {
            let rest = code.trim_start()[4..].trim_start()[4..].trim_start();
            tool_call(rest, false, line, st, cfg, diags).map_or_else(other, Statement::ToolCall)
        }
        (Some("TCH"), Some("PROBE")) => {
            let number = w(2).unwrap_or("");
            let title = code
                .split_whitespace()
                .skip(3)
                .collect::<Vec<_>>()
                .join(" ");
            match number.parse::<u16>().ok().and_then(params::table) {
                Some(table) => cycle(rb, table, title, None, st, cfg, diags),
                None => {
                    err(
                        diags,
                        line,
                        format!(
                            "TCH PROBE {number}: unknown cycle number {number} (supported: {})",
                            params::known_cycles()
                        ),
                    );
                    other()
                }
            }
        }
        _ => {
            if w(0) == Some("G247") {
                let inline = code.split_once(char::is_whitespace).map(|(_, r)| r.trim());
                return datum_setting(rb, inline, cfg, diags);
            }
            if w(0) == Some("G54") {
                let words: Vec<&str> = code.split_whitespace().skip(1).collect();
                return shift_words(&words, "G54", line, st.unit, diags).map_or_else(other, |s| {
                    Statement::Datum(DatumBlock::Shift(s.map(|v| v.unwrap_or(0.0))))
                });
            }
            if let Some(rest) = code.strip_prefix('%') {
                return iso_pgm(rest, index, line, st, diags).unwrap_or_else(other);
            }
            if let Some(n) = iso_cycle_number(code) {
                return match params::table(n) {
                    Some(table) => {
                        let inline = code.split_once(char::is_whitespace).map(|(_, r)| r.trim());
                        cycle(rb, table, table.name.to_string(), inline, st, cfg, diags)
                    }
                    None => {
                        err(
                            diags,
                            line,
                            format!(
                                "G{n}: unknown cycle number {n} (supported: {})",
                                params::known_cycles()
                            ),
                        );
                        other()
                    }
                };
            }
            if let Some(rest) = iso_tool_call(code) {
                return tool_call(rest, true, line, st, cfg, diags)
                    .map_or_else(other, Statement::ToolCall);
            }
            if let Some(parsed) = flow_block(rb) {
                return parsed.unwrap_or_else(|e| {
                    err(diags, line, e);
                    other()
                });
            }
            other_block(code, line, cfg, diags)
        }
    }
}

/// Q-parameter programming ([`crate::program_flow`]): assignments, labels, jumps,
/// calls, FN 14; a block continued with `~` is read as one line.
pub(super) fn flow_block(rb: &RawBlock) -> Option<Result<Statement, String>> {
    let parsed = if rb.body.is_empty() {
        crate::flow_block::parse_flow(rb.head.code)
    } else {
        let mut code = rb.head.code.to_string();
        for pl in &rb.body {
            code.push(' ');
            code.push_str(pl.code);
        }
        crate::flow_block::parse_flow(&code)
    };
    parsed.map(|r| r.map(Statement::from))
}

/// A block that is not a program frame, a TOOL CALL or a measuring cycle. Comments,
/// `L` positioning blocks (checked before the run, [`crate::runner::preflight_program`])
/// and blocks of M functions alone are accepted and run or skipped as such; anything
/// else cannot run here and is refused, so that a mistyped block (`TCH PROB 431`,
/// `CYCL DEFF`, `LL Z+100`) is never skipped without a word.
pub(super) fn other_block(
    code: &str,
    line: usize,
    cfg: &CyclesConfig,
    diags: &mut Vec<Diagnostic>,
) -> Statement {
    let accepted = match code.split_whitespace().next() {
        // Only a comment.
        None => true,
        // `* - text`: a structure comment.
        Some(w) if w.starts_with('*') => true,
        Some(w) if w.eq_ignore_ascii_case("L") => true,
        Some(_) => code.split_whitespace().all(is_m_function),
    };
    // What each M function means, at its line ([`m_function`]): refused ones never
    // reach `run`.
    let has_moves_or_m = code
        .split_whitespace()
        .next()
        .is_some_and(|w| !w.starts_with('*'));
    if accepted && has_moves_or_m {
        let m92 = cfg.parameters.m92_reference.is_some();
        if let Err(e) = m_function::check_words(code, m92) {
            err(diags, line, e);
            return Statement::Other(code.to_string());
        }
    }
    if !accepted {
        let upper = code.to_ascii_uppercase();
        let hint = if upper.starts_with("TCH") {
            " (a touch-probe cycle is written TCH PROBE <number>)"
        } else if upper.starts_with('L') {
            " (a positioning block is written L X.. Y.. Z..)"
        } else {
            ""
        };
        let shown: String = code.chars().take(40).collect();
        let more = if code.chars().count() > 40 { "..." } else { "" };
        err(
            diags,
            line,
            format!(
                "{shown}{more}: not a block probebridge can run{hint}; it runs BEGIN/END PGM, TOOL CALL, TCH PROBE {} (or G{}), CYCL DEF 7 and 247 (G54, G247), TRANS DATUM, L positioning blocks, M functions, FUNCTION MODE, Q-parameter programming (Qn = ..., FN 0..5, 9..12, 14, LBL, CALL LBL) and comments",
                params::known_cycles(),
                params::known_cycles().replace(", ", "/G")
            ),
        );
    }
    Statement::Other(code.to_string())
}

/// `M30`, `M3`: an M function ([`m_function`] says what it does).
pub(super) fn is_m_function(word: &str) -> bool {
    m_function::m_number(word).is_some()
}
