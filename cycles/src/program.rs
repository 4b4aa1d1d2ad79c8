//! A validated NC program: blocks in order, every measuring cycle with its parameters
//! resolved (defaults, PREDEF, inch converted to mm) and the probe it runs with.
//! Only [`crate::parser`] builds one, so holding a [`Program`] means it passed
//! validation and can run without further checks on its text.

use crate::cycle431::PlaneParams;
use crate::cycle444::Probing3dParams;
use hal::config::{MachineConfig, ProbeEntry};
use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

/// Unit of the program (`BEGIN PGM NAME MM|INCH`); values inside [`Program`] are mm.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LengthUnit {
    Mm,
    Inch,
}

/// The probe (tool) axis chosen by `TOOL CALL ... Z|X|Y`; it fixes which machine axes
/// are the main, minor and tool axis of the cycle coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProbeAxis {
    X,
    Y,
    Z,
}

impl ProbeAxis {
    /// Machine XYZ indices of (main, minor, tool) axis: Z -> X Y Z, X -> Y Z X,
    /// Y -> Z X Y (the TNC's working planes for each tool axis, right-handed).
    pub fn indices(self) -> [usize; 3] {
        match self {
            ProbeAxis::Z => [0, 1, 2],
            ProbeAxis::X => [1, 2, 0],
            ProbeAxis::Y => [2, 0, 1],
        }
    }

    /// (main, minor, tool) coordinates to machine X, Y, Z.
    pub fn to_machine(self, v: [f64; 3]) -> [f64; 3] {
        let mut m = [0.0; 3];
        for (k, i) in self.indices().into_iter().enumerate() {
            m[i] = v[k];
        }
        m
    }

    /// Machine X, Y, Z to (main, minor, tool).
    pub fn to_cycle(self, m: [f64; 3]) -> [f64; 3] {
        self.indices().map(|i| m[i])
    }

    pub fn tool_index(self) -> usize {
        self.indices()[2]
    }

    pub fn axis(self) -> hal::Axis {
        match self {
            ProbeAxis::X => hal::Axis::X,
            ProbeAxis::Y => hal::Axis::Y,
            ProbeAxis::Z => hal::Axis::Z,
        }
    }

    pub fn from_name(s: &str) -> Option<Self> {
        match s {
            "X" | "x" => Some(ProbeAxis::X),
            "Y" | "y" => Some(ProbeAxis::Y),
            "Z" | "z" => Some(ProbeAxis::Z),
            _ => None,
        }
    }
}

impl fmt::Display for ProbeAxis {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.axis().name())
    }
}

/// The active touch probe: the probe table entry and the probe axis.
#[derive(Clone, Debug, PartialEq)]
pub struct ToolCall {
    /// 1-based line of the TOOL CALL.
    pub line: usize,
    pub probe: ProbeEntry,
    pub axis: ProbeAxis,
}

/// A parameter value after resolution.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// mm, mm/min, degrees or dimensionless (inch values already converted).
    Number(f64),
    /// Rapid positioning feed (the probe table's FMAX).
    Fmax,
    /// Automatic feed (the TNC uses FMAX for positioning here too).
    Fauto,
    Text(String),
}

/// Where a value came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Origin {
    Written,
    /// PREDEF: from `[cycles.predef]` of the machine configuration.
    Predef,
    /// Left out; the table's default.
    Default,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Param {
    pub value: Value,
    pub origin: Origin,
    /// 1-based line where it was written (the cycle's first line for defaults).
    pub line: usize,
}

/// The typed parameters of the cycles this crate runs; 450 and 451 keep only their
/// validated table ([`CycleCall::params`]) for the kinematics cycles built on top.
#[derive(Clone, Debug, PartialEq)]
pub enum CycleKind {
    MeasurePlane(PlaneParams),
    Probing3d(Probing3dParams),
    MeasureKinematics,
    SaveKinematics,
}

/// One measuring cycle block.
#[derive(Clone, Debug, PartialEq)]
pub struct CycleCall {
    pub cycle: u16,
    /// Free text after the number (any language), or the table name for ISO blocks.
    pub title: String,
    /// 1-based first line of the block.
    pub line: usize,
    /// NC block number, or the line when the block has none.
    pub block: u32,
    /// Every parameter of the cycle's table, by name ("Q263", "QS400").
    pub params: BTreeMap<String, Param>,
    pub tool: ToolCall,
    pub kind: CycleKind,
}

/// Reads the parameters of a validated cycle block for a cycle's own checks. The
/// parameter table guarantees every value; a gap is reported as a diagnostic (never a
/// panic), and the line of a parameter is at hand for messages.
pub(crate) struct ParamReader<'a> {
    params: &'a BTreeMap<String, Param>,
    pub problems: Vec<Diagnostic>,
}

impl<'a> ParamReader<'a> {
    pub fn new(params: &'a BTreeMap<String, Param>) -> Self {
        Self {
            params,
            problems: Vec::new(),
        }
    }

    /// The numeric value of `name`; 0 (and a problem) when it has none.
    pub fn number(&mut self, name: &str) -> f64 {
        match self.params.get(name) {
            Some(Param {
                value: Value::Number(v),
                ..
            }) => *v,
            _ => {
                self.problems.push(Diagnostic {
                    line: 0,
                    message: format!("{name}: no numeric value"),
                });
                0.0
            }
        }
    }

    /// The text of `name` and its line (empty and 0 when absent).
    pub fn text(&self, name: &str) -> (String, usize) {
        match self.params.get(name) {
            Some(Param {
                value: Value::Text(t),
                line,
                ..
            }) => (t.clone(), *line),
            _ => (String::new(), 0),
        }
    }

    /// Line of `name` in the program (0 when absent).
    pub fn line(&self, name: &str) -> usize {
        self.params.get(name).map_or(0, |p| p.line)
    }

    pub fn problem(&mut self, line: usize, message: impl Into<String>) {
        self.problems.push(Diagnostic {
            line,
            message: message.into(),
        });
    }

    /// `Ok(value)` when no problem was found.
    pub fn finish<T>(self, value: T) -> Result<T, Vec<Diagnostic>> {
        if self.problems.is_empty() {
            Ok(value)
        } else {
            Err(self.problems)
        }
    }
}

impl CycleCall {
    pub fn number(&self, name: &str) -> Option<f64> {
        match self.params.get(name)?.value {
            Value::Number(v) => Some(v),
            _ => None,
        }
    }

    pub fn text(&self, name: &str) -> Option<&str> {
        match &self.params.get(name)?.value {
            Value::Text(s) => Some(s),
            _ => None,
        }
    }
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
    /// Any other NC block (moves, comments, FN, M functions, ...): not a measuring
    /// cycle, accepted and not run.
    Other(String),
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
    /// Parses and validates program text against a machine (probe table, PREDEF).
    pub fn parse(text: &str, cfg: &MachineConfig) -> Result<Program, ProgramErrors> {
        crate::parser::parse_program(text, cfg)
    }

    /// Reads, parses and validates a `.h` file.
    pub fn load(path: &Path, cfg: &MachineConfig) -> Result<Program, ProgramError> {
        let text = std::fs::read_to_string(path).map_err(|source| ProgramError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        let mut program = Program::parse(&text, cfg).map_err(|errors| ProgramError::Invalid {
            path: path.to_path_buf(),
            errors,
        })?;
        program.path = Some(path.to_path_buf());
        Ok(program)
    }

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

/// One problem found in a program, with its 1-based line.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Diagnostic {
    pub line: usize,
    pub message: String,
}

impl fmt::Display for Diagnostic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "line {}: {}", self.line, self.message)
    }
}

/// Every problem of a program (validation collects all, not just the first).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ProgramErrors(pub Vec<Diagnostic>);

impl fmt::Display for ProgramErrors {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, d) in self.0.iter().enumerate() {
            if i > 0 {
                f.write_str("\n")?;
            }
            write!(f, "{d}")?;
        }
        Ok(())
    }
}

impl std::error::Error for ProgramErrors {}

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
