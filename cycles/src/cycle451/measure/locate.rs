//! Where the sphere is when the cycle starts: located below the probe in two passes
//! (Q431 = 1/3), or taken at the active datum and approached there (Q431 = 0/2).

use super::{Measure, DATUM_REACH, DATUM_TOLERANCE, LOCATE_DEPTH, LOCATE_REACH};
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
    /// its radius is checked against Q407 and maxDevCalBall before the next move. Second
    /// pass: the sphere measured around that centre, radius monitored against
    /// maxDevCalBall. With a rotary axis off 0 the axes then turn to 0 and the sphere
    /// is measured there ([`Measure::locate_at_zero`]). Returns the centre with the
    /// rotary axes at 0 (ball centre in machine X/Y/Z), measured; Q431 = 1/3 set the
    /// preset there.
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
            .map_err(|e| self.not_found(e))?;
        let touch = Vector3::from(first.positions.xyz());
        let rough = self.first_pass(&start, run, first)?;
        self.checked = true;
        let n = self.frame(&start)[0];
        self.note(format!(
            "locating the sphere (first pass): the sphere centre is about {:.4} mm from below the start position; measuring it again around that centre",
            ((rough - touch) - n * n.dot(&(rough - touch))).norm()
        ));
        let mut located = self.sphere(&start, rough, "locating the sphere")?;
        self.table_point = self.model.table_point(&located.angles, &located.centre);
        // The preset is the sphere centre with the rotary axes at 0 (where the
        // reference is measured), wherever the operator left them. Carried there
        // through the active kinematics it would take the very errors the cycle
        // measures: with the axes turned, the sphere is measured again at 0.
        let zero = [0.0; 3];
        let mut ball = self
            .model
            .ball_in_machine(&zero, &self.model.predict(&zero, &self.table_point));
        let turned = located.angles.iter().any(|a| a.abs() > 1e-9);
        if turned {
            // Q408 counts from the preset while the axes turn: the predicted one.
            self.preset = ball;
            located = self.locate_at_zero(&start)?;
            ball = self.model.ball_in_machine(&zero, &located.centre);
        }
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

    /// The sphere located with the rotary axes at `start` (not all 0): they turn to 0
    /// as between any two positions ([`Measure::go_to`]: at Q408 above the predicted
    /// preset, or at the height that clears the sphere at every angle of the turn),
    /// and the sphere is measured there around where the active kinematics put it.
    /// That measurement is the preset (Q431 = 1/3) and, the axes not moving since, the
    /// first axis's reference.
    fn locate_at_zero(&mut self, start: &Angles) -> Result<super::Sphere, CycleError> {
        let zero = [0.0; 3];
        self.note(format!(
            "Q431={}: the sphere was located with the rotary axes at {}; they turn to 0 and the sphere is measured there, where the preset is taken",
            self.plan.params.preset,
            self.rotary(start)
        ));
        self.go_to(zero, None)?;
        let expected = self.model.predict(&zero, &self.table_point);
        let s = self.sphere(
            &zero,
            expected,
            "locating the sphere with the rotary axes at 0",
        )?;
        self.table_point = self.model.table_point(&zero, &s.centre);
        Ok(s)
    }

    /// A locating probe that found no sphere: the error with what to check (Q431 = 0/2:
    /// the preset; 1/3: where to pre-position, and the rotary axes when they stood
    /// off 0).
    fn not_found(&self, e: CycleError) -> CycleError {
        match e {
            e if self.at_datum() => self.not_at_preset(e),
            CycleError::Machine {
                step,
                kind,
                message,
            } if kind == hal::ErrorKind::NotTriggered => CycleError::Machine {
                step,
                kind,
                message: format!("{message}; before cycle 451 {}", self.where_to_start()),
            },
            e => e,
        }
    }

    /// Where the docs ask the probe to stand before a 451 with Q431 = 1/3 (and the
    /// rotary axes, when they stood off 0).
    fn where_to_start(&self) -> String {
        let rs = self.plan.params.sphere_radius + self.probe.radius;
        format!(
            "position the probe over the sphere centre (at most {:.3} mm off it in the working plane), about Q320 + SET_UP = {:.3} mm above the sphere{}",
            LOCATE_REACH * rs,
            self.clearance(),
            turned_table(&self.start)
        )
    }

    /// What a contact during a positioning move of the cycle tells the operator to
    /// check. Until the first locating pass has checked the radius, every move is
    /// planned with Q407 + R around where the preset (Q431 = 0/2) or the start
    /// (Q431 = 1/3) puts the sphere: a sphere larger than that, or further off than
    /// the documented reach, is met on the way, so the message names Q407, the probe
    /// table's R and the preset or the start. Once checked, the sphere's size is known
    /// and every move follows where the active kinematics put it.
    pub(super) fn contact_check(&self) -> String {
        let p = &self.plan.params;
        if self.checked {
            return format!(
                "the sphere's radius was checked when it was located, so at these angles it stands elsewhere than the active kinematics ({}) put it: check that the sphere is fixed on the table, the active kinematics, and Q320 = {:.4} mm (the clearance of every approach)",
                self.ctx.kinematics.display(),
                p.clearance
            );
        }
        let place = if self.at_datum() {
            format!(
                "the preset X{:+.4} Y{:+.4} Z{:+.4} (with Q431={} the sphere centre is taken at the preset, with the rotary axes at 0, within {:.3} mm): set the preset at the sphere centre, or use Q431=1 with the probe over the sphere",
                self.preset.x,
                self.preset.y,
                self.preset.z,
                p.preset,
                DATUM_REACH * (p.sphere_radius + self.probe.radius)
            )
        } else {
            format!(
                "where the probe stood before the cycle: {}",
                self.where_to_start()
            )
        };
        format!(
            "the sphere is larger than Q407 + R = {:.4} mm, or further off, than this move was planned for: check Q407 (typed {:.4} mm, the sphere's radius), the probe table's R ({:.4} mm, the stylus's ball radius: calibrate it with cycle 460), and {place}",
            p.sphere_radius + self.probe.radius,
            p.sphere_radius,
            self.probe.radius
        )
    }

    /// Q431 = 0/2: the sphere is taken at the active preset.
    pub(super) fn at_datum(&self) -> bool {
        matches!(self.plan.params.preset, 0 | 2)
    }

    /// Q431 = 0/2, a probe that did not trigger (locating or measuring): the sphere is
    /// not where the active preset puts it, so the message names the preset and what
    /// to do. Any other error is returned as it is.
    pub(super) fn not_at_preset(&self, e: CycleError) -> CycleError {
        let q431 = self.plan.params.preset;
        match e {
            CycleError::Machine {
                step,
                kind,
                message,
            } if kind == hal::ErrorKind::NotTriggered && self.at_datum() => CycleError::Machine {
                step,
                kind,
                message: format!(
                    "{message}: no sphere where the active preset X{:+.4} Y{:+.4} Z{:+.4} puts it (with Q431={q431} the sphere centre is taken at the preset, with the rotary axes at 0); check the preset (set it at the sphere centre), or use Q431=1 with the probe over the sphere",
                    self.preset.x, self.preset.y, self.preset.z
                ),
            },
            e => e,
        }
    }

    /// The first locating pass from the pole contact `touch` (ball centre, axes at
    /// `a`, in run `run`): the centre is somewhere on the half sphere of radius Q407 + R below
    /// `touch` (the ball came down along the tool axis without touching before). Every
    /// move clears all of those spheres by the clearance Q320 + SET_UP: up to
    /// Q407 + R + clearance over `touch`, out to 2 (Q407 + R) + clearance from its axis,
    /// down to LOCATE_DEPTH x (Q407 + R) below it, then Q423 points probed toward the
    /// axis (each from its own side, back out the way it came, on to the next along the
    /// tangents of their circle, [`Measure::next_start`]). A sphere with
    /// free radius through the pole contact and those points is the rough centre
    /// (corrected by the probe's calibration); its radius must be Q407 within
    /// maxDevCalBall, else the cycle stops here: every later move is planned with Q407.
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
        self.rapid_xyz(&format!("{what}: up to clear the sphere"), safe)?;
        let out = 2.0 * rs + clearance;
        let deep = touch - n * (LOCATE_DEPTH * rs);
        let phi0 = self.first_pass_start(a, [safe, deep], out);
        // Between points along the tangents of their circle (`out` from the axis):
        // every sphere the pole contact allows has its centre within Q407 + R of the
        // axis, so those legs clear it by Q320 + SET_UP, as the points' starts do.
        let mut prev = None;
        for i in 0..p.points {
            let phi = (phi0 + 360.0 * f64::from(i) / f64::from(p.points)).to_radians();
            let w = u * phi.cos() + v * phi.sin();
            let step = format!("{what}: point {} of {}", i + 1, p.points);
            self.next_start(&step, a, [deep, safe], out, prev, w)?;
            let c = self
                .probe(&step, -w, out + self.probe.dist)
                .map_err(|e| self.not_found(e))?;
            contacts.push(c);
            self.rapid_xyz(&step, deep + w * out)?;
            prev = Some(w);
        }
        if let Some(w) = prev {
            self.rapid_xyz(&format!("{what}: back up"), safe + w * out)?;
        }
        self.rapid_xyz(&format!("{what}: back over the pole"), safe)?;
        let fit =
            self.ctx.estimator.fit_sphere(run, &contacts).map_err(|e| {
                CycleError::Geometry(format!("{what}: sphere fit (run {run}): {e}"))
            })?;
        // The seeds: the control measures the radius first and ends the measurement
        // when it differs from the input by more than maxDevCalBall. Every later move
        // is planned with Q407: a sphere larger than that would be met positioning.
        let (centre, ball_sphere) = self.calibrated(a, &contacts, fit.centre, fit.radius);
        let radius = ball_sphere - self.probe.calibration().r;
        let dev = radius - p.sphere_radius;
        let max_dev = self.ctx.cfg.parameters.max_dev_cal_ball;
        if dev.is_nan() || dev.abs() > max_dev {
            return Err(CycleError::Geometry(format!(
                "{what}: the fitted sphere radius {radius:.4} mm differs from Q407 = {:.4} mm by {dev:+.4} mm, more than maxDevCalBall = {max_dev} mm: check Q407 (typed {:.4} mm, the sphere measures {radius:.4} mm) and the probe's calibration; stopped before the next move, nothing was changed",
                p.sphere_radius, p.sphere_radius
            )));
        }
        Ok(centre)
    }

    /// Where the first pass's Q423 points start, the points standing `out` from the
    /// axis through `safe` and `deep` (their high and low ends): Q380, or, when one of
    /// their positions or probing paths would leave the software limits (a head
    /// tilted to B+90 puts a point under the sphere), the first arrangement turned from
    /// Q380 in steps of 1/24 of their spacing that stays inside, as the measurement's
    /// points do ([`Measure::sphere`]). None fits: Q380, and the move is refused.
    fn first_pass_start(&mut self, a: &Angles, [safe, deep]: [Vector3<f64>; 2], out: f64) -> f64 {
        let p = &self.plan.params;
        let [_, u, v] = self.frame(a);
        let guard = hal::motion_guard::MotionGuard::new(&self.ctx.cfg.machine);
        let rotary = self.rotary(a);
        let at = |x: Vector3<f64>| AxisPositions::linear(super::arr(&x)).merged(&rotary);
        let fits = |phi0: f64| {
            (0..p.points).all(|i| {
                let phi = (phi0 + 360.0 * f64::from(i) / f64::from(p.points)).to_radians();
                let w = u * phi.cos() + v * phi.sin();
                let low = at(deep + w * out);
                let probe = hal::ProbeMove {
                    direction: super::arr(&-w),
                    feed: self.probe.f,
                    max_distance: out + self.probe.dist,
                };
                guard.check_target(&at(safe + w * out), "move").is_ok()
                    && guard.check_target(&low, "move").is_ok()
                    && guard.check_probe(&low, &probe).is_ok()
            })
        };
        let (phi0, turned) = super::start_angle(p.reference_angle, p.points, fits);
        if turned {
            self.note(format!(
                "locating the sphere (first pass): the points start at {phi0:.1} deg instead of Q380 = {:.1} deg, to stay inside the software limits",
                p.reference_angle
            ));
        }
        phi0
    }

    /// Q431 = 0/2: the sphere centre is the active datum with the rotary axes at their
    /// reference (0 deg), as the preset was set. From wherever the probe is: up along
    /// the tool axis to a height that clears the sphere for every angle the rotary
    /// axes pass on their way to 0 (and the pole start,
    /// and Q408 above the datum when higher, or where the probe already is); the
    /// rotary axes turn there; then over the sphere and down to [`DATUM_REACH`] x
    /// (Q407 + R) over the pole start, where it probes for the sphere
    /// ([`Measure::find_at_datum`]): heights and the pole start clear any sphere that
    /// far from the datum. Every point inside the software limits, else nothing moves.
    pub fn approach_datum(&mut self) -> Result<(), CycleError> {
        let start = self.start;
        let zero = [0.0; 3];
        let c = self.preset - self.model.ball_offset(&zero);
        self.table_point = self.model.table_point(&zero, &c);
        // The sphere is looked for where the datum defines it, with the rotary axes
        // at 0 (a swivel head upright): the first measurement's angles follow as any
        // other position's do.
        let first = zero;
        // The pole probe starts where no sphere within DATUM_REACH of the datum (in
        // any direction) reaches: a preset that far off is met probing, not positioning.
        let rise = DATUM_REACH * (self.plan.params.sphere_radius + self.probe.radius);
        let pole = self.predicted_pole(&first) + self.frame(&first)[0] * rise;
        let here = self.here()?;
        let t = self.tool.tool_index();
        let q408 = self.plan.params.retract_height;
        let clear = self.clear_height(&[start, first], self.reach() + rise);
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
                        "Q431={}: the sphere at the active datum X{:+.4} Y{:+.4} Z{:+.4} is reached over {axis}{v:+.4} with the rotary axes at {}, outside the software limits {:+.4} .. {:+.4}; set the preset at the sphere centre (cycle 247) or pre-position with Q431=1; nothing moved",
                        self.plan.params.preset, self.preset.x, self.preset.y, self.preset.z, self.rotary(&first), c.min, c.max
                    )));
                }
            }
        }
        self.note(format!(
            "Q431={}: the sphere is at the active datum X{:+.4} Y{:+.4} Z{:+.4} (rotary axes at 0); moving over it",
            self.plan.params.preset, self.preset.x, self.preset.y, self.preset.z
        ));
        let up = AxisPositions::new().with(Axis::LINEAR[t], height);
        self.mv("moving up to the safe height", up, self.plan.rapid_feed)?;
        if (0..3).any(|s| (first[s] - start[s]).abs() > 1e-9) {
            self.note(format!(
                "the rotary axes turn from {} to {} at the safe height before the approach",
                self.rotary(&start),
                self.rotary(&first)
            ));
            self.turn_rotary("turning the rotary axes to 0 at the safe height", &first)?;
            self.now = first;
        }
        self.rapid_xyz("moving over the sphere at the safe height", above)?;
        self.approach_xyz("approaching the sphere", pole)?;
        self.find_at_datum(&first, rise)
    }

    /// Q431 = 0/2, the probe `rise` over the pole start of the sphere the datum puts
    /// at `a`: probes for the pole, locates the sphere from that contact as the first
    /// locating pass does (every move clears any sphere the contact allows), and stops
    /// when its centre is further from where the datum puts it than
    /// [`DATUM_TOLERANCE`] x (Q320 + SET_UP or DIST, the smaller): the measurement
    /// around the datum clears a sphere only that far off, and reaches it. Leaves the
    /// probe over the pole.
    fn find_at_datum(&mut self, a: &Angles, rise: f64) -> Result<(), CycleError> {
        let p = &self.plan.params;
        let q431 = p.preset;
        let expected = self.model.predict(a, &self.table_point);
        let n = self.frame(a)[0];
        let dist = 2.0 * rise + self.clearance() + self.probe.dist;
        let run = self.next_run();
        let datum = self.preset;
        let pole = self
            .probe(
                &format!("Q431={q431}: probing the pole of the sphere at the active datum"),
                -n,
                dist,
            )
            .map_err(|e| self.not_at_preset(e))?;
        let centre = self.first_pass(a, run, pole)?;
        let off = (centre - expected).norm();
        let tolerance = DATUM_TOLERANCE * self.clearance().min(self.probe.dist);
        if off > tolerance {
            return Err(CycleError::Geometry(format!(
                "Q431={q431}: the sphere centre is {off:.2} mm from the preset (found {:+.3} {:+.3} {:+.3} mm off the active datum X{:+.4} Y{:+.4} Z{:+.4} along X, Y, Z); the cycle measures it around the preset only within {tolerance:.2} mm (half of Q320 + SET_UP or of DIST, the smaller): set the preset, or use Q431=1; stopped before the next move, nothing was changed",
                centre.x - expected.x,
                centre.y - expected.y,
                centre.z - expected.z,
                datum.x,
                datum.y,
                datum.z
            )));
        }
        self.checked = true;
        self.note(format!(
            "Q431={q431}: the sphere centre is {off:.4} mm from the preset (within {tolerance:.2} mm)"
        ));
        Ok(())
    }
}

/// Where the rotary axes stood when the sphere was not found, if any was off 0: a run
/// stopped mid-cycle leaves the table turned, and the sphere turned with it.
pub(super) fn turned_table(start: &Angles) -> String {
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
