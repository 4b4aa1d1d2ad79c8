//! Every file a command writes is whole or the command says which one is not: the
//! candump log (refused up front when it cannot be a log; a failed write ends the
//! command non-zero naming it) and the 451 protocol (written after the write-back,
//! stating its real outcome).

#[allow(
    dead_code,
    reason = "each test binary uses a part of the shared helpers"
)]
mod common;
use common::{bin, configs, run, tmpdir};
use std::os::unix::process::CommandExt;

fn probe_args(cmd: &mut std::process::Command) -> &mut std::process::Command {
    cmd.args(["probe", "--start", "0,0,60", "--dir", "0,0,-1"])
        .args(["--dist", "60", "--feed", "200"])
        .args([
            "--scenario",
            configs().join("scenarios/plane-z10.toml").to_str().unwrap(),
        ])
}

#[test]
fn a_candump_log_on_a_device_is_refused_before_the_machine_opens() {
    let d = tmpdir("candump-dev");
    let json = d.join("c.json");
    let out = run(probe_args(&mut bin())
        .args(["--candump", "/dev/full"])
        .args(["--json", json.to_str().unwrap()]));
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("/dev/full") && err.contains("character device"),
        "{err}"
    );
    assert!(
        !String::from_utf8_lossy(&out.stdout).contains("contact"),
        "nothing moved"
    );
    assert!(!json.exists());
}

#[test]
fn a_candump_write_that_fails_mid_session_ends_the_command_non_zero_naming_the_log() {
    let d = tmpdir("candump-full");
    let log = d.join("bus.log");
    let mut cmd = bin();
    probe_args(&mut cmd).args(["--candump", log.to_str().unwrap()]);
    // SAFETY: setrlimit and signal are async-signal-safe; nothing else runs between
    // fork and exec. Files beyond 1 MiB fail with EFBIG (SIGXFSZ ignored), as a full
    // disk fails a write: iceoryx2's shared memory fits, the log of the probing move
    // (about 3 MB) does not.
    unsafe {
        cmd.pre_exec(|| {
            let lim = libc::rlimit {
                rlim_cur: 1024 * 1024,
                rlim_max: 1024 * 1024,
            };
            libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
            if libc::setrlimit(libc::RLIMIT_FSIZE, &lim) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let out = run(&mut cmd);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("candump log") && err.contains("bus.log"),
        "{err}"
    );
    assert!(err.contains("incomplete"), "{err}");
}

/// The 451 protocol is written after the write-back and says that the kinematics file
/// could not be written, instead of "written to".
#[test]
fn the_451_protocol_states_a_failed_write_back() {
    let d = tmpdir("kin-fail");
    let out = run(bin()
        .args([
            "run",
            configs().join("programs/451-optimise.h").to_str().unwrap(),
        ])
        .args([
            "--scenario",
            configs()
                .join("scenarios/demo-sphere.toml")
                .to_str()
                .unwrap(),
        ])
        .args(["--out", d.to_str().unwrap()])
        .args(["--kinematics", "/proc/self/kin.toml", "--yes"])
        .args(["--service", &format!("pb-kinfail-{}", std::process::id())]));
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("/proc/self/kin.toml"), "{err}");
    let html = std::fs::read_to_string(d.join("TCHPRAUTO.html")).unwrap();
    assert!(
        html.contains("NOT written") && html.contains("/proc/self/kin.toml is unchanged"),
        "{html}"
    );
    assert!(!html.contains("written to /proc"), "{html}");
}
