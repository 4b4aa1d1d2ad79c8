//! A running `probebridge serve` for the gateway tests (serve_plc, serve_face,
//! history_faults): each test writes its own configuration, [`Serve::spawn`] starts
//! the service on it and waits until it says where it listens, [`Serve::plc`] runs a
//! PLC script of `tests/gateway/` against it. SIGTERM on drop, as systemd stops it.
#![allow(dead_code, reason = "each gateway test uses a part of it")]

use std::io::{BufRead, BufReader};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};

/// A running `probebridge serve`.
pub struct Serve {
    pub child: Child,
    /// Where its PLC face listens on 127.0.0.1.
    pub port: u16,
    /// The folder of its configuration and `serve.log`.
    pub dir: PathBuf,
}

/// Copies the shipped programs `(number, program)` to `dir/programs/NUMBER.h`, the
/// program folder of a gateway configuration written in `dir`.
pub fn copy_programs(dir: &Path, programs: &[(u16, &str)]) {
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/programs");
    let folder = dir.join("programs");
    std::fs::create_dir_all(&folder).unwrap();
    for (n, p) in programs {
        std::fs::copy(shipped.join(p), folder.join(format!("{n}.h"))).unwrap();
    }
}

impl Serve {
    /// Runs `cmd` (the binary, with what the test adds to its environment) as
    /// `serve --config CONFIG`, its stderr appended to `dir/serve.log` (a restart in
    /// the same folder keeps the earlier lines); returns once the service says where it
    /// listens, and fails with the log if it ends first.
    pub fn spawn(mut cmd: Command, dir: &Path, config: &Path) -> Self {
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(dir.join("serve.log"))
            .unwrap();
        let mut child = cmd
            .args(["serve", "--config", config.to_str().unwrap()])
            .stdout(Stdio::piped())
            .stderr(log)
            .spawn()
            .unwrap();
        // The service says its bound address once the machine is up.
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        let Some(addr) = line.trim().strip_prefix("probebridge serve: listening on ") else {
            let _ = child.kill();
            let _ = child.wait();
            panic!(
                "serve did not come up: {line:?}\n{}",
                std::fs::read_to_string(dir.join("serve.log")).unwrap_or_default()
            );
        };
        let port = addr.rsplit(':').next().unwrap().parse().unwrap();
        Self {
            child,
            port,
            dir: dir.to_path_buf(),
        }
    }

    pub fn addr(&self) -> SocketAddr {
        SocketAddr::from(([127, 0, 0, 1], self.port))
    }

    /// What the service wrote to stderr so far.
    pub fn log(&self) -> String {
        std::fs::read_to_string(self.dir.join("serve.log")).unwrap_or_default()
    }

    /// `tests/gateway/plc.py ARGS` against the service, with the Python `py`: the JSON
    /// it prints. Fails with its stderr and the service's log if it fails.
    pub fn plc(&self, py: &Path, args: &[&str]) -> serde_json::Value {
        self.plc_script(py, "plc.py", args)
    }

    /// As [`Serve::plc`], with another script of `tests/gateway/`.
    pub fn plc_script(&self, py: &Path, script: &str, args: &[&str]) -> serde_json::Value {
        let script = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/gateway")
            .join(script);
        let out = Command::new(py)
            .arg(script)
            .args(["127.0.0.1", &self.port.to_string()])
            .args(args)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "PLC {args:?}: {}\nserve log:\n{}",
            String::from_utf8_lossy(&out.stderr),
            self.log()
        );
        serde_json::from_slice(&out.stdout).unwrap()
    }

    /// SIGTERM; the exit status.
    pub fn stop(&mut self) -> ExitStatus {
        self.signal(libc::SIGTERM)
    }

    /// Sends `sig` and waits for the exit; the exit status.
    pub fn signal(&mut self, sig: libc::c_int) -> ExitStatus {
        // SAFETY: kill(2) on our own child's pid.
        unsafe { libc::kill(self.child.id() as i32, sig) };
        self.child.wait().unwrap()
    }
}

impl Drop for Serve {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            self.stop();
        }
    }
}
