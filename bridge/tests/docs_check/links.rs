//! Links and images: every relative target names a file that exists, and its
//! `#anchor` a heading of that file.

use super::markdown::anchors;
use std::path::Path;

/// The targets of Markdown links and images (`](target)`) and of HTML `src="..."` and
/// `href="..."` in a line (code spans already cut out).
pub(super) fn link_targets(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    for (at, _) in text.match_indices("](") {
        let rest = &text[at + 2..];
        if let Some(end) = rest.find(')') {
            let target = rest[..end].split_whitespace().next().unwrap_or("");
            out.push(target.trim_matches(|c| c == '<' || c == '>').to_string());
        }
    }
    for attr in ["src=\"", "href=\""] {
        for (at, _) in text.match_indices(attr) {
            let rest = &text[at + attr.len()..];
            if let Some(end) = rest.find('"') {
                out.push(rest[..end].to_string());
            }
        }
    }
    out
}

/// Checks one link of `page`; an error says why it does not resolve.
pub(super) fn check_link(root: &Path, page: &Path, text: &str, target: &str) -> Result<(), String> {
    if target.is_empty() {
        return Err("empty link".into());
    }
    if target.contains("://") || target.starts_with("mailto:") {
        return Ok(());
    }
    let (file, anchor) = match target.split_once('#') {
        Some((f, a)) => (f, Some(a)),
        None => (target, None),
    };
    let path = if file.is_empty() {
        page.to_path_buf()
    } else {
        page.parent().unwrap_or(Path::new("")).join(file)
    };
    let full = root.join(&path);
    if !full.exists() {
        return Err(format!("{} does not exist", path.display()));
    }
    if let Some(anchor) = anchor {
        let other;
        let text = if file.is_empty() {
            text
        } else {
            other = std::fs::read_to_string(&full)
                .map_err(|e| format!("#{anchor}: {} cannot be read: {e}", path.display()))?;
            &other
        };
        if !anchors(text).contains(anchor) {
            return Err(format!(
                "#{anchor}: no heading of {} has that anchor",
                path.display()
            ));
        }
    }
    Ok(())
}
