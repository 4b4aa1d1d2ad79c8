//! Splits a program's physical lines: block number, code, comment, the `~` that
//! continues a block; and recognises the words that start a cycle block.

/// One physical line, split.
#[derive(Clone, Copy, Debug)]
pub(super) struct Line<'a> {
    pub(super) no: usize,
    pub(super) number: Option<u32>,
    /// Text before the comment, block number and `~` removed, trimmed.
    pub(super) code: &'a str,
    pub(super) comment: Option<&'a str>,
    /// Ends with `~`: the block goes on.
    pub(super) cont: bool,
}

impl Line<'_> {
    pub(super) fn is_blank(&self) -> bool {
        self.code.is_empty() && self.comment.is_none() && !self.cont && self.number.is_none()
    }
}

pub(super) fn split_line(no: usize, raw: &str) -> Line<'_> {
    let mut t = raw.trim();
    let cont = t.ends_with('~');
    if cont {
        t = t[..t.len() - 1].trim_end();
    }
    // `;` inside a QS string is text, not a comment.
    let mut in_quotes = false;
    let mut cut = None;
    for (i, c) in t.char_indices() {
        match c {
            '"' => in_quotes = !in_quotes,
            ';' if !in_quotes => {
                cut = Some(i);
                break;
            }
            _ => {}
        }
    }
    let (code, comment) = match cut {
        Some(i) => (t[..i].trim(), Some(t[i + 1..].trim())),
        None => (t, None),
    };
    let (number, code) = split_block_number(code);
    // ISO blocks end with `*`; a line that starts with `*` is a structure comment.
    let code = match code.strip_suffix('*') {
        Some(c) if !code.starts_with('*') => c.trim_end(),
        _ => code,
    };
    Line {
        no,
        number,
        code,
        comment,
        cont,
    }
}

/// `11 TCH PROBE ...` / `N110 G444 ...`: the leading block number, if any.
pub(super) fn split_block_number(code: &str) -> (Option<u32>, &str) {
    let digits_from = usize::from(code.starts_with(['N', 'n']));
    let rest = &code[digits_from..];
    let end = rest
        .find(|c: char| !c.is_ascii_digit())
        .unwrap_or(rest.len());
    if end == 0 {
        return (None, code);
    }
    let after = &rest[end..];
    if !(after.is_empty() || after.starts_with(char::is_whitespace)) {
        return (None, code);
    }
    // "N" alone followed by digits and space is a block number; a bare "12" too.
    match rest[..end].parse() {
        Ok(n) => (Some(n), after.trim_start()),
        Err(_) => (None, code),
    }
}

/// `Q263=...` / `QS400=...` at the start of the code: a cycle parameter line.
pub(super) fn is_param_line(code: &str) -> bool {
    let b = code.as_bytes();
    if b.first().map(u8::to_ascii_uppercase) != Some(b'Q') {
        return false;
    }
    let mut i = 1;
    if b.get(1).map(u8::to_ascii_uppercase) == Some(b'S') {
        i = 2;
    }
    let start = i;
    while b.get(i).is_some_and(u8::is_ascii_digit) {
        i += 1;
    }
    i > start && code[i..].trim_start().starts_with('=')
}

pub(super) fn upper_words(code: &str) -> Vec<String> {
    code.split_whitespace()
        .map(str::to_ascii_uppercase)
        .collect()
}

/// A block that may carry parameter lines: a touch-probe cycle, or a `CYCL DEF` (cycle
/// 247's Q339; cycle 7's 7.x lines are blocks of their own).
pub(super) fn is_cycle_head(code: &str) -> bool {
    let w = upper_words(code);
    (w.len() >= 2 && ((w[0] == "TCH" && w[1] == "PROBE") || (w[0] == "CYCL" && w[1] == "DEF")))
        || iso_cycle_number(code).is_some()
        || w.first().is_some_and(|g| g == "G247")
}

/// `G444 ...` -> 444 for G codes in the touch-probe ranges (400..499, 1400..1499).
pub(super) fn iso_cycle_number(code: &str) -> Option<u16> {
    let first = code.split_whitespace().next()?;
    let digits = first.strip_prefix(['G', 'g'])?;
    let n: u16 = digits.parse().ok()?;
    (digits.len() >= 3 && ((400..=499).contains(&n) || (1400..=1499).contains(&n))).then_some(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_split() {
        let l = split_line(3, "  12 TCH PROBE 444 ANTASTEN 3D ~");
        assert_eq!(
            (l.number, l.code, l.cont),
            (Some(12), "TCH PROBE 444 ANTASTEN 3D", true)
        );
        let l = split_line(4, "QS400=\"a;b\" ;TOLERANZ ~");
        assert_eq!(
            (l.code, l.comment, l.cont),
            ("QS400=\"a;b\"", Some("TOLERANZ"), true)
        );
        let l = split_line(5, "N20 G444 Q263=+0 *");
        assert_eq!((l.number, l.code), (Some(20), "G444 Q263=+0"));
    }
}
