//! Cycle 444 PROBING 3D: one point of a free-form surface, probed against its surface
//! normal, compared with the nominal point along that normal (QS400 tolerance, Q309
//! reaction, Q183 status).

use crate::cycle::{CycleContext, MeasuringCycle};
use crate::cycle_block::{CycleBlock, Param, ParamReader};
use crate::diagnostic::Diagnostic;
use crate::error::CycleError;
use crate::length_unit::LengthUnit;
use crate::measuring_log::probing3d::{write_probing3d_log, Probing3dRecord, PROBING_3D_LOG};
use crate::planned_move::PlannedMove;
use crate::positioning::{xyz, Leg, Positioner};
use crate::probe_table::calibration::Table3d;
use crate::progress::ProgressSink;
use crate::results::CycleOutput;
use crate::tolerance::{Tolerance, WorkpieceStatus};
use crate::uncertainty::{fit_uncertainty, Fit, UncertaintyError};
use hal::{Axis, AxisPositions, Machine, ProbeMove};
use nalgebra::{DMatrix, Vector3};
use std::collections::BTreeMap;

/// Validated parameters; coordinates as (main, minor, tool axis), mm.
#[derive(Clone, Debug, PartialEq)]
pub struct Probing3dParams {
    /// Q263, Q264, Q294.
    pub nominal: [f64; 3],
    /// Q581, Q582, Q583 normalised (points away from the material).
    pub normal: [f64; 3],
    /// Q320.
    pub clearance: f64,
    /// Q260 (tool-axis coordinate).
    pub safe_height: f64,
    /// QS400 as written.
    pub tolerance_text: String,
    /// QS400 parsed, in mm; `None` = no tolerance.
    pub tolerance: Option<Tolerance>,
    /// Q309: 0 never stop, 1 stop when out of tolerance, 2 stop when undersize.
    pub reaction: u8,
}

impl Probing3dParams {
    /// Checks what the table cannot: the normal is not zero, QS400 follows the grammar.
    pub fn from_params(
        params: &BTreeMap<String, Param>,
        unit: LengthUnit,
    ) -> Result<Self, Vec<Diagnostic>> {
        let mut r = ParamReader::new(params);
        let nominal = [r.number("Q263"), r.number("Q264"), r.number("Q294")];
        let written = Vector3::new(r.number("Q581"), r.number("Q582"), r.number("Q583"));
        let clearance = r.number("Q320");
        let safe_height = r.number("Q260");
        let reaction = r.number("Q309") as u8;
        if written.norm() == 0.0 {
            r.problem(
                r.line("Q581"),
                "Q581/Q582/Q583: the surface normal is the zero vector; it needs a direction",
            );
        }
        let (text, text_line) = r.text("QS400");
        let tolerance = match Tolerance::parse(&text) {
            Ok(t) => t.map(|t| match unit {
                LengthUnit::Mm => t,
                LengthUnit::Inch => t.scaled(25.4),
            }),
            Err(e) => {
                r.problem(text_line, e.to_string());
                None
            }
        };
        let n = written.normalize();
        r.finish(Probing3dParams {
            nominal,
            normal: [n.x, n.y, n.z],
            clearance,
            safe_height,
            tolerance_text: text,
            tolerance,
            reaction,
        })
    }
}

/// Q309 decision. 1: out of tolerance (rework or scrap). 2: the actual point lies below
/// the nominal along the normal (Q164 < 0), as the seed words it, whatever the
/// tolerance; never for material left.
pub fn stop_message(reaction: u8, status: WorkpieceStatus, deviation_3d: f64) -> Option<String> {
    match reaction {
        1 if matches!(status, WorkpieceStatus::Rework | WorkpieceStatus::Scrap) => Some(format!(
            "out of tolerance ({status}): Q164 = {deviation_3d:+.4} mm; Q309=1 stops the program"
        )),
        2 if deviation_3d < 0.0 => Some(format!(
            "undersize: Q164 = {deviation_3d:+.4} mm below the nominal point; Q309=2 stops the program"
        )),
        _ => None,
    }
}

impl MeasuringCycle for Probing3dParams {
    /// Probes the point, then rewrites TCHPR444.html with every point of the run so
    /// far (complete even if a later cycle fails).
    fn run<M: Machine>(
        &self,
        call: &CycleBlock,
        machine: &mut M,
        ctx: &mut CycleContext<'_>,
    ) -> Result<CycleOutput, CycleError> {
        let origin = Vector3::from(ctx.datum.origin());
        let (q, mut record) = measure(call, self, origin, machine, &mut *ctx.progress)?;
        record.u = uncertainties(&record, call.tool.probe.repeatability())?;
        let u = record.u.clone();
        let stop = stop_message(self.reaction, record.status, record.deviation_3d);
        ctx.probing3d.push(record);
        let log = write_probing3d_log(ctx.out_dir, &ctx.probing3d, ctx.program).map_err(|e| {
            CycleError::MeasuringLog {
                path: ctx.out_dir.join(PROBING_3D_LOG).display().to_string(),
                message: e.source.to_string(),
            }
        })?;
        let mut out = CycleOutput::new(q, stop);
        out.u = u;
        out.logs.push(log);
        Ok(out)
    }
}

/// The standard uncertainty (k = 1) of Q151..Q153, Q161..Q164. One contact is the one
/// observation: its trigger scatters along the probing direction, the normal, with
/// the probe's repeatability (no degree of freedom: [`crate::uncertainty`]'s floor).
/// The point moves along the normal by it, each axis by its share of the normal.
pub fn uncertainties(
    r: &Probing3dRecord,
    repeatability: f64,
) -> Result<BTreeMap<String, f64>, CycleError> {
    let what = format!("cycle 444 (block {})", r.block);
    let fail = |e: UncertaintyError| CycleError::Geometry(e.to_string());
    // The parameter: where along the normal the point lies; residual exactly 0.
    let j = DMatrix::<f64>::from_element(1, 1, -1.0);
    let u = fit_uncertainty(&Fit::new(&what, &j, &[0.0], repeatability)).map_err(fail)?;
    let n = r.normal;
    let g = DMatrix::from_row_slice(4, 1, &[n[0], n[1], n[2], 1.0]);
    let v = u.propagate(&what, &g).map_err(fail)?.u();
    let mut out = BTreeMap::new();
    for (i, axis) in ["1", "2", "3"].into_iter().enumerate() {
        out.insert(format!("Q15{axis}"), v[i]);
        out.insert(format!("Q16{axis}"), v[i]);
    }
    out.insert("Q164".into(), v[3]);
    Ok(out)
}

/// Where and how the probe comes to the point, machine coordinates.
struct Approach {
    /// The surface normal (unit, away from the material).
    n: Vector3<f64>,
    /// The pre-position (axes): the nominal point plus R + SET_UP + Q320 along the
    /// normal, less the calibrated stylus shift.
    start: Vector3<f64>,
    /// The probing path: to the nominal point and DIST beyond it, mm.
    max_distance: f64,
    /// Q260 in machine coordinates (tool-axis coordinate).
    safe_height: f64,
}

impl Probing3dParams {
    /// The pre-position and probing path with the active datum at `origin` (machine
    /// XYZ). Q260 is where the probe moves unmonitored at FMAX, so it must clear what
    /// the block says is material (refused as cycle 431 refuses it, with the lowest
    /// value that clears): the pre-position must lie below it (else the probe would
    /// come up to the pre-position through the part), and the ball at Q260 must pass
    /// R + SET_UP above the probed point itself (on a face whose normal is not the tool
    /// axis, the material at the point rises to the nominal point's height).
    fn approach(&self, call: &CycleBlock, origin: Vector3<f64>) -> Result<Approach, CycleError> {
        let probe = &call.tool.probe;
        let cal = probe.calibration();
        let axis = call.tool.axis;
        let t = axis.tool_index();
        if let Some(t) = cal.table_3d.as_ref().filter(|t| !t.covers(self.normal)) {
            // Below the table's lowest ring the effective radius is not known: L
            // absorbs the axial pre-travel's excess, so a mirrored value errs by twice
            // it times the elevation's sine.
            return Err(CycleError::Plan(format!(
                "Q581/Q582/Q583: the surface normal points {:.1}° below the working plane, and the 3D calibration of probe \"{}\" covers normals from {:.1}° up to the pole only; recalibrate with cycle 460 and Q455 (its table reaches {:.0}°), or probe this point from a direction it covers; nothing moved",
                -Table3d::elevation(self.normal),
                probe.name,
                t.lowest_elevation(),
                crate::probe_table::calibration::RING_ELEVATIONS[0]
            )));
        }
        let n = Vector3::from(axis.to_machine(self.normal));
        // Program coordinates: relative to the active preset plus shift (`origin`).
        let nominal = Vector3::from(axis.to_machine(self.nominal)) + origin;
        let approach = cal.r + probe.set_up + self.clearance;
        // The true ball centre starts there: the axes go to it minus the stylus's
        // offset and length (its row of the probe table).
        let start = nominal + n * approach - Vector3::from(cal.centre_shift(axis));
        let safe_height = self.safe_height + origin[t];
        let over_point = nominal[t] + probe.radius + probe.set_up;
        let lowest = round_up(start[t].max(over_point) - origin[t]);
        if start[t] > safe_height {
            return Err(CycleError::Plan(format!(
                "Q260={} is below the start of the point ({:.4} = nominal + (R + SET_UP + Q320) along the normal); the lowest Q260 that clears is {lowest:.4}; nothing moved",
                self.safe_height,
                start[t] - origin[t]
            )));
        }
        if over_point > safe_height {
            return Err(CycleError::Plan(format!(
                "Q260={} does not clear the probed point: the ball at the safe height must pass R + SET_UP = {:.4} above the nominal point ({:.4}), or it touches the surface there; the lowest Q260 that clears is {lowest:.4}; nothing moved",
                self.safe_height,
                probe.radius + probe.set_up,
                nominal[t] - origin[t]
            )));
        }
        Ok(Approach {
            n,
            start,
            max_distance: approach + probe.dist,
            safe_height,
        })
    }

    /// Every move the cycle commands, in order, with the active datum at `origin`
    /// (machine XYZ) and the axes at `here` (the safe height and the working plane in
    /// the order `from_above` gives): what `check` and `run` hold against the machine before the
    /// program's first move. The retraction after the contact, MB back along the
    /// normal, lies between its ends for a contact at the start and at the path's end;
    /// under an overhang (a normal below the working plane) the probe then goes back
    /// along the normal to the pre-position and up the way it came.
    pub fn planned_moves(
        &self,
        call: &CycleBlock,
        origin: [f64; 3],
        here: &AxisPositions,
    ) -> Result<Vec<PlannedMove>, CycleError> {
        let a = self.approach(call, Vector3::from(origin))?;
        let probe = &call.tool.probe;
        let axis = call.tool.axis;
        let [main, minor, _] = axis.indices();
        let position = |step: &str, target: AxisPositions| PlannedMove::Position {
            step: step.to_string(),
            target,
            feed: probe.fmax,
        };
        let safe = AxisPositions::new().with(axis.axis(), a.safe_height);
        let over = AxisPositions::new()
            .with(Axis::LINEAR[main], a.start[main])
            .with(Axis::LINEAR[minor], a.start[minor]);
        let path_end = a.start - a.n * a.max_distance;
        let (up, across) = (
            position("moving to the safe height", safe),
            position("positioning in the working plane", over),
        );
        let [first, second] = if from_above(here.get(axis.axis()), a.safe_height) {
            [across, up]
        } else {
            [up, across]
        };
        Ok([
            first,
            second,
            position(
                "moving to the pre-position",
                AxisPositions::linear(a.start.into()),
            ),
            PlannedMove::Probe {
                step: "probing the point".into(),
                from: a.start.into(),
                mv: ProbeMove {
                    direction: (-a.n).into(),
                    feed: probe.f,
                    max_distance: a.max_distance,
                },
                // The ball touches R before the nominal point: after SET_UP + Q320.
                nominal: a.max_distance - probe.dist - probe.calibration().r,
            },
            PlannedMove::Retract {
                step: "retracting".into(),
                distance: probe.mb,
                bounds: [a.start, path_end]
                    .map(|p| AxisPositions::linear((p + a.n * probe.mb).into())),
                feed: probe.fmax,
            },
        ]
        .into_iter()
        .chain(under_material(a.n, axis).then(|| {
            position(
                "back to the pre-position",
                AxisPositions::linear(a.start.into()),
            )
        }))
        .chain([position("moving to the safe height", safe)])
        .collect())
    }
}

/// The positioning logic of the TNC's probing cycles: a probe that stands above the
/// safe height (`here`, its tool-axis coordinate) moves over the pre-position first
/// and comes down there, on the free side of the surface, never where it happens to
/// stand; one below it goes up to the safe height first, then across.
fn from_above(here: Option<f64>, safe_height: f64) -> bool {
    here.is_some_and(|h| h > safe_height)
}

/// Whether the surface normal `n` (machine frame) points below the working plane: the
/// material then overhangs the contact, and the probe leaves the way it came.
fn under_material(n: Vector3<f64>, axis: crate::probe_axis::ProbeAxis) -> bool {
    n[axis.tool_index()] < -1e-9
}

/// `v` rounded up to the 4 decimals a message shows (the lowest value shown clears).
fn round_up(v: f64) -> f64 {
    (v * 1e4 - 1e-3).ceil() / 1e4
}

/// The cycle's positioning moves as the operator reads them ([`Leg`]), in the order
/// they run: to Q260 and over the pre-position (up then across, or from above across
/// then down), down to the pre-position, back MB from the contact, under an overhang
/// back to the pre-position, up to Q260.
struct Legs {
    up: Leg,
    over: Leg,
    over_from_above: Leg,
    down_to_q260: Leg,
    pre_position: Leg,
    retract: Leg,
    back: Leg,
    leave: Leg,
}

const POINT: &str = "Q263, Q264, Q294";
const NORMAL: &str = "Q581, Q582, Q583";

impl Probing3dParams {
    /// The legs to the pre-position `start` (axes, machine XYZ) with the active datum
    /// at `origin`. What a contact means on each: at or above Q260, material Q260 does
    /// not clear; on the way down to the pre-position, the surface stands more than
    /// SET_UP + Q320 beyond the programmed point along the normal, or (under an
    /// overhang) the way down passes under material; after the contact, material
    /// behind the point along the normal.
    fn legs(&self, call: &CycleBlock, origin: Vector3<f64>, start: Vector3<f64>) -> Legs {
        let probe = &call.tool.probe;
        let cal = probe.calibration();
        let shift = Vector3::from(cal.centre_shift(call.tool.axis));
        let q260 = self.safe_height;
        // The ball centre's pre-position in the program's coordinates.
        let pre = xyz((start + shift - origin).into());
        let clear = probe.set_up + self.clearance;
        let leg = |step: &str, route: String, check: String| Leg {
            step: step.to_string(),
            route,
            check,
        };
        let above_q260 = format!(
            "the part stands higher than Q260 there: check Q260 against the part over the point ({POINT}) and the preset (the probe moves at Q260 unmonitored)"
        );
        let off_point = format!(
            "the surface stands more than SET_UP + Q320 = {clear:.4} mm beyond the programmed point along its normal, or (a normal below the working plane) the way down from Q260 passes under the part: check the point ({POINT}), its normal ({NORMAL}) and the preset against the part, or raise Q320 (SET_UP = {:.4} mm)",
            probe.set_up
        );
        let behind = format!(
            "the part stands behind the probed point along its normal: check the normal ({NORMAL}) against the part"
        );
        Legs {
            up: Leg::up_to_q260(q260),
            over: leg(
                "positioning in the working plane",
                format!("across at the clearance height Q260={q260:+.4} to over the pre-position {pre}"),
                above_q260.clone(),
            ),
            over_from_above: leg(
                "positioning in the working plane",
                format!("across above the clearance height Q260={q260:+.4}, where the probe stood, to over the pre-position {pre}"),
                "the part stands higher than where the blocks before the cycle left the probe: check those blocks and the preset".into(),
            ),
            down_to_q260: leg(
                "moving to the safe height",
                format!("down over the pre-position {pre} to the clearance height Q260={q260:+.4}"),
                above_q260,
            ),
            pre_position: leg(
                "moving to the pre-position",
                format!(
                    "down from the clearance height Q260={q260:+.4} to {pre}, R + SET_UP + Q320 = {:.4} mm from the programmed point along its normal",
                    cal.r + clear
                ),
                off_point.clone(),
            ),
            retract: leg(
                "retracting",
                format!("MB = {:.4} mm back along the normal from the contact", probe.mb),
                behind.clone(),
            ),
            back: leg(
                "back to the pre-position",
                format!("along the normal to {pre}"),
                behind,
            ),
            leave: leg(
                "moving to the safe height",
                format!("up from the pre-position {pre} to the clearance height Q260={q260:+.4}"),
                off_point,
            ),
        }
    }
}

/// Probes the point; its result parameters and what the log shows of it.
fn measure<M: Machine>(
    call: &CycleBlock,
    p: &Probing3dParams,
    origin: Vector3<f64>,
    machine: &mut M,
    progress: &mut ProgressSink<'_>,
) -> Result<(BTreeMap<String, f64>, Probing3dRecord), CycleError> {
    let probe = &call.tool.probe;
    let axis = call.tool.axis;
    let n_cycle = Vector3::from(p.normal);
    let Approach {
        n,
        start,
        max_distance,
        safe_height,
    } = p.approach(call, origin)?;
    let direction = -n;
    let here = machine
        .positions()
        .map_err(|e| CycleError::machine("reading the axis positions", &e))?
        .get(axis.axis());

    let mut pos = Positioner {
        machine,
        axis,
        fmax: probe.fmax,
        block: call.block,
        progress,
    };
    let legs = p.legs(call, origin, start);
    if from_above(here, safe_height) {
        pos.over(start.into(), &legs.over_from_above)?;
        pos.safe_height(safe_height, &legs.down_to_q260)?;
    } else {
        pos.safe_height(safe_height, &legs.up)?;
        pos.over(start.into(), &legs.over)?;
    }
    pos.to(start.into(), &legs.pre_position)?;
    let contact = pos.probe("probing the point", direction.into(), probe.f, max_distance)?;
    let centre = Vector3::from(contact.positions.xyz());
    // Retract from the contact by MB against the probing direction, then clear.
    pos.to((centre + n * probe.mb).into(), &legs.retract)?;
    if under_material(n, axis) {
        // Back the way it came: along the normal to the pre-position, which was
        // reached straight from the safe height. Straight up from under an overhang (a
        // point below a sphere's equator) would go through the material.
        pos.to(start.into(), &legs.back)?;
    }
    pos.safe_height(safe_height, &legs.leave)?;

    // The true ball centre at the contact, and the effective radius in the
    // direction the contact pushed the ball (the normal): the probe's calibration.
    let cal = probe.calibration();
    let true_centre = centre + Vector3::from(cal.centre_shift(axis));
    let actual_m = true_centre - n * cal.radius_toward(axis, n.into()) - origin;
    let actual = Vector3::from(axis.to_cycle(actual_m.into()));
    let nominal_c = Vector3::from(p.nominal);
    let deviation = actual - nominal_c;
    let deviation_3d = deviation.dot(&n_cycle);
    let status = WorkpieceStatus::of(p.tolerance.as_ref(), deviation_3d);

    let mut q = BTreeMap::new();
    for (i, name) in ["Q151", "Q152", "Q153"].into_iter().enumerate() {
        q.insert(name.to_string(), actual[i]);
    }
    for (i, name) in ["Q161", "Q162", "Q163"].into_iter().enumerate() {
        q.insert(name.to_string(), deviation[i]);
    }
    q.insert("Q164".into(), deviation_3d);
    q.insert("Q183".into(), status.q183());

    let record = Probing3dRecord {
        block: call.block,
        line: call.line,
        probe: probe.name.clone(),
        axis,
        direction: (-n_cycle * max_distance).into(),
        path_length: max_distance,
        nominal: p.nominal,
        normal: p.normal,
        actual: actual.into(),
        deviation: deviation.into(),
        deviation_3d,
        tolerance: p.tolerance,
        status,
        u: BTreeMap::new(),
    };
    Ok((q, record))
}
