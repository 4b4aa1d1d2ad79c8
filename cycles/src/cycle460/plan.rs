//! The moves of a 460 block, known before anything moves: the cycle's own probing
//! sequence ([`super::measure`]) run on a machine that moves nothing and holds an ideal sphere
//! where the block expects it, SET_UP + Q320 below the start along the tool axis
//! (the operator puts the probe there). `check` and `run` hold the moves against the
//! motion guard ([`crate::planned_move::check_planned`]), as for 431 and 444. The
//! spindle is taken as orientable, so the plan holds both equator rings: a machine
//! without an orientable spindle makes a subset of these moves.

use super::measure::Probing;
use super::CalibrationParams;
use crate::cycle::CycleContext;
use crate::cycle_block::CycleBlock;
use crate::cycles_config::CyclesConfig;
use crate::datum::Datum;
use crate::kinematics::LocalEstimator;
use crate::planned_move::PlannedMove;
use hal::{AxisPositions, Contact, ErrorKind, Machine, MachineError, ProbeMove};
use nalgebra::Vector3;

/// A machine that moves nothing: it records every move and answers a probing move
/// with its exact contact on the sphere of ball-centre radius `touch` about `sphere`.
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
