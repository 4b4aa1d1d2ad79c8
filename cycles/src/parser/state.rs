//! What the walk through a program's blocks carries from one block to the next (unit,
//! name, the tool called), and how a problem is recorded at its line.

use crate::cycle_block::ToolCall;
use crate::diagnostic::Diagnostic;
use crate::length_unit::LengthUnit;

pub(super) struct State {
    pub(super) unit: LengthUnit,
    pub(super) name: Option<String>,
    pub(super) begin_seen: bool,
    pub(super) end_line: Option<usize>,
    pub(super) tool: Option<ToolCall>,
    /// The block before was CYCL DEF 7.0 or 7.x: a 7.x may follow.
    pub(super) cycle7: bool,
    /// The line of a `FUNCTION MODE TURN` not yet undone by `FUNCTION MODE MILL`.
    pub(super) turn_mode: Option<usize>,
}

pub(super) fn err(diags: &mut Vec<Diagnostic>, line: usize, message: impl Into<String>) {
    diags.push(Diagnostic {
        line,
        message: message.into(),
    });
}
