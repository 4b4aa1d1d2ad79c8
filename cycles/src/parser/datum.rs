//! Datum blocks: `CYCL DEF 7` DATUM SHIFT, `TRANS DATUM`, `G54`, and cycle 247 DATUM
//! SETTING with its preset number checked against the preset table.

use super::block::{ParamLine, RawBlock};
use super::params::assignments;
use super::state::{err, State};
use crate::cycles_config::CyclesConfig;
use crate::datum::DatumBlock;
use crate::diagnostic::Diagnostic;
use crate::formula::parse_decimal;
use crate::length_unit::LengthUnit;
use crate::program::Statement;

/// `CYCL DEF 247 DATUM SETTING` (Q339 on its lines), `CYCL DEF 7.0 DATUM SHIFT` and its
/// `CYCL DEF 7.1 X+10` blocks; other `CYCL DEF`s cannot run here.
pub(super) fn cycl_def(
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
            // A touch-probe cycle under CYCL DEF: the TNC writes those TCH PROBE.
            let hint = match number.parse::<u16>().ok().and_then(crate::params::table) {
                Some(t) => format!(
                    "; a touch-probe cycle is written TCH PROBE {} {}",
                    t.number, t.name
                ),
                None => String::new(),
            };
            err(
                diags,
                line,
                format!("CYCL DEF {number}: not a cycle probebridge can run (it runs CYCL DEF 7 DATUM SHIFT and CYCL DEF 247 DATUM SETTING){hint}"),
            );
            Statement::Other(code.to_string())
        }
    }
}

/// `TRANS DATUM AXIS X+10 Y+5 Z+0` (axes left out: 0) and `TRANS DATUM RESET`.
pub(super) fn trans_datum(
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
pub(super) fn shift_words(
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
pub(super) fn datum_setting(
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
