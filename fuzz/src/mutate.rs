//! Mutations of one input: a stack of byte-level edits (bit flips, boundary values,
//! inserts, deletes, copies), dictionary tokens, splices with other corpus entries,
//! and, for text, edits of whole lines and words, so a program or a TOML file stays
//! close enough to valid to reach the checks behind the syntax.

use crate::rng::Rng;

/// Values at the edges of the integer types the decoders read.
const INTERESTING: [u64; 14] = [
    0,
    1,
    0x7F,
    0x80,
    0xFF,
    0x100,
    0x7FFF,
    0x8000,
    0xFFFF,
    0x1_0000,
    0x7FFF_FFFF,
    0x8000_0000,
    0xFFFF_FFFF,
    u64::MAX,
];

/// What the mutator may use besides the input.
pub struct Context<'a> {
    pub corpus: &'a [Vec<u8>],
    pub dictionary: &'a [Vec<u8>],
    pub max_len: usize,
}

/// A new input made from `input` by 1 to 8 stacked mutations, at most `max_len` bytes.
pub fn mutate(rng: &mut Rng, input: &[u8], cx: &Context<'_>) -> Vec<u8> {
    let mut out = input.to_vec();
    let text = looks_like_text(input);
    let rounds = 1 + rng.below(8);
    for _ in 0..rounds {
        if text && rng.chance(1, 2) {
            text_edit(rng, &mut out, cx);
        } else {
            byte_edit(rng, &mut out, cx);
        }
        out.truncate(cx.max_len);
    }
    out
}

fn looks_like_text(b: &[u8]) -> bool {
    !b.is_empty()
        && b.iter()
            .take(256)
            .all(|&c| c == b'\n' || c == b'\r' || c == b'\t' || (0x20..0x7F).contains(&c))
}

fn byte_edit(rng: &mut Rng, b: &mut Vec<u8>, cx: &Context<'_>) {
    match rng.below(12) {
        0 if !b.is_empty() => {
            let i = rng.below(b.len());
            b[i] ^= 1 << rng.below(8);
        }
        1 if !b.is_empty() => {
            let i = rng.below(b.len());
            b[i] = rng.byte();
        }
        2 if !b.is_empty() => {
            let i = rng.below(b.len());
            let delta = 1 + rng.below(16) as u8;
            b[i] = if rng.chance(1, 2) {
                b[i].wrapping_add(delta)
            } else {
                b[i].wrapping_sub(delta)
            };
        }
        3 if !b.is_empty() => {
            // A boundary value of 1, 2, 4 or 8 bytes, either byte order.
            let width = 1 << rng.below(4);
            let v = *rng.pick(&INTERESTING);
            let bytes = if rng.chance(1, 2) {
                v.to_le_bytes()
            } else {
                v.to_be_bytes()
            };
            let bytes = if bytes[0] == 0 && width < 8 {
                &bytes[8 - width..]
            } else {
                &bytes[..width]
            };
            let at = rng.below(b.len());
            let end = (at + bytes.len()).min(b.len());
            b[at..end].copy_from_slice(&bytes[..end - at]);
        }
        4 if b.len() > 1 => {
            let (at, len) = range(rng, b.len());
            b.drain(at..at + len);
        }
        5 => {
            let at = rng.below(b.len() + 1);
            let n = 1 + rng.below(16);
            let fresh: Vec<u8> = (0..n).map(|_| rng.byte()).collect();
            b.splice(at..at, fresh);
        }
        6 if !b.is_empty() => {
            // A copy of a piece elsewhere, sometimes many times (long inputs, hangs).
            let (from, len) = range(rng, b.len());
            let piece = b[from..from + len].to_vec();
            let times = if rng.chance(1, 8) {
                1 + rng.below(64)
            } else {
                1
            };
            let at = rng.below(b.len() + 1);
            let copies: Vec<u8> = piece.iter().copied().cycle().take(len * times).collect();
            b.splice(at..at, copies);
        }
        7 | 8 if !cx.dictionary.is_empty() => {
            let token = rng.pick(cx.dictionary).clone();
            let at = rng.below(b.len() + 1);
            if rng.chance(1, 2) || at == b.len() {
                b.splice(at..at, token);
            } else {
                let end = (at + token.len()).min(b.len());
                b.splice(at..end, token);
            }
        }
        9 | 10 if !cx.corpus.is_empty() => {
            // Splice: a head of this input and a tail of another.
            let other = rng.pick(cx.corpus);
            let cut = rng.below(b.len() + 1);
            let from = rng.below(other.len() + 1);
            b.truncate(cut);
            b.extend_from_slice(&other[from..]);
        }
        _ => {
            let at = rng.below(b.len() + 1);
            b.insert(at, rng.byte());
        }
    }
}

/// A start and a non-empty length inside `0..len` (`len` > 0), mostly short.
fn range(rng: &mut Rng, len: usize) -> (usize, usize) {
    let at = rng.below(len);
    let max = len - at;
    let n = if rng.chance(3, 4) {
        1 + rng.below(max.min(8))
    } else {
        1 + rng.below(max)
    };
    (at, n)
}

fn text_edit(rng: &mut Rng, b: &mut Vec<u8>, cx: &Context<'_>) {
    let mut lines: Vec<Vec<u8>> = b.split(|&c| c == b'\n').map(<[u8]>::to_vec).collect();
    match rng.below(7) {
        0 if lines.len() > 1 => {
            lines.remove(rng.below(lines.len()));
        }
        1 => {
            let l = rng.pick(&lines).clone();
            lines.insert(rng.below(lines.len() + 1), l);
        }
        2 if lines.len() > 1 => {
            let (i, j) = (rng.below(lines.len()), rng.below(lines.len()));
            lines.swap(i, j);
        }
        3 if !cx.corpus.is_empty() => {
            // A line of another entry (a block of another program, a key of another file).
            let other = rng.pick(cx.corpus);
            let theirs: Vec<&[u8]> = other.split(|&c| c == b'\n').collect();
            let l = rng.pick(&theirs).to_vec();
            lines.insert(rng.below(lines.len() + 1), l);
        }
        4 | 5 if !cx.dictionary.is_empty() => {
            // A word (letters, digits, sign, point) replaced by a token.
            let i = rng.below(lines.len());
            let words = word_spans(&lines[i]);
            if words.is_empty() {
                return;
            }
            let (s, e) = *rng.pick(&words);
            lines[i].splice(s..e, rng.pick(cx.dictionary).clone());
        }
        _ => {
            // A number changed into a boundary or non-finite one.
            let i = rng.below(lines.len());
            let numbers: Vec<(usize, usize)> = word_spans(&lines[i])
                .into_iter()
                .filter(|&(s, e)| lines[i][s..e].iter().any(u8::is_ascii_digit))
                .collect();
            if numbers.is_empty() {
                return;
            }
            const NUMBERS: [&str; 16] = [
                "0",
                "-0",
                "1",
                "-1",
                "0.0001",
                "1e-9",
                "1e308",
                "-1e308",
                "1e999",
                "nan",
                "inf",
                "-inf",
                "4294967296",
                "-2147483649",
                "99999999999999999999",
                "+.5",
            ];
            let (s, e) = *rng.pick(&numbers);
            lines[i].splice(s..e, rng.pick(&NUMBERS).bytes());
        }
    }
    *b = lines.join(&b'\n');
}

fn word_spans(line: &[u8]) -> Vec<(usize, usize)> {
    let is_word = |c: u8| c.is_ascii_alphanumeric() || matches!(c, b'.' | b'+' | b'-' | b'_');
    let mut spans = Vec::new();
    let mut start = None;
    for (i, &c) in line.iter().enumerate() {
        match (is_word(c), start) {
            (true, None) => start = Some(i),
            (false, Some(s)) => {
                spans.push((s, i));
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        spans.push((s, line.len()));
    }
    spans
}

/// The words and punctuation-free tokens of `seeds`, deduplicated: a dictionary of
/// the keywords, keys and numbers the seeds use.
pub fn tokens_of(seeds: &[Vec<u8>], extra: &[&str]) -> Vec<Vec<u8>> {
    let mut set = std::collections::BTreeSet::new();
    for s in seeds.iter().filter(|s| looks_like_text(s)) {
        for line in s.split(|&c| c == b'\n') {
            for (a, e) in word_spans(line) {
                if e - a <= 32 {
                    set.insert(line[a..e].to_vec());
                }
            }
        }
    }
    set.extend(extra.iter().map(|t| t.as_bytes().to_vec()));
    set.into_iter().collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mutations_stay_within_max_len_and_change_the_input() {
        let corpus = vec![b"BEGIN PGM 1 MM\nL X+1 FMAX\nEND PGM 1 MM".to_vec()];
        let dictionary = tokens_of(&corpus, &["TCH PROBE"]);
        assert!(dictionary.contains(&b"FMAX".to_vec()));
        let cx = Context {
            corpus: &corpus,
            dictionary: &dictionary,
            max_len: 64,
        };
        let mut rng = Rng::new(1);
        let mut changed = 0;
        for _ in 0..2000 {
            let m = mutate(&mut rng, &corpus[0], &cx);
            assert!(m.len() <= 64);
            changed += usize::from(m != corpus[0]);
        }
        assert!(changed > 1800, "{changed} of 2000 changed");
    }
}
