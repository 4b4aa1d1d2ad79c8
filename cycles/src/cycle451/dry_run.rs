//! The plan of every move of a 451 block, made by running the cycle's own sequence
//! ([`super::measure`]) on the planner's machine ([`crate::plan::PlanMachine`]): the
//! machine's motion guard, the sphere followed through the rotary axes, and a path
//! check that finds any positioning move that would touch it. The sequence runs once
//! for every sphere the block allows ([`worlds`]): Q431 = 1/3 the start anywhere the
//! docs allow over the sphere (from just above the pole up to Q320 + SET_UP above
//! it, up to LOCATE_REACH x (Q407 + R) off its centre), Q431 = 0/2 at the datum.
//! `check` and `run` both call
//! [`plan_moves`] before the program's first move, so `check` refuses what `run` could
//! meet, at the same step with the same message, and `run` never starts a cycle whose
//! moves it already knows can fail.

use super::measure::{Measure, LOCATE_REACH};
use super::plan::{plan_on, PlanError, PlanErrorKind};
use super::KinematicsParams;
use crate::cycle::CycleContext;
use crate::cycle_block::CycleBlock;
use crate::cycles_config::CyclesConfig;
use crate::datum::Datum;
use crate::error::CycleError;
use crate::kinematics::model::{angles_of, ErrorSet, KinematicModel};
use crate::kinematics::LocalEstimator;
use crate::kinematics_file::ActiveKinematics;
use crate::machine_time::Prediction;
use crate::plan::{in_every_world, when, PlanMachine, Sphere, SphereSet, StartReach, World};
use hal::AxisPositions;
use nalgebra::Vector3;
use std::path::Path;

/// Where the planned 451 block leaves the machine.
#[derive(Clone, Debug, PartialEq)]
pub struct PlannedRun {
    /// Every axis where the cycle leaves it.
    pub end: AxisPositions,
    /// The datum the cycle sets (Q431 = 1/3: the sphere centre), machine X/Y/Z.
    pub preset: [f64; 3],
    /// Every positioning target, in order.
    pub moves: Vec<AxisPositions>,
    /// The machine time the moves will take, and their lower bound.
    pub time: Prediction,
}

/// Plans every move of a 451 block: the plan of [`super::plan()`], then the cycle's
/// own sequence (locating or approaching, every position, the way back) on a
/// [`PlanMachine`] that starts at `start` (every axis where the program leaves it)
/// with the datum `datum`, once in every world of [`worlds`]. Any move the machine
/// would refuse, or that would touch the sphere outside a probing move, in any of
/// them, is an error naming the step (and the world, when it is not the expected
/// one), as `run` would meet it. The result is the expected world's.
pub fn plan_moves(
    params: &KinematicsParams,
    call: &CycleBlock,
    cfg: &CyclesConfig,
    kinematics: &Path,
    datum: &Datum,
    start: &AxisPositions,
) -> Result<PlannedRun, PlanError> {
    let kinematics_plan = plan_on(params, &call.tool.probe, cfg)?;
    let active = ActiveKinematics::load(kinematics, &cfg.machine)
        .map_err(|e| PlanError::new(PlanErrorKind::Moves, format!("active kinematics: {e}")))?;
    let model = KinematicModel::new(&kinematics_plan.chain, &ErrorSet::from_map(&active.errors));
    let (worlds, possible) = worlds(params, call, cfg, &model, datum, start);
    q408_for_every_start(params, call, cfg, &model, &worlds)?;
    let as_plan = |e: CycleError| match e {
        CycleError::Plan(m) => PlanError::new(PlanErrorKind::Moves, m),
        e => PlanError::new(PlanErrorKind::Moves, e.to_string()),
    };
    in_every_world(
        &worlds,
        |w| {
            let mut machine =
                PlanMachine::new(&cfg.machine, Some(model.clone()), w.truth, possible, *start);
            let mut estimator = LocalEstimator;
            let mut confirm = |_: &crate::confirmation::Confirmation| true;
            let mut progress = |_: crate::progress::ProgressEvent| {};
            let out_dir = std::env::temp_dir();
            let mut ctx = CycleContext {
                cfg,
                kinematics: kinematics.to_path_buf(),
                estimator: &mut estimator,
                confirm: &mut confirm,
                progress: &mut progress,
                out_dir: &out_dir,
                program: None,
                probing3d: Vec::new(),
                datum: datum.clone(),
                machine_time: None,
            };
            let preset = {
                let mut m = Measure::new(
                    &mut machine,
                    &mut ctx,
                    &kinematics_plan,
                    call,
                    model.clone(),
                )
                .map_err(as_plan)?;
                if params.preset == 1 || params.preset == 3 {
                    m.locate().map_err(as_plan)?;
                } else {
                    m.approach_datum().map_err(as_plan)?;
                }
                m.measure_axes().map_err(as_plan)?;
                m.preset
            };
            Ok(PlannedRun {
                end: machine.position(),
                preset: preset.into(),
                moves: machine.moves().to_vec(),
                time: machine.prediction(),
            })
        },
        |e: PlanError, what| PlanError::new(e.kind(), when(&e.to_string(), what)),
    )
}

/// Every sphere a 451 block allows, the expected one first, and the set of all of
/// them that a move before the first contact must keep off. Q431 = 1/3: the probe
/// stands over the sphere as the docs allow, from just above its pole up to
/// Q320 + SET_UP above it (expected: Q320 + SET_UP), with the centre up to
/// [`LOCATE_REACH`] x (Q407 + R) off below the start in the working plane. Q431 = 0/2:
/// the centre at the active datum with the rotary axes at 0. Before the first contact
/// a move also keeps off a radius up to half of maxDevCalBall above Q407 (the cycle
/// checks the radius only once it has probed). Each extreme alone: a start at two
/// limits at once is beyond what the pole probe reaches.
pub fn worlds(
    params: &KinematicsParams,
    call: &CycleBlock,
    cfg: &CyclesConfig,
    model: &KinematicModel,
    datum: &Datum,
    start: &AxisPositions,
) -> (Vec<World>, SphereSet) {
    let probe = &call.tool.probe;
    let rs = params.sphere_radius + probe.radius;
    let dev = 0.5 * cfg.parameters.max_dev_cal_ball;
    if params.preset != 1 && params.preset != 3 {
        let zero = [0.0; 3];
        let origin = Vector3::from(datum.origin()) - model.ball_offset(&zero);
        let centre = model.table_point(&zero, &origin);
        let worlds = vec![World {
            truth: Sphere { centre, touch: rs },
            what: None,
        }];
        return (
            worlds,
            SphereSet::one(Sphere {
                centre,
                touch: rs + dev,
            }),
        );
    }
    let a0 = angles_of(start);
    let [main, minor, tool] = call.tool.axis.indices();
    let unit = |i: usize| {
        let mut e = Vector3::zeros();
        e[i] = 1.0;
        model.tool_vector(&a0, e)
    };
    StartReach {
        start: Vector3::from(start.xyz()),
        frame: [unit(main), unit(minor), unit(tool)],
        rs,
        clear: probe.set_up + params.clearance,
        reach: LOCATE_REACH * rs,
        dev,
    }
    .worlds(|p| model.table_point(&a0, &p))
}

/// Q408 > 0 with Q431 = 1/3: the probe retracts to Q408 above the preset the cycle
/// sets at the sphere centre, so a start lower over the pole (which the docs allow)
/// retracts higher. Refused unless it stays inside the software limits from every
/// such start, with the highest Q408 that does.
fn q408_for_every_start(
    params: &KinematicsParams,
    call: &CycleBlock,
    cfg: &CyclesConfig,
    model: &KinematicModel,
    worlds: &[World],
) -> Result<(), PlanError> {
    let h = params.retract_height;
    if h <= 0.0 || !(params.preset == 1 || params.preset == 3) {
        return Ok(());
    }
    let t = call.tool.axis.tool_index();
    let axis = hal::Axis::LINEAR[t];
    let Some(limits) = cfg.machine.axis(axis) else {
        return Ok(());
    };
    // The preset the cycle sets in each world: the ball centre at the sphere centre
    // with the rotary axes at 0, wherever they stood at the start.
    let zero = [0.0; 3];
    let preset =
        |w: &World| model.ball_in_machine(&zero, &model.predict(&zero, &w.truth.centre))[t];
    let (high, highest) = worlds
        .iter()
        .map(|w| (w, preset(w)))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .expect("the expected world");
    if highest + h <= limits.max {
        return Ok(());
    }
    let when = match &high.what {
        Some(what) => format!(" when {what} (a start the docs allow)"),
        None => String::new(),
    };
    Err(PlanError::new(
        PlanErrorKind::Moves,
        format!(
            "Q408={h}: the retraction height {axis}{:+.4} (Q408 above the preset at the sphere centre, {axis}{highest:+.4}) is outside the software limits {:+.4} .. {:+.4}{when}; the highest Q408 that stays inside from every start the docs allow is {:.4}; nothing moved",
            highest + h,
            limits.min,
            limits.max,
            ((limits.max - highest) * 1e4 + 1e-3).floor() / 1e4
        ),
    ))
}
