//! The one way probebridge writes a file: complete or not at all, never through
//! something that is not a regular file.
//!
//! A result, a measuring log, the kinematics or the preset table is written to a
//! temporary file in the same folder, fsynced, renamed over the target and the folder
//! fsynced, so a crash or a kill leaves either the old file or the new one. A target
//! that exists but is not a regular file (a symlink, a device such as `/dev/full`, a
//! FIFO, a folder) is refused: renaming over it would replace the node itself, or the
//! write would go somewhere the user did not name. Temporaries left by a process that
//! died mid-write are removed by the next write to the same path.

use std::fs::{self, File, OpenOptions};
use std::io::Write;
use std::os::unix::fs::FileTypeExt;
use std::path::{Path, PathBuf};

/// Why a write was refused or failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum WriteErrorKind {
    /// Something other than a regular file is at the path; nothing was written.
    NotRegularFile,
    /// The folder the file goes into does not exist or is not a folder.
    NoFolder,
    /// The file system refused or failed the write (permissions, full, read-only).
    Io,
}

/// A refused or failed write, naming the file.
#[derive(Debug, thiserror::Error)]
#[error("cannot write {}: {message}", path.display())]
pub struct WriteError {
    pub path: PathBuf,
    kind: WriteErrorKind,
    /// The operating system's reason, for [`WriteErrorKind::Io`].
    io_kind: Option<std::io::ErrorKind>,
    message: String,
}

impl WriteError {
    pub fn kind(&self) -> WriteErrorKind {
        self.kind
    }

    /// Why, without the path (for errors that name the path themselves).
    pub fn reason(&self) -> &str {
        &self.message
    }

    /// As an `std::io::Error` (the reason, without the path), for callers whose errors
    /// carry one.
    pub fn to_io(&self) -> std::io::Error {
        let kind = match self.kind {
            WriteErrorKind::NotRegularFile => std::io::ErrorKind::InvalidInput,
            WriteErrorKind::NoFolder => std::io::ErrorKind::NotFound,
            WriteErrorKind::Io => self.io_kind.unwrap_or(std::io::ErrorKind::Other),
        };
        std::io::Error::new(kind, self.message.clone())
    }

    fn new(path: &Path, kind: WriteErrorKind, message: impl Into<String>) -> Self {
        Self {
            path: path.to_path_buf(),
            kind,
            io_kind: None,
            message: message.into(),
        }
    }

    fn io(path: &Path, e: &std::io::Error) -> Self {
        Self {
            io_kind: Some(e.kind()),
            ..Self::new(path, WriteErrorKind::Io, e.to_string())
        }
    }
}

/// What kind of node is at `path`, in words, when it is not a regular file.
fn non_regular(meta: &fs::Metadata) -> Option<&'static str> {
    let t = meta.file_type();
    if t.is_file() {
        None
    } else if t.is_symlink() {
        Some("a symbolic link")
    } else if t.is_dir() {
        Some("a folder")
    } else if t.is_char_device() {
        Some("a character device")
    } else if t.is_block_device() {
        Some("a block device")
    } else if t.is_fifo() {
        Some("a FIFO")
    } else if t.is_socket() {
        Some("a socket")
    } else {
        Some("not a regular file")
    }
}

fn folder_of(path: &Path) -> &Path {
    path.parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
}

fn file_name(path: &Path) -> Result<String, WriteError> {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .ok_or_else(|| WriteError::new(path, WriteErrorKind::NoFolder, "not a file name"))
}

fn temp_prefix(name: &str) -> String {
    format!(".{name}.tmp")
}

/// Refuses a path whose node is not a regular file, and a folder that is missing.
fn check_target(path: &Path) -> Result<(), WriteError> {
    match fs::symlink_metadata(path) {
        Ok(meta) => {
            if let Some(what) = non_regular(&meta) {
                return Err(WriteError::new(
                    path,
                    WriteErrorKind::NotRegularFile,
                    format!("it is {what}, not a regular file; refusing to replace it"),
                ));
            }
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => return Err(WriteError::io(path, &e)),
    }
    let dir = folder_of(path);
    match fs::metadata(dir) {
        Ok(m) if m.is_dir() => Ok(()),
        Ok(_) => Err(WriteError::new(
            path,
            WriteErrorKind::NoFolder,
            format!("{} is not a folder", dir.display()),
        )),
        Err(e) => Err(WriteError::new(
            path,
            WriteErrorKind::NoFolder,
            format!("folder {}: {e}", dir.display()),
        )),
    }
}

/// Checks, before anything moves, that `path` can be written: its folder exists, the
/// node at the path (if any) is a regular file, and a file can be created in the
/// folder (a real create and remove, which also catches a read-only file system).
pub fn check_writable(path: &Path) -> Result<(), WriteError> {
    check_target(path)?;
    let name = file_name(path)?;
    let probe = folder_of(path).join(format!(
        "{}{}-check",
        temp_prefix(&name),
        std::process::id()
    ));
    match OpenOptions::new().write(true).create_new(true).open(&probe) {
        Ok(_) => {
            let _ = fs::remove_file(&probe);
            Ok(())
        }
        Err(e) => Err(WriteError::io(path, &e)),
    }
}

/// Writes `bytes` to `path` atomically (see the module documentation).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), WriteError> {
    check_target(path)?;
    let name = file_name(path)?;
    let dir = folder_of(path);
    remove_stale_temporaries(dir, &name);
    // Unique per write, so two threads of one process writing the same path (a
    // gateway serving several requests) never share a temporary.
    static SERIAL: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let serial = SERIAL.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let tmp = dir.join(format!(
        "{}{}-{serial}",
        temp_prefix(&name),
        std::process::id()
    ));
    let result = (|| -> std::io::Result<()> {
        let mut f = OpenOptions::new()
            .write(true)
            .create(true)
            .truncate(true)
            .open(&tmp)?;
        // A replaced file keeps its permissions (a shared history or kinematics file
        // may be group-writable on purpose).
        if let Ok(meta) = fs::metadata(path) {
            f.set_permissions(meta.permissions())?;
        }
        f.write_all(bytes)?;
        f.sync_all()?;
        fs::rename(&tmp, path)?;
        // The rename is durable only once the folder is.
        File::open(dir)?.sync_all()
    })();
    result.map_err(|e| {
        let _ = fs::remove_file(&tmp);
        WriteError::io(path, &e)
    })
}

/// As [`write_atomic`], keeping the replaced file as `<path>.prev` (itself written
/// atomically). Nothing is kept when there was no file.
pub fn write_atomic_keeping_previous(path: &Path, bytes: &[u8]) -> Result<(), WriteError> {
    check_target(path)?;
    match fs::read(path) {
        Ok(old) => write_atomic(&previous_path(path), &old)?,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => return Err(WriteError::io(path, &e)),
    }
    write_atomic(path, bytes)
}

/// `<path>.prev`, where [`write_atomic_keeping_previous`] keeps the replaced version.
pub fn previous_path(path: &Path) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(".prev");
    PathBuf::from(s)
}

/// Removes `.<name>.tmp<pid>[-<serial>]` files in `dir` whose process no longer runs: what a
/// write killed between create and rename left behind.
fn remove_stale_temporaries(dir: &Path, name: &str) {
    let prefix = temp_prefix(name);
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let file = entry.file_name();
        let Some(rest) = file.to_str().and_then(|f| f.strip_prefix(&prefix)) else {
            continue;
        };
        // `<pid>`, `<pid>-<serial>` or `<pid>-check`.
        let pid = rest.split('-').next().unwrap_or(rest);
        let Ok(pid) = pid.parse::<i32>() else {
            continue;
        };
        if pid > 0 && !process_alive(pid) {
            let _ = fs::remove_file(entry.path());
        }
    }
}

fn process_alive(pid: i32) -> bool {
    // SAFETY: signal 0 sends nothing; it only asks whether the process exists.
    let r = unsafe { libc::kill(pid, 0) };
    r == 0 || std::io::Error::last_os_error().raw_os_error() == Some(libc::EPERM)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> PathBuf {
        let d =
            std::env::temp_dir().join(format!("probebridge-atomic-{name}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&d);
        fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn writes_replaces_and_keeps_the_previous_version() {
        let d = dir("replace");
        let p = d.join("r.json");
        write_atomic(&p, b"one").unwrap();
        write_atomic_keeping_previous(&p, b"two").unwrap();
        assert_eq!(fs::read(&p).unwrap(), b"two");
        assert_eq!(fs::read(previous_path(&p)).unwrap(), b"one");
        // Only the file and its .prev: no temporary left behind.
        assert_eq!(fs::read_dir(&d).unwrap().count(), 2);
    }

    #[test]
    fn refuses_a_symlink_and_leaves_its_target_alone() {
        let d = dir("symlink");
        let target = d.join("target.txt");
        fs::write(&target, "keep").unwrap();
        let link = d.join("link.txt");
        std::os::unix::fs::symlink(&target, &link).unwrap();
        let e = write_atomic(&link, b"x").unwrap_err();
        assert_eq!(e.kind(), WriteErrorKind::NotRegularFile);
        assert!(e.to_string().contains("symbolic link"), "{e}");
        assert_eq!(fs::read(&target).unwrap(), b"keep");
        assert!(fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(
            check_writable(&link).unwrap_err().kind(),
            WriteErrorKind::NotRegularFile
        );
    }

    #[test]
    fn refuses_a_device_and_a_fifo() {
        let e = write_atomic(Path::new("/dev/null"), b"x").unwrap_err();
        assert_eq!(e.kind(), WriteErrorKind::NotRegularFile);
        assert!(e.to_string().contains("character device"), "{e}");
        assert!(fs::metadata("/dev/null")
            .unwrap()
            .file_type()
            .is_char_device());

        let d = dir("fifo");
        let fifo = d.join("pipe");
        let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: plain mkfifo on a path we own.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        let e = write_atomic(&fifo, b"x").unwrap_err();
        assert_eq!(e.kind(), WriteErrorKind::NotRegularFile);
        assert!(e.to_string().contains("FIFO"), "{e}");
    }

    #[test]
    fn a_missing_folder_is_refused_before_anything_is_written() {
        let d = dir("missing");
        let p = d.join("no/such/r.json");
        let e = check_writable(&p).unwrap_err();
        assert_eq!(e.kind(), WriteErrorKind::NoFolder);
        assert!(e.to_string().contains("r.json"), "{e}");
        assert!(!d.join("no").exists());
    }

    #[test]
    fn check_writable_leaves_nothing_behind() {
        let d = dir("check");
        check_writable(&d.join("r.json")).unwrap();
        assert_eq!(fs::read_dir(&d).unwrap().count(), 0);
    }

    #[test]
    fn temporaries_of_dead_writers_are_removed() {
        let d = dir("stale");
        // A pid that cannot be running: above the kernel's pid_max limit.
        let stale = d.join(".k.toml.tmp2147483600");
        fs::write(&stale, "half").unwrap();
        let stale_serial = d.join(".k.toml.tmp2147483600-7");
        fs::write(&stale_serial, "half").unwrap();
        let mine = d.join(format!(".k.toml.tmp{}-check", std::process::id()));
        fs::write(&mine, "").unwrap();
        write_atomic(&d.join("k.toml"), b"whole").unwrap();
        assert!(!stale.exists());
        assert!(!stale_serial.exists());
        // A live process's temporary is not touched.
        assert!(mine.exists());
    }

    #[test]
    fn threads_of_one_process_writing_one_path_never_share_a_temporary() {
        let d = dir("threads");
        let p = d.join("TCHPR444.html");
        std::thread::scope(|s| {
            for t in 0..4u8 {
                let p = &p;
                s.spawn(move || {
                    for _ in 0..50 {
                        write_atomic(p, &[t; 64]).unwrap();
                    }
                });
            }
        });
        let bytes = fs::read(&p).unwrap();
        assert!(bytes.len() == 64 && bytes.iter().all(|b| *b == bytes[0]));
        assert_eq!(fs::read_dir(&d).unwrap().count(), 1, "no temporary left");
    }

    #[test]
    fn a_folder_at_the_path_is_refused() {
        let d = dir("folder");
        let p = d.join("sub");
        fs::create_dir(&p).unwrap();
        let e = write_atomic(&p, b"x").unwrap_err();
        assert_eq!(e.kind(), WriteErrorKind::NotRegularFile);
        assert!(e.to_string().contains("a folder"), "{e}");
    }

    #[test]
    fn a_failing_file_system_is_an_error_naming_the_file() {
        // /proc/self accepts no new files, even for root.
        let p = Path::new("/proc/self/kin.toml");
        let e = write_atomic(p, b"x").unwrap_err();
        assert_eq!(e.kind(), WriteErrorKind::Io);
        assert!(e.to_string().contains("/proc/self/kin.toml"), "{e}");
        assert_eq!(check_writable(p).unwrap_err().kind(), WriteErrorKind::Io);
    }
}
