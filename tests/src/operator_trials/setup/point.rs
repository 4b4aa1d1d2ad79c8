//! Cycle 444's case: a point on a sphere whose real surface is off the nominal, the
//! block, the truth.

use super::*;

pub(super) fn cycle444(
    case: &Case,
    s: &mut Setup,
    ms: &MachineSpec,
    clear: f64,
    calib: Vector3<f64>,
    pre: &mut Vec<String>,
) -> (Vec<String>, Truth) {
    let t = ms.tool;
    let inch = case.inch == 1.0;
    let (c, r) = SPHERE_444;
    let (se, ce) = case.el.to_radians().sin_cos();
    let (sa, ca) = case.az.to_radians().sin_cos();
    let n = [ce * ca, ce * sa, se];
    let real = r + case.surf;
    s.sc.spheres = sim::artefact::Sphere::new(Vector3::from(to_machine(t, c)), real)
        .into_iter()
        .collect();
    s.sc.planes.clear();
    if case.calibrate == 1.0 {
        s.sc.spheres
            .extend(sim::artefact::Sphere::new(calib, SPHERE));
        super::calibration::calibration_first(case, ms, calib, pre);
    }
    let p = [0, 1, 2].map(|i| c[i] + r * n[i]);
    let top = c[2] + real + BALL;
    let calib_top = to_cycle(t, [calib.x, calib.y, calib.z])[2] + SPHERE + BALL + 0.2;
    let q260 = match (case.q260.is_nan(), case.calibrate == 1.0) {
        (true, true) => (top + clear + 20.0).max(calib_top + 20.0),
        (true, false) => top + clear + 20.0,
        _ => case.q260,
    };
    let table_r = cycle_r(case);
    if case.surf > clear + table_r - BALL - 0.2 {
        s.beyond.push(format!(
            "the surface {:+.3} mm beyond the nominal point, within SET_UP + Q320",
            case.surf
        ));
    }
    let horizontal = (r + cycle_r(case) + clear) * ce;
    if case.el < 0.0 && horizontal < real + BALL + 0.2 {
        s.beyond
            .push("the start below the equator, under the sphere's overhang".into());
    }
    if case.calibrate == 1.0 && q260 < calib_top {
        s.beyond.push(format!(
            "Q260 {q260:+.3} below the calibration sphere's top"
        ));
    }
    if q260 < top + 0.2 {
        s.beyond
            .push(format!("Q260 {q260:+.3} below the sphere's top"));
    }
    let mut body = vec![l91(&[(LETTERS[t], ms.safe)], inch)];
    body.push(format!(
        "TCH PROBE 444 PROBING 3D ~\n  Q263={} ~\n  Q264={} ~\n  Q294={} ~\n  Q581={:+.6} ~\n  Q582={:+.6} ~\n  Q583={:+.6} ~\n  Q320={} ~\n  Q260={} ~\n  QS400=\" \" ~\n  Q309=+0",
        len(p[0], inch),
        len(p[1], inch),
        len(p[2], inch),
        n[0],
        n[1],
        n[2],
        len(case.q320, inch),
        len(q260, inch)
    ));
    let shift = [case.off1, case.off2, -case.len_err];
    let (want, allow) = if case.calibrate == 1.0 {
        let resolved = case.q455 >= 7.0 && (s.sc.machine.spindle.is_some() || case.backend == 2.0);
        // Without the 3D table (or the offset) the docs do not cover a point off the
        // equator: the stylus's whole deviation is allowed.
        let allow = if resolved { 0.0 } else { stylus_shift(case) };
        (case.surf, allow)
    } else {
        (
            case.surf + BALL - pretravel(case, n) - table_r - dot(shift, n),
            0.0,
        )
    };
    (body, Truth::Point(want, allow))
}
