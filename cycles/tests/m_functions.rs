//! M functions and FUNCTION blocks as the TNC means them: M91 puts a block's
//! coordinates in the machine coordinate system (in `run` and in the preflight `check`
//! runs), M92 needs the machine's reference point, M functions that change what a
//! move means are refused at their line by name, the harmless ones are accepted;
//! `FUNCTION MODE MILL` runs, and after `FUNCTION MODE TURN` the probe cycles are
//! refused.

mod common;

use common::MockMachine;
use probebridge_cycles::linear::LinearBlockErrorKind;
use probebridge_cycles::preset_table::Preset;
use probebridge_cycles::runner::{preflight_program, PreflightKind};
use probebridge_cycles::{check_program, CyclesConfig, Program};

/// The mock machine with preset row `n` at `xyz` as well as row 0.
fn config_with_row(n: u32, xyz: [f64; 3]) -> CyclesConfig {
    let mut cfg = common::config();
    let mut row = Preset::origin(n);
    [row.x, row.y, row.z] = xyz;
    cfg.presets.rows.push(row);
    cfg
}

fn moves(cfg: &CyclesConfig, text: &str, name: &str) -> Vec<[f64; 3]> {
    let program = Program::parse(text, cfg).unwrap_or_else(|e| panic!("{e}\n{text}"));
    let mut m = MockMachine::new(vec![]);
    let mut confirm = |_: &probebridge_cycles::confirmation::Confirmation| true;
    let mut progress = |_| {};
    let mut opts = probebridge_cycles::RunOptions {
        out_dir: common::temp_dir(name),
        confirm: &mut confirm,
        progress: &mut progress,
        kinematics: None,
        estimator: None,
    };
    let report = probebridge_cycles::run_program(&program, &mut m, cfg, &mut opts);
    assert!(report.completed(), "{report:?}");
    m.moves.iter().map(|(p, _)| *p).collect()
}

/// With a preset row active (and a datum shift on top), an `L` block with M91 goes to
/// the machine coordinates it names; the same block without M91 goes through the
/// datum. Several rows and shifts, not one value.
#[test]
fn m91_blocks_are_machine_coordinates_whatever_preset_is_active() {
    for (n, row, shift) in [
        (1, [50.0, -30.0, 80.0], [0.0, 0.0, 0.0]),
        (4, [-12.5, 7.25, -40.0], [3.0, -2.0, 1.5]),
        (17, [0.0, 0.0, 95.0], [-20.0, 0.0, 0.0]),
    ] {
        let cfg = config_with_row(n, row);
        let text = format!(
            "0 BEGIN PGM M MM\n1 TOOL CALL \"TOUCH_PROBE\" Z\n2 CYCL DEF 247 DATUM SETTING ~\n  Q339=+{n}\n3 TRANS DATUM AXIS X{:+} Y{:+} Z{:+}\n4 L Z+120 R0 FMAX M91\n5 L X+10 Y-20 R0 FMAX M91\n6 L X+10 Y-20 Z+5 R0 FMAX\n7 L Z+110 R0 FMAX M91 M9\n8 END PGM M MM\n",
            shift[0], shift[1], shift[2]
        );
        let got = moves(&cfg, &text, &format!("m91-{n}"));
        let o = [0, 1, 2].map(|i| row[i] + shift[i]);
        assert_eq!(
            got,
            vec![
                [0.0, 0.0, 120.0],
                [10.0, -20.0, 120.0],
                [10.0 + o[0], -20.0 + o[1], 5.0 + o[2]],
                [10.0 + o[0], -20.0 + o[1], 110.0],
            ],
            "row {n} at {row:?}, shift {shift:?}"
        );
    }
}

/// The preflight (what `check` runs) checks M91 targets in machine coordinates too: a
/// block inside the limits as machine coordinates passes with a preset far away, and
/// the same block through the datum is refused at its line.
#[test]
fn check_takes_m91_targets_as_machine_coordinates() {
    let cfg = config_with_row(2, [0.0, 0.0, 400.0]);
    let z_max = cfg
        .machine
        .axes
        .iter()
        .find(|a| a.name == hal::Axis::Z)
        .unwrap()
        .max;
    let z = z_max - 10.0;
    let head = "0 BEGIN PGM M MM\n1 TOOL CALL \"TOUCH_PROBE\" Z\n2 CYCL DEF 247 DATUM SETTING ~\n  Q339=+2\n";
    let kin = common::temp_dir("m91-check").join("k.toml");
    let ok = format!("{head}3 L Z{z:+} R0 FMAX M91\n4 END PGM M MM\n");
    let p = Program::parse(&ok, &cfg).unwrap();
    preflight_program(&p, 0b111, &cfg, &kin).unwrap();
    let bad = format!("{head}3 L Z{z:+} R0 FMAX\n4 END PGM M MM\n");
    let p = Program::parse(&bad, &cfg).unwrap();
    let e = preflight_program(&p, 0b111, &cfg, &kin).unwrap_err();
    assert_eq!(
        e.kind(),
        PreflightKind::Positioning(LinearBlockErrorKind::SoftwareLimit),
        "{e}"
    );
    assert!(e.to_string().starts_with("line 5:"), "{e}");
}

/// M92 is refused without `[cycles] m92_reference`; with it, the block's X/Y/Z are
/// relative to that point, whatever preset is active.
#[test]
fn m92_needs_the_machines_reference_point() {
    let text = "0 BEGIN PGM M MM\n1 TOOL CALL \"TOUCH_PROBE\" Z\n2 CYCL DEF 247 DATUM SETTING ~\n  Q339=+1\n3 L X+0 Y+0 Z+0 R0 FMAX M92\n4 END PGM M MM\n";
    let mut cfg = config_with_row(1, [5.0, 6.0, 7.0]);
    let errors = check_program(text, &cfg);
    assert_eq!(errors.len(), 1, "{errors:?}");
    assert_eq!(errors[0].line, 5);
    assert!(errors[0].message.contains("M92") && errors[0].message.contains("m92_reference"));
    cfg.parameters.m92_reference = Some([-30.0, 40.0, 150.0]);
    assert_eq!(moves(&cfg, text, "m92"), vec![[-30.0, 40.0, 150.0]]);
}

/// An M function that changes what a move means, or one not known at all, is refused
/// at its line with its name, in an `L` block or alone; nothing is skipped.
#[test]
fn m_functions_that_change_a_move_are_refused_at_their_line() {
    let cfg = common::config();
    for (block, name) in [
        ("L Z+100 R0 FMAX M128", "M128"),
        ("M126", "M126"),
        ("L C+90 FMAX M118", "M118"),
        ("M120", "M120"),
        ("L Z+100 M140", "M140"),
        ("M99", "M99"),
        ("M141", "M141"),
        ("M3 M77", "M77"),
    ] {
        let text = format!(
            "0 BEGIN PGM M MM\n1 TOOL CALL \"TOUCH_PROBE\" Z\n2 L Z+100 R0 FMAX\n3 {block}\n4 END PGM M MM\n"
        );
        let errors = check_program(&text, &cfg);
        assert_eq!(errors.len(), 1, "{block}: {errors:?}");
        assert_eq!(errors[0].line, 4, "{block}");
        assert!(
            errors[0].message.starts_with(name) && errors[0].message.contains("refused"),
            "{block}: {}",
            errors[0].message
        );
        assert!(Program::parse(&text, &cfg).is_err(), "run refuses it too");
    }
    // The harmless ones stay accepted, alone and in L blocks.
    let text = "0 BEGIN PGM M MM\n1 TOOL CALL \"TOUCH_PROBE\" Z\n2 M5 M9\n3 L Z+100 R0 FMAX M3 M8\n4 M0\n5 M1\n6 M129 M127\n7 M4\n8 M2\n9 M30\n10 END PGM M MM\n";
    assert_eq!(check_program(text, &cfg), vec![]);
    assert_eq!(moves(&cfg, text, "m-harmless"), vec![[0.0, 0.0, 100.0]]);
}

/// `FUNCTION MODE MILL` is accepted; after `FUNCTION MODE TURN` cycles 431, 444 and
/// 451 are refused at their line until `FUNCTION MODE MILL` comes back; `FUNCTION
/// TCPM` is refused by name.
#[test]
fn function_mode_mill_runs_and_turn_refuses_the_probe_cycles() {
    let cfg = common::config();
    let cycle444 = "TCH PROBE 444 PROBING 3D ~\n  Q263=+0 ~\n  Q264=+0 ~\n  Q294=+10 ~\n  Q581=+0 ~\n  Q582=+0 ~\n  Q583=+1 ~\n  Q260=+100\n";
    let cycle431 = "TCH PROBE 431 MEASURE PLANE ~\n  Q263=+0 ~\n  Q264=+0 ~\n  Q294=+13 ~\n  Q265=+50 ~\n  Q266=+0 ~\n  Q295=+15.7 ~\n  Q296=+0 ~\n  Q297=+50 ~\n  Q298=+17.5 ~\n  Q320=+0 ~\n  Q260=+50 ~\n  Q281=+0\n";
    let cycle451 = "TCH PROBE 451 MEASURE KINEMATICS ~\n  Q406=+0 ~\n  Q407=+12.5\n";
    let ok = format!(
        "0 BEGIN PGM F MM\n1 FUNCTION MODE MILL\n2 TOOL CALL \"TOUCH_PROBE\" Z\n3 {cycle444}4 END PGM F MM\n"
    );
    assert_eq!(check_program(&ok, &cfg), vec![]);
    for (number, cycle) in [(444, cycle444), (431, cycle431), (451, cycle451)] {
        let turn = format!(
            "0 BEGIN PGM F MM\n1 FUNCTION MODE TURN\n2 TOOL CALL \"TOUCH_PROBE\" Z\n3 {cycle}4 END PGM F MM\n"
        );
        let errors = check_program(&turn, &cfg);
        assert_eq!(errors.len(), 1, "{number}: {errors:?}");
        assert_eq!(errors[0].line, 4);
        assert!(
            errors[0].message.contains(&format!("cycle {number}"))
                && errors[0].message.contains("FUNCTION MODE TURN (line 2)"),
            "{}",
            errors[0].message
        );
        let back = format!(
            "0 BEGIN PGM F MM\n1 FUNCTION MODE TURN\n2 FUNCTION MODE MILL\n3 TOOL CALL \"TOUCH_PROBE\" Z\n4 {cycle}5 END PGM F MM\n"
        );
        assert_eq!(
            check_program(&back, &cfg),
            vec![],
            "{number} after MILL again"
        );
    }
    let tcpm = "0 BEGIN PGM F MM\n1 FUNCTION TCPM F TCP AXIS POS PATHCTRL AXIS\n2 END PGM F MM\n";
    let errors = check_program(tcpm, &cfg);
    assert_eq!(errors.len(), 1, "{errors:?}");
    assert_eq!(errors[0].line, 2);
    assert!(
        errors[0].message.contains("FUNCTION TCPM"),
        "{}",
        errors[0].message
    );
}
