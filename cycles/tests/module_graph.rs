//! No module of the cycles crate imports another in a circle.
//!
//! Builds the import graph of `cycles/src` from its sources: one node per file (a
//! module), one edge per `use crate::...`, `use super::...`, `use child::...` or inline
//! `crate::a::b` path to another file, resolved to the deepest module that exists.
//! Declaring a child (`mod child;`), comments and `#[cfg(test)]` sections are not
//! imports. Rerun with `cargo test -p probebridge-cycles --test module_graph`.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Module path (`crate::cycle451::plan`) of every source file, and its text.
fn modules(src: &Path) -> BTreeMap<String, String> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push(p);
            }
        }
    }
    let mut files = Vec::new();
    walk(src, &mut files);
    files
        .into_iter()
        .map(|f| {
            let rel = f.strip_prefix(src).unwrap().with_extension("");
            let mut parts: Vec<String> = rel
                .iter()
                .map(|s| s.to_string_lossy().into_owned())
                .collect();
            if matches!(parts.last().map(String::as_str), Some("mod" | "lib")) {
                parts.pop();
            }
            let name = std::iter::once("crate".to_string())
                .chain(parts)
                .collect::<Vec<_>>()
                .join("::");
            (name, std::fs::read_to_string(&f).unwrap())
        })
        .collect()
}

/// The code of a file without comments and without its `#[cfg(test)]` part.
fn code(text: &str) -> String {
    let mut out = String::new();
    for line in text.lines() {
        if line.trim_start().starts_with("#[cfg(test)]") {
            break;
        }
        let line = line.split("//").next().unwrap_or("");
        out.push_str(line);
        out.push('\n');
    }
    out
}

/// Expands `a::{b, c::{d, e}}` into `a::b`, `a::c::d`, `a::c::e`.
fn expand(tree: &str) -> Vec<String> {
    let tree: String = tree.chars().filter(|c| !c.is_whitespace()).collect();
    let Some(open) = tree.find('{') else {
        return vec![tree];
    };
    let prefix = &tree[..open];
    let inner = &tree[open + 1..tree.len() - 1];
    let mut parts = Vec::new();
    let (mut depth, mut start) = (0, 0);
    for (i, c) in inner.char_indices() {
        match c {
            '{' => depth += 1,
            '}' => depth -= 1,
            ',' if depth == 0 => {
                parts.push(&inner[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    parts.push(&inner[start..]);
    parts
        .into_iter()
        .filter(|p| !p.is_empty())
        .flat_map(|p| expand(&format!("{prefix}{p}")))
        .collect()
}

/// Paths a module's code names: the expanded `use` trees and inline `crate::`/`super::`
/// paths.
fn paths(code: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = code;
    // `use` statements (also `pub use`, `pub(crate) use`).
    while let Some(i) = rest.find("use ") {
        let before = rest[..i].chars().last();
        let after = &rest[i + 4..];
        let end = after.find(';').unwrap_or(after.len());
        if before.is_none_or(|c| !(c.is_alphanumeric() || c == '_')) {
            out.extend(expand(&after[..end]));
            rest = &after[end..];
        } else {
            rest = after;
        }
    }
    for start in ["crate::", "super::"] {
        let mut from = 0;
        while let Some(i) = code[from..].find(start) {
            let at = from + i;
            let path: String = code[at..]
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_' || *c == ':')
                .collect();
            out.push(path.trim_end_matches(':').to_string());
            from = at + start.len();
        }
    }
    out
}

/// The module a path in module `m` points into: the deepest existing module.
fn resolve(m: &str, path: &str, known: &BTreeSet<String>) -> Option<String> {
    let mut segs: Vec<&str> = path.split("::").collect();
    let mut base: Vec<&str> = m.split("::").collect();
    let absolute = match segs.first().copied() {
        Some("crate") => {
            segs.remove(0);
            vec!["crate"]
        }
        Some("super") => {
            while segs.first() == Some(&"super") {
                segs.remove(0);
                base.pop();
            }
            base
        }
        Some("self") => {
            segs.remove(0);
            base
        }
        // `use child::X` in a module with that child.
        Some(first) if known.contains(&format!("{m}::{first}")) => base,
        _ => return None,
    };
    let mut best = absolute.join("::");
    let mut cur = absolute.clone();
    for s in segs {
        cur.push(s);
        let name = cur.join("::");
        if known.contains(&name) {
            best = name;
        } else {
            break;
        }
    }
    Some(best)
}

fn graph(src: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let mods = modules(src);
    let known: BTreeSet<String> = mods.keys().cloned().collect();
    mods.iter()
        .map(|(m, text)| {
            let targets = paths(&code(text))
                .iter()
                .filter_map(|p| resolve(m, p, &known))
                .filter(|t| t != m)
                .collect();
            (m.clone(), targets)
        })
        .collect()
}

/// The circles of the graph (strongly connected components of two or more modules).
fn circles(g: &BTreeMap<String, BTreeSet<String>>) -> Vec<Vec<String>> {
    let reach = |from: &str| -> BTreeSet<String> {
        let mut seen = BTreeSet::new();
        let mut stack = vec![from.to_string()];
        while let Some(n) = stack.pop() {
            for t in g.get(&n).into_iter().flatten() {
                if seen.insert(t.clone()) {
                    stack.push(t.clone());
                }
            }
        }
        seen
    };
    let reachable: BTreeMap<&String, BTreeSet<String>> = g.keys().map(|m| (m, reach(m))).collect();
    let mut done = BTreeSet::new();
    let mut out = Vec::new();
    for m in g.keys() {
        if done.contains(m) || !reachable[m].contains(m) {
            continue;
        }
        let component: Vec<String> = g
            .keys()
            .filter(|n| reachable[m].contains(*n) && reachable[*n].contains(m))
            .cloned()
            .collect();
        done.extend(component.iter().cloned());
        out.push(component);
    }
    out
}

#[test]
fn no_module_imports_another_in_a_circle() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let g = graph(&src);
    assert!(g.len() > 10, "the sources were found: {g:?}");
    let found = circles(&g);
    assert!(
        found.is_empty(),
        "modules that import each other in a circle:\n{}",
        found
            .iter()
            .map(|c| format!("  {}", c.join(", ")))
            .collect::<Vec<_>>()
            .join("\n")
    );
}

#[test]
fn the_check_sees_a_circle() {
    let mut g = BTreeMap::new();
    let set = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<BTreeSet<_>>();
    g.insert("crate::a".to_string(), set(&["crate::b"]));
    g.insert("crate::b".to_string(), set(&["crate::c"]));
    g.insert("crate::c".to_string(), set(&["crate::a"]));
    g.insert("crate::d".to_string(), set(&["crate::a"]));
    assert_eq!(
        circles(&g),
        vec![vec![
            "crate::a".to_string(),
            "crate::b".into(),
            "crate::c".into()
        ]]
    );
    let known = set(&["crate", "crate::k", "crate::k::m", "crate::k::n"]);
    assert_eq!(
        resolve("crate::k::m", "super::n::X", &known).as_deref(),
        Some("crate::k::n")
    );
    assert_eq!(
        resolve("crate::k", "n::{X, Y}", &known).as_deref(),
        Some("crate::k::n")
    );
    assert_eq!(
        expand("crate::{a, b::{c, d}}"),
        vec!["crate::a", "crate::b::c", "crate::b::d"]
    );
}
