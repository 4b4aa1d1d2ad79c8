//! A [`Machine`] that passes every call on and keeps what was asked and how it ended:
//! the detector of I1 (a positioning move that ended in a contact, and anything that
//! moved after it) and of "refused before the first move" (I2, I3), on every backend.
//! It holds every move against the machine's motion guard first, as every real
//! backend does (the world machine has none), so a move outside the software limits
//! fails here as it would on the machine.

use hal::motion_guard::MotionGuard;
use hal::{AxisPositions, Contact, ErrorKind, Machine, MachineError, ProbeMove};

/// One motion request.
#[derive(Clone, Debug, PartialEq)]
pub struct Act {
    /// A probing move (else a positioning move).
    pub probing: bool,
    /// How it failed.
    pub failed: Option<ErrorKind>,
}

pub struct Recorder<M> {
    pub inner: M,
    pub acts: Vec<Act>,
    guard: MotionGuard,
}

impl<M> Recorder<M> {
    pub fn new(inner: M, guard: MotionGuard) -> Self {
        Self {
            inner,
            acts: Vec::new(),
            guard,
        }
    }
}

impl<M: Machine<Error = MachineError>> Machine for Recorder<M> {
    type Error = MachineError;

    fn axes(&self) -> u8 {
        self.inner.axes()
    }

    fn positions(&mut self) -> Result<AxisPositions, MachineError> {
        self.inner.positions()
    }

    fn move_to(&mut self, target: &AxisPositions, feed: f64) -> Result<(), MachineError> {
        let here = self.inner.positions()?;
        let r = self
            .guard
            .check_move_from(&here, target, feed)
            .and_then(|()| self.inner.move_to(target, feed));
        self.acts.push(Act {
            probing: false,
            failed: r.as_ref().err().map(hal::machine::Error::kind),
        });
        r
    }

    fn probe(&mut self, mv: &ProbeMove) -> Result<Contact, MachineError> {
        let here = self.inner.positions()?;
        let r = self
            .guard
            .check_probe(&here, mv)
            .and_then(|_| self.inner.probe(mv));
        self.acts.push(Act {
            probing: true,
            failed: r.as_ref().err().map(hal::machine::Error::kind),
        });
        r
    }

    fn set_run(&mut self, run_id: u64) {
        self.inner.set_run(run_id);
    }

    fn clock_ns(&mut self) -> u64 {
        self.inner.clock_ns()
    }

    fn health(&mut self) -> Result<(), MachineError> {
        self.inner.health()
    }

    fn orient_spindle(&mut self, angle_deg: f64) -> Result<bool, MachineError> {
        self.inner.orient_spindle(angle_deg)
    }
}
