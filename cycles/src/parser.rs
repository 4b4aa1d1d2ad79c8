//! Reads NC programs as the TNC stores them (`.h`, conversational) and ISO blocks:
//! groups lines into blocks (`~` continues a block, `;` starts a comment), recognises
//! BEGIN/END PGM, TOOL CALL and the measuring cycles, and validates every cycle
//! parameter against its table. All problems of a program are collected, each with
//! its line, so `check` shows them at once.

use crate::cycle431::PlaneParams;
use crate::cycle444::Probing3dParams;
use crate::cycle450::SaveParams;
use crate::cycle451::KinematicsParams;
use crate::cycle_block::{CycleBlock, Origin, Param, ToolCall, Value};
use crate::cycles_config::CyclesConfig;
use crate::datum::DatumBlock;
use crate::diagnostic::{Diagnostic, ProgramErrors};
use crate::formula::parse_decimal;
use crate::length_unit::LengthUnit;
use crate::m_function::{self, FunctionBlock};
use crate::params::{self, CycleTable, Default as ParamDefault, Kind, ParamSpec};
use crate::probe_axis::ProbeAxis;
use crate::program::{
    Block, CycleCall, CycleKind, DeferredCycle, Program, ProgramError, Statement,
};
use std::collections::BTreeMap;
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

/// One physical line, split.
#[derive(Clone, Copy, Debug)]
struct Line<'a> {
    no: usize,
    number: Option<u32>,
    /// Text before the comment, block number and `~` removed, trimmed.
    code: &'a str,
    comment: Option<&'a str>,
    /// Ends with `~`: the block goes on.
    cont: bool,
}

impl Line<'_> {
    fn is_blank(&self) -> bool {
        self.code.is_empty() && self.comment.is_none() && !self.cont && self.number.is_none()
    }
}

fn split_line(no: usize, raw: &str) -> Line<'_> {
    let mut t = raw.trim();
    let cont = t.ends_with('~');
    if cont {
        t = t[..t.len() - 1].trim_end();
    }
    // `;` inside a QS string is text, not a comment.
    let mut in_quotes = false;
    let mut cut = None;
    for (i, c) in t.char_indices() {
        match c {
            '"' => in_quotes = !in_quotes,
            ';' if !in_quotes => {
                cut = Some(i);
                break;
            }
            _ => {}
        }
    }
    let (code, comment) = match cut {
        Some(i) => (t[..i].trim(), Some(t[i + 1..].trim())),
        None => (t, None),
    };
    let (number, code) = split_block_number(code);
    // ISO blocks end with `*`; a line that starts with `*` is a structure comment.
    let code = match code.strip_suffix('*') {
        Some(c) if !code.starts_with('*') => c.trim_end(),
        _ => code,
    };
    Line {
        no,
        number,
        code,
        comment,
        cont,
    }
}

/// `11 TCH PROBE ...` / `N110 G444 ...`: the leading block number, if any.
fn split_block_number(code: &str) -> (Option<u32>, &str) {
    let digits_from = usize::from(code.starts_with(['N', 'n']));
    let rest = &code[digits_from..];
    let end = rest
        .find(|c: char| !c.is_ascii_digit())
        .unwrap_or(rest.len());
    if end == 0 {
        return (None, code);
    }
    let after = &rest[end..];
    if !(after.is_empty() || after.starts_with(char::is_whitespace)) {
        return (None, code);
    }
    // "N" alone followed by digits and space is a block number; a bare "12" too.
    match rest[..end].parse() {
        Ok(n) => (Some(n), after.trim_start()),
        Err(_) => (None, code),
    }
}

/// `Q263=...` / `QS400=...` at the start of the code: a cycle parameter line.
fn is_param_line(code: &str) -> bool {
    let b = code.as_bytes();
    if b.first().map(u8::to_ascii_uppercase) != Some(b'Q') {
        return false;
    }
    let mut i = 1;
    if b.get(1).map(u8::to_ascii_uppercase) == Some(b'S') {
        i = 2;
    }
    let start = i;
    while b.get(i).is_some_and(u8::is_ascii_digit) {
        i += 1;
    }
    i > start && code[i..].trim_start().starts_with('=')
}

#[derive(Clone, Copy, Debug)]
struct ParamLine<'a> {
    no: usize,
    code: &'a str,
    comment: Option<&'a str>,
}

#[derive(Debug)]
struct RawBlock<'a> {
    head: Line<'a>,
    body: Vec<ParamLine<'a>>,
    /// The last line read ended with `~`.
    open: bool,
    last_line: usize,
    /// The last line's comment (for the seed layout where the comment with its `~`
    /// stands on its own line after the value).
    last_has_comment: bool,
    is_cycle: bool,
}

/// Groups lines into blocks; reports continuation errors.
fn group<'a>(text: &'a str, diags: &mut Vec<Diagnostic>) -> Vec<RawBlock<'a>> {
    let mut blocks: Vec<RawBlock> = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = split_line(i + 1, raw);
        if line.is_blank() {
            continue;
        }
        if let Some(cur) = blocks.last_mut() {
            let comment_only = line.code.is_empty() && line.number.is_none();
            if cur.open && starts_block(&line) {
                // Continuation lines never carry a block number or a block keyword.
                diags.push(Diagnostic {
                    line: cur.last_line,
                    message: format!(
                        "the line ends with \"~\" but line {} starts a new block",
                        line.no
                    ),
                });
                cur.open = false;
            } else if cur.open || (comment_only && cur.is_cycle && !cur.last_has_comment) {
                if comment_only {
                    // A comment (and maybe the `~`) belonging to the line before.
                    if let Some(last) = cur.body.last_mut() {
                        last.comment = line.comment;
                    }
                    cur.last_has_comment = true;
                } else {
                    cur.body.push(ParamLine {
                        no: line.no,
                        code: line.code,
                        comment: line.comment,
                    });
                    cur.last_has_comment = line.comment.is_some();
                }
                cur.open = line.cont;
                cur.last_line = line.no;
                continue;
            }
            let name = line
                .code
                .split('=')
                .next()
                .unwrap_or("")
                .trim()
                .to_ascii_uppercase();
            if line.number.is_none()
                && is_param_line(line.code)
                && cur.is_cycle
                && cycle_takes(cur.head.code, &name)
            {
                diags.push(Diagnostic {
                    line: cur.last_line,
                    message: format!(
                        "missing continuation \"~\": the block ends here but line {} continues it with {name}",
                        line.no
                    ),
                });
                // Keep the parameter in its block so that it is not also reported
                // missing.
                cur.body.push(ParamLine {
                    no: line.no,
                    code: line.code,
                    comment: line.comment,
                });
                cur.open = line.cont;
                cur.last_line = line.no;
                cur.last_has_comment = line.comment.is_some();
                continue;
            }
        }
        // `Q1 = 5` on its own is an assignment; `Q263=+0 Q264=+0` is a cycle's.
        if line.number.is_none()
            && is_param_line(line.code)
            && !matches!(crate::flow_block::parse_flow(line.code), Some(Ok(_)))
        {
            diags.push(Diagnostic {
                line: line.no,
                message: "parameter line outside a cycle block (expected a TCH PROBE or G4xx block before it, its lines ending with \"~\")".into(),
            });
            continue;
        }
        let is_cycle = is_cycle_head(line.code);
        blocks.push(RawBlock {
            head: line,
            body: Vec::new(),
            open: line.cont,
            last_line: line.no,
            last_has_comment: line.comment.is_some(),
            is_cycle,
        });
    }
    if let Some(last) = blocks.last() {
        if last.open {
            diags.push(Diagnostic {
                line: last.last_line,
                message: "the block continues with \"~\" but the program ends".into(),
            });
        }
    }
    blocks
}

/// A line that can only be the start of a block.
fn starts_block(line: &Line) -> bool {
    let w = upper_words(line.code);
    let first_two = (w.first().map(String::as_str), w.get(1).map(String::as_str));
    line.number.is_some()
        || is_cycle_head(line.code)
        || matches!(
            first_two,
            (Some("TOOL"), Some("CALL")) | (Some("BEGIN" | "END"), Some("PGM"))
        )
}

fn upper_words(code: &str) -> Vec<String> {
    code.split_whitespace()
        .map(str::to_ascii_uppercase)
        .collect()
}

/// A block that may carry parameter lines: a touch-probe cycle, or a `CYCL DEF` (cycle
/// 247's Q339; cycle 7's 7.x lines are blocks of their own).
fn is_cycle_head(code: &str) -> bool {
    let w = upper_words(code);
    (w.len() >= 2 && ((w[0] == "TCH" && w[1] == "PROBE") || (w[0] == "CYCL" && w[1] == "DEF")))
        || iso_cycle_number(code).is_some()
        || w.first().is_some_and(|g| g == "G247")
}

/// `G444 ...` -> 444 for G codes in the touch-probe ranges (400..499, 1400..1499).
fn iso_cycle_number(code: &str) -> Option<u16> {
    let first = code.split_whitespace().next()?;
    let digits = first.strip_prefix(['G', 'g'])?;
    let n: u16 = digits.parse().ok()?;
    (digits.len() >= 3 && ((400..=499).contains(&n) || (1400..=1499).contains(&n))).then_some(n)
}

struct State {
    unit: LengthUnit,
    name: Option<String>,
    begin_seen: bool,
    end_line: Option<usize>,
    tool: Option<ToolCall>,
    /// The block before was CYCL DEF 7.0 or 7.x: a 7.x may follow.
    cycle7: bool,
    /// The line of a `FUNCTION MODE TURN` not yet undone by `FUNCTION MODE MILL`.
    turn_mode: Option<usize>,
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
            if matches!(cycle, 431 | 444 | 451) {
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

fn err(diags: &mut Vec<Diagnostic>, line: usize, message: impl Into<String>) {
    diags.push(Diagnostic {
        line,
        message: message.into(),
    });
}

fn statement(
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

/// `+Q5`, `-QL2`, `QR1`: a numeric parameter as a cycle parameter's value.
fn is_param_ref(raw: &str) -> bool {
    let r = raw.strip_prefix(['+', '-']).unwrap_or(raw);
    crate::q_params::QName::parse(r).is_some_and(|n| !n.is_text())
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

/// Q-parameter programming ([`crate::program_flow`]): assignments, labels, jumps,
/// calls, FN 14; a block continued with `~` is read as one line.
fn flow_block(rb: &RawBlock) -> Option<Result<Statement, String>> {
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

/// Whether the cycle block starting with `head` takes parameter `name` (so that a
/// `Qn=` line after it without `~` is its forgotten continuation, not a formula).
fn cycle_takes(head: &str, name: &str) -> bool {
    let w = upper_words(head);
    let number = match (w.first().map(String::as_str), w.get(1).map(String::as_str)) {
        (Some("TCH"), Some("PROBE")) | (Some("CYCL"), Some("DEF")) => {
            w.get(2).and_then(|n| n.parse::<u16>().ok())
        }
        (Some("G247"), _) => Some(247),
        _ => iso_cycle_number(head),
    };
    match number {
        Some(247) => name == "Q339",
        Some(n) => params::table(n).is_some_and(|t| t.param(name).is_some()),
        None => false,
    }
}

/// `CYCL DEF 247 DATUM SETTING` (Q339 on its lines), `CYCL DEF 7.0 DATUM SHIFT` and its
/// `CYCL DEF 7.1 X+10` blocks; other `CYCL DEF`s cannot run here.
fn cycl_def(
    rb: &RawBlock,
    after_cycle7: bool,
    st: &mut State,
    cfg: &CyclesConfig,
    diags: &mut Vec<Diagnostic>,
) -> Statement {
    let code = rb.head.code;
    let line = rb.head.no;
    let words: Vec<&str> = code.split_whitespace().skip(2).collect();
    let number = words.first().copied().unwrap_or("");
    match number {
        "247" => datum_setting(rb, None, cfg, diags),
        "7.0" | "7" => {
            st.cycle7 = true;
            Statement::Datum(DatumBlock::Shift([0.0; 3]))
        }
        n if n.starts_with("7.") => {
            if !after_cycle7 {
                err(
                    diags,
                    line,
                    format!(
                        "CYCL DEF {n}: must follow CYCL DEF 7.0 DATUM SHIFT (or another 7.x block)"
                    ),
                );
                return Statement::Other(code.to_string());
            }
            st.cycle7 = true;
            let shift = shift_words(&words[1..], &format!("CYCL DEF {n}"), line, st.unit, diags);
            match shift.map(|s| {
                s.into_iter()
                    .enumerate()
                    .filter_map(|(i, v)| v.map(|v| (i, v)))
                    .collect::<Vec<_>>()
            }) {
                Some(axes) if axes.len() == 1 => {
                    Statement::Datum(DatumBlock::ShiftAxis(axes[0].0, axes[0].1))
                }
                Some(_) => {
                    err(diags, line, format!("CYCL DEF {n}: expected one axis and its shift, such as CYCL DEF {n} X+10"));
                    Statement::Other(code.to_string())
                }
                None => Statement::Other(code.to_string()),
            }
        }
        _ => {
            err(
                diags,
                line,
                format!("CYCL DEF {number}: not a cycle probebridge can run (it runs CYCL DEF 7 DATUM SHIFT and CYCL DEF 247 DATUM SETTING)"),
            );
            Statement::Other(code.to_string())
        }
    }
}

/// `TRANS DATUM AXIS X+10 Y+5 Z+0` (axes left out: 0) and `TRANS DATUM RESET`.
fn trans_datum(
    code: &str,
    line: usize,
    unit: LengthUnit,
    diags: &mut Vec<Diagnostic>,
) -> Statement {
    let words: Vec<&str> = code.split_whitespace().skip(2).collect();
    match words.first().map(|w| w.to_ascii_uppercase()).as_deref() {
        Some("RESET") if words.len() == 1 => Statement::Datum(DatumBlock::Reset),
        Some("AXIS") => shift_words(&words[1..], "TRANS DATUM AXIS", line, unit, diags)
            .map_or_else(
                || Statement::Other(code.to_string()),
                |s| Statement::Datum(DatumBlock::Shift(s.map(|v| v.unwrap_or(0.0)))),
            ),
        _ => {
            err(diags, line, "TRANS DATUM: expected TRANS DATUM AXIS X.. Y.. Z.. or TRANS DATUM RESET (datum tables do not run here)");
            Statement::Other(code.to_string())
        }
    }
}

/// `X+10 Y-5.5 Z+0`: absolute shifts of X, Y, Z (inch programs converted to mm); at
/// least one, none twice.
fn shift_words(
    words: &[&str],
    what: &str,
    line: usize,
    unit: LengthUnit,
    diags: &mut Vec<Diagnostic>,
) -> Option<[Option<f64>; 3]> {
    let mut shift = [None; 3];
    for w in words {
        let u = w.to_ascii_uppercase();
        let i = match u.get(..1) {
            Some("X") => 0,
            Some("Y") => 1,
            Some("Z") => 2,
            _ => {
                err(
                    diags,
                    line,
                    format!("{what}: {w}: only absolute X, Y and Z shifts run here"),
                );
                return None;
            }
        };
        let Some(v) = parse_decimal(&u[1..]) else {
            err(
                diags,
                line,
                format!("{what}: {w}: not a coordinate (expected a signed decimal such as X+10)"),
            );
            return None;
        };
        if shift[i].is_some() {
            err(diags, line, format!("{what}: {} given twice", &u[..1]));
            return None;
        }
        shift[i] = Some(match unit {
            LengthUnit::Mm => v,
            LengthUnit::Inch => v * 25.4,
        });
    }
    if shift.iter().all(Option::is_none) {
        err(
            diags,
            line,
            format!("{what}: no axis (expected X.. Y.. Z..)"),
        );
        return None;
    }
    Some(shift)
}

/// Cycle 247 DATUM SETTING: Q339, the preset number, must be a row of the machine's
/// preset table.
fn datum_setting(
    rb: &RawBlock,
    inline: Option<&str>,
    cfg: &CyclesConfig,
    diags: &mut Vec<Diagnostic>,
) -> Statement {
    let line = rb.head.no;
    let mut lines: Vec<ParamLine> = Vec::new();
    if let Some(code) = inline.filter(|c| !c.is_empty()) {
        lines.push(ParamLine {
            no: line,
            code,
            comment: rb.head.comment,
        });
    }
    lines.extend(rb.body.iter().copied());
    let before = diags.len();
    let mut broken = Vec::new();
    let mut number: Option<(u32, usize, String)> = None;
    for pl in &lines {
        for a in assignments(pl, &mut broken, diags) {
            let shown = format!("{}={}", a.name, a.raw);
            if a.name != "Q339" {
                err(
                    diags,
                    a.line,
                    format!(
                        "{shown}: unknown parameter for cycle 247 DATUM SETTING (allowed: Q339)"
                    ),
                );
                continue;
            }
            if number.is_some() {
                err(diags, a.line, format!("{shown}: given twice"));
                continue;
            }
            match parse_decimal(a.raw) {
                Some(v) if (0.0..=65535.0).contains(&v) && v.fract() == 0.0 => {
                    number = Some((v as u32, a.line, shown));
                }
                _ => err(
                    diags,
                    a.line,
                    format!("{shown}: preset number out of range 0..65535 (an integer)"),
                ),
            }
        }
    }
    let other = || Statement::Other(rb.head.code.to_string());
    match number {
        Some((n, l, shown)) => match cfg.presets.row(n) {
            Some(_) if diags.len() == before => Statement::Datum(DatumBlock::Preset(n)),
            Some(_) => other(),
            None => {
                err(
                    diags,
                    l,
                    format!(
                        "{shown}: preset {n} is not in the preset table {} (allowed: {})",
                        cfg.presets.path.display(),
                        cfg.presets.numbers()
                    ),
                );
                other()
            }
        },
        None => {
            if diags.len() == before {
                err(
                    diags,
                    line,
                    "cycle 247 DATUM SETTING: missing required parameter Q339 (preset number)",
                );
            }
            other()
        }
    }
}

/// A block that is not a program frame, a TOOL CALL or a measuring cycle. Comments,
/// `L` positioning blocks (checked before the run, [`crate::runner::preflight_program`])
/// and blocks of M functions alone are accepted and run or skipped as such; anything
/// else cannot run here and is refused, so that a mistyped block (`TCH PROB 431`,
/// `CYCL DEFF`, `LL Z+100`) is never skipped without a word.
fn other_block(
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
fn is_m_function(word: &str) -> bool {
    m_function::m_number(word).is_some()
}

/// `NAME MM|INCH` after `BEGIN PGM` / `END PGM`; the name keeps its case.
fn pgm_name_unit(
    code: &str,
    line: usize,
    diags: &mut Vec<Diagnostic>,
) -> Option<(String, LengthUnit)> {
    let words: Vec<&str> = code.split_whitespace().skip(2).collect();
    let name = words.first().copied().unwrap_or("");
    let unit = match words.get(1).map(|w| w.to_ascii_uppercase()).as_deref() {
        Some("MM") => LengthUnit::Mm,
        Some("INCH") => LengthUnit::Inch,
        _ => {
            err(diags, line, "expected PGM NAME MM or PGM NAME INCH");
            return None;
        }
    };
    Some((name.to_string(), unit))
}

fn check_end(st: &State, name: &str, unit: LengthUnit, line: usize, diags: &mut Vec<Diagnostic>) {
    if !st.begin_seen {
        err(diags, line, "END PGM without BEGIN PGM");
    } else if st.name.as_deref() != Some(name) || st.unit != unit {
        err(
            diags,
            line,
            format!(
                "END PGM {name} {} does not match BEGIN PGM {} {}",
                unit_word(unit),
                st.name.as_deref().unwrap_or(""),
                unit_word(st.unit)
            ),
        );
    }
}

fn unit_word(u: LengthUnit) -> &'static str {
    match u {
        LengthUnit::Mm => "MM",
        LengthUnit::Inch => "INCH",
    }
}

/// ISO program start `%NAME G71` (mm) / `G70` (inch), and its end line.
fn iso_pgm(
    rest: &str,
    index: usize,
    line: usize,
    st: &mut State,
    diags: &mut Vec<Diagnostic>,
) -> Option<Statement> {
    let words = upper_words(rest);
    let unit = match words.get(1).map(String::as_str) {
        Some("G71") => LengthUnit::Mm,
        Some("G70") => LengthUnit::Inch,
        _ => {
            err(diags, line, "expected %NAME G71 (mm) or %NAME G70 (inch)");
            return None;
        }
    };
    let name = words[0].clone();
    if index == 0 {
        st.begin_seen = true;
        st.name = Some(name.clone());
        st.unit = unit;
        Some(Statement::BeginPgm { name, unit })
    } else {
        check_end(st, &name, unit, line, diags);
        st.end_line = Some(line);
        Some(Statement::EndPgm { name, unit })
    }
}

/// ISO tool call: `T1 G17`, `T"NAME" G17`, `T "NAME" G17`; returns what follows `T`.
fn iso_tool_call(code: &str) -> Option<&str> {
    let rest = code.strip_prefix(['T', 't'])?;
    let r = rest.trim_start();
    (r.starts_with('"') || r.starts_with(|c: char| c.is_ascii_digit())).then_some(r)
}

/// `"NAME" Z ...` / `1 Z ...` (conversational) or `"NAME" G17` / `1 G17` (ISO).
fn tool_call(
    rest: &str,
    iso: bool,
    line: usize,
    st: &mut State,
    cfg: &CyclesConfig,
    diags: &mut Vec<Diagnostic>,
) -> Option<ToolCall> {
    let (tool, after) = if let Some(q) = rest.strip_prefix('"') {
        let Some(end) = q.find('"') else {
            err(
                diags,
                line,
                "TOOL CALL: unterminated tool name (expected TOOL CALL \"NAME\" Z)",
            );
            return None;
        };
        (ToolRef::Name(q[..end].to_string()), &q[end + 1..])
    } else {
        let end = rest.find(char::is_whitespace).unwrap_or(rest.len());
        let token = &rest[..end];
        // Tool number with optional index (`5.1`): the index picks nothing here.
        match token.split('.').next().unwrap_or("").parse::<usize>() {
            Ok(n) => (ToolRef::Number(n), &rest[end..]),
            Err(_) => {
                err(
                    diags,
                    line,
                    format!("TOOL CALL {token}: expected a tool name in quotes or a tool number"),
                );
                return None;
            }
        }
    };
    let axis_word = after.split_whitespace().next();
    let previous = st.tool.as_ref().map_or(ProbeAxis::Z, |t| t.axis);
    let axis = if iso {
        match axis_word.map(str::to_ascii_uppercase).as_deref() {
            Some("G17") => ProbeAxis::Z,
            Some("G18") => ProbeAxis::Y,
            Some("G19") => ProbeAxis::X,
            _ => previous,
        }
    } else {
        match axis_word {
            Some(a) if a.len() == 1 && a.chars().all(|c| c.is_ascii_alphabetic()) => {
                match ProbeAxis::from_name(a) {
                    Some(ax) => ax,
                    None => {
                        err(
                            diags,
                            line,
                            format!("TOOL CALL: probe axis {a}: expected Z, X or Y"),
                        );
                        return None;
                    }
                }
            }
            // Without an axis the TNC keeps the previous one.
            _ => previous,
        }
    };
    let allowed = &cfg.parameters.tool_axes;
    if !allowed.contains(&axis) {
        let names: Vec<String> = allowed.iter().map(ToString::to_string).collect();
        let written = axis_word.is_some_and(|w| {
            let w = w.to_ascii_uppercase();
            ProbeAxis::from_name(&w).is_some() || (iso && ["G17", "G18", "G19"].contains(&&*w))
        });
        let how = if written {
            ""
        } else {
            " (no axis written: the previous one, or Z)"
        };
        err(
            diags,
            line,
            format!(
                "TOOL CALL: tool axis {axis}{how}: machine {} has no spindle along {axis}; its [cycles] tool_axes are {} ({})",
                cfg.machine.name,
                names.join(", "),
                cfg.machine.path.display()
            ),
        );
        return None;
    }
    let known = || {
        cfg.probes
            .iter()
            .map(|p| format!("\"{}\"", p.name))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let probe = match &tool {
        ToolRef::Name(name) => cfg.probe(name).cloned().or_else(|| {
            err(
                diags,
                line,
                format!(
                    "TOOL CALL \"{name}\": no probe of that name in the probe table (known: {})",
                    known()
                ),
            );
            None
        })?,
        // Tool numbers index the probe table's rows (its NO column), from 1.
        ToolRef::Number(n) => match n.checked_sub(1).and_then(|i| cfg.probes.get(i)) {
            Some(p) => p.clone(),
            None => {
                err(
                    diags,
                    line,
                    format!(
                        "TOOL CALL {n}: the probe table has {} row(s) (known: {})",
                        cfg.probes.len(),
                        known()
                    ),
                );
                return None;
            }
        },
    };
    let call = ToolCall { line, probe, axis };
    st.tool = Some(call.clone());
    Some(call)
}

enum ToolRef {
    Name(String),
    Number(usize),
}

/// One `Qnnn=value` as written.
struct Assignment<'a> {
    name: String,
    raw: &'a str,
    line: usize,
    comment: Option<&'a str>,
}

/// Splits `Q263=+0 Q264=+0 QS400="1-1"` into assignments; the line's comment goes to
/// its last assignment.
fn assignments<'a>(
    pl: &ParamLine<'a>,
    broken: &mut Vec<String>,
    diags: &mut Vec<Diagnostic>,
) -> Vec<Assignment<'a>> {
    let mut out = Vec::new();
    let mut s = pl.code.trim_start();
    while !s.is_empty() {
        let name_end = s
            .find(|c: char| c == '=' || c.is_whitespace())
            .unwrap_or(s.len());
        let name = s[..name_end].to_ascii_uppercase();
        let valid_name = name
            .strip_prefix("QS")
            .or_else(|| name.strip_prefix('Q'))
            .is_some_and(|d| !d.is_empty() && d.bytes().all(|b| b.is_ascii_digit()));
        let after = s[name_end..].trim_start();
        let Some(value_part) = after.strip_prefix('=').filter(|_| valid_name) else {
            if valid_name {
                broken.push(name);
            }
            let shown = s.split_whitespace().next().unwrap_or(s);
            err(
                diags,
                pl.no,
                format!("{shown}: expected Qnnn=value or QSnnn=\"text\""),
            );
            return out;
        };
        let v = value_part.trim_start();
        let (raw, rest) = if let Some(q) = v.strip_prefix('"') {
            match q.find('"') {
                Some(end) => (&v[..end + 2], &v[end + 2..]),
                None => {
                    broken.push(name.clone());
                    err(
                        diags,
                        pl.no,
                        format!("{name}={v}: unterminated string (expected {name}=\"text\")"),
                    );
                    return out;
                }
            }
        } else {
            let end = v.find(char::is_whitespace).unwrap_or(v.len());
            (&v[..end], &v[end..])
        };
        out.push(Assignment {
            name,
            raw,
            line: pl.no,
            comment: None,
        });
        s = rest.trim_start();
    }
    if let Some(last) = out.last_mut() {
        last.comment = pl.comment.filter(|c| !c.is_empty());
    }
    out
}

fn cycle(
    rb: &RawBlock,
    table: &'static CycleTable,
    title: String,
    inline: Option<&str>,
    st: &State,
    cfg: &CyclesConfig,
    diags: &mut Vec<Diagnostic>,
) -> Statement {
    let line = rb.head.no;
    let before = diags.len();
    let mut lines: Vec<ParamLine> = Vec::new();
    if let Some(code) = inline.filter(|c| !c.is_empty()) {
        lines.push(ParamLine {
            no: line,
            code,
            comment: rb.head.comment,
        });
    }
    lines.extend(rb.body.iter().copied());

    let mut params: BTreeMap<String, Param> = BTreeMap::new();
    // Written ones, valid or not: an invalid value is not also "missing".
    let mut written: Vec<String> = Vec::new();
    let mut deferred = false;
    for pl in &lines {
        for a in assignments(pl, &mut written, diags) {
            let Some(spec) = table.param(&a.name) else {
                err(
                    diags,
                    a.line,
                    format!(
                        "{}={}: unknown parameter for {table} (allowed: {})",
                        a.name,
                        a.raw,
                        table.names().join(" ")
                    ),
                );
                continue;
            };
            if let Some(first) = params.get(&a.name) {
                err(
                    diags,
                    a.line,
                    format!(
                        "{}={}: given twice (first on line {})",
                        a.name, a.raw, first.line
                    ),
                );
                continue;
            }
            written.push(a.name.clone());
            // `Q407=+Q5`: the value is the parameter's when the block runs.
            if matches!(spec.kind, Kind::Number { .. }) && is_param_ref(a.raw) {
                deferred = true;
                continue;
            }
            if let Some(value) = resolve(spec, &a, st.unit, cfg, diags) {
                params.insert(a.name.clone(), value);
            }
        }
    }
    fill_defaults(rb, table, &mut params, &written, diags);
    let Some(tool) = st.tool.clone() else {
        err(
            diags,
            line,
            format!("{table}: no TOOL CALL of a touch probe before this cycle"),
        );
        return Statement::Other(rb.head.code.to_string());
    };
    if diags.len() > before {
        return Statement::Other(rb.head.code.to_string());
    }
    if deferred {
        return Statement::Deferred(Box::new(DeferredCycle {
            cycle: table.number,
            line,
            block: rb.head.number.unwrap_or(line as u32),
            last_line: rb.last_line,
            source: String::new(),
            unit: st.unit,
            tool,
        }));
    }
    let kind = match table.number {
        431 => PlaneParams::from_params(&params, st.unit).map(CycleKind::MeasurePlane),
        444 => Probing3dParams::from_params(&params, st.unit).map(CycleKind::Probing3d),
        451 => KinematicsParams::from_params(&params, st.unit).map(CycleKind::MeasureKinematics),
        _ => SaveParams::from_params(&params, st.unit).map(CycleKind::SaveKinematics),
    };
    match kind {
        Ok(kind) => Statement::Cycle(Box::new(CycleCall {
            head: CycleBlock {
                cycle: table.number,
                title,
                line,
                block: rb.head.number.unwrap_or(line as u32),
                params,
                tool,
            },
            kind,
        })),
        Err(problems) => {
            diags.extend(problems);
            Statement::Other(rb.head.code.to_string())
        }
    }
}

/// Left-out parameters take the table's default; a missing required one is an error
/// (with a hint when the block ended early, a `~` forgotten).
fn fill_defaults(
    rb: &RawBlock,
    table: &'static CycleTable,
    params: &mut BTreeMap<String, Param>,
    written: &[String],
    diags: &mut Vec<Diagnostic>,
) {
    let line = rb.head.no;
    let mut missing = Vec::new();
    for spec in table.params {
        if params.contains_key(spec.name) || written.iter().any(|w| w == spec.name) {
            continue;
        }
        let value = match spec.default {
            ParamDefault::Required => {
                missing.push(spec);
                continue;
            }
            ParamDefault::Number(v) => Value::Number(v),
            ParamDefault::Text(s) => Value::Text(s.to_string()),
        };
        params.insert(
            spec.name.to_string(),
            Param {
                value,
                origin: Origin::Default,
                line,
            },
        );
    }
    if !missing.is_empty() {
        let hint = if rb.open {
            String::new()
        } else {
            format!(
                " (the block ends at line {}; is a \"~\" missing there?)",
                rb.last_line
            )
        };
        for spec in missing {
            err(
                diags,
                line,
                format!(
                    "{table}: missing required parameter {} ({}){hint}",
                    spec.name, spec.title
                ),
            );
        }
    }
}

fn resolve(
    spec: &ParamSpec,
    a: &Assignment,
    unit: LengthUnit,
    cfg: &CyclesConfig,
    diags: &mut Vec<Diagnostic>,
) -> Option<Param> {
    let shown = format!("{}={}", a.name, a.raw);
    let title = a.comment.unwrap_or(spec.title);
    let fail = |diags: &mut Vec<Diagnostic>, what: String| {
        err(diags, a.line, format!("{shown}: {what}"));
        None
    };
    let param = |value, origin| Param {
        value,
        origin,
        line: a.line,
    };
    match spec.kind {
        Kind::Text { max_len } => {
            let Some(text) = a.raw.strip_prefix('"').and_then(|r| r.strip_suffix('"')) else {
                return fail(
                    diags,
                    format!("{title}: expected a string in quotes, {}=\"...\"", a.name),
                );
            };
            let len = text.chars().count();
            if len > max_len {
                return fail(
                    diags,
                    format!("{title}: string of {len} characters is too long (at most {max_len})"),
                );
            }
            Some(param(Value::Text(text.to_string()), Origin::Written))
        }
        Kind::Number {
            min,
            max,
            integer,
            unit: quantity,
        } => {
            let word = a.raw.to_ascii_uppercase();
            let k = spec.keywords;
            match word.as_str() {
                "PREDEF" | "FMAX" | "FAUTO" => {
                    let allowed = match word.as_str() {
                        "PREDEF" => k.predef,
                        "FMAX" => k.fmax,
                        _ => k.fauto,
                    };
                    if !allowed {
                        return fail(
                            diags,
                            format!("{title} does not take {word} (allowed {})", spec.allowed()),
                        );
                    }
                    match word.as_str() {
                        "FMAX" => Some(param(Value::Fmax, Origin::Written)),
                        "FAUTO" => Some(param(Value::Fauto, Origin::Written)),
                        _ => {
                            // PREDEF values come from the machine configuration, in mm.
                            let Some(&v) = cfg.parameters.predef.get(spec.name) else {
                                return fail(
                                    diags,
                                    format!(
                                        "{title}: PREDEF but the machine configuration has no {} in [cycles.predef]",
                                        spec.name
                                    ),
                                );
                            };
                            if !(min..=max).contains(&v) {
                                return fail(
                                    diags,
                                    format!("{title}: PREDEF value {v} out of range {min}..{max}"),
                                );
                            }
                            Some(param(Value::Number(v), Origin::Predef))
                        }
                    }
                }
                _ => {
                    if a.raw.starts_with('"') {
                        return fail(
                            diags,
                            format!(
                                "{title}: expected a number, not a string (allowed {})",
                                spec.allowed()
                            ),
                        );
                    }
                    let Some(v) = parse_decimal(a.raw) else {
                        return fail(
                            diags,
                            format!(
                                "{title}: malformed number (expected a signed decimal such as +12.5; allowed {})",
                                spec.allowed()
                            ),
                        );
                    };
                    // The ranges are the TNC's in mm (mm/min): an inch value is held
                    // to them after the conversion.
                    let (mm, converted) = match unit {
                        LengthUnit::Mm => (v, String::new()),
                        LengthUnit::Inch if quantity.inch_factor() != 1.0 => {
                            let mm = v * quantity.inch_factor();
                            (mm, format!(" ({v} in an INCH program is {mm} in mm)"))
                        }
                        LengthUnit::Inch => (v, String::new()),
                    };
                    if !(min..=max).contains(&mm) || (integer && v.fract() != 0.0) {
                        return fail(
                            diags,
                            format!("{title} out of range {}{converted}", spec.allowed()),
                        );
                    }
                    Some(param(Value::Number(mm), Origin::Written))
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decimals() {
        for (s, v) in [
            ("+0", 0.0),
            ("-12.5", -12.5),
            ("5", 5.0),
            (".5", 0.5),
            ("+1e6", 1e6),
            ("3.", 3.0),
        ] {
            assert_eq!(parse_decimal(s), Some(v), "{s}");
        }
        for s in [
            "", "+", "1.2.3", "abc", "1e", "inf", "NaN", "+-1", "1,5", "Q1",
        ] {
            assert_eq!(parse_decimal(s), None, "{s}");
        }
    }

    #[test]
    fn line_split() {
        let l = split_line(3, "  12 TCH PROBE 444 ANTASTEN 3D ~");
        assert_eq!(
            (l.number, l.code, l.cont),
            (Some(12), "TCH PROBE 444 ANTASTEN 3D", true)
        );
        let l = split_line(4, "QS400=\"a;b\" ;TOLERANZ ~");
        assert_eq!(
            (l.code, l.comment, l.cont),
            ("QS400=\"a;b\"", Some("TOLERANZ"), true)
        );
        let l = split_line(5, "N20 G444 Q263=+0 *");
        assert_eq!((l.number, l.code), (Some(20), "G444 Q263=+0"));
    }
}
