//! Q-parameter formulas as the TNC writes them: `Q1 = ( Q2 + Q3 ) / 2`,
//! `Q10 = SQRT ( SQ Q1 + SQ Q2 )`, and string formulas
//! `QS1 = "X=" || TOCHAR ( DAT+Q1 DECIMALS3 )`, `QS0 = SUBSTR ( SRC_QS146 BEG0 LEN10 )`.
//!
//! Precedence as on the TNC: a sign belongs to its operand, a function (SQ, SQRT, SIN,
//! COS, TAN, ASIN, ACOS, ATAN, ABS, INT, FRAC, SGN) takes the operand right after it
//! (`SIN 30 ^ 2` is `(SIN 30) ^ 2`), then `^`, then `*` `/`, then `+` `-`; operators of
//! one level from left to right. Angles are in degrees.

mod decimal;
mod eval;
mod expr;
mod grammar;
mod lexer;

pub(crate) use decimal::parse_decimal;
pub use eval::{eval, eval_formula, eval_text, Env, EvalError, EvalErrorKind, Lookup};
pub use expr::{BinOp, Expr, Formula, Func, StrExpr};
pub use grammar::{parse_expr, parse_formula};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::q_params::{QName, QValue};
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
