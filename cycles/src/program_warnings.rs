//! What `check` and `run` warn of in a program without refusing it: block numbers
//! out of order or repeated (the TNC renumbers), and in an INCH program a length a
//! cycle measured in mm used as a length ([`mm_in_inch_warnings`]).

use crate::formula::Expr;
use crate::program::{Block, Program, Statement};
use crate::q_params::{QName, QParams};
use std::collections::BTreeMap;

/// Whether a formula's value is a length in mm that a cycle measured: it reads a
/// parameter that holds one ([`QParams::is_mm`]) and does not divide by 25.4 (the
/// conversion to inches).
pub(crate) fn reads_mm(formula: &crate::formula::Formula, params: &QParams) -> bool {
    use crate::formula::{BinOp, Formula};
    fn divides_by_inch(e: &Expr) -> bool {
        match e {
            Expr::Bin(BinOp::Div, a, b) => {
                matches!(**b, Expr::Num(v) if (v - 25.4).abs() < 1e-9)
                    || divides_by_inch(a)
                    || divides_by_inch(b)
            }
            Expr::Bin(_, a, b) => divides_by_inch(a) || divides_by_inch(b),
            Expr::Neg(e) | Expr::Func(_, e) => divides_by_inch(e),
            _ => false,
        }
    }
    let Formula::Number(e) = formula else {
        return false;
    };
    let mut read = Vec::new();
    e.params(&mut read);
    read.iter().any(|n| params.is_mm(*n)) && !divides_by_inch(e)
}

/// The warning for a block of an INCH program that uses a length a cycle measured
/// (in mm) as a length: an `L` block's X/Y/Z, or a cycle parameter of unit length
/// given as a parameter. `params`: as `check` has them at the block.
pub fn mm_in_inch_warnings(
    program: &Program,
    block: &Block,
    params: &QParams,
) -> Vec<crate::diagnostic::Diagnostic> {
    use crate::length_unit::LengthUnit;
    let mut out = Vec::new();
    if program.unit != LengthUnit::Inch {
        return out;
    }
    let mut warn = |line: usize, name: QName, used: &str| {
        out.push(crate::diagnostic::Diagnostic {
            line,
            message: format!(
                "warning: {name} is in mm (the cycle reports in mm); this INCH program reads it as inches ({used}): convert it first (Qn = {name} / 25.4)"
            ),
        })
    };
    // `+Q1`, `-QL2`: the parameter a value names.
    let named = |value: &str| {
        let v = value.trim_start_matches(['+', '-']);
        QName::parse(&v.to_ascii_uppercase()).filter(|n| !n.is_text() && params.is_mm(*n))
    };
    match &block.statement {
        Statement::Other(code) => {
            let mut words = code.split_whitespace();
            if !words.next().is_some_and(|w| w.eq_ignore_ascii_case("L")) {
                return out;
            }
            for w in words {
                let mut chars = w.chars();
                let axis = chars.next().map(|c| c.to_ascii_uppercase());
                if matches!(axis, Some('X' | 'Y' | 'Z')) {
                    if let Some(n) = named(chars.as_str()) {
                        warn(block.line, n, &format!("L {w}"));
                    }
                }
            }
        }
        Statement::Deferred(d) => {
            let Some(table) = crate::params::table(d.cycle) else {
                return out;
            };
            for (i, text) in d.source.lines().enumerate() {
                let code = text.split(';').next().unwrap_or("");
                for w in code.split_whitespace() {
                    let Some((param, value)) = w.split_once('=') else {
                        continue;
                    };
                    let length = table.param(&param.to_ascii_uppercase()).is_some_and(|p| {
                        matches!(
                            p.kind,
                            crate::params::Kind::Number {
                                unit: crate::params::Unit::Length,
                                ..
                            }
                        )
                    });
                    if let (true, Some(n)) = (length, named(value.trim_end_matches('~'))) {
                        warn(d.line + i, n, &format!("cycle {} {w}", d.cycle));
                    }
                }
            }
        }
        _ => {}
    }
    out
}

/// Block numbers that go backwards or repeat, each a warning at its line: the TNC
/// renumbers the blocks of a program as it loads it, so they run in the order they
/// stand; the number probebridge reports a block by is the one written.
pub fn block_number_warnings(program: &Program) -> Vec<crate::diagnostic::Diagnostic> {
    let mut out = Vec::new();
    let mut last: Option<(u32, usize)> = None;
    let mut seen: BTreeMap<u32, usize> = BTreeMap::new();
    for b in &program.blocks {
        let Some(n) = b.number else { continue };
        let message = if let Some(first) = seen.get(&n) {
            Some(format!(
                "warning: block number {n} again (first on line {first}): the blocks run in the order they stand (the TNC renumbers them)"
            ))
        } else {
            last.filter(|(before, _)| n < *before).map(|(before, at)| {
                format!(
                    "warning: block number {n} after {before} (line {at}): out of order; the blocks run in the order they stand (the TNC renumbers them)"
                )
            })
        };
        if let Some(message) = message {
            out.push(crate::diagnostic::Diagnostic {
                line: b.line,
                message,
            });
        }
        seen.entry(n).or_insert(b.line);
        last = Some((n, b.line));
    }
    out
}
