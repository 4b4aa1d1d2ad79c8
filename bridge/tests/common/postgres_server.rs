//! A PostgreSQL server of a test's own: Debian's `postgresql` binaries
//! (`scripts/install-test-peers`), `initdb` and `postgres` as an unprivileged user in a
//! temporary folder, on a port asked of the kernel (a test can pause the whole server,
//! backends included, with SIGSTOP).
//! Included with `#[path]` by the tests that need it (each uses part of it).
#![allow(dead_code)]

use super::common::tmpdir;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The folder holding `initdb` and `postgres`: on PATH, else Debian's
/// /usr/lib/postgresql/<version>/bin.
pub fn pg_bin() -> Option<PathBuf> {
    let on_path = std::env::var_os("PATH").and_then(|p| {
        std::env::split_paths(&p)
            .find(|d| d.join("initdb").is_file() && d.join("postgres").is_file())
    });
    on_path.or_else(|| {
        let mut dirs: Vec<PathBuf> = std::fs::read_dir("/usr/lib/postgresql")
            .ok()?
            .filter_map(|e| e.ok().map(|e| e.path().join("bin")))
            .filter(|d| d.join("initdb").is_file())
            .collect();
        dirs.sort();
        dirs.pop()
    })
}

/// A PostgreSQL server of this test; stopped (fast shutdown) and removed on drop.
pub struct Server {
    bin: PathBuf,
    child: Child,
    port: u16,
    dir: PathBuf,
    /// Started and not yet stopped (its pid is still ours to signal).
    running: bool,
}

/// The uid/gid to run PostgreSQL as: ours, or the `postgres` user's when we are root.
fn run_as() -> (u32, u32) {
    // SAFETY: getuid/getgid cannot fail.
    let (uid, gid) = unsafe { (libc::getuid(), libc::getgid()) };
    if uid != 0 {
        return (uid, gid);
    }
    let name = std::ffi::CString::new("postgres").unwrap();
    // SAFETY: getpwnam returns a pointer into static storage or null; read at once.
    let pw = unsafe { libc::getpwnam(name.as_ptr()) };
    assert!(
        !pw.is_null(),
        "running as root and there is no user \"postgres\" to run the server as"
    );
    // SAFETY: not null, checked above.
    unsafe { ((*pw).pw_uid, (*pw).pw_gid) }
}

fn as_user(cmd: &mut Command, (uid, gid): (u32, u32)) -> &mut Command {
    // std drops the supplementary groups when it changes the uid from root.
    cmd.uid(uid).gid(gid)
}

impl Server {
    pub fn start(bin: &Path, name: &str) -> Self {
        let dir = tmpdir(name);
        let user = run_as();
        let data = dir.join("data");
        std::fs::create_dir_all(&data).unwrap();
        for p in [&dir, &data] {
            let c = std::ffi::CString::new(p.to_str().unwrap()).unwrap();
            // SAFETY: chown(2) on a path we created.
            assert_eq!(unsafe { libc::chown(c.as_ptr(), user.0, user.1) }, 0);
        }
        let out = as_user(&mut Command::new(bin.join("initdb")), user)
            .args(["-D", data.to_str().unwrap()])
            .args([
                "-U",
                "probebridge",
                "--auth=trust",
                "-E",
                "UTF8",
                "--no-sync",
            ])
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "initdb: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        // PostgreSQL cannot take port 0: ask the kernel for a free port first.
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let child = Self::spawn(bin, &dir, port);
        let mut server = Self {
            bin: bin.to_path_buf(),
            child,
            port,
            dir,
            running: true,
        };
        server.wait_ready();
        server
    }

    fn spawn(bin: &Path, dir: &Path, port: u16) -> Child {
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(dir.join("server.log"))
            .unwrap();
        as_user(&mut Command::new(bin.join("postgres")), run_as())
            .args(["-D", dir.join("data").to_str().unwrap()])
            .args(["-p", &port.to_string()])
            .args(["-k", dir.to_str().unwrap()])
            .args(["-c", "listen_addresses=127.0.0.1", "-c", "fsync=off"])
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .unwrap()
    }

    /// Fast shutdown (SIGINT), waited for: the server is down, its data kept.
    pub fn stop(&mut self) {
        if !std::mem::replace(&mut self.running, false) {
            return;
        }
        // SAFETY: kill(2) on our own child, not yet reaped.
        unsafe { libc::kill(self.child.id() as i32, libc::SIGINT) };
        let _ = self.child.wait();
    }

    /// Starts the stopped server again, on the same port and data.
    pub fn start_again(&mut self) {
        self.child = Self::spawn(&self.bin, &self.dir, self.port);
        self.running = true;
        self.wait_ready();
    }

    /// SIGSTOP (`true`) or SIGCONT to the whole server: the postmaster and every
    /// process it started (each backend is a process group of its own). The
    /// postmaster is stopped first and its children are looked up only once it is
    /// stopped: a backend forked while the list was read (a client reconnecting at
    /// that moment) would otherwise go on answering. Continued in the reverse order.
    pub fn pause(&self, stop: bool) {
        assert!(self.running, "the server is stopped");
        let postmaster = self.child.id() as i32;
        // SAFETY (each kill): kill(2) on our child or its children.
        if stop {
            unsafe { libc::kill(postmaster, libc::SIGSTOP) };
            let deadline = Instant::now() + Duration::from_secs(10);
            while proc_stat(postmaster).map(|(state, _)| state) != Some('T') {
                assert!(Instant::now() < deadline, "the postmaster did not stop");
                std::thread::yield_now();
            }
            for pid in children(postmaster) {
                unsafe { libc::kill(pid, libc::SIGSTOP) };
            }
        } else {
            for pid in children(postmaster) {
                unsafe { libc::kill(pid, libc::SIGCONT) };
            }
            unsafe { libc::kill(postmaster, libc::SIGCONT) };
        }
    }

    pub fn url(&self) -> String {
        format!("postgres://probebridge@127.0.0.1:{}/postgres", self.port)
    }

    /// Until a connection is accepted (the server says nothing on stdout when ready).
    fn wait_ready(&mut self) {
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            match postgres::Client::connect(&self.url(), postgres::NoTls) {
                Ok(_) => return,
                Err(e) => {
                    if let Ok(Some(status)) = self.child.try_wait() {
                        panic!("postgres exited ({status}):\n{}", self.log());
                    }
                    assert!(
                        Instant::now() < deadline,
                        "postgres not ready: {e}\n{}",
                        self.log()
                    );
                    std::thread::sleep(Duration::from_millis(50));
                }
            }
        }
    }

    pub fn log(&self) -> String {
        std::fs::read_to_string(self.dir.join("server.log")).unwrap_or_default()
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        if self.running {
            // A paused server would not hear its shutdown.
            self.pause(false);
        }
        self.stop();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// The state letter and the parent of a process, from /proc/<pid>/stat.
fn proc_stat(pid: i32) -> Option<(char, i32)> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // pid (comm) state ppid ...: the fields after the last ')'.
    let mut rest = stat.rsplit_once(')')?.1.split_whitespace();
    let state = rest.next()?.chars().next()?;
    let ppid = rest.next()?.parse().ok()?;
    Some((state, ppid))
}

/// The processes whose parent is `parent`.
fn children(parent: i32) -> Vec<i32> {
    std::fs::read_dir("/proc")
        .unwrap()
        .flatten()
        .filter_map(|e| e.file_name().to_string_lossy().parse::<i32>().ok())
        .filter(|&pid| proc_stat(pid).is_some_and(|(_, ppid)| ppid == parent))
        .collect()
}
