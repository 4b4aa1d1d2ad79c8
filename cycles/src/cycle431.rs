//! Cycle 431 MEASURE PLANE: three points probed along the probe axis, the plane's
//! spatial angles (for PLANE SPATIAL) and projection angles.

use crate::error::CycleError;
use crate::plane::{plane_angles, PlaneAngles, COLLINEAR_SIN};
use crate::positioning::Positioner;
use crate::program::{CycleCall, Diagnostic, LengthUnit, Param, ParamReader};
use crate::runner::ProgressEvent;
use hal::Machine;
use nalgebra::Vector3;
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

#[derive(Clone, Debug, PartialEq)]
pub struct PlaneRecord {
    pub block: u32,
    pub line: usize,
    pub probe: String,
    pub axis: crate::program::ProbeAxis,
    pub nominal: [[f64; 3]; 3],
    /// Measured points (main, minor, Q173..Q175).
    pub measured: [[f64; 3]; 3],
    pub angles: PlaneAngles,
}

#[derive(Clone, Debug, PartialEq)]
pub struct PlaneOutcome {
    pub q: BTreeMap<String, f64>,
    pub record: PlaneRecord,
}

pub fn run<M: Machine>(
    call: &CycleCall,
    p: &PlaneParams,
    machine: &mut M,
    progress: &mut dyn FnMut(ProgressEvent),
) -> Result<PlaneOutcome, CycleError> {
    let probe = &call.tool.probe;
    let axis = call.tool.axis;
    let t = axis.tool_index();
    let approach = probe.radius + probe.set_up + p.clearance;
    // The probe comes from the positive tool-axis side (from above for Z).
    let mut up = [0.0; 3];
    up[t] = 1.0;
    let up = Vector3::from(up);
    let starts = p
        .points
        .map(|pt| Vector3::from(axis.to_machine(pt)) + up * approach);
    // Planned before anything moves: every start point must lie below the safe height.
    if let Some((i, s)) = starts
        .iter()
        .enumerate()
        .find(|(_, s)| s[t] > p.safe_height)
    {
        return Err(CycleError::Plan(format!(
            "Q260={} is below the start of point {} ({:.4} = nominal + R + SET_UP + Q320); nothing moved",
            p.safe_height,
            i + 1,
            s[t]
        )));
    }
    progress(ProgressEvent::Note {
        block: call.block,
        text: "basic rotation reset".into(),
    });
    let mut pos = Positioner {
        machine,
        axis,
        fmax: probe.fmax,
        block: call.block,
        progress,
    };
    let mut measured = p.points;
    pos.safe_height(p.safe_height)?;
    for (i, start) in starts.iter().enumerate() {
        pos.over((*start).into())?;
        pos.to(&format!("approaching point {}", i + 1), (*start).into())?;
        let contact = pos.probe(
            &format!("probing point {}", i + 1),
            (-up).into(),
            probe.f,
            approach + probe.dist,
        )?;
        // Ball centre shifted by R along the probing direction (no 3D radius
        // compensation: on a tilted plane this is a constant offset of all three
        // points, which leaves the angles exact).
        measured[i][2] = contact.positions.xyz()[t] - probe.radius;
        pos.safe_height(p.safe_height)?;
    }
    let angles = plane_angles(measured[0].into(), measured[1].into(), measured[2].into())
        .map_err(|e| CycleError::Geometry(e.to_string()))?;

    let mut q = BTreeMap::new();
    q.insert("Q158".to_string(), angles.proj_a);
    q.insert("Q159".to_string(), angles.proj_b);
    q.insert("Q170".to_string(), angles.spa);
    q.insert("Q171".to_string(), angles.spb);
    q.insert("Q172".to_string(), angles.spc);
    for (i, name) in ["Q173", "Q174", "Q175"].into_iter().enumerate() {
        q.insert(name.to_string(), measured[i][2]);
    }
    Ok(PlaneOutcome {
        q,
        record: PlaneRecord {
            block: call.block,
            line: call.line,
            probe: probe.name.clone(),
            axis,
            nominal: p.points,
            measured,
            angles,
        },
    })
}
