//! Cycle 460's probing: the pole from the start position (roughly over the sphere, as
//! the operator set it up), three points that locate the centre from outside every
//! place the sphere can be, the equator's Q423 points with the spindle at 0° (and at
//! 180° where it can be oriented), the pole again over the centre the equator gave,
//! and with Q455 the rings of the 3D calibration. All with the spindle at one angle
//! at a time, so every position here is the latched (nominal) ball centre: the sphere
//! as seen by the stylus of that angle, translated by minus its offset.
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
/// fraction of Q407 + R: the first pole contact is then lower, and is probed that much
/// further; the locating points start this much further out.
pub const START_REACH: f64 = 0.5;
/// Points that locate the sphere centre before the rings (a circle needs three).
pub const LOCATING_POINTS: usize = 3;
/// The equator is probed again when the pole over the found centre puts it more than
/// this far from where it was probed, mm.
pub const EQUATOR_HEIGHT_TOLERANCE: f64 = 0.1;

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
    /// Q407 + R (R as the probe's row gives it).
    pub rs: f64,
    /// SET_UP + Q320.
    pub clear: f64,
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
        self.machine
            .move_to(&target, probe.fmax)
            .map_err(|e| CycleError::machine(step, &e))
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
        let start = centre + u * (self.rs + self.clear + margin);
        if via_top {
            let over = self.at_height(start, top);
            self.go(
                &format!("{what}: positioning at the clearance height"),
                over,
            )?;
        }
        self.go(&format!("{what}: moving to the start"), start)?;
        let dist = self.call.tool.probe.dist;
        let c = self.probe(
            &format!("{what}: probing"),
            -u,
            self.clear + 2.0 * margin + dist,
        )?;
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
        let reach = self.rs * (1.0 - (1.0 - START_REACH * START_REACH).sqrt());
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
        // With the start up to START_REACH off the centre the pole is up to `reach`
        // above the contact: the clearance height holds for every such sphere.
        let above = n.dot(&first) + self.clear + reach;
        self.go(
            "cycle 460: retracting from the pole",
            self.at_height(first, above),
        )?;
        let mut centre = self.locate(start, first, above)?;
        let mut top = n.dot(&centre) + self.rs + self.clear;
        for pass in 0..2 {
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
            let found = n.dot(&pole) - self.rs;
            if pass == 1 || (height - found).abs() <= EQUATOR_HEIGHT_TOLERANCE {
                let contacts_3d = self.rings(self.at_height(equator[0].centre, found), top)?;
                return Ok(Probed {
                    equator,
                    equator_height: height,
                    pole,
                    contacts_3d,
                    oriented,
                });
            }
            centre = self.at_height(equator[0].centre, found);
            top = n.dot(&pole) + self.clear;
        }
        unreachable!("the second pass returns")
    }

    /// The sphere centre (ball centre coordinates) from the first pole contact
    /// `first`, probed from `start`: [`LOCATING_POINTS`] points at the height the
    /// contact suggests, each started START_REACH x (Q407 + R) further out than usual,
    /// so outside every sphere the contact allows, and reached via the clearance
    /// height `top`. Their circle gives the centre in the plane; the pole contact's
    /// distance from it, the centre's height.
    fn locate(
        &mut self,
        start: Vector3<f64>,
        first: Vector3<f64>,
        top: f64,
    ) -> Result<Vector3<f64>, CycleError> {
        let n = self.frame[2];
        let margin = START_REACH * self.rs;
        let guess = self.at_height(start, n.dot(&first) - self.rs);
        let mut contacts = Vec::with_capacity(LOCATING_POINTS);
        for k in 0..LOCATING_POINTS {
            let az = self.p.reference_angle + k as f64 * 360.0 / LOCATING_POINTS as f64;
            let u = direction(&self.frame, az, 0.0);
            let what = format!(
                "cycle 460: locating the sphere, point {} of {LOCATING_POINTS}",
                k + 1
            );
            contacts.push(self.point(&what, guess, u, top, true, margin)?);
        }
        let (axis, _) = self
            .circle(&contacts, 0.0)
            .map_err(|e| CycleError::Geometry(format!("cycle 460: locating the sphere: {e}")))?;
        // Distance from the centre's axis (along the tool axis) in the plane.
        let off_axis = |p: Vector3<f64>| (p - axis - n * n.dot(&(p - axis))).norm();
        let off = off_axis(first);
        if off >= self.rs {
            return Err(CycleError::Geometry(format!(
                "cycle 460: locating the sphere: the first pole contact is {off:.3} mm off the centre the locating points give, more than Q407 + R = {:.3} mm: it was not on the sphere",
                self.rs
            )));
        }
        let height = n.dot(&first) - (self.rs * self.rs - off * off).sqrt();
        let from_start = off_axis(start);
        let block = self.block();
        (self.ctx.progress)(ProgressEvent::Note {
            block,
            text: format!(
                "cycle 460: the sphere centre is {from_start:.4} mm from below the start position"
            ),
        });
        Ok(axis + n * height)
    }

    /// The 3D calibration's rings about `centre`, spindle at 0°: Q455 directions each,
    /// at [`RING_ELEVATIONS`].
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
                let c = self.point(&what, centre, u, top, true, 0.0)?;
                out.push(Contact3d { ring, k, centre: c });
            }
        }
        Ok(out)
    }
}
