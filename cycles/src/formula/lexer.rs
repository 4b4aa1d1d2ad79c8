//! Splits a formula into tokens: numbers, parameters, strings, words (functions and
//! the glued keywords `SRC_`, `SEA_`, `BEG`, `LEN`, `DAT`, `DECIMALS`), operators and `||`.

use crate::q_params::QName;
use std::fmt;

#[derive(Clone, Debug, PartialEq)]
pub(super) enum Tok {
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
const GLUED: [&str; 6] = ["SRC_", "SEA_", "BEG", "LEN", "DAT", "DECIMALS"];

pub(super) fn lex(s: &str) -> Result<Vec<Tok>, String> {
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
                // The 451 seed prints `:` for `;` before three of its comments.
                let hint = if ch == ':' {
                    " (a comment starts with ';')"
                } else {
                    ""
                };
                return Err(format!("unexpected character '{ch}'{hint}"));
            }
        }
    }
    Ok(out)
}
