//! The moves of a 460 block, known before anything moves: the cycle's own probing
//! sequence ([`super::measure`]) run on a machine that moves nothing and holds an ideal sphere
//! where the block expects it, SET_UP + Q320 below the start along the tool axis
//! (the operator puts the probe there). `check` and `run` hold the moves against the
//! motion guard ([`crate::planned_move::check_planned`]), as for 431 and 444. The
//! spindle is taken as orientable, so the plan holds both equator rings: a machine
//! without an orientable spindle makes a subset of these moves. A positioning move
//! whose straight path would bring the ball onto the sphere is refused, as 451's plan
//! refuses one: the sequence itself must never touch the sphere outside a probing
//! move.

use super::measure::Probing;
use super::CalibrationParams;
use crate::cycle::CycleContext;
use crate::cycle451::dry_run::TOUCH_TOLERANCE;
use crate::cycle_block::CycleBlock;
use crate::cycles_config::CyclesConfig;
use crate::datum::Datum;
use crate::kinematics::LocalEstimator;
use crate::planned_move::PlannedMove;
use hal::{AxisPositions, Contact, ErrorKind, Machine, MachineError, ProbeMove};
use nalgebra::Vector3;

/// A machine that moves nothing: it records every move, refuses a positioning move
/// whose path touches the sphere of ball-centre radius `touch` about `sphere`, and
/// answers a probing move with its exact contact on that sphere.
struct PlanMachine {
    axes: u8,
    sphere: Vector3<f64>,
    touch: f64,
    pos: AxisPositions,
    moves: Vec<PlannedMove>,
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
        let (a, b) = (
            Vector3::from(self.pos.xyz()),
            Vector3::from(self.pos.merged(target).xyz()),
        );
        // The point of the straight path nearest the sphere centre.
        let ab = b - a;
        let f = if ab.norm_squared() > 0.0 {
            ((self.sphere - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let near = a + ab * f;
        if (near - self.sphere).norm() < self.touch - TOUCH_TOLERANCE {
            return Err(MachineError::new(
                ErrorKind::ProbeCollision,
                format!(
                    "the planned path touches the calibration sphere at X{:+.4} Y{:+.4} Z{:+.4}; nothing moved",
                    near.x, near.y, near.z
                ),
            ));
        }
        self.moves.push(PlannedMove::Position {
            step: "cycle 460".into(),
            target: *target,
            feed,
        });
        self.pos = self.pos.merged(target);
        Ok(())
    }

    fn probe(&mut self, mv: &ProbeMove) -> Result<Contact, MachineError> {
        let from = self.pos.xyz();
        self.moves.push(PlannedMove::Probe {
            step: "cycle 460: probing".into(),
            from,
            mv: *mv,
        });
        let d = Vector3::from(mv.direction).normalize();
        let m = Vector3::from(from) - self.sphere;
        let b = m.dot(&d);
        let disc = b * b - (m.norm_squared() - self.touch * self.touch);
        let t = (disc >= 0.0)
            .then(|| -b - disc.sqrt())
            .filter(|t| (0.0..=mv.max_distance).contains(t));
        let Some(t) = t else {
            return Err(MachineError::new(
                ErrorKind::NotTriggered,
                format!("no contact within {:.3} mm", mv.max_distance),
            ));
        };
        let at = Vector3::from(from) + d * t;
        self.pos = self.pos.merged(&AxisPositions::linear(at.into()));
        Ok(Contact {
            positions: self.pos,
            trigger_ns: 0,
            sequence: 0,
            direction: d.into(),
        })
    }

    fn set_run(&mut self, _run_id: u64) {}

    fn orient_spindle(&mut self, _angle_deg: f64) -> Result<bool, MachineError> {
        Ok(true)
    }
}

/// Every move of the block from `start` (machine X/Y/Z where the program leaves the
/// axes), the sphere SET_UP + Q320 below it; `Err` says why it cannot be planned.
pub fn planned_moves(
    p: &CalibrationParams,
    call: &CycleBlock,
    cfg: &CyclesConfig,
    datum: &Datum,
    start: &AxisPositions,
) -> Result<Vec<PlannedMove>, String> {
    let probe = &call.tool.probe;
    let old = probe.calibration();
    let frame = super::frame(call);
    let rs = p.sphere_radius + old.r;
    let clear = probe.set_up + p.clearance;
    let mut machine = PlanMachine {
        axes: cfg.machine.axis_mask(),
        sphere: Vector3::from(start.xyz()) - frame[2] * (rs + clear),
        touch: rs,
        pos: *start,
        moves: Vec::new(),
    };
    let mut estimator = LocalEstimator;
    let mut confirm = |_: &str| true;
    let mut progress = |_: crate::progress::ProgressEvent| {};
    let out_dir = std::env::temp_dir();
    let mut ctx = CycleContext {
        cfg,
        kinematics: std::path::PathBuf::new(),
        estimator: &mut estimator,
        confirm: &mut confirm,
        progress: &mut progress,
        out_dir: &out_dir,
        program: None,
        probing3d: Vec::new(),
        datum: datum.clone(),
    };
    Probing {
        rs,
        clear,
        machine: &mut machine,
        ctx: &mut ctx,
        call,
        p,
        frame,
    }
    .run()
    .map_err(|e| format!("cycle 460 cannot be planned: {e}"))?;
    Ok(machine.moves)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn machine() -> PlanMachine {
        PlanMachine {
            axes: 0b111,
            sphere: Vector3::new(0.0, 0.0, 0.0),
            touch: 15.5,
            pos: AxisPositions::linear([20.0, 0.0, 0.0]),
            moves: Vec::new(),
        }
    }

    #[test]
    fn a_positioning_path_through_the_sphere_is_refused_and_not_recorded() {
        let mut m = machine();
        let e = m
            .move_to(&AxisPositions::linear([-20.0, 0.0, 0.0]), 1000.0)
            .unwrap_err();
        assert_eq!(hal::machine::Error::kind(&e), ErrorKind::ProbeCollision);
        assert!(e.to_string().contains("X+0.0000 Y+0.0000 Z+0.0000"), "{e}");
        assert!(m.moves.is_empty());
        assert_eq!(m.pos.xyz(), [20.0, 0.0, 0.0], "nothing moved");
    }

    #[test]
    fn a_path_that_keeps_the_ball_off_the_sphere_is_planned() {
        let mut m = machine();
        // Around it: 16 mm from the centre at the nearest point, then up and over.
        m.move_to(&AxisPositions::linear([20.0, 16.0, 0.0]), 1000.0)
            .unwrap();
        m.move_to(&AxisPositions::linear([-20.0, 16.0, 0.0]), 1000.0)
            .unwrap();
        m.move_to(&AxisPositions::linear([-20.0, 0.0, 16.0]), 1000.0)
            .unwrap();
        m.move_to(&AxisPositions::linear([20.0, 0.0, 16.0]), 1000.0)
            .unwrap();
        assert_eq!(m.moves.len(), 4);
        // A path that grazes the sphere by less than the tolerance is still a contact.
        let e = m
            .move_to(&AxisPositions::linear([20.0, 0.0, 15.49]), 1000.0)
            .map(|_| m.move_to(&AxisPositions::linear([-20.0, 0.0, 15.49]), 1000.0));
        assert!(matches!(e, Ok(Err(_))), "{e:?}");
    }
}
