//! Steps 2 and 3: locating the sphere, then measuring it at every position of every
//! planned axis. Between positions the probe retracts to Q408 above the preset and
//! over it before the rotary axes turn, or (Q408 = 0) follows the sphere at the pole in
//! steps of at most [`TRACK_STEP_DEG`]. A sphere is the pole along the (possibly tilted)
//! tool axis and Q423 points around the equator, fitted by the estimator; it is probed
//! again around the fitted centre when that is more than [`RE_PROBE_TOLERANCE`] from
//! where it was expected.

use super::plan::KinematicsPlan;
use super::report::SphereRecord;
use crate::cycle::CycleContext;
use crate::cycle_block::CycleBlock;
use crate::error::CycleError;
use crate::kinematics::model::{angles_of, rotary_slot, Angles, KinematicModel};
use crate::probe_axis::ProbeAxis;
use crate::probe_table::ProbeEntry;
use crate::progress::ProgressEvent;
use hal::{Axis, AxisPositions, Contact, Machine, ProbeMove};
use nalgebra::Vector3;
use std::collections::BTreeMap;

/// A sphere whose fitted centre is farther than this from where it was expected is
/// probed a second time around the fitted centre, mm.
pub const RE_PROBE_TOLERANCE: f64 = 0.1;
/// Largest rotary step of a move that follows the sphere (Q408 = 0), deg.
pub const TRACK_STEP_DEG: f64 = 5.0;
/// How far off the sphere centre the probe may start locating it (Q431 = 1/3), as a
/// fraction of Q407 + ball radius, in any direction of the working plane.
pub const LOCATE_REACH: f64 = 0.6;
/// Depth of the first locating pass's points below the pole contact, as a fraction
/// of Q407 + ball radius: a start within [`LOCATE_REACH`] puts the centre 0.8 to 1
/// of it below the contact, so the points pass within 0.1 of the centre's height.
pub const LOCATE_DEPTH: f64 = 0.9;

pub(super) fn axis_map(axes: &[Axis], a: &Angles) -> BTreeMap<String, f64> {
    axes.iter()
        .map(|x| (x.name().to_string(), a[rotary_slot(*x).expect("rotary")]))
        .collect()
}

pub(super) fn arr(v: &Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// Per position of an axis: whether it is the reference, and its sphere(s).
pub(super) type PositionSpheres = Vec<(bool, Vec<Sphere>)>;

/// A sphere measured at one position (last round).
#[derive(Clone, Debug)]
pub(super) struct Sphere {
    pub angles: Angles,
    pub centre: Vector3<f64>,
    pub radius: f64,
    pub record: SphereRecord,
}

/// Every measured axis (its index in the plan) and its positions.
pub(super) type Measured = Vec<(usize, PositionSpheres)>;

/// The machine, the plan and the model while the cycle measures.
pub(super) struct Measure<'a, 'c, M: Machine> {
    machine: &'a mut M,
    pub ctx: &'a mut CycleContext<'c>,
    plan: &'a KinematicsPlan,
    probe: &'a ProbeEntry,
    tool: ProbeAxis,
    block: u32,
    /// The control's model with the active kinematics.
    pub model: KinematicModel,
    run_base: u64,
    runs: u64,
    /// Commanded rotary angles now.
    now: Angles,
    /// Rotary angles where the cycle started (over the sphere).
    pub start: Angles,
    /// The sphere centre in table coordinates (from the locate measurement).
    table_point: Vector3<f64>,
    /// Active datum (preset plus shift), machine X/Y/Z.
    pub preset: Vector3<f64>,
    /// Notes for the report.
    pub notes: Vec<String>,
    /// The locating measurement (Q431 = 1/3), taken as the first reference when the
    /// axes have not moved since.
    located: Option<Sphere>,
    /// Spheres measured so far (a sphere probed twice counts once).
    pub spheres: usize,
}

impl<'a, 'c, M: Machine> Measure<'a, 'c, M> {
    /// Reads where the machine stands; nothing moves yet.
    pub fn new(
        machine: &'a mut M,
        ctx: &'a mut CycleContext<'c>,
        plan: &'a KinematicsPlan,
        call: &'a CycleBlock,
        model: KinematicModel,
    ) -> Result<Self, CycleError> {
        let start = machine
            .positions()
            .map_err(|e| CycleError::machine("reading the axis positions", &e))?;
        let start = angles_of(&start);
        let preset = Vector3::from(ctx.datum.origin());
        Ok(Measure {
            machine,
            ctx,
            plan,
            probe: &call.tool.probe,
            tool: call.tool.axis,
            block: call.block,
            model,
            run_base: hal::clock::monotonic_ns(),
            runs: 0,
            now: start,
            start,
            table_point: Vector3::zeros(),
            preset,
            notes: Vec::new(),
            located: None,
            spheres: 0,
        })
    }

    pub fn note(&mut self, text: String) {
        (self.ctx.progress)(ProgressEvent::Note {
            block: self.block,
            text,
        });
    }

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
                        "{message}; before cycle 451 position the probe over the sphere centre (at most {:.3} mm off it in the working plane), about Q320 + SET_UP = {:.3} mm above the sphere",
                        LOCATE_REACH * rs,
                        self.clearance()
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
                super::report::preset_words(p.mode.writes()),
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
            self.mv(
                "turning the rotary axes to the first measurement at the safe height",
                self.rotary(&first),
                self.plan.rotary_feed,
            )?;
            self.now = first;
        }
        self.move_xyz("moving over the sphere at the safe height", above)?;
        self.move_xyz("approaching the sphere", pole)
    }

    /// Every angle set the cycle commands, in order: from the start, each axis's
    /// reference and positions (from both sides with Q432), back to the start.
    fn cycle_path(&self) -> Vec<Angles> {
        let plan = self.plan;
        let mut path = vec![self.start];
        for ap in &plan.axes {
            let b = if plan.backlash_measured(ap) {
                plan.params.backlash
            } else {
                0.0
            };
            for &angle in std::iter::once(&0.0).chain(&ap.positions) {
                if b != 0.0 {
                    path.push(plan.angles(ap.axis, angle + b));
                    path.push(plan.angles(ap.axis, angle));
                    path.push(plan.angles(ap.axis, angle - b));
                }
                path.push(plan.angles(ap.axis, angle));
            }
        }
        path.push(self.start);
        path
    }

    /// The tool-axis coordinate of the X/Y/Z axes at which the ball passes `gap`
    /// from the sphere centre (or more) along the tool axis at every angle the rotary
    /// axes take on the straight way through `path` (sampled every degree).
    fn clear_height(&self, path: &[Angles], gap: f64) -> f64 {
        let t = self.tool.tool_index();
        let mut high = f64::NEG_INFINITY;
        for w in path.windows(2).chain(std::iter::once(&path[..1])) {
            let (from, to) = (w[0], *w.last().expect("one angle"));
            let turn = (0..3).map(|s| (to[s] - from[s]).abs()).fold(0.0, f64::max);
            let steps = (turn.ceil() as usize).max(1);
            for i in 0..=steps {
                let f = i as f64 / steps as f64;
                let a: Angles = std::array::from_fn(|s| from[s] + (to[s] - from[s]) * f);
                high = high.max(self.model.predict(&a, &self.table_point)[t] + gap);
            }
        }
        high
    }

    /// Measures every planned axis: the 0 deg reference, then its positions (from both
    /// sides with Q432), and goes back to where the cycle started.
    pub fn measure_axes(&mut self) -> Result<Measured, CycleError> {
        let plan = self.plan;
        let mut measured = Vec::new();
        for (gi, ap) in plan.axes.iter().enumerate() {
            let b = if plan.backlash_measured(ap) {
                plan.params.backlash
            } else {
                0.0
            };
            if plan.params.backlash != 0.0 && ap.hirth > 0.0 {
                self.notes.push(format!(
                    "{}: no backlash measurement on a Hirth axis",
                    ap.axis
                ));
            }
            let mut positions = Vec::new();
            for (k, &angle) in std::iter::once(&0.0).chain(&ap.positions).enumerate() {
                let what = if k == 0 {
                    format!("{} reference at 0 deg", ap.axis)
                } else {
                    format!("{} position {k} ({}{angle:+.4})", ap.axis, ap.axis)
                };
                self.note(format!("measuring {what}"));
                let spheres = self.position(ap.axis, angle, b, &what)?;
                positions.push((k == 0, spheres));
            }
            measured.push((gi, positions));
        }
        // Back to where the cycle started, over the sphere.
        self.go_to(self.start, None)?;
        Ok(measured)
    }

    /// The sphere(s) at one position of `axis`: approached from `angle + b` and from
    /// `angle - b` when `b != 0` (Q432), else directly.
    fn position(
        &mut self,
        axis: Axis,
        angle: f64,
        b: f64,
        what: &str,
    ) -> Result<Vec<Sphere>, CycleError> {
        let plan = self.plan;
        let target = plan.angles(axis, angle);
        let sides: Vec<Option<f64>> = if b != 0.0 {
            vec![Some(b), Some(-b)]
        } else {
            vec![None]
        };
        let unmoved = (0..3).all(|s| (target[s] - self.now[s]).abs() <= 1e-9);
        if b == 0.0 && unmoved {
            if let Some(s) = self.located.take() {
                // Nothing moved since the sphere was located there: that is this
                // position's measurement.
                self.note(format!(
                    "{what}: the locating measurement at the same angles is the reference"
                ));
                return Ok(vec![s]);
            }
        }
        self.located = None;
        let mut spheres = Vec::new();
        for (si, side) in sides.iter().enumerate() {
            let via = side.map(|off| plan.angles(axis, angle + off));
            if si == 0 {
                self.go_to(target, via)?;
            } else {
                if let Some(v) = via {
                    self.track(v)?;
                }
                self.track(target)?;
            }
            let expected = self.model.predict(&target, &self.table_point);
            let label = match side {
                Some(off) => format!(
                    "{what}, approached from {}",
                    if *off > 0.0 { "above" } else { "below" }
                ),
                None => what.to_string(),
            };
            let mut s = self.sphere(&target, expected, &label)?;
            s.record.approach = side.map(|off| if off > 0.0 { "above" } else { "below" }.into());
            spheres.push(s);
        }
        Ok(spheres)
    }

    fn mv(&mut self, step: &str, target: AxisPositions, feed: f64) -> Result<(), CycleError> {
        (self.ctx.progress)(ProgressEvent::Move {
            block: self.block,
            target,
            feed,
        });
        self.machine
            .move_to(&target, feed)
            .map_err(|e| CycleError::machine(step, &e))
    }

    fn move_xyz(&mut self, step: &str, p: Vector3<f64>) -> Result<(), CycleError> {
        self.mv(
            step,
            AxisPositions::linear(arr(&p)),
            self.plan.positioning_feed,
        )
    }

    fn probe(&mut self, step: &str, dir: Vector3<f64>, max: f64) -> Result<Contact, CycleError> {
        let direction = arr(&dir.normalize());
        (self.ctx.progress)(ProgressEvent::Probe {
            block: self.block,
            direction,
            max_distance: max,
        });
        let c = crate::positioning::probe_again_if_lost(
            self.machine,
            &ProbeMove {
                direction,
                feed: self.probe.f,
                max_distance: max,
            },
        )
        .map_err(|e| CycleError::machine(step, &e))?;
        (self.ctx.progress)(ProgressEvent::Contact {
            block: self.block,
            centre: c.positions.xyz(),
        });
        Ok(c)
    }

    fn clearance(&self) -> f64 {
        self.probe.set_up + self.plan.params.clearance
    }

    /// Distance of the ball centre from the sphere centre at a start point.
    fn reach(&self) -> f64 {
        self.plan.params.sphere_radius + self.probe.radius + self.clearance()
    }

    /// Tool axis, main axis and minor axis in machine coordinates at `a`.
    fn frame(&self, a: &Angles) -> [Vector3<f64>; 3] {
        let [main, minor, tool] = self.tool.indices();
        let unit = |i: usize| {
            let mut v = Vector3::zeros();
            v[i] = 1.0;
            self.model.tool_vector(a, v)
        };
        [unit(tool), unit(main), unit(minor)]
    }

    /// Pole start at `a` for the sphere centre `c` (X/Y/Z axis coordinates).
    fn pole(&self, a: &Angles, c: &Vector3<f64>) -> Vector3<f64> {
        c + self.frame(a)[0] * self.reach()
    }

    fn predicted_pole(&self, a: &Angles) -> Vector3<f64> {
        self.pole(a, &self.model.predict(a, &self.table_point))
    }

    fn rotary(&self, a: &Angles) -> AxisPositions {
        let mut p = AxisPositions::new();
        for &x in &self.plan.present {
            p.set(x, a[rotary_slot(x).expect("rotary")]);
        }
        p
    }

    fn next_run(&mut self) -> u64 {
        self.runs += 1;
        let id = self.run_base + self.runs;
        self.machine.set_run(id);
        id
    }

    /// Measures the sphere expected at `c` with the axes at `a` (the probe stands at
    /// the pole start or anywhere above the sphere on the tool axis side).
    fn sphere(
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
            contacts.push(self.probe(&format!("{what}: probing the pole"), -n, dist)?);
            self.move_xyz(&format!("{what}: retracting from the pole"), top)?;
            for i in 0..p.points {
                let phi = (phi0 + 360.0 * f64::from(i) / f64::from(p.points)).to_radians();
                let w = u * phi.cos() + v * phi.sin();
                let step = format!("{what}: point {} of {}", i + 1, p.points);
                self.move_xyz(&step, top + w * reach)?;
                self.move_xyz(&step, c + w * reach)?;
                contacts.push(self.probe(&step, -w, dist)?);
                self.move_xyz(&step, c + w * reach)?;
                self.move_xyz(&step, top + w * reach)?;
            }
            self.move_xyz(&format!("{what}: back over the pole"), top)?;
            let fit = self.ctx.estimator.fit_sphere(run, &contacts).map_err(|e| {
                CycleError::Geometry(format!("{what}: sphere fit (run {run}): {e}"))
            })?;
            let radius = fit.radius - self.probe.radius;
            let shift = (fit.centre - c).norm();
            if round == 0 && shift > RE_PROBE_TOLERANCE {
                self.note(format!(
                    "{what}: the sphere is {shift:.4} mm from where it was expected; probing it again around the fitted centre"
                ));
                c = fit.centre;
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
                centre: fit.centre,
                radius,
                record: SphereRecord {
                    angles: axis_map(&self.plan.present, &angles),
                    centre: arr(&fit.centre),
                    radius,
                    rms: fit.rms,
                    run_ids,
                    approach: None,
                },
            });
        }
        unreachable!("the second round returns")
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
        let spacing = 360.0 / f64::from(p.points);
        let turned = (0..24)
            .map(|k| p.reference_angle + spacing * f64::from(k) / 24.0)
            .find(|phi0| fits(*phi0));
        match turned {
            Some(phi0) if phi0 != p.reference_angle => {
                self.note(format!(
                    "{what}: the probing points start at {phi0:.1} deg instead of Q380 = {:.1} deg, to stay inside the software limits",
                    p.reference_angle
                ));
                phi0
            }
            _ => p.reference_angle,
        }
    }

    /// Turns the rotary axes to `to` following the sphere at the pole, in steps.
    fn track(&mut self, to: Angles) -> Result<(), CycleError> {
        let from = self.now;
        let turn = (0..3).map(|s| (to[s] - from[s]).abs()).fold(0.0, f64::max);
        let steps = ((turn / TRACK_STEP_DEG).ceil() as usize).max(1);
        for i in 1..=steps {
            let f = i as f64 / steps as f64;
            let mut a = from;
            for s in 0..3 {
                a[s] = from[s] + (to[s] - from[s]) * f;
            }
            if i == steps {
                a = to;
            }
            let target = self
                .rotary(&a)
                .merged(&AxisPositions::linear(arr(&self.predicted_pole(&a))));
            self.mv(
                "turning the rotary axes with the probe over the sphere",
                target,
                self.plan.positioning_feed,
            )?;
            self.now = a;
        }
        Ok(())
    }

    /// Goes to the pole start at `to`, approaching `to` from `via` (backlash).
    fn go_to(&mut self, to: Angles, via: Option<Angles>) -> Result<(), CycleError> {
        let moves = (0..3).any(|s| (to[s] - self.now[s]).abs() > 1e-9) || via.is_some();
        let h = self.plan.params.retract_height;
        if !moves {
            let pole = self.predicted_pole(&to);
            return self.move_xyz("moving over the sphere", pole);
        }
        if h > 0.0 {
            let t = self.tool.tool_index();
            let height = self.preset[t] + h;
            // The probe stands at Q408 unmonitored while the rotary axes turn: it must
            // clear the sphere by the ball radius and SET_UP at every angle on the way,
            // this turn's and every later one's (the message names one value for all).
            let mut path: Vec<Angles> = std::iter::once(self.now)
                .chain(via)
                .chain(std::iter::once(to))
                .collect();
            path.extend(self.cycle_path());
            let rs = self.plan.params.sphere_radius + self.probe.radius;
            let lowest = super::plan::round_up(
                self.clear_height(&path, rs + self.probe.set_up) - self.preset[t],
            );
            if h < lowest {
                return Err(CycleError::Plan(format!(
                    "Q408={h}: the retraction height does not clear the sphere by the ball radius + SET_UP at every angle the rotary axes turn through (the sphere rises with them); the lowest Q408 that clears it is {lowest:.4}"
                )));
            }
            let [main, minor, _] = self.tool.indices();
            let up = AxisPositions::new().with(Axis::LINEAR[t], height);
            self.mv("retracting to Q408", up, self.plan.positioning_feed)?;
            let over = AxisPositions::new()
                .with(Axis::LINEAR[main], self.preset[main])
                .with(Axis::LINEAR[minor], self.preset[minor]);
            self.mv(
                "moving over the preset at Q408",
                over,
                self.plan.positioning_feed,
            )?;
            for a in via.iter().chain(std::iter::once(&to)) {
                self.mv(
                    "turning the rotary axes (Q253)",
                    self.rotary(a),
                    self.plan.rotary_feed,
                )?;
                self.now = *a;
            }
            let pole = self.predicted_pole(&to);
            if pole[t] > height {
                return Err(CycleError::Plan(format!(
                    "Q408: the retraction height {height:.3} ({} above the preset) is below the probe's start point over the sphere ({:.3}) at {}; give a higher Q408",
                    h,
                    pole[t],
                    self.rotary(&to)
                )));
            }
            let mut above = pole;
            above[t] = height;
            self.move_xyz("moving over the sphere at Q408", above)?;
            self.move_xyz("approaching the sphere", pole)
        } else {
            if let Some(v) = via {
                self.track(v)?;
            }
            self.track(to)
        }
    }
}
