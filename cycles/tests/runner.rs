//! The program runner: errors end the program, validation failures move nothing, the
//! JSON shape of the report.

mod common;

use common::{MockMachine, Surface};
use hal::ErrorKind;
use nalgebra::Vector3;
use probebridge_cycles::runner::{preflight_program, PreflightKind};
use probebridge_cycles::{check_program, Program, ProgramReport, Status};

fn point(n: u32, x: f64) -> String {
    format!(
        "{n} TCH PROBE 444 PROBING 3D ~\nQ263={x:+} ~\nQ264=+0 ~\nQ294=+10 ~\nQ581=+0 ~\nQ582=+0 ~\nQ583=+1 ~\nQ260=+100\n"
    )
}

fn flat() -> Vec<Surface> {
    vec![Surface::Plane {
        point: Vector3::new(0.0, 0.0, 10.0),
        normal: Vector3::z(),
    }]
}

fn three_points() -> Program {
    let text = format!(
        "1 TOOL CALL \"TOUCH_PROBE\" Z\n{}{}{}",
        point(10, 0.0),
        point(11, 20.0),
        point(12, 40.0)
    );
    Program::parse(&text, &common::config()).unwrap()
}

#[test]
fn every_machine_error_ends_the_program_at_that_cycle() {
    for kind in [
        ErrorKind::NotTriggered,
        ErrorKind::AlreadyDeflected,
        ErrorKind::DriveFault,
        ErrorKind::NodeLost,
        ErrorKind::Timeout,
        ErrorKind::SoftwareLimit,
    ] {
        let mut m = MockMachine::new(flat());
        m.fail_probe = Some((1, kind));
        let (report, _) = common::run(&three_points(), &mut m, &common::temp_dir("run-err"), true);
        assert_eq!(report.cycles.len(), 2, "{kind:?}");
        assert_eq!(report.cycles[0].status, Status::Ok);
        let failed = &report.cycles[1];
        assert_eq!((failed.block, failed.status), (11, Status::Error));
        let msg = failed.message.as_deref().unwrap();
        assert!(
            msg.starts_with("probing the point: ") && msg.contains(kind.describe()),
            "{msg}"
        );
        assert!(failed.q.is_empty());
        assert!(report
            .stopped
            .as_deref()
            .unwrap()
            .starts_with("block 11: cycle 444 failed"));
        assert_eq!(m.probes.len(), 2, "block 12 must not probe");
        assert!(!report.completed());
    }
}

#[test]
fn a_contact_lost_in_transfer_is_probed_again_from_the_start_of_its_move() {
    let mut clean = MockMachine::new(flat());
    let (want, _) = common::run(
        &three_points(),
        &mut clean,
        &common::temp_dir("run-clean"),
        true,
    );
    let mut m = MockMachine::new(flat());
    m.fail_probe = Some((1, ErrorKind::ContactLost));
    let (report, _) = common::run(&three_points(), &mut m, &common::temp_dir("run-lost"), true);
    assert!(report.completed(), "{}", report.to_json());
    for (w, g) in want.cycles.iter().zip(&report.cycles) {
        assert_eq!(w.q, g.q);
    }
    // One probing move more, the same move again, after a move back to its start.
    assert_eq!(m.probes.len(), clean.probes.len() + 1);
    assert_eq!(m.probes[1], m.probes[2]);
    assert_eq!(m.moves.len(), clean.moves.len() + 1);
}

#[test]
fn surface_out_of_reach_is_probe_did_not_trigger() {
    let mut m = MockMachine::new(vec![Surface::Plane {
        point: Vector3::new(0.0, 0.0, -50.0),
        normal: Vector3::z(),
    }]);
    let (report, _) = common::run(&three_points(), &mut m, &common::temp_dir("run-miss"), true);
    assert_eq!(report.cycles.len(), 1);
    assert!(report.cycles[0]
        .message
        .as_deref()
        .unwrap()
        .contains("probe did not trigger"));
}

#[test]
fn nothing_moves_when_validation_fails() {
    let cfg = common::config();
    let bad = format!(
        "1 TOOL CALL \"TOUCH_PROBE\" Z\n{}{}",
        point(10, 0.0),
        point(11, 1e9)
    );
    let m = MockMachine::new(flat());
    assert!(Program::parse(&bad, &cfg).is_err());
    assert!(!check_program(&bad, &cfg).is_empty());
    assert_eq!(m.motion_count(), 0);

    // A cycle the machine cannot run (451 on a machine without rotary axes) stops the
    // program before the first cycle moves anything.
    let text = format!(
        "1 TOOL CALL \"TOUCH_PROBE\" Z\n{}20 G451 Q406=+0 Q407=+12.5\n",
        point(10, 0.0)
    );
    let program = Program::parse(&text, &cfg).unwrap();
    let mut m = MockMachine::new(flat());
    let (report, _) = common::run(&program, &mut m, &common::temp_dir("run-451"), true);
    assert_eq!(m.motion_count(), 0);
    assert_eq!(report.cycles.len(), 1);
    assert_eq!(
        (
            report.cycles[0].block,
            report.cycles[0].cycle,
            report.cycles[0].status
        ),
        (20, 451, Status::Error)
    );

    // The probe vanished from the table between validation and run.
    let program = three_points();
    let mut other = cfg.clone();
    other.probes.retain(|p| p.name != "TOUCH_PROBE");
    let mut m = MockMachine::new(flat());
    let mut confirm = |_: &probebridge_cycles::confirmation::Confirmation| true;
    let mut progress = |_| {};
    let mut opts = probebridge_cycles::RunOptions {
        out_dir: common::temp_dir("run-probe"),
        confirm: &mut confirm,
        progress: &mut progress,
        kinematics: None,
        estimator: None,
    };
    let report = probebridge_cycles::run_program(&program, &mut m, &other, &mut opts);
    assert_eq!(m.motion_count(), 0);
    assert_eq!(report.cycles[0].status, Status::Error);
    let e = preflight_program(
        &program,
        0b111,
        &other,
        &opts.kinematics_path(&other.machine),
    )
    .unwrap_err();
    assert_eq!(e.kind(), PreflightKind::ProbeNotInTable, "{e}");
    assert_eq!(
        report.cycles[0].message.as_deref(),
        Some(e.to_string().split_once(": ").unwrap().1),
        "the report says why"
    );
}

#[test]
fn report_json_has_the_agreed_shape() {
    let mut m = MockMachine::new(flat());
    let (report, _) = common::run(&three_points(), &mut m, &common::temp_dir("run-json"), true);
    assert!(report.completed());
    let v: serde_json::Value = serde_json::from_str(&report.to_json()).unwrap();
    let c = &v["cycles"][0];
    assert_eq!(c["block"], 10);
    assert_eq!(c["cycle"], 444);
    assert_eq!(c["status"], "ok");
    assert!(c["message"].is_null());
    assert!(c["qs"].as_object().unwrap().is_empty());
    assert_eq!(c["q"]["Q183"], -1.0);
    assert_eq!(v["cycles"].as_array().unwrap().len(), 3);
    let back: ProgramReport = serde_json::from_str(&report.to_json()).unwrap();
    assert_eq!(back.cycles, report.cycles);

    let mut one = ProgramReport::default();
    one.cycles.push(probebridge_cycles::CycleResult {
        block: 13,
        cycle: 444,
        q: [("Q151".to_string(), 0.0)].into(),
        qs: Default::default(),
        status: Status::Ok,
        message: None,
        u: Default::default(),
        kinematics: None,
        calibration: None,
        machine_time_s: None,
        machine_time_split_s: None,
    });
    assert_eq!(
        serde_json::to_string(&one).unwrap(),
        r#"{"cycles":[{"block":13,"cycle":444,"q":{"Q151":0.0},"qs":{},"status":"ok","message":null}]}"#
    );
}

#[test]
fn progress_reports_cycles_moves_and_contacts() {
    let program = three_points();
    let mut m = MockMachine::new(flat());
    let mut events = Vec::new();
    let mut confirm = |_: &probebridge_cycles::confirmation::Confirmation| true;
    let mut progress = |e| events.push(e);
    let mut opts = probebridge_cycles::RunOptions {
        out_dir: common::temp_dir("run-progress"),
        confirm: &mut confirm,
        progress: &mut progress,
        kinematics: None,
        estimator: None,
    };
    probebridge_cycles::run_program(&program, &mut m, &common::config(), &mut opts);
    use probebridge_cycles::ProgressEvent as E;
    let started = events
        .iter()
        .filter(|e| matches!(e, E::CycleStarted { .. }))
        .count();
    let contacts = events
        .iter()
        .filter(|e| matches!(e, E::Contact { .. }))
        .count();
    let finished = events
        .iter()
        .filter(|e| {
            matches!(
                e,
                E::CycleFinished {
                    status: Status::Ok,
                    ..
                }
            )
        })
        .count();
    assert_eq!((started, contacts, finished), (3, 3, 3));
}

/// Issue 34: a refusal whose message already says "nothing moved" (cycle 451's plan
/// with a Q253 the axes cannot run) said it twice: `check`'s message and `run`'s report say
/// it once.
#[test]
fn a_refusal_says_nothing_moved_once() {
    let root = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let cfg = probebridge_cycles::CyclesConfig::load(&root.join("configs/machines/table-ac.toml"))
        .unwrap();
    let text = std::fs::read_to_string(root.join("configs/programs/451-check.h")).unwrap();
    let dir = common::temp_dir("run-nothing-moved");
    let kinematics = dir.join("unreadable-kinematics.toml");
    std::fs::write(&kinematics, "not = [a kinematics file").unwrap();
    for (from, to) in [
        // Slower than the slowest feed the axes run (1 mm/min): the plan refuses it.
        ("Q253=+3000", "Q253=+0.25"),
        // A valid plan; the active kinematics file cannot be read.
        ("Q253=+3000", "Q253=+3000"),
    ] {
        let program = Program::parse(&text.replacen(from, to, 1), &cfg).unwrap();
        let e = preflight_program(&program, cfg.machine.axis_mask(), &cfg, &kinematics)
            .unwrap_err()
            .to_string();
        assert_eq!(e.matches("nothing moved").count(), 1, "{e}");
        let mut m = MockMachine::new(flat());
        let mut confirm = |_: &probebridge_cycles::confirmation::Confirmation| true;
        let mut progress = |_| {};
        let mut opts = probebridge_cycles::RunOptions {
            out_dir: dir.clone(),
            confirm: &mut confirm,
            progress: &mut progress,
            kinematics: Some(kinematics.clone()),
            estimator: None,
        };
        let report = probebridge_cycles::run_program(&program, &mut m, &cfg, &mut opts);
        assert_eq!(m.motion_count(), 0);
        let stopped = report.stopped.as_deref().unwrap();
        assert_eq!(stopped.matches("nothing moved").count(), 1, "{stopped}");
        for c in &report.cycles {
            let said = c.message.as_deref().unwrap_or("");
            assert!(said.matches("nothing moved").count() <= 1, "{said}");
        }
    }
}
