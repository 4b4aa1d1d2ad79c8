//! `TCHPRAUTO.html`, the measuring log of cycle 451 (seeds 000/004, "Protocol function";
//! spec.md): date and time, program, tool, active kinematics, mode, incidence angles;
//! per measured axis start and end angle, number of points, measuring circle radius,
//! mean backlash, the axis's position before and after optimisation (relative to the
//! start of the kinematic chain), angular position error, standard deviation, maximum
//! deviation, angular error, the preset shift in all axes, the mean positioning error
//! and its standard deviation about 0; and one inline SVG plot per error component
//! (`EXC`, `EYC`, `EZC`, ...: the deviation of the sphere centre in X/Y/Z over the axis
//! angle; red measured, green optimised).

use super::report::{AxisReport, KinematicsReport};
use crate::kinematics::model::{ErrorPart, ErrorSet, Joint};
use crate::measuring_log::{escape as esc, program_name, write, MeasuringLogError};
use hal::Axis;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

pub const KINEMATICS_LOG: &str = "TCHPRAUTO.html";

fn mode_text(mode: u8) -> &'static str {
    match mode {
        0 => "0 = check",
        1 => "1 = optimise position",
        2 => "2 = optimise orientation and position",
        _ => "3 = optimise machine datum, orientation and position",
    }
}

fn v3(v: &[f64; 3]) -> String {
    format!("X{:+.4} Y{:+.4} Z{:+.4}", v[0], v[1], v[2])
}

/// The full text of the log.
pub fn kinematics_log_html(
    r: &KinematicsReport,
    program: Option<&Path>,
    when: &str,
    written: Option<&str>,
) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>TCHPRAUTO cycle 451</title>\n<style>body{{font-family:sans-serif}} table{{border-collapse:collapse;margin:0.5em 0}} td,th{{border:1px solid #999;padding:2px 6px;text-align:right}} th{{background:#eee}} td.l,th.l{{text-align:left}} svg{{margin:0.5em 1em 0.5em 0}}</style></head><body>"
    );
    let _ = writeln!(s, "<h1>Cycle 451 MEASURE KINEMATICS</h1>");
    let _ = writeln!(s, "<table>");
    let row = |s: &mut String, k: &str, v: &str| {
        let _ = writeln!(
            s,
            "<tr><th class=\"l\">{k}</th><td class=\"l\">{v}</td></tr>"
        );
    };
    row(&mut s, "Date and time", &esc(when));
    row(&mut s, "NC program", &esc(&program_name(program)));
    row(&mut s, "Tool", &esc(&r.probe));
    row(
        &mut s,
        "Active kinematics",
        &format!(
            "machine {}, {}",
            esc(&r.machine),
            esc(&r.kinematics_file.display().to_string())
        ),
    );
    row(&mut s, "Mode (Q406)", mode_text(r.mode));
    row(
        &mut s,
        "Incidence angles",
        &r.incidence
            .iter()
            .map(|(a, v)| format!("{a} {v:+.4} deg"))
            .collect::<Vec<_>>()
            .join(", "),
    );
    row(&mut s, "Estimator", &esc(&r.estimator));
    if let Some(t) = &r.machine_time {
        row(&mut s, "Machine time", &t.to_string());
    }
    row(&mut s, "Preset before", &v3(&r.preset_before));
    if r.preset_set || !r.preset.contains("preset not set") {
        row(&mut s, "Preset after", &v3(&r.preset_after));
    } else {
        // Q431 = 1..3 in mode 0 (or refused kinematics): measured, not set.
        let why = if r.mode == 0 {
            "preset not set (mode 0)"
        } else {
            "preset not set (the kinematics were not accepted)"
        };
        row(&mut s, "Preset after", why);
        row(&mut s, "Sphere centre measured", &v3(&r.preset_after));
    }
    row(&mut s, "Preset shift (all axes)", &v3(&r.preset_shift));
    row(&mut s, "Offset error Q147..Q149", &v3(&r.offset_error));
    row(
        &mut s,
        "Kinematics",
        &esc(written.unwrap_or(if r.mode == 0 {
            "not changed (mode 0)"
        } else {
            "not changed"
        })),
    );
    let _ = writeln!(s, "</table>");

    for a in &r.axes {
        axis_section(&mut s, a, &r.incidence);
    }

    let _ = writeln!(s, "<h2>All errors (mm, deg)</h2>\n<table><tr><th class=\"l\">error</th><th>before</th><th>after &#177; standard uncertainty (k = 1)</th><th>change</th></tr>");
    for (name, before) in &r.errors_before {
        let after = r.errors_after.get(name).copied().unwrap_or(0.0);
        let _ = writeln!(
            s,
            "<tr><td class=\"l\">{name}</td><td>{before:+.6}</td><td>{after:+.6}{}</td><td>{:+.6}</td></tr>",
            plus_minus(&r.errors_u, name),
            after - before
        );
    }
    let _ = writeln!(s, "</table>");
    if !r.errors_u.is_empty() {
        let _ = writeln!(s, "<p>&#177; u: the standard uncertainty (k = 1) of each identified error, from the scatter of the probed points through the sphere fits and the identification. It does not cover the sphere's own form error, temperature, or an uncalibrated probe.</p>");
    }
    if !r.notes.is_empty() {
        let _ = writeln!(s, "<h2>Notes</h2><ul>");
        for n in &r.notes {
            let _ = writeln!(s, "<li>{}</li>", esc(n));
        }
        let _ = writeln!(s, "</ul>");
    }
    let _ = writeln!(s, "</body></html>");
    s
}

/// ` &#177; u` of error `name`, when it has one.
fn plus_minus(u: &std::collections::BTreeMap<String, f64>, name: &str) -> String {
    u.get(name)
        .map_or_else(String::new, |u| format!(" &#177; {u:.6}"))
}

fn error(map: &std::collections::BTreeMap<String, f64>, axis: Axis, part: ErrorPart) -> f64 {
    map.get(ErrorSet::name(ErrorSet::index(axis, part)))
        .copied()
        .unwrap_or(0.0)
}

/// The axis's table (before and after optimisation) and its positions.
fn axis_section(
    s: &mut String,
    a: &AxisReport,
    _incidence: &std::collections::BTreeMap<String, f64>,
) {
    let axis = Axis::from_name(&a.axis).unwrap_or(Axis::C);
    let _ = writeln!(s, "<h2>Axis {}</h2>\n<table>", a.axis);
    let mut row = |k: &str, before: String, after: String| {
        let _ = writeln!(
            s,
            "<tr><th class=\"l\">{k}</th><td>{before}</td><td>{after}</td></tr>"
        );
    };
    row(
        "",
        "before optimisation".into(),
        "after optimisation".into(),
    );
    row(
        "Start angle / end angle",
        format!("{:+.4} / {:+.4} deg", a.start, a.end),
        String::new(),
    );
    row("Number of points", a.points.to_string(), String::new());
    row(
        "Measuring circle radius",
        format!("{:.4} mm", a.circle_radius),
        String::new(),
    );
    row(
        "Mean backlash",
        a.backlash
            .map_or_else(|| "not measured".into(), |b| format!("{b:+.5} deg")),
        String::new(),
    );
    let none = std::collections::BTreeMap::new();
    let name = |part| ErrorSet::name(ErrorSet::index(axis, part));
    let pos = |m: &std::collections::BTreeMap<String, f64>, u| {
        let e = ErrorSet::from_map(m);
        let q = Joint::new(axis, a.pivot, e.axis(axis)).point;
        let [p0, p1] = [ErrorPart::Position(0), ErrorPart::Position(1)];
        format!(
            "X{:+.6} Y{:+.6} Z{:+.6} mm ({}={:+.6}{} {}={:+.6}{})",
            q.x,
            q.y,
            q.z,
            name(p0),
            error(m, axis, p0),
            plus_minus(u, name(p0)),
            name(p1),
            error(m, axis, p1),
            plus_minus(u, name(p1)),
        )
    };
    row(
        "Axis position (a point of the axis line relative to the start of the kinematic chain)",
        pos(&a.errors_before, &none),
        pos(&a.errors_after, &a.errors_u),
    );
    let ori = |m: &std::collections::BTreeMap<String, f64>, u| {
        let [o0, o1] = [ErrorPart::Orientation(0), ErrorPart::Orientation(1)];
        format!(
            "{}={:+.6}{} {}={:+.6}{} deg",
            name(o0),
            error(m, axis, o0),
            plus_minus(u, name(o0)),
            name(o1),
            error(m, axis, o1),
            plus_minus(u, name(o1)),
        )
    };
    row(
        "Angular position error",
        ori(&a.errors_before, &none),
        ori(&a.errors_after, &a.errors_u),
    );
    row(
        "Standard deviation (dispersion)",
        format!("{:.6} mm", a.dispersion_before),
        format!("{:.6} mm", a.dispersion_after),
    );
    row(
        "Maximum deviation",
        format!("{:.6} mm", a.max_before),
        format!("{:.6} mm", a.max_after),
    );
    let zero = |m: &std::collections::BTreeMap<String, f64>, u| {
        format!(
            "{}={:+.6}{} deg",
            name(ErrorPart::Zero),
            error(m, axis, ErrorPart::Zero),
            plus_minus(u, name(ErrorPart::Zero)),
        )
    };
    row(
        "Angular error (zero position)",
        zero(&a.errors_before, &none),
        zero(&a.errors_after, &a.errors_u),
    );
    row(
        "Positioning error: mean / standard deviation about 0",
        String::new(),
        format!(
            "{:+.6} / {:.6} deg",
            a.positioning_error_mean, a.positioning_error_std
        ),
    );
    let _ = writeln!(s, "</table>");
    positions_section(s, a);
}

/// Per position of an axis: its angles, sphere and deviations, and one plot per
/// component.
fn positions_section(s: &mut String, a: &AxisReport) {
    let _ = writeln!(
        s,
        "<table><tr><th>#</th><th class=\"l\">angles (deg)</th><th>centre X</th><th>Y</th><th>Z</th><th>radius</th><th>dev. before X</th><th>Y</th><th>Z</th><th>dev. after X</th><th>Y</th><th>Z</th></tr>"
    );
    for (k, p) in a.positions.iter().enumerate() {
        let angles = p
            .angles
            .iter()
            .map(|(n, v)| format!("{n}{v:+.4}"))
            .collect::<Vec<_>>()
            .join(" ");
        let _ = writeln!(
            s,
            "<tr><td>{}</td><td class=\"l\">{angles}</td><td>{:+.5}</td><td>{:+.5}</td><td>{:+.5}</td><td>{:.5}</td><td>{:+.6}</td><td>{:+.6}</td><td>{:+.6}</td><td>{:+.6}</td><td>{:+.6}</td><td>{:+.6}</td></tr>",
            if p.reference { "ref".to_string() } else { k.to_string() },
            p.centre[0],
            p.centre[1],
            p.centre[2],
            p.radius,
            p.deviation_before[0],
            p.deviation_before[1],
            p.deviation_before[2],
            p.deviation_after[0],
            p.deviation_after[1],
            p.deviation_after[2],
        );
    }
    let _ = writeln!(s, "</table>\n<div>");
    for (c, comp) in ["X", "Y", "Z"].iter().enumerate() {
        let pts: Vec<(f64, f64, f64)> = a
            .positions
            .iter()
            .map(|p| {
                (
                    p.angles.get(&a.axis).copied().unwrap_or(0.0),
                    p.deviation_before[c],
                    p.deviation_after[c],
                )
            })
            .collect();
        s.push_str(&svg_plot(&format!("E{comp}{}", a.axis), &a.axis, &pts));
    }
    let _ = writeln!(s, "</div>");
}

/// One plot: x the axis angle (deg), y the deviation (mm); red the measured values,
/// green the optimised ones.
pub fn svg_plot(name: &str, axis: &str, points: &[(f64, f64, f64)]) -> String {
    let (w, h) = (440.0, 240.0);
    let (l, r, t, b) = (70.0, 15.0, 28.0, 38.0);
    let mut pts = points.to_vec();
    pts.sort_by(|p, q| p.0.total_cmp(&q.0));
    let (mut x0, mut x1) = pts
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.0), hi.max(p.0))
        });
    if !x0.is_finite() || x1 - x0 < 1e-9 {
        x0 = x0.min(0.0) - 1.0;
        x1 = x1.max(0.0) + 1.0;
    }
    let ymax = pts
        .iter()
        .flat_map(|p| [p.1.abs(), p.2.abs()])
        .fold(0.0, f64::max)
        .max(1e-6)
        * 1.1;
    let sx = |x: f64| l + (x - x0) / (x1 - x0) * (w - l - r);
    let sy = |y: f64| t + (ymax - y) / (2.0 * ymax) * (h - t - b);
    let mut s = String::new();
    let _ = write!(
        s,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" viewBox=\"0 0 {w} {h}\"><title>{name}</title>"
    );
    let _ = write!(
        s,
        "<rect x=\"{l}\" y=\"{t}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"#888\"/>",
        w - l - r,
        h - t - b
    );
    let _ = write!(
        s,
        "<text x=\"{}\" y=\"18\" font-size=\"14\" text-anchor=\"middle\" font-weight=\"bold\">{name}</text>",
        w / 2.0
    );
    // Zero line and ticks.
    let _ = write!(
        s,
        "<line x1=\"{l}\" y1=\"{y}\" x2=\"{}\" y2=\"{y}\" stroke=\"#bbb\" stroke-dasharray=\"4 3\"/>",
        w - r,
        y = sy(0.0)
    );
    for yv in [-ymax / 1.1, 0.0, ymax / 1.1] {
        let _ = write!(
            s,
            "<text x=\"{}\" y=\"{}\" font-size=\"10\" text-anchor=\"end\">{yv:+.5}</text>",
            l - 4.0,
            sy(yv) + 3.0
        );
    }
    for xv in [x0, (x0 + x1) / 2.0, x1] {
        let _ = write!(
            s,
            "<text x=\"{}\" y=\"{}\" font-size=\"10\" text-anchor=\"middle\">{xv:.1}</text>",
            sx(xv),
            h - b + 14.0
        );
    }
    let _ = write!(
        s,
        "<text x=\"{}\" y=\"{}\" font-size=\"11\" text-anchor=\"middle\">{axis} axis angle (deg)</text>",
        (l + w - r) / 2.0,
        h - 6.0
    );
    let _ = write!(
        s,
        "<text x=\"14\" y=\"{}\" font-size=\"11\" text-anchor=\"middle\" transform=\"rotate(-90 14 {})\">deviation (mm)</text>",
        (t + h - b) / 2.0,
        (t + h - b) / 2.0
    );
    for (colour, which, label) in [("red", 1, "measured"), ("green", 2, "optimised")] {
        let line: Vec<String> = pts
            .iter()
            .map(|p| {
                let y = if which == 1 { p.1 } else { p.2 };
                format!("{:.2},{:.2}", sx(p.0), sy(y))
            })
            .collect();
        let _ = write!(
            s,
            "<polyline class=\"{label}\" fill=\"none\" stroke=\"{colour}\" stroke-width=\"2\" points=\"{}\"/>",
            line.join(" ")
        );
        for p in &line {
            let (x, y) = p.split_once(',').unwrap_or(("0", "0"));
            let _ = write!(
                s,
                "<circle cx=\"{x}\" cy=\"{y}\" r=\"2.5\" fill=\"{colour}\"/>"
            );
        }
    }
    let _ = write!(
        s,
        "<text x=\"{}\" y=\"{}\" font-size=\"10\" fill=\"red\">measured</text><text x=\"{}\" y=\"{}\" font-size=\"10\" fill=\"green\">optimised</text>",
        l + 6.0,
        t + 12.0,
        l + 70.0,
        t + 12.0
    );
    s.push_str("</svg>\n");
    s
}

/// Writes `TCHPRAUTO.html` into `dir`.
pub fn write_kinematics_log(
    dir: &Path,
    report: &KinematicsReport,
    program: Option<&Path>,
    when: &str,
    written: Option<&str>,
) -> Result<PathBuf, MeasuringLogError> {
    write(
        dir,
        KINEMATICS_LOG,
        &kinematics_log_html(report, program, when, written),
    )
}
