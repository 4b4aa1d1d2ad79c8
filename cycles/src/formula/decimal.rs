//! A signed decimal as the TNC writes it in a program.

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decimals() {
        for (s, v) in [
            ("+0", 0.0),
            ("-12.5", -12.5),
            ("5", 5.0),
            (".5", 0.5),
            ("+1e6", 1e6),
            ("3.", 3.0),
        ] {
            assert_eq!(parse_decimal(s), Some(v), "{s}");
        }
        for s in [
            "", "+", "1.2.3", "abc", "1e", "inf", "NaN", "+-1", "1,5", "Q1",
        ] {
            assert_eq!(parse_decimal(s), None, "{s}");
        }
    }
}
