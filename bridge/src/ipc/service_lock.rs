//! One bridge per service prefix. Two sessions on one `--service` would publish their
//! contacts into one stream and share one estimator, which ends with the first of them;
//! the second session is refused at once instead. The claim is an exclusive `flock` on
//! a lock file named after the prefix in [`super::lock_dir`] (the unit's runtime folder
//! under systemd, else the temporary folder): the kernel drops it when
//! the holder exits in any way (SIGKILL included), so a crashed bridge never blocks the
//! next one, and two bridges starting at the same instant cannot both win.

use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, SeekFrom, Write};
use std::os::fd::AsRawFd;
use std::os::unix::fs::{MetadataExt, OpenOptionsExt};
use std::path::{Path, PathBuf};

/// Held while a session uses its prefix; dropping it frees the prefix.
#[derive(Debug)]
pub struct ServiceLock {
    path: PathBuf,
    file: File,
}

/// Why a prefix could not be claimed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ServiceLockError {
    /// Another process holds the prefix.
    #[error("the iceoryx2 service {prefix:?} is in use by another probebridge ({holder}); give this one another --service")]
    InUse { prefix: String, holder: String },
    /// The lock file cannot be opened or locked.
    #[error("cannot claim the iceoryx2 service {prefix:?} ({path}): {source}")]
    Io {
        prefix: String,
        path: PathBuf,
        source: std::io::Error,
    },
}

impl ServiceLockError {
    pub fn kind(&self) -> ServiceLockErrorKind {
        match self {
            ServiceLockError::InUse { .. } => ServiceLockErrorKind::InUse,
            ServiceLockError::Io { .. } => ServiceLockErrorKind::Io,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum ServiceLockErrorKind {
    InUse,
    Io,
}

impl ServiceLock {
    /// Claims `prefix` for this process, or says who holds it.
    pub fn acquire(prefix: &str) -> Result<Self, ServiceLockError> {
        Self::acquire_in(&super::lock_dir(), prefix)
    }

    /// [`ServiceLock::acquire`] with the lock file in `dir`.
    pub fn acquire_in(dir: &Path, prefix: &str) -> Result<Self, ServiceLockError> {
        let path = dir.join(lock_file_name(prefix));
        let io = |source| ServiceLockError::Io {
            prefix: prefix.to_string(),
            path: path.clone(),
            source,
        };
        loop {
            // O_NOFOLLOW: a symlink planted at the path is not followed.
            let open = |write: bool| {
                OpenOptions::new()
                    .read(true)
                    .write(write)
                    .create(write)
                    .truncate(false)
                    .mode(0o644)
                    .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
                    .open(&path)
            };
            // A file another user left (a killed bridge of the gateway's user) can
            // still be locked read-only; only the pid is not written then.
            let (mut file, writable) = match open(true) {
                Ok(f) => (f, true),
                Err(e) if e.kind() == std::io::ErrorKind::PermissionDenied => {
                    (open(false).map_err(io)?, false)
                }
                Err(e) => return Err(io(e)),
            };
            // SAFETY: flock on a descriptor this function owns.
            if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
                let e = std::io::Error::last_os_error();
                if e.raw_os_error() != Some(libc::EWOULDBLOCK) {
                    return Err(io(e));
                }
                let mut holder = String::new();
                let _ = file.read_to_string(&mut holder);
                let holder = match holder.trim() {
                    "" => "a process that is starting".to_string(),
                    h => h.to_string(),
                };
                return Err(ServiceLockError::InUse {
                    prefix: prefix.to_string(),
                    holder,
                });
            }
            // The previous holder may have removed the file between our open and our
            // lock: then the lock is on a file nobody else will see; take a fresh one.
            let ours = file.metadata().map_err(io)?;
            match std::fs::symlink_metadata(&path) {
                Ok(now) if now.dev() == ours.dev() && now.ino() == ours.ino() => {}
                _ => continue,
            }
            if writable {
                file.set_len(0).map_err(io)?;
                file.seek(SeekFrom::Start(0)).map_err(io)?;
                write!(file, "pid {}", std::process::id()).map_err(io)?;
            }
            return Ok(Self { path, file });
        }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for ServiceLock {
    fn drop(&mut self) {
        // Removed while still locked, so no one can lock this file after we let go
        // (a process that opened it meanwhile sees it gone and starts over).
        let _ = std::fs::remove_file(&self.path);
        // SAFETY: unlocking our own descriptor (closing it would do the same).
        unsafe {
            libc::flock(self.file.as_raw_fd(), libc::LOCK_UN);
        }
    }
}

/// `probebridge-service-<prefix>.lock`, with every byte outside `[A-Za-z0-9._-]`
/// written as `%XX`, so distinct prefixes never share a file.
fn lock_file_name(prefix: &str) -> String {
    let mut name = String::from("probebridge-service-");
    for b in prefix.trim_end_matches('/').bytes() {
        if b.is_ascii_alphanumeric() || matches!(b, b'.' | b'_' | b'-') {
            name.push(b as char);
        } else {
            name.push_str(&format!("%{b:02X}"));
        }
    }
    name.push_str(".lock");
    name
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("pb-lock-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn a_second_claim_is_refused_until_the_first_is_dropped() {
        let d = dir("second");
        let first = ServiceLock::acquire_in(&d, "pb/a").unwrap();
        let e = ServiceLock::acquire_in(&d, "pb/a").unwrap_err();
        assert_eq!(e.kind(), ServiceLockErrorKind::InUse);
        let msg = e.to_string();
        assert!(
            msg.contains("\"pb/a\" is in use")
                && msg.contains(&format!("pid {}", std::process::id())),
            "{msg}"
        );
        // Another prefix is free.
        let other = ServiceLock::acquire_in(&d, "pb_a").unwrap();
        drop(first);
        assert!(!d.join(lock_file_name("pb/a")).exists());
        ServiceLock::acquire_in(&d, "pb/a").unwrap();
        drop(other);
    }

    #[test]
    fn names_keep_prefixes_apart() {
        assert_eq!(
            lock_file_name("probebridge"),
            "probebridge-service-probebridge.lock"
        );
        assert_ne!(lock_file_name("a/b"), lock_file_name("a_b"));
        assert_eq!(lock_file_name("a/b/"), "probebridge-service-a%2Fb.lock");
    }
}
