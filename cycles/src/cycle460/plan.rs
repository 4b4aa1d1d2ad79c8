//! The moves of a 460 block, known before anything moves: the cycle's own probing
//! sequence ([`super::measure`]) run on the planner's machine
//! ([`crate::plan::PlanMachine`]: motion guard, exact contacts, a path check against
//! every sphere still possible), once for every sphere the docs allow below the start
//! ([`worlds`]): SET_UP + Q320 below it (expected), just below it (the
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
use crate::plan::{in_every_world, when, PlanMachine, Sphere, SphereSet, World};
use hal::AxisPositions;
use nalgebra::Vector3;

/// Every sphere a 460 block allows below `start` (ball centre, machine X/Y/Z), the
/// expected one first, and the set of all of them, for a probe whose table row gives
/// Q407 + R = `rs` and SET_UP + Q320 = `clear`. Each extreme alone: a start at two
/// limits at once is beyond what the pole probe reaches.
pub fn worlds(
    start: Vector3<f64>,
    frame: &[Vector3<f64>; 3],
    rs: f64,
    clear: f64,
) -> (Vec<World>, SphereSet) {
    let n = frame[2];
    let at = |off: Vector3<f64>, gap: f64| Sphere {
        centre: start + off - n * (rs + gap),
        touch: rs,
    };
    let zero = Vector3::zeros();
    let mut worlds = vec![
        World {
            truth: at(zero, clear),
            what: None,
        },
        World {
            truth: at(zero, 0.0),
            what: Some(format!(
                "the probe starts just above the sphere's pole (the sphere {clear:.4} mm higher than SET_UP + Q320 below the start)"
            )),
        },
    ];
    let reach = START_REACH * rs;
    for (w, name) in [(frame[0], "main"), (frame[1], "minor")] {
        for (sign, s) in [(1.0, "+"), (-1.0, "-")] {
            worlds.push(World {
                truth: at(w * (sign * reach), clear),
                what: Some(format!(
                    "the sphere centre stands {reach:.4} mm off below the start toward the {s}{name} axis"
                )),
            });
        }
    }
    let base = start - n * (rs + clear);
    let possible = SphereSet {
        base,
        axis: n,
        length: clear,
        radial: reach,
        touch: rs,
    };
    (worlds, possible)
}

/// Plans every move of the block from `start` (every axis where the program leaves
/// them) in every world of [`worlds`]; where the expected world leaves the axes, or
/// why the block cannot be planned (the step, and the world when it is not the
/// expected one).
pub fn plan_moves(
    p: &CalibrationParams,
    call: &CycleBlock,
    cfg: &CyclesConfig,
    datum: &Datum,
    start: &AxisPositions,
) -> Result<AxisPositions, String> {
    let probe = &call.tool.probe;
    let old = probe.calibration();
    let frame = super::frame(call);
    let rs = p.sphere_radius + old.r;
    let clear = probe.set_up + p.clearance;
    let (worlds, possible) = worlds(Vector3::from(start.xyz()), &frame, rs, clear);
    in_every_world(
        &worlds,
        |w| {
            let mut machine = PlanMachine::new(&cfg.machine, None, w.truth, possible, *start)
                .with_orientable_spindle(true);
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
            Ok(machine.position())
        },
        |e: String, what| when(&e, what),
    )
}
