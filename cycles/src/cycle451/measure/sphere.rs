//! One sphere measured: the pole along the (possibly tilted) tool axis and Q423 points
//! around the equator, fitted by the estimator; probed again around the fitted centre
//! when that is more than [`super::RE_PROBE_TOLERANCE`] from where it was expected.

use super::{arr, axis_map, Measure, Sphere, RE_PROBE_TOLERANCE};
use crate::cycle451::report::SphereRecord;
use crate::error::CycleError;
use crate::kinematics::model::{angles_of, rotary_slot, Angles};
use hal::{Axis, AxisPositions, Machine, ProbeMove};
use nalgebra::Vector3;

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
            self.move_xyz(&format!("{what}: moving over the pole"), top)?;
            let pole = self.probe(&format!("{what}: probing the pole"), -n, dist);
            contacts.push(pole.map_err(|e| self.not_at_preset(e))?);
            self.move_xyz(&format!("{what}: retracting from the pole"), top)?;
            for i in 0..p.points {
                let phi = (phi0 + 360.0 * f64::from(i) / f64::from(p.points)).to_radians();
                let w = u * phi.cos() + v * phi.sin();
                let step = format!("{what}: point {} of {}", i + 1, p.points);
                self.move_xyz(&step, top + w * reach)?;
                self.move_xyz(&step, c + w * reach)?;
                let contact = self.probe(&step, -w, dist);
                contacts.push(contact.map_err(|e| self.not_at_preset(e))?);
                self.move_xyz(&step, c + w * reach)?;
                self.move_xyz(&step, top + w * reach)?;
            }
            self.move_xyz(&format!("{what}: back over the pole"), top)?;
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
