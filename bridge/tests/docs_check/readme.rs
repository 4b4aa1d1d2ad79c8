//! README.md is the front door: it shows the two commands CI and the tests run, and
//! stays short (the reference lives in docs/).

use super::commands::fenced_commands;
use super::root;

/// The most lines README.md may have (issue 24): past it, it is a reference again.
const README_MAX_LINES: usize = 250;

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
