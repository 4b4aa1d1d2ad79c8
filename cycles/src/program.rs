//! A validated NC program: blocks in order, every measuring cycle with its parameters
//! resolved (defaults, PREDEF, inch converted to mm) and the probe it runs with.
//! Only [`crate::parser`] builds one, so holding a [`Program`] means it passed
//! validation and can run without further checks on its text.

use crate::cycle431::PlaneParams;
use crate::cycle444::Probing3dParams;
use crate::cycle450::SaveParams;
use crate::cycle451::KinematicsParams;
use crate::cycle460::CalibrationParams;
pub use crate::cycle_block::{CycleBlock, Origin, Param, ToolCall, Value};
use crate::datum::DatumBlock;
pub use crate::diagnostic::{Diagnostic, ProgramErrors};
pub use crate::flow_block::{Assignment, CallLabel, FlowBlock, Jump, Label};
pub use crate::length_unit::LengthUnit;
pub use crate::probe_axis::ProbeAxis;
use std::path::{Path, PathBuf};

/// The typed parameters of a cycle block, checked at parse time.
#[derive(Clone, Debug, PartialEq)]
pub enum CycleKind {
    MeasurePlane(PlaneParams),
    Probing3d(Probing3dParams),
    MeasureKinematics(KinematicsParams),
    SaveKinematics(SaveParams),
    /// Cycle 460: calibrates the probe on a sphere, writes its probe table row.
    CalibrateProbe(CalibrationParams),
}

/// One measuring cycle block: where it stands and its typed parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct CycleCall {
    pub head: CycleBlock,
    pub kind: CycleKind,
}

#[derive(Clone, Debug, PartialEq)]
pub enum Statement {
    BeginPgm {
        name: String,
        unit: LengthUnit,
    },
    EndPgm {
        name: String,
        unit: LengthUnit,
    },
    ToolCall(ToolCall),
    Cycle(Box<CycleCall>),
    /// Cycle 247, cycle 7, TRANS DATUM, G247, G54: the datum changes.
    Datum(DatumBlock),
    /// A measuring cycle with parameters given as Q parameters (`Q407=+Q5`): resolved
    /// and validated when it runs ([`crate::parser::resolve_deferred`]).
    Deferred(Box<DeferredCycle>),
    /// `Q10 = Q141 * 1000`, `FN 0..5`, `QS0 = SUBSTR ( ... )`.
    Assign(Assignment),
    /// `LBL 5`, `LBL "NAME"`, `LBL 0` (end of a subprogram).
    Label(Label),
    /// `FN 9..12: IF a EQU|NE|GT|LT b GOTO LBL n`.
    Jump(Jump),
    /// `CALL LBL n REP k`.
    Call(CallLabel),
    /// `FN 14: ERROR = n`: the program stops with error number n.
    Stop(u32),
    /// Any other NC block (`L` moves, comments, M functions): not a measuring cycle;
    /// `L` blocks move, the rest is accepted and not run.
    Other(String),
}

/// A cycle block whose values come from Q parameters: what is needed to read it again
/// with their values.
#[derive(Clone, Debug, PartialEq)]
pub struct DeferredCycle {
    pub cycle: u16,
    /// 1-based first and last line.
    pub line: usize,
    pub last_line: usize,
    pub block: u32,
    /// The block's lines as written.
    pub source: String,
    pub unit: LengthUnit,
    pub tool: ToolCall,
}

impl From<FlowBlock> for Statement {
    fn from(b: FlowBlock) -> Self {
        match b {
            FlowBlock::Assign(a) => Statement::Assign(a),
            FlowBlock::Label(l) => Statement::Label(l),
            FlowBlock::Jump(j) => Statement::Jump(j),
            FlowBlock::Call(c) => Statement::Call(c),
            FlowBlock::Stop(n) => Statement::Stop(n),
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct Block {
    /// 1-based first line.
    pub line: usize,
    pub number: Option<u32>,
    pub statement: Statement,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Program {
    /// From BEGIN PGM, if the program has one.
    pub name: Option<String>,
    pub unit: LengthUnit,
    /// The file it was loaded from (protocols go next to it by default).
    pub path: Option<PathBuf>,
    pub blocks: Vec<Block>,
}

impl Program {
    /// The measuring cycles, in program order.
    pub fn cycles(&self) -> impl Iterator<Item = &CycleCall> {
        self.blocks.iter().filter_map(|b| match &b.statement {
            Statement::Cycle(c) => Some(&**c),
            _ => None,
        })
    }

    /// The folder next to the program (where the TNC puts protocols), if known.
    pub fn folder(&self) -> Option<&Path> {
        self.path.as_deref().and_then(Path::parent)
    }
}

/// Why a program file cannot be used.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum ProgramErrorKind {
    Read,
    Invalid,
}

#[derive(Debug, thiserror::Error)]
pub enum ProgramError {
    #[error("cannot read {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {} error(s):\n{errors}", errors.0.len())]
    Invalid {
        path: PathBuf,
        errors: ProgramErrors,
    },
}

impl ProgramError {
    pub fn kind(&self) -> ProgramErrorKind {
        match self {
            ProgramError::Read { .. } => ProgramErrorKind::Read,
            ProgramError::Invalid { .. } => ProgramErrorKind::Invalid,
        }
    }
}
