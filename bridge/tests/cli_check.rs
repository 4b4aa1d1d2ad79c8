//! `check` refuses what `run` would fail on, and `run` refuses it the same way (exit 2,
//! nothing moved): L-block targets outside the software limits, feeds outside the
//! motion guard's range, empty or cut-off programs; a BOM is fine; `/dev/zero` and
//! floods of errors end at once. Feeds a machine cannot run are refused before motion.

#[allow(
    dead_code,
    reason = "each test binary uses a part of the shared helpers"
)]
mod common;
use common::{bin, configs, run, tmpdir};

fn shipped_431() -> String {
    std::fs::read_to_string(configs().join("programs/431-plane.h")).unwrap()
}

fn scenario() -> String {
    configs()
        .join("scenarios/tilted-plane.toml")
        .to_string_lossy()
        .into_owned()
}

/// `check` and `run` of `text`: (check's exit, its stderr, run's exit, whether run
/// opened the machine).
fn check_and_run(name: &str, text: &[u8]) -> (Option<i32>, String, Option<i32>, bool) {
    let d = tmpdir(name);
    let program = d.join("p.h");
    std::fs::write(&program, text).unwrap();
    let check = run(bin()
        .args(["check", program.to_str().unwrap()])
        .args(["--scenario", &scenario()]));
    let log = d.join("bus.log");
    let r = run(bin()
        .args(["run", program.to_str().unwrap()])
        .args(["--scenario", &scenario()])
        .args(["--candump", log.to_str().unwrap()])
        .args([
            "--service",
            &format!("pb-chk-{name}-{}", std::process::id()),
        ]));
    (
        check.status.code(),
        String::from_utf8_lossy(&check.stderr).into_owned(),
        r.status.code(),
        log.exists(),
    )
}

#[test]
fn an_l_block_beyond_the_software_limits_is_refused_by_check_and_run_alike() {
    let text = shipped_431().replace("5 L Z+100 R0 FMAX", "5 L Z+1000 R0 FMAX");
    let (check, err, run, opened) = check_and_run("l-limit", text.as_bytes());
    assert_eq!(check, Some(2), "{err}");
    assert!(
        err.contains("line 6") && err.contains("software limits"),
        "{err}"
    );
    assert_eq!(run, Some(2));
    assert!(!opened, "run opened the machine");
}

#[test]
fn l_block_feeds_below_the_minimum_or_above_max_feed_are_refused() {
    for (name, f) in [("f-low", "F0.000001"), ("f-high", "F99999")] {
        let text = shipped_431().replace("5 L Z+100 R0 FMAX", &format!("5 L Z+100 R0 {f}"));
        let (check, err, run, opened) = check_and_run(name, text.as_bytes());
        assert_eq!(check, Some(2), "{f}: {err}");
        assert!(err.contains("line 6") && err.contains("feed"), "{err}");
        assert_eq!(run, Some(2), "{f}");
        assert!(!opened);
    }
}

#[test]
fn empty_and_cut_off_programs_are_refused() {
    let shipped = shipped_431();
    let no_end: String = shipped
        .lines()
        .filter(|l| !l.contains("END PGM"))
        .map(|l| format!("{l}\n"))
        .collect();
    for (name, text) in [
        ("empty", String::new()),
        ("blank", "  \n\t\n".to_string()),
        ("no-end", no_end),
        ("moves-only", "L Z+100 R0 FMAX\n".to_string()),
    ] {
        let (check, err, run, opened) = check_and_run(name, text.as_bytes());
        assert_eq!(check, Some(2), "{name}: {err}");
        assert!(err.contains("PGM"), "{name}: {err}");
        assert_eq!(run, Some(2), "{name}");
        assert!(!opened, "{name}");
    }
}

#[test]
fn a_utf8_byte_order_mark_is_accepted() {
    let mut text = "\u{feff}".to_string();
    text.push_str(&shipped_431());
    let d = tmpdir("bom");
    let program = d.join("p.h");
    std::fs::write(&program, text).unwrap();
    let out = run(bin()
        .args(["check", program.to_str().unwrap()])
        .args(["--scenario", &scenario()]));
    assert_eq!(out.status.code(), Some(0));
}

#[test]
fn check_of_dev_zero_ends_at_once_and_a_flood_of_errors_is_capped() {
    let out = run(bin().args(["check", "/dev/zero"]));
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("/dev/zero") && err.contains("larger than"),
        "{err}"
    );

    let d = tmpdir("flood");
    let program = d.join("p.h");
    let mut text = String::from("0 BEGIN PGM F MM\n");
    for i in 1..=5000 {
        text.push_str(&format!("{i} LL Z+1\n"));
    }
    text.push_str("5001 END PGM F MM\n");
    std::fs::write(&program, text).unwrap();
    let out = run(bin().args(["check", program.to_str().unwrap()]));
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.lines().count() < 110, "{} lines", err.lines().count());
    assert!(err.contains("... and 4900 more"), "{err}");
    assert!(err.contains("5000 error(s)"), "{err}");
}

/// `probe` with a feed the axes cannot run, or so slow it would never end: refused
/// before anything moves.
#[test]
fn probe_feeds_beyond_max_feed_or_below_the_minimum_are_refused_before_motion() {
    for (name, feed, why) in [
        ("p-high", "20000", "max_feed"),
        ("p-low", "1e-9", "between"),
    ] {
        let log = tmpdir(name).join("bus.log");
        let out = run(bin()
            .args(["probe", "--start", "0,0,60", "--dir", "0,0,-1"])
            .args(["--dist", "60", "--feed", feed])
            .args([
                "--scenario",
                configs().join("scenarios/plane-z10.toml").to_str().unwrap(),
            ])
            .args([
                "--service",
                &format!("pb-chk-{name}-{}", std::process::id()),
            ]));
        assert_eq!(out.status.code(), Some(1), "{feed}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(why), "{feed}: {err}");
        assert!(!log.exists(), "{feed}: the machine was opened");
    }
}

/// The tool axis Y on a machine whose spindle is vertical (`table-ac`, `[cycles]
/// tool_axes` left at Z): `check` and `run` refuse the shipped `431-plane-y.h` at its
/// TOOL CALL's line, nothing moves; on the horizontal spindle it checks clean.
#[test]
fn a_tool_axis_the_machine_has_no_spindle_for_is_refused_by_check_and_run_alike() {
    let text = std::fs::read_to_string(configs().join("programs/431-plane-y.h")).unwrap();
    let (check, err, run, opened) = check_and_run("tool-axis", text.as_bytes());
    assert_eq!(check, Some(2), "{err}");
    assert!(
        err.contains("line 7: TOOL CALL: tool axis Y: machine table-ac has no spindle along Y; its [cycles] tool_axes are Z"),
        "{err}"
    );
    assert_eq!(run, Some(2));
    assert!(!opened, "run opened the machine");
    let ok = common::run(
        bin()
            .args([
                "check",
                configs().join("programs/431-plane-y.h").to_str().unwrap(),
            ])
            .args([
                "--scenario",
                configs()
                    .join("scenarios/tilted-plane-y.toml")
                    .to_str()
                    .unwrap(),
            ]),
    );
    assert_eq!(
        ok.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );
}
