//! Cycle 451 as an operator uses it, on the simulated machines over CANopen: a probe
//! pre-positioned by eye (off the centre, too low, too high), rotary axes left off
//! their reference, clearance heights on both sides of their limit, and `check`
//! (the preflight) refusing exactly what `run` refuses, at the same step.

use cycles::program::Program;
use cycles::progress::ProgressEvent;
use cycles::results::{ProgramReport, Status};
use cycles::runner::{preflight_program, run_program, RunOptions};
use probebridge_tests::conformance::{Backend, CanInproc};
use probebridge_tests::spec451::errors_of;
use probebridge_tests::{configs_dir, cycles_config, progress};
use std::path::PathBuf;

/// Per rotary axis: (start, end, incidence, points).
#[derive(Clone, Copy, Debug)]
struct Ax(f64, f64, f64, u32);
const NONE: Ax = Ax(0.0, 0.0, 0.0, 0);

#[derive(Clone, Debug)]
struct P451 {
    mode: u8,
    radius: f64,
    q320: f64,
    q408: f64,
    q380: f64,
    a: Ax,
    b: Ax,
    c: Ax,
    points: u32,
    preset: u8,
    backlash: f64,
}

impl Default for P451 {
    fn default() -> Self {
        P451 {
            mode: 2,
            radius: 12.5,
            q320: 0.0,
            q408: 0.0,
            q380: 0.0,
            a: NONE,
            b: NONE,
            c: NONE,
            points: 4,
            preset: 1,
            backlash: 0.0,
        }
    }
}

fn block451(p: &P451) -> String {
    let ax = |a: Ax, q: [u32; 4]| {
        format!(
            "  Q{}={:+} ~\n  Q{}={:+} ~\n  Q{}={:+} ~\n  Q{}={:+} ~\n",
            q[0], a.0, q[1], a.1, q[2], a.2, q[3], a.3
        )
    };
    format!(
        "20 TCH PROBE 451 MEASURE KINEMATICS ~\n  Q406={:+} ;MODE ~\n  Q407={:+} ;SPHERE RADIUS ~\n\
  Q320={:+} ;SET-UP CLEARANCE ~\n  Q408={:+} ;RETR. HEIGHT ~\n  Q253=+750 ;F PRE-POSITIONING ~\n\
  Q380={:+} ;REFERENCE ANGLE ~\n{}{}{}  Q423={:+} ;NO. OF PROBE POINTS ~\n  Q431={:+} ;PRESET ~\n\
  Q432={:+} ;BACKLASH, ANG. RANGE\n",
        p.mode,
        p.radius,
        p.q320,
        p.q408,
        p.q380,
        ax(p.a, [411, 412, 413, 414]),
        ax(p.b, [415, 416, 417, 418]),
        ax(p.c, [419, 420, 421, 422]),
        p.points,
        p.preset,
        p.backlash
    )
}

/// Tool axis `axis`: up along it, over `start` in the working plane, down to `start`
/// along it; `before` (more blocks) then the 451 block.
fn program(p: &P451, axis: char, start: [f64; 3], before: &str) -> String {
    let t = "XYZ".find(axis).unwrap();
    let names = ['X', 'Y', 'Z'];
    let plane: Vec<String> = (0..3)
        .filter(|&i| i != t)
        .map(|i| format!("{}{:+.4}", names[i], start[i]))
        .collect();
    format!(
        "0 BEGIN PGM K451 MM\n1 TOOL CALL \"TOUCH_PROBE\" {axis}\n2 L {axis}{:+.4} R0 FMAX\n\
3 L {} R0 FMAX\n4 L {axis}{:+.4} R0 FMAX\n{before}{}99 END PGM K451 MM\n",
        start[t] + 80.0,
        plane.join(" "),
        start[t],
        block451(p)
    )
}

fn load(name: &str) -> sim::Scenario {
    sim::Scenario::load(
        &configs_dir().join("scenarios").join(name),
        Some(&configs_dir().join("machines")),
    )
    .unwrap()
}

fn temp_dir(name: &str) -> PathBuf {
    static NEXT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let d = std::env::temp_dir().join(format!("pb-451op-{name}-{}-{n}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

struct Run {
    report: ProgramReport,
    events: Vec<ProgressEvent>,
    /// What `check` says of the same program (its preflight): `None` = ok.
    check: Option<String>,
}

fn run_text(text: &str, sc: &sim::Scenario, cfg: &cycles::CyclesConfig, tag: &str) -> Run {
    run_on(text, CanInproc::open(sc), cfg, tag)
}

/// As [`run_text`], on the machine `m` (a simulator with a motion watch).
fn run_on<M: hal::Machine>(text: &str, mut m: M, cfg: &cycles::CyclesConfig, tag: &str) -> Run {
    let program = Program::parse(text, cfg).unwrap_or_else(|e| panic!("{e}\n{text}"));
    let dir = temp_dir(tag);
    let kinematics = dir.join("kinematics.toml");
    let check = preflight_program(&program, cfg.machine.axis_mask(), cfg, &kinematics)
        .err()
        .map(|e| e.to_string());
    let mut events = Vec::new();
    let mut confirm = |_: &cycles::confirmation::Confirmation| true;
    let mut progress = |e| events.push(e);
    let mut opts = RunOptions {
        out_dir: dir.clone(),
        confirm: &mut confirm,
        progress: &mut progress,
        kinematics: Some(kinematics),
        estimator: None,
    };
    let report = run_program(&program, &mut m, cfg, &mut opts);
    let _ = std::fs::remove_dir_all(&dir);
    Run {
        report,
        events,
        check,
    }
}

fn json(r: &Run) -> serde_json::Value {
    let v: serde_json::Value = serde_json::from_str(&r.report.to_json()).unwrap();
    v["cycles"][0].clone()
}

/// The run's 451 result: errors after, and the preset the cycle set (its centre).
fn result(r: &Run) -> (std::collections::BTreeMap<String, f64>, [f64; 3]) {
    assert!(r.check.is_none(), "check refused: {:?}", r.check);
    let c = &r.report.cycles[0];
    assert_eq!(c.status, Status::Ok, "{:?}", c.message);
    let v = json(r);
    let after = errors_of(&v["kinematics"]["errors_after"]);
    let p = &v["kinematics"]["preset_after"];
    (after, [0, 1, 2].map(|i| p[i].as_f64().unwrap()))
}

/// A point `f` x (Q407 + R) off `centre` in the working plane of tool axis `t` at
/// `deg`, `gap` above the sphere's pole along the tool axis (ball centre).
fn start_at(centre: [f64; 3], t: usize, rs: f64, f: f64, deg: f64, gap: f64) -> [f64; 3] {
    let [main, minor] = match t {
        0 => [1, 2],
        1 => [2, 0],
        _ => [0, 1],
    };
    let mut s = centre;
    s[main] += f * rs * deg.to_radians().cos();
    s[minor] += f * rs * deg.to_radians().sin();
    s[t] += rs + gap;
    s
}

/// Starts up to 0.6 x (Q407 + R) off the centre in several directions, from Q320 +
/// SET_UP up to the probing distance above the pole and below Q320 + SET_UP, with the
/// tool axis Z, Y and X: the same kinematics (1e-4) and preset (1e-3) as a centred
/// start, and no contact outside a probing move (the simulator stops at any).
#[test]
fn inaccurate_pre_positions_give_the_centred_result() {
    // (scenario, tool axis, sphere centre, params, [(off, direction deg, gap)]).
    type Case = (&'static str, char, [f64; 3], P451, Vec<(f64, f64, f64)>);
    let cases: Vec<Case> = vec![
        (
            "demo-sphere.toml",
            'Z',
            [50.0, -30.0, 80.0],
            P451 {
                a: Ax(-60.0, 60.0, 0.0, 2),
                c: Ax(90.0, 270.0, 0.0, 3),
                ..P451::default()
            },
            vec![(0.6, 0.0, 2.0), (0.6, 137.0, 12.0), (0.45, 250.0, 0.7)],
        ),
        (
            "horizontal-y-sphere.toml",
            'Y',
            [50.0, -30.0, 80.0],
            P451 {
                a: Ax(-45.0, 75.0, 0.0, 2),
                c: Ax(90.0, 270.0, 0.0, 2),
                points: 5,
                q320: 1.5,
                ..P451::default()
            },
            vec![(0.58, 300.0, 3.5), (0.3, 45.0, 13.0)],
        ),
        (
            "horizontal-x-head-b-table-c.toml",
            'X',
            [40.0, 25.0, 60.0],
            P451 {
                b: Ax(-50.0, 40.0, 0.0, 2),
                c: Ax(120.0, 240.0, 0.0, 2),
                points: 3,
                preset: 3,
                ..P451::default()
            },
            vec![(0.6, 210.0, 2.0), (0.5, 80.0, 9.0)],
        ),
    ];
    for (name, axis, centre, p, starts) in cases {
        // A minute or more in all: say which machine, past libtest's capture.
        progress(
            "cycle451_operator",
            format_args!("{name}: centred and off-centre starts"),
        );
        let sc = load(name);
        let cfg = cycles_config(&sc);
        let t = "XYZ".find(axis).unwrap();
        let rs = p.radius + 3.0;
        let clearance = 2.0 + p.q320;
        let centred = start_at(centre, t, rs, 0.0, 0.0, clearance);
        let r0 = run_text(&program(&p, axis, centred, ""), &sc, &cfg, "centred");
        let (e0, p0) = result(&r0);
        for (k, (f, deg, gap)) in starts.into_iter().enumerate() {
            let s = start_at(centre, t, rs, f, deg, gap);
            let r = run_text(&program(&p, axis, s, ""), &sc, &cfg, "off");
            let (e, pr) = result(&r);
            for (name_e, v) in &e0 {
                assert!(
                    (e[name_e] - v).abs() < 1e-4,
                    "{name} start {k} ({f} x {rs} at {deg} deg, {gap} above): {name_e} {} vs centred {v}",
                    e[name_e]
                );
            }
            for i in 0..3 {
                assert!(
                    (pr[i] - p0[i]).abs() < 1e-3,
                    "{name} start {k}: preset {pr:?} vs centred {p0:?}"
                );
            }
            assert!(
                r.events.iter().any(
                    |e| matches!(e, ProgressEvent::Note { text, .. } if text.contains("first pass"))
                ),
                "{name}: no first pass"
            );
        }
    }
}

/// A start so far off that the pole probe misses the sphere: today's message, and
/// nothing moves after that probing move.
#[test]
fn a_start_whose_pole_probe_misses_stops_and_nothing_else_moves() {
    for (name, axis, centre, f) in [
        ("demo-sphere.toml", 'Z', [50.0, -30.0, 80.0], 1.08),
        ("horizontal-y-sphere.toml", 'Y', [50.0, -30.0, 80.0], 1.4),
    ] {
        let sc = load(name);
        let cfg = cycles_config(&sc);
        let t = "XYZ".find(axis).unwrap();
        let p = P451 {
            c: Ax(90.0, 270.0, 0.0, 3),
            ..P451::default()
        };
        let s = start_at(centre, t, 15.5, f, 33.0, 2.0);
        let r = run_text(&program(&p, axis, s, ""), &sc, &cfg, "miss");
        assert!(r.check.is_none(), "{:?}", r.check);
        let c = &r.report.cycles[0];
        assert_eq!(c.status, Status::Error);
        let m = c.message.as_deref().unwrap();
        assert!(
            m.contains("probe did not trigger")
                && m.contains("before cycle 451 position the probe over the sphere centre"),
            "{m}"
        );
        let started = r
            .events
            .iter()
            .position(|e| matches!(e, ProgressEvent::CycleStarted { .. }))
            .unwrap();
        let after: Vec<_> = r.events[started..]
            .iter()
            .filter(|e| matches!(e, ProgressEvent::Move { .. } | ProgressEvent::Probe { .. }))
            .collect();
        assert_eq!(after.len(), 1, "{after:?}");
        assert!(matches!(after[0], ProgressEvent::Probe { .. }));
    }
}

/// `cfg` with preset row 1 at `centre` (instead of the shipped table's row 1),
/// activated by cycle 247 in the program.
fn with_preset_row(cfg: &mut cycles::CyclesConfig, centre: [f64; 3]) {
    let mut row = cycles::preset_table::Preset::origin(1);
    [row.x, row.y, row.z] = centre;
    cfg.presets.rows.retain(|r| r.number != 1);
    cfg.presets.rows.push(row);
}

/// Q431 = 0 with a rotary axis left off its reference by the program (`L C+90`,
/// `L A+30`, both): the datum is the sphere centre with the axes at 0, the axes turn
/// at a height that clears the sphere before the approach, and the result is the one
/// of a start with every axis at 0; on the vertical and the Y-spindle machine.
#[test]
fn q431_0_with_rotary_axes_off_their_reference() {
    for (name, axis, centre, turned) in [
        (
            "demo-sphere.toml",
            'Z',
            [50.0, -30.0, 80.0],
            vec!["L C+90 R0 FMAX"],
        ),
        (
            "demo-sphere.toml",
            'Z',
            [50.0, -30.0, 80.0],
            vec!["L A+30 R0 FMAX"],
        ),
        (
            "demo-sphere.toml",
            'Z',
            [50.0, -30.0, 80.0],
            vec!["L A-25 C+200 R0 FMAX"],
        ),
        (
            "horizontal-y-sphere.toml",
            'Y',
            [50.0, -30.0, 80.0],
            vec!["L C-135 R0 FMAX", "L A+40 R0 FMAX"],
        ),
    ] {
        let sc = load(name);
        let mut cfg = cycles_config(&sc);
        with_preset_row(&mut cfg, centre);
        let p = P451 {
            preset: 0,
            a: Ax(-60.0, 60.0, 0.0, 2),
            c: Ax(90.0, 270.0, 0.0, 3),
            ..P451::default()
        };
        let t = "XYZ".find(axis).unwrap();
        // In preset 1's coordinates: 60 above the sphere, 70 off in the plane.
        let mut away = [70.0, 0.0, 0.0];
        away[t] = 60.0;
        let base = "10 CYCL DEF 247 DATUM SETTING ~\n  Q339=+1 ;DATUM NUMBER\n".to_string();
        let reference = run_text(&program(&p, axis, away, &base), &sc, &cfg, "ref0");
        let (e0, _) = result(&reference);
        let before = format!(
            "{base}{}",
            turned
                .iter()
                .enumerate()
                .map(|(i, l)| format!("{} {l}\n", 11 + i))
                .collect::<String>()
        );
        let r = run_text(&program(&p, axis, away, &before), &sc, &cfg, "turned");
        let (e, _) = result(&r);
        for (n, v) in &e0 {
            assert!(
                (e[n] - v).abs() < 1e-4,
                "{name} {turned:?}: {n} {} vs {v}",
                e[n]
            );
        }
        let v = json(&r);
        for q in ["Q147", "Q148", "Q149"] {
            assert!(
                v["q"][q].as_f64().unwrap().abs() < 1e-6,
                "{q}: {}",
                v["q"][q]
            );
        }
        assert!(
            r.events.iter().any(
                |e| matches!(e, ProgressEvent::Note { text, .. } if text.contains("turn from"))
            ),
            "{name}: the axes did not turn before the approach"
        );
    }
}

/// The seed's second 451 example on head-b-table-c.toml (B -90..+90 in 4, C 90..270
/// in 3, Q423 = 3, Q431 = 1, Q432 = 0.5): `check` accepts it and it runs, B+90
/// approached from the side within the software limits.
#[test]
fn the_seeds_second_example_runs_on_the_b_head() {
    let sc = load("head-b-table-c.toml");
    let cfg = cycles_config(&sc);
    let p = P451 {
        mode: 1,
        b: Ax(-90.0, 90.0, 0.0, 4),
        c: Ax(90.0, 270.0, 0.0, 3),
        points: 3,
        preset: 1,
        backlash: 0.5,
        ..P451::default()
    };
    let s = start_at([40.0, 25.0, 60.0], 2, 15.5, 0.0, 0.0, 2.0);
    let r = run_text(&program(&p, 'Z', s, ""), &sc, &cfg, "seed2");
    let (e, _) = result(&r);
    for n in ["EX0B", "EZ0B", "EX0C", "EY0C"] {
        let truth = sc.truth.get(n).unwrap();
        // Mode 1 corrects positions only (the angle errors stay in them): near.
        assert!((e[n] - truth).abs() < 0.02, "{n}: {} vs {truth}", e[n]);
    }
    assert!(
        r.events.iter().any(
            |e| matches!(e, ProgressEvent::Note { text, .. } if text.contains("instead of Q380"))
        ),
        "B+90 not approached from the side"
    );
}

/// Q408 on a tilting table: at the centre's own height the sphere rises when A tilts;
/// Q408 just below what clears it at every angle on the way is refused by `check` and
/// `run` alike with the lowest value, which then runs.
#[test]
fn q408_must_clear_the_sphere_at_every_angle_on_the_way() {
    let sc = load("demo-sphere.toml");
    let cfg = cycles_config(&sc);
    let mut p = P451 {
        mode: 0,
        q408: 18.0,
        a: Ax(-90.0, 90.0, 0.0, 3),
        ..P451::default()
    };
    let s = start_at([50.0, -30.0, 80.0], 2, 15.5, 0.0, 0.0, 2.0);
    let r = run_text(&program(&p, 'Z', s, ""), &sc, &cfg, "q408-low");
    let check = r
        .check
        .clone()
        .expect("check accepted a Q408 that cuts the sphere");
    assert!(
        check.contains("Q408=18") && check.contains("the lowest Q408 that clears it is"),
        "{check}"
    );
    let stopped = r.report.stopped.clone().unwrap();
    let msg = &check[check.find("Q408=").unwrap()..];
    assert!(stopped.contains(msg), "run: {stopped}\ncheck: {check}");
    // Refused before the first block: not even the L blocks moved.
    assert!(
        !r.events
            .iter()
            .any(|e| matches!(e, ProgressEvent::Move { .. })),
        "something moved"
    );
    let lowest_in = |msg: &str| -> f64 {
        msg.rsplit("the lowest Q408 that clears it is ")
            .next()
            .unwrap()
            .split(|c: char| !(c.is_ascii_digit() || c == '.'))
            .next()
            .unwrap()
            .parse()
            .unwrap()
    };
    let lowest = lowest_in(msg);
    // Higher than the untilted Q407 + R + SET_UP: the sphere rises with A.
    assert!(lowest > 17.5, "{lowest}");
    // `check` plans every start the docs allow: a sphere up to 0.6 x (Q407 + R) off
    // below the start rises further with A, and the lowest Q408 named for it (with
    // the start it happens from) is higher. Followed until `check` accepts, that
    // value runs.
    p.q408 = lowest;
    let mut r = run_text(&program(&p, 'Z', s, ""), &sc, &cfg, "q408-ok");
    for _ in 0..3 {
        let Some(check) = r.check.clone() else { break };
        assert!(
            check.contains("when the sphere centre stands 9.3000 mm off below the start"),
            "{check}"
        );
        let higher = lowest_in(&check);
        assert!(higher > p.q408, "{check}");
        p.q408 = higher;
        r = run_text(&program(&p, 'Z', s, ""), &sc, &cfg, "q408-ok");
    }
    result(&r);
}

/// `check` and `run` agree: what `check` refuses, `run` refuses before its first
/// move with the same message; what `check` accepts, `run` carries out. On every
/// shipped program on its scenario, the seed's two 451 examples, and the issue's
/// cases (Q408 = +350 leaving the limits after the datum moved to the sphere, Q320 =
/// +99999, Q408 = +5, a 444 Q260 under its point).
#[test]
fn check_and_run_agree_at_the_same_move() {
    let read =
        |name: &str| std::fs::read_to_string(configs_dir().join("programs").join(name)).unwrap();
    let check451 = read("451-check.h");
    let seed = |b: Ax, c: Ax, points: u32, preset: u8, backlash: f64| {
        let p = P451 {
            mode: 0,
            b,
            c,
            points,
            preset,
            backlash,
            ..P451::default()
        };
        let s = start_at([40.0, 25.0, 60.0], 2, 15.5, 0.0, 0.0, 2.0);
        program(
            &p,
            'Z',
            s,
            "10 CYCL DEF 247 DATUM SETTING ~\n  Q339=+1 ;DATUM NUMBER\n",
        )
    };
    // The seed's 444 with another Q260.
    let q260 = |v: &str, refused: bool| {
        let text = read("444-seed.h").replace("Q260=+100", &format!("Q260={v}"));
        ("seed-444.toml", text, None, refused)
    };
    // (scenario, program text, preset row 1, refused?)
    let cases: Vec<(&str, String, Option<[f64; 3]>, bool)> = vec![
        ("tilted-plane.toml", read("431-plane.h"), None, false),
        ("plane-z10.toml", read("431-plane.h"), None, false),
        ("tilted-plane-y.toml", read("431-plane-y.h"), None, false),
        ("freeform.toml", read("444-freeform.h"), None, false),
        ("seed-444.toml", read("444-seed.h"), None, false),
        q260("-1", true),
        // The seed's face is vertical at X0, the side of a dome that rises to Z80
        // within the ball radius behind it: Q260 must clear the probed point itself
        // by R + SET_UP (5 over Z0), and the probe, standing above Q260, comes down
        // over the pre-position (X5), never at X0 where it stood (which drove it into
        // the dome at Q260 = +0.2 and +33 before).
        q260("+0.2", true),
        q260("+4.99", true),
        q260("+5", false),
        q260("+33", false),
        ("demo-sphere.toml", check451.clone(), None, false),
        ("demo-sphere.toml", read("451-optimise.h"), None, false),
        (
            "demo-sphere.toml",
            read("451-preset-247.h"),
            Some([50.0, -30.0, 80.0]),
            false,
        ),
        ("demo-sphere.toml", read("451-preset-set.h"), None, false),
        ("demo-sphere.toml", read("450-save-restore.h"), None, false),
        (
            "demo-sphere.toml",
            check451.replace("Q408=+50 ", "Q408=+350 "),
            None,
            true,
        ),
        (
            "demo-sphere.toml",
            check451.replace("Q408=+50 ", "Q408=+5 "),
            None,
            true,
        ),
        (
            "demo-sphere.toml",
            check451.replace("Q320=+0 ", "Q320=+99999 "),
            None,
            true,
        ),
        // Seed example 1 (Q431 = 0, B and C from -90 to +90 in 2, Q423 = 4): at B+-90
        // four points cannot all stay above Z-200 on this machine.
        (
            "head-b-table-c.toml",
            seed(Ax(-90.0, 90.0, 0.0, 2), Ax(-90.0, 90.0, 0.0, 2), 4, 0, 0.0),
            Some([40.0, 25.0, 60.0]),
            true,
        ),
        // Seed example 2.
        (
            "head-b-table-c.toml",
            seed(Ax(-90.0, 90.0, 0.0, 4), Ax(90.0, 270.0, 0.0, 3), 3, 1, 0.5),
            Some([40.0, 25.0, 60.0]),
            false,
        ),
    ];
    for (k, (name, text, row, refused)) in cases.into_iter().enumerate() {
        let sc = load(name);
        let mut cfg = cycles_config(&sc);
        if let Some(c) = row {
            with_preset_row(&mut cfg, c);
        }
        let r = run_text(&text, &sc, &cfg, &format!("agree{k}"));
        match &r.check {
            Some(check) => {
                assert!(refused, "case {k} ({name}): check refused: {check}");
                let stopped = r.report.stopped.clone().unwrap_or_default();
                // The same message (after "line L, block N (cycle C): ").
                let msg = check.split_once("): ").map_or(check.as_str(), |(_, m)| m);
                assert!(
                    stopped.contains(msg),
                    "case {k}: run: {stopped}\ncheck: {check}"
                );
                assert!(
                    !r.events.iter().any(|e| matches!(
                        e,
                        ProgressEvent::Move { .. } | ProgressEvent::Probe { .. }
                    )),
                    "case {k}: something moved"
                );
            }
            None => {
                assert!(!refused, "case {k} ({name}): check accepted it");
                assert!(
                    r.report.cycles.iter().all(|c| c.status == Status::Ok),
                    "case {k} ({name}): {:?}",
                    r.report.stopped
                );
            }
        }
    }
}

/// Replays the commanded moves of a run on the simulator's true geometry: no move
/// turns a rotary axis together with a linear one, and while a rotary axis turns the
/// ball clears the sphere by SET_UP (less 0.05 mm for the injected errors) at every
/// angle on the way. Returns the number of rotary moves.
fn turns_clear_the_sphere(sc: &sim::Scenario, set_up: f64, events: &[ProgressEvent]) -> usize {
    use hal::{Axis, AxisPositions};
    let world = sim::world::World::new(sc);
    let r = world.probe().ball_radius();
    // Every axis at 0: the program's L blocks set X, Y and Z before anything turns.
    let mut pos = AxisPositions::new();
    for a in Axis::ALL {
        if sc.machine.axis(a).is_some() {
            pos.set(a, 0.0);
        }
    }
    let mut turns = 0;
    for e in events {
        let ProgressEvent::Move { target, .. } = e else {
            continue;
        };
        let changes = |axes: &[Axis]| {
            axes.iter().any(|a| match (target.get(*a), pos.get(*a)) {
                (Some(t), Some(p)) => (t - p).abs() > 1e-9,
                _ => false,
            })
        };
        if changes(&Axis::ROTARY) {
            turns += 1;
            assert!(
                !changes(&Axis::LINEAR),
                "a rotary axis turns together with a linear one: {target:?} from {pos:?}"
            );
            let end = pos.merged(target);
            let span = Axis::ROTARY
                .iter()
                .filter_map(|a| Some((end.get(*a)? - pos.get(*a)?).abs()))
                .fold(0.0, f64::max);
            let steps = (span / 0.25).ceil().max(1.0) as usize;
            for i in 0..=steps {
                let f = i as f64 / steps as f64;
                let mut p = pos;
                for (a, v) in end.iter() {
                    let v0 = pos.get(a).unwrap_or(v);
                    p.set(a, v0 + (v - v0) * f);
                }
                let gap = world.distance(&p) - r;
                assert!(
                    gap > set_up - 0.05,
                    "while turning to {target:?}: the ball is {gap:.4} mm from the sphere at {p:?} (SET_UP {set_up})"
                );
            }
        }
        pos = pos.merged(target);
    }
    turns
}

/// The rotary axes turn only while the probe stands at a height that clears the
/// sphere for every angle on the way (Q408 = 0: the lowest such height; Q408 > 0:
/// Q408), and the approach starts only after they stand at the measurement's angles:
/// on a tilting table, a B head with a C table, and both horizontal machines, the
/// axes turning up and down (ranges in both directions, Q432 from both sides), with
/// the same result as before the turns were made this way (within 1e-4 of a run
/// whose axes start centred, checked by the other tests).
#[test]
fn rotary_axes_turn_only_at_a_height_that_clears_the_sphere() {
    type Case = (&'static str, char, [f64; 3], P451);
    let cases: Vec<Case> = vec![
        (
            "demo-sphere.toml",
            'Z',
            [50.0, -30.0, 80.0],
            P451 {
                a: Ax(-70.0, 80.0, 0.0, 3),
                c: Ax(300.0, 30.0, 0.0, 3),
                ..P451::default()
            },
        ),
        (
            "demo-sphere.toml",
            'Z',
            [50.0, -30.0, 80.0],
            P451 {
                a: Ax(85.0, -45.0, 0.0, 2),
                c: Ax(45.0, 315.0, 20.0, 2),
                backlash: 0.7,
                q408: 42.5,
                ..P451::default()
            },
        ),
        (
            "head-b-table-c.toml",
            'Z',
            [40.0, 25.0, 60.0],
            P451 {
                b: Ax(80.0, -70.0, 0.0, 3),
                c: Ax(90.0, 270.0, 0.0, 2),
                points: 3,
                backlash: 0.5,
                ..P451::default()
            },
        ),
        (
            "horizontal-y-sphere.toml",
            'Y',
            [50.0, -30.0, 80.0],
            P451 {
                a: Ax(60.0, -40.0, 0.0, 2),
                c: Ax(-60.0, 200.0, 0.0, 2),
                q320: 1.0,
                ..P451::default()
            },
        ),
        (
            "horizontal-x-head-b-table-c.toml",
            'X',
            [40.0, 25.0, 60.0],
            P451 {
                b: Ax(-50.0, 40.0, 0.0, 2),
                c: Ax(240.0, 100.0, 0.0, 2),
                points: 3,
                backlash: 0.4,
                ..P451::default()
            },
        ),
    ];
    for (k, (name, axis, centre, p)) in cases.into_iter().enumerate() {
        let sc = load(name);
        let cfg = cycles_config(&sc);
        let t = "XYZ".find(axis).unwrap();
        let set_up = cfg.probe("TOUCH_PROBE").unwrap().set_up;
        let s = start_at(centre, t, p.radius + 3.0, 0.0, 0.0, set_up + p.q320);
        let r = run_text(&program(&p, axis, s, ""), &sc, &cfg, "turns");
        result(&r);
        let turns = turns_clear_the_sphere(&sc, set_up, &r.events);
        assert!(turns >= 4, "case {k} ({name}): only {turns} turns");
    }
}

/// What the simulated machine did while a rotary axis moved, sampled at every SYNC:
/// the motion itself, not the commanded targets.
#[derive(Debug)]
struct Turning {
    /// Samples with a rotary axis moving since the last one.
    samples: usize,
    /// The lowest height of the ball centre above the sphere centre along the tool
    /// axis in those samples (machine coordinates, the scenario's true kinematics),
    /// and the axes there.
    lowest: (f64, hal::AxisPositions),
    /// The first samples where a linear axis moved together with a rotary one.
    together: Vec<String>,
}

/// A simulated machine for `sc` whose motion watch records [`Turning`] for the
/// scenario's sphere and the tool axis `t`.
fn watched(
    sc: &sim::Scenario,
    t: usize,
) -> (
    impl hal::Machine<Error = hal::MachineError>,
    std::sync::Arc<std::sync::Mutex<Turning>>,
) {
    use hal::{Axis, AxisPositions};
    use std::sync::{Arc, Mutex};
    let kin = sim::kinematics::TrueKinematics::new(&sc.machine, &sc.truth);
    let sphere = sc.spheres[0].center;
    let seen = Arc::new(Mutex::new(Turning {
        samples: 0,
        lowest: (f64::INFINITY, AxisPositions::new()),
        together: Vec::new(),
    }));
    let out = seen.clone();
    let last = Mutex::new(None::<AxisPositions>);
    let watch: sim::machine::MotionWatch = Arc::new(move |p: &AxisPositions| {
        let Some(q) = last.lock().unwrap().replace(*p) else {
            return;
        };
        let moved = |axes: &[Axis], tol: f64| {
            axes.iter().any(
                |a| matches!((p.get(*a), q.get(*a)), (Some(x), Some(y)) if (x - y).abs() > tol),
            )
        };
        if !moved(&Axis::ROTARY, 1e-9) {
            return;
        }
        let mut s = out.lock().unwrap();
        s.samples += 1;
        for at in [q, *p] {
            let h = (kin.ball_centre_in_machine(&at) - kin.table_to_machine(&at, sphere))[t];
            if h < s.lowest.0 {
                s.lowest = (h, at);
            }
        }
        if moved(&Axis::LINEAR, 1e-6) && s.together.len() < 3 {
            s.together.push(format!("{q} -> {p}"));
        }
    });
    let m = CanInproc::open_abortable(sc, hal::AbortFlag::fresh(), watch);
    (m, seen)
}

// (scenario, tool axis, sphere centre, params, blocks before the cycle: None =
// a start over the sphere, Some = preset row 1 at the centre, the probe away; the
// program turns the axes there, high above the sphere: only the cycle's turns
// are the subject).
type WatchCase = (&'static str, char, [f64; 3], P451, Option<&'static str>);

/// The cases of [`while_a_rotary_axis_moves_the_ball_stands_above_the_sphere`].
fn watched_cases() -> Vec<WatchCase> {
    vec![
        (
            "demo-sphere.toml",
            'Z',
            [50.0, -30.0, 80.0],
            P451 {
                a: Ax(-80.0, 70.0, 0.0, 3),
                c: Ax(30.0, 300.0, 0.0, 3),
                q320: 0.5,
                ..P451::default()
            },
            None,
        ),
        (
            "demo-sphere.toml",
            'Z',
            [50.0, -30.0, 80.0],
            P451 {
                preset: 0,
                a: Ax(55.0, -45.0, 0.0, 2),
                c: Ax(90.0, 270.0, 0.0, 2),
                ..P451::default()
            },
            Some("11 L Z+250 R0 FMAX\n12 L A-35 C+150 R0 FMAX\n"),
        ),
        (
            "demo-sphere.toml",
            'Z',
            [50.0, -30.0, 80.0],
            P451 {
                a: Ax(-60.0, 75.0, 0.0, 2),
                c: Ax(200.0, 20.0, 0.0, 2),
                backlash: 0.8,
                q408: 44.0,
                preset: 3,
                ..P451::default()
            },
            None,
        ),
        (
            "head-b-table-c.toml",
            'Z',
            [40.0, 25.0, 60.0],
            P451 {
                b: Ax(75.0, -85.0, 0.0, 3),
                c: Ax(270.0, 90.0, 0.0, 2),
                points: 3,
                ..P451::default()
            },
            None,
        ),
        (
            "horizontal-y-sphere.toml",
            'Y',
            [50.0, -30.0, 80.0],
            P451 {
                a: Ax(65.0, -55.0, 0.0, 2),
                c: Ax(-100.0, 170.0, 0.0, 2),
                q320: 0.8,
                backlash: 0.5,
                ..P451::default()
            },
            None,
        ),
        (
            "horizontal-x-head-b-table-c.toml",
            'X',
            [40.0, 25.0, 60.0],
            P451 {
                b: Ax(35.0, -55.0, 0.0, 2),
                c: Ax(110.0, 250.0, 0.0, 2),
                points: 3,
                ..P451::default()
            },
            None,
        ),
    ]
}

/// Watched on the simulated machine as it moves: whenever a rotary axis is moving,
/// no linear axis moves, and the ball centre stands at least Q407 + R + SET_UP + Q320
/// above the sphere centre along the tool axis (Q408 = 0), or Q407 + R + SET_UP
/// (Q408 > 0), less 0.05 mm for the injected errors. On the A/C table (Q431 = 1 and
/// 3, Q431 = 0 with the axes left off their reference, Q408 > 0 with Q432), the B head
/// over a C table, and both horizontal machines (tool axis Y and X); the results are
/// those of the other tests (ok, same kinematics).
#[test]
fn while_a_rotary_axis_moves_the_ball_stands_above_the_sphere() {
    let cases = watched_cases();
    for (k, (name, axis, centre, p, before)) in cases.into_iter().enumerate() {
        let sc = load(name);
        let mut cfg = cycles_config(&sc);
        let t = "XYZ".find(axis).unwrap();
        let set_up = cfg.probe("TOUCH_PROBE").unwrap().set_up;
        let rs = p.radius + sc.probe.ball_radius;
        let text = match before {
            None => program(
                &p,
                axis,
                start_at(centre, t, rs, 0.0, 0.0, set_up + p.q320),
                "",
            ),
            Some(turn) => {
                with_preset_row(&mut cfg, centre);
                let mut away = [70.0, 0.0, 0.0];
                away[t] = 60.0;
                let base = "10 CYCL DEF 247 DATUM SETTING ~\n  Q339=+1 ;DATUM NUMBER\n";
                program(&p, axis, away, &format!("{base}{turn}"))
            }
        };
        let (m, seen) = watched(&sc, t);
        let r = run_on(&text, m, &cfg, "watched");
        result(&r);
        let seen = seen.lock().unwrap();
        let clear = if p.q408 > 0.0 { 0.0 } else { p.q320 };
        let need = rs + set_up + clear - 0.05;
        eprintln!(
            "case {k} ({name}): {} samples with a rotary axis moving, the ball at least {:.4} mm above the sphere centre (needed {need:.4})",
            seen.samples, seen.lowest.0
        );
        assert!(
            seen.samples > 100,
            "case {k} ({name}): {} samples with a rotary axis moving",
            seen.samples
        );
        assert!(
            seen.lowest.0 >= need,
            "case {k} ({name}): a rotary axis moved with the ball {:.4} mm above the sphere centre along the tool axis (at least {need:.4} needed) at {}",
            seen.lowest.0,
            seen.lowest.1
        );
        assert!(
            seen.together.is_empty(),
            "case {k} ({name}): a linear axis moved with a rotary one: {:?}",
            seen.together
        );
    }
}

/// Q408 = 0 where the height that clears the sphere at every angle of a turn is
/// outside the software limits (the sphere far from the rotary axes rises with
/// them): `check` and `run` refuse the block, naming the turn, the height and the
/// limits, before anything moves. A/C table with tool axis Z (a turn between
/// measurements; Q431 = 0 with A left where the sphere stands high), and tool axis Y.
#[test]
fn a_turn_whose_clearing_height_is_outside_the_limits_is_refused() {
    // The far sphere: Q407 + R + SET_UP over its highest point on the way is above
    // the tool axis's upper limit, its pole at A = 0 is not.
    let far = |name: &str, c: [f64; 3]| {
        let mut sc = load(name);
        sc.spheres[0].center = c.into();
        sc
    };
    let p = P451 {
        mode: 0,
        a: Ax(-60.0, 60.0, 0.0, 2),
        ..P451::default()
    };
    let q431_0 = format!(
        "0 BEGIN PGM K451 MM\n1 TOOL CALL \"TOUCH_PROBE\" Z\n2 L Z+390 R0 FMAX M91\n\
3 L X+120 Y-250 R0 FMAX M91\n4 L A-40 R0 FMAX\n\
10 CYCL DEF 247 DATUM SETTING ~\n  Q339=+1 ;DATUM NUMBER\n{}99 END PGM K451 MM\n",
        block451(&P451 {
            preset: 0,
            a: Ax(-30.0, 30.0, 0.0, 2),
            ..p.clone()
        })
    );
    // (scenario, program, preset row 1, the height's axis and its limit).
    let cases = vec![
        (
            far("demo-sphere.toml", [50.0, -250.0, 300.0]),
            program(&p, 'Z', [50.0, -250.0, 317.5], ""),
            None,
            "Z",
        ),
        (
            far("horizontal-y-sphere.toml", [50.0, 195.0, 205.0]),
            program(
                &P451 {
                    q320: 1.0,
                    ..p.clone()
                },
                'Y',
                [50.0, 213.5, 205.0],
                "",
            ),
            None,
            "Y",
        ),
        (
            far("demo-sphere.toml", [50.0, -250.0, 300.0]),
            q431_0,
            Some([50.0, -250.0, 300.0]),
            "Z",
        ),
    ];
    for (k, (sc, text, row, axis)) in cases.into_iter().enumerate() {
        let mut cfg = cycles_config(&sc);
        if let Some(c) = row {
            with_preset_row(&mut cfg, c);
        }
        let r = run_text(&text, &sc, &cfg, "turn-limits");
        let check = r
            .check
            .clone()
            .unwrap_or_else(|| panic!("case {k}: check accepted a turn above the limits"));
        let msg = check.split_once("): ").map_or(check.as_str(), |(_, m)| m);
        assert!(
            msg.starts_with("the rotary axes turn from A")
                && msg.contains(&format!("only with the probe at {axis}+"))
                && msg.contains("outside the software limits -")
                && msg.contains("nothing moved"),
            "case {k}: {check}"
        );
        let stopped = r.report.stopped.clone().unwrap_or_default();
        assert!(
            stopped.contains(msg),
            "case {k}: run: {stopped}\ncheck: {check}"
        );
        assert!(
            !r.events
                .iter()
                .any(|e| matches!(e, ProgressEvent::Move { .. } | ProgressEvent::Probe { .. })),
            "case {k}: something moved"
        );
    }
}

/// Q408 near the end of travel with the probe started lower over the pole than
/// Q320 + SET_UP (which the docs allow): the sphere, and the preset Q431 = 1 sets at
/// its centre, stand higher than `check` would assume from the start, so the
/// retraction Q408 above it leaves the software limits. `check` plans for every start
/// the docs allow (from just above the pole), so it refuses the block, and `run`
/// refuses it before its first move with the same message, which names Q408, the
/// limit, why, and the highest Q408 that stays inside; that one runs.
#[test]
fn q408_near_the_end_of_travel_is_refused_for_every_start_height_over_the_pole() {
    let sc = load("demo-sphere.toml");
    let cfg = cycles_config(&sc);
    // Ball 0.5 mm over the pole; Z's limit is +400. From the start, SET_UP + Q320
    // = 2 mm below it would put the centre at Z+78.5 (retracting to Z+399.0); the
    // sphere is at Z+80 (Z+400.5), and from just over the pole at Z+80.5 (Z+401).
    let s = start_at([50.0, -30.0, 80.0], 2, 15.5, 0.0, 0.0, 0.5);
    let mut p = P451 {
        mode: 0,
        q408: 320.5,
        c: Ax(90.0, 270.0, 0.0, 3),
        ..P451::default()
    };
    let r = run_text(&program(&p, 'Z', s, ""), &sc, &cfg, "q408-travel");
    let check = r
        .check
        .clone()
        .expect("check accepted a Q408 that leaves the limits from a lower start");
    assert!(
        check.contains("(cycle 451): Q408=320.5: the retraction height Z+401.0000")
            && check.contains("outside the software limits -200.0000 .. +400.0000")
            && check.contains("when the probe starts just above the sphere's pole")
            && check.contains(
                "the highest Q408 that stays inside from every start the docs allow is 319.5000"
            ),
        "{check}"
    );
    let stopped = r.report.stopped.clone().unwrap_or_default();
    let msg = &check[check.find("Q408=").unwrap()..];
    assert!(stopped.contains(msg), "run: {stopped}\ncheck: {check}");
    assert!(
        !r.events
            .iter()
            .any(|e| matches!(e, ProgressEvent::Move { .. } | ProgressEvent::Probe { .. })),
        "something moved"
    );
    // The value the message names runs from that start.
    p.q408 = 319.5;
    let r = run_text(&program(&p, 'Z', s, ""), &sc, &cfg, "q408-travel-ok");
    let (_, preset) = result(&r);
    assert!((preset[2] - 80.0).abs() < 1e-3, "{preset:?}");
}
