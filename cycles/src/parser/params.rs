//! A cycle's parameter lines: `Qnnn=value` assignments, each checked against the
//! cycle's parameter table (range, unit, PREDEF, strings), defaults for those left out.

use super::block::{ParamLine, RawBlock};
use super::state::{err, State};
use crate::cycle431::PlaneParams;
use crate::cycle444::Probing3dParams;
use crate::cycle450::SaveParams;
use crate::cycle451::KinematicsParams;
use crate::cycle460::CalibrationParams;
use crate::cycle_block::{CycleBlock, Origin, Param, Value};
use crate::cycles_config::CyclesConfig;
use crate::diagnostic::Diagnostic;
use crate::formula::parse_decimal;
use crate::length_unit::LengthUnit;
use crate::params::{CycleTable, Default as ParamDefault, Kind, ParamSpec};
use crate::program::{CycleCall, CycleKind, DeferredCycle, Statement};
use std::collections::BTreeMap;

/// `+Q5`, `-QL2`, `QR1`: a numeric parameter as a cycle parameter's value.
pub(super) fn is_param_ref(raw: &str) -> bool {
    let r = raw.strip_prefix(['+', '-']).unwrap_or(raw);
    crate::q_params::QName::parse(r).is_some_and(|n| !n.is_text())
}

/// `QS5`: a string parameter as a string cycle parameter's value (`QS400=QS5`).
fn is_text_ref(raw: &str) -> bool {
    crate::q_params::QName::parse(raw).is_some_and(|n| n.is_text())
}

/// One `Qnnn=value` as written.
pub(super) struct Assignment<'a> {
    pub(super) name: String,
    pub(super) raw: &'a str,
    pub(super) line: usize,
    pub(super) comment: Option<&'a str>,
}

/// Splits `Q263=+0 Q264=+0 QS400="1-1"` into assignments; the line's comment goes to
/// its last assignment.
pub(super) fn assignments<'a>(
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

pub(super) fn cycle(
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
            // `Q407=+Q5`, `QS400=QS1`: the value is the parameter's when the block runs.
            let deferrable = match spec.kind {
                Kind::Number { .. } => is_param_ref(a.raw),
                Kind::Text { .. } => is_text_ref(a.raw),
            };
            if deferrable {
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
        460 => CalibrationParams::from_params(&params, st.unit).map(CycleKind::CalibrateProbe),
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
pub(super) fn fill_defaults(
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

pub(super) fn resolve(
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
                    format!(
                        "{title}: expected a string in quotes, {}=\"...\", or a string parameter, {}=QSn",
                        a.name, a.name
                    ),
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
