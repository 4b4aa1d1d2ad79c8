//! The documentation cannot drift from the tree or the binary. A test module of the
//! binary (`main.rs` declares it under `#[cfg(test)]`), so it reaches the CLI's own clap
//! definition, `Cli`, without exposing it; run it with
//! `cargo test -p probebridge --bin probebridge docs_check`. One concern a file:
//!
//! - `links.rs`: every relative link and image in README.md, ARCHITECTURE.md and
//!   docs/*.md names a file that exists, and its `#anchor` a heading of that file
//!   (GitHub's slugs, `markdown.rs`);
//! - `paths.rs`: every path of the tree written in backticks (`hal/src/motion_guard.rs`,
//!   `tests/vcan/cases`, `hal/src/canopen/`) exists, and every Rust file named without
//!   its folder (`cli_signals.rs`, `master/pacing.rs`) is the end of some file's path;
//! - `commands.rs`: every command line shown in a fenced block whose first word is
//!   `probebridge` (also `./target/release/probebridge`, `cargo run ... -p probebridge --
//!   ...`, after a `$ ` prompt) parses with the current CLI;
//! - `runs.rs`: every such line of README.md runs as a process from the clone and exits
//!   as the README says (the binary the suite built, a `HOME` and `TMPDIR` of its own);
//! - `readme.rs`: README.md still shows the two commands CI and the tests run, and
//!   stays a front door (the reference lives in docs/);
//! - `architecture.rs`: each crate's `lib.rs` points to its section of ARCHITECTURE.md,
//!   and the section is there;
//! - `names.rs`: every type, function and macro ARCHITECTURE.md names in backticks is
//!   defined in the sources.

mod architecture;
mod commands;
mod links;
mod markdown;
mod names;
mod paths;
mod readme;
mod runs;

use commands::{fenced_commands, parses, probebridge_args, shell_words};
use links::{check_link, link_targets};
use markdown::{lines, slug, split_code, Line};
use paths::{bare_rust_file, tree_files, tree_paths};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

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
