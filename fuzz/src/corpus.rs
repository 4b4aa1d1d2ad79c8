//! Seeds: the files the project ships (programs, machines, scenarios, the gateway
//! configuration, candump logs), read from the workspace this crate was built in.

use std::path::{Path, PathBuf};

/// The workspace root (the folder holding `configs/`).
pub fn workspace() -> PathBuf {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    manifest.parent().unwrap_or(manifest).to_path_buf()
}

/// `configs/<sub>` of the workspace.
pub fn configs(sub: &str) -> PathBuf {
    workspace().join("configs").join(sub)
}

/// The contents of the files in `dir` whose names end with `suffix`, by name.
pub fn files(dir: &Path, suffix: &str) -> Vec<Vec<u8>> {
    let mut paths: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    paths.retain(|p| p.to_string_lossy().ends_with(suffix));
    paths.sort();
    paths.iter().filter_map(|p| std::fs::read(p).ok()).collect()
}

/// Seeds from files plus literal ones.
pub fn with(mut from_files: Vec<Vec<u8>>, literal: &[&str]) -> Vec<Vec<u8>> {
    from_files.extend(literal.iter().map(|s| s.as_bytes().to_vec()));
    from_files
}
