//! One sphere measured: the pole along the (possibly tilted) tool axis and Q423 points
//! around the equator, fitted by the estimator; probed again around the fitted centre
//! when that is more than [`super::RE_PROBE_TOLERANCE`] from where it was expected.
//!
//! The probe goes down to the equator once, at min(Q253, FMAX), and from one point's
//! start to the next along the tangents of the circle the starts lie on
//! ([`Measure::next_start`]): every point of those two legs is at least as far from the
//! expected centre as the starts, where the ball stands before each probe anyway. Those
//! legs, the retracts and the moves over the sphere run at the probe table's FMAX. Where
//! the sphere's holder may lie in the plane of the points (the table tilted against the
//! tool axis) or a corner is outside the software limits, the probe goes over the top
//! instead (up, over, down), as it did between all points before.

use super::{arr, axis_map, Measure, Sphere, RE_PROBE_TOLERANCE};
use crate::cycle451::report::SphereRecord;
use crate::error::CycleError;
use crate::kinematics::model::{angles_of, rotary_slot, Angles};
use hal::{Axis, AxisPositions, Machine, ProbeMove};
use nalgebra::Vector3;

/// How far (deg) the sphere's holder may turn from the tool axis for the probe to go
/// from one equator point to the next in their plane ([`Measure::next_start`]).
pub const HOLDER_ALONG_TOOL_AXIS: f64 = 1.0;

impl<M: Machine> Measure<'_, '_, M> {
    /// Measures the sphere expected at `c` with the axes at `a` (the probe stands at
    /// the pole start or anywhere above the sphere on the tool axis side).
    pub(super) fn sphere(
        &mut self,
        a: &Angles,
        mut c: Vector3<f64>,
        what: &str,
    ) -> Result<Sphere, CycleError> {
        let p = &self.plan.params;
        let (reach, dist) = (self.reach(), self.clearance() + self.probe.dist);
        let [n, u, v] = self.frame(a);
        let mut run_ids = Vec::new();
        for round in 0..2 {
            let run = self.next_run();
            run_ids.push(run);
            let mut contacts = Vec::with_capacity(1 + p.points as usize);
            let top = c + n * reach;
            let phi0 = self.equator_start(a, c, what);
            self.approach_xyz(&format!("{what}: moving over the pole"), top)?;
            let pole = self.probe(&format!("{what}: probing the pole"), -n, dist);
            contacts.push(pole.map_err(|e| self.not_at_preset(e))?);
            self.rapid_xyz(&format!("{what}: retracting from the pole"), top)?;
            let mut prev = None;
            for i in 0..p.points {
                let phi = (phi0 + 360.0 * f64::from(i) / f64::from(p.points)).to_radians();
                let w = u * phi.cos() + v * phi.sin();
                let step = format!("{what}: point {} of {}", i + 1, p.points);
                self.next_start(&step, a, [c, top], reach, prev, w)?;
                let contact = self.probe(&step, -w, dist);
                contacts.push(contact.map_err(|e| self.not_at_preset(e))?);
                self.rapid_xyz(&step, c + w * reach)?;
                prev = Some(w);
            }
            if let Some(w) = prev {
                self.rapid_xyz(&format!("{what}: back up"), top + w * reach)?;
            }
            self.rapid_xyz(&format!("{what}: back over the pole"), top)?;
            let fit = self.ctx.estimator.fit_sphere(run, &contacts).map_err(|e| {
                CycleError::Geometry(format!("{what}: sphere fit (run {run}): {e}"))
            })?;
            // The probe's calibration (probe table row): the true ball-centre sphere.
            let (centre, ball_sphere) = self.calibrated(a, &contacts, fit.centre, fit.radius);
            let radius = ball_sphere - self.probe.calibration().r;
            let shift = (centre - c).norm();
            if round == 0 && shift > RE_PROBE_TOLERANCE {
                self.note(format!(
                    "{what}: the sphere is {shift:.4} mm from where it was expected; probing it again around the fitted centre"
                ));
                c = centre;
                continue;
            }
            let dev = radius - p.sphere_radius;
            if dev.abs() > self.ctx.cfg.parameters.max_dev_cal_ball {
                return Err(CycleError::Geometry(format!(
                    "{what}: the fitted sphere radius {radius:.4} mm differs from Q407 = {:.4} mm by {dev:+.4} mm, more than maxDevCalBall = {} mm; wrong sphere, or a probe that is not calibrated; nothing was changed",
                    p.sphere_radius, self.ctx.cfg.parameters.max_dev_cal_ball
                )));
            }
            let n_c = contacts.len() as f64;
            let mut angles = [0.0; 3];
            for k in contacts.iter() {
                let l = angles_of(&k.positions);
                for s in 0..3 {
                    angles[s] += l[s] / n_c;
                }
            }
            for &x in &Axis::ROTARY {
                if !self.plan.present.contains(&x) {
                    angles[rotary_slot(x).expect("rotary")] = 0.0;
                }
            }
            self.spheres += 1;
            return Ok(Sphere {
                angles,
                centre,
                radius,
                record: SphereRecord {
                    angles: axis_map(&self.plan.present, &angles),
                    centre: arr(&centre),
                    radius,
                    rms: fit.rms,
                    run_ids,
                    approach: None,
                },
            });
        }
        unreachable!("the second round returns")
    }

    /// A sphere fitted through latched ball centres (`centre`, `radius`), corrected by
    /// the probe's calibration ([`crate::probe_table::calibration::Calibration::correct_sphere`]):
    /// the stylus offset and length, and the 3D table's effect on the fit. The stylus
    /// turns with a swivel head, so the correction is made in the head's frame at `a`.
    /// Returns the true ball-centre sphere (centre in machine X/Y/Z, radius).
    pub(super) fn calibrated(
        &self,
        a: &Angles,
        contacts: &[hal::Contact],
        centre: Vector3<f64>,
        radius: f64,
    ) -> (Vector3<f64>, f64) {
        let cal = self.probe.calibration();
        let rot = nalgebra::Matrix3::from_columns(
            &[Vector3::x(), Vector3::y(), Vector3::z()].map(|e| self.model.tool_vector(a, e)),
        );
        let back = rot.transpose();
        let directions: Vec<[f64; 3]> = contacts
            .iter()
            .map(|k| (back * Vector3::from(k.direction)).into())
            .collect();
        let (c, r) = cal.correct_sphere(self.tool, (back * centre).into(), radius, &directions);
        (rot * Vector3::from(c), r)
    }

    /// To the start of the next of Q423 points standing `r` from the tool axis through
    /// `c` (in the direction `w`), from the start of the previous one (`prev`; `None`:
    /// the probe stands at `top`, over `c` on that axis). From one start to the next
    /// along the tangents of their circle, through the corner where they meet: no
    /// point of the way is nearer the axis than `r`. That way stays in the plane of the
    /// points, where nothing but the sphere is known to be: only while the sphere's
    /// holder (the table's normal, down from the sphere) runs along the tool axis, below
    /// that plane. With the table tilted against the tool axis the holder may cross the
    /// plane between two points (Q380 turns the points off it, not the corners), and a
    /// corner may be outside the software limits: then, and for the first point, up to
    /// the height of `top`, over, and down at the approach feed.
    pub(super) fn next_start(
        &mut self,
        step: &str,
        a: &Angles,
        [c, top]: [Vector3<f64>; 2],
        r: f64,
        prev: Option<Vector3<f64>>,
        w: Vector3<f64>,
    ) -> Result<(), CycleError> {
        let half = (180.0 / f64::from(self.plan.params.points)).to_radians();
        if let Some(p) = prev {
            let corner = c + (p + w).normalize() * (r / half.cos());
            if self.holder_below(a) && self.reachable(a, corner) {
                self.rapid_xyz(step, corner)?;
                return self.rapid_xyz(step, c + w * r);
            }
            self.rapid_xyz(step, top + p * r)?;
        }
        self.rapid_xyz(step, top + w * r)?;
        self.approach_xyz(step, c + w * r)
    }

    /// Whether the sphere's holder, along the table's normal down from the sphere,
    /// runs along the tool axis at `a` (within [`HOLDER_ALONG_TOOL_AXIS`] degrees): away
    /// from the probe, below the plane of the equator's points.
    fn holder_below(&self, a: &Angles) -> bool {
        let down = self.model.table_transform(a).rotation * -Vector3::z();
        let away = -self.frame(a)[0];
        down.dot(&away) >= HOLDER_ALONG_TOOL_AXIS.to_radians().cos()
    }

    /// Whether the machine may stand at `p` (X/Y/Z) with the rotary axes at `a`.
    fn reachable(&self, a: &Angles, p: Vector3<f64>) -> bool {
        let guard = hal::motion_guard::MotionGuard::new(&self.ctx.cfg.machine);
        let at = AxisPositions::linear(arr(&p)).merged(&self.rotary(a));
        guard.check_target(&at, "move").is_ok()
    }

    /// Where the Q423 points around the sphere at `c` (axes at `a`) start: Q380, or,
    /// when one of their positions or probing paths would leave the software limits
    /// (a head tilted to B+90 puts a point under the sphere), the first arrangement
    /// turned from Q380 in steps of 1/24 of their spacing that stays inside: the same
    /// points around the same equator, approached from where the machine can go.
    fn equator_start(&mut self, a: &Angles, c: Vector3<f64>, what: &str) -> f64 {
        let p = &self.plan.params;
        let (reach, dist) = (self.reach(), self.clearance() + self.probe.dist);
        let [n, u, v] = self.frame(a);
        let top = c + n * reach;
        let guard = hal::motion_guard::MotionGuard::new(&self.ctx.cfg.machine);
        let rotary = self.rotary(a);
        let fits = |phi0: f64| {
            (0..p.points).all(|i| {
                let phi = (phi0 + 360.0 * f64::from(i) / f64::from(p.points)).to_radians();
                let w = u * phi.cos() + v * phi.sin();
                let at = |x: Vector3<f64>| AxisPositions::linear(arr(&x)).merged(&rotary);
                let from = at(c + w * reach);
                guard.check_target(&from, "move").is_ok()
                    && guard.check_target(&at(top + w * reach), "move").is_ok()
                    && guard
                        .check_probe(
                            &from,
                            &ProbeMove {
                                direction: arr(&-w),
                                feed: self.probe.f,
                                max_distance: dist,
                            },
                        )
                        .is_ok()
            })
        };
        let (phi0, turned) = super::start_angle(p.reference_angle, p.points, fits);
        if turned {
            self.note(format!(
                "{what}: the probing points start at {phi0:.1} deg instead of Q380 = {:.1} deg, to stay inside the software limits",
                p.reference_angle
            ));
        }
        phi0
    }
}
