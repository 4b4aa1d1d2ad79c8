//! The program frame (`BEGIN PGM`/`END PGM`, ISO `%NAME G71`) and `TOOL CALL`: the
//! probe from the probe table and its axis.

use super::lexer::upper_words;
use super::state::{err, State};
use crate::cycle_block::ToolCall;
use crate::cycles_config::CyclesConfig;
use crate::diagnostic::Diagnostic;
use crate::length_unit::LengthUnit;
use crate::probe_axis::ProbeAxis;
use crate::program::Statement;

/// `NAME MM|INCH` after `BEGIN PGM` / `END PGM`; the name keeps its case.
pub(super) fn pgm_name_unit(
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

pub(super) fn check_end(
    st: &State,
    name: &str,
    unit: LengthUnit,
    line: usize,
    diags: &mut Vec<Diagnostic>,
) {
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

pub(super) fn unit_word(u: LengthUnit) -> &'static str {
    match u {
        LengthUnit::Mm => "MM",
        LengthUnit::Inch => "INCH",
    }
}

/// ISO program start `%NAME G71` (mm) / `G70` (inch), and its end line.
pub(super) fn iso_pgm(
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
pub(super) fn iso_tool_call(code: &str) -> Option<&str> {
    let rest = code.strip_prefix(['T', 't'])?;
    let r = rest.trim_start();
    (r.starts_with('"') || r.starts_with(|c: char| c.is_ascii_digit())).then_some(r)
}

/// `"NAME" Z ...` / `1 Z ...` (conversational) or `"NAME" G17` / `1 G17` (ISO).
pub(super) fn tool_call(
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

pub(super) enum ToolRef {
    Name(String),
    Number(usize),
}
