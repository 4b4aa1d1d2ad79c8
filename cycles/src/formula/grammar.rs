//! Reads the tokens of a formula into its expression tree, with the TNC's precedence.

use super::expr::{BinOp, Expr, Formula, Func, StrExpr};
use super::lexer::{lex, Tok};
use crate::q_params::{QKind, QName};

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
            Some(Tok::Word(w)) if w == "STRCOMP" || w == "INSTR" => self.search(&w),
            Some(Tok::Word(w)) => match Func::from_word(&w) {
                Some(f) => Ok(Expr::Func(f, Box::new(self.unary()?))),
                None => Err(format!(
                    "{w}: unknown function (known: SQ, SQRT, SIN, COS, TAN, ASIN, ACOS, ATAN, ABS, INT, FRAC, SGN, PI, TONUMB, STRLEN, STRCOMP, INSTR)"
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
        self.string_param(func, "SRC_", "the string parameter to read")
    }

    /// `STRCOMP ( SRC_QSa SEA_QSb )` and `INSTR ( SRC_QSa SEA_QSb BEGn )`, after the
    /// function's name.
    fn search(&mut self, func: &str) -> Result<Expr, String> {
        self.expect_op('(', &format!("after {func}"))?;
        let src = self.source(func)?;
        let sea = self.string_param(func, "SEA_", "the string parameter to compare or find")?;
        let beg = if func == "INSTR" && self.eat_word("BEG") {
            Some(Box::new(self.unary()?))
        } else {
            None
        };
        self.expect_op(')', &format!("to close {func}"))?;
        Ok(if func == "STRCOMP" {
            Expr::StrComp { src, sea }
        } else {
            Expr::InStr { src, sea, beg }
        })
    }

    /// `<key>QSn`: a string parameter named after a keyword (`SRC_`, `SEA_`).
    fn string_param(&mut self, func: &str, key: &str, what: &str) -> Result<QName, String> {
        if self.eat_word(key) {
            if let Some(Tok::Name(n)) = self.peek().cloned() {
                if n.kind == QKind::QS {
                    self.pos += 1;
                    return Ok(n);
                }
            }
        }
        Err(format!(
            "{func}: expected {key}QSn ({what}), found {}",
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
