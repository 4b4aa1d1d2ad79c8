//! The operator's stop request (a signal, a stop button, a PLC's abort): a flag that a
//! signal handler may raise (one atomic read-modify-write, async-signal-safe) and every
//! blocking wait of a backend polls, so a move in progress is braked instead of waited
//! out.
//!
//! The flag is re-armable, for a gateway that must measure again after an abort: the
//! owner of the machine clears it once the command it cut short has returned (the axes
//! are then at rest and the drives enabled). Every re-arm starts a new generation, and
//! [`AbortFlag::raise_in`] raises only within the generation it names, so an abort meant
//! for one measurement cannot hit the next one.

use std::sync::atomic::{AtomicU64, Ordering};

/// Bit 0 of the state: raised. The bits above it: the generation.
const RAISED: u64 = 1;

/// A shared stop request. `Copy`: backends keep it in their options.
#[derive(Clone, Copy, Debug)]
pub struct AbortFlag(&'static AtomicU64);

impl AbortFlag {
    /// The flag behind `state` (a `static` initialised to 0, which a signal handler can
    /// reach).
    pub const fn new(state: &'static AtomicU64) -> Self {
        Self(state)
    }

    /// A fresh flag of its own (tests, embedding): leaks one `AtomicU64`.
    pub fn fresh() -> Self {
        Self(Box::leak(Box::new(AtomicU64::new(0))))
    }

    /// Raises the flag in whatever generation is current (a signal handler).
    pub fn raise(&self) {
        self.0.fetch_or(RAISED, Ordering::AcqRel);
    }

    /// Raises the flag only if it is still in `generation` (see [`Self::generation`]);
    /// false when it was re-armed since, i.e. the abort is stale.
    pub fn raise_in(&self, generation: u64) -> bool {
        let armed = generation << 1;
        match self
            .0
            .compare_exchange(armed, armed | RAISED, Ordering::AcqRel, Ordering::Acquire)
        {
            Ok(_) => true,
            Err(now) => now == armed | RAISED,
        }
    }

    pub fn is_raised(&self) -> bool {
        self.0.load(Ordering::Acquire) & RAISED != 0
    }

    /// The current generation (it changes at every [`Self::rearm`]).
    pub fn generation(&self) -> u64 {
        self.0.load(Ordering::Acquire) >> 1
    }

    /// Clears the flag and starts a new generation; returns it. Call it only when no
    /// command is under way (the command the abort cut short has returned): backends
    /// then take commands again.
    pub fn rearm(&self) -> u64 {
        let mut cur = self.0.load(Ordering::Acquire);
        loop {
            let next = ((cur >> 1).wrapping_add(1) << 1) & !RAISED;
            match self
                .0
                .compare_exchange_weak(cur, next, Ordering::AcqRel, Ordering::Acquire)
            {
                Ok(_) => return next >> 1,
                Err(now) => cur = now,
            }
        }
    }
}

/// The error of a command refused or cut short by the stop request.
pub fn aborted_error(what: &str) -> crate::MachineError {
    crate::MachineError::new(crate::ErrorKind::Aborted, what.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rearm_clears_and_a_stale_abort_misses_the_next_generation() {
        let f = AbortFlag::fresh();
        let g0 = f.generation();
        assert!(!f.is_raised());
        assert!(f.raise_in(g0));
        assert!(f.is_raised());
        // Raised twice in the same generation: still raised, still true.
        assert!(f.raise_in(g0));
        let g1 = f.rearm();
        assert_eq!(g1, g0 + 1);
        assert!(!f.is_raised());
        // The abort meant for the measurement of g0 arrives late: it does nothing.
        assert!(!f.raise_in(g0));
        assert!(!f.is_raised());
        f.raise();
        assert!(f.is_raised());
        assert_eq!(f.generation(), g1);
        f.rearm();
        assert!(!f.is_raised());
    }
}
