//! Cycle 451 MEASURE KINEMATICS: the calibration sphere measured at several angles of
//! each rotary axis, compared with the active kinematic model, and (modes 1..3) the
//! model corrected (spec.md, "Cycle 451"; seeds 000, 001, 004).
//!
//! # Sequence
//!
//! 1. Locate: the probe stands roughly over the sphere, about Q320 + SET_UP above it
//!    (an `L` block or the operator put it there). It probes down along the tool axis,
//!    then measures the sphere around that estimate. This machine has no preset table:
//!    the active preset is the table origin until Q431 = 1/3 sets it to this centre.
//! 2. Per measured axis, in the order A, B, C: the 0 deg reference first, then the
//!    measuring positions ([`crate::kinematics::positions`]); the other rotary axes stand
//!    at their incidence angles (Q413/Q417/Q421). Between positions the probe retracts to
//!    Q408 above the preset and over the preset in the working plane before the rotary
//!    axes turn at Q253; with Q408 = 0 it follows the sphere at the pole in steps of at
//!    most [`TRACK_STEP_DEG`] (refused with a Hirth axis). Linear pre-positioning runs at
//!    min(Q253, FMAX).
//! 3. Sphere measurement: the pole along the (possibly tilted) tool axis, then Q423
//!    points around the equator in the working plane from Q380, radially toward the
//!    centre; a sphere with free radius through the latched X/Y/Z positions (each
//!    measurement its own run id, fitted by the [`Estimator`]). When the fit moved the
//!    centre by more than [`RE_PROBE_TOLERANCE`] from where it was expected, the sphere is
//!    probed once more around the new centre; the radius of the last round must be Q407
//!    within `maxDevCalBall`.
//! 4. Q432 != 0: every position is measured twice, approached from angle + Q432 and from
//!    angle - Q432; the identification uses the mean, the backlash is the mean tangential
//!    difference over the measuring circle radius (not for radii < 1 mm or Hirth axes).
//! 5. Identification ([`crate::kinematics::identification`]) by the estimator, results
//!    (Q141..Q149, QS144..QS146), protocol `TCHPRAUTO.html`, and for modes 1..3 the
//!    corrected errors written through [`ActiveKinematics::write`]: only after all of that
//!    succeeded, and beyond `maxModification` only when confirmed.

use crate::error::CycleError;
use crate::kinematics::identification::{
    machine_datum_targets, AxisMeasurement, IdentificationInput, IdentificationResult,
    MeasuredPosition, Mode,
};
use crate::kinematics::model::{
    angles_of, rotary_slot, Angles, ChainSpec, ErrorSet, KinematicModel,
};
use crate::kinematics::positions::{measuring_positions, on_grid};
use crate::kinematics::{qs_string, Estimator};
use crate::kinematics_file::ActiveKinematics;
use crate::program::{CycleCall, ProbeAxis, Value};
use crate::runner::ProgressEvent;
use hal::config::{MachineConfig, ProbeEntry};
use hal::{Axis, AxisPositions, Contact, Machine, ProbeMove};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A sphere whose fitted centre is farther than this from where it was expected is
/// probed a second time around the fitted centre, mm.
pub const RE_PROBE_TOLERANCE: f64 = 0.1;
/// Largest rotary step of a move that follows the sphere (Q408 = 0), deg.
pub const TRACK_STEP_DEG: f64 = 5.0;
/// Backlash is not computed on a measuring circle smaller than this, mm.
pub const MIN_BACKLASH_RADIUS: f64 = 1.0;

/// One rotary axis's Q parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxisRange {
    pub start: f64,
    pub end: f64,
    pub incidence: f64,
    pub points: u32,
}

/// Q253.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Feed {
    Value(f64),
    /// FMAX or FAUTO: the probe table's FMAX.
    Fmax,
}

/// The parameters of a 451 block (validated by the parser's table).
#[derive(Clone, Debug, PartialEq)]
pub struct KinematicsParams {
    pub mode: Mode,
    /// Q407.
    pub sphere_radius: f64,
    /// Q320.
    pub clearance: f64,
    /// Q408; 0 = move directly.
    pub retract_height: f64,
    /// Q253.
    pub feed: Feed,
    /// Q380.
    pub reference_angle: f64,
    /// A, B, C: Q411..Q414, Q415..Q418, Q419..Q422.
    pub ranges: [AxisRange; 3],
    /// Q423.
    pub points: u32,
    /// Q431.
    pub preset: u8,
    /// Q432.
    pub backlash: f64,
}

impl KinematicsParams {
    pub fn from_call(call: &CycleCall) -> Result<Self, String> {
        let num = |name: &str| {
            call.number(name)
                .ok_or_else(|| format!("{name}: no numeric value"))
        };
        let feed = match call.params.get("Q253").map(|p| &p.value) {
            Some(Value::Number(v)) => Feed::Value(*v),
            Some(Value::Fmax) | Some(Value::Fauto) => Feed::Fmax,
            _ => return Err("Q253: no value".into()),
        };
        let range = |q: [&str; 4]| -> Result<AxisRange, String> {
            Ok(AxisRange {
                start: num(q[0])?,
                end: num(q[1])?,
                incidence: num(q[2])?,
                points: num(q[3])? as u32,
            })
        };
        Ok(Self {
            mode: Mode::from_q406(num("Q406")?).ok_or("Q406 must be 0..3")?,
            sphere_radius: num("Q407")?,
            clearance: num("Q320")?,
            retract_height: num("Q408")?,
            feed,
            reference_angle: num("Q380")?,
            ranges: [
                range(["Q411", "Q412", "Q413", "Q414"])?,
                range(["Q415", "Q416", "Q417", "Q418"])?,
                range(["Q419", "Q420", "Q421", "Q422"])?,
            ],
            points: num("Q423")? as u32,
            preset: num("Q431")? as u8,
            backlash: num("Q432")?,
        })
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
    /// Linear pre-positioning feed: min(Q253, FMAX), mm/min.
    pub positioning_feed: f64,
    /// Rotary positioning feed: Q253 (FMAX: the probe table's), deg/min.
    pub rotary_feed: f64,
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
pub fn plan(call: &CycleCall, cfg: &MachineConfig) -> Result<KinematicsPlan, String> {
    let params = KinematicsParams::from_call(call)?;
    let probe = &call.tool.probe;
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
    let count_q = ["Q414", "Q418", "Q422"];
    let mut axes = Vec::new();
    for &a in &present {
        let s = rotary_slot(a).expect("rotary");
        let range = params.ranges[s];
        if range.points == 0 {
            continue;
        }
        let positions = measuring_positions(range.start, range.end, range.points, hirth(a));
        if positions.is_empty() {
            return Err(format!(
                "{}: the only measuring position of {a} is 0 deg, the reference; give another start angle or more points",
                count_q[s]
            ));
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
        return Err(format!(
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
        ));
    }
    if params.retract_height == 0.0 {
        if let Some(a) = present.iter().find(|a| hirth(**a) > 0.0) {
            return Err(format!(
                "Q408=0 (move directly) is not allowed with the Hirth axis {a} (grid {} deg): give a retraction height",
                hirth(*a)
            ));
        }
    }
    let positioning_feed = match params.feed {
        Feed::Fmax => probe.fmax,
        Feed::Value(v) => v.min(probe.fmax),
    };
    let rotary_feed = match params.feed {
        Feed::Fmax => probe.fmax,
        Feed::Value(v) => v,
    };
    if positioning_feed <= 0.0 {
        return Err("Q253=0: the pre-positioning feed must be > 0".into());
    }
    // Every angle the cycle commands must be inside the software limits.
    let limit_q = [
        ["Q411", "Q412", "Q413"],
        ["Q415", "Q416", "Q417"],
        ["Q419", "Q420", "Q421"],
    ];
    for &a in &present {
        let s = rotary_slot(a).expect("rotary");
        let c = cfg.axis(a).expect("present");
        let check = |v: f64, what: &str| -> Result<(), String> {
            if v < c.min || v > c.max {
                Err(format!(
                    "{what}: {a}{v:+.4} is outside the software limits {:+.4} .. {:+.4}; nothing moved",
                    c.min, c.max
                ))
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
    if params.mode == Mode::MachineDatum {
        let measured: Vec<Axis> = axes.iter().map(|a| a.axis).collect();
        if machine_datum_targets(&chain, &measured).is_empty() {
            return Err(format!(
                "Q406=3: none of the measured axes ({}) has a rotary axis nearer the machine bed in its kinematic chain whose machine datum could take up its orientation error; use Q406=2",
                measured.iter().map(|a| a.name()).collect::<Vec<_>>().join(", ")
            ));
        }
    }
    Ok(KinematicsPlan {
        params,
        chain,
        axes,
        present,
        incidence,
        positioning_feed,
        rotary_feed,
    })
}

/// One sphere measurement (all rounds).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SphereRecord {
    /// Latched rotary angles (mean over the contacts) by axis name.
    pub angles: BTreeMap<String, f64>,
    /// Fitted centre of the latched X/Y/Z positions, mm.
    pub centre: [f64; 3],
    /// Fitted sphere radius (ball radius subtracted), mm.
    pub radius: f64,
    /// RMS residual of the fit, mm.
    pub rms: f64,
    /// Run id of each round (the last one counts).
    pub run_ids: Vec<u64>,
    /// "above" or "below" when approached for the backlash measurement.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub approach: Option<String>,
}

/// One measuring position of an axis in the result.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PositionReport {
    /// The 0 deg reference.
    pub reference: bool,
    /// All rotary angles (latched), deg.
    pub angles: BTreeMap<String, f64>,
    /// Measured sphere centre (mean of both approaches with Q432), mm.
    pub centre: [f64; 3],
    /// Fitted sphere radius, mm.
    pub radius: f64,
    /// `d_k` with the active kinematics and with the optimised ones, mm.
    pub deviation_before: [f64; 3],
    pub deviation_after: [f64; 3],
    pub measurements: Vec<SphereRecord>,
}

/// One measured axis in the result.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AxisReport {
    pub axis: String,
    pub start: f64,
    pub end: f64,
    pub points: u32,
    pub hirth: f64,
    /// The configured pivot of the axis (nominal chain), mm.
    pub pivot: [f64; 3],
    /// Radius of the circle the measured centre describes about the axis, mm.
    pub circle_radius: f64,
    /// Mean backlash, deg (None: not measured or not computable, see `notes`).
    pub backlash: Option<f64>,
    pub dispersion_before: f64,
    pub max_before: f64,
    pub dispersion_after: f64,
    pub max_after: f64,
    /// Angular positioning error (tangential deviation over the circle radius) after
    /// optimisation: mean and standard deviation about 0, deg.
    pub positioning_error_mean: f64,
    pub positioning_error_std: f64,
    /// The axis's errors by ISO name (location errors and zero error).
    pub errors_before: BTreeMap<String, f64>,
    pub errors_after: BTreeMap<String, f64>,
    pub positions: Vec<PositionReport>,
}

/// The extra result of a 451 cycle (`"kinematics"` in `--json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct KinematicsReport {
    pub mode: u8,
    pub machine: String,
    pub kinematics_file: PathBuf,
    pub estimator: String,
    pub probe: String,
    /// The corrected errors were written to the kinematics file.
    pub written: bool,
    /// Incidence angles of the machine's rotary axes, deg.
    pub incidence: BTreeMap<String, f64>,
    /// Active preset (machine X/Y/Z) before and after the cycle, and the shift.
    pub preset_before: [f64; 3],
    pub preset_after: [f64; 3],
    pub preset_shift: [f64; 3],
    /// Q147..Q149.
    pub offset_error: [f64; 3],
    /// All errors of the machine's rotary axes, by ISO name.
    pub errors_before: BTreeMap<String, f64>,
    pub errors_after: BTreeMap<String, f64>,
    pub axes: Vec<AxisReport>,
    pub notes: Vec<String>,
}

impl KinematicsReport {
    /// A few lines for the text result: per axis the dispersion and the errors before
    /// and after optimisation, and what happened to the kinematics file.
    pub fn summary(&self) -> String {
        let mut s = String::new();
        for a in &self.axes {
            s.push_str(&format!(
                "  axis {}: dispersion {:.6} -> {:.6} mm, max deviation {:.6} -> {:.6} mm{}\n",
                a.axis,
                a.dispersion_before,
                a.dispersion_after,
                a.max_before,
                a.max_after,
                a.backlash
                    .map_or_else(String::new, |b| format!(", backlash {b:+.5} deg"))
            ));
            for (name, before) in &a.errors_before {
                let after = a.errors_after.get(name).copied().unwrap_or(0.0);
                s.push_str(&format!(
                    "    {name} {before:+.6} -> {after:+.6}{}\n",
                    if after != *before { " *" } else { "" }
                ));
            }
        }
        s.push_str(&format!(
            "  kinematics {}: {}\n",
            self.kinematics_file.display(),
            if self.written {
                "corrected errors written"
            } else {
                "not changed"
            }
        ));
        s
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct KinematicsOutcome {
    pub q: BTreeMap<String, f64>,
    pub qs: BTreeMap<String, String>,
    pub report: KinematicsReport,
    /// The program stops (the correction was not confirmed).
    pub stop: Option<String>,
    pub protocol: Option<PathBuf>,
}

/// What the cycle needs besides the machine.
pub struct Context<'a> {
    pub cfg: &'a MachineConfig,
    pub kinematics: PathBuf,
    pub estimator: &'a mut dyn Estimator,
    pub confirm: &'a mut dyn FnMut(&str) -> bool,
    pub progress: &'a mut dyn FnMut(ProgressEvent),
    pub out_dir: &'a Path,
    pub program: Option<&'a Path>,
}

fn axis_map(axes: &[Axis], a: &Angles) -> BTreeMap<String, f64> {
    axes.iter()
        .map(|x| (x.name().to_string(), a[rotary_slot(*x).expect("rotary")]))
        .collect()
}

fn arr(v: &Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// Per position of an axis: whether it is the reference, and its sphere(s).
type PositionSpheres = Vec<(bool, Vec<Sphere>)>;

/// A sphere measured at one position (last round).
#[derive(Clone, Debug)]
struct Sphere {
    angles: Angles,
    centre: Vector3<f64>,
    radius: f64,
    record: SphereRecord,
}

struct Measure<'a, 'c, M: Machine> {
    machine: &'a mut M,
    ctx: &'a mut Context<'c>,
    plan: &'a KinematicsPlan,
    probe: &'a ProbeEntry,
    tool: ProbeAxis,
    block: u32,
    model: KinematicModel,
    run_base: u64,
    runs: u64,
    /// Commanded rotary angles now.
    now: Angles,
    /// The sphere centre in table coordinates (from the locate measurement).
    table_point: Vector3<f64>,
    /// Active preset, machine X/Y/Z.
    preset: Vector3<f64>,
    notes: Vec<String>,
}

impl<M: Machine> Measure<'_, '_, M> {
    fn note(&mut self, text: String) {
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
        self.machine
            .move_to(&target, feed)
            .map_err(|e| CycleError::machine(step, &e))
    }

    fn move_xyz(&mut self, step: &str, p: Vector3<f64>) -> Result<(), CycleError> {
        self.mv(
            step,
            AxisPositions::linear(arr(&p)),
            self.plan.positioning_feed,
        )
    }

    fn probe(&mut self, step: &str, dir: Vector3<f64>, max: f64) -> Result<Contact, CycleError> {
        let direction = arr(&dir.normalize());
        (self.ctx.progress)(ProgressEvent::Probe {
            block: self.block,
            direction,
            max_distance: max,
        });
        let c = self
            .machine
            .probe(&ProbeMove {
                direction,
                feed: self.probe.f,
                max_distance: max,
            })
            .map_err(|e| CycleError::machine(step, &e))?;
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

    /// Measures the sphere expected at `c` with the axes at `a` (the probe stands at
    /// the pole start or anywhere above the sphere on the tool axis side).
    fn sphere(
        &mut self,
        a: &Angles,
        mut c: Vector3<f64>,
        what: &str,
    ) -> Result<Sphere, CycleError> {
        let p = &self.plan.params;
        let (reach, dist) = (self.reach(), self.clearance() + self.probe.dist);
        let [n, u, v] = self.frame(a);
        let mut run_ids = Vec::new();
        for round in 0..2 {
            let run = self.next_run();
            run_ids.push(run);
            let mut contacts = Vec::with_capacity(1 + p.points as usize);
            let top = c + n * reach;
            self.move_xyz(&format!("{what}: moving over the pole"), top)?;
            contacts.push(self.probe(&format!("{what}: probing the pole"), -n, dist)?);
            self.move_xyz(&format!("{what}: retracting from the pole"), top)?;
            for i in 0..p.points {
                let phi =
                    (p.reference_angle + 360.0 * f64::from(i) / f64::from(p.points)).to_radians();
                let w = u * phi.cos() + v * phi.sin();
                let step = format!("{what}: point {} of {}", i + 1, p.points);
                self.move_xyz(&step, top + w * reach)?;
                self.move_xyz(&step, c + w * reach)?;
                contacts.push(self.probe(&step, -w, dist)?);
                self.move_xyz(&step, c + w * reach)?;
                self.move_xyz(&step, top + w * reach)?;
            }
            self.move_xyz(&format!("{what}: back over the pole"), top)?;
            let fit = self.ctx.estimator.fit_sphere(run, &contacts).map_err(|e| {
                CycleError::Geometry(format!("{what}: sphere fit (run {run}): {e}"))
            })?;
            let radius = fit.radius - self.probe.radius;
            let shift = (fit.centre - c).norm();
            if round == 0 && shift > RE_PROBE_TOLERANCE {
                self.note(format!(
                    "{what}: the sphere is {shift:.4} mm from where it was expected; probing it again around the fitted centre"
                ));
                c = fit.centre;
                continue;
            }
            let dev = radius - p.sphere_radius;
            if dev.abs() > self.ctx.cfg.cycles.max_dev_cal_ball {
                return Err(CycleError::Geometry(format!(
                    "{what}: the fitted sphere radius {radius:.4} mm differs from Q407 = {:.4} mm by {dev:+.4} mm, more than maxDevCalBall = {} mm; wrong sphere, or a probe that is not calibrated; nothing was changed",
                    p.sphere_radius, self.ctx.cfg.cycles.max_dev_cal_ball
                )));
            }
            let n_c = contacts.len() as f64;
            let mut angles = [0.0; 3];
            for k in contacts.iter() {
                let l = angles_of(&k.positions);
                for s in 0..3 {
                    angles[s] += l[s] / n_c;
                }
            }
            for &x in &Axis::ROTARY {
                if !self.plan.present.contains(&x) {
                    angles[rotary_slot(x).expect("rotary")] = 0.0;
                }
            }
            return Ok(Sphere {
                angles,
                centre: fit.centre,
                radius,
                record: SphereRecord {
                    angles: axis_map(&self.plan.present, &angles),
                    centre: arr(&fit.centre),
                    radius,
                    rms: fit.rms,
                    run_ids,
                    approach: None,
                },
            });
        }
        unreachable!("the second round returns")
    }

    /// Turns the rotary axes to `to` following the sphere at the pole, in steps.
    fn track(&mut self, to: Angles) -> Result<(), CycleError> {
        let from = self.now;
        let turn = (0..3).map(|s| (to[s] - from[s]).abs()).fold(0.0, f64::max);
        let steps = ((turn / TRACK_STEP_DEG).ceil() as usize).max(1);
        for i in 1..=steps {
            let f = i as f64 / steps as f64;
            let mut a = from;
            for s in 0..3 {
                a[s] = from[s] + (to[s] - from[s]) * f;
            }
            if i == steps {
                a = to;
            }
            let target = self
                .rotary(&a)
                .merged(&AxisPositions::linear(arr(&self.predicted_pole(&a))));
            self.mv(
                "turning the rotary axes with the probe over the sphere",
                target,
                self.plan.positioning_feed,
            )?;
            self.now = a;
        }
        Ok(())
    }

    /// Goes to the pole start at `to`, approaching `to` from `via` (backlash).
    fn go_to(&mut self, to: Angles, via: Option<Angles>) -> Result<(), CycleError> {
        let moves = (0..3).any(|s| (to[s] - self.now[s]).abs() > 1e-9) || via.is_some();
        let h = self.plan.params.retract_height;
        if !moves {
            let pole = self.predicted_pole(&to);
            return self.move_xyz("moving over the sphere", pole);
        }
        if h > 0.0 {
            let t = self.tool.tool_index();
            let height = self.preset[t] + h;
            let [main, minor, _] = self.tool.indices();
            let up = AxisPositions::new().with(Axis::LINEAR[t], height);
            self.mv("retracting to Q408", up, self.plan.positioning_feed)?;
            let over = AxisPositions::new()
                .with(Axis::LINEAR[main], self.preset[main])
                .with(Axis::LINEAR[minor], self.preset[minor]);
            self.mv(
                "moving over the preset at Q408",
                over,
                self.plan.positioning_feed,
            )?;
            for a in via.iter().chain(std::iter::once(&to)) {
                self.mv(
                    "turning the rotary axes (Q253)",
                    self.rotary(a),
                    self.plan.rotary_feed,
                )?;
                self.now = *a;
            }
            let pole = self.predicted_pole(&to);
            if pole[t] > height {
                return Err(CycleError::Plan(format!(
                    "Q408: the retraction height {height:.3} ({} above the preset) is below the probe's start point over the sphere ({:.3}) at {}; give a higher Q408",
                    h,
                    pole[t],
                    self.rotary(&to)
                )));
            }
            let mut above = pole;
            above[t] = height;
            self.move_xyz("moving over the sphere at Q408", above)?;
            self.move_xyz("approaching the sphere", pole)
        } else {
            if let Some(v) = via {
                self.track(v)?;
            }
            self.track(to)
        }
    }
}

/// Radius of the circle the measured centre describes about `axis` at `a` (mm), and
/// the unit tangent (direction of increasing angle) of that circle.
fn circle(model: &KinematicModel, axis: Axis, a: &Angles, p: &Vector3<f64>) -> (f64, Vector3<f64>) {
    let s = rotary_slot(axis).expect("rotary");
    let h = 1e-3;
    let (mut ap, mut am) = (*a, *a);
    ap[s] += h;
    am[s] -= h;
    let v = (model.predict(&ap, p) - model.predict(&am, p)) / (2.0 * h); // mm per deg
    let r = v.norm().to_degrees();
    let t = if v.norm() > 0.0 { v / v.norm() } else { v };
    (r, t)
}

pub fn run<M: Machine>(
    call: &CycleCall,
    plan: &KinematicsPlan,
    machine: &mut M,
    ctx: &mut Context,
) -> Result<KinematicsOutcome, CycleError> {
    let cfg = ctx.cfg;
    let active = ActiveKinematics::load(&ctx.kinematics, cfg)
        .map_err(|e| CycleError::Plan(format!("active kinematics: {e}")))?;
    let active_set = ErrorSet::from_map(&active.errors);
    let model = KinematicModel::new(&plan.chain, &active_set);
    let p = &plan.params;
    let start = machine
        .positions()
        .map_err(|e| CycleError::machine("reading the axis positions", &e))?;
    let start_angles = angles_of(&start);
    let mut m = Measure {
        machine,
        ctx,
        plan,
        probe: &call.tool.probe,
        tool: call.tool.axis,
        block: call.block,
        model,
        run_base: hal::clock::monotonic_ns(),
        runs: 0,
        now: start_angles,
        table_point: Vector3::zeros(),
        preset: Vector3::zeros(),
        notes: Vec::new(),
    };

    // 1. Locate the sphere below the probe.
    let n0 = m.frame(&start_angles)[0];
    let dist = m.clearance() + m.probe.dist;
    let first = m
        .probe("locating the sphere: probing along the tool axis from the start position", -n0, dist)
        .map_err(|e| match e {
            CycleError::Machine { step, kind, message } if kind == hal::ErrorKind::NotTriggered => {
                CycleError::Machine {
                    step,
                    kind,
                    message: format!(
                        "{message}; before cycle 451 position the probe over the sphere centre, about Q320 + SET_UP = {:.3} mm above the sphere",
                        m.clearance()
                    ),
                }
            }
            e => e,
        })?;
    let c0 = Vector3::from(first.positions.xyz()) - n0 * (p.sphere_radius + m.probe.radius);
    let located = m.sphere(&start_angles, c0, "locating the sphere")?;
    m.table_point = m.model.table_point(&located.angles, &located.centre);
    let located_ball = m.model.ball_in_machine(&located.angles, &located.centre);
    let preset_before = Vector3::zeros();
    if p.preset == 1 || p.preset == 3 {
        m.preset = located_ball;
        m.note(format!(
            "Q431={}: preset set to the sphere centre X{:+.4} Y{:+.4} Z{:+.4}",
            p.preset, located_ball.x, located_ball.y, located_ball.z
        ));
    }
    let preset_measuring = m.preset;

    // 2. The axes.
    let mut measured: Vec<(usize, PositionSpheres)> = Vec::new();
    for (gi, ap) in plan.axes.iter().enumerate() {
        let b = if plan.backlash_measured(ap) {
            p.backlash
        } else {
            0.0
        };
        if p.backlash != 0.0 && ap.hirth > 0.0 {
            m.notes.push(format!(
                "{}: no backlash measurement on a Hirth axis",
                ap.axis
            ));
        }
        let mut positions = Vec::new();
        for (k, &angle) in std::iter::once(&0.0).chain(&ap.positions).enumerate() {
            let target = plan.angles(ap.axis, angle);
            let what = if k == 0 {
                format!("{} reference at 0 deg", ap.axis)
            } else {
                format!("{} position {k} ({}{angle:+.4})", ap.axis, ap.axis)
            };
            m.note(format!("measuring {what}"));
            let mut spheres = Vec::new();
            let sides: Vec<Option<f64>> = if b != 0.0 {
                vec![Some(b), Some(-b)]
            } else {
                vec![None]
            };
            for (si, side) in sides.iter().enumerate() {
                let via = side.map(|off| plan.angles(ap.axis, angle + off));
                if si == 0 {
                    m.go_to(target, via)?;
                } else {
                    if let Some(v) = via {
                        m.track(v)?;
                    }
                    m.track(target)?;
                }
                let expected = m.model.predict(&target, &m.table_point);
                let label = match side {
                    Some(off) => format!(
                        "{what}, approached from {}",
                        if *off > 0.0 { "above" } else { "below" }
                    ),
                    None => what.clone(),
                };
                let mut s = m.sphere(&target, expected, &label)?;
                s.record.approach =
                    side.map(|off| if off > 0.0 { "above" } else { "below" }.into());
                spheres.push(s);
            }
            positions.push((k == 0, spheres));
        }
        measured.push((gi, positions));
    }
    // Back to where the cycle started, over the sphere.
    m.go_to(start_angles, None)?;

    // 3. Identification.
    let mean_of = |spheres: &[Sphere]| -> (Angles, Vector3<f64>, f64) {
        let n = spheres.len() as f64;
        let mut a = [0.0; 3];
        let mut c = Vector3::zeros();
        let mut r = 0.0;
        for s in spheres {
            for (x, y) in a.iter_mut().zip(s.angles) {
                *x += y / n;
            }
            c += s.centre / n;
            r += s.radius / n;
        }
        (a, c, r)
    };
    let input = IdentificationInput {
        chain: plan.chain.clone(),
        active: active_set,
        mode: p.mode,
        axes: measured
            .iter()
            .map(|(gi, positions)| AxisMeasurement {
                axis: plan.axes[*gi].axis,
                positions: positions
                    .iter()
                    .map(|(_, s)| {
                        let (angles, c, _) = mean_of(s);
                        MeasuredPosition {
                            angles,
                            centre: arr(&c),
                        }
                    })
                    .collect(),
            })
            .collect(),
    };
    let result: IdentificationResult = m
        .ctx
        .estimator
        .identify(&input)
        .map_err(|e| CycleError::Geometry(e.to_string()))?;
    let estimator_name = m.ctx.estimator.name();

    // 4. Results.
    let present = plan.present.clone();
    let errors_by_name = |e: &ErrorSet, axes: &[Axis]| e.to_map(axes);
    let mut axes_report = Vec::new();
    let mut q = BTreeMap::new();
    let mut qs = BTreeMap::new();
    let model_after = KinematicModel::new(&plan.chain, &result.after);
    for (gi, positions) in &measured {
        let ap = &plan.axes[*gi];
        let st = result.axis(ap.axis).ok_or_else(|| {
            CycleError::Geometry(format!(
                "the estimator returned no statistics for {}",
                ap.axis
            ))
        })?;
        let reference = &input
            .axes
            .iter()
            .find(|g| g.axis == ap.axis)
            .expect("measured")
            .positions[0];
        let p_ref = m
            .model
            .table_point(&reference.angles, &Vector3::from(reference.centre));
        let (circle_radius, _) = circle(&m.model, ap.axis, &reference.angles, &p_ref);
        // Backlash.
        let mut backlash = None;
        if plan.backlash_measured(ap) {
            if circle_radius < MIN_BACKLASH_RADIUS {
                m.notes.push(format!(
                    "{}: measuring circle radius {circle_radius:.3} mm < {MIN_BACKLASH_RADIUS} mm: no backlash computed",
                    ap.axis
                ));
            } else {
                let mut sum = 0.0;
                for (_, spheres) in positions {
                    let (a, _, _) = mean_of(spheres);
                    let (above, below) = if p.backlash > 0.0 {
                        (&spheres[0], &spheres[1])
                    } else {
                        (&spheres[1], &spheres[0])
                    };
                    let (r, t) = circle(&m.model, ap.axis, &a, &p_ref);
                    sum += (above.centre - below.centre).dot(&t) / r.to_radians();
                }
                backlash = Some(sum / positions.len() as f64);
            }
        }
        // Angular positioning error after optimisation, per position.
        let p_after = model_after.table_point(&reference.angles, &Vector3::from(reference.centre));
        let errs: Vec<f64> = positions
            .iter()
            .zip(&st.deviations_after)
            .map(|((_, s), d)| {
                let (a, _, _) = mean_of(s);
                let (r, t) = circle(&model_after, ap.axis, &a, &p_after);
                if r > 0.0 {
                    (Vector3::from(*d).dot(&t) / r).to_degrees()
                } else {
                    0.0
                }
            })
            .collect();
        let n = errs.len().max(1) as f64;
        let mean = errs.iter().sum::<f64>() / n;
        let std = (errs.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
        let positions_report = positions
            .iter()
            .enumerate()
            .map(|(k, (is_ref, spheres))| {
                let (a, c, r) = mean_of(spheres);
                PositionReport {
                    reference: *is_ref,
                    angles: axis_map(&present, &a),
                    centre: arr(&c),
                    radius: r,
                    deviation_before: st.deviations_before[k],
                    deviation_after: st.deviations_after[k],
                    measurements: spheres.iter().map(|s| s.record.clone()).collect(),
                }
            })
            .collect();
        axes_report.push(AxisReport {
            axis: ap.axis.name().to_string(),
            start: ap.range.start,
            end: ap.range.end,
            points: ap.range.points,
            hirth: ap.hirth,
            pivot: plan
                .chain
                .table
                .iter()
                .chain(&plan.chain.head)
                .find(|(a, _)| *a == ap.axis)
                .map_or([0.0; 3], |(_, p)| *p),
            circle_radius,
            backlash,
            dispersion_before: st.dispersion_before,
            max_before: st.max_before,
            dispersion_after: st.dispersion_after,
            max_after: st.max_after,
            positioning_error_mean: mean,
            positioning_error_std: std,
            errors_before: errors_by_name(&result.before, &[ap.axis]),
            errors_after: errors_by_name(&result.after, &[ap.axis]),
            positions: positions_report,
        });
    }
    for (i, axis) in Axis::ROTARY.into_iter().enumerate() {
        let st = axes_report.iter().find(|a| a.axis == axis.name());
        q.insert(
            format!("Q{}", 141 + i),
            st.map_or(-1.0, |a| a.dispersion_before),
        );
        q.insert(
            format!("Q{}", 144 + i),
            st.map_or(-1.0, |a| a.dispersion_after),
        );
        let values = if st.is_some() {
            result.after.location(axis)
        } else {
            [-1.0; 4]
        };
        qs.insert(format!("QS{}", 144 + i), qs_string(values));
    }
    // Q147..Q149: the sphere centre at the (first) reference relative to the active preset.
    let first_ref = &input.axes[0].positions[0];
    let ref_ball = m
        .model
        .ball_in_machine(&first_ref.angles, &Vector3::from(first_ref.centre));
    let offset = ref_ball - preset_measuring;
    for (i, v) in offset.iter().enumerate() {
        q.insert(format!("Q{}", 147 + i), *v);
    }
    // Q431 = 2/3: the preset goes to the sphere centre where the cycle ends (it returns
    // to the rotary angles it started at, where the sphere was located).
    let mut preset_after = m.preset;
    if p.preset == 2 || p.preset == 3 {
        preset_after = located_ball;
        m.note(format!(
            "Q431={}: preset set to the sphere centre X{:+.4} Y{:+.4} Z{:+.4}",
            p.preset, located_ball.x, located_ball.y, located_ball.z
        ));
    }
    for t in &result.transfers {
        m.notes.push(format!(
            "machine datum: {} = {:+.6} deg moved into {}",
            ErrorSet::name(t.from),
            t.value,
            ErrorSet::name(t.to)
        ));
    }

    // 5. Decide about the write-back.
    let changes: Vec<(usize, f64, f64)> = (0..result.before.0.len())
        .filter(|&i| result.after.0[i] != result.before.0[i])
        .map(|i| (i, result.before.0[i], result.after.0[i]))
        .collect();
    let mut stop = None;
    let mut accept = p.mode.writes() && !changes.is_empty();
    if accept {
        let largest = changes
            .iter()
            .map(|(_, b, a)| (a - b).abs())
            .fold(0.0, f64::max);
        let limit = cfg.cycles.max_modification;
        if largest > limit {
            let mut text = format!(
                "Cycle 451 (block {}): the correction exceeds maxModification = {limit} (mm / deg):\n",
                call.block
            );
            for (i, b, a) in &changes {
                let (_, part) = ErrorSet::describe(*i);
                text.push_str(&format!(
                    "  {:<5} {b:+.6} -> {a:+.6} {} ({:+.6})\n",
                    ErrorSet::name(*i),
                    part.unit(),
                    a - b
                ));
            }
            text.push_str(&format!(
                "Accept and write it to {}?",
                ctx_path(&m.ctx.kinematics)
            ));
            if !(m.ctx.confirm)(&text) {
                accept = false;
                stop = Some(format!(
                    "the kinematics correction (largest change {largest:.6} > maxModification {limit}) was not confirmed; {} was not changed",
                    ctx_path(&m.ctx.kinematics)
                ));
            }
        }
    }
    if !p.mode.writes() {
        m.notes
            .push("mode 0 (check): the kinematics were not changed".into());
    }

    let notes = std::mem::take(&mut m.notes);
    let mut report = KinematicsReport {
        mode: p.mode.q406(),
        machine: cfg.name.clone(),
        kinematics_file: m.ctx.kinematics.clone(),
        estimator: estimator_name,
        probe: call.tool.probe.name.clone(),
        written: false,
        incidence: axis_map(&present, &plan.incidence),
        preset_before: arr(&preset_before),
        preset_after: arr(&preset_after),
        preset_shift: arr(&(preset_after - preset_before)),
        offset_error: arr(&offset),
        errors_before: errors_by_name(&result.before, &present),
        errors_after: errors_by_name(&result.after, &present),
        axes: axes_report,
        notes,
    };

    // 6. Protocol, then the kinematics.
    let written_text = if accept {
        Some(format!("written to {}", ctx_path(&m.ctx.kinematics)))
    } else {
        None
    };
    let protocol = crate::protocol451::write_kinematics_protocol(
        m.ctx.out_dir,
        &report,
        m.ctx.program,
        &crate::protocol::timestamp_utc(),
        written_text.as_deref(),
    )
    .map_err(|e| CycleError::Protocol {
        path: m
            .ctx
            .out_dir
            .join(crate::protocol451::KINEMATICS_PROTOCOL)
            .display()
            .to_string(),
        message: e.to_string(),
    })?;
    if accept {
        let mut new = active.clone();
        for (i, _, a) in &changes {
            new.errors.insert(ErrorSet::name(*i).to_string(), *a);
        }
        new.write()
            .map_err(|e| CycleError::Plan(format!("writing the corrected kinematics: {e}")))?;
        report.written = true;
        m.note(format!(
            "corrected kinematics written to {} (previous version kept as .prev)",
            ctx_path(&m.ctx.kinematics)
        ));
    }
    Ok(KinematicsOutcome {
        q,
        qs,
        report,
        stop,
        protocol: Some(protocol),
    })
}

fn ctx_path(p: &Path) -> String {
    p.display().to_string()
}
