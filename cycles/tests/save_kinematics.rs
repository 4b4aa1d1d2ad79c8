//! Cycle 450 SAVE KINEMATICS in a program: save, restore, show and delete the active
//! kinematics file, without moving anything.

mod common;

use probebridge_cycles::kinematics_file::ActiveKinematics;
use probebridge_cycles::{run_program, Program, RunOptions, Status};

fn program_450(mode: u8, designation: u32) -> String {
    format!(
        "0 BEGIN PGM K MM\n1 TOOL CALL \"TOUCH_PROBE\" Z\n2 TCH PROBE 450 SAVE KINEMATICS ~\n  Q410=+{mode} ;MODE ~\n  Q409=+{designation} ;MEMORY DESIGNATION\n3 END PGM K MM\n"
    )
}

/// The table-ac machine: its C axis carries the errors saved and restored here.
fn config() -> probebridge_cycles::CyclesConfig {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/machines/table-ac.toml");
    probebridge_cycles::CyclesConfig::load(&path).unwrap()
}

fn run(text: &str, kin: &std::path::Path) -> (probebridge_cycles::ProgramReport, Vec<String>) {
    let cfg = config();
    let program = Program::parse(text, &cfg).unwrap();
    let mut m = common::MockMachine::new(vec![]);
    let mut notes = Vec::new();
    let mut confirm = |_: &probebridge_cycles::confirmation::Confirmation| true;
    let mut progress = |e: probebridge_cycles::ProgressEvent| {
        if let probebridge_cycles::ProgressEvent::Note { text, .. } = e {
            notes.push(text);
        }
    };
    let mut opts = RunOptions {
        out_dir: kin.parent().unwrap().to_path_buf(),
        confirm: &mut confirm,
        progress: &mut progress,
        kinematics: Some(kin.to_path_buf()),
        estimator: None,
    };
    let report = run_program(&program, &mut m, &cfg, &mut opts);
    assert_eq!(m.motion_count(), 0, "cycle 450 must not move the machine");
    (report, notes)
}

#[test]
fn save_change_restore_delete() {
    let dir = common::temp_dir("450");
    let kin = dir.join("table-ac.kinematics.toml");
    let cfg = config();
    let mut k = ActiveKinematics::load(&kin, &cfg.machine).unwrap();
    k.errors.insert("EX0C".into(), 0.011);
    k.write().unwrap();

    let (r, notes) = run(&program_450(0, 12), &kin);
    assert_eq!(r.cycles[0].status, Status::Ok, "{:?}", r.cycles[0].message);
    assert!(notes[0].contains("saved under 12"), "{notes:?}");

    k.errors.insert("EX0C".into(), 0.2);
    k.write().unwrap();
    let (r, notes) = run(&program_450(2, 12), &kin);
    assert_eq!(r.cycles[0].status, Status::Ok);
    assert!(notes[0].contains("12: EX0C=+0.011000"), "{notes:?}");

    let (r, _) = run(&program_450(1, 12), &kin);
    assert_eq!(r.cycles[0].status, Status::Ok, "{:?}", r.cycles[0].message);
    assert_eq!(
        ActiveKinematics::load(&kin, &cfg.machine)
            .unwrap()
            .error("EX0C"),
        0.011
    );

    let (r, _) = run(&program_450(3, 12), &kin);
    assert_eq!(r.cycles[0].status, Status::Ok);
    let before = std::fs::read(&kin).unwrap();
    let (r, _) = run(&program_450(1, 12), &kin);
    assert_eq!(r.cycles[0].status, Status::Error);
    let msg = r.cycles[0].message.clone().unwrap_or_default();
    assert!(
        msg.contains("nothing is saved under designation 12"),
        "{msg}"
    );
    assert_eq!(
        std::fs::read(&kin).unwrap(),
        before,
        "a failed restore changes nothing"
    );
}

#[test]
fn mode_out_of_range_is_refused_at_validation() {
    let e = Program::parse(&program_450(4, 1), &config())
        .unwrap_err()
        .to_string();
    assert!(e.contains("line 4: Q410=+4") && e.contains("0..3"), "{e}");
}
