//! Paths of the tree named in backticks: each exists, and a Rust file named without
//! its folder is the end of some file's path.

use std::path::{Path, PathBuf};

/// The top folders whose paths the pages name in backticks.
pub(super) const TREE: [&str; 12] = [
    "hal/",
    "cycles/",
    "sim/",
    "bridge/",
    "tests/",
    "fuzz/",
    "configs/",
    "scripts/",
    "deploy/",
    "docs/",
    ".ci/",
    "clippy.toml",
];

/// A code span that names a path of the tree (`hal/src/master/rt_loop/latch.rs`,
/// `sim/src/drive/`, `configs/machines/table-ac.toml`), with `{a,b}` expanded; none
/// for commands, placeholders (`<machine>`, `NAME`, `*`) and module paths.
pub(super) fn tree_paths(span: &str) -> Vec<String> {
    let looks_like_path = TREE.iter().any(|t| span.starts_with(t))
        && !span.contains(char::is_whitespace)
        && !span.contains(['*', '<', '>', '$', ':', '=', ','].as_slice())
        // an all-capitals segment is a placeholder (fuzz/crashes/TARGET/KIND-HASH)
        && !span.split('/').any(|s| {
            s.len() > 1 && s.chars().all(|c| c.is_ascii_uppercase() || c == '-' || c == '_')
        });
    let braced = TREE.iter().any(|t| span.starts_with(t))
        && !span.contains(char::is_whitespace)
        && span.contains('{');
    if braced {
        let (head, rest) = span.split_once('{').expect("contains {");
        let Some((alts, tail)) = rest.split_once('}') else {
            return vec![span.to_string()];
        };
        return alts
            .split(',')
            .flat_map(|a| tree_paths(&format!("{head}{a}{tail}")))
            .collect();
    }
    if looks_like_path {
        vec![span.to_string()]
    } else {
        Vec::new()
    }
}

/// Every file of the tree below the crates' folders, as `/`-separated paths from the
/// root (target/ and .git/ left out).
pub(super) fn tree_files(root: &Path) -> Vec<String> {
    let mut out = Vec::new();
    let mut todo: Vec<PathBuf> = TREE
        .iter()
        .filter(|t| t.ends_with('/'))
        .map(|t| root.join(t))
        .collect();
    while let Some(dir) = todo.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                todo.push(p);
            } else if let Ok(rel) = p.strip_prefix(root) {
                out.push(rel.to_string_lossy().into_owned());
            }
        }
    }
    out
}

/// A code span that names a Rust file without its full path (`latch.rs`,
/// `rt_loop/motion.rs`, `cli_signals.rs`): it must be the end of some file's path.
pub(super) fn bare_rust_file(span: &str) -> Option<&str> {
    let plain = span.ends_with(".rs")
        && !TREE.iter().any(|t| span.starts_with(t))
        && span
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '/' | '.'));
    plain.then_some(span)
}
