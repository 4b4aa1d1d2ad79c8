//! Output paths are checked before the machine is opened: a measurement is never made
//! only to lose its results, and nothing but a regular file is ever replaced.

#[allow(
    dead_code,
    reason = "each test binary uses a part of the shared helpers"
)]
mod common;
use common::{bin, configs, run, tmpdir};
use std::os::unix::fs::FileTypeExt;

/// `probe` with `--json json` and a candump log in `dir`: the log exists only if the
/// machine was opened.
fn probe(dir: &std::path::Path, json: &str) -> (std::process::Output, bool) {
    let log = dir.join("bus.log");
    let out = run(bin()
        .args(["probe", "--start", "0,0,60", "--dir", "0,0,-1"])
        .args(["--dist", "40", "--feed", "200"])
        .args([
            "--scenario",
            configs().join("scenarios/plane-z10.toml").to_str().unwrap(),
        ])
        .args(["--json", json])
        .args(["--candump", log.to_str().unwrap()]));
    (out, log.exists())
}

#[test]
fn a_json_path_in_a_missing_folder_is_refused_before_the_machine_opens() {
    let d = tmpdir("out-missing");
    let json = d.join("missing/dir/r.json");
    let (out, opened) = probe(&d, json.to_str().unwrap());
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("missing/dir/r.json"), "{err}");
    assert!(
        !opened,
        "the machine was opened before the output path was checked"
    );
}

#[test]
fn a_device_at_the_json_path_is_refused_and_left_in_place() {
    let d = tmpdir("out-device");
    let (out, opened) = probe(&d, "/dev/null");
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("character device"), "{err}");
    assert!(!opened);
    assert!(std::fs::metadata("/dev/null")
        .unwrap()
        .file_type()
        .is_char_device());
}

#[test]
fn a_symlink_at_the_json_path_is_refused_and_its_target_kept() {
    let d = tmpdir("out-symlink");
    let target = d.join("precious.txt");
    std::fs::write(&target, "keep").unwrap();
    let link = d.join("r.json");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    let (out, opened) = probe(&d, link.to_str().unwrap());
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("symbolic link"));
    assert!(!opened);
    assert_eq!(std::fs::read_to_string(&target).unwrap(), "keep");
}

#[test]
fn run_refuses_a_json_path_it_could_not_write_before_anything_moves() {
    let d = tmpdir("out-run");
    let log = d.join("bus.log");
    let program = configs().join("programs/431-plane.h");
    let out = run(bin()
        .args(["run", program.to_str().unwrap()])
        .args([
            "--scenario",
            configs()
                .join("scenarios/tilted-plane.toml")
                .to_str()
                .unwrap(),
        ])
        .args(["--out", d.to_str().unwrap()])
        .args(["--json", d.join("no/such/r.json").to_str().unwrap()])
        .args(["--candump", log.to_str().unwrap()]));
    assert_ne!(out.status.code(), Some(0));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no/such/r.json"));
    assert!(!log.exists(), "the machine was opened");
    assert!(!d.join("TCHPR431.TXT").exists());
}
