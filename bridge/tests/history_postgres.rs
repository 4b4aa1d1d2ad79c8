//! The history on a real PostgreSQL server, as on SQLite: `probebridge run --history`
//! records the same runs into both, and `probebridge history --json` lists the same
//! rows from either (ids, results, 451's ISO errors and dispersions; only the clock
//! times differ). The server is Debian's `postgresql` (`scripts/install-test-peers`),
//! started by the test in a folder of its own on a free port, as an unprivileged user
//! (PostgreSQL refuses to run as root). Skipped with a line saying why where the
//! binaries are missing, never in CI.

mod common;

use common::*;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The folder holding `initdb` and `postgres`: on PATH, else Debian's
/// /usr/lib/postgresql/<version>/bin.
fn pg_bin() -> Option<PathBuf> {
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
struct Server {
    child: Child,
    port: u16,
    dir: PathBuf,
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
    fn start(bin: &Path, name: &str) -> Self {
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
        let log = std::fs::File::create(dir.join("server.log")).unwrap();
        let child = as_user(&mut Command::new(bin.join("postgres")), user)
            .args(["-D", data.to_str().unwrap()])
            .args(["-p", &port.to_string()])
            .args(["-k", dir.to_str().unwrap()])
            .args(["-c", "listen_addresses=127.0.0.1", "-c", "fsync=off"])
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .unwrap();
        let mut server = Self { child, port, dir };
        server.wait_ready();
        server
    }

    fn url(&self) -> String {
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

    fn log(&self) -> String {
        std::fs::read_to_string(self.dir.join("server.log")).unwrap_or_default()
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        // SIGINT: PostgreSQL's fast shutdown.
        // SAFETY: kill(2) on our own child.
        unsafe { libc::kill(self.child.id() as i32, libc::SIGINT) };
        let _ = self.child.wait();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

fn history_json(target: &str) -> Vec<serde_json::Value> {
    let out = run(bin().args(["history", "--db", target, "--json"]));
    assert!(out.status.success());
    serde_json::from_slice::<serde_json::Value>(&out.stdout)
        .unwrap()
        .as_array()
        .unwrap()
        .clone()
}

/// A run without its clock times (the one thing that differs between the runs).
fn timeless(mut run: serde_json::Value) -> serde_json::Value {
    let o = run.as_object_mut().unwrap();
    for k in ["started", "finished"] {
        assert!(o.remove(k).is_some_and(|v| v.is_string()), "{k}");
    }
    run
}

#[test]
fn postgres_history_lists_what_sqlite_lists() {
    let Some(bin_dir) = pg_bin() else {
        assert!(
            std::env::var("CI").ok().as_deref() != Some("true"),
            "PostgreSQL (initdb, postgres) is missing in CI: scripts/install-test-peers installs Debian's postgresql"
        );
        eprintln!("SKIPPED: no PostgreSQL server binaries (initdb, postgres); scripts/install-test-peers installs them");
        return;
    };
    let server = Server::start(&bin_dir, "pg-server");
    let url = server.url();
    let dir = tmpdir("pg-history");
    let sqlite = dir.join("history.sqlite");
    for (program, scenario) in [
        ("431-plane.h", "tilted-plane.toml"),
        ("451-check.h", "demo-sphere.toml"),
    ] {
        for target in [url.as_str(), sqlite.to_str().unwrap()] {
            // Each run from the same start: no preset row or kinematics of the last.
            for f in [
                "presets.toml",
                "presets.toml.prev",
                "kinematics.toml",
                "kinematics.toml.prev",
            ] {
                let _ = std::fs::remove_file(dir.join(f));
            }
            let (out, _) = run_program(
                &configs().join("programs").join(program),
                &configs().join("scenarios").join(scenario),
                &dir,
                &[
                    "--yes",
                    "--kinematics",
                    dir.join("kinematics.toml").to_str().unwrap(),
                    "--history",
                    target,
                ],
            );
            assert!(out.status.success(), "{program} into {target}");
        }
    }
    let pg = history_json(&url);
    let lite = history_json(sqlite.to_str().unwrap());
    assert_eq!(pg.len(), 2, "{pg:?}");
    assert!(
        !pg[1]["iso_errors"].as_array().unwrap().is_empty(),
        "{}",
        pg[1]
    );
    assert!(
        !pg[1]["dispersion"].as_array().unwrap().is_empty(),
        "{}",
        pg[1]
    );
    let pg: Vec<_> = pg.into_iter().map(timeless).collect();
    let lite: Vec<_> = lite.into_iter().map(timeless).collect();
    assert_eq!(pg, lite);
    // The text listing and the trend page from the server too.
    let text = run(bin().args(["history", "--db", &url]));
    assert!(text.status.success());
    assert_eq!(String::from_utf8_lossy(&text.stdout).lines().count(), 2);
    let page = dir.join("trend.html");
    let out = run(bin().args(["history", "--db", &url, "--html", page.to_str().unwrap()]));
    assert!(out.status.success());
    let html = std::fs::read_to_string(&page).unwrap();
    assert!(html.matches("<svg").count() > 0, "{html}");
    // A wrong password's server message comes through, naming the server without it.
    let bad = url.replace("probebridge@", "nobody:secret@");
    let out = bin().args(["history", "--db", &bad]).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("nobody:***@") && !err.contains("secret"),
        "{err}"
    );
    drop(server);
}
