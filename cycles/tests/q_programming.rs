//! Q-parameter programming as the TNC has it (issue 27): arithmetic and every
//! function, strings, each jump kind, subprograms and repeats, FN 14, QR kept across
//! runs, errors at their line, and what `check` evaluates before anything moves.

mod common;

use common::{MockMachine, Surface};
use nalgebra::Vector3;
use probebridge_cycles::q_params::QValue;
use probebridge_cycles::runner::{preflight_program, program_warnings, PreflightKind};
use probebridge_cycles::{CyclesConfig, Program, ProgramReport};
use std::path::Path;

/// The mock machine with its preset table (and so its QR file) in `dir`.
fn cfg_in(dir: &Path) -> CyclesConfig {
    let mut cfg = common::config();
    cfg.presets.path = dir.join("mock.presets.toml");
    cfg
}

fn program(text: &str, cfg: &CyclesConfig) -> Program {
    Program::parse(text, cfg).unwrap_or_else(|e| panic!("{e}"))
}

fn wrap(body: &str) -> String {
    format!("0 BEGIN PGM T MM\n{body}\n99999 END PGM T MM\n")
}

/// Runs `body` (between BEGIN and END PGM) on a mock over a plane at Z=0.
fn run_in(dir: &Path, body: &str) -> (ProgramReport, MockMachine) {
    let cfg = cfg_in(dir);
    let p = program(&wrap(body), &cfg);
    let mut m = MockMachine::new(vec![Surface::Plane {
        point: Vector3::zeros(),
        normal: Vector3::z(),
    }]);
    let (report, _) = common::run_on(&cfg, &p, &mut m, dir, true);
    (report, m)
}

fn run(body: &str) -> ProgramReport {
    run_in(&common::temp_dir("q"), body).0
}

fn num(r: &ProgramReport, name: &str) -> f64 {
    match r.parameters.get(name) {
        Some(QValue::Number(v)) => *v,
        other => panic!(
            "{name}: {other:?} in {:?} (stopped: {:?})",
            r.parameters, r.stopped
        ),
    }
}

fn text(r: &ProgramReport, name: &str) -> String {
    match r.parameters.get(name) {
        Some(QValue::Text(t)) => t.clone(),
        other => panic!("{name}: {other:?} (stopped: {:?})", r.stopped),
    }
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-9
}

#[test]
fn arithmetic_fn_0_to_5_and_formulas() {
    let r = run("1 FN 0: Q1 = +5
2 FN 1: Q2 = +Q1 + +3
3 FN 2: Q3 = +Q1 - +7
4 FN 3: Q4 = +Q1 * -2
5 FN 4: Q5 = +Q1 / +4
6 FN 5: Q6 = SQRT +Q2
7 Q7 = ( Q1 + Q2 ) / 2
8 Q8 = 5 * 3 + 2 * 10
9 QL0 = 2 ^ 3 ^ 2
10 Q9 = -Q1 + +2 * ( 1 - 3 )");
    assert!(r.completed(), "{:?}", r.stopped);
    for (n, v) in [
        ("Q1", 5.0),
        ("Q2", 8.0),
        ("Q3", -2.0),
        ("Q4", -10.0),
        ("Q5", 1.25),
        ("Q6", 8f64.sqrt()),
        ("Q7", 6.5),
        ("Q8", 35.0),
        ("QL0", 64.0),
        ("Q9", -9.0),
    ] {
        assert!(close(num(&r, n), v), "{n} = {} (expected {v})", num(&r, n));
    }
}

#[test]
fn every_function() {
    let r = run("1 Q1 = SQ 3
2 Q2 = SQRT 16
3 Q3 = SIN 30
4 Q4 = COS 60
5 Q5 = TAN 45
6 Q6 = ASIN 0.5
7 Q7 = ACOS 0.5
8 Q8 = ATAN 1
9 Q9 = ABS -2.5
10 Q10 = INT -2.7
11 Q11 = FRAC 2.75
12 Q12 = SGN -0.1
13 Q13 = SGN 0
14 Q14 = PI
15 Q15 = SIN 30 ^ 2
16 Q16 = SQ 10 - 3 ^ 3");
    assert!(r.completed(), "{:?}", r.stopped);
    for (n, v) in [
        ("Q1", 9.0),
        ("Q2", 4.0),
        ("Q3", 0.5),
        ("Q4", 0.5),
        ("Q5", 1.0),
        ("Q6", 30.0),
        ("Q7", 60.0),
        ("Q8", 45.0),
        ("Q9", 2.5),
        ("Q10", -2.0),
        ("Q11", 0.75),
        ("Q12", -1.0),
        ("Q13", 0.0),
        ("Q14", std::f64::consts::PI),
        ("Q15", 0.25),
        ("Q16", 73.0),
    ] {
        assert!(close(num(&r, n), v), "{n} = {} (expected {v})", num(&r, n));
    }
}

#[test]
fn strings() {
    let r = run("1 QS1 = \"X=\"
2 Q1 = 12.34567
3 QS2 = QS1 || TOCHAR ( DAT+Q1 DECIMALS2 ) || \" mm\"
4 Q2 = STRLEN ( SRC_QS2 )
5 QS3 = SUBSTR ( SRC_QS2 BEG2 LEN5 )
6 Q3 = TONUMB ( SRC_QS3 ) * 2
7 DECLARE STRING QS4 = \"a;b\"
8 STRING FORMULA QS5 = QS4 || QS4");
    assert!(r.completed(), "{:?}", r.stopped);
    assert_eq!(text(&r, "QS2"), "X=12.35 mm");
    assert_eq!(num(&r, "Q2"), 10.0);
    assert_eq!(text(&r, "QS3"), "12.35");
    assert!(close(num(&r, "Q3"), 24.7));
    assert_eq!(text(&r, "QS5"), "a;ba;b");
}

#[test]
fn each_jump_kind() {
    // FN 9..12 each taken once and not taken once; a taken jump skips Q9x = 1.
    let r = run("1 Q1 = 2
2 FN 9: IF +Q1 EQU +2 GOTO LBL 1
3 Q91 = 1
4 LBL 1
5 FN 9: IF +Q1 EQU +3 GOTO LBL 2
6 Q92 = 1
7 LBL 2
8 FN 10: IF +Q1 NE +3 GOTO LBL \"NE\"
9 Q101 = 1
10 LBL \"NE\"
11 FN 10: IF +Q1 NE +2 GOTO LBL 3
12 Q102 = 1
13 LBL 3
14 FN 11: IF +Q1 GT +1 GOTO LBL 4
15 Q111 = 1
16 LBL 4
17 FN 11: IF +Q1 GT +2 GOTO LBL 5
18 Q112 = 1
19 LBL 5
20 FN 12: IF +Q1 LT +3 GOTO LBL 6
21 Q121 = 1
22 LBL 6
23 FN 12: IF +Q1 LT +Q1 GOTO LBL 7
24 Q122 = 1
25 LBL 7");
    assert!(r.completed(), "{:?}", r.stopped);
    for taken in ["Q91", "Q101", "Q111", "Q121"] {
        assert!(
            !r.parameters.contains_key(taken),
            "{taken} set: the jump was not taken"
        );
    }
    for not_taken in ["Q92", "Q102", "Q112", "Q122"] {
        assert_eq!(num(&r, not_taken), 1.0, "{not_taken}");
    }
}

#[test]
fn loop_with_a_counter_moves_each_time() {
    let dir = common::temp_dir("q-loop");
    let (r, m) = run_in(
        &dir,
        "1 Q1 = 0
2 Q2 = 250 * 2
3 LBL \"STEP\"
4 Q1 = Q1 + 1
5 L X+Q1 Y-Q1 Z+50 R0 FQ2
6 FN 12: IF +Q1 LT +4 GOTO LBL \"STEP\"",
    );
    assert!(r.completed(), "{:?}", r.stopped);
    assert_eq!(num(&r, "Q1"), 4.0);
    let xs: Vec<[f64; 3]> = m.moves.iter().map(|(p, _)| *p).collect();
    assert_eq!(xs.len(), 4, "{xs:?}");
    assert_eq!(xs[3], [4.0, -4.0, 50.0]);
    // The feed from FQ2, as the program computed it.
    assert!(m.moves.iter().all(|(_, f)| *f == 500.0), "{:?}", m.moves);
}

#[test]
fn subprograms_and_section_repeats() {
    let r = run("1 Q1 = 0
2 Q2 = 0
3 CALL LBL 10 REP 2
4 CALL LBL \"ADD\"
5 LBL 1
6 Q2 = Q2 + 1
7 CALL LBL 1 REP 3
8 M30
9 LBL 10
10 Q1 = Q1 + 1
11 LBL 0
12 LBL \"ADD\"
13 Q1 = Q1 + 100
14 LBL 0");
    assert!(r.completed(), "{:?}", r.stopped);
    // LBL 10 called 1 + 2 times, ADD once; the section 5..7 runs 1 + 3 times; M30
    // ends the program before the subprograms.
    assert_eq!(num(&r, "Q1"), 103.0);
    assert_eq!(num(&r, "Q2"), 4.0);
}

/// Issue 34: `CALL LBL n` without REP is a subprogram call wherever the label stands.
/// Here the subprogram LBL 7 stands before the subprogram LBL 8 that calls it (both
/// after M30); it runs (its move too) and returns after the call, each time.
#[test]
fn a_call_without_rep_runs_a_subprogram_standing_before_it() {
    let dir = common::temp_dir("q-sub-before");
    let body = "1 Q1 = 0
2 Q3 = 0
3 CALL LBL 8
4 CALL LBL 8
5 L Z+40 R0 FMAX
6 M30
7 LBL 7
8 Q1 = Q1 + 2.5
9 L X+Q1 Z+30 R0 FMAX
10 LBL 0
11 LBL 8
12 Q3 = Q3 + 1
13 CALL LBL 7
14 Q3 = Q3 * 10
15 LBL 0";
    let cfg = cfg_in(&dir);
    preflight_program(
        &program(&wrap(body), &cfg),
        0b111,
        &cfg,
        &dir.join("k.toml"),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let (r, m) = run_in(&dir, body);
    assert!(r.completed(), "{:?}", r.stopped);
    // LBL 8 twice, each time LBL 7 once: Q1 = 2 x 2.5, Q3 = ((0 + 1) * 10 + 1) * 10.
    assert_eq!(num(&r, "Q1"), 5.0);
    assert_eq!(num(&r, "Q3"), 110.0);
    let xs: Vec<[f64; 3]> = m.moves.iter().map(|(p, _)| *p).collect();
    assert_eq!(xs.len(), 3, "{xs:?}");
    assert_eq!(xs[0][0], 2.5);
    assert_eq!(xs[1][0], 5.0);
    assert_eq!(xs[2][2], 40.0);
    // A section repeat still needs REP and a label before the CALL.
    let r = run("1 Q2 = 0\n2 LBL 3\n3 Q2 = Q2 + 1\n4 CALL LBL 3 REP 2");
    assert_eq!(num(&r, "Q2"), 3.0);
}

/// A CALL that would run nothing is refused at its line by the parser, so by `check`
/// and by `run` before anything moves: a section repeat of no blocks or with REP 0, a
/// subprogram call to a label without LBL 0 after it, an empty subprogram.
#[test]
fn a_call_that_runs_nothing_is_refused_at_its_line() {
    let cfg = common::config();
    for (body, line, what) in [
        (
            "1 LBL 4\n2 * - nothing here\n3 CALL LBL 4 REP 2",
            4,
            "the section from LBL 4 (line 2) to this CALL is empty",
        ),
        (
            "1 LBL 4\n2 Q1 = 1\n3 CALL LBL 4 REP 0",
            4,
            "REP 0 repeats the section",
        ),
        ("1 LBL 4\n2 Q1 = 1\n3 CALL LBL 4", 4, "no LBL 0 follows it"),
        (
            "1 CALL LBL 5\n2 M30\n3 LBL 5\n4 L Z+10 R0 FMAX",
            2,
            "no LBL 0 follows it",
        ),
        (
            "1 CALL LBL \"S\"\n2 M30\n3 LBL \"S\"\n4 LBL 0",
            2,
            "with nothing in it",
        ),
    ] {
        let e = Program::parse(&wrap(body), &cfg).unwrap_err();
        let shown = e.to_string();
        assert!(
            shown.starts_with(&format!("line {line}: ")) && shown.contains(what),
            "{body}: {shown}"
        );
    }
}

#[test]
fn fn14_stops_the_program_with_its_number_and_text() {
    let dir = common::temp_dir("q-fn14");
    let mut cfg = cfg_in(&dir);
    cfg.parameters
        .errors
        .insert("1001".into(), "dispersion too large".into());
    let p = program(&wrap("1 Q1 = 1\n2 FN 14: ERROR = 1001\n3 Q2 = 2"), &cfg);
    let mut m = MockMachine::new(Vec::new());
    let (r, _) = common::run_on(&cfg, &p, &mut m, &dir, true);
    assert!(!r.completed());
    let e = r.error.as_ref().expect("FN 14 reported");
    assert_eq!((e.line, e.number), (3, 1001));
    assert_eq!(e.text.as_deref(), Some("dispersion too large"));
    assert!(
        r.stopped
            .as_deref()
            .unwrap()
            .contains("ERROR = 1001: dispersion too large"),
        "{:?}",
        r.stopped
    );
    assert!(!r.parameters.contains_key("Q2"));
    assert!(r.to_json().contains("\"number\": 1001"));
}

#[test]
fn qr_parameters_are_kept_across_two_runs() {
    let dir = common::temp_dir("q-qr");
    let body = "1 FN 9: IF +QR1 EQU +QR1 GOTO LBL 1
2 LBL 1
3 QR1 = QR1 + 1
4 QR2 = 0.5";
    // The first run, on a fresh state (no QR file): QR1 reads 0, as the TNC's
    // remanent memory starts (issue 34: the docs' own counter failed here).
    assert!(!dir.join("mock.qr.toml").exists());
    let (r, _) = run_in(&dir, body);
    assert!(r.completed(), "{:?}", r.stopped);
    assert_eq!(num(&r, "QR1"), 1.0);
    let (r, _) = run_in(&dir, "1 QR1 = 10");
    assert!(r.completed());
    let (r, _) = run_in(&dir, body);
    assert!(r.completed(), "{:?}", r.stopped);
    assert_eq!(num(&r, "QR1"), 11.0);
    let (r, _) = run_in(&dir, body);
    assert_eq!(num(&r, "QR1"), 12.0);
    let kept = std::fs::read_to_string(dir.join("mock.qr.toml")).unwrap();
    assert!(
        kept.contains("QR1 = 12.0") && kept.contains("QR2 = 0.5"),
        "{kept}"
    );
    // Q and QL are not kept.
    let (r, _) = run_in(&dir, "1 Q5 = 1\n2 QL5 = 1");
    assert!(r.completed());
    let (r, _) = run_in(&dir, "1 Q6 = Q5");
    assert!(r.stopped.as_deref().unwrap().contains("Q5 is not defined"));
    let (r, _) = run_in(&dir, "1 Q6 = QL5");
    assert!(r.stopped.as_deref().unwrap().contains("QL5 is not defined"));
}

/// docs/q-parameters.md's QR example on a fresh state: `check` passes it and two runs
/// count 1, 2 (a QR never set reads 0).
#[test]
fn the_docs_qr_counter_works_on_a_fresh_state() {
    let dir = common::temp_dir("q-qr-fresh");
    let cfg = cfg_in(&dir);
    let p = program(&wrap("1 QR7 = QR7 + 1\n2 L Z+QR7 R0 FMAX"), &cfg);
    preflight_program(&p, 0b111, &cfg, &dir.join("k.toml")).unwrap_or_else(|e| panic!("{e}"));
    for n in [1.0, 2.0] {
        let (r, m) = run_in(&dir, "1 QR7 = QR7 + 1\n2 L Z+QR7 R0 FMAX");
        assert!(r.completed(), "{:?}", r.stopped);
        assert_eq!(num(&r, "QR7"), n);
        assert_eq!(m.moves.last().unwrap().0[2], n);
    }
}

/// Each error stops the program at its line, before the move after it.
#[test]
fn errors_at_their_line() {
    for (body, line, what) in [
        ("1 Q1 = Q7 + 1\n2 L Z+10 R0 FMAX", 1, "Q7 is not defined"),
        (
            "1 Q1 = 0\n2 Q2 = 5 / Q1\n3 L Z+10 R0 FMAX",
            2,
            "division by zero",
        ),
        (
            "1 Q1 = -4\n2 Q2 = SQRT Q1\n3 L Z+10 R0 FMAX",
            2,
            "square root of a negative",
        ),
        (
            "1 QS1 = \"abc\"\n2 QS2 = SUBSTR ( SRC_QS1 BEG2 LEN5 )",
            2,
            "beyond QS1",
        ),
        (
            "1 QS1 = \"1,5\"\n2 Q1 = TONUMB ( SRC_QS1 )",
            2,
            "not a number",
        ),
        ("1 Q1 = ASIN 2", 1, "within -1..+1"),
        ("1 L Z+10 R0 FMAX\n2 L X+Q9 R0 FMAX", 2, "Q9 is not defined"),
    ] {
        let dir = common::temp_dir("q-err");
        let cfg = cfg_in(&dir);
        let p = program(&wrap(body), &cfg);
        // check refuses it, at its line...
        let e = preflight_program(&p, 0b111, &cfg, &dir.join("k.toml")).unwrap_err();
        assert!(
            e.to_string().starts_with(&format!("line {}: ", line + 1))
                && e.to_string().contains(what),
            "{body}: {e}"
        );
        assert!(matches!(e.kind(), PreflightKind::Program(_)), "{e:?}");
        // ...and run moves nothing.
        let (r, m) = run_in(&dir, body);
        assert!(
            r.stopped.as_deref().unwrap().contains(what),
            "{:?}",
            r.stopped
        );
        assert!(m.moves.is_empty(), "{body}: moved {:?}", m.moves);
    }
}

#[test]
fn a_loop_forever_is_stopped_after_the_configured_jumps() {
    let dir = common::temp_dir("q-jumps");
    let mut cfg = cfg_in(&dir);
    cfg.parameters.max_jumps = 50;
    let p = program(
        &wrap("1 Q1 = 0\n2 LBL 1\n3 Q1 = Q1 + 1\n4 FN 9: IF +0 EQU +0 GOTO LBL 1"),
        &cfg,
    );
    let e = preflight_program(&p, 0b111, &cfg, &dir.join("k.toml")).unwrap_err();
    assert!(
        e.to_string().starts_with("line 5: more than 50 jumps"),
        "{e}"
    );
    // run refuses it the same way, before the machine moves.
    let mut m = MockMachine::new(Vec::new());
    let (r, _) = common::run_on(&cfg, &p, &mut m, &dir, true);
    let stopped = r.stopped.as_deref().unwrap();
    assert!(
        stopped.contains("more than 50 jumps") && stopped.contains("nothing moved"),
        "{stopped}"
    );
    assert!(m.moves.is_empty());
}

#[test]
fn check_refuses_an_l_block_whose_q_value_is_outside_the_limits() {
    let dir = common::temp_dir("q-limits");
    let cfg = cfg_in(&dir);
    let p = program(
        &wrap("1 Q20 = 400\n2 Q20 = Q20 * 5\n3 L Z+Q20 R0 FMAX"),
        &cfg,
    );
    let e = preflight_program(&p, 0b111, &cfg, &dir.join("k.toml")).unwrap_err();
    assert!(
        e.to_string().starts_with("line 4: ") && e.to_string().contains("software limits"),
        "{e}"
    );
    // Within them, the same program is fine; -Q20 negates.
    let p = program(&wrap("1 Q20 = 100\n2 L Z-Q20 X+Q20 R0 FQ20"), &cfg);
    preflight_program(&p, 0b111, &cfg, &dir.join("k.toml")).unwrap();
}

#[test]
fn parse_errors_name_their_line() {
    let cfg = common::config();
    for (body, line, what) in [
        ("1 Q1 = ( 2 + 3", 2, "expected ')'"),
        (
            "1 FN 9: IF +Q1 EQU +2 GOTO LBL 7",
            2,
            "LBL 7 is not defined",
        ),
        ("1 LBL 3\n2 LBL 3", 3, "LBL 3 is defined twice"),
        (
            "1 FN 11: IF +Q1 LT +2 GOTO LBL 1\n2 LBL 1",
            2,
            "compares with GT",
        ),
        (
            "1 FN 16: F-PRINT TNC:\\a.A/TNC:\\b.TXT",
            2,
            "F-PRINT does not run here",
        ),
        ("1 Q1 = QS1 + 1", 2, "QS1 is a string"),
        ("1 Q2000 = 1", 2, "no such parameter"),
        ("1 FN 1: Q1 = +2 * +3", 2, "FN 1: expected"),
        ("1 CALL LBL 0", 2, "label 0"),
        ("1 Q1 = FOO 3", 2, "FOO: unknown function"),
        // As the 451 seed prints three of its comments: `:` where `;` is meant.
        (
            "1 QL1 = TONUMB ( SRC_QS0 ) :QS0 to a number",
            2,
            "unexpected character ':' (a comment starts with ';')",
        ),
    ] {
        let e = Program::parse(&wrap(body), &cfg).unwrap_err();
        let shown = e.to_string();
        assert!(
            shown.starts_with(&format!("line {line}: ")) && shown.contains(what),
            "{body}: {shown}"
        );
    }
}

/// Q parameters as cycle parameter values: resolved when the block runs, validated as
/// written numbers are (an out-of-range value stops at the cycle's line); a measured
/// value as the nominal point of the next 444.
#[test]
fn q_parameters_as_cycle_parameter_values() {
    let block = |z: &str| {
        format!(
            "2 TCH PROBE 444 PROBING 3D ~\n  Q263=+Q1 ~\n  Q264=-QL2 ~\n  Q294={z} ~\n  Q581=+0 ~\n  Q582=+0 ~\n  Q583=+1 ~\n  Q320=+1 ~\n  Q260=+Q3"
        )
    };
    let body = format!(
        "1 TOOL CALL \"TOUCH_PROBE\" Z\n3 Q1 = 10\n4 QL2 = 5\n5 Q3 = 100\n{}\n6 Q4 = Q153 + 1\n{}",
        block("+0.25"),
        block("+Q4")
    );
    let dir = common::temp_dir("q-cycle");
    let (r, m) = run_in(&dir, &body);
    assert!(r.completed(), "{:?}", r.stopped);
    assert_eq!(r.cycles.len(), 2);
    // The plane is at Z=0: the first point (nominal 0.25) deviates by -0.25...
    assert!(
        (r.cycles[0].q["Q164"] + 0.25).abs() < 1e-9,
        "{:?}",
        r.cycles[0].q
    );
    assert!(
        (r.cycles[0].q["Q151"] - 10.0).abs() < 1e-9 && (r.cycles[0].q["Q152"] + 5.0).abs() < 1e-9
    );
    // ...the second's nominal is Q153 + 1 = 1, measured at run time.
    assert!((num(&r, "Q4") - 1.0).abs() < 1e-9);
    assert!(
        (r.cycles[1].q["Q164"] + 1.0).abs() < 1e-9,
        "{:?}",
        r.cycles[1].q
    );
    assert!(!m.probes.is_empty());
    // A value outside the parameter's range stops at the cycle's line, nothing probed.
    let bad = format!(
        "1 TOOL CALL \"TOUCH_PROBE\" Z\n3 Q1 = 1000000\n4 QL2 = 5\n5 Q3 = 100\n{}",
        block("+0")
    );
    let (r, m) = run_in(&common::temp_dir("q-cycle-bad"), &bad);
    let stopped = r.stopped.as_deref().unwrap();
    assert!(
        stopped.contains("line 6") && stopped.contains("Q263"),
        "{stopped}"
    );
    assert!(m.probes.is_empty());
}

/// Cycle 444 at X10 Y5, nominal Z+0.25 (the scenario's point is 0.25 off it: Q164 is
/// -0.25), as blocks 1 and 2 of a program whose blocks 3.. act on what it measured.
const PROBE_444: &str = "1 TOOL CALL \"TOUCH_PROBE\" Z\n2 TCH PROBE 444 PROBING 3D ~\n  Q263=+10 ~\n  Q264=+5 ~\n  Q294=+0.25 ~\n  Q581=+0 ~\n  Q582=+0 ~\n  Q583=+1 ~\n  Q320=+1 ~\n  Q260=+100\n";

/// `blocks` after [`PROBE_444`]: `check` must pass them (it cannot know the measured
/// values), then the run.
fn checked_then_run(name: &str, blocks: &str) -> (ProgramReport, MockMachine) {
    let body = format!("{PROBE_444}{blocks}");
    let dir = common::temp_dir(name);
    let cfg = cfg_in(&dir);
    let p = program(&wrap(&body), &cfg);
    preflight_program(&p, 0b111, &cfg, &dir.join("k.toml"))
        .unwrap_or_else(|e| panic!("check cannot know the measured value: {e}"));
    run_in(&dir, &body)
}

/// An error that only the measured value makes (a division by a result that is 0):
/// `check` cannot know it and lets the program start; the run stops at its line after
/// the cycle, and the move after it is not made.
#[test]
fn an_error_on_a_measured_value_stops_at_its_line_before_the_next_move() {
    let (r, m) = checked_then_run(
        "q-measured-error",
        "3 Q5 = Q164 + 0.25\n4 Q6 = 1 / Q5\n5 L Z+50 R0 FMAX",
    );
    assert_eq!(r.cycles.len(), 1);
    assert!(
        (r.cycles[0].q["Q164"] + 0.25).abs() < 1e-9,
        "{:?}",
        r.cycles[0].q
    );
    let stopped = r.stopped.as_deref().unwrap();
    // Physical line 13: BEGIN PGM, TOOL CALL, the cycle's nine lines, Q5, then Q6.
    assert!(
        stopped.starts_with("line 13: ") && stopped.contains("division by zero"),
        "{stopped}"
    );
    assert!(!m.probes.is_empty());
    assert!(
        m.moves.iter().all(|(p, _)| (p[2] - 50.0).abs() > 1e-9),
        "the L block after the error moved: {:?}",
        m.moves
    );
}

/// A move on a measured value: `check` cannot know it; the run checks it against the
/// limits once the value is known, and stops at its line before it moves.
#[test]
fn a_move_on_a_measured_value_is_checked_before_it_moves() {
    let (r, m) = checked_then_run(
        "q-measured-move",
        "3 Q20 = Q164 * 100000\n4 L X+Q20 R0 FMAX",
    );
    assert_eq!(r.cycles.len(), 1);
    assert!((num(&r, "Q20") + 25000.0).abs() < 1e-6);
    let stopped = r.stopped.as_deref().unwrap();
    assert!(
        stopped.contains("line 13") && stopped.contains("software limits"),
        "{stopped}"
    );
    assert!(
        m.moves.iter().all(|(p, _)| p[0] > -1000.0),
        "the L block outside the limits moved: {:?}",
        m.moves
    );
}

/// The results docs/q-parameters.md lists for 431 and 444 are readable by the program
/// after the cycle, with the values the cycle wrote.
#[test]
fn the_results_of_431_and_444_are_readable_after_the_cycle() {
    let c431 = "2 TCH PROBE 431 MEASURE PLANE ~\n  Q263=+0 ~\n  Q264=+0 ~\n  Q294=+0.5 ~\n  Q265=+50 ~\n  Q266=+0 ~\n  Q295=+0.5 ~\n  Q296=+0 ~\n  Q297=+50 ~\n  Q298=+0.5 ~\n  Q320=+0 ~\n  Q260=+50 ~\n  Q281=+0";
    let c444 = "2 TCH PROBE 444 PROBING 3D ~\n  Q263=+10 ~\n  Q264=+5 ~\n  Q294=+0.25 ~\n  Q581=+0 ~\n  Q582=+0 ~\n  Q583=+1 ~\n  Q320=+1 ~\n  Q260=+100";
    for (cycle, names) in [
        (
            c431,
            &[
                "Q158", "Q159", "Q170", "Q171", "Q172", "Q173", "Q174", "Q175",
            ][..],
        ),
        (
            c444,
            &[
                "Q151", "Q152", "Q153", "Q161", "Q162", "Q163", "Q164", "Q183",
            ][..],
        ),
    ] {
        let reads: Vec<String> = names
            .iter()
            .enumerate()
            .map(|(i, q)| format!("{} QL{i} = {q} + 0", 3 + i))
            .collect();
        let body = format!(
            "1 TOOL CALL \"TOUCH_PROBE\" Z\n{cycle}\n{}",
            reads.join("\n")
        );
        let dir = common::temp_dir("q-results");
        let cfg = cfg_in(&dir);
        preflight_program(
            &program(&wrap(&body), &cfg),
            0b111,
            &cfg,
            &dir.join("k.toml"),
        )
        .unwrap_or_else(|e| panic!("check knows what the cycle writes: {e}"));
        let (r, _) = run_in(&dir, &body);
        assert!(r.completed(), "{:?}", r.stopped);
        for (i, q) in names.iter().enumerate() {
            let written = r.cycles[0].q[*q];
            assert_eq!(num(&r, &format!("QL{i}")), written, "{q}");
            assert_eq!(num(&r, q), written, "{q} in the run's parameters");
        }
    }
}

/// STRCOMP and INSTR, as the TNC has them: a text comparison gives a number the jumps
/// compare.
#[test]
fn string_comparison_with_strcomp_and_instr() {
    let r = run("1 QS1 = \"ABC\"
2 QS2 = \"ABD\"
3 QS3 = \"ABC\"
4 Q1 = STRCOMP ( SRC_QS1 SEA_QS2 )
5 Q2 = STRCOMP ( SRC_QS2 SEA_QS1 )
6 Q3 = STRCOMP ( SRC_QS1 SEA_QS3 )
7 QS4 = \"B\"
8 Q4 = INSTR ( SRC_QS1 SEA_QS4 )
9 Q5 = INSTR ( SRC_QS1 SEA_QS4 BEG2 )
10 QS5 = \"abc\"
11 Q6 = STRCOMP ( SRC_QS1 SEA_QS5 )
12 FN 9: IF +Q3 EQU +0 GOTO LBL \"SAME\"
13 Q7 = 1
14 LBL \"SAME\"
15 FN 9: IF STRCOMP ( SRC_QS1 SEA_QS2 ) EQU +0 GOTO LBL 1
16 Q8 = 1
17 LBL 1");
    assert!(r.completed(), "{:?}", r.stopped);
    for (n, v) in [
        ("Q1", -1.0),
        ("Q2", 1.0),
        ("Q3", 0.0),
        ("Q4", 1.0),
        // Not found from character 2 on: the length of QS1.
        ("Q5", 3.0),
        // Upper case comes before lower case in the character order.
        ("Q6", -1.0),
        ("Q8", 1.0),
    ] {
        assert_eq!(num(&r, n), v, "{n}");
    }
    assert!(!r.parameters.contains_key("Q7"), "the jump was not taken");
}

#[test]
fn string_errors_at_their_line() {
    let cfg = common::config();
    for (body, line, what) in [
        (
            "1 QS1 = \"A\"\n2 QS2 = \"A\"\n3 FN 9: IF QS1 EQU QS2 GOTO LBL 1\n4 LBL 1",
            4,
            "STRCOMP ( SRC_QSa SEA_QSb )",
        ),
        (
            "1 FN 10: IF +Q1 NE \"A\" GOTO LBL 1\n2 LBL 1",
            2,
            "FN 9..12 compare numbers",
        ),
        ("1 Q1 = STRCOMP ( SRC_QS1 QS2 )", 2, "expected SEA_QSn"),
        ("1 Q1 = STRCOMP ( SRC_Q1 SEA_QS2 )", 2, "expected SRC_QSn"),
        ("1 Q1 = INSTR ( SRC_QS1 SEA_QS2 BEG1", 2, "to close INSTR"),
    ] {
        let e = Program::parse(&wrap(body), &cfg).unwrap_err();
        let shown = e.to_string();
        assert!(
            shown.starts_with(&format!("line {line}: ")) && shown.contains(what),
            "{body}: {shown}"
        );
    }
    // At run time: stopped at the line, nothing moved after it.
    for (body, what) in [
        (
            "1 QS1 = \"A\"\n2 Q1 = STRCOMP ( SRC_QS1 SEA_QS9 )\n3 L Z+10 R0 FMAX",
            "QS9 is not defined",
        ),
        (
            "1 QS1 = \"AB\"\n2 Q1 = INSTR ( SRC_QS1 SEA_QS1 BEG3 )\n3 L Z+10 R0 FMAX",
            "INSTR: BEG3 is beyond QS1",
        ),
    ] {
        let dir = common::temp_dir("q-str-err");
        let (r, m) = run_in(&dir, body);
        let stopped = r.stopped.as_deref().unwrap();
        assert!(
            stopped.contains("line 3") && stopped.contains(what),
            "{stopped}"
        );
        assert!(m.moves.is_empty(), "{body}: moved {:?}", m.moves);
    }
}

/// A QS parameter as a cycle's string value (`QS400=QS1`): read when the block runs
/// and validated as a written string is.
#[test]
fn qs_parameters_as_cycle_string_values() {
    let block = "2 TCH PROBE 444 PROBING 3D ~\n  Q263=+0 ~\n  Q264=+0 ~\n  Q294=+0.5 ~\n  Q581=+0 ~\n  Q582=+0 ~\n  Q583=+1 ~\n  Q320=+1 ~\n  Q260=+100 ~\n  QS400=QS1 ~\n  Q309=+0";
    // The plane is at Z=0, the nominal point at 0.5: 0.5 undersize.
    for (tol, status) in [("0.4-0.1", 2.0), ("1-1", 0.0), (" ", -1.0)] {
        let body = format!("1 TOOL CALL \"TOUCH_PROBE\" Z\n3 QS1 = \"{tol}\"\n{block}");
        let (r, _) = run_in(&common::temp_dir("q-qs400"), &body);
        assert!(r.completed(), "{tol}: {:?}", r.stopped);
        assert_eq!(
            r.cycles[0].q["Q183"], status,
            "QS400=QS1 with QS1 = \"{tol}\""
        );
    }
    // A text that is no tolerance stops at the cycle's line, nothing probed.
    let body = format!("1 TOOL CALL \"TOUCH_PROBE\" Z\n3 QS1 = \"wide\"\n{block}");
    let (r, m) = run_in(&common::temp_dir("q-qs400-bad"), &body);
    let stopped = r.stopped.as_deref().unwrap();
    assert!(
        stopped.contains("line 4") && stopped.contains("QS400"),
        "{stopped}"
    );
    assert!(m.probes.is_empty());
    // An undefined one too.
    let body = format!("1 TOOL CALL \"TOUCH_PROBE\" Z\n{block}");
    let (r, m) = run_in(&common::temp_dir("q-qs400-undef"), &body);
    let stopped = r.stopped.as_deref().unwrap();
    assert!(stopped.contains("QS1 is not defined"), "{stopped}");
    assert!(m.probes.is_empty());
}

/// Issue 34: block numbers out of order or repeated are a warning at their line (the
/// TNC renumbers), from `check` and `run` alike (both ask
/// [`program_warnings`]); the program is not refused and runs in the order written.
#[test]
fn block_numbers_out_of_order_or_repeated_are_warned_at_their_line() {
    let dir = common::temp_dir("q-numbers");
    let cfg = cfg_in(&dir);
    let body = "10 Q1 = 1\n30 Q1 = Q1 * 3\n20 Q1 = Q1 + 4\n30 L Z+Q1 R0 FMAX";
    let p = program(&wrap(body), &cfg);
    let said: Vec<String> = program_warnings(&p, &cfg)
        .iter()
        .map(ToString::to_string)
        .collect();
    assert_eq!(said.len(), 2, "{said:?}");
    assert!(
        said[0].starts_with("line 4: warning: block number 20 after 30 (line 3)"),
        "{said:?}"
    );
    assert!(
        said[1].starts_with("line 5: warning: block number 30 again (first on line 3)"),
        "{said:?}"
    );
    preflight_program(&p, 0b111, &cfg, &dir.join("k.toml")).unwrap_or_else(|e| panic!("{e}"));
    let (r, m) = run_in(&dir, body);
    assert!(r.completed(), "{:?}", r.stopped);
    assert_eq!(num(&r, "Q1"), 7.0);
    assert_eq!(m.moves.last().unwrap().0[2], 7.0);
    // In order: nothing to say.
    let p = program(&wrap("1 Q1 = 1\n2 Q2 = 2\n7 Q3 = 3"), &cfg);
    assert!(program_warnings(&p, &cfg).is_empty());
}

/// A 444 in an INCH program (values in inches), then `blocks`.
fn inch_444(blocks: &str, unit: &str) -> String {
    format!(
        "0 BEGIN PGM T {unit}
1 TOOL CALL \"TOUCH_PROBE\" Z
2 TCH PROBE 444 PROBING 3D ~
  Q263=+0.4 ~
  Q264=+0.2 ~
  Q294=+0.01 ~
  Q581=+0 ~
  Q582=+0 ~
  Q583=+1 ~
  Q320=+0.04 ~
  Q260=+4
{blocks}
99999 END PGM T {unit}
"
    )
}

/// Issue 34: the cycles report lengths in mm whatever the program's unit. An INCH
/// program that moves to a measured length, or gives it to a cycle parameter of unit
/// length, directly or through assignments, is warned at that line; one that converts
/// it (/ 25.4) or uses a measured angle or count is not, nor an MM program.
#[test]
fn an_inch_program_using_a_length_measured_in_mm_is_warned_at_the_line() {
    let cfg = common::config();
    let blocks = "3 Q1 = Q151
4 Q2 = Q1 * 2 + 0.1
5 Q3 = Q161 / 25.4
6 Q4 = Q183 + 1
7 L X+Q2 Y+Q3 Z+Q4 R0 FMAX
8 L X-Q151 R0 FMAX
9 Q1 = 0.5
10 L X+Q1 R0 FMAX
11 TCH PROBE 444 PROBING 3D ~
  Q263=+Q3 ~
  Q264=-Q164 ~
  Q294=+0.01 ~
  Q581=+0 ~
  Q582=+0 ~
  Q583=+1 ~
  Q320=+Q2 ~
  Q260=+4";
    let p = program(&inch_444(blocks, "INCH"), &cfg);
    let said: Vec<String> = program_warnings(&p, &cfg)
        .iter()
        .map(ToString::to_string)
        .collect();
    let expected = [
        "line 16: warning: Q2 is in mm (the cycle reports in mm); this INCH program reads it as inches (L X+Q2)",
        "line 17: warning: Q151 is in mm (the cycle reports in mm); this INCH program reads it as inches (L X-Q151)",
        "line 22: warning: Q164 is in mm (the cycle reports in mm); this INCH program reads it as inches (cycle 444 Q264=-Q164)",
        "line 27: warning: Q2 is in mm (the cycle reports in mm); this INCH program reads it as inches (cycle 444 Q320=+Q2)",
    ];
    assert_eq!(said.len(), expected.len(), "{said:#?}");
    for (s, e) in said.iter().zip(expected) {
        assert!(s.starts_with(e), "{s}\nexpected {e}");
    }
    // The same in MM: nothing to say.
    let p = program(&inch_444(blocks, "MM"), &cfg);
    assert!(program_warnings(&p, &cfg).is_empty());
}

/// The taint follows the program's flow: a measured length assigned in a subprogram
/// that stands after M30 and is called before the move.
#[test]
fn the_mm_warning_follows_calls_and_jumps() {
    let cfg = common::config();
    let blocks = "3 CALL LBL 5
4 FN 11: IF +Q183 GT +0 GOTO LBL 6
5 L Z+QL1 R0 FMAX
6 LBL 6
7 M30
8 LBL 5
9 QL1 = ABS Q153
10 LBL 0";
    let p = program(&inch_444(blocks, "INCH"), &cfg);
    let said: Vec<String> = program_warnings(&p, &cfg)
        .iter()
        .map(ToString::to_string)
        .collect();
    assert_eq!(said.len(), 1, "{said:#?}");
    assert!(
        said[0].starts_with("line 14: warning: QL1 is in mm"),
        "{said:?}"
    );
}
