//! The plan of every move of a 451 block, made by running the cycle's own sequence
//! ([`super::measure`]) on a [`DryRunMachine`]: the sphere where the program puts it,
//! the machine's motion guard, and a path check that finds any positioning move that
//! would touch the sphere. `check` and `run` both call [`plan_moves`] before the
//! program's first move, so `check` refuses what `run` would refuse, at the same step
//! with the same message, and `run` never starts a cycle whose moves it already knows
//! to fail.

use super::measure::Measure;
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
use hal::motion_guard::MotionGuard;
use hal::{AxisPositions, Contact, ErrorKind, Machine, MachineError, ProbeMove};
use nalgebra::Vector3;
use std::path::Path;

/// Largest step, mm or deg, at which a positioning path is checked against the sphere.
const PATH_STEP: f64 = 0.2;
/// A ball centre closer to the sphere centre than Q407 + R by more than this is a
/// contact, mm (a probing contact leaves the ball exactly at Q407 + R). Cycle 460's
/// plan uses it too.
pub(crate) const TOUCH_TOLERANCE: f64 = 1e-3;

/// A machine that moves nothing: it holds every move against the machine's motion
/// guard (the checks every backend makes first, with their messages), follows the
/// sphere through the rotary axes with the active kinematic model, answers probing
/// moves with the exact contact on that sphere, and refuses a positioning move whose
/// path comes within the ball radius of the sphere.
pub struct DryRunMachine {
    guard: MotionGuard,
    axes: u8,
    model: KinematicModel,
    /// Sphere centre in table coordinates (where the ball centre would be at it).
    sphere: Vector3<f64>,
    /// Q407 + ball radius.
    touch: f64,
    pos: AxisPositions,
    /// Every positioning target, in order (what `run` will command).
    pub moves: Vec<AxisPositions>,
}

impl DryRunMachine {
    /// Distance of the ball centre from the sphere centre at `p`.
    fn gap(&self, p: &AxisPositions) -> f64 {
        let a = angles_of(p);
        (Vector3::from(p.xyz()) - self.model.predict(&a, &self.sphere)).norm()
    }

    pub fn positions_now(&self) -> AxisPositions {
        self.pos
    }
}

impl Machine for DryRunMachine {
    type Error = MachineError;

    fn axes(&self) -> u8 {
        self.axes
    }

    fn positions(&mut self) -> Result<AxisPositions, MachineError> {
        Ok(self.pos)
    }

    fn move_to(&mut self, target: &AxisPositions, feed: f64) -> Result<(), MachineError> {
        self.guard.check_move_from(&self.pos, target, feed)?;
        let end = self.pos.merged(target);
        let span = hal::Axis::ALL
            .iter()
            .filter_map(|a| Some((end.get(*a)? - self.pos.get(*a)?).abs()))
            .fold(0.0, f64::max);
        let steps = ((span / PATH_STEP).ceil() as usize).clamp(1, 100_000);
        let from = self.pos;
        for i in 1..=steps {
            let f = i as f64 / steps as f64;
            let mut p = from;
            for (axis, v) in end.iter() {
                let v0 = from.get(axis).unwrap_or(v);
                p.set(axis, v0 + (v - v0) * f);
            }
            if self.gap(&p) < self.touch - TOUCH_TOLERANCE {
                let [x, y, z] = p.xyz();
                return Err(MachineError::new(
                    ErrorKind::ProbeCollision,
                    format!(
                        "the planned path touches the calibration sphere at X{x:+.4} Y{y:+.4} Z{z:+.4}; nothing moved"
                    ),
                ));
            }
        }
        self.pos = end;
        self.moves.push(*target);
        Ok(())
    }

    fn probe(&mut self, mv: &ProbeMove) -> Result<Contact, MachineError> {
        let d = Vector3::from(self.guard.check_probe(&self.pos, mv)?.direction);
        let a = angles_of(&self.pos);
        let c = self.model.predict(&a, &self.sphere);
        let p = Vector3::from(self.pos.xyz());
        // |p + d t - c| = touch: the smaller root at or after the start.
        let m = p - c;
        let b = m.dot(&d);
        let disc = b * b - (m.norm_squared() - self.touch * self.touch);
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
        self.pos = self.pos.merged(&AxisPositions::linear(at.into()));
        Ok(Contact {
            positions: self.pos,
            trigger_ns: 0,
            sequence: 0,
            direction: d.into(),
        })
    }

    fn set_run(&mut self, _run_id: u64) {}
}

/// Where the planned 451 block leaves the machine.
#[derive(Clone, Debug, PartialEq)]
pub struct PlannedRun {
    /// Every axis where the cycle leaves it.
    pub end: AxisPositions,
    /// The datum the cycle sets (Q431 = 1/3: the sphere centre), machine X/Y/Z.
    pub preset: [f64; 3],
    /// Every positioning target, in order.
    pub moves: Vec<AxisPositions>,
}

/// Plans every move of a 451 block: the plan of [`super::plan()`], then the cycle's
/// own sequence (locating or approaching, every position, the way back) on a
/// [`DryRunMachine`] that starts at `start` (every axis where the program leaves it)
/// with the datum `datum`. The sphere is where the block expects it: Q431 = 1/3
/// Q320 + SET_UP below the probe along the tool axis, Q431 = 0/2 at the datum with the
/// rotary axes at 0. Any move the machine would refuse, or that would touch the
/// sphere outside a probing move, is an error naming the step, as `run` would.
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
    let probe = &call.tool.probe;
    let reach = params.sphere_radius + probe.radius + probe.set_up + params.clearance;
    let a0 = angles_of(start);
    let sphere = if params.preset == 1 || params.preset == 3 {
        let n = model.tool_vector(&a0, tool_unit(call));
        model.table_point(&a0, &(Vector3::from(start.xyz()) - n * reach))
    } else {
        let zero = [0.0; 3];
        let origin = Vector3::from(datum.origin()) - model.ball_offset(&zero);
        model.table_point(&zero, &origin)
    };
    let mut machine = DryRunMachine {
        guard: MotionGuard::new(&cfg.machine),
        axes: cfg.machine.axis_mask(),
        model: model.clone(),
        sphere,
        touch: params.sphere_radius + probe.radius,
        pos: *start,
        moves: Vec::new(),
    };
    let mut estimator = LocalEstimator;
    let mut confirm = |_: &str| true;
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
    };
    let as_plan = |e: CycleError| match e {
        CycleError::Plan(m) => PlanError::new(PlanErrorKind::Moves, m),
        e => PlanError::new(PlanErrorKind::Moves, e.to_string()),
    };
    let preset = {
        let mut m =
            Measure::new(&mut machine, &mut ctx, &kinematics_plan, call, model).map_err(as_plan)?;
        if params.preset == 1 || params.preset == 3 {
            m.locate().map_err(as_plan)?;
        } else {
            m.approach_datum().map_err(as_plan)?;
        }
        m.measure_axes().map_err(as_plan)?;
        m.preset
    };
    Ok(PlannedRun {
        end: machine.pos,
        preset: preset.into(),
        moves: machine.moves,
    })
}

/// The tool direction at all axes 0 (the probe's +tool axis), machine X/Y/Z.
fn tool_unit(call: &CycleBlock) -> Vector3<f64> {
    let mut v = Vector3::zeros();
    v[call.tool.axis.tool_index()] = 1.0;
    v
}
