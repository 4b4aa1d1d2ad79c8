//! A measuring cycle block as the parser resolved it: its parameters (value, origin,
//! line), the active touch probe, and a reader for the cycles' own checks.

use crate::diagnostic::Diagnostic;
use crate::probe_axis::ProbeAxis;
use crate::probe_table::ProbeEntry;
use std::collections::BTreeMap;

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

/// The common part of every measuring cycle block: where it stands, its parameter
/// table as resolved, and the probe it runs with. The typed parameters of each cycle
/// are in [`crate::program::CycleKind`].
#[derive(Clone, Debug, PartialEq)]
pub struct CycleBlock {
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

    /// The value of `name` as resolved (a number, FMAX, FAUTO or text); `None` (and a
    /// problem) when it has none.
    pub fn value(&mut self, name: &str) -> Option<Value> {
        let v = self.params.get(name).map(|p| p.value.clone());
        if v.is_none() {
            self.problems.push(Diagnostic {
                line: 0,
                message: format!("{name}: no value"),
            });
        }
        v
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

impl CycleBlock {
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
