//! Step 1: everything decided before anything moves: which axes the cycle measures and
//! where, Q408 with Hirth axes, feeds, software limits, mode 3's machine datum.

use super::parameters::{AxisRange, Feed, KinematicsParams};
use crate::kinematics::identification::{machine_datum_targets, Mode};
use crate::kinematics::model::{rotary_slot, Angles, ChainSpec};
use crate::kinematics::positions::{measuring_positions, on_grid};
use crate::probe_table::ProbeEntry;
use hal::config::MachineConfig;
use hal::Axis;

/// Why a 451 block cannot run on this machine (nothing moved).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum PlanErrorKind {
    /// An axis's only measuring position is the 0 deg reference.
    NoMeasuringPosition,
    /// Q414/Q418/Q422 ask for no rotary axis the machine has.
    NoAxisToMeasure,
    /// Q408 = 0 (follow the sphere) with a Hirth axis.
    DirectMoveWithHirth,
    /// Q253 (or the probe's FMAX it falls back to) below the motion guard's minimum
    /// feed or above the fastest axis's `max_feed`.
    Feed,
    /// An angle the cycle would command is outside the software limits.
    SoftwareLimit,
    /// Q406 = 3 but no measured axis has a machine datum to take up its error.
    NoMachineDatum,
    /// A move of the cycle the machine would refuse, one that would touch the sphere
    /// outside a probing move, or a Q408 that does not clear the sphere (found by
    /// planning every move before the first, [`super::dry_run`]).
    Moves,
    /// Q432 (backlash) on a machine whose rotary axes an M function positions
    /// (`mStrobeRotAxPos`): the seeds say it cannot be measured there.
    BacklashWithMFunction,
    /// Q408 = 0 (follow the sphere) with rotary axes an M function positions: the PLC
    /// turns them alone, so the probe must stand retracted while they turn.
    DirectMoveWithMFunction,
}

/// A 451 block the machine cannot run; the message names the parameter.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{message}")]
pub struct PlanError {
    kind: PlanErrorKind,
    message: String,
}

impl PlanError {
    pub(crate) fn new(kind: PlanErrorKind, message: impl Into<String>) -> Self {
        Self {
            kind,
            message: message.into(),
        }
    }

    pub fn kind(&self) -> PlanErrorKind {
        self.kind
    }
}

/// A measured axis and its positions.
#[derive(Clone, Debug, PartialEq)]
pub struct AxisPlan {
    pub axis: Axis,
    pub range: AxisRange,
    /// Hirth grid, deg (0 = none).
    pub hirth: f64,
    /// The measuring positions after the 0 deg reference (on the grid, 0 dropped).
    pub positions: Vec<f64>,
}

/// Everything decided before anything moves.
#[derive(Clone, Debug, PartialEq)]
pub struct KinematicsPlan {
    pub params: KinematicsParams,
    pub chain: ChainSpec,
    /// Measured axes, A-B-C order.
    pub axes: Vec<AxisPlan>,
    /// The machine's rotary axes.
    pub present: Vec<Axis>,
    /// Incidence angles of the present axes (on their grid), 0 for absent ones.
    pub incidence: Angles,
    /// The approach to the probing height along the tool axis: min(Q253, FMAX), mm/min
    /// (the seeds). Every move that brings the probe nearer the sphere along the tool
    /// axis runs at it.
    pub approach_feed: f64,
    /// Every other linear positioning move (up, over, around the sphere at a distance
    /// the plan proves clear): the probe table's FMAX, mm/min, as the touch probe
    /// cycles' positioning logic moves.
    pub rapid_feed: f64,
    /// Rotary positioning feed: Q253 (FMAX: the probe table's), deg/min.
    pub rotary_feed: f64,
    /// The M function that positions the rotary axes (`mStrobeRotAxPos`), if one does.
    pub rotary_m: Option<u32>,
}

impl KinematicsPlan {
    /// Angles with `axis` at `angle` and the others at their incidence angles.
    pub fn angles(&self, axis: Axis, angle: f64) -> Angles {
        let mut a = self.incidence;
        a[rotary_slot(axis).expect("rotary")] = angle;
        a
    }

    /// The measured axes.
    pub fn measured(&self) -> Vec<Axis> {
        self.axes.iter().map(|a| a.axis).collect()
    }

    /// Whether Q432 measures the backlash of this axis.
    pub fn backlash_measured(&self, a: &AxisPlan) -> bool {
        self.params.backlash != 0.0 && a.hirth == 0.0
    }
}

/// Checks a 451 block against the machine before anything moves: which axes it
/// measures and where, Q408 with Hirth axes, feeds, software limits, mode 3's machine
/// datum. The message names the parameter.
pub fn plan(
    params: &KinematicsParams,
    probe: &ProbeEntry,
    cfg: &MachineConfig,
) -> Result<KinematicsPlan, PlanError> {
    let params = params.clone();
    let chain = ChainSpec::of(cfg);
    let present: Vec<Axis> = Axis::ROTARY
        .into_iter()
        .filter(|a| cfg.axis(*a).is_some())
        .collect();
    let hirth = |a: Axis| cfg.axis(a).map_or(0.0, |c| c.hirth);
    let mut incidence = [0.0; 3];
    for &a in &present {
        let s = rotary_slot(a).expect("rotary");
        incidence[s] = on_grid(params.ranges[s].incidence, hirth(a));
    }
    let axes = measured_axes(&params, &present, cfg)?;
    if params.retract_height == 0.0 {
        if let Some(a) = present.iter().find(|a| hirth(**a) > 0.0) {
            return Err(PlanError::new(PlanErrorKind::DirectMoveWithHirth, format!(
                "Q408=0 (move directly) is not allowed with the Hirth axis {a} (grid {} deg): give a retraction height",
                hirth(*a)
            )));
        }
    }
    let approach_feed = match params.feed {
        Feed::Fmax => probe.fmax,
        Feed::Value(v) => v.min(probe.fmax),
    };
    let rotary_feed = match params.feed {
        Feed::Fmax => probe.fmax,
        Feed::Value(v) => v,
    };
    // The motion guard refuses a feed below its minimum (the move would look like a
    // hang) or above the fastest axis: refused here, before the first move.
    let fastest = cfg.axes.iter().map(|a| a.max_feed).fold(0.0, f64::max);
    let feed_range = hal::config::bounds::MIN_FEED..=fastest;
    for (what, feed) in [
        (
            "Q253: the approach feed to the probing height min(Q253, FMAX)",
            approach_feed,
        ),
        (
            "the probe table's FMAX (the positioning feed of every other linear move)",
            probe.fmax,
        ),
        ("Q253: the rotary positioning feed", rotary_feed),
    ] {
        if !feed_range.contains(&feed) {
            return Err(PlanError::new(
                PlanErrorKind::Feed,
                format!(
                    "{what} {feed} must be between {} and the machine's fastest max_feed {fastest} (mm/min, deg/min); nothing moved",
                    hal::config::bounds::MIN_FEED
                ),
            ));
        }
    }
    check_limits(&params, &present, &incidence, &axes, cfg)?;
    if params.mode == Mode::MachineDatum {
        let measured: Vec<Axis> = axes.iter().map(|a| a.axis).collect();
        if machine_datum_targets(&chain, &measured).is_empty() {
            return Err(PlanError::new(PlanErrorKind::NoMachineDatum, format!(
                "Q406=3: none of the measured axes ({}) has a rotary axis nearer the machine bed in its kinematic chain whose machine datum could take up its orientation error; use Q406=2",
                measured.iter().map(|a| a.name()).collect::<Vec<_>>().join(", ")
            )));
        }
    }
    Ok(KinematicsPlan {
        params,
        chain,
        axes,
        present,
        incidence,
        approach_feed,
        rapid_feed: probe.fmax,
        rotary_feed,
        rotary_m: None,
    })
}

/// [`plan`] with the cycles' machine parameters: where an M function positions the
/// rotary axes (`[cycles] mStrobeRotAxPos`), the seeds allow no backlash measurement
/// (Q432), and the axes turn only with the probe retracted (Q408 > 0).
pub fn plan_on(
    params: &KinematicsParams,
    probe: &ProbeEntry,
    cfg: &crate::cycles_config::CyclesConfig,
) -> Result<KinematicsPlan, PlanError> {
    let Some(m) = cfg.parameters.rotary_m_function() else {
        return plan(params, probe, &cfg.machine);
    };
    if params.backlash != 0.0 {
        return Err(PlanError::new(
            PlanErrorKind::BacklashWithMFunction,
            format!(
                "Q432={}: backlash cannot be measured when an M function positions the rotary axes (mStrobeRotAxPos = {m} in [cycles] of the machine configuration); give Q432=0; nothing moved",
                params.backlash
            ),
        ));
    }
    if params.retract_height == 0.0 {
        return Err(PlanError::new(
            PlanErrorKind::DirectMoveWithMFunction,
            format!(
                "Q408=0 (move directly) is not allowed when M{m} positions the rotary axes (mStrobeRotAxPos): the probe cannot follow the sphere while the PLC turns them; give a retraction height; nothing moved"
            ),
        ));
    }
    let mut p = plan(params, probe, &cfg.machine)?;
    p.rotary_m = Some(m);
    Ok(p)
}

/// `v` rounded up to the 4 decimals a message shows, so that the value it names as
/// the lowest that clears does clear.
pub(crate) fn round_up(v: f64) -> f64 {
    (v * 1e4 - 1e-3).ceil() / 1e4
}

/// The axes Q414/Q418/Q422 ask for that the machine has, with their measuring
/// positions; at least one.
fn measured_axes(
    params: &KinematicsParams,
    present: &[Axis],
    cfg: &MachineConfig,
) -> Result<Vec<AxisPlan>, PlanError> {
    let hirth = |a: Axis| cfg.axis(a).map_or(0.0, |c| c.hirth);
    let count_q = ["Q414", "Q418", "Q422"];
    let mut axes = Vec::new();
    for &a in present {
        let s = rotary_slot(a).expect("rotary");
        let range = params.ranges[s];
        if range.points == 0 {
            continue;
        }
        let positions = measuring_positions(range.start, range.end, range.points, hirth(a));
        if positions.is_empty() {
            return Err(PlanError::new(PlanErrorKind::NoMeasuringPosition, format!(
                "{}: the only measuring position of {a} is 0 deg, the reference; give another start angle or more points",
                count_q[s]
            )));
        }
        axes.push(AxisPlan {
            axis: a,
            range,
            hirth: hirth(a),
            positions,
        });
    }
    if axes.is_empty() {
        let have: Vec<&str> = present.iter().map(|a| a.name()).collect();
        let asked: Vec<String> = ["A", "B", "C"]
            .iter()
            .zip(params.ranges)
            .filter(|(_, r)| r.points > 0)
            .map(|(n, r)| format!("{} point(s) on {n}", r.points))
            .collect();
        return Err(PlanError::new(
            PlanErrorKind::NoAxisToMeasure,
            format!(
                "no rotary axis to measure: the machine has {} and Q414/Q418/Q422 ask for {}",
                if have.is_empty() {
                    "no rotary axis".to_string()
                } else {
                    have.join(", ")
                },
                if asked.is_empty() {
                    "none".to_string()
                } else {
                    asked.join(", ")
                }
            ),
        ));
    }
    Ok(axes)
}

/// Every angle the cycle commands must be inside the software limits: the incidence
/// angles, the positions, and the positions +/- Q432.
fn check_limits(
    params: &KinematicsParams,
    present: &[Axis],
    incidence: &Angles,
    axes: &[AxisPlan],
    cfg: &MachineConfig,
) -> Result<(), PlanError> {
    let hirth = |a: Axis| cfg.axis(a).map_or(0.0, |c| c.hirth);
    let limit_q = [
        ["Q411", "Q412", "Q413"],
        ["Q415", "Q416", "Q417"],
        ["Q419", "Q420", "Q421"],
    ];
    for &a in present {
        let s = rotary_slot(a).expect("rotary");
        let c = cfg.axis(a).expect("present");
        let check = |v: f64, what: &str| -> Result<(), PlanError> {
            if v < c.min || v > c.max {
                Err(PlanError::new(PlanErrorKind::SoftwareLimit, format!(
                    "{what}: {a}{v:+.4} is outside the software limits {:+.4} .. {:+.4}; nothing moved",
                    c.min, c.max
                )))
            } else {
                Ok(())
            }
        };
        check(incidence[s], limit_q[s][2])?;
        if let Some(p) = axes.iter().find(|p| p.axis == a) {
            let b = if hirth(a) == 0.0 {
                params.backlash.abs()
            } else {
                0.0
            };
            for &v in std::iter::once(&0.0).chain(&p.positions) {
                check(v, &format!("{}/{}", limit_q[s][0], limit_q[s][1]))?;
                if b > 0.0 {
                    check(v + b, "Q432")?;
                    check(v - b, "Q432")?;
                }
            }
        }
    }
    Ok(())
}
