//! Where the sphere is when the cycle starts: located below the probe in two passes
//! (Q431 = 1/3), or taken at the active datum and approached there (Q431 = 0/2).

use super::{Measure, LOCATE_DEPTH, LOCATE_REACH};
use crate::error::CycleError;
use crate::kinematics::model::Angles;
use hal::{Axis, AxisPositions, Contact, Machine};
use nalgebra::Vector3;

impl<M: Machine> Measure<'_, '_, M> {
    /// Locates the sphere below the probe in two passes (the seeds' note on preset
    /// setting: with an inaccurate pre-position the sphere is probed twice, and the
    /// radius is monitored only in the second measurement). First pass
    /// ([`Measure::first_pass`]): from the contact of the pole probe, every
    /// positioning move clears the sphere for any centre consistent with that contact;
    /// its rough centre is not checked against Q407. Second pass: the sphere measured
    /// around that centre, radius monitored against maxDevCalBall. Returns its centre
    /// (ball centre in machine X/Y/Z); Q431 = 1/3 set the preset there.
    pub fn locate(&mut self) -> Result<Vector3<f64>, CycleError> {
        let start = self.start;
        let p = &self.plan.params;
        let n0 = self.frame(&start)[0];
        let rs = p.sphere_radius + self.probe.radius;
        // A start up to LOCATE_REACH x (Q407 + R) off the centre meets the sphere up
        // to (1 - sqrt(1 - reach^2)) x (Q407 + R) below its pole: probed that much
        // further than from a centred start (with a tenth more reach, so that a start
        // at both limits at once still triggers).
        let reach = 1.1 * LOCATE_REACH;
        let dist = self.clearance() + self.probe.dist + rs * (1.0 - (1.0 - reach * reach).sqrt());
        let run = self.next_run();
        let first = self
            .probe(
                "locating the sphere: probing along the tool axis from the start position",
                -n0,
                dist,
            )
            .map_err(|e| match e {
                CycleError::Machine {
                    step,
                    kind,
                    message,
                } if kind == hal::ErrorKind::NotTriggered => CycleError::Machine {
                    step,
                    kind,
                    message: format!(
                        "{message}; before cycle 451 position the probe over the sphere centre (at most {:.3} mm off it in the working plane), about Q320 + SET_UP = {:.3} mm above the sphere{}",
                        LOCATE_REACH * rs,
                        self.clearance(),
                        turned_table(&self.start)
                    ),
                },
                e => e,
            })?;
        let rough = self.first_pass(&start, run, first)?;
        let located = self.sphere(&start, rough, "locating the sphere")?;
        self.table_point = self.model.table_point(&located.angles, &located.centre);
        let ball = self.model.ball_in_machine(&located.angles, &located.centre);
        self.located = Some(located);
        if p.preset == 1 || p.preset == 3 {
            self.preset = ball;
            self.note(format!(
                "Q431={}: {} X{:+.4} Y{:+.4} Z{:+.4}",
                p.preset,
                crate::cycle451::report::preset_words(p.mode.writes()),
                ball.x,
                ball.y,
                ball.z
            ));
        }
        Ok(ball)
    }

    /// The first locating pass from the pole contact `touch` (ball centre, axes at
    /// `a`, in run `run`): the centre is somewhere on the half sphere of radius Q407 + R below
    /// `touch` (the ball came down along the tool axis without touching before). Every
    /// move clears all of those spheres by the clearance Q320 + SET_UP: up to
    /// Q407 + R + clearance over `touch`, out to 2 (Q407 + R) + clearance from its axis,
    /// down to LOCATE_DEPTH x (Q407 + R) below it, then Q423 points probed toward the
    /// axis (each from its own side, back out the way it came, up again). A sphere with
    /// free radius through the pole contact and those points is the rough centre;
    /// nothing is checked against Q407 here.
    fn first_pass(
        &mut self,
        a: &Angles,
        run: u64,
        pole: Contact,
    ) -> Result<Vector3<f64>, CycleError> {
        let p = &self.plan.params;
        let rs = p.sphere_radius + self.probe.radius;
        let clearance = self.clearance();
        let [n, u, v] = self.frame(a);
        let what = "locating the sphere (first pass)";
        let touch = Vector3::from(pole.positions.xyz());
        let mut contacts = Vec::with_capacity(1 + p.points as usize);
        contacts.push(pole);
        let safe = touch + n * (rs + clearance);
        self.move_xyz(&format!("{what}: up to clear the sphere"), safe)?;
        let out = 2.0 * rs + clearance;
        for i in 0..p.points {
            let phi = (p.reference_angle + 360.0 * f64::from(i) / f64::from(p.points)).to_radians();
            let w = u * phi.cos() + v * phi.sin();
            let step = format!("{what}: point {} of {}", i + 1, p.points);
            let high = safe + w * out;
            let low = touch - n * (LOCATE_DEPTH * rs) + w * out;
            self.move_xyz(&step, high)?;
            self.move_xyz(&step, low)?;
            contacts.push(self.probe(&step, -w, out + self.probe.dist)?);
            self.move_xyz(&step, low)?;
            self.move_xyz(&step, high)?;
        }
        self.move_xyz(&format!("{what}: back over the pole"), safe)?;
        let fit =
            self.ctx.estimator.fit_sphere(run, &contacts).map_err(|e| {
                CycleError::Geometry(format!("{what}: sphere fit (run {run}): {e}"))
            })?;
        self.note(format!(
            "{what}: the sphere centre is about {:.4} mm from below the start position; measuring it again around that centre",
            ((fit.centre - touch) - n * n.dot(&(fit.centre - touch))).norm()
        ));
        Ok(fit.centre)
    }

    /// Q431 = 0/2: the sphere centre is the active datum with the rotary axes at their
    /// reference (0 deg), as the preset was set. From wherever the probe is: up along
    /// the tool axis to a height that clears the sphere for every angle the rotary
    /// axes pass on their way to the first measurement's angles (and the pole start,
    /// and Q408 above the datum when higher, or where the probe already is); the
    /// rotary axes turn there; then over the sphere and down to the pole start. Every
    /// point inside the software limits, else nothing moves.
    pub fn approach_datum(&mut self) -> Result<(), CycleError> {
        let start = self.start;
        let zero = [0.0; 3];
        let c = self.preset - self.model.ball_offset(&zero);
        self.table_point = self.model.table_point(&zero, &c);
        let first = self.plan.angles(self.plan.axes[0].axis, 0.0);
        let pole = self.predicted_pole(&first);
        let here = self
            .machine
            .positions()
            .map_err(|e| CycleError::machine("reading the axis positions", &e))?
            .xyz();
        let t = self.tool.tool_index();
        let q408 = self.plan.params.retract_height;
        let clear = self.clear_height(&[start, first], self.reach());
        if (0..3).any(|s| (first[s] - start[s]).abs() > 1e-9) {
            self.turn_height_in_limits(&[start, first], clear)?;
        }
        let mut height = pole[t].max(here[t]).max(clear);
        if q408 > 0.0 {
            height = height.max(self.preset[t] + q408);
        }
        let mut above = pole;
        above[t] = height;
        for axis in Axis::LINEAR {
            let i = axis.index();
            let Some(c) = self.ctx.cfg.machine.axis(axis) else {
                continue;
            };
            for v in [above[i], pole[i]] {
                if v < c.min || v > c.max {
                    return Err(CycleError::Plan(format!(
                        "Q431={}: the sphere at the active datum X{:+.4} Y{:+.4} Z{:+.4} is reached over {axis}{v:+.4}, outside the software limits {:+.4} .. {:+.4}; set the preset at the sphere centre (cycle 247) or pre-position with Q431=1; nothing moved",
                        self.plan.params.preset, self.preset.x, self.preset.y, self.preset.z, c.min, c.max
                    )));
                }
            }
        }
        self.note(format!(
            "Q431={}: the sphere is at the active datum X{:+.4} Y{:+.4} Z{:+.4} (rotary axes at 0); moving over it",
            self.plan.params.preset, self.preset.x, self.preset.y, self.preset.z
        ));
        let up = AxisPositions::new().with(Axis::LINEAR[t], height);
        self.mv(
            "moving up to the safe height",
            up,
            self.plan.positioning_feed,
        )?;
        if (0..3).any(|s| (first[s] - start[s]).abs() > 1e-9) {
            self.note(format!(
                "the rotary axes turn from {} to {} at the safe height before the approach",
                self.rotary(&start),
                self.rotary(&first)
            ));
            self.turn_rotary(
                "turning the rotary axes to the first measurement at the safe height",
                &first,
            )?;
            self.now = first;
        }
        self.move_xyz("moving over the sphere at the safe height", above)?;
        self.move_xyz("approaching the sphere", pole)
    }
}

/// Where the rotary axes stood when the sphere was not found, if any was off 0: a run
/// stopped mid-cycle leaves the table turned, and the sphere turned with it.
fn turned_table(start: &Angles) -> String {
    let off: Vec<(Axis, f64)> = Axis::ROTARY
        .iter()
        .zip(start)
        .filter(|(_, a)| a.abs() > 1e-4)
        .map(|(axis, a)| (*axis, *a))
        .collect();
    if off.is_empty() {
        return String::new();
    }
    let stood: Vec<String> = off.iter().map(|(x, a)| format!("{x}{a:+.4}")).collect();
    let zero: Vec<String> = off.iter().map(|(x, _)| format!("{x}+0")).collect();
    format!(
        "; the rotary axes stood at {} (not 0), and the sphere turned with them: bring them to 0 at a safe height first (L {} R0 FMAX M91)",
        stood.join(" "),
        zero.join(" ")
    )
}
