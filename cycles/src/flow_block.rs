//! The blocks of Q-parameter programming as written: assignments (`Q1 = ...`,
//! `FN 0..5`, string formulas), labels (`LBL 5`, `LBL "NAME"`, `LBL 0`), jumps
//! (`FN 9..12`), `CALL LBL n` (a subprogram), `CALL LBL n REP k` (a section repeat) and
//! `FN 14: ERROR = n`. [`crate::program_flow`] runs them.

use crate::formula::{parse_formula, BinOp, Expr, Formula, Func};
use crate::q_params::QName;
use std::fmt;

/// One block of Q-parameter programming.
#[derive(Clone, Debug, PartialEq)]
pub enum FlowBlock {
    Assign(Assignment),
    Label(Label),
    Jump(Jump),
    Call(CallLabel),
    /// `FN 14: ERROR = n`.
    Stop(u32),
}

/// A label: `LBL 5` or `LBL "NAME"`. `LBL 0` marks the end of a subprogram.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Label {
    Number(u32),
    Name(String),
}

impl fmt::Display for Label {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Label::Number(n) => write!(f, "LBL {n}"),
            Label::Name(s) => write!(f, "LBL \"{s}\""),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Compare {
    /// FN 9: IF .. EQU .. GOTO
    Equ,
    /// FN 10: IF .. NE .. GOTO
    Ne,
    /// FN 11: IF .. GT .. GOTO
    Gt,
    /// FN 12: IF .. LT .. GOTO
    Lt,
}

impl Compare {
    fn word(self) -> &'static str {
        match self {
            Compare::Equ => "EQU",
            Compare::Ne => "NE",
            Compare::Gt => "GT",
            Compare::Lt => "LT",
        }
    }

    pub(crate) fn holds(self, a: f64, b: f64) -> bool {
        match self {
            Compare::Equ => a == b,
            Compare::Ne => a != b,
            Compare::Gt => a > b,
            Compare::Lt => a < b,
        }
    }
}

/// `FN 11: IF +Q141 GT +0.01 GOTO LBL 99`.
#[derive(Clone, Debug, PartialEq)]
pub struct Jump {
    pub left: Expr,
    pub compare: Compare,
    pub right: Expr,
    pub target: Label,
}

/// `CALL LBL 5` / `CALL LBL 5 REP 3`, as the TNC runs them: without REP a subprogram
/// call (the blocks from `LBL 5` to its `LBL 0`, wherever the label stands, then back
/// after the call); with REP and the label before the call a program-section repeat
/// (the blocks from the label to the call `rep` more times); with REP and the label
/// after the call the subprogram, called `1 + rep` times.
#[derive(Clone, Debug, PartialEq)]
pub struct CallLabel {
    pub target: Label,
    /// `REP k` as written; `None` without REP.
    pub rep: Option<u32>,
}

impl CallLabel {
    /// A program-section repeat: REP given and the label (at block `target`) before
    /// the call (at block `call`); anything else calls a subprogram.
    pub fn is_section_repeat(&self, target: usize, call: usize) -> bool {
        self.rep.is_some() && target < call
    }
}

/// `Q10 = Q141 * 1000`, `FN 0: Q1 = +5`, `QS0 = SUBSTR ( ... )`.
#[derive(Clone, Debug, PartialEq)]
pub struct Assignment {
    pub target: QName,
    pub formula: Formula,
}

/// The deepest subprogram nesting (the TNC's).
pub const MAX_NESTING: usize = 19;

/// Parses a block of Q-parameter programming; `None` when `code` is none.
pub fn parse_flow(code: &str) -> Option<Result<FlowBlock, String>> {
    let upper = code.to_ascii_uppercase();
    let words: Vec<&str> = upper.split_whitespace().collect();
    match words.first().copied() {
        Some("LBL") => return Some(parse_label(code["LBL".len()..].trim()).map(FlowBlock::Label)),
        Some("CALL") if words.get(1) == Some(&"LBL") => {
            let rest = code.trim_start()[4..].trim_start()[3..].trim();
            return Some(parse_call(rest));
        }
        Some("DECLARE") if words.get(1) == Some(&"STRING") => {
            let rest = skip_words(code, 2);
            return Some(parse_assignment(rest).and_then(|a| match a {
                Some(a) if a.target.is_text() => Ok(FlowBlock::Assign(a)),
                _ => Err("DECLARE STRING: expected DECLARE STRING QSn = \"text\"".into()),
            }));
        }
        Some("STRING") if words.get(1) == Some(&"FORMULA") => {
            let rest = skip_words(code, 2);
            return Some(parse_assignment(rest).and_then(|a| match a {
                Some(a) if a.target.is_text() => Ok(FlowBlock::Assign(a)),
                _ => Err("STRING FORMULA: expected STRING FORMULA QSn = ...".into()),
            }));
        }
        _ => {}
    }
    if let Some(rest) = upper.strip_prefix("FN") {
        let digits: String = rest
            .trim_start()
            .chars()
            .take_while(char::is_ascii_digit)
            .collect();
        if !digits.is_empty() {
            let after_digits = rest.trim_start()[digits.len()..].trim_start();
            if let Some(body_upper) = after_digits.strip_prefix(':') {
                // The same text with its case (strings keep it).
                let body = &code[code.len() - body_upper.len()..];
                return Some(parse_fn(&digits, body.trim()));
            }
        }
    }
    match parse_assignment(code) {
        Ok(Some(a)) => Some(Ok(FlowBlock::Assign(a))),
        Ok(None) => None,
        Err(e) => Some(Err(e)),
    }
}

fn skip_words(code: &str, n: usize) -> &str {
    let mut s = code.trim_start();
    for _ in 0..n {
        s = s
            .find(char::is_whitespace)
            .map_or("", |i| s[i..].trim_start());
    }
    s
}

/// `Qn = formula`; `None` when `code` does not start with a parameter and `=`.
fn parse_assignment(code: &str) -> Result<Option<Assignment>, String> {
    let code = code.trim();
    let (target, len) = match QName::parse_prefix(code) {
        None => return Ok(None),
        Some(r) => r?,
    };
    let Some(rhs) = code[len..].trim_start().strip_prefix('=') else {
        return Ok(None);
    };
    let formula = parse_formula(target, rhs.trim()).map_err(|e| format!("{target} = ...: {e}"))?;
    Ok(Some(Assignment { target, formula }))
}

fn parse_label(s: &str) -> Result<Label, String> {
    if let Some(q) = s.strip_prefix('"') {
        let name = q
            .strip_suffix('"')
            .filter(|n| !n.is_empty() && !n.contains('"'))
            .ok_or_else(|| format!("LBL {s}: expected LBL \"NAME\""))?;
        return Ok(Label::Name(name.to_string()));
    }
    match s.parse::<u32>() {
        Ok(n) if n <= 65535 => Ok(Label::Number(n)),
        _ => Err(format!(
            "LBL {s}: expected a label number 0..65535 or a name in quotes"
        )),
    }
}

fn parse_call(rest: &str) -> Result<FlowBlock, String> {
    let upper = rest.to_ascii_uppercase();
    let (label_part, rep) = match upper.find(" REP") {
        Some(i) => {
            let r = rest[i + 4..].trim();
            // The TNC shows `REP 2/2` (repeats left / programmed).
            let first = r.split('/').next().unwrap_or("").trim();
            let rep = first
                .parse::<u32>()
                .ok()
                .filter(|n| *n <= 65534)
                .ok_or_else(|| {
                    format!("CALL LBL: REP {r}: expected a number of repeats 0..65534")
                })?;
            (rest[..i].trim(), Some(rep))
        }
        None => (rest.trim(), None),
    };
    let target = parse_label(label_part)?;
    if target == Label::Number(0) {
        return Err("CALL LBL 0: label 0 only ends a subprogram and cannot be called".into());
    }
    Ok(FlowBlock::Call(CallLabel { target, rep }))
}

fn parse_fn(number: &str, body: &str) -> Result<FlowBlock, String> {
    let n: u32 = number
        .parse()
        .map_err(|_| format!("FN {number}: not a function"))?;
    match n {
        0..=5 => {
            let a = parse_assignment(body)?
                .ok_or_else(|| format!("FN {n}: expected FN {n}: Qn = ..."))?;
            let Formula::Number(e) = &a.formula else {
                return Err(format!("FN {n}: {} is a string parameter", a.target));
            };
            let operand = |e: &Expr| match e {
                Expr::Neg(x) => matches!(**x, Expr::Num(_) | Expr::Param(_)),
                Expr::Num(_) | Expr::Param(_) => true,
                _ => false,
            };
            let ok = match (n, e) {
                (0, e) => operand(e),
                (1..=4, Expr::Bin(op, a, b)) => {
                    let want = [BinOp::Add, BinOp::Sub, BinOp::Mul, BinOp::Div][n as usize - 1];
                    *op == want && operand(a) && operand(b)
                }
                (5, Expr::Func(Func::Sqrt, a)) => operand(a),
                _ => false,
            };
            if !ok {
                let form = ["Qn = a", "Qn = a + b", "Qn = a - b", "Qn = a * b", "Qn = a / b", "Qn = SQRT a"][n as usize];
                return Err(format!(
                    "FN {n}: expected FN {n}: {form} (a, b: a number or a parameter; formulas are written Qn = ... without FN)"
                ));
            }
            Ok(FlowBlock::Assign(a))
        }
        9..=12 => parse_jump(n, body).map(FlowBlock::Jump),
        14 => {
            let upper = body.to_ascii_uppercase();
            let v = upper
                .strip_prefix("ERROR")
                .and_then(|r| r.trim_start().strip_prefix('='))
                .map(str::trim)
                .ok_or_else(|| "FN 14: expected FN 14: ERROR = n".to_string())?;
            match v.trim_start_matches('+').parse::<u32>() {
                Ok(e) if e <= 65535 => Ok(FlowBlock::Stop(e)),
                _ => Err(format!("FN 14: ERROR = {v}: expected an error number 0..65535")),
            }
        }
        16 => Err("FN 16: F-PRINT does not run here (probebridge writes its own protocols and --json; see docs/q-parameters.md)".into()),
        _ => Err(format!(
            "FN {n}: not a function probebridge runs (it runs FN 0..5, FN 9..12 and FN 14, and formulas Qn = ...)"
        )),
    }
}

fn parse_jump(n: u32, body: &str) -> Result<Jump, String> {
    let compare = [Compare::Equ, Compare::Ne, Compare::Gt, Compare::Lt][n as usize - 9];
    let usage = format!(
        "FN {n}: expected FN {n}: IF a {} b GOTO LBL n",
        compare.word()
    );
    let upper = body.to_ascii_uppercase();
    let rest = upper.strip_prefix("IF").ok_or_else(|| usage.clone())?;
    let words: Vec<&str> = body[2..].split_whitespace().collect();
    let uwords: Vec<&str> = rest.split_whitespace().collect();
    let cmp = uwords
        .iter()
        .position(|w| ["EQU", "NE", "GT", "LT"].contains(w))
        .ok_or_else(|| usage.clone())?;
    if uwords[cmp] != compare.word() {
        return Err(format!(
            "FN {n}: compares with {}, not {} ({usage})",
            compare.word(),
            uwords[cmp]
        ));
    }
    let goto = uwords
        .iter()
        .position(|w| *w == "GOTO")
        .filter(|g| *g > cmp && uwords.get(g + 1) == Some(&"LBL"))
        .ok_or_else(|| usage.clone())?;
    // The TNC's jumps compare numbers; texts are compared with STRCOMP first.
    let string_operand = words[..cmp]
        .iter()
        .chain(&words[cmp + 1..goto])
        .map(|w| w.trim_start_matches(['+', '-']))
        .find(|w| {
            w.starts_with('"') || QName::parse(&w.to_ascii_uppercase()).is_some_and(|q| q.is_text())
        });
    if let Some(w) = string_operand {
        return Err(format!(
            "FN {n}: {w} is a string, and FN 9..12 compare numbers: compare texts with Qn = STRCOMP ( SRC_QSa SEA_QSb ) (0: the same, -1: before, +1: after) and jump on Qn"
        ));
    }
    let left =
        crate::formula::parse_expr(&words[..cmp].join(" ")).map_err(|e| format!("FN {n}: {e}"))?;
    let right = crate::formula::parse_expr(&words[cmp + 1..goto].join(" "))
        .map_err(|e| format!("FN {n}: {e}"))?;
    let target = parse_label(&words[goto + 2..].join(" "))?;
    if target == Label::Number(0) {
        return Err(format!(
            "FN {n}: GOTO LBL 0: label 0 only ends a subprogram"
        ));
    }
    Ok(Jump {
        left,
        compare,
        right,
        target,
    })
}
