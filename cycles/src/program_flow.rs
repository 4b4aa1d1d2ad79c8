//! The program as the TNC runs it: Q-parameter assignments (`Q1 = ...`, `FN 0..5`,
//! string formulas), labels (`LBL 5`, `LBL "NAME"`, `LBL 0` ends a subprogram), jumps
//! (`FN 9`..`FN 12`), subprogram calls and program-section repeats
//! (`CALL LBL 5 REP 3`), and `FN 14: ERROR = n` ([`crate::flow_block`]). [`Flow`] steps through the blocks,
//! doing what only touches parameters itself and handing every other block (moves,
//! cycles, datum changes) to its caller: `run` acts on them, `check` checks them.

use crate::flow_block::{Label, MAX_NESTING};
use crate::formula::{eval_formula, Env, EvalError, EvalErrorKind, Expr, Lookup, StrExpr};
use crate::program::{Block, Program, Statement};
use crate::q_params::{QName, QParams, QValue};
use std::borrow::Cow;
use std::collections::BTreeMap;

pub use crate::check_walk::{fingerprint, CheckFault, CheckWalk, MAX_CHECK_PATHS};
use crate::program_warnings::reads_mm;

/// Labels defined twice, and jumps or calls to labels that do not exist, each at its
/// line.
pub fn check_labels(blocks: &[Block]) -> Vec<crate::diagnostic::Diagnostic> {
    let mut out = Vec::new();
    let mut seen: BTreeMap<&Label, usize> = BTreeMap::new();
    for b in blocks {
        if let Statement::Label(l) = &b.statement {
            if *l == Label::Number(0) {
                continue;
            }
            if let Some(first) = seen.get(l) {
                out.push(crate::diagnostic::Diagnostic {
                    line: b.line,
                    message: format!("{l} is defined twice (first on line {first})"),
                });
            } else {
                seen.insert(l, b.line);
            }
        }
    }
    for (index, b) in blocks.iter().enumerate() {
        let target = match &b.statement {
            Statement::Jump(j) => &j.target,
            Statement::Call(c) => &c.target,
            _ => continue,
        };
        if !seen.contains_key(target) {
            out.push(crate::diagnostic::Diagnostic {
                line: b.line,
                message: format!("{target} is not defined in this program"),
            });
        } else if let Statement::Call(c) = &b.statement {
            if let Some(message) = call_runs_nothing(blocks, index, c) {
                out.push(crate::diagnostic::Diagnostic {
                    line: b.line,
                    message,
                });
            }
        }
    }
    out
}

/// Whether a block does anything when it runs (labels and comments do not).
fn does_something(s: &Statement) -> bool {
    match s {
        Statement::Label(_) => false,
        Statement::Other(code) => {
            let code = code.trim_start();
            !(code.is_empty() || code.starts_with('*'))
        }
        _ => true,
    }
}

/// Why the CALL at block `index` would run nothing (a section repeat of no blocks or
/// REP 0, a subprogram without its `LBL 0` or with nothing in it); `None` when it runs
/// something.
fn call_runs_nothing(
    blocks: &[Block],
    index: usize,
    c: &crate::flow_block::CallLabel,
) -> Option<String> {
    let target = label_index(blocks, &c.target)?;
    let label_line = blocks[target].line;
    let name = &c.target;
    if c.is_section_repeat(target, index) {
        if c.rep == Some(0) {
            return Some(format!(
                "CALL {name} REP 0 repeats the section from {name} (line {label_line}) no time: it runs nothing (give REP 1 or more, or leave the CALL out)"
            ));
        }
        if !blocks[target + 1..index]
            .iter()
            .any(|b| does_something(&b.statement))
        {
            return Some(format!(
                "CALL {name} REP {}: the section from {name} (line {label_line}) to this CALL is empty: the repeat runs nothing",
                c.rep.unwrap_or(0)
            ));
        }
        return None;
    }
    let Some(end) = blocks[target + 1..]
        .iter()
        .position(|b| b.statement == Statement::Label(Label::Number(0)))
        .map(|i| target + 1 + i)
    else {
        let hint = if target < index {
            format!(
                "; to repeat the blocks from {name} to this CALL, write CALL {name} REP k (a program-section repeat)"
            )
        } else {
            String::new()
        };
        return Some(format!(
            "CALL {name} calls the subprogram {name} (line {label_line}), but no LBL 0 follows it to end it: the call would run into the end of the program (a subprogram is {name} ... LBL 0){hint}"
        ));
    };
    if !blocks[target + 1..end]
        .iter()
        .any(|b| does_something(&b.statement))
    {
        return Some(format!(
            "CALL {name}: the subprogram {name} (line {label_line}) ends at LBL 0 (line {}) with nothing in it: the call runs nothing",
            blocks[end].line
        ));
    }
    None
}

/// Reads parameters for formulas: `run`'s values, and for `check` the parameters a
/// cycle will measure ([`QParams::mark_measured`]). A QR parameter that no run has set
/// reads 0: the TNC's remanent parameters are a memory that starts at 0, so a counter
/// `QR1 = QR1 + 1` works on a fresh machine; a Q or QL parameter nothing set before is
/// still an error (a typo, or a result read before its cycle ran).
impl Env for QParams {
    fn lookup(&self, name: QName) -> Lookup {
        if self.is_measured(name) {
            return Lookup::Measured;
        }
        match self.get(name) {
            Some(v) => Lookup::Value(v.clone()),
            None if name.kind == crate::q_params::QKind::QR => Lookup::Value(QValue::Number(0.0)),
            None => Lookup::Undefined,
        }
    }
}

/// `L X+Q1 Y-Q2 R0 FQ3`: the block with each parameter replaced by its value (as
/// written, `-Q2` negated). Other blocks are returned as they are.
pub fn substitute_params<'a>(code: &'a str, env: &dyn Env) -> Result<Cow<'a, str>, EvalError> {
    let mut words = code.split_whitespace();
    if !words.next().is_some_and(|w| w.eq_ignore_ascii_case("L"))
        || !code.to_ascii_uppercase().contains('Q')
    {
        return Ok(Cow::Borrowed(code));
    }
    let mut out = String::from("L");
    for w in words {
        out.push(' ');
        let u = w.to_ascii_uppercase();
        let letter = &u[..u.chars().next().map_or(0, char::len_utf8)];
        let rest = &u[letter.len()..];
        let (neg, name) = match rest.as_bytes().first() {
            Some(b'+') => (false, &rest[1..]),
            Some(b'-') => (true, &rest[1..]),
            _ => (false, rest),
        };
        match QName::parse(name).filter(|n| !n.is_text() && "XYZABCF".contains(letter)) {
            Some(n) => {
                let v = crate::formula::eval(&Expr::Param(n), env)?;
                let v = if neg { -v } else { v };
                out.push_str(&format!("{letter}{v:+}"));
            }
            None => out.push_str(w),
        }
    }
    Ok(Cow::Owned(out))
}

/// A cycle block's text with each `Qnnn=+Qm` (`-Qm`, `QLm`, `QRm`) replaced by the
/// value (`Qnnn=+12.5`), and each `QSnnn=QSm` by the text (`QSnnn="..."`); nothing
/// inside a quoted string is touched.
pub fn substitute_cycle_values(source: &str, env: &dyn Env) -> Result<String, EvalError> {
    let mut out = String::with_capacity(source.len());
    let mut rest = source;
    while let Some(i) = rest.find('=') {
        out.push_str(&rest[..=i]);
        rest = &rest[i + 1..];
        if out.matches('"').count() % 2 == 1 {
            continue;
        }
        let trimmed = rest.trim_start();
        let (neg, after_sign) = match trimmed.as_bytes().first() {
            Some(b'+') => (false, &trimmed[1..]),
            Some(b'-') => (true, &trimmed[1..]),
            _ => (false, trimmed),
        };
        if let Some(Ok((name, len))) = QName::parse_prefix(after_sign) {
            if !name.is_text() {
                let v = crate::formula::eval(&Expr::Param(name), env)?;
                let v = if neg { -v } else { v };
                out.push_str(&format!("{v:+}"));
                rest = &after_sign[len..];
            } else if after_sign.len() == trimmed.len() {
                let t = crate::formula::eval_text(&StrExpr::Param(name), env)?;
                out.push_str(&format!("\"{t}\""));
                rest = &after_sign[len..];
            }
        }
    }
    out.push_str(rest);
    Ok(out)
}

/// Why the program stops (besides a machine or cycle error).
#[derive(Clone, Debug, PartialEq)]
pub enum FlowStop {
    /// `FN 14: ERROR = n`.
    Error { line: usize, number: u32 },
    /// A block that cannot be carried out (an undefined parameter, a division by zero,
    /// too many jumps, ...).
    Fault {
        line: usize,
        kind: FlowFaultKind,
        message: String,
    },
    /// `check` only: a jump whose condition depends on a measured result.
    Undecided { index: usize, target: usize },
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum FlowFaultKind {
    Eval(EvalErrorKind),
    /// More jumps than `[cycles] max_jumps` allows: the program loops.
    JumpLimit,
    /// Subprograms nested deeper than the TNC allows.
    Nesting,
    /// A subprogram runs into the program's end without its LBL 0.
    NoReturn,
}

/// What the caller does next.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Step {
    /// Act on the block at this index (a move, a cycle, a datum change, a frame, ...).
    Act(usize),
    /// The program ended (END PGM, M2/M30, or its last block).
    End,
}

/// Where the program stands: the next block, the subprograms' return points, the
/// repeats left per CALL block, the jumps made so far.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Flow {
    pub(crate) pc: usize,
    pub(crate) returns: Vec<usize>,
    pub(crate) repeats: BTreeMap<usize, u32>,
    pub(crate) jumps: u64,
    pub(crate) max_jumps: u64,
    pub(crate) ending: bool,
}

/// Block index of each label (and of each `LBL 0`).
fn label_index(blocks: &[Block], target: &Label) -> Option<usize> {
    blocks
        .iter()
        .position(|b| matches!(&b.statement, Statement::Label(l) if l == target))
}

/// M2 or M30 in a block (alone or in an `L` block): the program run ends there.
fn ends_program(code: &str) -> bool {
    code.split_whitespace().any(|w| {
        w.eq_ignore_ascii_case("M2")
            || w.eq_ignore_ascii_case("M02")
            || w.eq_ignore_ascii_case("M30")
    })
}

impl Flow {
    pub fn new(max_jumps: u64) -> Self {
        Self {
            pc: 0,
            returns: Vec::new(),
            repeats: BTreeMap::new(),
            jumps: 0,
            max_jumps,
            ending: false,
        }
    }

    pub fn jumps(&self) -> u64 {
        self.jumps
    }

    fn jump(&mut self, line: usize, to: usize) -> Result<(), FlowStop> {
        self.jumps += 1;
        if self.jumps > self.max_jumps {
            return Err(FlowStop::Fault {
                line,
                kind: FlowFaultKind::JumpLimit,
                message: format!(
                    "more than {} jumps: the program loops (the limit is the machine configuration's [cycles] max_jumps)",
                    self.max_jumps
                ),
            });
        }
        self.pc = to;
        Ok(())
    }

    /// Takes (or not) the jump of the block at `index` whose condition `check` could
    /// not decide; `target` as [`FlowStop::Undecided`] gave it.
    pub fn decide(
        &mut self,
        program: &Program,
        index: usize,
        target: usize,
        taken: bool,
    ) -> Result<(), FlowStop> {
        if taken {
            self.jump(program.blocks[index].line, target)
        } else {
            self.pc = index + 1;
            Ok(())
        }
    }

    /// Runs parameter blocks and jumps until a block for the caller, the end, or a
    /// stop.
    pub fn advance(&mut self, program: &Program, params: &mut QParams) -> Result<Step, FlowStop> {
        let blocks = &program.blocks;
        loop {
            if self.ending {
                return Ok(Step::End);
            }
            let index = self.pc;
            let Some(block) = blocks.get(index) else {
                return self.end(blocks);
            };
            let line = block.line;
            let fault = |e: EvalError| FlowStop::Fault {
                line,
                kind: FlowFaultKind::Eval(e.kind),
                message: e.message,
            };
            self.pc = index + 1;
            match &block.statement {
                Statement::EndPgm { .. } => return self.end(blocks),
                Statement::Assign(a) => {
                    let mm = reads_mm(&a.formula, params);
                    match eval_formula(&a.formula, params) {
                        Ok(v) => params.set(a.target, v),
                        // check: the value will be known when the program runs.
                        Err(e) if e.kind == EvalErrorKind::Measured => {
                            params.mark_measured(a.target)
                        }
                        Err(e) => return Err(fault(e)),
                    }
                    if mm {
                        params.mark_mm(a.target);
                    }
                }
                Statement::Label(Label::Number(0)) => {
                    if let Some(back) = self.returns.pop() {
                        self.pc = back;
                    }
                }
                Statement::Label(_) => {}
                Statement::Jump(j) => {
                    let target =
                        label_index(blocks, &j.target).expect("labels checked at parse time");
                    let l = crate::formula::eval(&j.left, params);
                    let r = crate::formula::eval(&j.right, params);
                    match (l, r) {
                        (Ok(a), Ok(b)) => {
                            if j.compare.holds(a, b) {
                                self.jump(line, target)?;
                            }
                        }
                        (Err(e), _) | (_, Err(e)) if e.kind == EvalErrorKind::Measured => {
                            self.pc = index;
                            return Err(FlowStop::Undecided { index, target });
                        }
                        (Err(e), _) | (_, Err(e)) => return Err(fault(e)),
                    }
                }
                Statement::Call(c) => {
                    let target =
                        label_index(blocks, &c.target).expect("labels checked at parse time");
                    if c.is_section_repeat(target, index) {
                        // Program-section repeat: back to the label `rep` more times.
                        let left = self.repeats.entry(index).or_insert(c.rep.unwrap_or(0));
                        if *left > 0 {
                            *left -= 1;
                            self.jump(line, target)?;
                        } else {
                            self.repeats.remove(&index);
                        }
                    } else {
                        // Subprogram, wherever its label stands, called 1 + rep times:
                        // come back to this block while repeats are left.
                        let left = self.repeats.entry(index).or_insert(c.rep.unwrap_or(0) + 1);
                        *left -= 1;
                        let back = if *left > 0 {
                            index
                        } else {
                            self.repeats.remove(&index);
                            index + 1
                        };
                        if self.returns.len() >= MAX_NESTING {
                            return Err(FlowStop::Fault {
                                line,
                                kind: FlowFaultKind::Nesting,
                                message: format!(
                                    "subprograms nested deeper than {MAX_NESTING} levels"
                                ),
                            });
                        }
                        self.returns.push(back);
                        self.jump(line, target + 1)?;
                    }
                }
                Statement::Stop(number) => {
                    return Err(FlowStop::Error {
                        line,
                        number: *number,
                    })
                }
                Statement::Other(code) if ends_program(code) => {
                    self.ending = true;
                    return Ok(Step::Act(index));
                }
                _ => return Ok(Step::Act(index)),
            }
        }
    }

    fn end(&mut self, blocks: &[Block]) -> Result<Step, FlowStop> {
        if let Some(&back) = self.returns.last() {
            let line = blocks.get(back.saturating_sub(1)).map_or(0, |b| b.line);
            return Err(FlowStop::Fault {
                line,
                kind: FlowFaultKind::NoReturn,
                message: "the subprogram called here runs into the end of the program: its LBL 0 is missing".into(),
            });
        }
        self.ending = true;
        Ok(Step::End)
    }
}

/// How many measuring cycles a run of `program` starts, when that is known before it
/// runs: a program without jumps and calls runs its cycle blocks (with written or
/// Q-parameter values) up to its end (M2/M30, END PGM) or FN 14 once each. `None`
/// with jumps or calls: a loop or a subprogram starts a cycle block as often as the
/// program's values say.
pub fn cycle_count(program: &Program) -> Option<usize> {
    let mut n = 0;
    for b in &program.blocks {
        match &b.statement {
            Statement::Jump(_) | Statement::Call(_) => return None,
            Statement::Cycle(_) | Statement::Deferred(_) => n += 1,
            Statement::EndPgm { .. } | Statement::Stop(_) => break,
            Statement::Other(code) if ends_program(code) => break,
            _ => {}
        }
    }
    // Blocks after the end (subprograms) run only when called: there are no calls.
    Some(n)
}

/// The remanent parameters of the machine, as `run` and `check` start with them.
pub fn start_params(remanent: &BTreeMap<QName, f64>) -> QParams {
    let mut p = QParams::new();
    for (n, v) in remanent {
        p.preset(*n, QValue::Number(*v));
    }
    p
}

/// Parameters that a measuring cycle writes, as `check` sees them after the cycle;
/// `rotary_targets`: what 451 also writes on this machine (Q120..Q122 with
/// `mStrobeRotAxPos`).
pub fn mark_cycle_results(params: &mut QParams, cycle: u16, rotary_targets: &[QName]) {
    let also = if cycle == 451 { rotary_targets } else { &[] };
    for n in crate::q_params::results_of(cycle)
        .into_iter()
        .chain(also.iter().copied())
    {
        params.mark_measured(n);
    }
    for n in crate::q_params::length_results_of(cycle) {
        params.mark_mm(n);
    }
}
