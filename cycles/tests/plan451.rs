//! Cycle 451's plan refuses, before anything moves, what the machine cannot do; the
//! error's kind says which check failed.

use probebridge_cycles::cycle451::rotary_m_function::written_params;
use probebridge_cycles::cycle451::{plan, plan_on, KinematicsParams, PlanErrorKind};
use probebridge_cycles::kinematics::Mode;
use probebridge_cycles::program::CycleKind;
use probebridge_cycles::{CyclesConfig, Program};
use std::path::PathBuf;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn table_ac() -> CyclesConfig {
    CyclesConfig::load(&root().join("configs/machines/table-ac.toml")).unwrap()
}

/// configs/programs/451-check.h with `from` replaced by `to`.
fn params(cfg: &CyclesConfig, from: &str, to: &str) -> KinematicsParams {
    let text = std::fs::read_to_string(root().join("configs/programs/451-check.h")).unwrap();
    assert!(text.contains(from), "451-check.h has no {from}");
    let text = text.replacen(from, to, 1);
    let p = Program::parse(&text, cfg).unwrap_or_else(|e| panic!("{e}"));
    let call = p.cycles().next().unwrap();
    let CycleKind::MeasureKinematics(k) = &call.kind else {
        panic!("{:?}", call.kind)
    };
    k.clone()
}

#[test]
fn plan_errors_have_their_kind() {
    let cfg = table_ac();
    let probe = &cfg.probes[0];
    let ok = params(&cfg, "", "");
    let planned = plan(&ok, probe, &cfg.machine).unwrap();
    assert_eq!(planned.measured().len(), 2);
    for (from, to, kind) in [
        ("Q411=-90", "Q411=-150", PlanErrorKind::SoftwareLimit),
        ("Q413=+0", "Q413=+130", PlanErrorKind::SoftwareLimit),
        // Only A, the axis nearest the bed: no machine datum can take up its error.
        ("Q422=+3", "Q422=+0", PlanErrorKind::NoMachineDatum),
    ] {
        let mut p = params(&cfg, from, to);
        if kind == PlanErrorKind::NoMachineDatum {
            // Mode 2 measures A alone; mode 3 cannot.
            p.mode = Mode::PositionAndAngle;
            plan(&p, probe, &cfg.machine).unwrap();
            p.mode = Mode::MachineDatum;
        }
        let e = plan(&p, probe, &cfg.machine).unwrap_err();
        assert_eq!(e.kind(), kind, "{to}: {e}");
    }
    // A rotary axis the machine lacks is not measured: B's points are ignored, and
    // with A and C asking for none there is nothing to measure.
    let mut none = ok.clone();
    none.ranges[0].points = 0;
    none.ranges[2].points = 0;
    none.ranges[1].points = 3;
    assert_eq!(
        plan(&none, probe, &cfg.machine).unwrap_err().kind(),
        PlanErrorKind::NoAxisToMeasure
    );
}

/// `[cycles] mStrobeRotAxPos`: the rotary axes positioned by an M function. The seeds
/// allow no backlash measurement there; the probe cannot follow the sphere (Q408 = 0)
/// while the PLC turns the table. Both refused before anything moves.
#[test]
fn rotary_axes_positioned_by_an_m_function() {
    let mut cfg = table_ac();
    let probe = cfg.probes[0].clone();
    let retracted = params(&cfg, "Q408=+50", "Q408=+30");
    // Not set (-1): as before.
    assert_eq!(plan_on(&retracted, &probe, &cfg).unwrap().rotary_m, None);
    assert!(written_params(&cfg).is_empty());
    cfg.parameters.strobe_rot_ax_pos = 203;
    assert_eq!(cfg.parameters.invalid_field(), None);
    // check knows that 451 then writes Q120 (A) and Q122 (C): table-ac has no B.
    let names: Vec<String> = written_params(&cfg).iter().map(|n| n.to_string()).collect();
    assert_eq!(names, ["Q120", "Q122"]);
    assert_eq!(
        plan_on(&retracted, &probe, &cfg).unwrap().rotary_m,
        Some(203)
    );
    let mut backlash = retracted.clone();
    backlash.backlash = 0.5;
    let e = plan_on(&backlash, &probe, &cfg).unwrap_err();
    assert_eq!(e.kind(), PlanErrorKind::BacklashWithMFunction, "{e}");
    assert!(
        e.to_string()
            .starts_with("Q432=0.5: backlash cannot be measured")
            && e.to_string().contains("mStrobeRotAxPos = 203"),
        "{e}"
    );
    let direct = params(&cfg, "Q408=+50", "Q408=+0");
    assert_eq!(direct.retract_height, 0.0);
    let e = plan_on(&direct, &probe, &cfg).unwrap_err();
    assert_eq!(e.kind(), PlanErrorKind::DirectMoveWithMFunction, "{e}");
    // Without the key, Q432 is measured as before.
    cfg.parameters.strobe_rot_ax_pos = -1;
    plan_on(&backlash, &probe, &cfg).unwrap();
    // Out of range: refused with its key.
    for bad in [-2, 10000] {
        cfg.parameters.strobe_rot_ax_pos = bad;
        let (key, _) = cfg.parameters.invalid_field().unwrap();
        assert_eq!(key, "cycles.mStrobeRotAxPos");
    }
}
