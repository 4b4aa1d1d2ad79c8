//! Steps 2 and 3: locating the sphere, then measuring it at every position of every
//! planned axis. Between positions the probe retracts to Q408 above the preset and
//! over it before the rotary axes turn, or (Q408 = 0) to the lowest height that clears
//! the sphere at every angle of the turn. A sphere is the pole along the (possibly tilted)
//! tool axis and Q423 points around the equator, fitted by the estimator; it is probed
//! again around the fitted centre when that is more than [`RE_PROBE_TOLERANCE`] from
//! where it was expected.

use super::plan::KinematicsPlan;
use super::report::SphereRecord;
use super::rotary_m_function;
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

mod locate;
mod positions;
mod sphere;

/// A sphere whose fitted centre is farther than this from where it was expected is
/// probed a second time around the fitted centre, mm.
pub const RE_PROBE_TOLERANCE: f64 = 0.1;
/// How far off the sphere centre the probe may start locating it (Q431 = 1/3), as a
/// fraction of Q407 + ball radius, in any direction of the working plane.
pub const LOCATE_REACH: f64 = 0.6;
/// Q431 = 0/2: how far from the active datum, in any direction, a sphere is still
/// met by the first pole probe rather than a positioning move, as a fraction of Q407 +
/// ball radius (1.5 x [`LOCATE_REACH`]).
pub const DATUM_REACH: f64 = 1.5 * LOCATE_REACH;
/// Q431 = 0/2: how far from where the datum puts it the sphere may be found for the
/// cycle to measure it there, as a fraction of Q320 + SET_UP or of the probe table's
/// DIST, the smaller (its equator approaches pass Q320 + SET_UP from the expected
/// sphere, and each probe looks DIST past it: this leaves half of either).
pub const DATUM_TOLERANCE: f64 = 0.5;
/// Depth of the first locating pass's points below the pole contact, as a fraction
/// of Q407 + ball radius: a start within [`LOCATE_REACH`] puts the centre 0.8 to 1
/// of it below the contact, so the points pass within 0.1 of the centre's height.
pub const LOCATE_DEPTH: f64 = 0.9;

pub(super) fn axis_map(axes: &[Axis], a: &Angles) -> BTreeMap<String, f64> {
    axes.iter()
        .map(|x| (x.name().to_string(), a[rotary_slot(*x).expect("rotary")]))
        .collect()
}

/// Where a sphere's probing points start: Q380 when every point fits there, else the
/// first of 24 steps across one point spacing at which they all fit (inside the
/// software limits); Q380 when none does, so the move itself is refused with its
/// limit. Whether the start was turned from Q380 (the operator is told).
pub(super) fn start_angle(reference: f64, points: u32, fits: impl Fn(f64) -> bool) -> (f64, bool) {
    let spacing = 360.0 / f64::from(points);
    match (0..24)
        .map(|k| reference + spacing * f64::from(k) / 24.0)
        .find(|phi0| fits(*phi0))
    {
        Some(phi0) if phi0 != reference => (phi0, true),
        _ => (reference, false),
    }
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
    /// Whether the first locating pass has checked the sphere's radius (and, with
    /// Q431 = 0/2, its distance from the preset): what a contact while positioning
    /// tells the operator to check ([`Measure::contact_check`]).
    checked: bool,
    /// Spheres measured so far (a sphere probed twice counts once).
    pub spheres: usize,
    /// With `mStrobeRotAxPos`: Q120..Q122 as the last strobe of the M function left
    /// them (the program reads them after the cycle).
    pub rotary_targets: BTreeMap<String, f64>,
}

impl<'a, 'c, M: Machine> Measure<'a, 'c, M> {
    /// The machine's clock now (the cycle's machine time is read against it).
    pub(super) fn clock_ns(&mut self) -> u64 {
        self.machine.clock_ns()
    }

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
            checked: false,
            spheres: 0,
            rotary_targets: BTreeMap::new(),
        })
    }

    pub fn note(&mut self, text: String) {
        (self.ctx.progress)(ProgressEvent::Note {
            block: self.block,
            text,
        });
    }

    fn mv(&mut self, step: &str, target: AxisPositions, feed: f64) -> Result<(), CycleError> {
        (self.ctx.progress)(ProgressEvent::Move {
            block: self.block,
            target,
            feed,
        });
        let done = self.machine.move_to(&target, feed);
        done.map_err(|e| {
            let e = self.at_rotary(CycleError::machine(step, &e));
            match e {
                // The planner's refusal: nothing moved, and it says what to check.
                CycleError::Machine { ref message, .. } if message.ends_with("nothing moved") => e,
                e => crate::positioning::contact_names(
                    e,
                    &format!("positioning to {target} (machine coordinates)"),
                    || self.contact_check(),
                ),
            }
        })
    }

    /// A software-limit refusal names where the rotary axes stand: on a swivel head
    /// the same X/Y/Z point is inside the limits at one angle and outside at another.
    fn at_rotary(&self, e: CycleError) -> CycleError {
        match e {
            CycleError::Machine {
                step,
                kind,
                message,
            } if kind == hal::ErrorKind::SoftwareLimit && !self.plan.present.is_empty() => {
                let at = format!("the rotary axes standing at {}", self.rotary(&self.now));
                let message = match message.strip_suffix("; nothing moved") {
                    Some(m) => format!("{m} with {at}; nothing moved"),
                    None => format!("{message} ({at})"),
                };
                CycleError::Machine {
                    step,
                    kind,
                    message,
                }
            }
            e => e,
        }
    }

    /// Where the X/Y/Z axes stand now (read from the machine).
    fn here(&mut self) -> Result<Vector3<f64>, CycleError> {
        let at = self.machine.positions();
        let at = at.map_err(|e| CycleError::machine("reading the axis positions", &e))?;
        Ok(Vector3::from(at.xyz()))
    }

    /// A linear move that brings the probe nearer the sphere along the tool axis (to
    /// the probing height, or down to a start over it): min(Q253, FMAX), as the seeds say.
    fn approach_xyz(&mut self, step: &str, p: Vector3<f64>) -> Result<(), CycleError> {
        let feed = self.plan.approach_feed;
        self.mv(step, AxisPositions::linear(arr(&p)), feed)
    }

    /// Any other linear positioning move (away from the sphere, or beside it at a
    /// distance the plan proves clear): the probe table's FMAX.
    fn rapid_xyz(&mut self, step: &str, p: Vector3<f64>) -> Result<(), CycleError> {
        let feed = self.plan.rapid_feed;
        self.mv(step, AxisPositions::linear(arr(&p)), feed)
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
        );
        let c = c.map_err(|e| self.at_rotary(CycleError::machine(step, &e)))?;
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

    /// Turns the rotary axes to `a` (`step` names the move in an error). With
    /// `mStrobeRotAxPos` the TNC writes the target angles into Q120 (A), Q121 (B),
    /// Q122 (C) and strobes the M function; the PLC positions the axes, which the
    /// machine's positioning carries out like any other move.
    fn turn_rotary(&mut self, step: &str, a: &Angles) -> Result<(), CycleError> {
        let target = self.rotary(a);
        let Some(m) = self.plan.rotary_m else {
            return self.mv(step, target, self.plan.rotary_feed);
        };
        let values = rotary_m_function::target_values(&target);
        self.note(rotary_m_function::strobe_note(m, &values));
        for (q, v) in values {
            self.rotary_targets.insert(q.to_string(), v);
        }
        let step = format!("{step}: M{m} (mStrobeRotAxPos)");
        self.mv(&step, target, self.plan.rotary_feed)
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
}
