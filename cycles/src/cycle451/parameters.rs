//! The parameters of a 451 block, typed at parse time.

use crate::cycle_block::{Param, ParamReader, Value};
use crate::diagnostic::Diagnostic;
use crate::kinematics::identification::Mode;
use crate::length_unit::LengthUnit;
use std::collections::BTreeMap;

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

/// The parameters of a 451 block (ranges checked by the parser's table).
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
    /// Reads the validated table values of a 451 block (the table checked the ranges;
    /// the machine-dependent checks are [`super::plan::plan`]'s).
    pub fn from_params(
        params: &BTreeMap<String, Param>,
        _unit: LengthUnit,
    ) -> Result<Self, Vec<Diagnostic>> {
        let mut r = ParamReader::new(params);
        let feed = match r.value("Q253") {
            Some(Value::Number(v)) => Feed::Value(v),
            _ => Feed::Fmax,
        };
        let mut range = |q: [&str; 4]| AxisRange {
            start: r.number(q[0]),
            end: r.number(q[1]),
            incidence: r.number(q[2]),
            points: r.number(q[3]) as u32,
        };
        let ranges = [
            range(["Q411", "Q412", "Q413", "Q414"]),
            range(["Q415", "Q416", "Q417", "Q418"]),
            range(["Q419", "Q420", "Q421", "Q422"]),
        ];
        let q406 = r.number("Q406");
        let mode = Mode::from_q406(q406).unwrap_or_else(|| {
            r.problem(
                r.line("Q406"),
                format!("Q406={q406}: the mode must be 0..3"),
            );
            Mode::Check
        });
        let params = KinematicsParams {
            mode,
            sphere_radius: r.number("Q407"),
            clearance: r.number("Q320"),
            retract_height: r.number("Q408"),
            feed,
            reference_angle: r.number("Q380"),
            ranges,
            points: r.number("Q423") as u32,
            preset: r.number("Q431") as u8,
            backlash: r.number("Q432"),
        };
        r.finish(params)
    }
}
