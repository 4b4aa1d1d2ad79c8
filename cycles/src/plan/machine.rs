//! The machine every cycle's plan runs on: it moves nothing. It holds every move
//! against the machine's motion guard (the checks and messages of every backend),
//! follows the sphere through the rotary axes with the active kinematic model,
//! answers a probing move with its exact contact on the sphere of the geometry being
//! planned, and refuses a positioning move whose path comes onto any sphere still
//! possible: before the first contact every sphere the cycle's tolerances allow,
//! after it the one the contact found.

use super::path::{first_touch, Sphere, SphereSet, TOUCH_TOLERANCE};
use crate::kinematics::model::{angles_of, KinematicModel};
use crate::machine_time::{MotionModel, Prediction};
use hal::config::MachineConfig;
use hal::motion_guard::MotionGuard;
use hal::{AxisPositions, Contact, ErrorKind, Machine, MachineError, ProbeMove};
use nalgebra::Vector3;

/// A machine that moves nothing; see the module doc.
pub struct PlanMachine {
    guard: MotionGuard,
    axes: u8,
    /// Follows the sphere through the rotary axes; `None`: the cycle turns none, and
    /// the spheres are in machine coordinates.
    model: Option<KinematicModel>,
    /// The sphere of the geometry planned: it answers the probing moves.
    truth: Sphere,
    /// Every sphere still possible before the first contact.
    possible: SphereSet,
    contacted: bool,
    orientable: bool,
    pos: AxisPositions,
    moves: Vec<AxisPositions>,
    /// The machine time of the moves so far, as [`MotionModel`] predicts it: the
    /// plan's clock ([`Machine::clock_ns`]).
    motion: MotionModel,
    prediction: Prediction,
    spindle_deg: f64,
}

impl PlanMachine {
    /// At `start`, the sphere `truth` one of `possible` (it is added to the set's
    /// reach if it lies outside it, so the set always holds what the probe meets).
    pub fn new(
        machine: &MachineConfig,
        model: Option<KinematicModel>,
        truth: Sphere,
        possible: SphereSet,
        start: AxisPositions,
    ) -> Self {
        debug_assert!(possible.contains(&truth), "{truth:?} not in {possible:?}");
        PlanMachine {
            guard: MotionGuard::new(machine),
            axes: machine.axis_mask(),
            model,
            truth,
            possible,
            contacted: false,
            orientable: false,
            pos: start,
            moves: Vec::new(),
            motion: MotionModel::new(machine),
            prediction: Prediction::default(),
            spindle_deg: 0.0,
        }
    }

    /// Whether [`Machine::orient_spindle`] turns the spindle (planned as if it can:
    /// the plan then holds the moves of both spindle angles).
    pub fn with_orientable_spindle(mut self, yes: bool) -> Self {
        self.orientable = yes;
        self
    }

    /// Where the axes stand now.
    pub fn position(&self) -> AxisPositions {
        self.pos
    }

    /// Every positioning target so far, in order (what `run` will command).
    pub fn moves(&self) -> &[AxisPositions] {
        &self.moves
    }

    /// The machine time of the moves so far and their lower bound.
    pub fn prediction(&self) -> Prediction {
        self.prediction
    }

    /// The spheres a positioning move must keep off now.
    fn keep_off(&self) -> SphereSet {
        if self.contacted {
            SphereSet::one(self.truth)
        } else {
            self.possible
        }
    }
}

impl Machine for PlanMachine {
    type Error = MachineError;

    fn axes(&self) -> u8 {
        self.axes
    }

    fn positions(&mut self) -> Result<AxisPositions, MachineError> {
        Ok(self.pos)
    }

    fn move_to(&mut self, target: &AxisPositions, feed: f64) -> Result<(), MachineError> {
        self.guard.check_move_from(&self.pos, target, feed)?;
        let set = self.keep_off();
        if let Some(p) = first_touch(&set, self.model.as_ref(), &self.pos, target) {
            let [x, y, z] = p.xyz();
            let anywhere = if set.is_one() {
                String::new()
            } else {
                format!(
                    " where the sphere can stand before the first contact (its centre up to {:.4} mm off the expected one across the tool axis, over {:.4} mm along it, Q407 + R up to {:.4} mm): check the pre-position and Q320",
                    set.radial, set.length, set.touch
                )
            };
            return Err(MachineError::new(
                ErrorKind::ProbeCollision,
                format!(
                    "the planned path touches the calibration sphere at X{x:+.4} Y{y:+.4} Z{z:+.4}{anywhere}; nothing moved"
                ),
            ));
        }
        self.prediction
            .add_move(&self.motion, &self.pos, target, feed);
        self.pos = self.pos.merged(target);
        self.moves.push(*target);
        Ok(())
    }

    fn probe(&mut self, mv: &ProbeMove) -> Result<Contact, MachineError> {
        let d = Vector3::from(self.guard.check_probe(&self.pos, mv)?.direction);
        let c = match &self.model {
            Some(m) => m.predict(&angles_of(&self.pos), &self.truth.centre),
            None => self.truth.centre,
        };
        let p = Vector3::from(self.pos.xyz());
        let touch = self.truth.touch;
        // |p + d t - c| = touch: the smaller root at or after the start.
        let m = p - c;
        let b = m.dot(&d);
        let disc = b * b - (m.norm_squared() - touch * touch);
        let t = (disc >= 0.0)
            .then(|| -b - disc.sqrt())
            .filter(|t| *t >= -TOUCH_TOLERANCE && *t <= mv.max_distance);
        let Some(t) = t else {
            let end = p + d * mv.max_distance;
            self.pos = self.pos.merged(&AxisPositions::linear(end.into()));
            return Err(MachineError::new(
                ErrorKind::NotTriggered,
                format!(
                    "no contact within {:.3} mm; axes stopped at the end of the path",
                    mv.max_distance
                ),
            ));
        };
        let at = p + d * t.max(0.0);
        self.prediction
            .add_probe(&self.motion, d.into(), mv.feed, t.max(0.0), mv.max_distance);
        self.pos = self.pos.merged(&AxisPositions::linear(at.into()));
        self.contacted = true;
        Ok(Contact {
            positions: self.pos,
            trigger_ns: 0,
            sequence: 0,
            direction: d.into(),
        })
    }

    fn set_run(&mut self, _run_id: u64) {}

    fn orient_spindle(&mut self, angle_deg: f64) -> Result<bool, MachineError> {
        if self.orientable {
            self.prediction
                .add_orient(&self.motion, angle_deg - self.spindle_deg);
            self.spindle_deg = angle_deg;
        }
        Ok(self.orientable)
    }

    /// The predicted time of the moves so far.
    fn clock_ns(&mut self) -> u64 {
        (self.prediction.split.total() * 1e9) as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn config() -> MachineConfig {
        let mut text = String::from("name = \"m\"\n");
        for (node, axis) in ["X", "Y", "Z"].into_iter().enumerate() {
            text.push_str(&format!(
                "[[axis]]\nname = \"{axis}\"\nnode = {}\nincrements_per_unit = 1000.0\nmin = -100.0\nmax = 100.0\nmax_feed = 5000.0\nmax_acceleration = 1000.0\n",
                node + 1
            ));
        }
        MachineConfig::parse(&text, Path::new("m.toml")).unwrap()
    }

    fn sphere() -> Sphere {
        Sphere {
            centre: Vector3::zeros(),
            touch: 15.5,
        }
    }

    fn machine(possible: SphereSet) -> PlanMachine {
        PlanMachine::new(
            &config(),
            None,
            sphere(),
            possible,
            AxisPositions::linear([20.0, 0.0, 0.0]),
        )
    }

    #[test]
    fn a_positioning_path_through_the_sphere_is_refused_and_not_recorded() {
        let mut m = machine(SphereSet::one(sphere()));
        let e = m
            .move_to(&AxisPositions::linear([-20.0, 0.0, 0.0]), 1000.0)
            .unwrap_err();
        assert_eq!(hal::machine::Error::kind(&e), ErrorKind::ProbeCollision);
        assert!(e.to_string().contains("X+0.0000 Y+0.0000 Z+0.0000"), "{e}");
        assert!(m.moves().is_empty());
        assert_eq!(m.position().xyz(), [20.0, 0.0, 0.0], "nothing moved");
        // The motion guard's own checks and messages.
        let e = m
            .move_to(&AxisPositions::linear([20.0, 0.0, 150.0]), 1000.0)
            .unwrap_err();
        assert!(
            e.to_string()
                .contains("Z+150.0000 is outside the software limits"),
            "{e}"
        );
    }

    #[test]
    fn a_path_that_keeps_the_ball_off_the_sphere_is_planned() {
        let mut m = machine(SphereSet::one(sphere()));
        // Around it: 16 mm from the centre at the nearest point, then up and over.
        for p in [
            [20.0, 16.0, 0.0],
            [-20.0, 16.0, 0.0],
            [-20.0, 0.0, 16.0],
            [20.0, 0.0, 16.0],
        ] {
            m.move_to(&AxisPositions::linear(p), 1000.0).unwrap();
        }
        assert_eq!(m.moves().len(), 4);
        // A path that grazes the sphere by less than the tolerance is still a contact.
        m.move_to(&AxisPositions::linear([20.0, 0.0, 15.49]), 1000.0)
            .unwrap();
        assert!(m
            .move_to(&AxisPositions::linear([-20.0, 0.0, 15.49]), 1000.0)
            .is_err());
    }

    /// Before the first contact every sphere the tolerance allows is kept off; the
    /// contact tells which one it is, and from then on that one alone.
    #[test]
    fn before_the_first_contact_every_possible_sphere_is_kept_off() {
        let possible = SphereSet {
            base: Vector3::new(0.0, 0.0, -2.0),
            axis: Vector3::z(),
            length: 4.0,
            radial: 9.3,
            touch: 15.5,
        };
        let mut m = PlanMachine::new(
            &config(),
            None,
            sphere(),
            possible,
            AxisPositions::linear([0.0, 0.0, 40.0]),
        );
        // 17 mm over the nominal centre clears it, not one standing 2 mm higher.
        let e = m
            .move_to(&AxisPositions::linear([0.0, 0.0, 17.0]), 1000.0)
            .unwrap_err();
        assert!(e.to_string().contains("before the first contact"), "{e}");
        assert_eq!(m.position().xyz(), [0.0, 0.0, 40.0], "nothing moved");
        let c = m
            .probe(&ProbeMove {
                direction: [0.0, 0.0, -1.0],
                feed: 100.0,
                max_distance: 30.0,
            })
            .unwrap();
        assert!((c.positions.xyz()[2] - 15.5).abs() < 1e-9, "{c:?}");
        // Now the sphere is known: 17 mm over its centre clears it.
        m.move_to(&AxisPositions::linear([0.0, 0.0, 17.0]), 1000.0)
            .unwrap();
        m.move_to(&AxisPositions::linear([20.0, 0.0, 17.0]), 1000.0)
            .unwrap();
    }
}
