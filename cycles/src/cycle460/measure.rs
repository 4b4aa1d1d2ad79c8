//! Cycle 460's probing: the pole from the start position (roughly over the sphere, as
//! the operator set it up), three points that locate the sphere (centre and radius)
//! from outside every place it can be for a start up to 1.5 x the reach, the checks of
//! what was located against Q407, the probe table's R and the reach, the equator's Q423 points with the
//! spindle at 0° (and at 180° where it can be oriented) and the pole again over the
//! centre they gave, repeated at the measured equator until ring and pole agree, and
//! with Q455 the rings of the 3D calibration (below the equator too). All with the
//! spindle at one angle at a time, so every position here is the latched (nominal)
//! ball centre: the sphere as seen by the stylus of that angle, translated by minus
//! its offset.
//!
//! Why the locating points: the pole contact does not say how far off the centre the
//! start was. Rings about the start's axis at that contact's height would, with a
//! start a few mm off, put the start points of one side inside the sphere, and the
//! move there would touch it outside a probing move.

use super::evaluate::{direction, fit_circle, Contact3d};
use super::parameters::CalibrationParams;
use crate::cycle::CycleContext;
use crate::cycle_block::CycleBlock;
use crate::error::CycleError;
use crate::positioning::probe_again_if_lost;
use crate::probe_table::calibration::RING_ELEVATIONS;
use crate::progress::ProgressEvent;
use hal::{AxisPositions, Machine, ProbeMove};
use nalgebra::Vector3;

/// The start may be this far off the sphere centre in the working plane, as a
/// fraction of Q407 + R (the documented reach): beyond it the cycle stops after
/// locating the sphere, before the next move.
pub const START_REACH: f64 = 0.5;
/// The locating points start outside every sphere whose centre is up to this fraction
/// of Q407 + R off the start (1.5 x the reach), so that a start beyond the reach is
/// found and refused, not run into.
pub const LOCATE_REACH: f64 = 1.5 * START_REACH;
/// Points that locate the sphere centre before the rings (a circle needs three).
pub const LOCATING_POINTS: usize = 3;
/// How far the sphere may differ from Q407 + the probe table's R (beyond
/// maxDevCalBall) and still be located without a contact outside a probing move, mm:
/// the moves up to locating are planned for it, so that a Q407 typed up to this much
/// wrong, or a table R left from another stylus, is found and refused, not run into.
/// Located, a sphere off by more than maxDevCalBall stops the cycle
/// (`Probing::locate`).
pub const MAX_STYLUS_CHANGE: f64 = 2.0;
/// The equator rings are probed again until their height and the one the pole over
/// their centre gives agree to this, mm.
pub const EQUATOR_HEIGHT_TOLERANCE: f64 = 0.01;
/// The most passes of the equator rings (the second normally agrees: the first is
/// probed at the height locating found).
pub const MAX_EQUATOR_PASSES: usize = 4;

/// The drop below the pole of a ball-centre sphere of radius `s` at `off` mm off its
/// axis (`s` where `off` reaches it: the flank can be anywhere down to the equator).
pub fn flank_drop(s: f64, off: f64) -> f64 {
    if off >= s {
        s
    } else {
        s - (s * s - off * off).sqrt()
    }
}

/// The ball-centre sphere radius (Q407 + R) and the sphere centre's tool-axis
/// coordinate from a ring of radius `rho` probed at height `ring` and the pole contact
/// at `pole` over its centre: `S² = rho² + (ring - (pole - S))²`, solved in closed
/// form (no iteration): `S = -(rho² + a²) / 2a` with `a = ring - pole < 0`.
pub fn sphere_from_ring_and_pole(rho: f64, ring: f64, pole: f64) -> Result<(f64, f64), String> {
    let a = ring - pole;
    if a.is_nan() || a >= 0.0 {
        return Err(format!(
            "the pole contact ({pole:.4}) is not above the ring ({ring:.4})"
        ));
    }
    let s = -(rho * rho + a * a) / (2.0 * a);
    Ok((s, pole - s))
}

/// One equator ring: the spindle angle, its contacts (ball centres) and the circle.
#[derive(Clone, Debug, PartialEq)]
pub struct EquatorRing {
    pub spindle: f64,
    pub contacts: Vec<Vector3<f64>>,
    /// Circle centre in machine coordinates (at the ring's height) and radius.
    pub centre: Vector3<f64>,
    pub radius: f64,
}

/// What cycle 460 probed.
#[derive(Clone, Debug, PartialEq)]
pub struct Probed {
    /// The equator at 0° and (with an orientable spindle) at 180°.
    pub equator: Vec<EquatorRing>,
    /// Height (tool-axis coordinate, machine) the equator was probed at.
    pub equator_height: f64,
    /// The pole contact over the found centre, spindle at 0°.
    pub pole: Vector3<f64>,
    /// The 3D calibration's contacts, spindle at 0°.
    pub contacts_3d: Vec<Contact3d>,
    /// Whether the spindle could be oriented.
    pub oriented: bool,
}

/// The machine and what the cycle knows while it probes.
pub(super) struct Probing<'a, 'c, M: Machine> {
    pub machine: &'a mut M,
    pub ctx: &'a mut CycleContext<'c>,
    pub call: &'a CycleBlock,
    pub p: &'a CalibrationParams,
    /// (main, minor, tool) unit vectors, machine coordinates.
    pub frame: [Vector3<f64>; 3],
    /// Q407 + R: as the probe's row gives it until the sphere is located, then as
    /// measured (every move after locating uses what was measured).
    pub rs: f64,
    /// SET_UP + Q320.
    pub clear: f64,
    /// Whether the sphere has been located (its radius checked against Q407 and the
    /// table's R, its centre against the reach): what a contact while positioning
    /// tells the operator to check ([`Probing::contact_check`]).
    pub located: bool,
}

impl<M: Machine> Probing<'_, '_, M> {
    fn block(&self) -> u32 {
        self.call.block
    }

    fn go(&mut self, step: &str, p: Vector3<f64>) -> Result<(), CycleError> {
        let probe = &self.call.tool.probe;
        let target = AxisPositions::linear([p.x, p.y, p.z]);
        (self.ctx.progress)(ProgressEvent::Move {
            block: self.call.block,
            target,
            feed: probe.fmax,
        });
        let done = self.machine.move_to(&target, probe.fmax);
        done.map_err(|e| match CycleError::machine(step, &e) {
            // The planner's refusal: nothing moved, and it says what to check.
            e @ CycleError::Machine { .. } if e.to_string().ends_with("nothing moved") => e,
            e => crate::positioning::contact_names(
                e,
                &format!("positioning to {target} (machine coordinates)"),
                || self.contact_check(),
            ),
        })
    }

    /// What a contact during a positioning move tells the operator to check. Until the
    /// sphere is located every move is planned with Q407 + the table's R (up to
    /// maxDevCalBall + [`MAX_STYLUS_CHANGE`] larger) about where the start puts it: a
    /// larger sphere, or one further off than 1.5 x the reach, is met on the way, so
    /// the message names Q407, the probe table's R and where to start. Located, its
    /// size and place are measured, and every move follows them.
    fn contact_check(&self) -> String {
        if self.located {
            return format!(
                "the sphere was located and measured, so it moved or is larger than measured: check that the sphere is clamped firmly and the stylus is tight, and Q320 = {:.4} mm (the clearance of every approach)",
                self.p.clearance
            );
        }
        let r = self.call.tool.probe.calibration().r;
        format!(
            "the sphere is larger than Q407 + R = {:.4} mm (+ {:.4} mm), or further off, than this move was planned for: check Q407 (typed {:.4} mm, the sphere's radius), the probe table's R ({r:.4} mm, left from another stylus?), and where the probe stood before the cycle: position the probe over the sphere centre (at most {:.3} mm off it), about SET_UP + Q320 = {:.3} mm above the sphere",
            self.p.sphere_radius + r,
            self.radius_planned(),
            self.p.sphere_radius,
            START_REACH * (self.p.sphere_radius + r),
            self.clear
        )
    }

    /// Probes along `dir` from where the probe is, up to `max` mm; the latched ball
    /// centre.
    fn probe(
        &mut self,
        step: &str,
        dir: Vector3<f64>,
        max: f64,
    ) -> Result<Vector3<f64>, CycleError> {
        let mv = ProbeMove {
            direction: [dir.x, dir.y, dir.z],
            feed: self.call.tool.probe.f,
            max_distance: max,
        };
        let block = self.block();
        (self.ctx.progress)(ProgressEvent::Probe {
            block,
            direction: mv.direction,
            max_distance: max,
        });
        let c =
            probe_again_if_lost(self.machine, &mv).map_err(|e| CycleError::machine(step, &e))?;
        let centre = c.positions.xyz();
        (self.ctx.progress)(ProgressEvent::Contact { block, centre });
        Ok(Vector3::from(centre))
    }

    /// Turns the spindle to `deg`; `false` when the machine has no orientable spindle.
    fn orient(&mut self, deg: f64) -> Result<bool, CycleError> {
        self.machine
            .orient_spindle(deg)
            .map_err(|e| CycleError::machine(format!("orienting the spindle to {deg}°"), &e))
    }

    /// `p` with its tool-axis coordinate replaced by `t`.
    fn at_height(&self, p: Vector3<f64>, t: f64) -> Vector3<f64> {
        let n = self.frame[2];
        p + n * (t - n.dot(&p))
    }

    /// The pole from `over` (ball centre, above the sphere): probes down the tool
    /// axis, backs up to `top`; the contact.
    fn pole(
        &mut self,
        what: &str,
        over: Vector3<f64>,
        max: f64,
        top: f64,
    ) -> Result<Vector3<f64>, CycleError> {
        let n = self.frame[2];
        self.go(&format!("{what}: over the sphere"), over)?;
        let c = self.probe(&format!("{what}: probing the pole"), -n, max)?;
        let up = self.at_height(c, top);
        self.go(&format!("{what}: retracting"), up)?;
        Ok(c)
    }

    /// Probes the sphere about `centre` (ball centre coordinates) against the
    /// direction `u`: from `centre + u (Q407 + R + clearance + margin)`, coming from
    /// and going back to the clearance height `top` when `via_top`. `margin`: how far
    /// the true centre may be from `centre` in the plane (0 once it is known).
    fn point(
        &mut self,
        what: &str,
        centre: Vector3<f64>,
        u: Vector3<f64>,
        top: f64,
        via_top: bool,
        margin: f64,
    ) -> Result<Vector3<f64>, CycleError> {
        let travel = self.clear + 2.0 * margin + self.call.tool.probe.dist;
        self.point_with(what, centre, u, top, via_top, margin, travel)
    }

    /// [`Self::point`] with the probing travel `travel`, mm.
    #[allow(clippy::too_many_arguments)]
    fn point_with(
        &mut self,
        what: &str,
        centre: Vector3<f64>,
        u: Vector3<f64>,
        top: f64,
        via_top: bool,
        margin: f64,
        travel: f64,
    ) -> Result<Vector3<f64>, CycleError> {
        let start = centre + u * (self.rs + self.clear + margin);
        if via_top {
            let over = self.at_height(start, top);
            self.go(
                &format!("{what}: positioning at the clearance height"),
                over,
            )?;
        }
        self.go(&format!("{what}: moving to the start"), start)?;
        let c = self.probe(&format!("{what}: probing"), -u, travel)?;
        self.go(&format!("{what}: retracting"), start)?;
        if via_top {
            let over = self.at_height(start, top);
            self.go(&format!("{what}: to the clearance height"), over)?;
        }
        Ok(c)
    }

    /// Moves at the measuring height around the sphere from azimuth `from` to `to`
    /// (deg) on the circle of the start points, in chords that keep half the clearance.
    fn around(&mut self, centre: Vector3<f64>, from: f64, to: f64) -> Result<(), CycleError> {
        let d = self.rs + self.clear;
        let keep = (self.rs + self.clear / 2.0) / d;
        let max_step = 2.0 * keep.clamp(-1.0, 1.0).acos().to_degrees();
        let steps = ((to - from).abs() / max_step.max(1.0)).ceil().max(1.0) as usize;
        for i in 1..steps {
            let az = from + (to - from) * i as f64 / steps as f64;
            let p = centre + direction(&self.frame, az, 0.0) * d;
            self.go("moving around the sphere at the measuring height", p)?;
        }
        Ok(())
    }

    /// The equator about `centre` (its height is the ring's): Q423 points from Q380.
    fn equator(
        &mut self,
        spindle: f64,
        centre: Vector3<f64>,
        top: f64,
    ) -> Result<EquatorRing, CycleError> {
        let n = self.p.points;
        let via_top = self.p.to_clearance_height;
        let mut contacts = Vec::with_capacity(n);
        let mut last_az = None;
        for k in 0..n {
            let az = self.p.reference_angle + k as f64 * 360.0 / n as f64;
            if let (false, Some(prev)) = (via_top, last_az) {
                self.around(centre, prev, az)?;
            }
            let u = direction(&self.frame, az, 0.0);
            let what = format!("equator, spindle at {spindle}°, point {}", k + 1);
            if !via_top && last_az.is_none() {
                // Q301 = 0 moves at the measuring height between points; the first is
                // still reached from above (straight there would cut through the sphere).
                let over = self.at_height(centre + u * (self.rs + self.clear), top);
                self.go(
                    &format!("{what}: positioning at the clearance height"),
                    over,
                )?;
            }
            contacts.push(self.point(&what, centre, u, top, via_top, 0.0)?);
            last_az = Some(az);
        }
        if !via_top {
            let over = self.at_height(
                centre
                    + direction(&self.frame, last_az.unwrap_or(0.0), 0.0) * (self.rs + self.clear),
                top,
            );
            self.go("equator: to the clearance height", over)?;
        }
        let (centre, radius) = self
            .circle(&contacts, self.frame[2].dot(&centre))
            .map_err(|e| {
                CycleError::Geometry(format!("cycle 460: equator at spindle {spindle}°: {e}"))
            })?;
        Ok(EquatorRing {
            spindle,
            contacts,
            centre,
            radius,
        })
    }

    /// The least-squares circle of `contacts` in the working plane: its centre at
    /// tool-axis coordinate `height`, and its radius.
    fn circle(
        &self,
        contacts: &[Vector3<f64>],
        height: f64,
    ) -> Result<(Vector3<f64>, f64), String> {
        let plane: Vec<[f64; 2]> = contacts
            .iter()
            .map(|c| [self.frame[0].dot(c), self.frame[1].dot(c)])
            .collect();
        let (c2, radius) = fit_circle(&plane)?;
        let centre = self.frame[0] * c2[0] + self.frame[1] * c2[1] + self.frame[2] * height;
        Ok((centre, radius))
    }

    /// How far the ball-centre sphere may differ from Q407 + R (the table's) for the
    /// moves up to locating it, mm: maxDevCalBall plus [`MAX_STYLUS_CHANGE`].
    fn radius_planned(&self) -> f64 {
        self.ctx.cfg.parameters.max_dev_cal_ball + MAX_STYLUS_CHANGE
    }

    /// The whole probing sequence; see the module doc.
    pub fn run(&mut self) -> Result<Probed, CycleError> {
        let n = self.frame[2];
        let here = self
            .machine
            .positions()
            .map_err(|e| CycleError::machine("reading the axis positions", &e))?;
        let start = Vector3::from(here.xyz());
        let oriented = self.orient(0.0)?;
        let dist = self.call.tool.probe.dist;
        let reach = flank_drop(self.rs, START_REACH * self.rs);
        let first = self
            .probe("cycle 460: probing the pole from the start position", -n, self.clear + dist + reach)
            .map_err(|e| match e {
                CycleError::Machine { step, kind, message } if kind == hal::ErrorKind::NotTriggered => {
                    CycleError::Machine {
                        step,
                        kind,
                        message: format!(
                            "{message}; before cycle 460 position the probe over the sphere centre (at most {:.3} mm off it), about SET_UP + Q320 = {:.3} mm above the sphere",
                            START_REACH * self.rs,
                            self.clear
                        ),
                    }
                }
                e => e,
            })?;
        // The clearance height holds for every sphere the locating points allow: its
        // centre up to LOCATE_REACH off the start, its radius down to what the cycle
        // is planned for (a smaller sphere's pole stands higher above a flank contact).
        let smallest = (self.rs - self.radius_planned()).max(self.rs / 2.0);
        let above = n.dot(&first) + self.clear + flank_drop(smallest, LOCATE_REACH * self.rs);
        self.go(
            "cycle 460: retracting from the pole",
            self.at_height(first, above),
        )?;
        let mut centre = self.locate(start, first, above)?;
        let mut top = n.dot(&centre) + self.rs + self.clear;
        let mut last = None;
        for pass in 1..=MAX_EQUATOR_PASSES {
            let mut equator = vec![self.equator(0.0, centre, top)?];
            if oriented {
                self.orient(180.0)?;
                equator.push(self.equator(180.0, centre, top)?);
                self.orient(0.0)?;
            }
            let over = self.at_height(equator[0].centre, top);
            let pole = self.pole(
                "cycle 460: the pole over the centre",
                over,
                self.clear + dist,
                top,
            )?;
            let height = n.dot(&centre);
            let rho = equator.iter().map(|r| r.radius).sum::<f64>() / equator.len() as f64;
            let (s, found) = sphere_from_ring_and_pole(rho, height, n.dot(&pole)).map_err(|e| {
                CycleError::Geometry(format!("cycle 460: the equator, pass {pass}: {e}"))
            })?;
            self.rs = s;
            if (height - found).abs() <= EQUATOR_HEIGHT_TOLERANCE {
                let contacts_3d = self.rings(self.at_height(equator[0].centre, found), top)?;
                return Ok(Probed {
                    equator,
                    equator_height: height,
                    pole,
                    contacts_3d,
                    oriented,
                });
            }
            last = Some((height, found));
            centre = self.at_height(equator[0].centre, found);
            top = n.dot(&pole) + self.clear;
        }
        let (height, found) = last.unwrap_or_default();
        Err(CycleError::Geometry(format!(
            "cycle 460: the equator did not settle: after {MAX_EQUATOR_PASSES} passes the rings were probed at {height:.4} and the pole over their centre puts the equator at {found:.4} ({:.4} mm apart, more than the {EQUATOR_HEIGHT_TOLERANCE} mm the cycle accepts); check that the sphere is clamped firmly and the probe's stylus is tight; the probe table was not changed",
            (height - found).abs()
        )))
    }

    /// The sphere centre (ball centre coordinates) from the first pole contact
    /// `first`, probed from `start`: [`LOCATING_POINTS`] points at the height the
    /// contact suggests, each started LOCATE_REACH x (Q407 + R) plus the radius error
    /// the moves are planned for further out than usual, so outside every sphere a
    /// start up to 1.5 x the reach allows, and reached via the clearance height `top`.
    /// Their circle and the pole contact give the sphere (centre and radius): the R it
    /// gives with Q407 must agree with the probe table's R within maxDevCalBall, and
    /// the pole contact must lie no lower than a start within the reach allows; else
    /// the cycle stops here, before the next move. From here on the moves use the
    /// measured radius.
    fn locate(
        &mut self,
        start: Vector3<f64>,
        first: Vector3<f64>,
        top: f64,
    ) -> Result<Vector3<f64>, CycleError> {
        let n = self.frame[2];
        let far = LOCATE_REACH * self.rs;
        let margin = far + self.radius_planned();
        let hl = n.dot(&first) - self.rs;
        let guess = self.at_height(start, hl);
        let mut contacts = Vec::with_capacity(LOCATING_POINTS);
        let dist = self.call.tool.probe.dist;
        for k in 0..LOCATING_POINTS {
            let az = self.p.reference_angle + k as f64 * 360.0 / LOCATING_POINTS as f64;
            let u = direction(&self.frame, az, 0.0);
            let what = format!(
                "cycle 460: locating the sphere, point {} of {LOCATING_POINTS}",
                k + 1
            );
            // Through to `far` beyond the guess's axis: the sphere's near side lies
            // before it wherever its centre is within `far`.
            let travel = self.rs + self.clear + margin + far + dist;
            contacts.push(self.point_with(&what, guess, u, top, true, margin, travel)?);
        }
        let (axis, rho) = self
            .circle(&contacts, 0.0)
            .map_err(|e| CycleError::Geometry(format!("cycle 460: locating the sphere: {e}")))?;
        // Distance from the centre's axis (along the tool axis) in the plane.
        let off_axis = |p: Vector3<f64>| (p - axis - n * n.dot(&(p - axis))).norm();
        let first_t = n.dot(&first);
        let off = off_axis(first);
        // The sphere through the ring (radius rho at height hl) and the pole contact.
        let centre_t =
            (off * off + first_t * first_t - rho * rho - hl * hl) / (2.0 * (first_t - hl));
        let s = rho.hypot(hl - centre_t);
        self.against_the_table(s)?;
        let drop = centre_t + s - first_t;
        let reach = START_REACH * s;
        let allowed = flank_drop(s, reach);
        let from_start = off_axis(start);
        if drop > allowed + 1e-6 {
            return Err(CycleError::Geometry(format!(
                "cycle 460: the first pole contact is {drop:.4} mm below the sphere's pole, more than the {allowed:.4} mm a start within the reach allows: the start was {from_start:.4} mm off the sphere centre; position the probe over the sphere centre, at most {reach:.3} mm off (half of Q407 + R); the probe table was not changed"
            )));
        }
        self.rs = s;
        self.located = true;
        let block = self.block();
        (self.ctx.progress)(ProgressEvent::Note {
            block,
            text: format!(
                "cycle 460: the sphere centre is {from_start:.4} mm from below the start position"
            ),
        });
        Ok(axis + n * centre_t)
    }

    /// The located sphere's ball-centre radius `s` against Q407 + the probe table's R:
    /// the contacts see only the sum, so a Q407 typed wrong and a table R left from
    /// another stylus look the same. Within maxDevCalBall the difference is the
    /// stylus's (and the certificate's) and goes into R; beyond it the cycle stops
    /// before the next move, nothing written: the operator knows which of the two it
    /// is (a stylus changed, or not), the cycle cannot.
    fn against_the_table(&self, s: f64) -> Result<(), CycleError> {
        let probe = &self.call.tool.probe;
        let table_r = probe.calibration().r;
        let q407 = self.p.sphere_radius;
        let measured = s - q407;
        let dev = measured - table_r;
        let max_dev = self.ctx.cfg.parameters.max_dev_cal_ball;
        if dev.is_nan() || dev.abs() > max_dev {
            return Err(CycleError::Geometry(format!(
                "cycle 460: with Q407 = {q407:.4} mm the sphere found gives R = {measured:.4} mm (its ball-centre radius {s:.4} less Q407), but the probe table holds R = {table_r:.4} mm for probe \"{}\": {dev:+.4} mm apart, more than maxDevCalBall = {max_dev} mm (with the table's R the sphere measures radius {:.4} mm); if the stylus was changed, enter its nominal radius in the probe table (R) and run 460 again; otherwise check Q407 against the sphere's certificate; stopped before the next move, the probe table was not changed",
                probe.name,
                s - table_r
            )));
        }
        Ok(())
    }

    /// The 3D calibration's rings about `centre`, spindle at 0°: Q455 directions each,
    /// at [`RING_ELEVATIONS`]. A direction below the equator is reached from the side:
    /// down beside the sphere to the equator's start point, then in the vertical
    /// plane around the sphere down to its own start (straight down from above would
    /// cut through the sphere), and back the same way.
    fn rings(&mut self, centre: Vector3<f64>, top: f64) -> Result<Vec<Contact3d>, CycleError> {
        let per_ring = self.p.points_3d;
        let mut out = Vec::with_capacity(per_ring * RING_ELEVATIONS.len());
        if per_ring == 0 {
            return Ok(out);
        }
        for (ring, el) in RING_ELEVATIONS.iter().enumerate() {
            for k in 0..per_ring {
                let az = self.p.reference_angle + k as f64 * 360.0 / per_ring as f64;
                let u = direction(&self.frame, az, *el);
                let what = format!("3D calibration, elevation {el}°, direction {}", k + 1);
                let c = if *el < 0.0 {
                    let side = centre + direction(&self.frame, az, 0.0) * (self.rs + self.clear);
                    self.go(
                        &format!("{what}: positioning at the clearance height"),
                        self.at_height(side, top),
                    )?;
                    self.go(&format!("{what}: down beside the sphere"), side)?;
                    self.arc(&what, centre, az, 0.0, *el)?;
                    let c = self.point(&what, centre, u, top, false, 0.0)?;
                    self.arc(&what, centre, az, *el, 0.0)?;
                    self.go(&format!("{what}: beside the sphere"), side)?;
                    self.go(
                        &format!("{what}: to the clearance height"),
                        self.at_height(side, top),
                    )?;
                    c
                } else {
                    self.point(&what, centre, u, top, true, 0.0)?
                };
                out.push(Contact3d { ring, k, centre: c });
            }
        }
        Ok(out)
    }

    /// Moves in the vertical plane of azimuth `az` from elevation `from` to `to` (deg)
    /// on the sphere of the start points, in chords that keep half the clearance.
    fn arc(
        &mut self,
        what: &str,
        centre: Vector3<f64>,
        az: f64,
        from: f64,
        to: f64,
    ) -> Result<(), CycleError> {
        let d = self.rs + self.clear;
        let keep = (self.rs + self.clear / 2.0) / d;
        let max_step = 2.0 * keep.clamp(-1.0, 1.0).acos().to_degrees();
        let steps = ((to - from).abs() / max_step.max(1.0)).ceil().max(1.0) as usize;
        for i in 1..=steps {
            let el = from + (to - from) * i as f64 / steps as f64;
            let p = centre + direction(&self.frame, az, el) * d;
            self.go(&format!("{what}: around the sphere"), p)?;
        }
        Ok(())
    }
}
