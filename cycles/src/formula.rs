//! Q-parameter formulas as the TNC writes them: `Q1 = ( Q2 + Q3 ) / 2`,
//! `Q10 = SQRT ( SQ Q1 + SQ Q2 )`, and string formulas
//! `QS1 = "X=" || TOCHAR ( DAT+Q1 DECIMALS3 )`, `QS0 = SUBSTR ( SRC_QS146 BEG0 LEN10 )`.
//!
//! Precedence as on the TNC: a sign belongs to its operand, a function (SQ, SQRT, SIN,
//! COS, TAN, ASIN, ACOS, ATAN, ABS, INT, FRAC, SGN) takes the operand right after it
//! (`SIN 30 ^ 2` is `(SIN 30) ^ 2`), then `^`, then `*` `/`, then `+` `-`; operators of
//! one level from left to right. Angles are in degrees.

use crate::q_params::{QKind, QName, QValue, MAX_TEXT};
use std::fmt;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Func {
    Sq,
    Sqrt,
    Sin,
    Cos,
    Tan,
    Asin,
    Acos,
    Atan,
    Abs,
    Int,
    Frac,
    Sgn,
}

impl Func {
    const ALL: [(&'static str, Func); 12] = [
        ("SQ", Func::Sq),
        ("SQRT", Func::Sqrt),
        ("SIN", Func::Sin),
        ("COS", Func::Cos),
        ("TAN", Func::Tan),
        ("ASIN", Func::Asin),
        ("ACOS", Func::Acos),
        ("ATAN", Func::Atan),
        ("ABS", Func::Abs),
        ("INT", Func::Int),
        ("FRAC", Func::Frac),
        ("SGN", Func::Sgn),
    ];

    fn from_word(w: &str) -> Option<Func> {
        Self::ALL.iter().find(|(n, _)| *n == w).map(|(_, f)| *f)
    }

    pub fn name(self) -> &'static str {
        Self::ALL
            .iter()
            .find(|(_, f)| *f == self)
            .map_or("", |(n, _)| n)
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BinOp {
    Add,
    Sub,
    Mul,
    Div,
    Pow,
}

/// A numeric expression.
#[derive(Clone, Debug, PartialEq)]
pub enum Expr {
    Num(f64),
    Param(QName),
    Pi,
    Neg(Box<Expr>),
    Bin(BinOp, Box<Expr>, Box<Expr>),
    Func(Func, Box<Expr>),
    /// `TONUMB ( SRC_QSn )`.
    ToNumb(QName),
    /// `STRLEN ( SRC_QSn )`.
    StrLen(QName),
}

/// A string expression.
#[derive(Clone, Debug, PartialEq)]
pub enum StrExpr {
    Lit(String),
    Param(QName),
    /// `a || b || ...`.
    Concat(Vec<StrExpr>),
    /// `SUBSTR ( SRC_QSn BEGx LENy )`: `LEN` characters from `BEG` (0 = the first).
    Substr {
        src: QName,
        beg: Box<Expr>,
        len: Box<Expr>,
    },
    /// `TOCHAR ( DAT+Qn DECIMALSm )`: the number with `m` decimals (4 if left out).
    ToChar {
        dat: Box<Expr>,
        decimals: Option<Box<Expr>>,
    },
}

/// The right-hand side of an assignment.
#[derive(Clone, Debug, PartialEq)]
pub enum Formula {
    Number(Expr),
    Text(StrExpr),
}

impl Expr {
    /// Every parameter the expression reads.
    pub fn params(&self, out: &mut Vec<QName>) {
        match self {
            Expr::Num(_) | Expr::Pi => {}
            Expr::Param(n) | Expr::ToNumb(n) | Expr::StrLen(n) => out.push(*n),
            Expr::Neg(e) | Expr::Func(_, e) => e.params(out),
            Expr::Bin(_, a, b) => {
                a.params(out);
                b.params(out);
            }
        }
    }
}

// ----- lexing -----

#[derive(Clone, Debug, PartialEq)]
enum Tok {
    Num(f64),
    Name(QName),
    Str(String),
    Word(String),
    Op(char),
    Concat,
}

impl fmt::Display for Tok {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Tok::Num(v) => write!(f, "{v}"),
            Tok::Name(n) => write!(f, "{n}"),
            Tok::Str(s) => write!(f, "\"{s}\""),
            Tok::Word(w) => f.write_str(w),
            Tok::Op(c) => write!(f, "{c}"),
            Tok::Concat => f.write_str("||"),
        }
    }
}

/// Words that carry their value glued on (`BEG0`, `SRC_QS146`, `DECIMALS3`).
const GLUED: [&str; 5] = ["SRC_", "BEG", "LEN", "DAT", "DECIMALS"];

fn lex(s: &str) -> Result<Vec<Tok>, String> {
    let mut out = Vec::new();
    let b = s.as_bytes();
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        match c {
            b' ' | b'\t' => i += 1,
            b'"' => {
                let rest = &s[i + 1..];
                let end = rest
                    .find('"')
                    .ok_or_else(|| "unterminated string (a closing \" is missing)".to_string())?;
                out.push(Tok::Str(rest[..end].to_string()));
                i += end + 2;
            }
            b'|' if b.get(i + 1) == Some(&b'|') => {
                out.push(Tok::Concat);
                i += 2;
            }
            b'+' | b'-' | b'*' | b'/' | b'^' | b'(' | b')' => {
                out.push(Tok::Op(c as char));
                i += 1;
            }
            b'0'..=b'9' | b'.' => {
                let start = i;
                while i < b.len() && (b[i].is_ascii_digit() || b[i] == b'.') {
                    i += 1;
                }
                let text = &s[start..i];
                let v: f64 = text
                    .parse()
                    .ok()
                    .filter(|v: &f64| v.is_finite())
                    .ok_or_else(|| format!("{text}: not a number"))?;
                out.push(Tok::Num(v));
            }
            c if c.is_ascii_alphabetic() || c == b'_' => {
                let start = i;
                while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_') {
                    i += 1;
                }
                let word = s[start..i].to_ascii_uppercase();
                if let Some(n) = QName::parse_prefix(&word) {
                    let (n, _) = n?;
                    out.push(Tok::Name(n));
                    continue;
                }
                let glued = GLUED.iter().find(|k| {
                    word.len() > k.len()
                        && word.starts_with(*k)
                        && (word[k.len()..].bytes().all(|b| b.is_ascii_digit())
                            || QName::parse(&word[k.len()..]).is_some())
                });
                match glued {
                    Some(k) => {
                        out.push(Tok::Word(k.to_string()));
                        // The value: re-read from where the keyword ends.
                        i = start + k.len();
                    }
                    None => out.push(Tok::Word(word)),
                }
            }
            _ => {
                let ch = s[i..].chars().next().unwrap_or('?');
                return Err(format!("unexpected character '{ch}'"));
            }
        }
    }
    Ok(out)
}

// ----- parsing -----

struct Parser {
    toks: Vec<Tok>,
    pos: usize,
}

impl Parser {
    fn peek(&self) -> Option<&Tok> {
        self.toks.get(self.pos)
    }

    fn next(&mut self) -> Option<Tok> {
        let t = self.toks.get(self.pos).cloned();
        self.pos += 1;
        t
    }

    fn eat_op(&mut self, c: char) -> bool {
        if self.peek() == Some(&Tok::Op(c)) {
            self.pos += 1;
            true
        } else {
            false
        }
    }

    fn expect_op(&mut self, c: char, what: &str) -> Result<(), String> {
        if self.eat_op(c) {
            Ok(())
        } else {
            Err(format!("expected '{c}' {what}, found {}", self.found()))
        }
    }

    fn eat_word(&mut self, w: &str) -> bool {
        if matches!(self.peek(), Some(Tok::Word(x)) if x == w) {
            self.pos += 1;
            true
        } else {
            false
        }
    }

    fn found(&self) -> String {
        match self.peek() {
            Some(t) => format!("\"{t}\""),
            None => "the end of the block".to_string(),
        }
    }

    fn expr(&mut self) -> Result<Expr, String> {
        let mut left = self.term()?;
        loop {
            let op = if self.eat_op('+') {
                BinOp::Add
            } else if self.eat_op('-') {
                BinOp::Sub
            } else {
                return Ok(left);
            };
            let right = self.term()?;
            left = Expr::Bin(op, Box::new(left), Box::new(right));
        }
    }

    fn term(&mut self) -> Result<Expr, String> {
        let mut left = self.power()?;
        loop {
            let op = if self.eat_op('*') {
                BinOp::Mul
            } else if self.eat_op('/') {
                BinOp::Div
            } else {
                return Ok(left);
            };
            let right = self.power()?;
            left = Expr::Bin(op, Box::new(left), Box::new(right));
        }
    }

    fn power(&mut self) -> Result<Expr, String> {
        let mut left = self.unary()?;
        while self.eat_op('^') {
            let right = self.unary()?;
            left = Expr::Bin(BinOp::Pow, Box::new(left), Box::new(right));
        }
        Ok(left)
    }

    fn unary(&mut self) -> Result<Expr, String> {
        if self.eat_op('+') {
            return self.unary();
        }
        if self.eat_op('-') {
            return Ok(Expr::Neg(Box::new(self.unary()?)));
        }
        self.primary()
    }

    fn primary(&mut self) -> Result<Expr, String> {
        let found = self.found();
        match self.next() {
            Some(Tok::Num(v)) => Ok(Expr::Num(v)),
            Some(Tok::Name(n)) if n.is_text() => Err(format!(
                "{n} is a string where a number is expected (TONUMB ( SRC_{n} ) converts it)"
            )),
            Some(Tok::Name(n)) => Ok(Expr::Param(n)),
            Some(Tok::Op('(')) => {
                let e = self.expr()?;
                self.expect_op(')', "to close the parenthesis")?;
                Ok(e)
            }
            Some(Tok::Word(w)) if w == "PI" => Ok(Expr::Pi),
            Some(Tok::Word(w)) if w == "TONUMB" || w == "STRLEN" => {
                self.expect_op('(', &format!("after {w}"))?;
                let src = self.source(&w)?;
                self.expect_op(')', &format!("to close {w}"))?;
                Ok(if w == "TONUMB" {
                    Expr::ToNumb(src)
                } else {
                    Expr::StrLen(src)
                })
            }
            Some(Tok::Word(w)) => match Func::from_word(&w) {
                Some(f) => Ok(Expr::Func(f, Box::new(self.unary()?))),
                None => Err(format!(
                    "{w}: unknown function (known: SQ, SQRT, SIN, COS, TAN, ASIN, ACOS, ATAN, ABS, INT, FRAC, SGN, PI, TONUMB, STRLEN)"
                )),
            },
            Some(Tok::Str(_)) => Err(format!(
                "{found}: a string where a number is expected (strings go into QS parameters)"
            )),
            _ => Err(format!("expected a number, a parameter or a function, found {found}")),
        }
    }

    /// `SRC_QSn`.
    fn source(&mut self, func: &str) -> Result<QName, String> {
        if self.eat_word("SRC_") {
            if let Some(Tok::Name(n)) = self.peek().cloned() {
                if n.kind == QKind::QS {
                    self.pos += 1;
                    return Ok(n);
                }
            }
        }
        Err(format!(
            "{func}: expected SRC_QSn (the string parameter to read), found {}",
            self.found()
        ))
    }

    fn text(&mut self) -> Result<StrExpr, String> {
        let mut parts = vec![self.text_atom()?];
        while self.peek() == Some(&Tok::Concat) {
            self.pos += 1;
            parts.push(self.text_atom()?);
        }
        Ok(if parts.len() == 1 {
            parts.remove(0)
        } else {
            StrExpr::Concat(parts)
        })
    }

    fn text_atom(&mut self) -> Result<StrExpr, String> {
        let found = self.found();
        match self.next() {
            Some(Tok::Str(s)) => Ok(StrExpr::Lit(s)),
            Some(Tok::Name(n)) if n.is_text() => Ok(StrExpr::Param(n)),
            Some(Tok::Name(n)) => Err(format!(
                "{n} is a number where a string is expected (TOCHAR ( DAT+{n} ) converts it)"
            )),
            Some(Tok::Word(w)) if w == "SUBSTR" => {
                self.expect_op('(', "after SUBSTR")?;
                let src = self.source("SUBSTR")?;
                if !self.eat_word("BEG") {
                    return Err(format!(
                        "SUBSTR: expected BEGn after SRC_{src}, found {}",
                        self.found()
                    ));
                }
                let beg = self.unary()?;
                if !self.eat_word("LEN") {
                    return Err(format!(
                        "SUBSTR: expected LENn after BEG, found {}",
                        self.found()
                    ));
                }
                let len = self.unary()?;
                self.expect_op(')', "to close SUBSTR")?;
                Ok(StrExpr::Substr {
                    src,
                    beg: Box::new(beg),
                    len: Box::new(len),
                })
            }
            Some(Tok::Word(w)) if w == "TOCHAR" => {
                self.expect_op('(', "after TOCHAR")?;
                if !self.eat_word("DAT") {
                    return Err(format!(
                        "TOCHAR: expected DAT+Qn or DATn, found {}",
                        self.found()
                    ));
                }
                let dat = self.unary()?;
                let decimals = if self.eat_word("DECIMALS") {
                    Some(Box::new(self.unary()?))
                } else {
                    None
                };
                self.expect_op(')', "to close TOCHAR")?;
                Ok(StrExpr::ToChar {
                    dat: Box::new(dat),
                    decimals,
                })
            }
            _ => Err(format!(
                "expected a string (\"text\", QSn, SUBSTR, TOCHAR), found {found}"
            )),
        }
    }

    fn end(&self) -> Result<(), String> {
        match self.peek() {
            None => Ok(()),
            Some(t) => Err(format!("unexpected \"{t}\" (an operator is missing?)")),
        }
    }
}

/// A numeric expression, the whole of `s`.
pub fn parse_expr(s: &str) -> Result<Expr, String> {
    let mut p = Parser {
        toks: lex(s)?,
        pos: 0,
    };
    if p.toks.is_empty() {
        return Err("no value after '='".into());
    }
    let e = p.expr()?;
    p.end()?;
    Ok(e)
}

/// The right-hand side for `target`: a string formula for QS, a numeric one otherwise.
pub fn parse_formula(target: QName, s: &str) -> Result<Formula, String> {
    if !target.is_text() {
        return parse_expr(s).map(Formula::Number);
    }
    let mut p = Parser {
        toks: lex(s)?,
        pos: 0,
    };
    if p.toks.is_empty() {
        return Err("no value after '='".into());
    }
    let e = p.text()?;
    p.end()?;
    Ok(Formula::Text(e))
}

/// A signed decimal as the TNC writes it (`+12.5`, `-0.1`, `5`, `.5`), exponent allowed.
pub(crate) fn parse_decimal(s: &str) -> Option<f64> {
    let b = s.as_bytes();
    let mut i = usize::from(matches!(b.first(), Some(b'+' | b'-')));
    let int_start = i;
    while b.get(i).is_some_and(u8::is_ascii_digit) {
        i += 1;
    }
    let mut digits = i - int_start;
    if b.get(i) == Some(&b'.') {
        i += 1;
        let frac_start = i;
        while b.get(i).is_some_and(u8::is_ascii_digit) {
            i += 1;
        }
        digits += i - frac_start;
    }
    if digits == 0 {
        return None;
    }
    if matches!(b.get(i), Some(b'e' | b'E')) {
        i += 1;
        if matches!(b.get(i), Some(b'+' | b'-')) {
            i += 1;
        }
        let exp_start = i;
        while b.get(i).is_some_and(u8::is_ascii_digit) {
            i += 1;
        }
        if i == exp_start {
            return None;
        }
    }
    if i != b.len() {
        return None;
    }
    s.parse().ok().filter(|v: &f64| v.is_finite())
}

// ----- evaluation -----

/// What a parameter holds when a formula reads it.
pub enum Lookup {
    Value(QValue),
    /// Set by a measuring cycle: known only when the program runs (check).
    Measured,
    Undefined,
}

/// Where formulas read parameters.
pub trait Env {
    fn lookup(&self, name: QName) -> Lookup;
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum EvalErrorKind {
    /// A parameter read before anything set it.
    Undefined,
    DivisionByZero,
    /// SQRT of a negative number.
    NegativeRoot,
    /// ASIN/ACOS outside -1..1, a power without a real result, a result too large.
    Domain,
    /// A string operation that cannot be done (SUBSTR outside the string, TONUMB of
    /// text that is no number, a string longer than 255 characters).
    Text,
    /// The value depends on a measured result (check only; run knows it).
    Measured,
}

#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{message}")]
pub struct EvalError {
    pub kind: EvalErrorKind,
    pub message: String,
}

fn fail<T>(kind: EvalErrorKind, message: impl Into<String>) -> Result<T, EvalError> {
    Err(EvalError {
        kind,
        message: message.into(),
    })
}

fn read(env: &dyn Env, n: QName) -> Result<QValue, EvalError> {
    match env.lookup(n) {
        Lookup::Value(v) => Ok(v),
        Lookup::Measured => fail(EvalErrorKind::Measured, format!("{n} is a measured result")),
        Lookup::Undefined => fail(
            EvalErrorKind::Undefined,
            format!("{n} is not defined (nothing set it before this block)"),
        ),
    }
}

fn read_text(env: &dyn Env, n: QName) -> Result<String, EvalError> {
    match read(env, n)? {
        QValue::Text(t) => Ok(t),
        QValue::Number(v) => Ok(format!("{v}")),
    }
}

fn finite(v: f64, what: &str) -> Result<f64, EvalError> {
    if v.is_finite() {
        Ok(v)
    } else {
        fail(
            EvalErrorKind::Domain,
            format!("{what} has no finite result"),
        )
    }
}

pub fn eval(e: &Expr, env: &dyn Env) -> Result<f64, EvalError> {
    use EvalErrorKind as K;
    Ok(match e {
        Expr::Num(v) => *v,
        Expr::Pi => std::f64::consts::PI,
        Expr::Param(n) => match read(env, *n)? {
            QValue::Number(v) => v,
            QValue::Text(_) => return fail(K::Text, format!("{n} holds a string")),
        },
        Expr::Neg(a) => -eval(a, env)?,
        Expr::Bin(op, a, b) => {
            let (x, y) = (eval(a, env)?, eval(b, env)?);
            match op {
                BinOp::Add => finite(x + y, "the sum")?,
                BinOp::Sub => finite(x - y, "the difference")?,
                BinOp::Mul => finite(x * y, "the product")?,
                BinOp::Div if y == 0.0 => {
                    return fail(K::DivisionByZero, format!("division by zero ({x} / 0)"))
                }
                BinOp::Div => finite(x / y, "the quotient")?,
                BinOp::Pow => finite(x.powf(y), &format!("{x} ^ {y}"))?,
            }
        }
        Expr::Func(f, a) => {
            let x = eval(a, env)?;
            let v = match f {
                Func::Sq => x * x,
                Func::Sqrt if x < 0.0 => {
                    return fail(
                        K::NegativeRoot,
                        format!("square root of a negative number (SQRT {x})"),
                    )
                }
                Func::Sqrt => x.sqrt(),
                Func::Sin => x.to_radians().sin(),
                Func::Cos => x.to_radians().cos(),
                Func::Tan => x.to_radians().tan(),
                Func::Asin | Func::Acos if !(-1.0..=1.0).contains(&x) => {
                    return fail(
                        K::Domain,
                        format!("{} {x}: the argument must be within -1..+1", f.name()),
                    )
                }
                Func::Asin => x.asin().to_degrees(),
                Func::Acos => x.acos().to_degrees(),
                Func::Atan => x.atan().to_degrees(),
                Func::Abs => x.abs(),
                Func::Int => x.trunc(),
                Func::Frac => x - x.trunc(),
                Func::Sgn if x == 0.0 => 0.0,
                Func::Sgn => x.signum(),
            };
            finite(v, &format!("{} {x}", f.name()))?
        }
        Expr::ToNumb(n) => {
            let t = read_text(env, *n)?;
            match parse_decimal(t.trim()) {
                Some(v) => v,
                None => return fail(K::Text, format!("TONUMB: {n} = \"{t}\" is not a number")),
            }
        }
        Expr::StrLen(n) => read_text(env, *n)?.chars().count() as f64,
    })
}

fn whole(v: f64, what: &str) -> Result<usize, EvalError> {
    if v >= 0.0 && v.fract() == 0.0 && v <= MAX_TEXT as f64 {
        Ok(v as usize)
    } else {
        fail(
            EvalErrorKind::Text,
            format!("{what} {v}: must be a whole number 0..{MAX_TEXT}"),
        )
    }
}

pub fn eval_text(e: &StrExpr, env: &dyn Env) -> Result<String, EvalError> {
    let s = match e {
        StrExpr::Lit(s) => s.clone(),
        StrExpr::Param(n) => read_text(env, *n)?,
        StrExpr::Concat(parts) => {
            let mut s = String::new();
            for p in parts {
                s.push_str(&eval_text(p, env)?);
            }
            s
        }
        StrExpr::Substr { src, beg, len } => {
            let t = read_text(env, *src)?;
            let beg = whole(eval(beg, env)?, "SUBSTR: BEG")?;
            let len = whole(eval(len, env)?, "SUBSTR: LEN")?;
            let count = t.chars().count();
            if beg + len > count {
                return fail(
                    EvalErrorKind::Text,
                    format!(
                        "SUBSTR: BEG{beg} LEN{len} reaches beyond {src}, which has {count} characters"
                    ),
                );
            }
            t.chars().skip(beg).take(len).collect()
        }
        StrExpr::ToChar { dat, decimals } => {
            let v = eval(dat, env)?;
            let d = match decimals {
                Some(d) => whole(eval(d, env)?, "TOCHAR: DECIMALS")?.min(15),
                None => 4,
            };
            format!("{v:.d$}")
        }
    };
    if s.chars().count() > MAX_TEXT {
        return fail(
            EvalErrorKind::Text,
            format!(
                "the string has {} characters (at most {MAX_TEXT})",
                s.chars().count()
            ),
        );
    }
    Ok(s)
}

pub fn eval_formula(f: &Formula, env: &dyn Env) -> Result<QValue, EvalError> {
    match f {
        Formula::Number(e) => eval(e, env).map(QValue::Number),
        Formula::Text(e) => eval_text(e, env).map(QValue::Text),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    struct Map(BTreeMap<QName, QValue>);
    impl Env for Map {
        fn lookup(&self, n: QName) -> Lookup {
            self.0
                .get(&n)
                .cloned()
                .map_or(Lookup::Undefined, Lookup::Value)
        }
    }

    fn env() -> Map {
        let mut m = BTreeMap::new();
        m.insert(QName::parse("Q1").unwrap(), QValue::Number(3.0));
        m.insert(QName::parse("Q2").unwrap(), QValue::Number(4.0));
        m.insert(
            QName::parse("QS146").unwrap(),
            QValue::Text("0.01234567 -0.0123456 0.00123456 -0.0012345".into()),
        );
        Map(m)
    }

    fn num(s: &str) -> f64 {
        eval(&parse_expr(s).unwrap(), &env()).unwrap()
    }

    #[test]
    fn precedence_as_the_tnc() {
        assert_eq!(num("5 * 3 + 2 * 10"), 35.0);
        assert_eq!(num("SQ 10 - 3 ^ 3"), 73.0);
        assert!((num("SIN 30 ^ 2") - 0.25).abs() < 1e-12);
        assert_eq!(num("( Q1 + Q2 ) / 2"), 3.5);
        assert_eq!(num("2 ^ 3 ^ 2"), 64.0);
        assert_eq!(num("-Q1 + +5"), 2.0);
        assert_eq!(num("SQRT ( SQ Q1 + SQ Q2 )"), 5.0);
    }

    #[test]
    fn seed_substr_tonumb() {
        let mut e = env();
        let s = eval_text(
            &match parse_formula(
                QName::parse("QS0").unwrap(),
                "SUBSTR ( SRC_QS146 BEG11 LEN10 )",
            )
            .unwrap()
            {
                Formula::Text(t) => t,
                Formula::Number(_) => unreachable!(),
            },
            &e,
        )
        .unwrap();
        assert_eq!(s, "-0.0123456");
        e.0.insert(QName::parse("QS0").unwrap(), QValue::Text(s));
        let v = eval(&parse_expr("TONUMB ( SRC_QS0 )").unwrap(), &e).unwrap();
        assert_eq!(v, -0.0123456);
    }
}
