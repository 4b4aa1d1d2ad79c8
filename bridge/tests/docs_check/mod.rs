//! The documentation cannot drift from the tree or the binary. A test module of the
//! binary (`main.rs` declares it under `#[cfg(test)]`), so it reaches the CLI's own clap
//! definition, `Cli`, without exposing it; run it with
//! `cargo test -p probebridge --bin probebridge docs_check`.
//!
//!
//! - every relative link and image in README.md, ARCHITECTURE.md and docs/*.md names a
//!   file that exists, and its `#anchor` a heading of that file (GitHub's slugs);
//! - every path of the tree written in backticks (`hal/src/motion_guard.rs`,
//!   `tests/vcan/cases`, `hal/src/canopen/`) exists, and every Rust file named without
//!   its folder (`cli_signals.rs`, `master/pacing.rs`) is the end of some file's path;
//! - every command line shown in a fenced block whose first word is `probebridge`
//!   (also `./target/release/probebridge`, `cargo run ... -p probebridge -- ...`, after a
//!   `$ ` prompt) parses with the current CLI;
//! - README.md still shows the two commands CI and the tests run, and stays a front
//!   door of at most [`README_MAX_LINES`] lines (the reference lives in docs/);
//! - each crate's `lib.rs` points to its section of ARCHITECTURE.md, and the section
//!   is there.

use super::Cli;
use clap::Parser;
use std::collections::HashSet;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The most lines README.md may have (issue 24): past it, it is a reference again.
const README_MAX_LINES: usize = 250;

/// The workspace root (this crate is `bridge/`).
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("bridge/ has a parent")
        .to_path_buf()
}

/// README.md, ARCHITECTURE.md and every page of docs/, relative to the root.
fn pages(root: &Path) -> Vec<PathBuf> {
    let mut out = vec![PathBuf::from("README.md"), PathBuf::from("ARCHITECTURE.md")];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root.join("docs"))
        .expect("docs/ is readable")
        .map(|e| e.expect("docs/ entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "md"))
        .map(|p| p.strip_prefix(root).expect("under the root").to_path_buf())
        .collect();
    docs.sort();
    out.extend(docs);
    out
}

/// A line of a page outside fenced blocks, or a line inside one.
enum Line<'a> {
    Text(usize, &'a str),
    /// (line number, the block's info string, the line)
    Fenced(usize, &'a str, &'a str),
}

/// The lines of a page, each marked as text or as part of a fenced block (``` or ~~~).
fn lines(text: &str) -> Vec<Line<'_>> {
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
fn slug(heading: &str) -> String {
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
fn anchors(text: &str) -> HashSet<String> {
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
fn split_code(line: &str) -> (String, Vec<&str>) {
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

/// The targets of Markdown links and images (`](target)`) and of HTML `src="..."` and
/// `href="..."` in a line (code spans already cut out).
fn link_targets(text: &str) -> Vec<String> {
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
fn check_link(root: &Path, page: &Path, text: &str, target: &str) -> Result<(), String> {
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

/// The top folders whose paths the pages name in backticks.
const TREE: [&str; 12] = [
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
fn tree_paths(span: &str) -> Vec<String> {
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
fn tree_files(root: &Path) -> Vec<String> {
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
fn bare_rust_file(span: &str) -> Option<&str> {
    let plain = span.ends_with(".rs")
        && !TREE.iter().any(|t| span.starts_with(t))
        && span
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '/' | '.'));
    plain.then_some(span)
}

/// Splits a shell line into words (quotes and backslashes as the shell reads them);
/// stops at a comment or an operator (`|`, `>`, `<`, `;`, `&`), since what follows is
/// another command.
fn shell_words(line: &str) -> Result<Vec<String>, String> {
    let mut words = Vec::new();
    let mut word = String::new();
    let mut in_word = false;
    let mut chars = line.chars();
    while let Some(c) = chars.next() {
        match c {
            '\'' => {
                in_word = true;
                loop {
                    match chars.next() {
                        Some('\'') => break,
                        Some(x) => word.push(x),
                        None => return Err("unclosed ' quote".into()),
                    }
                }
            }
            '"' => {
                in_word = true;
                loop {
                    match chars.next() {
                        Some('"') => break,
                        Some('\\') => match chars.next() {
                            Some(x @ ('"' | '\\' | '$' | '`')) => word.push(x),
                            Some(x) => {
                                word.push('\\');
                                word.push(x);
                            }
                            None => return Err("unclosed \" quote".into()),
                        },
                        Some(x) => word.push(x),
                        None => return Err("unclosed \" quote".into()),
                    }
                }
            }
            '\\' => {
                in_word = true;
                if let Some(x) = chars.next() {
                    word.push(x);
                }
            }
            '#' if !in_word => break,
            '|' | '>' | '<' | ';' | '&' => {
                // `2>&1`: the digits name a file descriptor, not an argument
                if in_word && !word.is_empty() && word.chars().all(|d| d.is_ascii_digit()) {
                    in_word = false;
                }
                break;
            }
            c if c.is_whitespace() => {
                if in_word {
                    words.push(std::mem::take(&mut word));
                    in_word = false;
                }
            }
            c => {
                in_word = true;
                word.push(c);
            }
        }
    }
    if in_word {
        words.push(word);
    }
    Ok(words)
}

/// The arguments after the program name, if the words run probebridge.
fn probebridge_args(words: &[String]) -> Option<Vec<String>> {
    let first = words.first()?;
    if first == "probebridge" || first.ends_with("/probebridge") {
        return Some(words[1..].to_vec());
    }
    let cargo_run = first == "cargo"
        && words.get(1).is_some_and(|w| w == "run")
        && words.windows(2).any(|w| {
            matches!(w[0].as_str(), "-p" | "--package" | "--bin") && w[1] == "probebridge"
        });
    if cargo_run {
        let dashes = words.iter().position(|w| w == "--")?;
        return Some(words[dashes + 1..].to_vec());
    }
    None
}

/// The command lines of a page's fenced shell blocks: (line number, the line as
/// written with `\` continuations joined). A block with `$ ` prompts shows commands only
/// on those lines (the rest is their output).
fn fenced_commands(text: &str) -> Vec<(usize, String)> {
    let mut blocks: Vec<(&str, Vec<(usize, &str)>)> = Vec::new();
    let mut last = 0;
    for line in lines(text) {
        let Line::Fenced(n, info, l) = line else {
            continue;
        };
        if n != last + 1 || blocks.is_empty() {
            blocks.push((info, Vec::new()));
        }
        last = n;
        blocks.last_mut().expect("pushed").1.push((n, l));
    }
    let mut out = Vec::new();
    for (info, block) in blocks {
        let lang = info.split_whitespace().next().unwrap_or("");
        if !matches!(lang, "" | "sh" | "shell" | "bash" | "console" | "text") {
            continue;
        }
        let prompts = block.iter().any(|(_, l)| l.trim_start().starts_with("$ "));
        let mut pending: Option<(usize, String)> = None;
        for (n, l) in block {
            let l = l.trim();
            let (start, mut joined) = match pending.take() {
                Some((start, so_far)) => (start, so_far),
                None if prompts => match l.strip_prefix("$ ") {
                    Some(_) => (n, String::new()),
                    None => continue,
                },
                None => (n, String::new()),
            };
            let l = if joined.is_empty() {
                l.strip_prefix("$ ").unwrap_or(l)
            } else {
                l
            };
            match l.strip_suffix('\\') {
                Some(head) => {
                    joined.push_str(head.trim_end());
                    joined.push(' ');
                    pending = Some((start, joined));
                }
                None => {
                    joined.push_str(l);
                    out.push((start, joined));
                }
            }
        }
        if let Some(p) = pending {
            out.push(p);
        }
    }
    out
}

/// Whether `args` parse with the CLI (`--help`/`--version` count as parsing); else
/// clap's error.
fn parses(args: &[String]) -> Result<(), String> {
    let argv = std::iter::once("probebridge".to_string()).chain(args.iter().cloned());
    match Cli::try_parse_from(argv) {
        Ok(_) => Ok(()),
        Err(e)
            if matches!(
                e.kind(),
                clap::error::ErrorKind::DisplayHelp | clap::error::ErrorKind::DisplayVersion
            ) =>
        {
            Ok(())
        }
        Err(e) => Err(e.to_string().lines().next().unwrap_or("").to_string()),
    }
}

/// What one page gets wrong, one line each; and how many links, paths and commands it
/// checked.
#[derive(Default)]
struct Findings {
    errors: Vec<String>,
    links: usize,
    paths: usize,
    commands: usize,
}

fn check_page(root: &Path, files: &[String], page: &Path, text: &str, found: &mut Findings) {
    let name = page.display();
    for line in lines(text) {
        let Line::Text(n, l) = line else { continue };
        let (prose, spans) = split_code(l);
        for target in link_targets(&prose) {
            found.links += 1;
            if let Err(e) = check_link(root, page, text, &target) {
                found
                    .errors
                    .push(format!("{name}:{n}: link ({target}): {e}"));
            }
        }
        for span in spans {
            for path in tree_paths(span) {
                found.paths += 1;
                if !root.join(&path).exists() {
                    found
                        .errors
                        .push(format!("{name}:{n}: `{path}` does not exist in the tree"));
                }
            }
            if let Some(file) = bare_rust_file(span) {
                found.paths += 1;
                let tail = format!("/{file}");
                if !files.iter().any(|f| f.ends_with(&tail)) {
                    found.errors.push(format!(
                        "{name}:{n}: `{file}`: no file of the tree is called so"
                    ));
                }
            }
        }
    }
    for (n, command) in fenced_commands(text) {
        let words = match shell_words(&command) {
            Ok(w) => w,
            Err(e) => {
                found.errors.push(format!("{name}:{n}: {command}: {e}"));
                continue;
            }
        };
        if let Some(args) = probebridge_args(&words) {
            found.commands += 1;
            if let Err(e) = parses(&args) {
                found
                    .errors
                    .push(format!("{name}:{n}: `{command}` does not parse: {e}"));
            }
        }
    }
}

fn check_tree(root: &Path) -> Findings {
    let mut found = Findings::default();
    let files = tree_files(root);
    for page in pages(root) {
        match std::fs::read_to_string(root.join(&page)) {
            Ok(text) => check_page(root, &files, &page, &text, &mut found),
            Err(e) => found
                .errors
                .push(format!("{}: cannot be read: {e}", page.display())),
        }
    }
    found
}

#[test]
fn every_link_path_and_command_of_the_docs_holds() {
    let root = root();
    let found = check_tree(&root);
    println!(
        "docs: {} links, {} tree paths, {} probebridge command lines checked",
        found.links, found.paths, found.commands
    );
    let mut report = String::new();
    for e in &found.errors {
        let _ = writeln!(report, "  {e}");
    }
    assert!(found.errors.is_empty(), "the docs have drifted:\n{report}");
    // The check has something to check: it would pass vacuously if a change to the
    // pages (or to this parser) made it find nothing.
    assert!(
        found.links > 50 && found.paths > 50 && found.commands >= 5,
        "too little found"
    );
}

#[test]
fn the_readme_still_shows_the_two_commands() {
    let readme = std::fs::read_to_string(root().join("README.md")).expect("README.md");
    let commands: Vec<String> = fenced_commands(&readme)
        .into_iter()
        .map(|(_, c)| c)
        .collect();
    for wanted in [
        "cargo run --release -p probebridge -- demo",
        "bash scripts/test",
    ] {
        assert!(
            commands.iter().any(|c| c == wanted),
            "README.md must show `{wanted}` in a fenced block (CI and the tests run it)"
        );
    }
}

#[test]
fn the_readme_stays_a_front_door() {
    let readme = std::fs::read_to_string(root().join("README.md")).expect("README.md");
    let n = readme.lines().count();
    assert!(
        n <= README_MAX_LINES,
        "README.md has {n} lines, at most {README_MAX_LINES}: it is the front door; \
         move the reference into a page of docs/ and link it from \"Where to go next\""
    );
}

/// The workspace's members, as the root `Cargo.toml` lists them.
fn members(root: &Path) -> Vec<String> {
    let manifest = std::fs::read_to_string(root.join("Cargo.toml")).expect("Cargo.toml");
    let list = manifest
        .lines()
        .find_map(|l| l.trim().strip_prefix("members = ["))
        .expect("Cargo.toml lists its members on one line");
    list.trim_end_matches(']')
        .split(',')
        .map(|m| m.trim().trim_matches('"').to_string())
        .filter(|m| !m.is_empty())
        .collect()
}

#[test]
fn each_crates_lib_rs_points_to_its_section_of_architecture_md() {
    let root = root();
    let arch = std::fs::read_to_string(root.join("ARCHITECTURE.md")).expect("ARCHITECTURE.md");
    let sections = anchors(&arch);
    let crates = members(&root);
    assert!(crates.len() >= 6, "the members were found: {crates:?}");
    let mut wrong = Vec::new();
    for member in &crates {
        let lib = format!("{member}/src/lib.rs");
        let text = std::fs::read_to_string(root.join(&lib)).unwrap_or_default();
        let doc: String = text
            .lines()
            .filter_map(|l| l.trim_start().strip_prefix("//!"))
            .collect::<Vec<_>>()
            .join("\n");
        let link = format!("ARCHITECTURE.md#{member}");
        if !doc.contains(&link) {
            wrong.push(format!("  {lib}: its crate doc does not name `{link}`"));
        } else if !sections.contains(member.as_str()) {
            wrong.push(format!("  {lib}: ARCHITECTURE.md has no section #{member}"));
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

#[test]
fn a_broken_link_a_missing_path_and_a_wrong_flag_are_found() {
    let root = root();
    let page = Path::new("docs/testing.md");
    let text = "# A page\n\n## Its part\n\n\
        [fine](#its-part), [fine too](../README.md#two-commands), [gone](nowhere.md),\n\
        [no anchor](modbus.md#no-such-heading), `hal/src/no_such_file.rs`,\n\
        `bridge/src/{main,no_such}.rs`, `fuzz/crashes/TARGET/KIND-HASH`.\n\n\
        ```sh\n$ probebridge run configs/programs/431-plane.h \\\n    --no-such-flag\n\
        no output is parsed\n$ probebridge demo --realtime\n```\n";
    let mut found = Findings::default();
    check_page(&root, &tree_files(&root), page, text, &mut found);
    let all = found.errors.join("\n");
    assert_eq!(found.errors.len(), 5, "{all}");
    for wanted in [
        "docs/testing.md:5: link (nowhere.md): docs/nowhere.md does not exist",
        "docs/testing.md:6: link (modbus.md#no-such-heading): #no-such-heading: no heading",
        "docs/testing.md:6: `hal/src/no_such_file.rs` does not exist",
        "docs/testing.md:7: `bridge/src/no_such.rs` does not exist",
        "docs/testing.md:10: `probebridge run configs/programs/431-plane.h --no-such-flag` \
         does not parse: error: unexpected argument '--no-such-flag'",
    ] {
        assert!(all.contains(wanted), "missing: {wanted}\nin:\n{all}");
    }
    assert_eq!((found.links, found.paths, found.commands), (4, 3, 2));
}

#[test]
fn slugs_and_words_are_read_as_github_and_the_shell_read_them() {
    assert_eq!(
        slug("The PLC face: register map"),
        "the-plc-face-register-map"
    );
    assert_eq!(
        slug("Real SocketCAN in a VM (`.ci/vcan/run`)"),
        "real-socketcan-in-a-vm-civcanrun"
    );
    assert_eq!(slug("What happens when..."), "what-happens-when");
    let words = shell_words(r#"probebridge run "a b.h" --out 'x y' c\ d # comment"#).unwrap();
    assert_eq!(
        words,
        ["probebridge", "run", "a b.h", "--out", "x y", "c d"]
    );
    assert_eq!(
        shell_words("probebridge demo 2>&1 | head -3").unwrap(),
        ["probebridge", "demo"]
    );
}
