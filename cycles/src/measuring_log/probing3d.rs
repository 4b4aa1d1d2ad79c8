//! `TCHPR444.html`, the measuring log of cycle 444: every point of the run.

use super::{axis_names, escape, program_name, timestamp_utc, write, MeasuringLogError};
use crate::probe_axis::ProbeAxis;
use crate::tolerance::{Tolerance, WorkpieceStatus};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

pub const PROBING_3D_LOG: &str = "TCHPR444.html";

/// What the log shows of one probed point; vectors as (main, minor, tool).
#[derive(Clone, Debug, PartialEq)]
pub struct Probing3dRecord {
    pub block: u32,
    pub line: usize,
    pub probe: String,
    pub axis: ProbeAxis,
    /// Probing direction scaled to the configured probing path.
    pub direction: [f64; 3],
    pub path_length: f64,
    pub nominal: [f64; 3],
    /// Unit surface normal.
    pub normal: [f64; 3],
    pub actual: [f64; 3],
    /// Q161..Q163.
    pub deviation: [f64; 3],
    /// Q164.
    pub deviation_3d: f64,
    pub tolerance: Option<Tolerance>,
    pub status: WorkpieceStatus,
    /// Standard uncertainty (k = 1) by result parameter (Q151 ...).
    pub u: std::collections::BTreeMap<String, f64>,
}

fn colour_style(status: WorkpieceStatus) -> String {
    match status {
        WorkpieceStatus::Undefined => String::new(),
        s => format!(" style=\"background:{}\"", s.colour()),
    }
}

/// ` &#177; u` (the standard uncertainty, k = 1) of result `q`, when reported.
fn plus_minus(r: &Probing3dRecord, q: &str) -> String {
    r.u.get(q)
        .map_or_else(String::new, |u| format!(" &#177; {u:.4}"))
}

/// The HTML protocol of all 444 points of a run. Per axis: the probing direction
/// (length = configured probing path), nominal, the limits and the deviation along the
/// normal split onto the axis (when QS400 sets a tolerance), the actual coordinate;
/// values coloured by the workpiece status.
pub fn probing3d_log_html(
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
        escape(&program_name(program))
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
                "<tr><th>{}</th><td>{:+.4}</td><td>{:+.4}</td>{limits}<td{style}>{:+.4}{}</td></tr>",
                name,
                r.direction[i],
                r.nominal[i],
                r.actual[i],
                plus_minus(r, &format!("Q15{}", i + 1))
            );
        }
        let _ = writeln!(s, "</table>");
        let limits = tol.map_or_else(
            || "no tolerance".to_string(),
            |t| format!("upper {:+.4}, lower {:+.4}", t.upper, t.lower),
        );
        let _ = writeln!(
            s,
            "<p{style}>3D deviation Q164 = {:+.4}{} mm ({limits}); status Q183 = {} ({})</p>",
            r.deviation_3d,
            plus_minus(r, "Q164"),
            r.status.q183(),
            r.status
        );
    }
    let _ = writeln!(s, "</body></html>");
    s
}

pub fn write_probing3d_log(
    dir: &Path,
    records: &[Probing3dRecord],
    program: Option<&Path>,
) -> Result<PathBuf, MeasuringLogError> {
    write(
        dir,
        PROBING_3D_LOG,
        &probing3d_log_html(records, program, &timestamp_utc()),
    )
}
