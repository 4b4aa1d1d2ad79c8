//! The physical world of one simulated machine: true kinematics, backlash and Hirth
//! grid of the rotary axes, the artefacts on the table and the probe. The drive
//! simulation calls [`World::step`] once per simulation step with the encoder
//! positions at the start and end of the step; nothing here allocates after
//! [`World::new`].
//!
//! Per rotary axis the physical angle is: encoder angle -> backlash dead band
//! ([`crate::backlash`]) -> Hirth grid (rounded to the nearest multiple of the grid,
//! when there is one) -> the kinematics, which add the zero-position error.

use crate::artefact::{Artefact, ArtefactSet, Surface};
use crate::backlash::Backlash;
use crate::kinematics::TrueKinematics;
use crate::probe::Probe;
use crate::scenario::{effective_hirth, Scenario};
use hal::axis::MAX_AXES;
use hal::{Axis, AxisPositions};
use nalgebra::{Rotation3, Vector3};

/// Sub-steps of a step in which a rotary axis moves: the ball-centre path in table
/// coordinates is then a curve, solved exactly on each chord.
pub const MIN_ROTARY_SUBSTEPS: usize = 64;
/// Largest rotary move per sub-step, deg; long moves get more sub-steps (a chord of
/// 0.01 deg at 500 mm radius deviates by < 0.01 µm from the arc).
const MAX_SUBSTEP_DEG: f64 = 0.01;
const MAX_SUBSTEPS: usize = 1 << 16;

#[derive(Clone, Copy, Debug)]
struct RotaryMechanics {
    present: bool,
    backlash: Backlash,
    hirth: f64,
}

impl RotaryMechanics {
    fn physical(&self, mech: f64) -> f64 {
        if self.hirth > 0.0 {
            (mech / self.hirth).round() * self.hirth
        } else {
            mech
        }
    }
}

/// Kinematics + backlash + artefacts + probe state.
#[derive(Clone, Debug)]
pub struct World {
    kinematics: TrueKinematics,
    artefacts: ArtefactSet,
    probe: Probe,
    /// A, B, C.
    rotary: [RotaryMechanics; 3],
    /// Whether state (backlash, signal) has been taken from a position yet.
    started: bool,
    /// Spindle orientation, deg: turns the stylus (its offset and lobes) about the
    /// tool axis.
    spindle_deg: f64,
}

impl World {
    pub fn new(scenario: &Scenario) -> Self {
        let artefacts = scenario
            .spheres
            .iter()
            .map(|s| Artefact::Sphere(*s))
            .chain(scenario.planes.iter().map(|p| Artefact::Plane(*p)))
            .chain(scenario.cylinders.iter().map(|c| Artefact::Cylinder(*c)))
            .collect();
        let rotary = Axis::ROTARY.map(|axis| RotaryMechanics {
            present: scenario.machine.axis(axis).is_some(),
            backlash: Backlash::new(scenario.truth.axis(axis).map_or(0.0, |t| t.backlash)),
            hirth: effective_hirth(&scenario.machine, &scenario.truth, axis),
        });
        Self {
            kinematics: TrueKinematics::new(&scenario.machine, &scenario.truth),
            artefacts: ArtefactSet::new(artefacts),
            probe: Probe::new(&scenario.probe, scenario.seed),
            rotary,
            started: false,
            spindle_deg: 0.0,
        }
    }

    /// The spindle turns to `deg` (an oriented spindle stop): the stylus turns with it.
    pub fn orient_spindle(&mut self, deg: f64) {
        self.spindle_deg = deg;
    }

    /// Spindle orientation, deg.
    pub fn spindle_deg(&self) -> f64 {
        self.spindle_deg
    }

    pub fn kinematics(&self) -> &TrueKinematics {
        &self.kinematics
    }

    pub fn artefacts(&self) -> &ArtefactSet {
        &self.artefacts
    }

    pub fn probe(&self) -> &Probe {
        &self.probe
    }

    /// Starts the state over at `axes`: no backlash offset, signal taken from the
    /// position without an edge. [`World::step`] does this itself on its first call.
    pub fn reset(&mut self, axes: &AxisPositions) {
        for (m, axis) in self.rotary.iter_mut().zip(Axis::ROTARY) {
            m.backlash.reset(axes.get(axis).unwrap_or(0.0));
        }
        let (c, to_stylus) = (self.ball_centre_in_table(axes), self.to_stylus(axes));
        self.probe.reset(&self.artefacts, &c, &to_stylus);
        self.started = true;
    }

    /// Physical axis positions for encoder positions `axes` given the current
    /// backlash state (rotary angles after dead band and Hirth grid; before the zero
    /// error, which belongs to the kinematics).
    pub fn mechanical(&self, axes: &AxisPositions) -> AxisPositions {
        let mut out = *axes;
        for (m, axis) in self.rotary.iter().zip(Axis::ROTARY) {
            if let Some(cmd) = axes.get(axis).filter(|_| m.present) {
                out.set(axis, m.physical(m.backlash.mechanical(cmd)));
            }
        }
        out
    }

    /// Ball centre in table coordinates with the axes at `axes` (encoder positions):
    /// the real stylus's centre, off the ideal one by its offset and length error.
    pub fn ball_centre_in_table(&self, axes: &AxisPositions) -> Vector3<f64> {
        let mech = self.mechanical(axes);
        let v = self.probe.stylus().centre(self.spindle_deg);
        if v == Vector3::zeros() {
            return self.kinematics.ball_centre_in_table(&mech);
        }
        let m = self.kinematics.head_point_in_machine(&mech, &v);
        self.kinematics.machine_to_table(&mech, m)
    }

    /// Turns table-frame directions into the stylus frame with the axes at `axes`
    /// (table rotation, head rotation, spindle orientation); the identity for an
    /// isotropic stylus, which needs no directions.
    pub fn to_stylus(&self, axes: &AxisPositions) -> Rotation3<f64> {
        let stylus = self.probe.stylus();
        if stylus.is_isotropic() {
            return Rotation3::identity();
        }
        let mech = self.mechanical(axes);
        let table = self.kinematics.table_transform(&mech).rotation;
        let head = self.kinematics.head_transform(&mech).rotation;
        stylus.from_tool_frame(self.spindle_deg) * (head.inverse() * table).to_rotation_matrix()
    }

    /// Signed distance of the ball centre to the nearest artefact surface, mm.
    pub fn distance(&self, axes: &AxisPositions) -> f64 {
        self.artefacts.distance(&self.ball_centre_in_table(axes))
    }

    /// Is the probe deflected with the axes at `axes` (encoder positions)?
    pub fn deflected(&self, axes: &AxisPositions) -> bool {
        let c = self.ball_centre_in_table(axes);
        self.probe
            .deflected_at(&self.artefacts, &c, &self.to_stylus(axes))
    }

    /// How far the ball is pressed into the material, mm (`R` minus the centre's
    /// distance to the nearest surface); 0 when free.
    pub fn penetration(&self, axes: &AxisPositions) -> f64 {
        (self.probe.ball_radius() - self.distance(axes)).max(0.0)
    }

    /// Advances one step: every axis moves linearly from `from` to `to` (encoder
    /// positions). Returns the fraction in `[0, 1]` of the step at which the probe
    /// signal first rises (solved exactly on each linear piece of the ball-centre
    /// path), `None` if it does not. Updates backlash and probe state.
    pub fn step(&mut self, from: &AxisPositions, to: &AxisPositions) -> Option<f64> {
        if !self.started {
            self.reset(from);
        }
        // The axes may have been placed somewhere else since the last step.
        self.update_backlash(from);
        let mut c_prev = self.ball_centre_in_table(from);

        let n = self.substeps(from, to);
        let (f, t) = (from.raw(), to.raw());
        let mask = from.mask() | to.mask();
        let mut edge = None;
        for i in 1..=n {
            let at = if i == n {
                AxisPositions::from_raw(t, mask)
            } else {
                let s = i as f64 / n as f64;
                let mut v = [0.0; MAX_AXES];
                for (k, v) in v.iter_mut().enumerate() {
                    *v = f[k] + s * (t[k] - f[k]);
                }
                AxisPositions::from_raw(v, mask)
            };
            self.update_backlash(&at);
            let c = self.ball_centre_in_table(&at);
            let to_stylus = self.to_stylus(&at);
            if let Some(x) = self.probe.advance(&self.artefacts, &c_prev, &c, &to_stylus) {
                edge.get_or_insert(((i - 1) as f64 + x) / n as f64);
            }
            c_prev = c;
        }
        edge
    }

    fn update_backlash(&mut self, axes: &AxisPositions) {
        for (m, axis) in self.rotary.iter_mut().zip(Axis::ROTARY) {
            if let Some(cmd) = axes.get(axis) {
                m.backlash.update(cmd);
            }
        }
    }

    /// 1 when only linear axes move (the path is then a straight line in table
    /// coordinates); otherwise enough pieces for the rotation to be a chord.
    fn substeps(&self, from: &AxisPositions, to: &AxisPositions) -> usize {
        let (f, t) = (from.raw(), to.raw());
        let turn = Axis::ROTARY
            .iter()
            .zip(&self.rotary)
            .filter(|(_, m)| m.present)
            .map(|(a, _)| (t[a.index()] - f[a.index()]).abs())
            .fold(0.0, f64::max);
        if turn == 0.0 {
            1
        } else {
            ((turn / MAX_SUBSTEP_DEG).ceil() as usize).clamp(MIN_ROTARY_SUBSTEPS, MAX_SUBSTEPS)
        }
    }
}
