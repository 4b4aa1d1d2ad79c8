//! The operator's stop request (a signal, a stop button): a flag that a signal handler
//! may raise (one atomic store, async-signal-safe) and every blocking wait of a
//! backend polls, so a move in progress is braked instead of waited out.

use std::sync::atomic::{AtomicBool, Ordering};

/// A shared stop request. `Copy`: backends keep it in their options.
#[derive(Clone, Copy, Debug)]
pub struct AbortFlag(&'static AtomicBool);

impl AbortFlag {
    /// The flag behind `flag` (a `static`, which a signal handler can reach).
    pub const fn new(flag: &'static AtomicBool) -> Self {
        Self(flag)
    }

    /// A fresh flag of its own (tests, embedding): leaks one `AtomicBool`.
    pub fn fresh() -> Self {
        Self(Box::leak(Box::new(AtomicBool::new(false))))
    }

    pub fn raise(&self) {
        self.0.store(true, Ordering::Release);
    }

    pub fn is_raised(&self) -> bool {
        self.0.load(Ordering::Acquire)
    }
}

/// The error of a command refused or cut short by the stop request.
pub fn aborted_error(what: &str) -> crate::MachineError {
    crate::MachineError::new(crate::ErrorKind::Aborted, what.to_string())
}

/// A backend whose waits do not poll the flag themselves (Modbus, where the PLC owns
/// the motion): no move starts once the flag is raised, and a move that ends after it
/// is reported as aborted, so a cycle never goes on after the operator's stop.
pub struct AbortGate<M> {
    pub inner: M,
    pub flag: AbortFlag,
}

impl<M: crate::Machine<Error = crate::MachineError>> AbortGate<M> {
    fn check(&self) -> Result<(), crate::MachineError> {
        if self.flag.is_raised() {
            Err(aborted_error("stop requested; no further motion"))
        } else {
            Ok(())
        }
    }
}

impl<M: crate::Machine<Error = crate::MachineError>> crate::Machine for AbortGate<M> {
    type Error = crate::MachineError;

    fn axes(&self) -> u8 {
        self.inner.axes()
    }

    fn positions(&mut self) -> Result<crate::AxisPositions, Self::Error> {
        self.inner.positions()
    }

    fn move_to(&mut self, target: &crate::AxisPositions, feed: f64) -> Result<(), Self::Error> {
        self.check()?;
        self.inner.move_to(target, feed)?;
        self.check()
    }

    fn probe(&mut self, mv: &crate::ProbeMove) -> Result<crate::Contact, Self::Error> {
        self.check()?;
        let c = self.inner.probe(mv)?;
        self.check()?;
        Ok(c)
    }

    fn set_run(&mut self, run_id: u64) {
        self.inner.set_run(run_id);
    }
}
