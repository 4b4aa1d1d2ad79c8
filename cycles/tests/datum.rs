//! The datum of a program: cycle 247 activates a row of the preset table, cycle 7,
//! TRANS DATUM and ISO G54 shift it, TRANS DATUM RESET undoes the shift; `L` blocks
//! and cycle 431's points and results are relative to preset plus shift. Unknown
//! preset numbers and malformed blocks are refused with their line.

mod common;

use common::{MockMachine, Surface};
use nalgebra::Vector3;
use probebridge_cycles::datum::DatumBlock;
use probebridge_cycles::preset_table::Preset;
use probebridge_cycles::program::Statement;
use probebridge_cycles::{CyclesConfig, Program, Status};

/// The mock machine with rows 0 (origin) and 3 (X+100 Y-50 Z+20).
fn config() -> CyclesConfig {
    let mut cfg = common::config();
    let mut row = Preset::origin(3);
    [row.x, row.y, row.z] = [100.0, -50.0, 20.0];
    cfg.presets.rows.push(row);
    cfg
}

fn datum_blocks(text: &str) -> Vec<DatumBlock> {
    let p = Program::parse(text, &config()).unwrap_or_else(|e| panic!("{e}\n{text}"));
    p.blocks
        .iter()
        .filter_map(|b| match &b.statement {
            Statement::Datum(d) => Some(*d),
            _ => None,
        })
        .collect()
}

#[test]
fn every_form_parses() {
    let text = "0 BEGIN PGM D MM\n\
1 CYCL DEF 247 DATUM SETTING ~\n  Q339=+3 ;DATUM NUMBER\n\
2 CYCL DEF 7.0 DATUM SHIFT\n3 CYCL DEF 7.1 X+10\n4 CYCL DEF 7.2 Y-5.5\n5 CYCL DEF 7.3 Z+0\n\
6 TRANS DATUM AXIS X+1 Z+2\n7 TRANS DATUM RESET\n8 END PGM D MM\n";
    assert_eq!(
        datum_blocks(text),
        vec![
            DatumBlock::Preset(3),
            DatumBlock::Shift([0.0; 3]),
            DatumBlock::ShiftAxis(0, 10.0),
            DatumBlock::ShiftAxis(1, -5.5),
            DatumBlock::ShiftAxis(2, 0.0),
            DatumBlock::Shift([1.0, 0.0, 2.0]),
            DatumBlock::Reset,
        ]
    );
    let iso = "%D G71 *\nN10 G247 Q339=+0 *\nN20 G54 X+10 Y+2 Z-1 *\n%D G71 *\n";
    assert_eq!(
        datum_blocks(iso),
        vec![DatumBlock::Preset(0), DatumBlock::Shift([10.0, 2.0, -1.0])]
    );
    let inch = "0 BEGIN PGM D INCH\n1 TRANS DATUM AXIS X+1\n2 END PGM D INCH\n";
    assert_eq!(
        datum_blocks(inch),
        vec![DatumBlock::Shift([25.4, 0.0, 0.0])]
    );
}

#[test]
fn errors_name_the_line_and_what_is_allowed() {
    let cfg = config();
    for (text, line, want) in [
        (
            "1 CYCL DEF 247 DATUM SETTING ~\n  Q339=+7\n",
            2,
            "preset 7 is not in the preset table",
        ),
        ("N10 G247 Q339=+9 *\n", 1, "(allowed: 0, 3)"),
        (
            "1 CYCL DEF 247 DATUM SETTING\n",
            1,
            "missing required parameter Q339",
        ),
        (
            "1 CYCL DEF 247 DATUM SETTING ~\n  Q339=+1.5\n",
            2,
            "0..65535",
        ),
        (
            "1 CYCL DEF 247 DATUM SETTING ~\n  Q338=+1\n",
            2,
            "allowed: Q339",
        ),
        ("1 CYCL DEF 7.1 X+10\n", 1, "must follow CYCL DEF 7.0"),
        (
            "1 CYCL DEF 7.0 DATUM SHIFT\n2 CYCL DEF 7.1 #5\n",
            2,
            "only absolute X, Y and Z",
        ),
        (
            "1 CYCL DEF 7.0 DATUM SHIFT\n2 CYCL DEF 7.1 X+1 Y+2\n",
            2,
            "one axis",
        ),
        ("1 TRANS DATUM AXIS X+1 X+2\n", 1, "X given twice"),
        ("1 TRANS DATUM TABLE TABLINE 5\n", 1, "TRANS DATUM RESET"),
        ("1 TRANS DATUM AXIS A+5\n", 1, "only absolute X, Y and Z"),
        ("1 CYCL DEF 200 DRILLING\n", 1, "CYCL DEF 247 DATUM SETTING"),
    ] {
        let e = Program::parse(text, &cfg).unwrap_err();
        let d = e.0.iter().find(|d| d.message.contains(want));
        assert!(
            d.is_some_and(|d| d.line == line),
            "{text:?}: want line {line} \"{want}\", got {e}"
        );
    }
    // The preset table's numbers are in the message.
    let e = Program::parse("1 CYCL DEF 247 DATUM SETTING ~\n  Q339=+7\n", &cfg).unwrap_err();
    assert!(e.to_string().contains("(allowed: 0, 3)"), "{e}");
}

#[test]
fn l_blocks_and_431_are_relative_to_preset_plus_shift() {
    let cfg = config();
    let text = "0 BEGIN PGM D MM\n1 TOOL CALL \"TOUCH_PROBE\" Z\n\
2 CYCL DEF 247 DATUM SETTING ~\n  Q339=+3\n3 L X+0 Y+0 Z+80 R0 FMAX\n\
4 TRANS DATUM AXIS X+10 Y+20\n5 L X+0 Y+0 R0 FMAX\n\
6 CYCL DEF 7.0 DATUM SHIFT\n7 CYCL DEF 7.1 Z+5\n8 L Z+0 R0 FMAX\n\
9 TRANS DATUM RESET\n10 L X+1 FMAX\n\
11 TCH PROBE 431 MEASURE PLANE ~\n Q263=+0 ~\n Q264=+0 ~\n Q294=+0 ~\n Q265=+40 ~\n Q266=+0 ~\n Q295=+0 ~\n\
 Q296=+0 ~\n Q297=+30 ~\n Q298=+0 ~\n Q320=+0 ~\n Q260=+50 ~\n Q281=+0\n12 END PGM D MM\n";
    let program = Program::parse(text, &cfg).unwrap_or_else(|e| panic!("{e}"));
    // The plane lies 2 mm above the datum's Z (machine Z 22).
    let mut m = MockMachine::new(vec![Surface::Plane {
        point: Vector3::new(0.0, 0.0, 22.0),
        normal: Vector3::z(),
    }]);
    let (report, _) = common::run_on(&cfg, &program, &mut m, &common::temp_dir("datum"), true);
    assert!(report.completed(), "{report:?}");
    let targets: Vec<[f64; 3]> = m.moves.iter().map(|(p, _)| *p).take(4).collect();
    assert_eq!(
        targets,
        vec![
            [100.0, -50.0, 100.0],
            [110.0, -30.0, 100.0],
            [110.0, -30.0, 25.0],
            [101.0, -30.0, 25.0],
        ]
    );
    // 431: safe height Q260 = 50 above the datum, the points over datum + nominal.
    assert_eq!(m.moves[4].0[2], 70.0);
    assert_eq!((m.moves[5].0[0], m.moves[5].0[1]), (100.0, -50.0));
    let c = &report.cycles[0];
    assert_eq!(c.status, Status::Ok, "{:?}", c.message);
    for q in ["Q173", "Q174", "Q175"] {
        assert!((c.q[q] - 2.0).abs() < 1e-9, "{q} = {}", c.q[q]);
    }
}
