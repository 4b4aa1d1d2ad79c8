//! Every type, function and macro ARCHITECTURE.md names in backticks (`RtLoop`,
//! `Core::prepared`, `run_program`, `machine_conformance!`) is defined in the
//! workspace's Rust sources, or is one of the few outside names it cites on purpose
//! ([`OUTSIDE`]): a renamed or removed type cannot stay on the map.

use super::markdown::{lines, split_code, Line};
use super::paths::tree_files;
use super::root;
use std::collections::HashSet;
use std::path::Path;

/// Names from outside the workspace that ARCHITECTURE.md cites: std's, iceoryx2's, the
/// OPC UA companion specifications' (third_party/opcua-nodesets), and the path roots.
const OUTSIDE: &[&str] = &[
    "Copy",
    "catch_unwind",
    "WaitSet",
    "MachineToolType",
    "std",
    "crate",
    "super",
    "self",
    "Self",
];

/// The keywords an item's name follows.
const ITEMS: &[&str] = &[
    "struct", "enum", "trait", "type", "union", "fn", "const", "static", "mod",
];

fn ident(s: &str) -> bool {
    let mut chars = s.chars();
    chars
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// The segments of a code span that is a Rust name: `Type`, `Type::item`,
/// `path::to::f()`, `f()`, `snake_name`, `name!`. `None` for anything else: a plain
/// word (`check`, `running`), a file, a command, an acronym.
fn rust_name(span: &str) -> Option<Vec<&str>> {
    let span = span.strip_suffix("()").unwrap_or(span);
    if let Some(m) = span.strip_suffix('!') {
        return ident(m).then(|| vec![span]);
    }
    if span.contains("::") {
        let segs: Vec<&str> = span.split("::").collect();
        return segs.iter().all(|s| ident(s)).then_some(segs);
    }
    if !ident(span) {
        return None;
    }
    let camel = span.starts_with(|c: char| c.is_ascii_uppercase())
        && span.chars().any(|c| c.is_ascii_lowercase());
    let snake = span.contains('_') && !span.chars().any(|c| c.is_ascii_uppercase());
    (camel || snake).then(|| vec![span])
}

/// Every name the workspace's Rust files define: items, enum variants and fields (a
/// line that starts with a name and `,`, `(`, `{`, `=` or `:`), macros (`name!`).
fn definitions(root: &Path) -> HashSet<String> {
    let mut out = HashSet::new();
    for file in tree_files(root).iter().filter(|f| f.ends_with(".rs")) {
        let Ok(text) = std::fs::read_to_string(root.join(file)) else {
            continue;
        };
        for line in text.lines() {
            let words: Vec<&str> = line
                .split(|c: char| !(c.is_ascii_alphanumeric() || c == '_' || c == '!'))
                .filter(|w| !w.is_empty())
                .collect();
            for pair in words.windows(2) {
                if ITEMS.contains(&pair[0]) && ident(pair[1]) {
                    out.insert(pair[1].to_string());
                }
                if pair[0] == "macro_rules!" && ident(pair[1]) {
                    out.insert(format!("{}!", pair[1]));
                }
            }
            let t = line.trim_start();
            let t = t.strip_prefix("pub(crate) ").unwrap_or(t);
            let t = t.strip_prefix("pub(super) ").unwrap_or(t);
            let t = t.strip_prefix("pub ").unwrap_or(t);
            let end = t
                .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                .unwrap_or(t.len());
            let (name, rest) = t.split_at(end);
            if ident(name) && rest.trim_start().starts_with([',', '(', '{', '=', ':']) {
                out.insert(name.to_string());
            }
        }
    }
    out
}

#[test]
fn every_name_architecture_md_cites_is_defined() {
    let root = root();
    let arch = std::fs::read_to_string(root.join("ARCHITECTURE.md")).expect("ARCHITECTURE.md");
    let defined = definitions(&root);
    let crates = [
        "hal",
        "cycles",
        "sim",
        "bridge",
        "probebridge",
        "tests",
        "fuzz",
    ];
    let mut checked = 0;
    let mut missing = Vec::new();
    for line in lines(&arch) {
        let Line::Text(n, l) = line else { continue };
        for span in split_code(l).1 {
            let Some(segs) = rust_name(span) else {
                continue;
            };
            checked += 1;
            let unknown: Vec<&str> = segs
                .into_iter()
                .filter(|s| !defined.contains(*s) && !OUTSIDE.contains(s) && !crates.contains(s))
                .collect();
            if !unknown.is_empty() {
                missing.push(format!(
                    "  ARCHITECTURE.md:{n}: `{span}`: {} defined nowhere in the sources",
                    unknown.join(", ")
                ));
            }
        }
    }
    assert!(checked > 50, "the names were found: {checked}");
    assert!(
        missing.is_empty(),
        "names ARCHITECTURE.md cites that the code does not have (renamed, removed, or \
         from outside: then add it to OUTSIDE):\n{}",
        missing.join("\n")
    );
}

#[test]
fn names_are_told_from_words_files_and_commands() {
    assert_eq!(rust_name("RtLoop"), Some(vec!["RtLoop"]));
    assert_eq!(rust_name("Core::prepared"), Some(vec!["Core", "prepared"]));
    assert_eq!(
        rust_name("cycles::runner::run_program()"),
        Some(vec!["cycles", "runner", "run_program"])
    );
    assert_eq!(
        rust_name("machine_conformance!"),
        Some(vec!["machine_conformance!"])
    );
    assert_eq!(rust_name("move_to"), Some(vec!["move_to"]));
    for not_a_name in [
        "check",
        "SYNC",
        "lib.rs",
        "probebridge run",
        "[bus]",
        "#[repr(C)]",
    ] {
        assert_eq!(rust_name(not_a_name), None, "{not_a_name}");
    }
    let defs = definitions(&root());
    for name in [
        "RtLoop",
        "run_program",
        "machine_conformance!",
        "max_jumps",
        "RotaryAtZero",
    ] {
        assert!(defs.contains(name), "{name}");
    }
    assert!(!defs.contains("ForwardingSink"));
}
