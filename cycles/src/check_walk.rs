//! The walk `check` makes through a program: every way a condition on a measured
//! result can go, each path's state fingerprinted so that a loop is walked once.

use crate::datum::Datum;
use crate::program::{Block, Program, Statement};
use crate::program_flow::*;
use crate::q_params::{QName, QParams};

/// A fingerprint of a `check` path's state, so that a loop around a measured
/// condition is walked once.
pub fn fingerprint(flow: &Flow, params: &QParams, extra: &str) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    // Not the jump count: a loop comes back to the same state with more jumps.
    (flow.pc, &flow.returns, &flow.repeats, flow.ending).hash(&mut h);
    format!("{params:?}").hash(&mut h);
    extra.hash(&mut h);
    h.finish()
}

/// The most paths `check` follows beyond the first (each a condition on a measured
/// result, both ways); what lies beyond is checked when the program runs.
pub const MAX_CHECK_PATHS: usize = 64;

/// One way through the program as `check` follows it.
#[derive(Clone, Debug)]
struct CheckPath {
    flow: Flow,
    params: QParams,
    datum: Datum,
    /// Where the blocks before leave the axes on this path (cycle 451 plans its moves
    /// from there).
    here: hal::AxisPositions,
}

/// `check`'s walk over the program: every block as `run` would reach it, with the
/// parameters known before anything moves (constants, values computed from them, the
/// QR values); a jump on a measured result is followed both ways.
pub struct CheckWalk<'p> {
    program: &'p Program,
    current: Option<CheckPath>,
    pending: Vec<CheckPath>,
    seen: std::collections::HashSet<u64>,
    paths: usize,
    /// Which way is walked now: 0 the first, counted up as each other is taken up.
    way: usize,
    /// Q120..Q122 that cycle 451 writes on this machine (`mStrobeRotAxPos`).
    rotary_targets: Vec<QName>,
}

/// A block `check` refuses while walking: its line, kind and why.
#[derive(Clone, Debug, PartialEq)]
pub struct CheckFault {
    pub line: usize,
    pub kind: FlowFaultKind,
    pub message: String,
}

impl<'p> CheckWalk<'p> {
    pub fn new(
        program: &'p Program,
        params: QParams,
        datum: Datum,
        here: hal::AxisPositions,
        max_jumps: u64,
        rotary_targets: Vec<QName>,
    ) -> Self {
        Self {
            program,
            current: Some(CheckPath {
                flow: Flow::new(max_jumps),
                params,
                datum,
                here,
            }),
            pending: Vec::new(),
            seen: std::collections::HashSet::new(),
            paths: 0,
            way: 0,
            rotary_targets,
        }
    }

    /// The next block to check (a move, a cycle, a datum change, ...), `None` when
    /// every path is walked.
    pub fn next_block(&mut self) -> Result<Option<&'p Block>, CheckFault> {
        let program = self.program;
        loop {
            let Some(cur) = self.current.as_mut() else {
                match self.pending.pop() {
                    Some(p) => {
                        self.current = Some(p);
                        self.way += 1;
                        continue;
                    }
                    None => return Ok(None),
                }
            };
            let fault = |stop: FlowStop| match stop {
                FlowStop::Fault {
                    line,
                    kind,
                    message,
                } => Some(CheckFault {
                    line,
                    kind,
                    message,
                }),
                _ => None,
            };
            match cur.flow.advance(program, &mut cur.params) {
                Ok(Step::Act(i)) => {
                    let b = &program.blocks[i];
                    match &b.statement {
                        Statement::Cycle(c) => {
                            mark_cycle_results(&mut cur.params, c.head.cycle, &self.rotary_targets)
                        }
                        Statement::Deferred(d) => {
                            mark_cycle_results(&mut cur.params, d.cycle, &self.rotary_targets)
                        }
                        _ => {}
                    }
                    return Ok(Some(b));
                }
                // FN 14 is the program's own stop: this path ends there.
                Ok(Step::End) | Err(FlowStop::Error { .. }) => self.current = None,
                Err(FlowStop::Undecided { index, target }) => {
                    let mut taken = cur.clone();
                    if let Err(stop) = taken.flow.decide(program, index, target, true) {
                        if let Some(f) = fault(stop) {
                            return Err(f);
                        }
                    }
                    cur.flow.decide(program, index, target, false).ok();
                    let key = |p: &CheckPath| {
                        fingerprint(&p.flow, &p.params, &format!("{:?}{:?}", p.datum, p.here))
                    };
                    if self.seen.insert(key(&taken)) && self.paths < MAX_CHECK_PATHS {
                        self.paths += 1;
                        self.pending.push(taken);
                    }
                    let fall = key(cur);
                    if !self.seen.insert(fall) {
                        self.current = None;
                    }
                }
                Err(stop) => {
                    if let Some(f) = fault(stop) {
                        return Err(f);
                    }
                    self.current = None;
                }
            }
        }
    }

    /// Which way through the program the blocks come from: 0 the first (where no
    /// condition on a measured value jumps), then one more for each other way.
    pub fn path(&self) -> usize {
        self.way
    }

    /// The datum, the parameters and the axes' positions of the path being walked.
    pub fn state(&mut self) -> (&mut Datum, &QParams, &mut hal::AxisPositions) {
        let cur = self
            .current
            .as_mut()
            .expect("state() is asked after next_block() returned a block");
        (&mut cur.datum, &cur.params, &mut cur.here)
    }

    /// This path goes no further (`run` stops there).
    pub fn end_path(&mut self) {
        self.current = None;
    }
}
