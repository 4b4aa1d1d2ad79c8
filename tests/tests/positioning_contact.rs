//! Cycles 431 and 444 beyond what the block says (issue 34, I1): the part stands higher
//! than R + SET_UP + Q320 over a programmed point, so the probe touches it on the way
//! down to the pre-position. The contact is caught (the axes brake, no move after it)
//! and the message says which move it was (which point, from which height to which
//! pre-position, in the program's coordinates) and what to check (the point's Q
//! parameters, the preset, Q320 and SET_UP), not only the machine's words. Over
//! CANopen (lockstep), each move recorded.

use cycles::program::Program;
use cycles::results::{ProgramReport, Status};
use cycles::runner::{run_program, RunOptions};
use hal::ErrorKind;
use probebridge_tests::conformance::{Backend, CanInproc};
use probebridge_tests::operator_trials::invariants::names_what_to_check;
use probebridge_tests::operator_trials::recorder::{Act, Recorder};
use probebridge_tests::{cycles_config, table_ac_plane};

/// Runs `program` on table-ac over a face at Z+15 (the probe's R 3, SET_UP 2); the
/// report and every move the machine was asked for.
fn run(program: &str, tag: &str) -> (ProgramReport, Vec<Act>) {
    let sc = table_ac_plane(15.0, "");
    let cfg = cycles_config(&sc);
    let program = Program::parse(program, &cfg).unwrap_or_else(|e| panic!("{e}"));
    let mut m = Recorder::new(
        CanInproc::open(&sc),
        hal::motion_guard::MotionGuard::new(&cfg.machine),
    );
    let out = std::env::temp_dir().join(format!("pb-contact-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&out).unwrap();
    let mut confirm = |_: &cycles::confirmation::Confirmation| true;
    let mut progress = |_| {};
    let mut opts = RunOptions {
        out_dir: out.clone(),
        confirm: &mut confirm,
        progress: &mut progress,
        kinematics: None,
        estimator: None,
    };
    let report = run_program(&program, &mut m, &cfg, &mut opts);
    let _ = std::fs::remove_dir_all(&out);
    (report, m.acts)
}

/// The contact is the last move, a positioning move; the cycle failed with `says`.
fn caught_and_named(report: &ProgramReport, acts: &[Act], says: &[&str]) {
    let last = acts.last().expect("moves");
    assert!(
        !last.probing
            && matches!(
                last.failed,
                Some(ErrorKind::ProbeCollision | ErrorKind::AlreadyDeflected)
            ),
        "the last move is not the contact: {last:?}\n{}",
        report.to_text()
    );
    assert_eq!(
        acts.iter().filter(|a| a.failed.is_some()).count(),
        1,
        "{}",
        report.to_text()
    );
    let c = &report.cycles[0];
    assert_eq!(c.status, Status::Error, "{}", report.to_text());
    let why = c.message.clone().unwrap_or_default();
    for s in says {
        assert!(why.contains(s), "no {s:?} in: {why}");
    }
    assert!(names_what_to_check(&why), "{why}");
}

/// 431: point 2 programmed 3 mm under the face (Q295=+12), Q320 = 0: its pre-position
/// Z+17 puts the ball 1 mm into the face. The old message said `approaching point 2:
/// probe deflected during a positioning move: the probe touched while positioning to
/// [60.0, 5.0, ...]` and named nothing to check.
#[test]
fn a_431_contact_on_the_way_to_a_point_names_the_point_q320_and_the_preset() {
    let program = "BEGIN PGM C431 MM\nTOOL CALL \"TOUCH_PROBE\" Z\nL Z+100 R0 FMAX M91\n\
TCH PROBE 431 MEASURE PLANE ~\n  Q263=+0 ~\n  Q264=+0 ~\n  Q294=+15 ~\n  Q265=+60 ~\n  Q266=+5 ~\n  Q295=+12 ~\n\
  Q296=+10 ~\n  Q297=+55 ~\n  Q298=+15 ~\n  Q320=+0 ;SET-UP CLEARANCE ~\n  Q260=+60 ;CLEARANCE HEIGHT ~\n  Q281=+0\n\
END PGM C431 MM\n";
    let (report, acts) = run(program, "431");
    caught_and_named(
        &report,
        &acts,
        &[
            "approaching point 2, down from the clearance height Q260=+60.0000 to its pre-position X+60.0000 Y+5.0000 Z+17.0000, R + SET_UP + Q320 = 5.0000 mm above the programmed point",
            "the part stands higher at point 2 than SET_UP + Q320 = 2.0000 mm above the programmed point: check point 2's coordinates (Q265, Q266, Q295) and the preset against the part, or raise Q320 (SET_UP = 2.0000 mm)",
        ],
    );
    // Point 1 was probed; nothing moved toward point 3.
    assert_eq!(acts.iter().filter(|a| a.probing).count(), 1);
}

/// 444: a point programmed 4 mm under the face (Z+11, normal +Z), Q320 = 0: the
/// pre-position Z+16 puts the ball 2 mm into it.
#[test]
fn a_444_contact_on_the_way_to_the_pre_position_names_the_point_its_normal_and_q320() {
    let program = "BEGIN PGM C444 MM\nTOOL CALL \"TOUCH_PROBE\" Z\nL Z+100 R0 FMAX M91\n\
TCH PROBE 444 PROBING 3D ~\n  Q263=+30 ~\n  Q264=+20 ~\n  Q294=+11 ~\n  Q581=+0 ~\n  Q582=+0 ~\n  Q583=+1 ~\n\
  Q320=+0 ~\n  Q260=+60 ~\n  QS400=\" \" ~\n  Q309=+0\nEND PGM C444 MM\n";
    let (report, acts) = run(program, "444");
    caught_and_named(
        &report,
        &acts,
        &[
            "moving to the pre-position, down from the clearance height Q260=+60.0000 to X+30.0000 Y+20.0000 Z+16.0000, R + SET_UP + Q320 = 5.0000 mm from the programmed point along its normal",
            "the surface stands more than SET_UP + Q320 = 2.0000 mm beyond the programmed point along its normal",
            "check the point (Q263, Q264, Q294), its normal (Q581, Q582, Q583) and the preset against the part, or raise Q320 (SET_UP = 2.0000 mm)",
        ],
    );
    assert_eq!(acts.iter().filter(|a| a.probing).count(), 0);
}
