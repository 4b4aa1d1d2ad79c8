//! Outcome features: what tells runs of a target apart without coverage
//! instrumentation. A target reports the features of one run (each error message,
//! each kind of event); the driver keeps an input when one of them, or a feature
//! seen a new power-of-two number of times, is new. Messages are reduced to their
//! own words: numbers, punctuation and every word that also occurs in the input are
//! dropped, so "line 3: Q263 = 1e308 ..." and "line 9: Q263 = 7 ..." are one feature
//! and the corpus grows by kinds of errors, not by values.

/// The features of one run.
#[derive(Clone, Debug, Default)]
pub struct Sig {
    parts: Vec<u64>,
}

impl Sig {
    /// Adds `text` as it is (a fixed label).
    pub fn text(&mut self, text: &str) -> &mut Self {
        self.value(fnv(text.as_bytes()))
    }

    /// Adds an error message, reduced to its own words: quoted text (`"..."` with
    /// `\"` escapes, as `{:?}` writes it, and serde's `` `...` ``), the source lines TOML errors show
    /// (`3 | key = ...`), numbers and punctuation are dropped.
    pub fn message(&mut self, message: &str) -> &mut Self {
        let mut key = String::new();
        for line in message.lines().filter(|l| !is_snippet(l)) {
            let mut quoted: Option<char> = None;
            let mut escaped = false;
            let mut word = String::new();
            for c in line.chars().chain([' ']) {
                if let Some(q) = quoted {
                    match (escaped, c) {
                        (false, '\\') if q == '"' => escaped = true,
                        (false, c) if c == q => quoted = None,
                        _ => escaped = false,
                    }
                    continue;
                }
                if c == '"' || c == '`' {
                    quoted = Some(c);
                }
                if c.is_ascii_alphabetic() {
                    word.push(c);
                } else {
                    if word.len() >= 2 {
                        key.push_str(&word);
                        key.push(' ');
                    }
                    word.clear();
                }
            }
        }
        self.text(&key)
    }

    /// Adds a value as it is (an enum variant, a small count).
    pub fn value(&mut self, v: u64) -> &mut Self {
        self.parts.push(v);
        self
    }

    /// Adds the `Debug` form of a value with its digits dropped (decoded values vary,
    /// variants and fields do not).
    pub fn debug(&mut self, v: &impl std::fmt::Debug) -> &mut Self {
        let s: String = format!("{v:?}")
            .chars()
            .filter(|c| !c.is_ascii_digit())
            .collect();
        self.text(&s)
    }

    /// The distinct features: each part with the power of two of its count.
    pub fn features(&self) -> Vec<u64> {
        let mut parts = self.parts.clone();
        parts.sort_unstable();
        let mut out = Vec::new();
        let mut i = 0;
        while i < parts.len() {
            let n = parts[i..].iter().take_while(|&&p| p == parts[i]).count();
            out.push(parts[i].rotate_left(7) ^ u64::from(usize::BITS - n.leading_zeros()));
            i += n;
        }
        out
    }
}

/// A source line as TOML errors show it: `  |`, `3 | key = 1`, `  |     ^`.
fn is_snippet(line: &str) -> bool {
    let t = line.trim_start_matches(|c: char| c.is_ascii_digit() || c == ' ');
    t.starts_with('|')
}

/// FNV-1a, for file names and signatures.
pub fn fnv(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_and_quoted_input_make_no_new_feature_message_words_do() {
        let f = |m: &str| Sig::default().message(m).features();
        assert_eq!(
            f("line 3: Q263 = 1e308 is too large"),
            f("line 12: Q263 = 7e3 is too large")
        );
        assert_ne!(f("line 3: unknown block"), f("line 3: no END PGM"));
        assert_eq!(f(r#""F\"OO" unknown"#), f(r#""BAR" unknown"#));
        assert_eq!(f("unknown field `xy`"), f("unknown field `z`"));
        assert_eq!(
            f("TOML parse error at line 3, column 1\n  |\n3 | foo bar\n  | ^\nexpected"),
            f("TOML parse error at line 9, column 2\n  |\n9 | baz\n  | ^\nexpected")
        );
    }

    #[test]
    fn counts_matter_by_power_of_two() {
        let mut a = Sig::default();
        a.value(1).value(1).value(1);
        let mut b = Sig::default();
        b.value(1).value(1).value(1).value(1);
        let mut c = Sig::default();
        c.value(1).value(1);
        assert_eq!(a.features(), c.features());
        assert_ne!(a.features(), b.features());
    }
}
