//! The expression tree of a Q-parameter formula: numeric ([`Expr`]) and string
//! ([`StrExpr`]) expressions, the TNC's functions and operators.

use crate::q_params::QName;

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

    pub(super) fn from_word(w: &str) -> Option<Func> {
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
    /// `STRCOMP ( SRC_QSa SEA_QSb )`: 0 when the texts are the same, -1 when QSa comes
    /// first in the character order, +1 when it comes after.
    StrComp {
        src: QName,
        sea: QName,
    },
    /// `INSTR ( SRC_QSa SEA_QSb BEGn )`: where QSb first occurs in QSa from character
    /// `n` on (0 = the first; `BEG` left out: 0), or QSa's length when it does not.
    InStr {
        src: QName,
        sea: QName,
        beg: Option<Box<Expr>>,
    },
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
            Expr::StrComp { src, sea } => out.extend([*src, *sea]),
            Expr::InStr { src, sea, beg } => {
                out.extend([*src, *sea]);
                if let Some(b) = beg {
                    b.params(out);
                }
            }
        }
    }
}
