//! Where the machine's state lives: the preset table, the active and the saved
//! kinematics (and whatever else a machine remembers between runs), never in the
//! shipped `configs/`. One folder per machine below the root this module resolves.

use std::path::{Path, PathBuf};

/// The state root: `explicit` (`--state-dir`), else systemd's `$STATE_DIRECTORY`
/// (the unit's `StateDirectory=`, for `serve`; its first entry), else
/// `$XDG_STATE_HOME/probebridge`, else `$HOME/.local/state/probebridge` (the XDG
/// default). Created when missing; `Err` says which variable was used and why it
/// cannot be.
pub fn state_dir(explicit: Option<&Path>) -> Result<PathBuf, String> {
    let env = |name: &str| std::env::var_os(name).filter(|v| !v.is_empty());
    let (dir, from) = if let Some(d) = explicit {
        (d.to_path_buf(), "--state-dir".to_string())
    } else if let Some(d) = env("STATE_DIRECTORY") {
        // systemd joins several StateDirectory= entries with ':'.
        let first = d
            .to_string_lossy()
            .split(':')
            .next()
            .unwrap_or("")
            .to_string();
        (PathBuf::from(first), "$STATE_DIRECTORY".to_string())
    } else if let Some(d) = env("XDG_STATE_HOME").filter(|d| Path::new(d).is_absolute()) {
        (
            PathBuf::from(d).join("probebridge"),
            "$XDG_STATE_HOME".to_string(),
        )
    } else if let Some(h) = env("HOME") {
        (
            PathBuf::from(h).join(".local/state/probebridge"),
            "$HOME/.local/state".to_string(),
        )
    } else {
        return Err(
            "no state directory: neither --state-dir, $STATE_DIRECTORY, $XDG_STATE_HOME nor $HOME is set"
                .into(),
        );
    };
    std::fs::create_dir_all(&dir)
        .map_err(|e| format!("state directory {} (from {from}): {e}", dir.display()))?;
    Ok(dir)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_explicit_folder_is_created_and_used() {
        let d = std::env::temp_dir().join(format!("pb-state-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        let got = state_dir(Some(&d.join("a/b"))).unwrap();
        assert_eq!(got, d.join("a/b"));
        assert!(got.is_dir());
        let _ = std::fs::remove_dir_all(&d);
        let e = state_dir(Some(Path::new("/proc/self/no/such"))).unwrap_err();
        assert!(e.contains("--state-dir"), "{e}");
    }
}
