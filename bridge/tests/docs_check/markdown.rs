//! The Markdown of the pages as GitHub reads it: fenced blocks apart from the text,
//! inline code spans apart from the prose, headings' anchors.

use std::collections::HashSet;

/// A line of a page outside fenced blocks, or a line inside one.
pub(super) enum Line<'a> {
    Text(usize, &'a str),
    /// (line number, the block's info string, the line)
    Fenced(usize, &'a str, &'a str),
}

/// The lines of a page, each marked as text or as part of a fenced block (``` or ~~~).
pub(super) fn lines(text: &str) -> Vec<Line<'_>> {
    let mut out = Vec::new();
    let mut fence: Option<(&str, &str)> = None;
    for (i, line) in text.lines().enumerate() {
        let t = line.trim_start();
        let marker = ["```", "~~~"].into_iter().find(|m| t.starts_with(m));
        match (fence, marker) {
            (None, Some(m)) => fence = Some((m, t[m.len()..].trim())),
            (Some((open, _)), Some(m)) if m == open && t.trim_end() == m => fence = None,
            (Some((_, info)), _) => out.push(Line::Fenced(i + 1, info, line)),
            (None, None) => out.push(Line::Text(i + 1, line)),
        }
    }
    out
}

/// GitHub's anchor of a heading: lower case, punctuation dropped (letters, digits,
/// `-`, `_` and spaces kept), spaces to `-`.
pub(super) fn slug(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || matches!(c, '-' | '_' | ' '))
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// The anchors a page offers: its headings' slugs (a repeated one gets `-1`, `-2`, as
/// on GitHub) and explicit `id="..."`/`name="..."` attributes.
pub(super) fn anchors(text: &str) -> HashSet<String> {
    let mut out = HashSet::new();
    for line in lines(text) {
        let Line::Text(_, l) = line else { continue };
        let hashes = l.chars().take_while(|&c| c == '#').count();
        if (1..=6).contains(&hashes) && l[hashes..].starts_with(' ') {
            let base = slug(&l[hashes..]);
            let mut s = base.clone();
            let mut n = 0;
            while out.contains(&s) {
                n += 1;
                s = format!("{base}-{n}");
            }
            out.insert(s);
        }
        for attr in ["id=\"", "name=\""] {
            for (at, _) in l.match_indices(attr) {
                let rest = &l[at + attr.len()..];
                if let Some(end) = rest.find('"') {
                    out.insert(rest[..end].to_string());
                }
            }
        }
    }
    out
}

/// A text line with its inline code spans cut out, and the spans.
pub(super) fn split_code(line: &str) -> (String, Vec<&str>) {
    let mut text = String::new();
    let mut spans = Vec::new();
    let mut rest = line;
    while let Some(open) = rest.find('`') {
        text.push_str(&rest[..open]);
        let ticks = rest[open..].chars().take_while(|&c| c == '`').count();
        let after = &rest[open + ticks..];
        let closing = "`".repeat(ticks);
        match after.find(&closing) {
            Some(close) => {
                spans.push(after[..close].trim());
                rest = &after[close + ticks..];
            }
            None => {
                text.push_str(&rest[open..]);
                rest = "";
            }
        }
    }
    text.push_str(rest);
    (text, spans)
}
