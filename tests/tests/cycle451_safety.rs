//! Cycle 451's measuring sequence against what the operator got wrong (issue 34): a
//! mistyped Q407, a preset away from the sphere with Q431 = 0/2, rotary axes left
//! turned with Q431 = 1/3, starts beyond the locating reach, and the limit refusal
//! on the B head. On the simulator's physics without a bus ([`WorldMachine`]): any
//! positioning move that touches the sphere fails the run, so a collision shows.

use cycles::program::Program;
use cycles::progress::ProgressEvent;
use cycles::results::{ProgramReport, Status};
use cycles::runner::{preflight_program, run_program, RunOptions};
use hal::{Axis, AxisPositions};
use probebridge_tests::world_machine::WorldMachine;
use probebridge_tests::{configs_dir, cycles_config};
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
    a: Ax,
    b: Ax,
    c: Ax,
    points: u32,
    preset: u8,
    q408: f64,
}

impl Default for P451 {
    fn default() -> Self {
        P451 {
            mode: 2,
            radius: 12.5,
            q320: 0.0,
            a: NONE,
            b: NONE,
            c: NONE,
            points: 4,
            preset: 1,
            q408: 0.0,
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
  Q380=+0 ;REFERENCE ANGLE ~\n{}{}{}  Q423={:+} ;NO. OF PROBE POINTS ~\n  Q431={:+} ;PRESET ~\n\
  Q432=+0 ;BACKLASH, ANG. RANGE\n",
        p.mode,
        p.radius,
        p.q320,
        p.q408,
        ax(p.a, [411, 412, 413, 414]),
        ax(p.b, [415, 416, 417, 418]),
        ax(p.c, [419, 420, 421, 422]),
        p.points,
        p.preset,
    )
}

/// Tool axis Z: up, `before` (blocks that may turn the axes up there), over `start`,
/// down to it, then the 451 block.
fn program(p: &P451, start: [f64; 3], before: &str) -> String {
    format!(
        "0 BEGIN PGM K451 MM\n1 TOOL CALL \"TOUCH_PROBE\" Z\n2 L Z+250 R0 FMAX\n{before}\
5 L X{:+.4} Y{:+.4} R0 FMAX\n6 L Z{:+.4} R0 FMAX\n{}99 END PGM K451 MM\n",
        start[0],
        start[1],
        start[2],
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
    let d = std::env::temp_dir().join(format!("pb-451safe-{name}-{}-{n}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

struct Run {
    report: ProgramReport,
    events: Vec<ProgressEvent>,
    /// What `check` says of the same program: `None` = ok.
    check: Option<String>,
    /// Whether the run wrote the kinematics file or the preset table.
    written: bool,
}

fn run(text: &str, sc: &sim::Scenario, cfg: &cycles::CyclesConfig, tag: &str) -> Run {
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
        kinematics: Some(kinematics.clone()),
        estimator: None,
    };
    let mut m = WorldMachine::new(sc);
    let report = run_program(&program, &mut m, cfg, &mut opts);
    let written = kinematics.exists() || cfg.presets.path.exists();
    let _ = std::fs::remove_dir_all(&dir);
    Run {
        report,
        events,
        check,
        written,
    }
}

fn json(r: &Run) -> serde_json::Value {
    let v: serde_json::Value = serde_json::from_str(&r.report.to_json()).unwrap();
    v["cycles"][0].clone()
}

/// The 451 cycle's message (the run stopped in it).
fn stopped(r: &Run) -> String {
    let c = &r.report.cycles[0];
    assert_eq!(c.status, Status::Error, "the cycle did not stop");
    c.message.clone().unwrap_or_default()
}

/// No positioning move touched the sphere (the world machine refuses it).
fn no_collision(r: &Run, case: &str) {
    for c in &r.report.cycles {
        let m = c.message.as_deref().unwrap_or("");
        assert!(
            !m.contains("touched while positioning") && !m.contains("collision"),
            "{case}: a positioning move touched the sphere: {m}"
        );
    }
    if let Some(s) = &r.report.stopped {
        assert!(!s.contains("touched while positioning"), "{case}: {s}");
    }
}

/// Moves and probing moves of the cycle, in order (after its start).
/// A stop with Q431=0/2 before the measurement: nothing written, no "measuring" note.
fn stopped_before_measuring(r: &Run, case: &str, what: &str) {
    assert!(!r.written, "{case}: something was written");
    assert!(
        !r.events.iter().any(|e| matches!(
            e,
            ProgressEvent::Note { text, .. } if text.starts_with("measuring ")
        )),
        "{case}: {what}"
    );
}

fn cycle_motion(r: &Run) -> Vec<&ProgressEvent> {
    let started = r
        .events
        .iter()
        .position(|e| matches!(e, ProgressEvent::CycleStarted { .. }))
        .expect("the cycle started");
    r.events[started..]
        .iter()
        .filter(|e| matches!(e, ProgressEvent::Move { .. } | ProgressEvent::Probe { .. }))
        .collect()
}

fn probes(r: &Run) -> usize {
    cycle_motion(r)
        .iter()
        .filter(|e| matches!(e, ProgressEvent::Probe { .. }))
        .count()
}

/// The number after `key` in `text`.
fn number_after(text: &str, key: &str) -> f64 {
    let rest = &text[text
        .find(key)
        .unwrap_or_else(|| panic!("no {key:?} in {text}"))
        + key.len()..];
    let s: String = rest
        .trim_start()
        .chars()
        .take_while(|c| c.is_ascii_digit() || *c == '.' || *c == '-' || *c == '+')
        .collect();
    s.parse()
        .unwrap_or_else(|_| panic!("no number after {key:?} in {text}"))
}

/// Q407 typed 30 % and 15 % small, 2 mm and 1.2 mm small, 1.5 mm and 20 % large
/// (the sphere's radius is 12.5): the first locating pass finds the real sphere and
/// the cycle stops there, before the next move, naming Q407, the typed and the
/// measured radius; nothing is written and no positioning move touches the sphere.
/// Before, 2 mm small descended onto the sphere in the second pass.
#[test]
fn a_mistyped_q407_stops_after_the_first_locating_pass() {
    let sc = load("demo-sphere.toml");
    let cfg = cycles_config(&sc);
    let centre = [50.0, -30.0, 80.0];
    for typed in [12.5 * 0.7, 12.5 * 0.85, 10.5, 11.3, 14.0, 12.5 * 1.2] {
        for (off, deg) in [(0.0, 0.0), (0.3, 115.0)] {
            let p = P451 {
                radius: typed,
                c: Ax(90.0, 270.0, 0.0, 2),
                ..P451::default()
            };
            // Over the sphere as the operator sees it, Q320 + SET_UP over its pole.
            let rs = typed + 3.0;
            let phi = f64::to_radians(deg);
            let start = [
                centre[0] + off * rs * phi.cos(),
                centre[1] + off * rs * phi.sin(),
                centre[2] + 12.5 + 3.0 + 2.0,
            ];
            let case = format!("Q407={typed} start {off} x {rs} at {deg} deg");
            let r = run(&program(&p, start, ""), &sc, &cfg, "q407");
            no_collision(&r, &case);
            let m = stopped(&r);
            assert!(
                m.contains("first pass") && m.contains("Q407"),
                "{case}: {m}"
            );
            let q407 = number_after(&m, "Q407 =");
            assert!((q407 - typed).abs() < 1e-3, "{case}: {m}");
            let measured = number_after(&m, "the fitted sphere radius");
            assert!((measured - 12.5).abs() < 0.01, "{case}: {m}");
            // The pole and the first pass's points, nothing probed after them.
            assert_eq!(probes(&r), 1 + p.points as usize, "{case}: {m}");
            assert!(!r.written, "{case}: something was written");
        }
    }
    // Q431 = 0 at the sphere's datum: the sphere located from the pole contact is
    // measured against Q407 the same way.
    for typed in [10.5, 12.5 * 1.2] {
        let mut cfg = cycles_config(&sc);
        with_preset_row(&mut cfg, centre);
        let p = P451 {
            radius: typed,
            preset: 0,
            c: Ax(90.0, 270.0, 0.0, 2),
            ..P451::default()
        };
        let text = format!(
            "0 BEGIN PGM K451 MM\n1 TOOL CALL \"TOUCH_PROBE\" Z\n10 CYCL DEF 247 DATUM SETTING ~\n  Q339=+1 ;DATUM NUMBER\n\
11 L Z+60 R0 FMAX\n12 L X+70 Y+0 R0 FMAX\n{}99 END PGM K451 MM\n",
            block451(&p)
        );
        let case = format!("Q431=0, Q407={typed}");
        let r = run(&text, &sc, &cfg, "q407-0");
        no_collision(&r, &case);
        let m = stopped(&r);
        assert!(
            m.contains("first pass") && m.contains("Q407"),
            "{case}: {m}"
        );
        let measured = number_after(&m, "the fitted sphere radius");
        assert!((measured - 12.5).abs() < 0.01, "{case}: {m}");
        assert!(!r.written, "{case}: something was written");
    }
}

/// `cfg` with preset row 1 at `at`, activated by cycle 247 in the program.
fn with_preset_row(cfg: &mut cycles::CyclesConfig, at: [f64; 3]) {
    let mut row = cycles::preset_table::Preset::origin(1);
    [row.x, row.y, row.z] = at;
    cfg.presets.rows.retain(|r| r.number != 1);
    cfg.presets.rows.push(row);
}

/// Q431 = 0 and 2 with the active preset 4.5 to 10 mm from the sphere centre, up to
/// 1.5 x the Q431 = 1 reach (0.9 x (Q407 + R) = 13.95 mm), in the plane, above and
/// below: no positioning move touches the sphere; the cycle stops before it measures,
/// naming how far the sphere centre is from the preset (the number true to 0.05 mm)
/// or that it found no sphere there; nothing is written. Before, it trusted the datum
/// and descended onto the sphere at an equator point.
#[test]
fn q431_0_and_2_stop_when_the_sphere_is_away_from_the_preset() {
    let sc = load("demo-sphere.toml");
    let centre = [50.0, -30.0, 80.0];
    let offsets: [[f64; 3]; 8] = [
        [4.5, 0.0, 0.0],
        [0.0, -6.1, 0.0],
        [-5.0, 5.0, 0.0],
        [7.0, 7.0, 0.0],
        [3.0, -2.0, -4.0],
        [-2.0, 1.0, 5.5],
        [0.0, 0.0, 9.5],
        [9.0, -6.0, 7.5],
    ];
    for preset in [0u8, 2] {
        for off in offsets {
            let mut cfg = cycles_config(&sc);
            // The preset where the operator believes the sphere is.
            let at = [0, 1, 2].map(|i| centre[i] - off[i]);
            with_preset_row(&mut cfg, at);
            let p = P451 {
                preset,
                a: Ax(-60.0, 60.0, 0.0, 2),
                c: Ax(90.0, 270.0, 0.0, 2),
                ..P451::default()
            };
            let base = "10 CYCL DEF 247 DATUM SETTING ~\n  Q339=+1 ;DATUM NUMBER\n";
            let text = format!(
                "0 BEGIN PGM K451 MM\n1 TOOL CALL \"TOUCH_PROBE\" Z\n{base}\
11 L Z+60 R0 FMAX\n12 L X+70 Y+0 R0 FMAX\n{}99 END PGM K451 MM\n",
                block451(&p)
            );
            let case = format!("Q431={preset}, sphere {off:?} from the preset");
            let r = run(&text, &sc, &cfg, "q431-0");
            assert!(r.check.is_none(), "{case}: {:?}", r.check);
            no_collision(&r, &case);
            let m = stopped(&r);
            let dist = off.iter().map(|v| v * v).sum::<f64>().sqrt();
            if m.contains("mm from the preset") {
                assert!(m.contains("set the preset, or use Q431=1"), "{case}: {m}");
                let said = number_after(&m, "the sphere centre is");
                assert!(
                    (said - dist).abs() < 0.05,
                    "{case}: said {said}, true {dist}: {m}"
                );
            } else {
                assert!(
                    m.contains("no sphere") && m.contains("preset"),
                    "{case}: {m}"
                );
            }
            // Stopped where it found that out: nothing measured around the datum.
            stopped_before_measuring(&r, &case, "it went on measuring");
        }
    }
}

/// Q431 = 0 and 2 with Q320 + SET_UP larger than the probe table's DIST (Q320 = 24
/// and 37, DIST = 10): the preset 11 mm, 8.5 mm and 7.8 mm from the sphere centre
/// (inside half of Q320 + SET_UP, beyond half of DIST), and one 33 mm off (no sphere
/// under the pole probe). Every stop names the preset and what to do (the distance
/// where the cycle found the sphere, or that no sphere is where the preset puts it),
/// before anything is measured around the preset; no positioning move touches the
/// sphere; nothing is written; `check` cannot know and accepts. Before, the first
/// three were measured around the preset, and the first equator point ended with
/// "probe did not trigger" and no word of the preset.
#[test]
fn q431_0_and_2_name_the_preset_when_q320_is_larger_than_dist() {
    let sc = load("demo-sphere.toml");
    let centre = [50.0, -30.0, 80.0];
    let cases: [([f64; 3], f64); 4] = [
        ([-11.0, 0.0, 0.0], 24.0),
        ([6.0, -6.0, 0.0], 24.0),
        ([0.0, 7.5, -2.0], 37.0),
        ([0.0, 33.0, 0.0], 24.0),
    ];
    for preset in [0u8, 2] {
        for (off, q320) in cases {
            let mut cfg = cycles_config(&sc);
            with_preset_row(&mut cfg, [0, 1, 2].map(|i| centre[i] - off[i]));
            let p = P451 {
                preset,
                q320,
                a: Ax(-45.0, 45.0, 0.0, 2),
                c: Ax(0.0, 180.0, 0.0, 3),
                points: 5,
                ..P451::default()
            };
            let text = format!(
                "0 BEGIN PGM K451 MM\n1 TOOL CALL \"TOUCH_PROBE\" Z\n10 CYCL DEF 247 DATUM SETTING ~\n  Q339=+1 ;DATUM NUMBER\n\
11 L Z+90 R0 FMAX\n12 L X+70 Y+0 R0 FMAX\n{}99 END PGM K451 MM\n",
                block451(&p)
            );
            let case = format!("Q431={preset} Q320={q320}, sphere {off:?} from the preset");
            let r = run(&text, &sc, &cfg, "q431-0-dist");
            assert!(r.check.is_none(), "{case}: {:?}", r.check);
            no_collision(&r, &case);
            let m = stopped(&r);
            assert!(
                m.contains("preset") && m.contains("use Q431=1"),
                "{case}: {m}"
            );
            let dist = off.iter().map(|v| v * v).sum::<f64>().sqrt();
            if dist < 20.0 {
                let said = number_after(&m, "the sphere centre is");
                assert!(
                    (said - dist).abs() < 0.05,
                    "{case}: said {said}, true {dist}: {m}"
                );
            } else {
                assert!(
                    m.contains("did not trigger")
                        && m.contains("no sphere where the active preset X+50.0000 Y-63.0000 Z+80.0000 puts it"),
                    "{case}: {m}"
                );
            }
            stopped_before_measuring(&r, &case, "it went on measuring around the preset");
        }
    }
}

/// Q431 = 0 with the preset at the sphere centre still runs as before: the result's
/// Q147..Q149 are 0 and the kinematics come out.
#[test]
fn q431_0_at_the_sphere_centre_still_runs() {
    let sc = load("demo-sphere.toml");
    let mut cfg = cycles_config(&sc);
    with_preset_row(&mut cfg, [50.0, -30.0, 80.0]);
    let p = P451 {
        preset: 0,
        mode: 0,
        a: Ax(-60.0, 60.0, 0.0, 2),
        c: Ax(90.0, 270.0, 0.0, 2),
        ..P451::default()
    };
    let text = format!(
        "0 BEGIN PGM K451 MM\n1 TOOL CALL \"TOUCH_PROBE\" Z\n10 CYCL DEF 247 DATUM SETTING ~\n  Q339=+1 ;DATUM NUMBER\n\
11 L Z+60 R0 FMAX\n12 L X+70 Y+0 R0 FMAX\n{}99 END PGM K451 MM\n",
        block451(&p)
    );
    let r = run(&text, &sc, &cfg, "q431-0-ok");
    assert!(r.check.is_none(), "{:?}", r.check);
    assert_eq!(
        r.report.cycles[0].status,
        Status::Ok,
        "{:?}",
        r.report.cycles[0].message
    );
    let v = json(&r);
    for q in ["Q147", "Q148", "Q149"] {
        assert!(
            v["q"][q].as_f64().unwrap().abs() < 1e-3,
            "{q}: {}",
            v["q"][q]
        );
    }
}

/// Q431 = 1 and 3 with C left at +37 deg and A (the tilting table) or B (the swivel
/// head) at -12 deg by the program, and A+25 C-140 with Q408 = 180 (the probe put
/// over the sphere where the turned table holds it, along the turned tool axis): the
/// preset is the sphere centre with the rotary axes at 0, as the simulator's truth
/// has it, to 1e-3 mm (the sphere is measured again with the axes at 0, and that
/// measurement is the reference), and Q147..Q149 are as small; `check` accepts it.
/// Before, the preset was carried back to 0 through the active kinematics, with
/// their errors: 0.01 mm off, and Q147..Q149 as much.
#[test]
fn q431_1_and_3_with_the_rotary_axes_left_turned_set_the_preset_at_0_deg() {
    // (scenario, the turned axes, params).
    let cases = [
        (
            "demo-sphere.toml",
            [(Axis::A, -12.0), (Axis::C, 37.0)],
            P451 {
                a: Ax(-60.0, 60.0, 0.0, 2),
                c: Ax(90.0, 270.0, 0.0, 2),
                ..P451::default()
            },
        ),
        (
            "demo-sphere.toml",
            [(Axis::A, 25.0), (Axis::C, -140.0)],
            P451 {
                mode: 1,
                q408: 180.0,
                a: Ax(-45.0, 45.0, 0.0, 3),
                c: Ax(0.0, 240.0, 0.0, 4),
                points: 5,
                ..P451::default()
            },
        ),
        (
            "head-b-table-c.toml",
            [(Axis::B, -12.0), (Axis::C, 37.0)],
            P451 {
                b: Ax(-40.0, 40.0, 0.0, 2),
                c: Ax(90.0, 270.0, 0.0, 2),
                points: 3,
                ..P451::default()
            },
        ),
    ];
    for (name, axes, params) in cases {
        let sc = load(name);
        let cfg = cycles_config(&sc);
        let kin = sim::kinematics::TrueKinematics::new(&sc.machine, &sc.truth);
        let sphere = sc.spheres[0].center;
        let mut zero = AxisPositions::new();
        let mut turned = AxisPositions::new();
        for (a, v) in axes {
            zero.set(a, 0.0);
            turned.set(a, v);
        }
        for a in [Axis::X, Axis::Y, Axis::Z] {
            zero.set(a, 0.0);
            turned.set(a, 0.0);
        }
        let truth0 = kin.table_to_machine(&zero, sphere);
        let there = kin.table_to_machine(&turned, sphere);
        // The ball Q320 + SET_UP over the pole along the (tilted) tool axis, and the
        // X/Y/Z positions that put it there with the head turned.
        let mut up = there;
        up.fill(0.0);
        up.z = 1.0;
        let n = kin.head_transform(&turned).rotation * up;
        let ball = there + n * (15.5 + 2.0);
        let start = ball - kin.ball_centre_in_machine(&turned);
        let turn: String = axes.iter().map(|(a, v)| format!(" {a}{v:+}")).collect();
        for preset in [1u8, 3] {
            let p = P451 {
                preset,
                ..params.clone()
            };
            let case = format!("{name} Q431={preset}{turn}");
            let r = run(
                &program(&p, start.into(), &format!("3 L{turn} R0 FMAX\n")),
                &sc,
                &cfg,
                "turned",
            );
            assert!(r.check.is_none(), "{case}: {:?}", r.check);
            no_collision(&r, &case);
            let c = &r.report.cycles[0];
            assert_eq!(c.status, Status::Ok, "{case}: {:?}", c.message);
            let v = json(&r);
            let written = &v["kinematics"]["preset_after"];
            for i in 0..3 {
                let w = written[i].as_f64().unwrap();
                assert!(
                    (w - truth0[i]).abs() < 1e-3,
                    "{case}: preset {written} vs the sphere centre at 0 {truth0:?}"
                );
            }
            for q in ["Q147", "Q148", "Q149"] {
                let x = v["q"][q].as_f64().unwrap();
                assert!(x.abs() < 1e-3, "{case}: {q} = {x}");
            }
            assert!(
                r.events.iter().any(|e| matches!(
                    e,
                    ProgressEvent::Note { text, .. } if text.contains("they turn to 0 and the sphere is measured there")
                )),
                "{case}: the sphere was not measured again at 0"
            );
        }
    }
}

/// Starts at 1.1, 1.3 and 1.5 x the locating reach (0.6 x (Q407 + R)) off the centre,
/// at several angles and heights over the pole (3 mm below it, 0.5 mm, Q320 + SET_UP,
/// 1.5 x Q320 + SET_UP + DIST), on the A/C table and on the B head over a C table: no
/// positioning move touches the sphere; the cycle either measures (the same preset as
/// a centred start, 1e-3) or stops with a message naming what to check.
#[test]
fn starts_beyond_the_locating_reach_never_touch_the_sphere_positioning() {
    for (name, centre) in [
        ("demo-sphere.toml", [50.0, -30.0, 80.0]),
        ("head-b-table-c.toml", [40.0, 25.0, 60.0]),
    ] {
        let sc = load(name);
        let cfg = cycles_config(&sc);
        let p = P451 {
            mode: 0,
            points: 3,
            c: Ax(90.0, 270.0, 0.0, 2),
            ..P451::default()
        };
        let rs = 15.5;
        let pole = centre[2] + rs;
        let centred = run(
            &program(&p, [centre[0], centre[1], pole + 2.0], ""),
            &sc,
            &cfg,
            "reach0",
        );
        let c0 = &centred.report.cycles[0];
        assert_eq!(c0.status, Status::Ok, "{name}: {:?}", c0.message);
        let p0 = json(&centred)["kinematics"]["preset_after"].clone();
        let (mut measured, mut refused) = (0, 0);
        for f in [1.1, 1.3, 1.5] {
            for (deg, gap) in [15.0, 140.0, 255.0]
                .into_iter()
                .flat_map(|d| [-3.0, 0.5, 2.0, 18.0].map(|g| (d, g)))
            {
                let off = f * 0.6 * rs;
                let phi = f64::to_radians(deg);
                let start = [
                    centre[0] + off * phi.cos(),
                    centre[1] + off * phi.sin(),
                    pole + gap,
                ];
                let case = format!("{name}: {f} x reach at {deg} deg, {gap} over the pole");
                let r = run(&program(&p, start, ""), &sc, &cfg, "reach");
                assert!(r.check.is_none(), "{case}: {:?}", r.check);
                no_collision(&r, &case);
                let c = &r.report.cycles[0];
                if c.status == Status::Ok {
                    measured += 1;
                    let pr = &json(&r)["kinematics"]["preset_after"];
                    for i in 0..3 {
                        let d = pr[i].as_f64().unwrap() - p0[i].as_f64().unwrap();
                        assert!(d.abs() < 1e-3, "{case}: preset {pr} vs {p0}");
                    }
                } else {
                    refused += 1;
                    let m = c.message.clone().unwrap_or_default();
                    assert!(
                        m.contains("position the probe over the sphere centre"),
                        "{case}: {m}"
                    );
                }
            }
        }
        eprintln!("{name}: {measured} starts measured, {refused} stopped");
    }
}

/// Software-limit refusals on the B head over a C table name where B stands and the
/// block: C measured with B at its incidence angle +90 (Q417, Q431 = 0, Q423 = 4),
/// where the four points around the horizontal stylus cannot all stay above Z-200
/// (the step, "C reference at 0 deg", names no B); and the seed's first example (B
/// and C -90..+90 in 2, Q423 = 4). `check` and `run` alike.
#[test]
fn the_b_head_limit_refusal_names_the_b_position_and_the_block() {
    let sc = load("head-b-table-c.toml");
    let mut cfg = cycles_config(&sc);
    with_preset_row(&mut cfg, [40.0, 25.0, 60.0]);
    let cases = [
        (
            P451 {
                mode: 0,
                preset: 0,
                b: Ax(0.0, 0.0, 90.0, 0),
                c: Ax(90.0, 270.0, 0.0, 2),
                ..P451::default()
            },
            "B+90",
        ),
        (
            P451 {
                mode: 0,
                preset: 0,
                b: Ax(-90.0, 90.0, 0.0, 2),
                c: Ax(-90.0, 90.0, 0.0, 2),
                ..P451::default()
            },
            "B",
        ),
    ];
    for (k, (p, b)) in cases.into_iter().enumerate() {
        let text = format!(
            "0 BEGIN PGM K451 MM\n1 TOOL CALL \"TOUCH_PROBE\" Z\n10 CYCL DEF 247 DATUM SETTING ~\n  Q339=+1 ;DATUM NUMBER\n\
11 L Z+60 R0 FMAX\n12 L X+70 Y+0 R0 FMAX\n{}99 END PGM K451 MM\n",
            block451(&p)
        );
        let r = run(&text, &sc, &cfg, "b-limit");
        let check = r
            .check
            .clone()
            .unwrap_or_else(|| panic!("case {k}: check accepted B+-90 with four points"));
        let stopped = r.report.stopped.clone().unwrap_or_default();
        for m in [check.as_str(), stopped.as_str()] {
            assert!(m.contains("software limits"), "case {k}: {m}");
            assert!(m.contains("block 20"), "case {k}: {m}");
            // The B position in the refusal itself (after the block), not only in a
            // step that names the measured axis.
            let refusal = &m[m.find("software limits").unwrap()..];
            let named =
                refusal.contains(&format!("{b}+90")) || refusal.contains(&format!("{b}-90"));
            let named = named || refusal.contains("B+90") || refusal.contains("B-90");
            assert!(named, "case {k}: the refusal does not name B: {m}");
        }
    }
    // Three points fit at B+90 once turned from Q380: Q431 = 0 locates the sphere
    // there (its first pass's points turned too) and measures C.
    let p = P451 {
        mode: 0,
        preset: 0,
        points: 3,
        b: Ax(0.0, 0.0, 90.0, 0),
        c: Ax(90.0, 270.0, 0.0, 2),
        ..P451::default()
    };
    let text = format!(
        "0 BEGIN PGM K451 MM\n1 TOOL CALL \"TOUCH_PROBE\" Z\n10 CYCL DEF 247 DATUM SETTING ~\n  Q339=+1 ;DATUM NUMBER\n\
11 L Z+60 R0 FMAX\n12 L X+70 Y+0 R0 FMAX\n{}99 END PGM K451 MM\n",
        block451(&p)
    );
    let r = run(&text, &sc, &cfg, "b90-3");
    assert!(r.check.is_none(), "{:?}", r.check);
    no_collision(&r, "B+90, Q423=3");
    let c = &r.report.cycles[0];
    assert_eq!(c.status, Status::Ok, "{:?}", c.message);
}

/// The generated operators' cases of the two classes (issue 34), shrunk, hold every
/// invariant now: Q431 = 1 and 3 with A-12 C+37 left on the A/C table and B-12 C+37
/// on the B head (the preset and Q147..Q149 were 0.01 mm off), and Q431 = 0 with
/// Q320 = 21.524 and the preset 11.7 mm off (a missed probe named nothing).
#[test]
fn the_shrunk_generated_cases_of_both_classes_hold_every_invariant() {
    use probebridge_tests::operator_trials::{self, Case};
    let cases = [
        Case {
            cycle: 451.0,
            q431: 1.0,
            rot1: -12.0,
            rot2: 37.0,
            ..Case::nominal()
        },
        Case {
            cycle: 451.0,
            machine: 1.0,
            q431: 3.0,
            rot1: -12.0,
            rot2: 37.0,
            ..Case::nominal()
        },
        Case {
            cycle: 451.0,
            q320: 21.524,
            q431: 0.0,
            preset_err: 1.257,
            ..Case::nominal()
        },
    ];
    for case in cases {
        assert_eq!(operator_trials::violations(&case), vec![], "{case:?}");
    }
}
