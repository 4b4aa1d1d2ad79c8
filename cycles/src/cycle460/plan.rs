//! The moves of a 460 block, known before anything moves: the cycle's own probing
//! sequence ([`super::measure`]) run on the planner's machine
//! ([`crate::plan::PlanMachine`]: motion guard, exact contacts, a path check against
//! every sphere still possible), once for every sphere the docs allow below the start
//! ([`StartReach::worlds`]): SET_UP + Q320 below it (expected), just below it (the
//! probe started just over the pole), and [`START_REACH`] x (Q407 + R) off in each direction of the working
//! plane. `check` and `run` both plan it before the first move. The spindle is taken as
//! orientable, so the plan holds both equator rings: a machine without an orientable
//! spindle makes a subset of these moves. A positioning move whose straight path would
//! bring the ball onto the sphere is refused: the sequence itself must never touch the
//! sphere outside a probing move. The rotary axes do not move in 460: the spheres are
//! planned in machine coordinates.

use super::measure::{Probing, START_REACH};
use super::CalibrationParams;
use crate::cycle::CycleContext;
use crate::cycle_block::CycleBlock;
use crate::cycles_config::CyclesConfig;
use crate::datum::Datum;
use crate::kinematics::LocalEstimator;
use crate::machine_time::Prediction;
use crate::plan::{in_every_world, when, PlanMachine, StartReach};
use hal::AxisPositions;
use nalgebra::Vector3;

/// Plans every move of the block from `start` (every axis where the program leaves
/// them) in every world of [`StartReach::worlds`]; where the expected world leaves the axes, or
/// why the block cannot be planned (the step, and the world when it is not the
/// expected one).
pub fn plan_moves(
    p: &CalibrationParams,
    call: &CycleBlock,
    cfg: &CyclesConfig,
    datum: &Datum,
    start: &AxisPositions,
) -> Result<(AxisPositions, Prediction), String> {
    let probe = &call.tool.probe;
    let old = probe.calibration();
    let frame = super::frame(call);
    let rs = p.sphere_radius + old.r;
    let clear = probe.set_up + p.clearance;
    let (worlds, possible) = StartReach {
        start: Vector3::from(start.xyz()),
        frame,
        rs,
        clear,
        reach: START_REACH * rs,
        dev: 0.0,
    }
    .worlds(|p| p);
    in_every_world(
        &worlds,
        |w| {
            let mut machine = PlanMachine::new(&cfg.machine, None, w.truth, possible, *start)
                .with_orientable_spindle(true);
            let mut estimator = LocalEstimator;
            let mut confirm = |_: &crate::confirmation::Confirmation| true;
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
                machine_time: None,
            };
            Probing {
                rs,
                clear,
                located: false,
                machine: &mut machine,
                ctx: &mut ctx,
                call,
                p,
                frame,
            }
            .run()
            .map_err(|e| format!("cycle 460 cannot be planned: {e}"))?;
            Ok((machine.position(), machine.prediction()))
        },
        |e: String, what| when(&e, what),
    )
}
