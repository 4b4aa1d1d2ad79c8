//! Evaluates a formula against the parameters it reads ([`Env`]): the values, or an
//! error that says why (undefined, division by zero, a negative root, ...).

use super::decimal::parse_decimal;
use super::expr::{BinOp, Expr, Formula, Func, StrExpr};
use crate::q_params::{QName, QValue, MAX_TEXT};

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
        Expr::StrComp { src, sea } => match read_text(env, *src)?.cmp(&read_text(env, *sea)?) {
            std::cmp::Ordering::Less => -1.0,
            std::cmp::Ordering::Equal => 0.0,
            std::cmp::Ordering::Greater => 1.0,
        },
        Expr::InStr { src, sea, beg } => {
            let (t, find) = (read_text(env, *src)?, read_text(env, *sea)?);
            let count = t.chars().count();
            let beg = match beg {
                Some(b) => whole(eval(b, env)?, "INSTR: BEG")?,
                None => 0,
            };
            if beg > count {
                return fail(
                    K::Text,
                    format!("INSTR: BEG{beg} is beyond {src}, which has {count} characters"),
                );
            }
            // Counted in characters, as SUBSTR's BEG and LEN are.
            let from: String = t.chars().skip(beg).collect();
            match from.find(&find) {
                Some(i) => (beg + from[..i].chars().count()) as f64,
                None => count as f64,
            }
        }
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
