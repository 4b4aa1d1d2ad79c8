//! `L` positioning blocks run in program order between the cycles; one the runner
//! cannot execute is refused before anything moves.

mod common;

use common::MockMachine;
use probebridge_cycles::linear::LinearBlockErrorKind;
use probebridge_cycles::runner::{preflight_program, Preflight, PreflightKind};
use probebridge_cycles::Program;

#[test]
fn l_blocks_move_in_program_order() {
    let cfg = common::config();
    let text = "0 BEGIN PGM L MM\n1 TOOL CALL \"TOUCH_PROBE\" Z\n2 L Z+100 R0 FMAX\n3 L X+10 Y-20 F500\n4 L Z+40 M3\n5 END PGM L MM\n";
    let program = Program::parse(text, &cfg).unwrap();
    let mut m = MockMachine::new(vec![]);
    let (report, _) = common::run(&program, &mut m, &common::temp_dir("l-blocks"), true);
    assert!(report.completed(), "{report:?}");
    let targets: Vec<[f64; 3]> = m.moves.iter().map(|(p, _)| *p).collect();
    assert_eq!(
        targets,
        vec![[0.0, 0.0, 100.0], [10.0, -20.0, 100.0], [10.0, -20.0, 40.0]]
    );
    assert_eq!(m.moves[1].1, 500.0);
    // Rapid: the fastest axis feed of the machine.
    assert_eq!(m.moves[0].1, 10000.0);
}

#[test]
fn an_l_block_that_cannot_run_is_refused_before_anything_moves() {
    let cfg = common::config();
    let text = "1 TOOL CALL \"TOUCH_PROBE\" Z\n2 L Z+100 R0 FMAX\n3 L IX+10 FMAX\n";
    let program = Program::parse(text, &cfg).unwrap();
    let mut m = MockMachine::new(vec![]);
    let (report, _) = common::run(&program, &mut m, &common::temp_dir("l-bad"), true);
    assert_eq!(m.motion_count(), 0);
    let e = preflight_program(
        &program,
        0b111,
        &cfg,
        &common::temp_dir("l-bad").join("k.toml"),
    )
    .unwrap_err();
    assert_eq!(
        e.kind(),
        PreflightKind::Positioning(LinearBlockErrorKind::UnsupportedWord)
    );
    assert!(matches!(e, Preflight::Positioning { line: 3, .. }), "{e}");
    assert_eq!(report.stopped.unwrap(), format!("{e}; nothing moved"));
}
