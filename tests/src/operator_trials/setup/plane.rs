//! Cycle 431's case: a tilted face, three points off it, the block, the truth.

use super::*;

pub(super) fn cycle431(
    case: &Case,
    s: &mut Setup,
    ms: &MachineSpec,
    clear: f64,
    calib: Vector3<f64>,
    pre: &mut Vec<String>,
) -> (Vec<String>, Truth) {
    let t = ms.tool;
    let inch = case.inch == 1.0;
    let n = unit([
        case.tilt2.to_radians().tan(),
        -case.tilt1.to_radians().tan(),
        1.0,
    ]);
    // The face 60 mm under the calibration sphere's centre, so that the sphere stands
    // clear of the face's material on every machine.
    let calib_c = to_cycle(t, [calib.x, calib.y, calib.z]);
    let face = [FACE_431[0], FACE_431[1], calib_c[2] - 60.0];
    let height = |x: f64, y: f64| face[2] - (n[0] * (x - face[0]) + n[1] * (y - face[1])) / n[2];
    let pm = to_machine(t, face);
    let nm = to_machine(t, n);
    s.sc.spheres.clear();
    s.sc.planes = sim::artefact::Plane::new(Vector3::from(pm), Vector3::from(nm))
        .into_iter()
        .collect();
    if case.calibrate == 1.0 {
        s.sc.spheres
            .extend(sim::artefact::Sphere::new(calib, SPHERE));
        super::calibration::calibration_first(case, ms, calib, pre);
    }
    let hs = [case.h1, case.h2, case.h3];
    let pts: Vec<[f64; 3]> = POINTS_431
        .iter()
        .zip(hs)
        .map(|(p, h)| [p[0], p[1], height(p[0], p[1]) + h])
        .collect();
    let top = pts.iter().map(|p| p[2]).fold(f64::MIN, f64::max) + BALL + clear;
    let calib_top = calib_c[2] + SPHERE + BALL + 0.2;
    let q260 = match (case.q260.is_nan(), case.calibrate == 1.0) {
        (true, true) => (top + 20.0).max(calib_top + 20.0),
        (true, false) => top + 20.0,
        _ => case.q260,
    };
    let lift = (1.0 / n[2] - 1.0) * BALL;
    // The start is SET_UP + Q320 + the table's R over the nominal point (after a 460
    // in the program, its calibrated R).
    let table_r = cycle_r(case);
    let room = clear + table_r - BALL;
    for (i, h) in hs.iter().enumerate() {
        // Nominal under the face by more than that room: the start is in it.
        if -h > room - 0.3 - lift {
            s.beyond.push(format!(
                "point {} nominal {h:+.3} mm under the face, beyond SET_UP + Q320",
                i + 1
            ));
        }
    }
    if case.calibrate == 1.0 && q260 < calib_top {
        s.beyond.push(format!(
            "Q260 {q260:+.3} below the calibration sphere's top"
        ));
    }
    let mut body = vec![l91(&[(LETTERS[t], ms.safe)], inch)];
    let mut block = String::from("TCH PROBE 431 MEASURE PLANE ~\n");
    for (p, q) in pts
        .iter()
        .zip([[263, 264, 294], [265, 266, 295], [296, 297, 298]])
    {
        for k in 0..3 {
            block.push_str(&format!("  Q{}={} ~\n", q[k], len(p[k], inch)));
        }
    }
    block.push_str(&format!(
        "  Q320={} ;SET-UP CLEARANCE ~\n  Q260={} ;CLEARANCE HEIGHT ~\n  Q281=+0 ;MEASURING LOG",
        len(case.q320, inch),
        len(q260, inch)
    ));
    body.push(block);
    // Truth: the face's heights under the ball's centre (which the offset moves), the
    // ball's distance along the tool axis (tilted face), the length error; the angles
    // of the face itself.
    let calibrated = case.calibrate == 1.0;
    let p = pretravel(case, n);
    let mut v = Vec::new();
    for (i, q) in ["Q173", "Q174", "Q175"].into_iter().enumerate() {
        let [x, y] = POINTS_431[i];
        let want = if calibrated {
            height(x, y) + BALL * (1.0 / n[2] - 1.0)
        } else {
            height(x + case.off1, y + case.off2) + (BALL - p) / n[2] + case.len_err - table_r
        };
        v.push((q, want, if calibrated { stylus_shift(case) } else { 0.0 }));
    }
    v.push(("Q158", case.tilt1, 0.0));
    v.push(("Q159", case.tilt2, 0.0));
    (body, Truth::Plane(v))
}
