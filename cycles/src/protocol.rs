//! Measuring protocols next to the program (or in the run's output folder):
//! `TCHPR431.TXT` for cycle 431 (Q281), `TCHPR444.html` for cycle 444.

use crate::cycle431::PlaneRecord;
use crate::cycle444::Probing3dRecord;
use crate::program::ProbeAxis;
use crate::tolerance::WorkpieceStatus;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

pub const PLANE_PROTOCOL: &str = "TCHPR431.TXT";
pub const PROBING_3D_PROTOCOL: &str = "TCHPR444.html";

/// `YYYY-MM-DD HH:MM:SS UTC` of now (no time-zone database on the gateway).
pub fn timestamp_utc() -> String {
    let secs = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let (days, rem) = ((secs / 86_400) as i64, secs % 86_400);
    // Civil date from days since 1970-01-01 (H. Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02} {:02}:{:02}:{:02} UTC",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

fn axis_names(axis: ProbeAxis) -> [&'static str; 3] {
    axis.indices().map(|i| hal::Axis::LINEAR[i].name())
}

/// The text of `TCHPR431.TXT`.
pub fn plane_protocol_text(r: &PlaneRecord, program: Option<&Path>, when: &str) -> String {
    let names = axis_names(r.axis);
    let mut s = String::new();
    let _ = writeln!(s, "TCHPR431 MEASURE PLANE");
    let _ = writeln!(s, "Date/time:   {when}");
    let _ = writeln!(
        s,
        "Program:     {}",
        program.map_or_else(|| "-".to_string(), |p| p.display().to_string())
    );
    let _ = writeln!(s, "Block:       {} (line {})", r.block, r.line);
    let _ = writeln!(s, "Probe:       {} (axis {})", r.probe, r.axis);
    let _ = writeln!(s);
    let _ = writeln!(
        s,
        "Point  Nominal {0:>2}/{1}/{2}                      Measured {2}    Q",
        names[0], names[1], names[2]
    );
    for (i, (n, m)) in r.nominal.iter().zip(&r.measured).enumerate() {
        let _ = writeln!(
            s,
            "{:>5}  {:+12.4} {:+12.4} {:+12.4}   {:+12.4}   Q{}",
            i + 1,
            n[0],
            n[1],
            n[2],
            m[2],
            173 + i
        );
    }
    let a = &r.angles;
    let _ = writeln!(s);
    let _ = writeln!(s, "Spatial angle A  Q170 = {:+.4} deg", a.spa);
    let _ = writeln!(s, "Spatial angle B  Q171 = {:+.4} deg", a.spb);
    let _ = writeln!(s, "Spatial angle C  Q172 = {:+.4} deg", a.spc);
    let _ = writeln!(s, "Projection A     Q158 = {:+.4} deg", a.proj_a);
    let _ = writeln!(s, "Projection B     Q159 = {:+.4} deg", a.proj_b);
    let _ = writeln!(
        s,
        "Plane normal     ({:+.6}, {:+.6}, {:+.6})",
        a.normal.x, a.normal.y, a.normal.z
    );
    s
}

pub fn write_plane_protocol(
    dir: &Path,
    r: &PlaneRecord,
    program: Option<&Path>,
) -> std::io::Result<PathBuf> {
    let path = dir.join(PLANE_PROTOCOL);
    std::fs::create_dir_all(dir)?;
    std::fs::write(&path, plane_protocol_text(r, program, &timestamp_utc()))?;
    Ok(path)
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

fn colour_style(status: WorkpieceStatus) -> String {
    match status {
        WorkpieceStatus::Undefined => String::new(),
        s => format!(" style=\"background:{}\"", s.colour()),
    }
}

/// The HTML protocol of all 444 points of a run. Per axis: the probing direction
/// (length = configured probing path), nominal, the limits and the deviation along the
/// normal split onto the axis (when QS400 sets a tolerance), the actual coordinate;
/// values coloured by the workpiece status.
pub fn probing3d_protocol_html(
    records: &[Probing3dRecord],
    program: Option<&Path>,
    when: &str,
) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>TCHPR444 PROBING 3D</title>\n\
         <style>table{{border-collapse:collapse;margin-bottom:1em}}td,th{{border:1px solid #888;padding:2px 8px;text-align:right}}</style>\n\
         </head><body>\n<h1>Cycle 444 PROBING 3D</h1>"
    );
    let _ = writeln!(
        s,
        "<p>Date/time: {}<br>Program: {}</p>",
        escape(when),
        escape(&program.map_or_else(|| "-".to_string(), |p| p.display().to_string()))
    );
    for r in records {
        let names = axis_names(r.axis);
        let tol = r.tolerance;
        let style = colour_style(r.status);
        let _ = writeln!(
            s,
            "<h2>Block {} (line {}), probe {}</h2>\n<table>\n<tr><th>Axis</th><th>Probing direction</th><th>Nominal</th>{}<th>Actual</th></tr>",
            r.block,
            r.line,
            escape(&r.probe),
            if tol.is_some() {
                "<th>Upper limit</th><th>Lower limit</th><th>Deviation along normal</th>"
            } else {
                ""
            }
        );
        for (i, name) in names.iter().enumerate() {
            let limits = match tol {
                Some(t) => format!(
                    "<td>{:+.4}</td><td>{:+.4}</td><td{style}>{:+.4}</td>",
                    r.nominal[i] + t.upper * r.normal[i],
                    r.nominal[i] + t.lower * r.normal[i],
                    r.deviation_3d * r.normal[i]
                ),
                None => String::new(),
            };
            let _ = writeln!(
                s,
                "<tr><th>{}</th><td>{:+.4}</td><td>{:+.4}</td>{limits}<td{style}>{:+.4}</td></tr>",
                name, r.direction[i], r.nominal[i], r.actual[i]
            );
        }
        let _ = writeln!(s, "</table>");
        let limits = tol.map_or_else(
            || "no tolerance".to_string(),
            |t| format!("upper {:+.4}, lower {:+.4}", t.upper, t.lower),
        );
        let _ = writeln!(
            s,
            "<p{style}>3D deviation Q164 = {:+.4} mm ({limits}); status Q183 = {} ({})</p>",
            r.deviation_3d,
            r.status.q183(),
            r.status
        );
    }
    let _ = writeln!(s, "</body></html>");
    s
}

pub fn write_probing3d_protocol(
    dir: &Path,
    records: &[Probing3dRecord],
    program: Option<&Path>,
) -> std::io::Result<PathBuf> {
    let path = dir.join(PROBING_3D_PROTOCOL);
    std::fs::create_dir_all(dir)?;
    std::fs::write(
        &path,
        probing3d_protocol_html(records, program, &timestamp_utc()),
    )?;
    Ok(path)
}
