//! `TCHPR431.TXT`, the measuring log of cycle 431 (Q281 = 1, or shown for Q281 = 2).

use super::{axis_names, program_name, timestamp_utc, write, MeasuringLogError};
use crate::plane::PlaneAngles;
use crate::probe_axis::ProbeAxis;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

pub const PLANE_LOG: &str = "TCHPR431.TXT";

/// What the log shows of one plane.
#[derive(Clone, Debug, PartialEq)]
pub struct PlaneRecord {
    pub block: u32,
    pub line: usize,
    pub probe: String,
    pub axis: ProbeAxis,
    pub nominal: [[f64; 3]; 3],
    /// Measured points (main, minor, Q173..Q175).
    pub measured: [[f64; 3]; 3],
    pub angles: PlaneAngles,
    /// Standard uncertainty (k = 1) by result parameter (Q158 ...).
    pub u: std::collections::BTreeMap<String, f64>,
}

/// The text of `TCHPR431.TXT`.
pub fn plane_log_text(r: &PlaneRecord, program: Option<&Path>, when: &str) -> String {
    let names = axis_names(r.axis);
    let mut s = String::new();
    let _ = writeln!(s, "TCHPR431 MEASURE PLANE");
    let _ = writeln!(s, "Date/time:   {when}");
    let _ = writeln!(s, "Program:     {}", program_name(program));
    let _ = writeln!(s, "Block:       {} (line {})", r.block, r.line);
    let _ = writeln!(s, "Probe:       {} (axis {})", r.probe, r.axis);
    let _ = writeln!(s);
    let _ = writeln!(
        s,
        "Point  Nominal {0:>2}/{1}/{2}                      Measured {2}    Q",
        names[0], names[1], names[2]
    );
    // "± u": the standard uncertainty (k = 1), when the cycle reported one.
    let pm = |q: &str, decimals: usize| {
        r.u.get(q)
            .map_or_else(String::new, |u| format!(" ± {u:.decimals$}"))
    };
    for (i, (n, m)) in r.nominal.iter().zip(&r.measured).enumerate() {
        let q = format!("Q{}", 173 + i);
        let _ = writeln!(
            s,
            "{:>5}  {:+12.4} {:+12.4} {:+12.4}   {:+12.4}   {q}{}",
            i + 1,
            n[0],
            n[1],
            n[2],
            m[2],
            pm(&q, 4)
        );
    }
    let a = &r.angles;
    let _ = writeln!(s);
    for (label, q, v) in [
        ("Spatial angle A ", "Q170", a.spa),
        ("Spatial angle B ", "Q171", a.spb),
        ("Spatial angle C ", "Q172", a.spc),
        ("Projection A    ", "Q158", a.proj_a),
        ("Projection B    ", "Q159", a.proj_b),
    ] {
        let _ = writeln!(s, "{label} {q} = {v:+.4}{} deg", pm(q, 4));
    }
    if !r.u.is_empty() {
        let _ = writeln!(
            s,
            "(± standard uncertainty, k = 1: the probe's scatter only, not the form of the plane or temperature)"
        );
    }
    let _ = writeln!(
        s,
        "Plane normal     ({:+.6}, {:+.6}, {:+.6})",
        a.normal.x, a.normal.y, a.normal.z
    );
    s
}

pub fn write_plane_log(
    dir: &Path,
    r: &PlaneRecord,
    program: Option<&Path>,
) -> Result<PathBuf, MeasuringLogError> {
    write(
        dir,
        PLANE_LOG,
        &plane_log_text(r, program, &timestamp_utc()),
    )
}
