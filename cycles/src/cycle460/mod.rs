//! Cycle 460 CALIBRATION OF TS ON A SPHERE: calibrates the active touch probe on a
//! calibration sphere of known radius (Q407) and writes its row of the probe table
//! (`probes.toml`, [`crate::probe_table::probes_file`]): the effective radius R, the
//! ball centre's offset from the spindle axis (CAL_OF1, CAL_OF2 at CAL_ANG), with Q433
//! the length L against Q434, and with Q455 the 3D table of the effective radius by
//! direction.
//!
//! The offset needs the spindle turned by 180°: on a machine whose spindle cannot be
//! oriented the cycle says that the offset cannot be separated from the sphere's
//! position, and keeps the row's offset as it was.

pub mod evaluate;
pub mod measure;
pub mod measuring_log;
pub mod parameters;
pub mod plan;
pub mod report;
pub mod uncertainty;

pub use parameters::{CalibrationParams, CYCLE_460};
pub use report::{CalibrationReport, RowValues};

use crate::cycle::{CycleContext, MeasuringCycle};
use crate::cycle_block::CycleBlock;
use crate::error::CycleError;
use crate::measuring_log::timestamp_utc;
use crate::probe_table::calibration::{Calibration, RING_ELEVATIONS};
use crate::probe_table::probes_file::CalibrationRow;
use crate::results::CycleOutput;
use evaluate::table_3d;
use hal::Machine;
use measure::{Probed, Probing};
use measuring_log::{write_calibration_log, CALIBRATION_LOG};
use nalgebra::Vector3;
use std::collections::BTreeMap;

/// The unit vectors of (main, minor, tool) in machine coordinates.
fn frame(call: &CycleBlock) -> [Vector3<f64>; 3] {
    let axis = call.tool.axis;
    [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]].map(|e| Vector3::from(axis.to_machine(e)))
}

/// The new calibration from what was probed, starting from `old`.
pub fn evaluate(
    p: &CalibrationParams,
    probed: &Probed,
    old: &Calibration,
    frame: &[Vector3<f64>; 3],
    origin_t: f64,
) -> Result<(Calibration, Vector3<f64>, Vec<String>), CycleError> {
    let mut notes = Vec::new();
    let n = frame[2];
    let eq = &probed.equator;
    let plane = |v: &Vector3<f64>| [frame[0].dot(v), frame[1].dot(v)];
    let rho = eq.iter().map(|r| r.radius).sum::<f64>() / eq.len() as f64;
    let offset = if let [e0, e180] = &eq[..] {
        let d = (e180.centre - e0.centre) / 2.0;
        plane(&d)
    } else {
        notes.push(
            "no orientable spindle: the stylus offset cannot be separated from the sphere's position (it needs the spindle at 0° and 180°); CAL_OF1/CAL_OF2 kept".to_string(),
        );
        old.offset
    };
    // The pole over the found centre fixes the equator's true height: the circle of
    // a ring probed ε off it has radius sqrt(S² - ε²). Solved in closed form, so
    // exact whatever R the table held (the probing re-probes the rings until ε is
    // within EQUATOR_HEIGHT_TOLERANCE, so that the axial pre-travel's bias of the pole
    // enters only to second order).
    let pole_t = n.dot(&probed.pole);
    let (s, _) = measure::sphere_from_ring_and_pole(rho, probed.equator_height, pole_t)
        .map_err(|e| CycleError::Geometry(format!("cycle 460: evaluating R: {e}")))?;
    let r = s - p.sphere_radius;
    let l = if p.calibrate_length {
        pole_t - origin_t - p.length_datum - p.sphere_radius - r
    } else {
        notes.push("Q433=0: the length L kept".to_string());
        old.l
    };
    // Sphere centre as the stylus at 0° sees it (latched coordinates).
    let c0 = eq[0].centre;
    let seen = frame[0] * frame[0].dot(&c0)
        + frame[1] * frame[1].dot(&c0)
        + n * (pole_t - p.sphere_radius - r);
    let table = (p.points_3d > 0).then(|| {
        table_3d(
            &RING_ELEVATIONS,
            p.points_3d,
            p.reference_angle,
            &probed.contacts_3d,
            seen,
            p.sphere_radius,
            r,
        )
    });
    let cal = Calibration {
        r,
        offset,
        cal_ang: 0.0,
        l,
        table_3d: table,
    };
    // The true sphere centre: the latched one plus the stylus's shift.
    let true_centre = seen + frame[0] * offset[0] + frame[1] * offset[1] - n * l;
    Ok((cal, true_centre, notes))
}

/// R, CAL_OF1/2 and L as the cycle's results, by the row's column names (the TNC's 460
/// has no result Q parameters).
fn row_results(cal: &Calibration) -> BTreeMap<String, f64> {
    let row = RowValues::of(cal);
    [
        ("R", row.r),
        ("CAL_OF1", row.cal_of1),
        ("CAL_OF2", row.cal_of2),
        ("L", row.l),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect()
}

impl MeasuringCycle for CalibrationParams {
    fn run<M: Machine>(
        &self,
        call: &CycleBlock,
        machine: &mut M,
        ctx: &mut CycleContext<'_>,
    ) -> Result<CycleOutput, CycleError> {
        let probe = call.tool.probe.clone();
        let old = probe.calibration();
        let frame = frame(call);
        let origin_t = frame[2].dot(&Vector3::from(ctx.datum.origin()));
        let probed = Probing {
            rs: self.sphere_radius + old.r,
            clear: probe.set_up + self.clearance,
            located: false,
            machine,
            ctx: &mut *ctx,
            call,
            p: self,
            frame,
        }
        .run()?;
        let (cal, centre, notes) = evaluate(self, &probed, &old, &frame, origin_t)?;
        if let Some((key, why)) = cal.invalid_field() {
            return Err(CycleError::Geometry(format!(
                "cycle 460: the calibration is not plausible ({key}: {why}); the probe table was not changed"
            )));
        }
        let stamp = timestamp_utc();
        let row = CalibrationRow::new(
            &probe.name,
            &cal,
            format!(
                "{stamp}, cycle 460 on a sphere of radius {} mm",
                self.sphere_radius
            ),
        );
        let mut table = ctx.cfg.calibrations.clone();
        table
            .write_row(row, &ctx.cfg.probes)
            .map_err(|e| CycleError::MeasuringLog {
                path: e.path.display().to_string(),
                message: format!(
                    "the probe table row was not written ({}); the probe keeps its old calibration",
                    e.reason()
                ),
            })?;
        let file = table.path.clone();
        ctx.note(
            call.block,
            format!(
                "probe table row \"{}\" written: {}",
                probe.name,
                file.display()
            ),
        );
        for n in &notes {
            ctx.note(call.block, n.clone());
        }
        let max_dev = cal.table_3d.as_ref().map(|t| {
            t.deviations
                .iter()
                .flatten()
                .fold(t.pole.abs(), |m, v| m.max(v.abs()))
        });
        let mut notes = notes;
        let u = uncertainty::row_uncertainty(
            &probed,
            &frame,
            probe.repeatability(),
            self.calibrate_length,
        )
        .unwrap_or_else(|e| {
            notes.push(format!("no uncertainty: {e}"));
            BTreeMap::new()
        });
        let report = CalibrationReport {
            probe: probe.name.clone(),
            sphere_radius: self.sphere_radius,
            before: RowValues::of(&old),
            after: RowValues::of(&cal),
            sphere_centre: centre.into(),
            offset_measured: probed.oriented,
            length_measured: self.calibrate_length,
            points_3d: self.points_3d,
            max_deviation_3d: max_dev,
            notes,
            file: file.display().to_string(),
            u: u.clone(),
        };
        let log =
            write_calibration_log(ctx.out_dir, &report, &probed, ctx.program).map_err(|e| {
                CycleError::MeasuringLog {
                    path: ctx.out_dir.join(CALIBRATION_LOG).display().to_string(),
                    message: e.source.to_string(),
                }
            })?;
        let mut out = CycleOutput::new(row_results(&cal), None);
        out.u = u;
        out.logs.push(log);
        out.calibration = Some(Box::new(report));
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::measure::EquatorRing;
    use super::*;

    const FRAME: [Vector3<f64>; 3] = [
        Vector3::new(1.0, 0.0, 0.0),
        Vector3::new(0.0, 1.0, 0.0),
        Vector3::new(0.0, 0.0, 1.0),
    ];

    /// A ring of 8 ball centres about `c` probed `eps` above the equator of the
    /// ball-centre sphere of radius `s`, with the stylus offset `off` at `spindle`.
    fn ring(c: Vector3<f64>, s: f64, eps: f64, off: [f64; 2], spindle: f64) -> EquatorRing {
        let rho = (s * s - eps * eps).sqrt();
        let shift = Vector3::new(off[0], off[1], 0.0);
        let centre = c - shift + Vector3::new(0.0, 0.0, eps);
        let contacts = (0..8)
            .map(|k| {
                let a = (k as f64 * 45.0f64).to_radians();
                centre + Vector3::new(rho * a.cos(), rho * a.sin(), 0.0)
            })
            .collect();
        EquatorRing {
            spindle,
            contacts,
            centre,
            radius: rho,
        }
    }

    /// The rings probed 1.9 mm above the equator of a small sphere (Q407 = 6, R = 2:
    /// what a table R 1.9 mm too small did) give R, the offset and L exactly. The old
    /// height correction stopped after three fixed steps, 2.8 µm short here.
    #[test]
    fn r_is_exact_with_the_rings_far_off_the_equator() {
        let (q407, r_true, eps) = (6.0, 2.0, 1.9);
        let s = q407 + r_true;
        let c = Vector3::new(10.0, -5.0, 30.0);
        let off = [0.003, -0.002];
        let probed = Probed {
            equator: vec![
                ring(c, s, eps, off, 0.0),
                ring(c, s, eps, [-off[0], -off[1]], 180.0),
            ],
            equator_height: c.z + eps,
            pole: c + Vector3::new(-off[0], -off[1], s),
            contacts_3d: Vec::new(),
            oriented: true,
        };
        let p = CalibrationParams {
            sphere_radius: q407,
            clearance: 0.0,
            to_clearance_height: true,
            points: 8,
            reference_angle: 0.0,
            calibrate_length: true,
            length_datum: c.z,
            points_3d: 0,
        };
        let (cal, centre, _) = evaluate(
            &p,
            &probed,
            &Calibration::nominal(r_true - eps),
            &FRAME,
            0.0,
        )
        .unwrap();
        assert!((cal.r - r_true).abs() < 1e-12, "R = {}", cal.r);
        assert!((cal.offset[0] - off[0]).abs() < 1e-12, "{:?}", cal.offset);
        assert!((cal.offset[1] - off[1]).abs() < 1e-12, "{:?}", cal.offset);
        assert!(cal.l.abs() < 1e-12, "L = {}", cal.l);
        assert!((centre - c).norm() < 1e-9, "{centre:?}");
    }

    /// The closed form needs the pole above the ring; otherwise it says so.
    #[test]
    fn a_pole_not_above_the_ring_is_an_error() {
        let (s, c) = measure::sphere_from_ring_and_pole(7.9, 30.3, 38.0).unwrap();
        assert!((s - (7.9f64 * 7.9 + 7.7 * 7.7) / 15.4).abs() < 1e-12);
        assert!((c - (38.0 - s)).abs() < 1e-12);
        let e = measure::sphere_from_ring_and_pole(7.9, 38.0, 38.0).unwrap_err();
        assert!(e.contains("not above the ring"), "{e}");
    }
}
