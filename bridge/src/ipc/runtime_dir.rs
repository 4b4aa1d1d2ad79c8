//! Where a bridge keeps its run-time files: the service lock ([`super::ServiceLock`])
//! and iceoryx2's root folder (its node and service records, its event sockets).
//!
//! Under systemd that is the unit's `RuntimeDirectory=`, which systemd creates for the
//! service user (no one else may write there) and names in `$RUNTIME_DIRECTORY`; the
//! iceoryx2 root is its `iceoryx2/` folder. Elsewhere it is the temporary folder and
//! iceoryx2's own default root (`/tmp/iceoryx2/`), as for any iceoryx2 program. The
//! estimator child inherits the environment, so `run`, `serve` and their estimator
//! always agree. iceoryx2's shared memory itself lives in `/dev/shm` (POSIX shared
//! memory has no folder of its own).

use iceoryx2::prelude::{Config, SemanticString};
use iceoryx2_bb_system_types::path::Path as IoxPath;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The variable systemd sets for a unit with `RuntimeDirectory=`.
pub const RUNTIME_DIRECTORY: &str = "RUNTIME_DIRECTORY";

/// The unit's runtime folder, if this process runs under one: the first entry of
/// `$RUNTIME_DIRECTORY` (systemd joins several with `:`), when it is absolute.
pub fn unit_runtime_dir() -> Option<PathBuf> {
    unit_runtime_dir_of(std::env::var_os(RUNTIME_DIRECTORY).as_deref())
}

fn unit_runtime_dir_of(value: Option<&std::ffi::OsStr>) -> Option<PathBuf> {
    let value = value?.to_str()?;
    let first = value.split(':').next()?;
    let path = Path::new(first);
    path.is_absolute().then(|| path.to_path_buf())
}

/// The folder of the service lock: the unit's runtime folder, else the temporary one.
pub fn lock_dir() -> PathBuf {
    unit_runtime_dir().unwrap_or_else(std::env::temp_dir)
}

/// The iceoryx2 configuration every node and node listing of this process uses: the
/// global one (iceoryx2's config files or defaults), with the root folder moved into
/// the unit's runtime folder when there is one.
pub fn iceoryx_config() -> Result<&'static Config, String> {
    static CONFIG: OnceLock<Result<Config, String>> = OnceLock::new();
    CONFIG
        .get_or_init(|| {
            let mut config = Config::global_config().clone();
            if let Some(dir) = unit_runtime_dir() {
                let root = iceoryx_root_in(&dir);
                let path = IoxPath::new(root.as_os_str().as_encoded_bytes()).map_err(|e| {
                    format!(
                        "${RUNTIME_DIRECTORY}: {} cannot be the iceoryx2 root: {e:?}",
                        root.display()
                    )
                })?;
                config.global.set_root_path(&path);
            }
            Ok(config)
        })
        .as_ref()
        .map_err(Clone::clone)
}

/// The iceoryx2 root inside a runtime folder (with the trailing `/` iceoryx2 expects).
pub fn iceoryx_root_in(dir: &Path) -> PathBuf {
    let mut root = dir.join("iceoryx2").into_os_string();
    root.push("/");
    PathBuf::from(root)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::ffi::OsStr;

    #[test]
    fn the_first_absolute_entry_of_runtime_directory_is_taken() {
        assert_eq!(unit_runtime_dir_of(None), None);
        assert_eq!(unit_runtime_dir_of(Some(OsStr::new(""))), None);
        assert_eq!(unit_runtime_dir_of(Some(OsStr::new("relative/dir"))), None);
        assert_eq!(
            unit_runtime_dir_of(Some(OsStr::new("/run/probebridge"))),
            Some(PathBuf::from("/run/probebridge"))
        );
        assert_eq!(
            unit_runtime_dir_of(Some(OsStr::new("/run/probebridge:/run/other"))),
            Some(PathBuf::from("/run/probebridge"))
        );
    }

    #[test]
    fn the_iceoryx2_root_is_a_folder_of_the_runtime_folder() {
        assert_eq!(
            iceoryx_root_in(Path::new("/run/probebridge")),
            PathBuf::from("/run/probebridge/iceoryx2/")
        );
        assert!(IoxPath::new(b"/run/probebridge/iceoryx2/").is_ok());
    }
}
