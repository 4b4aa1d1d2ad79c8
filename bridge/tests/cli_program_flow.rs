//! Issue 34, the NC program as the TNC runs it, through `probebridge run` and `check`
//! as a user runs them: the progress count of cycles in a loop, and the warnings (block
//! numbers out of order, a length measured in mm used by an INCH program).

#[allow(
    dead_code,
    reason = "each test binary uses a part of the shared helpers"
)]
mod common;

use common::*;

/// The manual's 444 point on configs/scenarios/seed-444.toml (a face 0.25 mm proud of
/// X0), its Y from `y`.
fn point444(block: u32, y: &str) -> String {
    format!(
        "{block} TCH PROBE 444 PROBING 3D ~
  Q263=+0 ~
  Q264={y} ~
  Q294=+0 ~
  Q581=+1 ~
  Q582=+0 ~
  Q583=+0 ~
  Q320=+0 ~
  Q260=+100 ~
  QS400=\"1-1\" ~
  Q309=+0
"
    )
}

/// A cycle in a loop ran as `[1/0] [2/0] [3/0]` (the count of written cycle blocks,
/// none here: its values come from Q parameters): in a loop the count is the cycles
/// started so far; a program without jumps or calls keeps `[i/n]`, its Q-valued cycles
/// counted.
#[test]
fn the_progress_count_makes_sense_in_a_loop() {
    let dir = tmpdir("flow-progress");
    let looped = dir.join("loop.h");
    std::fs::write(
        &looped,
        format!(
            "0 BEGIN PGM LOOP MM
1 TOOL CALL \"TOUCH_PROBE\" Z
2 Q1 = -2
3 LBL 1
{}5 Q1 = Q1 + 2
6 FN 12: IF +Q1 LT +4 GOTO LBL 1
7 END PGM LOOP MM
",
            point444(4, "+Q1")
        ),
    )
    .unwrap();
    let straight = dir.join("straight.h");
    std::fs::write(
        &straight,
        format!(
            "0 BEGIN PGM LINE MM
1 TOOL CALL \"TOUCH_PROBE\" Z
2 Q1 = 1.5
{}{}5 END PGM LINE MM
",
            point444(3, "+Q1"),
            point444(4, "-1")
        ),
    )
    .unwrap();
    let scenario = configs().join("scenarios/seed-444.toml");
    let (out, v) = run_program(&looped, &scenario, &dir, &[]);
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{said}");
    assert_eq!(v.unwrap()["cycles"].as_array().unwrap().len(), 3);
    for n in 1..=3 {
        assert!(
            said.contains(&format!("[cycle {n}] block 4 (line 5): cycle 444")),
            "{said}"
        );
    }
    assert!(
        !said.contains("/0]") && !said.contains("[cycle 4]"),
        "{said}"
    );
    let (out, _) = run_program(&straight, &scenario, &dir, &[]);
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{said}");
    assert!(
        said.contains("[1/2] block 3 (line 4): cycle 444")
            && said.contains("[2/2] block 4 (line 15): cycle 444"),
        "{said}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Block numbers out of order and a length measured in mm used by an INCH program:
/// `check` and `run` say each at its line and go on (exit 0).
#[test]
fn check_and_run_warn_at_the_line_and_go_on() {
    let dir = tmpdir("flow-warnings");
    let numbers = dir.join("numbers.h");
    std::fs::write(
        &numbers,
        format!(
            "0 BEGIN PGM NUM MM
1 TOOL CALL \"TOUCH_PROBE\" Z
{}6 L Z+100 R0 FMAX
4 L Z+120 R0 FMAX
9 END PGM NUM MM
",
            point444(5, "+0")
        ),
    )
    .unwrap();
    let warned = "line 15: warning: block number 4 after 6 (line 14)";
    let out = run(bin().args(["check", numbers.to_str().unwrap()]));
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{said}");
    assert!(said.contains(warned), "{said}");
    let (out, v) = run_program(
        &numbers,
        &configs().join("scenarios/seed-444.toml"),
        &dir,
        &[],
    );
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{said}");
    assert!(said.contains(warned), "{said}");
    assert_eq!(v.unwrap()["cycles"][0]["status"], "ok");

    let inch = dir.join("inch.h");
    std::fs::write(
        &inch,
        "0 BEGIN PGM IN INCH
1 TOOL CALL \"TOUCH_PROBE\" Z
2 TCH PROBE 444 PROBING 3D ~
  Q263=+0 ~
  Q264=+0 ~
  Q294=+0 ~
  Q581=+1 ~
  Q582=+0 ~
  Q583=+0 ~
  Q320=+0 ~
  Q260=+4
3 Q10 = Q151 + 0.5
4 L X+Q10 R0 FMAX
5 END PGM IN INCH
",
    )
    .unwrap();
    let out = run(bin().args(["check", inch.to_str().unwrap()]));
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{said}");
    assert!(
        said.contains("line 13: warning: Q10 is in mm (the cycle reports in mm); this INCH program reads it as inches (L X+Q10)"),
        "{said}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
