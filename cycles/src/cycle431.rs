//! Cycle 431 MEASURE PLANE: three points probed along the probe axis, the plane's
//! spatial angles (for PLANE SPATIAL) and projection angles.

use crate::confirmation::{ConfirmKind, Confirmation};
use crate::cycle::{CycleContext, MeasuringCycle};
use crate::cycle_block::{CycleBlock, Param, ParamReader};
use crate::diagnostic::Diagnostic;
use crate::error::CycleError;
use crate::length_unit::LengthUnit;
use crate::measuring_log::plane::{plane_log_text, write_plane_log, PlaneRecord, PLANE_LOG};
use crate::measuring_log::{timestamp_utc, MeasuringLogError};
use crate::plane::{plane_angles, COLLINEAR_SIN};
use crate::planned_move::PlannedMove;
use crate::positioning::{xyz, Leg, Positioner};
use crate::results::CycleOutput;
use crate::uncertainty::{fit_uncertainty, Fit, UncertaintyError};
use hal::{Axis, AxisPositions, Machine, ProbeMove};
use nalgebra::{DMatrix, Vector3};
use std::collections::BTreeMap;

const POINTS: [[&str; 3]; 3] = [
    ["Q263", "Q264", "Q294"],
    ["Q265", "Q266", "Q295"],
    ["Q296", "Q297", "Q298"],
];

/// Validated parameters; points as (main, minor, tool axis), mm.
#[derive(Clone, Debug, PartialEq)]
pub struct PlaneParams {
    pub points: [[f64; 3]; 3],
    /// Q320.
    pub clearance: f64,
    /// Q260 (tool-axis coordinate).
    pub safe_height: f64,
    /// Q281: 0 none, 1 write TCHPR431.TXT, 2 show and wait for confirmation.
    pub protocol: u8,
}

impl PlaneParams {
    /// Refuses nominal points on a line: such a program can never give a plane.
    pub fn from_params(
        params: &BTreeMap<String, Param>,
        _unit: LengthUnit,
    ) -> Result<Self, Vec<Diagnostic>> {
        let mut r = ParamReader::new(params);
        let points = POINTS.map(|names| names.map(|n| r.number(n)));
        let clearance = r.number("Q320");
        let safe_height = r.number("Q260");
        let protocol = r.number("Q281") as u8;
        let v = points.map(Vector3::from);
        let (a, b) = (v[1] - v[0], v[2] - v[0]);
        if a.cross(&b).norm() <= COLLINEAR_SIN * a.norm() * b.norm() {
            r.problem(
                r.line("Q263"),
                "Q263..Q298: the three nominal points lie on a line (or coincide); they do not define a plane",
            );
        }
        r.finish(PlaneParams {
            points,
            clearance,
            safe_height,
            protocol,
        })
    }
}

impl MeasuringCycle for PlaneParams {
    fn run<M: Machine>(
        &self,
        call: &CycleBlock,
        machine: &mut M,
        ctx: &mut CycleContext<'_>,
    ) -> Result<CycleOutput, CycleError> {
        let mut record = measure(call, self, machine, ctx)?;
        record.u = uncertainties(&record, call.tool.probe.repeatability())?;
        let q = results(&record);
        let mut out = CycleOutput::new(q, None);
        out.u = record.u.clone();
        // Q281: 1 writes TCHPR431.TXT; 2 shows it and goes on only when confirmed.
        match self.protocol {
            1 => out
                .logs
                .push(write_plane_log(ctx.out_dir, &record, ctx.program).map_err(log_error(ctx))?),
            2 => {
                let text = plane_log_text(&record, ctx.program, &timestamp_utc());
                let question = Confirmation::new(ConfirmKind::PlaneProtocol, text);
                if !(ctx.confirm)(&question) {
                    out.stop = Some(
                        "the cycle 431 protocol was not confirmed (Q281=2); program stopped"
                            .to_string(),
                    );
                }
            }
            _ => {}
        }
        Ok(out)
    }
}

fn log_error(ctx: &CycleContext<'_>) -> impl Fn(MeasuringLogError) -> CycleError {
    let path = ctx.out_dir.join(PLANE_LOG).display().to_string();
    move |e| CycleError::MeasuringLog {
        path: path.clone(),
        message: e.source.to_string(),
    }
}

/// Q158, Q159 (projection angles), Q170..Q172 (spatial angles), Q173..Q175 (measured
/// tool-axis coordinates).
fn results(r: &PlaneRecord) -> BTreeMap<String, f64> {
    let angles = &r.angles;
    let mut q = BTreeMap::new();
    q.insert("Q158".to_string(), angles.proj_a);
    q.insert("Q159".to_string(), angles.proj_b);
    q.insert("Q170".to_string(), angles.spa);
    q.insert("Q171".to_string(), angles.spb);
    q.insert("Q172".to_string(), angles.spc);
    for (i, name) in ["Q173", "Q174", "Q175"].into_iter().enumerate() {
        q.insert(name.to_string(), r.measured[i][2]);
    }
    q
}

/// The standard uncertainty (k = 1) of Q158, Q159, Q170..Q175. The observations are
/// the three probe-axis coordinates, one contact each: three points determine the
/// plane exactly and leave no degree of freedom, so `σ` is the probe's repeatability
/// ([`crate::uncertainty`]); the angles follow by propagation through the plane's
/// formulas (central differences).
pub fn uncertainties(
    r: &PlaneRecord,
    repeatability: f64,
) -> Result<BTreeMap<String, f64>, CycleError> {
    let what = format!("cycle 431 (block {})", r.block);
    let fail = |e: UncertaintyError| CycleError::Geometry(e.to_string());
    // Parameters: the three coordinates; residual z_i - θ_i, exactly 0.
    let j = DMatrix::<f64>::from_diagonal_element(3, 3, -1.0);
    let u = fit_uncertainty(&Fit::new(&what, &j, &[0.0; 3], repeatability)).map_err(fail)?;
    let angles = |z: [f64; 3]| -> Result<[f64; 5], CycleError> {
        let mut m = r.measured;
        for (p, z) in m.iter_mut().zip(z) {
            p[2] = z;
        }
        let a = plane_angles(m[0].into(), m[1].into(), m[2].into())
            .map_err(|e| CycleError::Geometry(format!("{what}: {e}")))?;
        Ok([a.proj_a, a.proj_b, a.spa, a.spb, a.spc])
    };
    let z = r.measured.map(|p| p[2]);
    let mut g = DMatrix::<f64>::zeros(5, 3);
    for i in 0..3 {
        let (mut plus, mut minus) = (z, z);
        plus[i] += ANGLE_STEP;
        minus[i] -= ANGLE_STEP;
        let (ap, am) = (angles(plus)?, angles(minus)?);
        for k in 0..5 {
            // Across ±180° an angle wraps: the difference is the short way round.
            let d = (ap[k] - am[k] + 540.0).rem_euclid(360.0) - 180.0;
            g[(k, i)] = d / (2.0 * ANGLE_STEP);
        }
    }
    let ua = u.propagate(&what, &g).map_err(fail)?.u();
    let mut out = BTreeMap::new();
    for (name, v) in ["Q158", "Q159", "Q170", "Q171", "Q172"].into_iter().zip(ua) {
        out.insert(name.to_string(), v);
    }
    for (name, v) in ["Q173", "Q174", "Q175"].into_iter().zip(u.u()) {
        out.insert(name.to_string(), v);
    }
    Ok(out)
}

/// Central-difference step of the plane's angles by a point's coordinate, mm.
const ANGLE_STEP: f64 = 1e-6;

/// Where and how the probe comes to each point, machine coordinates.
struct Approach {
    /// Unit vector along the tool axis, away from the material.
    up: Vector3<f64>,
    /// From a start point to its nominal point: R + SET_UP + Q320, mm.
    distance: f64,
    /// Q260 in machine coordinates (tool-axis coordinate).
    safe_height: f64,
    starts: [Vector3<f64>; 3],
}

impl PlaneParams {
    /// The start points over the three nominal points, with the active datum at
    /// `origin` (machine XYZ); every one must lie below the safe height.
    fn approach(&self, call: &CycleBlock, origin: Vector3<f64>) -> Result<Approach, CycleError> {
        let probe = &call.tool.probe;
        let cal = probe.calibration();
        let axis = call.tool.axis;
        let t = axis.tool_index();
        let distance = cal.r + probe.set_up + self.clearance;
        // The true ball centre goes over each point: the axes, less the calibrated
        // stylus offset and length.
        let shift = Vector3::from(cal.centre_shift(axis));
        // The probe comes from the positive tool-axis side (from above for Z).
        let mut up = [0.0; 3];
        up[t] = 1.0;
        let up = Vector3::from(up);
        // Program coordinates: relative to the active preset plus shift.
        let safe_height = self.safe_height + origin[t];
        let starts = self
            .points
            .map(|pt| Vector3::from(axis.to_machine(pt)) + origin + up * distance - shift);
        if let Some((i, s)) = starts.iter().enumerate().find(|(_, s)| s[t] > safe_height) {
            // The value that clears all three starts, not just this one: raised to this
            // point's start, Q260 could still be below another's.
            let highest = starts
                .iter()
                .map(|s| s[t])
                .fold(f64::NEG_INFINITY, f64::max);
            let lowest = crate::cycle451::plan::round_up(highest - origin[t]);
            return Err(CycleError::Plan(format!(
                "Q260={} is below the start of point {} ({:.4} = nominal + R + SET_UP + Q320); the lowest Q260 that clears is {lowest:.4}; nothing moved",
                self.safe_height,
                i + 1,
                s[t] - origin[t]
            )));
        }
        Ok(Approach {
            up,
            distance,
            safe_height,
            starts,
        })
    }

    /// Every move the cycle commands, in order, with the active datum at `origin`
    /// (machine XYZ): what `check` and `run` hold against the machine before the
    /// program's first move.
    pub fn planned_moves(
        &self,
        call: &CycleBlock,
        origin: [f64; 3],
    ) -> Result<Vec<PlannedMove>, CycleError> {
        let a = self.approach(call, Vector3::from(origin))?;
        let probe = &call.tool.probe;
        let axis = call.tool.axis;
        let [main, minor, _] = axis.indices();
        let position = |step: String, target: AxisPositions| PlannedMove::Position {
            step,
            target,
            feed: probe.fmax,
        };
        let safe = || {
            position(
                "moving to the safe height".into(),
                AxisPositions::new().with(axis.axis(), a.safe_height),
            )
        };
        let mut moves = vec![safe()];
        for (i, s) in a.starts.iter().enumerate() {
            let over = AxisPositions::new()
                .with(Axis::LINEAR[main], s[main])
                .with(Axis::LINEAR[minor], s[minor]);
            moves.push(position(format!("positioning over point {}", i + 1), over));
            moves.push(position(
                format!("approaching point {}", i + 1),
                AxisPositions::linear((*s).into()),
            ));
            moves.push(PlannedMove::Probe {
                step: format!("probing point {}", i + 1),
                from: (*s).into(),
                mv: ProbeMove {
                    direction: (-a.up).into(),
                    feed: probe.f,
                    max_distance: a.distance + probe.dist,
                },
                // The ball touches R before the nominal point: after SET_UP + Q320.
                nominal: a.distance - probe.calibration().r,
            });
            moves.push(safe());
        }
        Ok(moves)
    }
}

/// The cycle's positioning moves as the operator reads them ([`Leg`]): up to Q260,
/// and for each point across at Q260, down to its pre-position and back up.
struct Legs {
    up: Leg,
    over: Vec<Leg>,
    down: Vec<Leg>,
    back: Vec<Leg>,
}

impl PlaneParams {
    /// The legs to the pre-positions `starts` (axes, machine XYZ) with the active
    /// datum at `origin`. What each contact means: on the way up or across, material
    /// above Q260; on the way down to a pre-position, the part stands higher at that
    /// point than R + SET_UP + Q320 above the programmed point (the point, the preset
    /// or Q320 is wrong).
    fn legs(&self, call: &CycleBlock, origin: Vector3<f64>, starts: &[Vector3<f64>; 3]) -> Legs {
        let probe = &call.tool.probe;
        let cal = probe.calibration();
        let axis = call.tool.axis;
        let shift = Vector3::from(cal.centre_shift(axis));
        let q260 = self.safe_height;
        // The ball centre's pre-position in the program's coordinates.
        let at = |s: &Vector3<f64>| xyz((s + shift - origin).into());
        let up = Leg::up_to_q260(q260);
        let over = (0..3)
            .map(|i| Leg {
                step: format!("positioning over point {}", i + 1),
                route: format!(
                    "across at the clearance height Q260={q260:+.4} to over its pre-position {}",
                    at(&starts[i])
                ),
                check: "the part stands higher than Q260 on the way: check Q260 against the part's highest point between the points (the probe crosses at Q260 unmonitored) and the preset".into(),
            })
            .collect();
        let down = (0..3)
            .map(|i| Leg {
                step: format!("approaching point {}", i + 1),
                route: format!(
                    "down from the clearance height Q260={q260:+.4} to its pre-position {}, R + SET_UP + Q320 = {:.4} mm above the programmed point",
                    at(&starts[i]),
                    cal.r + probe.set_up + self.clearance
                ),
                check: format!(
                    "the part stands higher at point {} than SET_UP + Q320 = {:.4} mm above the programmed point: check point {}'s coordinates ({}) and the preset against the part, or raise Q320 (SET_UP = {:.4} mm)",
                    i + 1,
                    probe.set_up + self.clearance,
                    i + 1,
                    POINTS[i].join(", "),
                    probe.set_up
                ),
            })
            .collect();
        let back = (0..3)
            .map(|i| Leg {
                step: "moving to the safe height".into(),
                route: format!(
                    "up from point {} to the clearance height Q260={q260:+.4}",
                    i + 1
                ),
                check: format!(
                    "the part stands over point {} below Q260: check Q260 and point {}'s coordinates ({}) against the part",
                    i + 1,
                    i + 1,
                    POINTS[i].join(", ")
                ),
            })
            .collect();
        Legs {
            up,
            over,
            down,
            back,
        }
    }
}

/// Probes the three points and computes the plane's angles.
fn measure<M: Machine>(
    call: &CycleBlock,
    p: &PlaneParams,
    machine: &mut M,
    ctx: &mut CycleContext<'_>,
) -> Result<PlaneRecord, CycleError> {
    let probe = &call.tool.probe;
    let axis = call.tool.axis;
    let t = axis.tool_index();
    let origin = Vector3::from(ctx.datum.origin());
    let Approach {
        up,
        distance: approach,
        safe_height,
        starts,
    } = p.approach(call, origin)?;
    let cal = probe.calibration();
    let shift = Vector3::from(cal.centre_shift(axis));
    let radius = cal.radius_toward(axis, up.into());
    ctx.note(call.block, "basic rotation reset");
    let mut pos = Positioner {
        machine,
        axis,
        fmax: probe.fmax,
        block: call.block,
        progress: &mut *ctx.progress,
    };
    let mut measured = p.points;
    let legs = p.legs(call, origin, &starts);
    pos.safe_height(safe_height, &legs.up)?;
    for (i, start) in starts.iter().enumerate() {
        pos.over((*start).into(), &legs.over[i])?;
        pos.to((*start).into(), &legs.down[i])?;
        let contact = pos.probe(
            &format!("probing point {}", i + 1),
            (-up).into(),
            probe.f,
            approach + probe.dist,
        )?;
        // The true ball centre (latched plus the calibrated stylus shift) less the
        // effective radius along the probing direction (no 3D radius compensation: on
        // a tilted plane this is a constant offset of all three points, which leaves
        // the angles exact).
        let centre = Vector3::from(contact.positions.xyz()) + shift;
        measured[i][2] = centre[t] - radius - origin[t];
        pos.safe_height(safe_height, &legs.back[i])?;
    }
    let angles = plane_angles(measured[0].into(), measured[1].into(), measured[2].into())
        .map_err(|e| CycleError::Geometry(e.to_string()))?;
    Ok(PlaneRecord {
        block: call.block,
        line: call.line,
        probe: probe.name.clone(),
        axis,
        nominal: p.points,
        measured,
        angles,
        u: BTreeMap::new(),
    })
}
