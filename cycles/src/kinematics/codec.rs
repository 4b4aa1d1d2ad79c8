//! The identification's input and result as flat `f64` arrays, for the fixed-size IPC
//! payloads between the bridge and the estimator process (which carry them in chunks).
//! Integers (counts, axis slots, codes) are stored as exact `f64` values. Each array
//! starts with [`VERSION`]; a reader refuses any other.
//!
//! Input: `VERSION, mode, n_table, (axis, px, py, pz)*, n_head, (axis, px, py, pz)*,
//! active[15], n_axes, (axis, m, (a, b, c, x, y, z)*m)*`.
//!
//! Result: `VERSION, 0, before[15], after[15], n_free, free*, n_transfers,
//! (from, to, value)*, iterations, objective_before, objective_after, n_axes,
//! (axis, dispersion_before, max_before, dispersion_after, max_after, m,
//! deviations_before[3m], deviations_after[3m])*`, or `VERSION, 1, code, ...` for an
//! [`IdentificationError`].

use super::identification::{
    AxisMeasurement, AxisStatistics, DatumTransfer, IdentificationError, IdentificationInput,
    IdentificationResult, MeasuredPosition, MeasurementProblem, Mode, Step,
};
use super::model::{rotary_slot, ChainSpec, ErrorSet, ERROR_COUNT};
use hal::Axis;

pub const VERSION: f64 = 1.0;

/// What is wrong with the values at [`CodecError::at`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum CodecErrorKind {
    /// Written by another version of this format.
    Version,
    /// The values end before the data does.
    EndsEarly,
    /// A count or code out of its range.
    OutOfRange,
    /// Values after the end of the data.
    TrailingValues,
}

#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("malformed identification data at value {at}: {what}")]
pub struct CodecError {
    pub at: usize,
    pub kind: CodecErrorKind,
    pub what: String,
}

impl CodecError {
    pub fn kind(&self) -> CodecErrorKind {
        self.kind
    }
}

struct Reader<'a> {
    v: &'a [f64],
    at: usize,
}

impl Reader<'_> {
    fn err(&self, kind: CodecErrorKind, what: impl Into<String>) -> CodecError {
        CodecError {
            at: self.at,
            kind,
            what: what.into(),
        }
    }

    fn f(&mut self) -> Result<f64, CodecError> {
        let x = *self
            .v
            .get(self.at)
            .ok_or_else(|| self.err(CodecErrorKind::EndsEarly, "ends early"))?;
        self.at += 1;
        Ok(x)
    }

    fn n(&mut self, max: usize) -> Result<usize, CodecError> {
        let x = self.f()?;
        if !(x >= 0.0 && x.fract() == 0.0 && x <= max as f64) {
            self.at -= 1;
            return Err(self.err(
                CodecErrorKind::OutOfRange,
                format!("{x} is not a count 0..{max}"),
            ));
        }
        Ok(x as usize)
    }

    fn axis(&mut self) -> Result<Axis, CodecError> {
        Ok(Axis::ROTARY[self.n(2)?])
    }

    fn arr<const N: usize>(&mut self) -> Result<[f64; N], CodecError> {
        let mut a = [0.0; N];
        for x in &mut a {
            *x = self.f()?;
        }
        Ok(a)
    }

    fn end(&self) -> Result<(), CodecError> {
        if self.at != self.v.len() {
            return Err(self.err(
                CodecErrorKind::TrailingValues,
                "unexpected values after the end",
            ));
        }
        Ok(())
    }
}

fn axis_code(a: Axis) -> f64 {
    rotary_slot(a).expect("a rotary axis") as f64
}

const MAX_LIST: usize = 1 << 16;

pub fn encode_input(i: &IdentificationInput) -> Vec<f64> {
    let mut v = vec![VERSION, f64::from(i.mode.q406())];
    for list in [&i.chain.table, &i.chain.head] {
        v.push(list.len() as f64);
        for (a, p) in list {
            v.push(axis_code(*a));
            v.extend_from_slice(p);
        }
    }
    v.extend_from_slice(&i.active.0);
    v.push(i.axes.len() as f64);
    for g in &i.axes {
        v.push(axis_code(g.axis));
        v.push(g.positions.len() as f64);
        for p in &g.positions {
            v.extend_from_slice(&p.angles);
            v.extend_from_slice(&p.centre);
        }
    }
    v
}

fn version(r: &mut Reader) -> Result<(), CodecError> {
    let ver = r.f()?;
    if ver != VERSION {
        return Err(r.err(
            CodecErrorKind::Version,
            format!("version {ver}, this build reads {VERSION}"),
        ));
    }
    Ok(())
}

pub fn decode_input(v: &[f64]) -> Result<IdentificationInput, CodecError> {
    let mut r = Reader { v, at: 0 };
    version(&mut r)?;
    let mode = Mode::from_q406(r.n(3)? as f64).expect("0..3");
    let mut chain = ChainSpec::default();
    for side in 0..2 {
        let n = r.n(3)?;
        for _ in 0..n {
            let a = r.axis()?;
            let p = r.arr::<3>()?;
            if side == 0 {
                chain.table.push((a, p));
            } else {
                chain.head.push((a, p));
            }
        }
    }
    let active = ErrorSet(r.arr::<ERROR_COUNT>()?);
    let n_axes = r.n(3)?;
    let mut axes = Vec::with_capacity(n_axes);
    for _ in 0..n_axes {
        let axis = r.axis()?;
        let m = r.n(MAX_LIST)?;
        let mut positions = Vec::with_capacity(m);
        for _ in 0..m {
            positions.push(MeasuredPosition {
                angles: r.arr()?,
                centre: r.arr()?,
            });
        }
        axes.push(AxisMeasurement { axis, positions });
    }
    r.end()?;
    Ok(IdentificationInput {
        chain,
        active,
        mode,
        axes,
    })
}

fn step_code(s: Step) -> f64 {
    Step::ALL.iter().position(|x| *x == s).expect("listed") as f64
}

pub fn encode_result(res: &Result<IdentificationResult, IdentificationError>) -> Vec<f64> {
    let mut v = vec![VERSION];
    match res {
        Ok(r) => {
            v.push(0.0);
            v.extend_from_slice(&r.before.0);
            v.extend_from_slice(&r.after.0);
            v.push(r.free.len() as f64);
            v.extend(r.free.iter().map(|&s| s as f64));
            v.push(r.transfers.len() as f64);
            for t in &r.transfers {
                v.extend_from_slice(&[t.from as f64, t.to as f64, t.value]);
            }
            v.push(f64::from(r.iterations));
            v.push(r.objective_before);
            v.push(r.objective_after);
            v.push(r.axes.len() as f64);
            for a in &r.axes {
                v.push(axis_code(a.axis));
                v.extend_from_slice(&[
                    a.dispersion_before,
                    a.max_before,
                    a.dispersion_after,
                    a.max_after,
                ]);
                v.push(a.deviations_before.len() as f64);
                for d in a.deviations_before.iter().chain(&a.deviations_after) {
                    v.extend_from_slice(d);
                }
            }
        }
        Err(e) => {
            v.push(1.0);
            match e {
                IdentificationError::NoAxes => v.push(1.0),
                IdentificationError::BadMeasurement { axis, problem } => {
                    let (code, arg) = match problem {
                        MeasurementProblem::NotInChain => (1.0, 0.0),
                        MeasurementProblem::TooFewPositions(n) => (2.0, *n as f64),
                        MeasurementProblem::NotFinite(k) => (3.0, *k as f64),
                        MeasurementProblem::Duplicate => (4.0, 0.0),
                    };
                    v.extend_from_slice(&[2.0, axis_code(*axis), code, arg]);
                }
                IdentificationError::Undetermined { step, names } => {
                    v.extend_from_slice(&[3.0, step_code(*step), names.len() as f64]);
                    v.extend(names.iter().map(|&s| s as f64));
                }
                IdentificationError::NoMachineDatum { axes } => {
                    v.extend_from_slice(&[4.0, axes.len() as f64]);
                    v.extend(axes.iter().map(|&a| axis_code(a)));
                }
                IdentificationError::NotConverged {
                    step,
                    iterations,
                    last_step,
                } => v.extend_from_slice(&[
                    5.0,
                    step_code(*step),
                    f64::from(*iterations),
                    *last_step,
                ]),
                IdentificationError::Solver { step } => {
                    v.extend_from_slice(&[6.0, step_code(*step)])
                }
            }
        }
    }
    v
}

pub fn decode_result(
    v: &[f64],
) -> Result<Result<IdentificationResult, IdentificationError>, CodecError> {
    let mut r = Reader { v, at: 0 };
    version(&mut r)?;
    let step = |r: &mut Reader| -> Result<Step, CodecError> { Ok(Step::ALL[r.n(3)?]) };
    let out = match r.n(1)? {
        0 => {
            let before = ErrorSet(r.arr()?);
            let after = ErrorSet(r.arr()?);
            let n = r.n(ERROR_COUNT)?;
            let mut free = Vec::with_capacity(n);
            for _ in 0..n {
                free.push(r.n(ERROR_COUNT - 1)?);
            }
            let n = r.n(ERROR_COUNT)?;
            let mut transfers = Vec::with_capacity(n);
            for _ in 0..n {
                transfers.push(DatumTransfer {
                    from: r.n(ERROR_COUNT - 1)?,
                    to: r.n(ERROR_COUNT - 1)?,
                    value: r.f()?,
                });
            }
            let iterations = r.n(u32::MAX as usize)? as u32;
            let objective_before = r.f()?;
            let objective_after = r.f()?;
            let n = r.n(3)?;
            let mut axes = Vec::with_capacity(n);
            for _ in 0..n {
                let axis = r.axis()?;
                let [dispersion_before, max_before, dispersion_after, max_after] = r.arr()?;
                let m = r.n(MAX_LIST)?;
                let mut deviations_before = Vec::with_capacity(m);
                for _ in 0..m {
                    deviations_before.push(r.arr()?);
                }
                let mut deviations_after = Vec::with_capacity(m);
                for _ in 0..m {
                    deviations_after.push(r.arr()?);
                }
                axes.push(AxisStatistics {
                    axis,
                    dispersion_before,
                    max_before,
                    dispersion_after,
                    max_after,
                    deviations_before,
                    deviations_after,
                });
            }
            Ok(IdentificationResult {
                before,
                after,
                free,
                axes,
                transfers,
                iterations,
                objective_before,
                objective_after,
            })
        }
        _ => Err(match r.n(6)? {
            1 => IdentificationError::NoAxes,
            2 => {
                let axis = r.axis()?;
                let code = r.n(4)?;
                let arg = r.n(MAX_LIST)?;
                let problem = match code {
                    1 => MeasurementProblem::NotInChain,
                    2 => MeasurementProblem::TooFewPositions(arg),
                    3 => MeasurementProblem::NotFinite(arg),
                    4 => MeasurementProblem::Duplicate,
                    _ => {
                        return Err(r.err(
                            CodecErrorKind::OutOfRange,
                            format!("unknown measurement problem {code}"),
                        ))
                    }
                };
                IdentificationError::BadMeasurement { axis, problem }
            }
            3 => {
                let step = step(&mut r)?;
                let n = r.n(ERROR_COUNT)?;
                let mut names = Vec::with_capacity(n);
                for _ in 0..n {
                    names.push(r.n(ERROR_COUNT - 1)?);
                }
                IdentificationError::Undetermined { step, names }
            }
            4 => {
                let n = r.n(3)?;
                let mut axes = Vec::with_capacity(n);
                for _ in 0..n {
                    axes.push(r.axis()?);
                }
                IdentificationError::NoMachineDatum { axes }
            }
            5 => IdentificationError::NotConverged {
                step: step(&mut r)?,
                iterations: r.n(u32::MAX as usize)? as u32,
                last_step: r.f()?,
            },
            6 => IdentificationError::Solver {
                step: step(&mut r)?,
            },
            c => {
                return Err(r.err(
                    CodecErrorKind::OutOfRange,
                    format!("unknown error code {c}"),
                ))
            }
        }),
    };
    r.end()?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::identification::identify;

    fn input() -> IdentificationInput {
        let chain = ChainSpec {
            table: vec![(Axis::C, [0.0, 0.0, 0.0])],
            head: vec![(Axis::B, [0.0, 0.0, 250.0])],
        };
        let mut active = ErrorSet::default();
        active.0[3] = 0.25;
        let pos = |a: f64, x: f64| MeasuredPosition {
            angles: [0.0, 0.0, a],
            centre: [40.0 + x, 25.0 - x, 60.0],
        };
        IdentificationInput {
            chain,
            active,
            mode: Mode::PositionAndAngle,
            axes: vec![AxisMeasurement {
                axis: Axis::C,
                positions: vec![pos(0.0, 0.0), pos(90.0, 0.001), pos(180.0, -0.002)],
            }],
        }
    }

    #[test]
    fn input_and_results_round_trip() {
        let i = input();
        assert_eq!(decode_input(&encode_input(&i)).unwrap(), i);
        let mut j = i.clone();
        j.mode = Mode::Position;
        let ok = identify(&j);
        assert!(ok.is_ok(), "{ok:?}");
        assert_eq!(decode_result(&encode_result(&ok)).unwrap(), ok);
        for e in [
            IdentificationError::NoAxes,
            IdentificationError::BadMeasurement {
                axis: Axis::B,
                problem: MeasurementProblem::TooFewPositions(1),
            },
            IdentificationError::Undetermined {
                step: Step::AfterMachineDatum,
                names: vec![3, 4],
            },
            IdentificationError::NoMachineDatum {
                axes: vec![Axis::B, Axis::C],
            },
            IdentificationError::NotConverged {
                step: Step::Positions,
                iterations: 50,
                last_step: 1e-3,
            },
            IdentificationError::Solver {
                step: Step::OrientationsAndPositions,
            },
        ] {
            let r = Err(e);
            assert_eq!(decode_result(&encode_result(&r)).unwrap(), r);
        }
    }

    #[test]
    fn malformed_data_is_refused_with_the_place() {
        let mut v = encode_input(&input());
        v[0] = 2.0;
        assert_eq!(
            decode_input(&v).unwrap_err().kind(),
            CodecErrorKind::Version
        );
        let v = encode_input(&input());
        let e = decode_input(&v[..v.len() - 1]).unwrap_err();
        assert_eq!(e.kind(), CodecErrorKind::EndsEarly, "{e}");
        let mut v = encode_input(&input());
        v.push(0.0);
        let e = decode_input(&v).unwrap_err();
        assert_eq!(e.kind(), CodecErrorKind::TrailingValues, "{e}");
        let mut v = encode_input(&input());
        v[1] = 7.0;
        let e = decode_input(&v).unwrap_err();
        assert_eq!((e.at, e.kind()), (1, CodecErrorKind::OutOfRange), "{e}");
    }
}
