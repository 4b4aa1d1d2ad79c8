//! Parameter tables and program validation: every range one step outside, the error
//! kinds, all errors collected, each with its line.

mod common;

use probebridge_cycles::params::{self, CycleTable, Kind};
use probebridge_cycles::program::{CycleKind, LengthUnit, Origin, ProbeAxis, Statement, Value};
use probebridge_cycles::{check_program, Program};

/// A valid value for every parameter (in range, points not on a line, normal not 0).
fn valid_value(cycle: u16, name: &str) -> String {
    match (cycle, name) {
        (_, "QS400") => "\"0.4-0.1\"".into(),
        (431, "Q265") | (431, "Q297") => "+50".into(),
        (444, "Q583") => "+1".into(),
        (451, "Q407") => "+12.5".into(),
        (451, "Q423") => "+4".into(),
        (460, "Q407") => "+12.5".into(),
        (460, "Q423") => "+8".into(),
        _ => "+0".into(),
    }
}

/// Full program: header (line 1), TOOL CALL (line 2), cycle (line 3), one parameter
/// per line from line 4 in table order; `over` replaces one value.
fn program(table: &CycleTable, over: Option<(&str, &str)>) -> String {
    let mut s = format!(
        "0 BEGIN PGM T MM\n1 TOOL CALL \"TOUCH_PROBE\" Z\n2 TCH PROBE {} {} ~\n",
        table.number, table.name
    );
    let n = table.params.len();
    for (i, p) in table.params.iter().enumerate() {
        let v = match over {
            Some((name, v)) if name == p.name => v.to_string(),
            _ => valid_value(table.number, p.name),
        };
        let cont = if i + 1 < n { " ~" } else { "" };
        s.push_str(&format!("  {}={v} ;{}{cont}\n", p.name, p.title));
    }
    s.push_str(&format!("{} END PGM T MM\n", n + 3));
    s
}

fn line_of(table: &CycleTable, name: &str) -> usize {
    4 + table.params.iter().position(|p| p.name == name).unwrap()
}

#[test]
fn valid_programs_of_every_table_parse() {
    for table in params::TABLES {
        let text = program(table, None);
        Program::parse(&text, &common::config()).unwrap_or_else(|e| panic!("{e}\n{text}"));
    }
}

#[test]
fn every_number_rejected_one_step_outside_and_accepted_at_its_limits() {
    let cfg = common::config();
    for table in params::TABLES {
        for p in table.params {
            let Kind::Number {
                min, max, integer, ..
            } = p.kind
            else {
                continue;
            };
            let step = if integer { 1.0 } else { 0.0001 };
            for (v, ok) in [
                (min, true),
                (max, true),
                (min - step, false),
                (max + step, false),
            ] {
                let written = format!("{v:+}");
                let text = program(table, Some((p.name, &written)));
                let diags = check_program(&text, &cfg);
                if ok {
                    assert!(
                        diags.is_empty(),
                        "{} {}={written}: {diags:?}",
                        table.number,
                        p.name
                    );
                    continue;
                }
                assert_eq!(
                    diags.len(),
                    1,
                    "{} {}={written}: {diags:?}",
                    table.number,
                    p.name
                );
                let d = &diags[0];
                assert_eq!(d.line, line_of(table, p.name), "{d}");
                let expected = format!(
                    "{}={written}: {} out of range {min}..{max}",
                    p.name, p.title
                );
                assert!(d.message.starts_with(&expected), "{d}\nexpected {expected}");
            }
            if integer {
                let text = program(table, Some((p.name, "+1.5")));
                let diags = check_program(&text, &cfg);
                assert_eq!(diags.len(), 1, "{}: {diags:?}", p.name);
                assert!(diags[0].message.contains("whole numbers"), "{}", diags[0]);
            }
        }
    }
}

#[test]
fn message_names_line_parameter_comment_and_range() {
    let text = "11 TOOL CALL \"TOUCH_PROBE\" Z\n12 TCH PROBE 444 ANTASTEN 3D ~\n\
        Q263=+1e6 ;1. PUNKT 1. ACHSE ~\nQ264=+0 ~\nQ294=+0 ~\nQ581=+1 ~\nQ582=+0 ~\nQ583=+0 ~\nQ260=+100";
    let e = Program::parse(text, &common::config()).unwrap_err();
    assert_eq!(
        e.to_string(),
        "line 3: Q263=+1e6: 1. PUNKT 1. ACHSE out of range -99999.9999..99999.9999"
    );
}

fn diags_of(text: &str) -> Vec<String> {
    check_program(text, &common::config())
        .into_iter()
        .map(|d| d.to_string())
        .collect()
}

const HEAD: &str = "1 TOOL CALL \"TOUCH_PROBE\" Z\n2 TCH PROBE 444 PROBING 3D ~\n";

#[test]
fn unknown_parameter() {
    let d = diags_of(&format!(
        "{HEAD}Q263=+0 ~\nQ264=+0 ~\nQ294=+0 ~\nQ581=+1 ~\nQ582=+0 ~\nQ583=+0 ~\nQ999=+1 ;X ~\nQ260=+50"
    ));
    assert_eq!(d.len(), 1, "{d:?}");
    assert!(
        d[0].starts_with(
            "line 9: Q999=+1: unknown parameter for cycle 444 PROBING 3D (allowed: Q263"
        ),
        "{}",
        d[0]
    );
}

#[test]
fn missing_continuation_is_named_at_the_line_without_tilde() {
    let d = diags_of(&format!(
        "{HEAD}Q263=+0 ;A ~\nQ264=+0 ;B\nQ294=+0 ;C ~\nQ581=+1 ~\nQ582=+0 ~\nQ583=+0 ~\nQ260=+50"
    ));
    assert_eq!(
        d,
        vec!["line 4: missing continuation \"~\": the block ends here but line 5 continues it with Q294"]
    );
    // The block ends too early: the parameters still expected are named, with the hint.
    let d = diags_of(&format!(
        "{HEAD}Q263=+0 ~\nQ264=+0 ~\nQ294=+0\n3 L Z+100 FMAX"
    ));
    assert_eq!(d.len(), 4, "{d:?}");
    for (q, line) in d.iter().zip(["Q581", "Q582", "Q583", "Q260"]) {
        assert!(
            q.starts_with("line 2: cycle 444 PROBING 3D: missing required parameter"),
            "{q}"
        );
        assert!(
            q.contains(line) && q.contains("the block ends at line 5"),
            "{q}"
        );
    }
    // `~` on the last line, then the file ends.
    let d = diags_of(&format!("{HEAD}Q263=+0 ~"));
    assert!(
        d.iter()
            .any(|m| m == "line 3: the block continues with \"~\" but the program ends"),
        "{d:?}"
    );
}

#[test]
fn malformed_number_and_syntax() {
    let base = "Q263=+0 ~\nQ264=+0 ~\nQ294=+0 ~\nQ581=+1 ~\nQ582=+0 ~\nQ583=+0 ~\nQ260=+50";
    // (`Q264=Q1` is a Q parameter as the value, resolved when the block runs.)
    for bad in ["+1.2.3", "abc", "+", "1,5", "QS1", "--1"] {
        let d = diags_of(&format!(
            "{HEAD}{}",
            base.replace("Q264=+0", &format!("Q264={bad}"))
        ));
        assert_eq!(d.len(), 1, "{bad}: {d:?}");
        assert!(
            d[0].starts_with(&format!(
                "line 4: Q264={bad}: 1ST POINT 2ND AXIS: malformed number"
            )),
            "{}",
            d[0]
        );
    }
    let d = diags_of(&format!("{HEAD}{}", base.replace("Q264=+0", "Q264 +0")));
    assert!(
        d[0].starts_with("line 4: Q264: expected Qnnn=value"),
        "{d:?}"
    );
    let d = diags_of(&format!(
        "{HEAD}{}",
        base.replace("Q264=+0", "QS400=\"open")
    ));
    assert!(
        d.iter()
            .any(|m| m.starts_with("line 4: QS400=\"open: unterminated string")),
        "{d:?}"
    );
}

#[test]
fn string_length_limit() {
    let base =
        "Q263=+0 ~\nQ264=+0 ~\nQ294=+0 ~\nQ581=+1 ~\nQ582=+0 ~\nQ583=+0 ~\nQ260=+50 ~\nQS400=\"X\"";
    let long = " ".repeat(255);
    assert!(diags_of(&format!(
        "{HEAD}{}",
        base.replace("\"X\"", &format!("\"{long}\""))
    ))
    .is_empty());
    let too_long = "0".repeat(256);
    let d = diags_of(&format!(
        "{HEAD}{}",
        base.replace("\"X\"", &format!("\"{too_long}\""))
    ));
    assert_eq!(d.len(), 1);
    assert!(
        d[0].starts_with("line 10: QS400=")
            && d[0].contains("string of 256 characters is too long (at most 255)"),
        "{}",
        d[0]
    );
    // And the tolerance grammar.
    let d = diags_of(&format!("{HEAD}{}", base.replace("\"X\"", "\"0.4*0.1\"")));
    assert_eq!(d.len(), 1);
    assert!(
        d[0].starts_with("line 10: QS400=\"0.4*0.1\": malformed tolerance"),
        "{}",
        d[0]
    );
}

#[test]
fn unknown_cycle_number() {
    let d = diags_of(
        "1 TOOL CALL \"TOUCH_PROBE\" Z\n2 TCH PROBE 400 BASIC ROTATION ~\nQ263=+0\n3 G425 Q311=+1",
    );
    assert_eq!(d.len(), 2, "{d:?}");
    assert!(d[0].starts_with(
        "line 2: TCH PROBE 400: unknown cycle number 400 (supported: 431, 444, 450, 451, 460)"
    ));
    assert!(d[1].starts_with("line 4: G425: unknown cycle number 425"));
}

#[test]
fn keywords_only_where_the_table_allows_them() {
    let base = "Q263=+0 ~\nQ264=+0 ~\nQ294=+0 ~\nQ581=+1 ~\nQ582=+0 ~\nQ583=+0 ~\nQ320=PREDEF ~\nQ260=PREDEF";
    let p = Program::parse(&format!("{HEAD}{base}"), &common::config()).unwrap();
    let c = p.cycles().next().unwrap();
    assert_eq!(c.head.number("Q320"), Some(0.5));
    assert_eq!(c.head.params["Q320"].origin, Origin::Predef);
    assert_eq!(c.head.number("Q260"), Some(150.0));
    let d = diags_of(&format!("{HEAD}{}", base.replace("Q263=+0", "Q263=PREDEF")));
    assert_eq!(d, vec!["line 3: Q263=PREDEF: 1ST POINT 1ST AXIS does not take PREDEF (allowed -99999.9999..99999.9999)"]);
    let d = diags_of(&format!("{HEAD}{}", base.replace("Q263=+0", "Q263=FMAX")));
    assert!(d[0].contains("does not take FMAX"), "{d:?}");
    // PREDEF needs a value in the configuration.
    let mut cfg = common::config();
    cfg.parameters.predef.remove("Q260");
    let d = check_program(&format!("{HEAD}{base}"), &cfg);
    assert_eq!(d.len(), 1);
    assert_eq!(d[0].line, 10);
    assert!(
        d[0].message.contains("no Q260 in [cycles.predef]"),
        "{}",
        d[0]
    );
    // 451's feed takes FMAX and FAUTO.
    let text = "1 TOOL CALL \"TOUCH_PROBE\" Z\n2 G451 Q406=+0 Q407=+12.5 Q253=FMAX";
    let p = Program::parse(text, &common::config()).unwrap();
    assert_eq!(
        p.cycles().next().unwrap().head.params["Q253"].value,
        Value::Fmax
    );
}

#[test]
fn defaults_fill_optional_parameters() {
    let p = Program::parse(
        &format!(
            "{HEAD}Q263=+0 ~\nQ264=+0 ~\nQ294=+0 ~\nQ581=+1 ~\nQ582=+0 ~\nQ583=+0 ~\nQ260=+50"
        ),
        &common::config(),
    )
    .unwrap();
    let c = p.cycles().next().unwrap();
    for (q, v) in [("Q320", 0.0), ("Q309", 0.0)] {
        assert_eq!(c.head.number(q), Some(v));
        assert_eq!(c.head.params[q].origin, Origin::Default);
    }
    let CycleKind::Probing3d(params) = &c.kind else {
        panic!()
    };
    assert_eq!(params.tolerance, None);
}

#[test]
fn all_errors_of_a_program_are_collected() {
    let text = "0 BEGIN PGM BAD MM\n1 TOOL CALL \"NOPE\" Z\n2 TOOL CALL \"TOUCH_PROBE\" Z\n\
        3 TCH PROBE 444 ANTASTEN 3D ~\nQ263=+1e6 ~\nQ264=x ~\nQ294=+0 ~\nQ581=+0 ~\nQ582=+0 ~\nQ583=+0 ~\nQ260=+50 ~\nQ309=+3\n\
        4 TCH PROBE 431 PLANE ~\nQ263=+0 ~\nQ264=+0 ~\nQ294=+0 ~\nQ265=+10 ~\nQ266=+0 ~\nQ295=+0 ~\nQ296=+20 ~\nQ297=+0 ~\nQ298=+0 ~\nQ260=+50\n\
        5 END PGM OTHER MM";
    let d = diags_of(text);
    let lines: Vec<&str> = d.iter().map(|s| s.split(':').next().unwrap()).collect();
    assert_eq!(
        lines,
        ["line 2", "line 5", "line 6", "line 12", "line 14", "line 24"],
        "{d:#?}"
    );
    assert!(d[0].contains("TOOL CALL \"NOPE\": no probe of that name in the probe table (known: \"TOUCH_PROBE\", \"TS 460\")"));
    assert!(
        d[4].contains("three nominal points lie on a line"),
        "{}",
        d[4]
    );
    assert!(d[5].contains("does not match BEGIN PGM BAD MM"), "{}", d[5]);
    // The zero normal is reported once the other 444 errors are fixed.
    let d = diags_of(
        &text
            .replace("Q263=+1e6", "Q263=+0")
            .replace("Q264=x", "Q264=+0")
            .replace("Q309=+3", "Q309=+0"),
    );
    assert!(d.iter().any(|m| m.starts_with("line 8: Q581/Q582/Q583: the surface normal is the zero vector")), "{d:#?}");
}

#[test]
fn cycle_without_tool_call_and_unknown_probe_number() {
    let d = diags_of("1 TCH PROBE 450 SAVE ~\nQ410=+0 ~\nQ409=+1");
    assert_eq!(
        d,
        vec!["line 1: cycle 450 SAVE KINEMATICS: no TOOL CALL of a touch probe before this cycle"]
    );
    let d = diags_of("1 TOOL CALL 3 Z");
    assert!(
        d[0].starts_with("line 1: TOOL CALL 3: the probe table has 2 row(s)"),
        "{d:?}"
    );
    let d = diags_of("1 TOOL CALL \"TOUCH_PROBE\" B");
    assert!(d[0].contains("probe axis B: expected Z, X or Y"), "{d:?}");
}

#[test]
fn tool_calls_by_name_number_and_axis() {
    let cfg = common::config();
    let p = Program::parse(
        "TOOL CALL 2 X\nTOOL CALL \"TOUCH_PROBE\"\nN30 T1 G18 *",
        &cfg,
    )
    .unwrap();
    let calls: Vec<_> = p
        .blocks
        .iter()
        .filter_map(|b| match &b.statement {
            Statement::ToolCall(t) => Some((t.probe.name.clone(), t.axis, t.line)),
            _ => None,
        })
        .collect();
    assert_eq!(
        calls,
        [
            ("TS 460".to_string(), ProbeAxis::X, 1),
            ("TOUCH_PROBE".to_string(), ProbeAxis::X, 2),
            ("TOUCH_PROBE".to_string(), ProbeAxis::Y, 3)
        ]
    );
}

#[test]
fn iso_form_on_one_line_and_with_continuation() {
    let cfg = common::config();
    let one = "%ISO G71 *\nN10 T\"TOUCH_PROBE\" G17 *\nN20 G444 Q263=+1 Q264=+2 Q294=+3 Q581=+0 Q582=+0 Q583=+1 Q320=+0 Q260=+100 QS400=\"0.4-0.1\" Q309=+1 *\nN30 %ISO G71 *";
    let cont = "N20 G444 Q263=+1 Q264=+2 Q294=+3 ~\n  Q581=+0 Q582=+0 Q583=+1 ~\n  Q260=+100 QS400=\"0.4-0.1\" Q309=+1";
    for (text, block) in [(one.to_string(), 20), (format!("N10 T1 G17\n{cont}"), 20)] {
        let p = Program::parse(&text, &cfg).unwrap_or_else(|e| panic!("{e}"));
        let c = p.cycles().next().unwrap();
        assert_eq!((c.head.cycle, c.head.block), (444, block));
        let CycleKind::Probing3d(q) = &c.kind else {
            panic!()
        };
        assert_eq!(q.nominal, [1.0, 2.0, 3.0]);
        assert_eq!(q.reaction, 1);
    }
}

#[test]
fn inch_programs_are_converted_to_mm() {
    let text = "0 BEGIN PGM IN INCH\n1 TOOL CALL \"TOUCH_PROBE\" Z\n2 TCH PROBE 444 PROBING 3D ~\n\
        Q263=+1 ~\nQ264=-2 ~\nQ294=+0.5 ~\nQ581=+0 ~\nQ582=+0 ~\nQ583=+2 ~\nQ320=+0.1 ~\nQ260=+4 ~\nQS400=\"0.01-0.002\"\n\
        3 G451 Q406=+0 Q407=+0.5 Q253=+100\n4 END PGM IN INCH";
    let p = Program::parse(text, &common::config()).unwrap();
    assert_eq!(p.unit, LengthUnit::Inch);
    let mut cycles = p.cycles();
    let c = cycles.next().unwrap();
    let CycleKind::Probing3d(q) = &c.kind else {
        panic!()
    };
    assert!(
        (q.nominal[0] - 25.4).abs() < 1e-12
            && (q.nominal[1] + 50.8).abs() < 1e-12
            && (q.nominal[2] - 12.7).abs() < 1e-12
    );
    assert_eq!(q.normal, [0.0, 0.0, 1.0], "normal is dimensionless");
    assert!((q.clearance - 2.54).abs() < 1e-12 && (q.safe_height - 101.6).abs() < 1e-12);
    let t = q.tolerance.unwrap();
    assert!((t.upper - 0.254).abs() < 1e-12 && (t.lower + 0.0508).abs() < 1e-12);
    let k = cycles.next().unwrap();
    assert!((k.head.number("Q407").unwrap() - 12.7).abs() < 1e-12);
    assert!(
        (k.head.number("Q253").unwrap() - 254.0).abs() < 1e-9,
        "feed in 1/10 inch/min"
    );
    assert_eq!(k.head.number("Q380"), Some(0.0), "angles are not converted");
}

/// The ranges are mm: an INCH value is held to them after the conversion. Q407 =
/// +99 is a valid radius in mm, but 99 inch is 2514.6 mm, beyond 99.9999. On main
/// before this check the range was applied to the inch number and Q407=+99 passed.
#[test]
fn inch_values_are_range_checked_after_the_conversion_to_mm() {
    let program = |unit: &str, q407: &str| {
        format!(
            "0 BEGIN PGM IN {unit}\n1 TOOL CALL \"TOUCH_PROBE\" Z\n\
             2 G451 Q406=+0 Q407={q407} Q253=+100\n3 END PGM IN {unit}"
        )
    };
    Program::parse(&program("MM", "+99"), &common::config()).unwrap();
    Program::parse(&program("INCH", "+3"), &common::config()).unwrap();
    let e = Program::parse(&program("INCH", "+99"), &common::config())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("line 3")
            && e.contains("Q407")
            && e.contains("out of range 0.0001..99.9999")
            && e.contains("99 in an INCH program is 2514.6 in mm"),
        "{e}"
    );
    // Feeds: Q253 in 1/10 inch/min; 50000 is 127000 mm/min, beyond 99999.9999.
    let e = Program::parse(
        &program("INCH", "+1").replace("Q253=+100", "Q253=+50000"),
        &common::config(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("Q253") && e.contains("out of range"), "{e}");
}

#[test]
fn comments_l_blocks_and_m_functions_are_accepted_and_not_cycles() {
    let text = "0 BEGIN PGM X MM\n* - structure\n1 ; a comment\n2 L Z+100 R0 FMAX M3\n\
        3 M30\n4 m5 M9\n5 END PGM X MM";
    let p = Program::parse(text, &common::config()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(p.cycles().count(), 0);
    let others = p
        .blocks
        .iter()
        .filter(|b| matches!(b.statement, Statement::Other(_)))
        .count();
    assert_eq!(others, 5);
    assert_eq!(p.name.as_deref(), Some("X"));
}

#[test]
fn blocks_that_cannot_run_are_refused_with_their_line() {
    // (FN 0..5, 9..12 and 14 run since issue 27; FN 18 does not.)
    let text = "0 BEGIN PGM X MM\n1 BLK FORM 0.1 Z X+0 Y+0 Z-20\n2 FN 18: SYSREAD Q1 = ID210 NR4\n\
        3 CYCL DEF 200 BOHREN ~\n  Q200=+2 ;SICHERHEITS-ABST. ~\n  Q201=-20\n4 STOP\n5 END PGM X MM";
    let d = check_program(text, &common::config());
    let lines: Vec<usize> = d.iter().map(|d| d.line).collect();
    assert_eq!(lines, [2, 3, 4, 7], "{d:?}");
    assert!(
        d[0].message
            .starts_with("BLK FORM 0.1 Z X+0 Y+0 Z-20: not a block probebridge can run"),
        "{}",
        d[0]
    );
}

/// Issue 13, finding 1: configs/programs/431-plane.h with its cycle or a move
/// mistyped said "ok" and ran without the cycle.
#[test]
fn a_mistyped_block_is_an_error_at_its_line_never_skipped() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/programs/431-plane.h");
    let text = std::fs::read_to_string(path).unwrap();
    let cfg = common::config();
    assert_eq!(check_program(&text, &cfg), vec![]);
    for (from, to, line, hint) in [
        ("6 TCH PROBE 431", "6 TCH PROB 431", 7, "TCH PROBE <number>"),
        ("6 TCH PROBE 431", "6 TCHPROBE 431", 7, "TCH PROBE <number>"),
        ("6 TCH PROBE 431", "6 CYCL DEFF 431", 7, ""),
        (
            "7 L Z+100 R0 FMAX",
            "7 LL Z+100 R0 FMAX",
            20,
            "L X.. Y.. Z..",
        ),
    ] {
        let changed = text.replacen(from, to, 1);
        assert_ne!(changed, text);
        let d = check_program(&changed, &cfg);
        assert_eq!(d.len(), 1, "{to}: {d:?}");
        assert_eq!(d[0].line, line, "{to}: {}", d[0]);
        assert!(
            d[0].message.contains("not a block probebridge can run"),
            "{}",
            d[0]
        );
        assert!(d[0].message.contains(hint), "{}", d[0]);
        assert!(
            Program::parse(&changed, &cfg).is_err(),
            "{to}: run refuses it too"
        );
    }
}

/// A machine whose spindle is vertical (`[cycles] tool_axes` left at Z) refuses a TOOL
/// CALL along X or Y at its line, in both dialects; the cycle after it is not run.
#[test]
fn tool_axis_the_machine_has_no_spindle_for_is_refused() {
    let cfg = probebridge_cycles::CyclesConfig::parse(
        common::CONFIG,
        std::path::Path::new("vertical.toml"),
    )
    .unwrap();
    let d: Vec<String> = check_program(
        "0 BEGIN PGM T MM\n1 TOOL CALL \"TOUCH_PROBE\" X\n2 END PGM T MM",
        &cfg,
    )
    .into_iter()
    .map(|d| d.to_string())
    .collect();
    assert_eq!(
        d,
        ["line 2: TOOL CALL: tool axis X: machine mock has no spindle along X; its [cycles] tool_axes are Z (vertical.toml)"]
    );
    let d: Vec<String> = check_program("N10 T1 G18 *", &cfg)
        .into_iter()
        .map(|d| d.to_string())
        .collect();
    assert_eq!(d.len(), 1, "{d:?}");
    assert!(
        d[0].starts_with("line 1: TOOL CALL: tool axis Y: machine mock has no spindle along Y"),
        "{d:?}"
    );
    // Z, written or not, is the spindle's.
    assert!(check_program("1 TOOL CALL \"TOUCH_PROBE\" Z\n2 TOOL CALL 2", &cfg).is_empty());
}

/// Cycle 460 as the TNC writes it parses into its typed parameters; a value the table
/// allows but the cycle cannot use (Q455 = 1 or 2: a 3D table needs 3 directions a
/// ring) is refused at its line with the parameter's name; `CYCL DEF 460` says how the
/// TNC writes a touch-probe cycle.
#[test]
fn cycle_460_parses_and_its_own_checks_name_the_line() {
    let block = |q455: &str| {
        format!(
            "1 TOOL CALL \"TOUCH_PROBE\" Z\n2 TCH PROBE 460 CALIBRATION OF TS ON A SPHERE ~\n\
  Q407=+12.5 ;RADIUS OF CALIB. SPHERE ~\n  Q320=+0 ;SET-UP CLEARANCE ~\n  Q301=+1 ;MOVE TO CLEARANCE ~\n\
  Q423=+8 ;NO. OF PROBE POINTS ~\n  Q380=+0 ;REFERENCE ANGLE ~\n  Q433=+1 ;CALIBRATE LENGTH ~\n\
  Q434=+80 ;DATUM FOR LENGTH ~\n  Q455={q455} ;NO. OF POINTS IN 3D CAL.\n"
        )
    };
    let p = Program::parse(&block("+8"), &common::config()).unwrap();
    let c = p.cycles().next().unwrap();
    let CycleKind::CalibrateProbe(k) = &c.kind else {
        panic!("{:?}", c.kind)
    };
    assert_eq!(
        (
            k.sphere_radius,
            k.points,
            k.calibrate_length,
            k.length_datum,
            k.points_3d
        ),
        (12.5, 8, true, 80.0, 8)
    );
    let d = diags_of(&block("+2"));
    assert_eq!(d.len(), 1, "{d:?}");
    assert!(
        d[0].starts_with("line 10: Q455=2: a 3D calibration needs at least 3 directions"),
        "{d:?}"
    );
    let d = diags_of(&block("+8").replace("Q407=+12.5", "Q407=+0"));
    assert!(
        d[0].starts_with("line 3: Q407=+0: RADIUS OF CALIB. SPHERE out of range"),
        "{d:?}"
    );
    let d = diags_of("1 TOOL CALL \"TOUCH_PROBE\" Z\n2 CYCL DEF 460 Q407=+12.5");
    assert!(
        d[0].contains("a touch-probe cycle is written TCH PROBE 460 CALIBRATION OF TS ON A SPHERE"),
        "{d:?}"
    );
}
