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

/// The 431 block of the shipped program with its block number and the second point's
/// X replaced.
fn second_431(number: u32, q265: &str) -> String {
    let shipped = shipped_431();
    let start = shipped.find("6 TCH PROBE 431").unwrap();
    let end = shipped.find("7 L Z+100").unwrap();
    shipped[start..end]
        .replacen("6 TCH", &format!("{number} TCH"), 1)
        .replace("Q265=+50 ", &format!("Q265={q265} "))
}

/// A 431 whose second point lies beyond X's software limit (+400 on table-ac), after a
/// good 431: `check` refuses it with the line, and `run` refuses before anything moves
/// rather than running the first cycle and stopping in the second. On main before
/// this check, `check` said ok (exit 0) and `run` measured the first plane, then
/// failed mid-program with exit 1.
#[test]
fn a_431_point_beyond_the_software_limits_is_refused_before_the_first_cycle() {
    let text = shipped_431().replace(
        "7 L Z+100 R0 FMAX",
        &format!("7 L Z+100 R0 FMAX\n{}", second_431(8, "+500")),
    );
    let line = text
        .lines()
        .position(|l| l.starts_with("8 TCH PROBE 431"))
        .unwrap()
        + 1;
    let (check, err, run, opened) = check_and_run("431-limit", text.as_bytes());
    assert_eq!(check, Some(2), "{err}");
    assert!(
        err.contains(&format!("line {line}, block 8 (cycle 431)"))
            && err.contains("point 2")
            && err.contains("X+500.0000 is outside the software limits"),
        "{err}"
    );
    assert_eq!(run, Some(2));
    assert!(!opened, "run opened the machine");

    // Within the limits, the same two cycles pass.
    let text = shipped_431().replace(
        "7 L Z+100 R0 FMAX",
        &format!("7 L Z+100 R0 FMAX\n{}", second_431(8, "+60")),
    );
    let (check, err, _, _) = check_and_run("431-inside", text.as_bytes());
    assert_eq!(check, Some(0), "{err}");
}

/// Cycle 444's pre-position and probing path count too: a nominal point near Z's
/// lower limit (-200) whose probing path runs past it. On main `check` passed it.
#[test]
fn a_444_probing_path_beyond_the_software_limits_is_refused() {
    let program = std::fs::read_to_string(configs().join("programs/444-freeform.h")).unwrap();
    let text = program.replacen(
        "Q294=+0        ;1ST POINT 3RD AXIS",
        "Q294=-195       ;1ST POINT 3RD AXIS",
        1,
    );
    let (check, err, run, opened) = check_and_run("444-limit", text.as_bytes());
    assert_eq!(check, Some(2), "{err}");
    assert!(
        err.contains("(cycle 444)")
            && err.contains("probing the point")
            && err.contains("outside the software limits"),
        "{err}"
    );
    assert_eq!(run, Some(2));
    assert!(!opened);
}

/// Q253 below the motion guard's minimum feed (1 mm/min): the rotary axes would turn
/// at 0.0001 deg/min, a run that looks like a hang. On main `check` passed it.
#[test]
fn a_q253_below_the_minimum_feed_is_refused_by_check_and_run() {
    let program = std::fs::read_to_string(configs().join("programs/451-check.h")).unwrap();
    let text = program.replace("Q253=+3000 ", "Q253=+0.0001 ");
    let d = tmpdir("q253");
    let p = d.join("p.h");
    std::fs::write(&p, text).unwrap();
    let scenario = configs().join("scenarios/demo-sphere.toml");
    let check = run(bin()
        .args(["check", p.to_str().unwrap()])
        .args(["--scenario", scenario.to_str().unwrap()]));
    let err = String::from_utf8_lossy(&check.stderr);
    assert_eq!(check.status.code(), Some(2), "{err}");
    assert!(
        err.contains("Q253") && err.contains("0.0001 must be between 1"),
        "{err}"
    );
    let log = d.join("bus.log");
    let r = run(bin()
        .args(["run", p.to_str().unwrap()])
        .args(["--scenario", scenario.to_str().unwrap()])
        .args(["--candump", log.to_str().unwrap()])
        .args(["--service", &format!("pb-chk-q253-{}", std::process::id())]));
    assert_eq!(r.status.code(), Some(2));
    assert!(!log.exists());
}

/// Two runs on one `--service`: the second is refused at once, naming the service and
/// the first run's pid, and opens nothing; once the first has ended the service is
/// free again (the kernel dropped its claim). The first run is held at its Q281=2
/// confirmation, so both are alive at once without any sleep. On main before the
/// claim, the second run shared the first's estimator and contact stream and ran.
#[test]
fn a_second_run_on_the_same_service_is_refused_at_once() {
    use std::io::{BufRead, BufReader, Write};
    use std::process::Stdio;
    let d = tmpdir("service-twice");
    let program = d.join("p.h");
    std::fs::write(&program, shipped_431().replace("Q281=+1 ", "Q281=+2 ")).unwrap();
    let service = format!("pb-chk-twice-{}", std::process::id());
    let start = |log: &str| {
        let mut cmd = bin();
        cmd.args(["run", program.to_str().unwrap()])
            .args(["--scenario", &scenario()])
            .args(["--out", d.to_str().unwrap()])
            .args(["--candump", d.join(log).to_str().unwrap()])
            .args(["--service", &service]);
        cmd
    };
    let mut first = start("first.log")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // Wait until the first run asks for its confirmation: it holds the service.
    let mut out = BufReader::new(first.stdout.take().unwrap());
    let mut seen = String::new();
    while !seen.contains("Press Enter") {
        let mut chunk = Vec::new();
        let n = out.read_until(b':', &mut chunk).unwrap();
        assert!(n > 0, "the first run ended early: {seen}");
        seen.push_str(&String::from_utf8_lossy(&chunk));
    }

    let second = run(&mut start("second.log"));
    let err = String::from_utf8_lossy(&second.stderr);
    assert_eq!(second.status.code(), Some(1), "{err}");
    assert!(
        err.contains(&format!("service \"{service}\" is in use"))
            && err.contains(&format!("pid {}", first.id()))
            && err.contains("--service"),
        "{err}"
    );
    assert!(
        !d.join("second.log").exists(),
        "the second run opened the bus"
    );

    // The operator stops the first run; then the service is free.
    first.stdin.take().unwrap().write_all(b"n\n").unwrap();
    assert_eq!(first.wait().unwrap().code(), Some(1));
    let third = run(start("third.log").arg("--yes"));
    assert_eq!(third.status.code(), Some(0));
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
