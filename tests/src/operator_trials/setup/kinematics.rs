//! Cycle 451's case: the start over the sphere (Q431 = 1/3) or the preset row off its
//! centre (Q431 = 0/2), the rotary axes left turned, the block, and the truth.

use super::*;

pub(super) fn cycle451(
    case: &Case,
    s: &mut Setup,
    ms: &MachineSpec,
    clear: f64,
    dist: f64,
    pre: &mut Vec<String>,
) -> (Vec<String>, Truth) {
    let t = ms.tool;
    let inch = case.inch == 1.0;
    let true_centre = s.sc.spheres[0].center;
    let rs = SPHERE + BALL;
    let reach = cycles::cycle451::measure::LOCATE_REACH * rs;
    let typed = SPHERE * (1.0 + case.q407_err);
    let tol = s.cfg.parameters.max_dev_cal_ball;
    if (typed - SPHERE).abs() > tol {
        s.beyond.push(format!(
            "Q407 {:.4} mm off the sphere's radius (maxDevCalBall {tol})",
            typed - SPHERE
        ));
    }
    if case.stale_r.abs() > tol {
        s.beyond
            .push(format!("the probe table's R {:+.4} mm off", case.stale_r));
    }
    let rot = left_rotary(case, ms);
    let q431 = case.q431 as u8;
    let centre0 = [true_centre.x, true_centre.y, true_centre.z];
    let mut body = Vec::new();
    let q147;
    if q431 == 1 || q431 == 3 {
        let cc = to_cycle(t, sphere_at(&s.sc, &rot, true_centre));
        let height = clear + case.rise * dist;
        if case.off > 1.0 {
            s.beyond
                .push(format!("start {:.3} x the reach off the centre", case.off));
        }
        if case.rise > 1.0 {
            s.beyond
                .push(format!("start {:.3} mm above the pole", height));
        }
        let start = start_over(cc, rs, case.off * reach, case.off_dir, height);
        body.extend(approach(t, ms.safe, &rot, to_machine(t, start), inch));
        q147 = [0.0; 3];
    } else {
        let (sn, cs) = case.preset_dir.to_radians().sin_cos();
        let e = case.preset_err * reach;
        let err = to_machine(t, [e * cs, e * sn, case.preset_up]);
        if case.preset_err > 1.0 || case.preset_up.abs() > reach {
            s.beyond.push(format!(
                "the preset {:.3} mm off the sphere centre",
                e.hypot(case.preset_up)
            ));
        }
        let mut row = cycles::preset_table::Preset::origin(1);
        [row.x, row.y, row.z] = [0, 1, 2].map(|i| centre0[i] + err[i]);
        s.cfg.presets.rows.retain(|r| r.number != 1);
        s.cfg.presets.rows.push(row);
        pre.push("CYCL DEF 247 DATUM SETTING ~\n  Q339=+1 ;DATUM NUMBER".into());
        let away = to_machine(t, {
            let c = to_cycle(t, centre0);
            [c[0] + 70.0, c[1], c[2] + 60.0]
        });
        body.extend(approach(t, ms.safe, &rot, away, inch));
        q147 = [0, 1, 2].map(|i| -err[i]);
    }
    let (first, _, q, range, pts) = ms.first;
    let ax = |q: u32, r: [f64; 2], n: u32| {
        format!(
            "  Q{}={:+} ~\n  Q{}={:+} ~\n  Q{}=+0 ~\n  Q{}={:+} ~\n",
            q,
            r[0],
            q + 1,
            r[1],
            q + 2,
            q + 3,
            n
        )
    };
    let (with_first, with_c) = match case.axes as u8 {
        0 => (true, false),
        1 => (false, true),
        _ => (true, true),
    };
    let mut axes = String::new();
    for (qb, letter) in [(411, Axis::A), (415, Axis::B), (419, Axis::C)] {
        let on = (letter == first && with_first) || (letter == Axis::C && with_c);
        if !on {
            axes.push_str(&ax(qb, [0.0, 0.0], 0));
        } else if letter == Axis::C {
            axes.push_str(&ax(qb, ms.c.0, ms.c.1));
        } else {
            axes.push_str(&ax(q, range, pts));
        }
    }
    body.push(format!(
        "TCH PROBE 451 MEASURE KINEMATICS ~\n  Q406={:+} ;MODE ~\n  Q407={} ;SPHERE RADIUS ~\n  Q320={} ;SET-UP CLEARANCE ~\n  Q408={} ;RETR. HEIGHT ~\n  Q253={} ;F PRE-POSITIONING ~\n  Q380=+0 ;REFERENCE ANGLE ~\n{axes}  Q423={:+} ;NO. OF PROBE POINTS ~\n  Q431={:+} ;PRESET ~\n  Q432={:+} ;BACKLASH, ANG. RANGE",
        case.mode,
        len(typed, inch),
        len(case.q320, inch),
        len(case.q408, inch),
        feed(case.q253, inch),
        case.points,
        q431,
        case.q432
    ));
    let shift = stylus_shift(case);
    let head = !ms.first.1;
    let truth = Truth::Kinematics {
        check_errors: case.mode == 2.0,
        centre: centre0,
        check_preset: (q431 == 1 || q431 == 3) && case.mode != 0.0,
        q147,
        // A constant shift of every centre moves the fitted axes (the docs: an
        // uncalibrated stylus is not covered); the head turns it with B.
        allow_pos: if head { 2.0 * shift } else { shift },
        allow_preset: shift,
    };
    (body, truth)
}
