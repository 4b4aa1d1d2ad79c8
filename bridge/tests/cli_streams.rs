//! Output never panics: a closed pipe (`| head -3`) or a full device on stdout or
//! stderr ends the output, not the command.

#[allow(
    dead_code,
    reason = "each test binary uses a part of the shared helpers"
)]
mod common;
use common::{bin, configs, tmpdir};
use std::io::{BufRead, BufReader};
use std::os::fd::{FromRawFd, IntoRawFd, OwnedFd};
use std::process::Stdio;

/// `probebridge run 431-plane.h 2>&1 | head -3`: both streams into one pipe whose
/// reader goes away after three lines. The measurement completes and the JSON is
/// written.
#[test]
fn run_into_a_pipe_closed_after_three_lines_completes_and_writes_its_json() {
    let dir = tmpdir("head3");
    let json = dir.join("r.json");
    let mut fds = [0; 2];
    // SAFETY: pipe2 fills two descriptors we then own.
    assert_eq!(unsafe { libc::pipe2(fds.as_mut_ptr(), libc::O_CLOEXEC) }, 0);
    // SAFETY: fresh descriptors from pipe2, owned once each.
    let (read_end, write_end) =
        unsafe { (OwnedFd::from_raw_fd(fds[0]), OwnedFd::from_raw_fd(fds[1])) };
    let write_2 = write_end.try_clone().unwrap();
    let mut child = bin()
        .args([
            "run",
            configs().join("programs/431-plane.h").to_str().unwrap(),
        ])
        .args([
            "--scenario",
            configs()
                .join("scenarios/tilted-plane.toml")
                .to_str()
                .unwrap(),
        ])
        .args(["--out", dir.to_str().unwrap()])
        .args(["--json", json.to_str().unwrap()])
        .args(["--service", &format!("pb-head3-{}", std::process::id())])
        .stdout(Stdio::from(write_end))
        .stderr(Stdio::from(write_2))
        .spawn()
        .unwrap();
    {
        // SAFETY: the read end is ours alone.
        let f = unsafe { std::fs::File::from_raw_fd(read_end.into_raw_fd()) };
        let mut lines = BufReader::new(f).lines();
        for _ in 0..3 {
            lines.next().expect("three lines").unwrap();
        }
        // The reader goes away here, as `head -3` does.
    }
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(0), "no panic (101), no SIGPIPE death");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("the JSON")).unwrap();
    assert_eq!(v["cycles"][0]["status"], "ok", "{v}");
}

/// `check ... >/dev/full` and `2>/dev/full`: no panic, the check's own exit status.
#[test]
fn check_onto_a_full_device_does_not_panic() {
    for (program, want) in [("programs/431-plane.h", 0), ("scenarios/plane-z10.toml", 2)] {
        let full = || {
            std::fs::OpenOptions::new()
                .write(true)
                .open("/dev/full")
                .unwrap()
        };
        let out = bin()
            .args(["check", configs().join(program).to_str().unwrap()])
            .stdout(Stdio::from(full()))
            .stderr(Stdio::from(full()))
            .status()
            .unwrap();
        assert_eq!(out.code(), Some(want), "{program}");
    }
}
