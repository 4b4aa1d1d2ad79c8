//! A machine that refuses the next motion once the gateway aborts the measurement, and
//! remembers the last machine error for the PLC's error registers. The cycles have no
//! abort hook of their own: every cycle moves only through `move_to` and `probe`, so
//! the abort takes effect at the end of the move under way (the backend leaves the
//! axes stopped after each move) and no further axis moves.

use super::handshake::AbortReason;
use hal::{AxisPositions, Contact, ErrorKind, Machine, MachineError, ProbeMove};
use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::Arc;

pub struct Abortable<'a, M: ?Sized> {
    pub inner: &'a mut M,
    pub abort: Arc<AtomicU8>,
    /// The last error a motion returned (kind, device code).
    pub last_error: Option<(ErrorKind, Option<u16>)>,
}

impl<M: Machine<Error = MachineError> + ?Sized> Abortable<'_, M> {
    fn check(&self) -> Result<(), MachineError> {
        match AbortReason::from_u8(self.abort.load(Ordering::Acquire)) {
            Some(r) => Err(MachineError::new(
                ErrorKind::Other,
                format!("aborted: {}", r.describe()),
            )),
            None => Ok(()),
        }
    }

    fn note<T>(&mut self, r: Result<T, MachineError>) -> Result<T, MachineError> {
        if let Err(e) = &r {
            self.last_error = Some((e.kind, e.code));
        }
        // A motion that ended after the abort does not count either.
        let r = r?;
        self.check()?;
        Ok(r)
    }
}

impl<M: Machine<Error = MachineError> + ?Sized> Machine for Abortable<'_, M> {
    type Error = MachineError;
    fn axes(&self) -> u8 {
        self.inner.axes()
    }
    fn positions(&mut self) -> Result<AxisPositions, MachineError> {
        self.inner.positions()
    }
    fn move_to(&mut self, target: &AxisPositions, feed: f64) -> Result<(), MachineError> {
        self.check()?;
        let r = self.inner.move_to(target, feed);
        self.note(r)
    }
    fn probe(&mut self, mv: &ProbeMove) -> Result<Contact, MachineError> {
        self.check()?;
        let r = self.inner.probe(mv);
        self.note(r)
    }
    fn set_run(&mut self, run_id: u64) {
        self.inner.set_run(run_id);
    }
}
