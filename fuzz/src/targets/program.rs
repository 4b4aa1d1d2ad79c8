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
            seeds: || corpus::with(corpus::files(&corpus::configs("programs"), ".h"), &[STRINGS]),
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
