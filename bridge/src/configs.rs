//! Where the shipped configuration lives: `$PROBEBRIDGE_CONFIGS`, `./configs`, the
//! repository's `configs/` next to the build, or `/etc/probebridge` on a gateway.

use std::path::{Path, PathBuf};

pub fn configs_dir() -> PathBuf {
    if let Some(d) = std::env::var_os("PROBEBRIDGE_CONFIGS") {
        return PathBuf::from(d);
    }
    let local = PathBuf::from("configs");
    if local.join("machines").is_dir() {
        return local;
    }
    // target/{debug,release}/probebridge -> the workspace's configs/.
    if let Ok(exe) = std::env::current_exe() {
        for up in exe.ancestors().skip(1).take(4) {
            let c = up.join("configs");
            if c.join("machines").is_dir() {
                return c;
            }
        }
    }
    let source_tree = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs");
    if source_tree.join("machines").is_dir() {
        return source_tree;
    }
    PathBuf::from("/etc/probebridge")
}

/// The scenario `probe`, `run` and `demo` use when none is given.
pub fn default_scenario() -> PathBuf {
    configs_dir().join("scenarios/demo-sphere.toml")
}

pub fn machines_dir() -> PathBuf {
    configs_dir().join("machines")
}
