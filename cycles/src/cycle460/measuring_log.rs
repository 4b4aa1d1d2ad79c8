//! `TCHPR460.TXT`, the measuring log of cycle 460: the probe's row before and after,
//! every contact, and what was kept and why.

use super::measure::Probed;
use super::report::CalibrationReport;
use crate::measuring_log::{program_name, timestamp_utc, write, MeasuringLogError};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

pub const CALIBRATION_LOG: &str = "TCHPR460.TXT";

/// The text of `TCHPR460.TXT`.
pub fn calibration_log_text(
    r: &CalibrationReport,
    probed: &Probed,
    program: Option<&Path>,
    when: &str,
) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "TCHPR460 CALIBRATION OF TS ON A SPHERE");
    let _ = writeln!(s, "Date/time:   {when}");
    let _ = writeln!(s, "Program:     {}", program_name(program));
    let _ = writeln!(s, "Probe:       {}", r.probe);
    let _ = writeln!(s, "Sphere:      Q407 = {:.4} mm", r.sphere_radius);
    let c = r.sphere_centre;
    let _ = writeln!(
        s,
        "Centre:      X{:+.4} Y{:+.4} Z{:+.4} (machine)",
        c[0], c[1], c[2]
    );
    let _ = writeln!(s, "Probe table: {}", r.file);
    let _ = writeln!(s);
    let _ = writeln!(s, "Column         before          after");
    let (b, a) = (&r.before, &r.after);
    for (name, x, y) in [
        ("R", b.r, a.r),
        ("CAL_OF1", b.cal_of1, a.cal_of1),
        ("CAL_OF2", b.cal_of2, a.cal_of2),
        ("CAL_ANG", b.cal_ang, a.cal_ang),
        ("L", b.l, a.l),
    ] {
        let u =
            r.u.get(name)
                .map_or_else(String::new, |u| format!(" ± {u:.6}"));
        let _ = writeln!(s, "{name:<8} {x:>+14.6} {y:>+14.6}{u}");
    }
    if let Some(m) = r.max_deviation_3d {
        let _ = writeln!(
            s,
            "3D calibration: {} directions per ring, largest |effective radius - R| {:.6} mm",
            r.points_3d, m
        );
    }
    for n in &r.notes {
        let _ = writeln!(s, "Note: {n}");
    }
    let _ = writeln!(s);
    for ring in &probed.equator {
        let _ = writeln!(
            s,
            "Equator, spindle {:>5.1} deg: circle radius {:.6} mm, centre X{:+.6} Y{:+.6} Z{:+.6}",
            ring.spindle, ring.radius, ring.centre.x, ring.centre.y, ring.centre.z
        );
        for (i, p) in ring.contacts.iter().enumerate() {
            let _ = writeln!(s, "  {:>2}  X{:+.6} Y{:+.6} Z{:+.6}", i + 1, p.x, p.y, p.z);
        }
    }
    let p = probed.pole;
    let _ = writeln!(s, "Pole:          X{:+.6} Y{:+.6} Z{:+.6}", p.x, p.y, p.z);
    for c in &probed.contacts_3d {
        let _ = writeln!(
            s,
            "3D ring {} direction {:>2}: X{:+.6} Y{:+.6} Z{:+.6}",
            c.ring + 1,
            c.k + 1,
            c.centre.x,
            c.centre.y,
            c.centre.z
        );
    }
    s
}

pub fn write_calibration_log(
    dir: &Path,
    r: &CalibrationReport,
    probed: &Probed,
    program: Option<&Path>,
) -> Result<PathBuf, MeasuringLogError> {
    write(
        dir,
        CALIBRATION_LOG,
        &calibration_log_text(r, probed, program, &timestamp_utc()),
    )
}
