//! Each crate's `lib.rs` points to its section of ARCHITECTURE.md, and the section is
//! there.

use super::markdown::anchors;
use super::root;
use std::path::Path;

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
