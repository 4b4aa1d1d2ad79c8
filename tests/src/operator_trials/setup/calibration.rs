//! Cycle 460's case: the start over the sphere, the block, the stylus's truth; and the
//! 460 that calibrates the probe before a 431 or 444.

use super::*;

pub(super) fn cycle460(
    case: &Case,
    s: &mut Setup,
    ms: &MachineSpec,
    clear: f64,
    dist: f64,
    centre: Vector3<f64>,
) -> (Vec<String>, Truth) {
    let t = ms.tool;
    let inch = case.inch == 1.0;
    let rs = SPHERE + BALL;
    let reach = cycles::cycle460::measure::START_REACH * rs;
    let typed = SPHERE * (1.0 + case.q407_err);
    let tol = s.cfg.parameters.max_dev_cal_ball;
    if (typed - SPHERE).abs() > tol {
        s.beyond.push(format!(
            "Q407 {:.4} mm off the sphere's radius",
            typed - SPHERE
        ));
    }
    if case.off > 1.0 {
        s.beyond
            .push(format!("start {:.3} x the reach off the centre", case.off));
    }
    if case.rise > 1.0 {
        s.beyond.push(format!(
            "start {:.3} mm above the pole",
            clear + case.rise * dist
        ));
    }
    let rot = left_rotary(case, ms);
    let cc = to_cycle(t, sphere_at(&s.sc, &rot, centre));
    let start = start_over(
        cc,
        rs,
        case.off * reach,
        case.off_dir,
        clear + case.rise * dist,
    );
    let mut body = approach(t, ms.safe, &rot, to_machine(t, start), inch);
    body.push(block460(case, typed, case.q320, cc[2], inch));
    body.push(l91(&[(LETTERS[t], ms.safe)], inch));
    (
        body,
        Truth::Calibration(truth460(
            case,
            typed,
            tol,
            s.sc.machine.spindle.is_some() || case.backend == 2.0,
        )),
    )
}

fn block460(case: &Case, typed: f64, q320: f64, q434: f64, inch: bool) -> String {
    format!(
        "TCH PROBE 460 CALIBRATION OF TS ON A SPHERE ~\n  Q407={} ;RADIUS OF CALIB. SPHERE ~\n  Q320={} ;SET-UP CLEARANCE ~\n  Q301={:+} ;MOVE TO CLEARANCE ~\n  Q423={:+} ;NO. OF PROBE POINTS ~\n  Q380=+0 ;REFERENCE ANGLE ~\n  Q433=+1 ;CALIBRATE LENGTH ~\n  Q434={} ;DATUM FOR LENGTH ~\n  Q455={:+} ;NO. OF POINTS IN 3D CAL.",
        len(typed, inch),
        len(q320, inch),
        case.q301,
        case.points,
        len(q434, inch),
        case.q455
    )
}

/// 460's columns: the stylus's truth, with Q407's error in R where the cycle cannot
/// see it (the docs: the contacts see only Q407 + R, so Q407's error goes into R
/// unseen where R then agrees with the probe table's within maxDevCalBall; beyond,
/// the cycle stops), and the lobes where 3 or 4 points cannot tell them from the
/// circle.
fn truth460(case: &Case, typed: f64, tol: f64, oriented: bool) -> Vec<(&'static str, f64, f64)> {
    let axial = if case.axial.is_nan() {
        case.pretravel
    } else {
        case.axial
    };
    let aliased = if case.points <= 4.0 { case.lobing } else { 0.0 };
    let effective = BALL - case.pretravel;
    // The R the cycle measures less the table's; 5 µm for what the locating contacts
    // see of the pre-travel's direction and the lobes.
    let table = (effective + case.stale_r).max(0.05);
    let apart = effective + SPHERE - typed - table;
    let q407 = if apart.abs() <= tol + 0.005 {
        SPHERE - typed
    } else {
        0.0
    };
    let mut v = vec![
        ("R", BALL - case.pretravel + q407, aliased),
        ("L", case.len_err - (axial - case.pretravel), aliased),
    ];
    if oriented {
        v.push(("CAL_OF1", case.off1, aliased));
        v.push(("CAL_OF2", case.off2, aliased));
    }
    v
}

/// Cycle 460 on the calibration sphere before a 431 or 444 (nominal values, the drawn
/// Q455 and points), with its L blocks.
pub(super) fn calibration_first(
    case: &Case,
    ms: &MachineSpec,
    centre: Vector3<f64>,
    pre: &mut Vec<String>,
) {
    let t = ms.tool;
    let inch = case.inch == 1.0;
    let cc = to_cycle(t, [centre.x, centre.y, centre.z]);
    let start = [cc[0], cc[1], cc[2] + SPHERE + BALL + 2.0];
    pre.extend(approach(t, ms.safe, &[], to_machine(t, start), inch));
    let mut nominal = case.clone();
    nominal.q301 = 1.0;
    nominal.points = 8.0;
    pre.push(block460(&nominal, SPHERE, 0.0, cc[2], inch));
    pre.push(l91(&[(LETTERS[t], ms.safe)], inch));
}
