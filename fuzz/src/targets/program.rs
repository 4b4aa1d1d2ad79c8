//! NC programs as `probebridge check` takes them, and the QS400 tolerance grammar.

use super::text;
use crate::corpus;
use crate::driver::Target;
use crate::sig::Sig;
use cycles::kinematics_file::ActiveKinematics;
use cycles::tolerance::{Tolerance, WorkpieceStatus};
use cycles::CyclesConfig;
use probebridge::commands::check::check_text;
use std::path::PathBuf;
use std::sync::OnceLock;

pub fn targets() -> Vec<Target> {
    vec![
        Target {
            name: "check",
            about: "NC program text through `probebridge check` (parser, Q-parameter programming, BEGIN/END PGM, preflight of every cycle and L block on every path) on two machines",
            max_len: 16 * 1024,
            prepare: || {
                machines();
            },
            seeds: || {
                corpus::with(
                    corpus::files(&corpus::configs("programs"), ".h"),
                    &[STRINGS, FLOW],
                )
            },
            dictionary: &[
                "TCH PROBE", "CYCL DEF", "BEGIN PGM", "END PGM", "TOOL CALL", "FMAX", "FAUTO",
                "MM", "INCH", "L ", "~\n", ";", " ~", "QS400=", "Q", "R0", "M99", "IX", "IY",
                "IZ", "X+", "Y-", "Z+", "A+", "B-", "C+", "PREDEF", "\"", "\r\n", "\u{feff}",
                "431", "444", "450", "451", "1e308", "nan", "-0",
                // Q-parameter programming (issue 27).
                "Q1 = ", "QL0 = ", "QR1 = ", "QS1 = \"", " + ", " - ", " * ", " / ", " ^ ",
                "( ", " )", "SQ ", "SQRT ", "SIN ", "COS ", "TAN ", "ASIN ", "ACOS ", "ATAN ",
                "ABS ", "INT ", "FRAC ", "SGN ", "PI", "FN 0: ", "FN 4: Q1 = +1 / +0",
                "FN 5: Q1 = SQRT -1", "FN 9: IF +Q1 EQU +0 GOTO LBL 1", "FN 10: IF ",
                "FN 11: IF +Q141 GT +0.01 GOTO LBL \"END\"", "FN 12: IF ", " GOTO LBL ",
                "LBL 1", "LBL 0", "LBL \"", "CALL LBL 1 REP 3", "FN 14: ERROR = 1001",
                "FN 16: F-PRINT", " || ", "SUBSTR ( SRC_QS146 BEG0 LEN10 )",
                "TONUMB ( SRC_QS0 )", "TOCHAR ( DAT+Q1 DECIMALS3 )", "STRLEN ( SRC_QS1 )",
                "X+Q1", "Y-QL2", "FQ3", "M30", "DECLARE STRING ", "STRING FORMULA ",
                // String comparison and string cycle values.
                "STRCOMP ( SRC_QS1 SEA_QS2 )", "INSTR ( SRC_QS1 SEA_QS2 BEG0 )", "SEA_QS",
                "SRC_QS", " BEG", "QS400=QS1", "FN 9: IF QS1 EQU QS2 GOTO LBL 1",
                // Every FN of 0..16 (6..8, 13, 15 and 16 are refused at their line), the
                // bare words the mutator can recombine, the program's mode and M91/M92.
                "FN 1: Q1 = +Q2 + +3", "FN 2: Q1 = +Q2 - +3", "FN 3: Q1 = +Q2 * +3",
                "FN 6: Q1 = SIN +30", "FN 7: Q1 = COS +30", "FN 8: Q1 = +3 LEN +4",
                "FN 13: Q1 = +3 ANG +4", "FN 15: PRINT Q1", "FN 16: F-PRINT TNC:\\M.A / TNC:\\O.TXT",
                "FN ", "FN 99: ", "QS", "QL", "QR", "QR0 = QR0 + 1", "SUBSTR", "TONUMB", "TOCHAR",
                "STRLEN", "STRCOMP", "INSTR", "DAT+", "DECIMALS", "LEN", "BEG", "EQU", "NE", "GT",
                "LT", "GOTO", "LBL", "CALL LBL", " REP ", "CALL LBL \"SUB\" REP 2", "LBL \"SUB\"",
                "FUNCTION MODE MILL", "FUNCTION MODE TURN", "FUNCTION ", "M91", "M92", "L Z+Q20 R0 FMAX M91",
            ],
            run: run_check,
        },
        Target {
            name: "tolerance",
            about: "the QS400 tolerance grammar, and the status of deviations against it",
            max_len: 256,
            prepare: || {},
            seeds: || {
                corpus::with(
                    Vec::new(),
                    &[
                        "", "0.1", "-0.05+0.1", "+0.2-0.2", "0.01 - 0.02", "1e-3+1e-3", "+-1",
                        "0.1+", "-", ".5-.5", "0,1", "1e308-1e308", "nan", "inf",
                    ],
                )
            },
            dictionary: &["+", "-", ".", "e", "E", " ", "0", "9", "inf", "nan", ","],
            run: run_tolerance,
        },
    ]
}

/// A seed with the string functions, string comparison and a QS parameter as a
/// cycle's string value.
const STRINGS: &str = "0 BEGIN PGM STRINGS MM
1 TOOL CALL \"TOUCH_PROBE\" Z
2 QS1 = \"0.4-0.1\"
3 QS2 = \"0.4-0.1\"
4 Q1 = STRCOMP ( SRC_QS1 SEA_QS2 )
5 Q2 = INSTR ( SRC_QS1 SEA_QS2 BEG0 ) + STRLEN ( SRC_QS1 )
6 FN 10: IF +Q1 NE +0 GOTO LBL 9
7 L Z+100 R0 FMAX
8 TCH PROBE 444 PROBING 3D ~
  Q263=+0 ~
  Q264=+0 ~
  Q294=+0 ~
  Q581=+0 ~
  Q582=+0 ~
  Q583=+1 ~
  Q320=+1 ~
  Q260=+100 ~
  QS400=QS1 ~
  Q309=+0
9 LBL 9
10 END PGM STRINGS MM
";

/// A seed with every kind of Q-parameter block: QL/QR/QS, FN 0..5 and the formulas,
/// each jump, a subprogram with REP, TOCHAR/SUBSTR/TONUMB, M91 and FUNCTION MODE, FN 14.
const FLOW: &str = "0 BEGIN PGM FLOW MM
1 FUNCTION MODE MILL
2 TOOL CALL \"TOUCH_PROBE\" Z
3 FN 0: Q1 = +5
4 FN 1: Q2 = +Q1 + +2.5
5 FN 2: Q3 = +Q2 - +1
6 FN 3: Q4 = +Q3 * -2
7 FN 4: Q5 = +Q4 / +4
8 FN 5: Q6 = SQRT +16
9 QL1 = ( Q1 + Q2 ) / 2 + SQ 3 - ABS -1 + INT 2.7 + FRAC 1.25 + SGN -4 + PI
10 QR1 = 2
11 QR1 = QR1 + 1
12 QS1 = TOCHAR ( DAT+QL1 DECIMALS3 ) || \";\"
13 QS2 = SUBSTR ( SRC_QS1 BEG0 LEN2 )
14 Q7 = TONUMB ( SRC_QS2 ) + STRLEN ( SRC_QS1 )
15 Q8 = 0
16 CALL LBL \"SUB\" REP 2
17 FN 9: IF +Q1 EQU +5 GOTO LBL 2
18 FN 14: ERROR = 1000
19 LBL 2
20 FN 10: IF +Q1 NE +5 GOTO LBL 2
21 FN 12: IF +Q2 LT +0 GOTO LBL 2
22 FN 11: IF +Q7 GT +1000 GOTO LBL 99
23 Q9 = Q6 * 250
24 L Z+150 R0 FMAX M91
25 L X+Q1 Y-Q2 R0 FQ9
26 M30
27 LBL \"SUB\"
28 Q8 = Q8 + SIN 30 + COS 60 + TAN 45 + ASIN 0.5 + ACOS 0.5 + ATAN 1
29 LBL 0
30 LBL 99
31 FN 14: ERROR = 1001
32 END PGM FLOW MM
";

struct Machine {
    cfg: CyclesConfig,
    kinematics: PathBuf,
}

fn machines() -> &'static [Machine] {
    static M: OnceLock<Vec<Machine>> = OnceLock::new();
    M.get_or_init(|| {
        ["table-ac.toml", "head-b-table-c.toml"]
            .iter()
            .map(|name| {
                let path = corpus::configs("machines").join(name);
                let mut cfg = CyclesConfig::load(&path)
                    .unwrap_or_else(|e| panic!("fuzz target check: {}: {e}", path.display()));
                // A mutated loop ends after this many jumps, so that one input stays
                // well under the driver's second (the default is 100000).
                cfg.parameters.max_jumps = 1000;
                // A file that is not there: the nominal kinematics, nothing read.
                let kinematics = ActiveKinematics::default_path(&cfg.machine)
                    .with_file_name("probebridge-fuzz-absent.kinematics.toml");
                Machine { cfg, kinematics }
            })
            .collect()
    })
}

fn run_check(data: &[u8]) -> Sig {
    let program = text(data);
    let mut sig = Sig::default();
    for m in machines() {
        let errors = check_text(&program, &m.cfg, &m.kinematics);
        if errors.is_empty() {
            super::accepted_finite(&cycles::parse_program(&program, &m.cfg), "program");
        }
        sig.value(errors.len().min(3) as u64);
        for e in errors.iter().take(8) {
            sig.message(e);
        }
    }
    sig
}

fn run_tolerance(data: &[u8]) -> Sig {
    let mut sig = Sig::default();
    let qs400 = text(data);
    match Tolerance::parse(&qs400) {
        Ok(None) => sig.text("none"),
        Ok(Some(t)) => {
            // A tolerance is a band of finite limits, upper above lower.
            assert!(
                t.upper.is_finite() && t.lower.is_finite() && t.upper > t.lower,
                "QS400 {qs400:?} gave the tolerance {t:?}"
            );
            let scaled = t.scaled(25.4);
            let status = WorkpieceStatus::of(Some(&scaled), 0.0);
            let _ = (status.q183(), status.colour(), status.to_string());
            sig.text("some").debug(&status)
        }
        // The message repeats the text unquoted: the kind is the outcome.
        Err(e) => sig.debug(&e.kind()),
    };
    sig
}
