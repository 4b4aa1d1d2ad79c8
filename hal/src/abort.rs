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
