//! A machine that times every call on the machine's own clock and books it to the
//! part of the split it belongs to: what the runner hands each cycle.

use super::{moves_linear, TimeSplit};
use hal::{AxisPositions, Contact, Machine, ProbeMove};
use std::cell::Cell;
use std::rc::Rc;

#[derive(Clone, Copy, Debug, Default)]
struct Booked {
    start_ns: u64,
    /// Standing is not booked: it is what the clock says beyond the moves.
    moving: TimeSplit,
}

/// What a [`TimedMachine`] has booked, readable while it runs: the cycle reads it for
/// its measuring log ([`crate::cycle::CycleContext::machine_time`]).
#[derive(Clone, Debug, Default)]
pub struct TimeLedger(Rc<Cell<Booked>>);

impl TimeLedger {
    /// The split from the start up to `now_ns` on the machine's clock.
    pub fn split_at(&self, now_ns: u64) -> TimeSplit {
        let b = self.0.get();
        let total = elapsed_s(b.start_ns, now_ns);
        let m = b.moving;
        TimeSplit {
            standing: (total - m.positioning - m.rotary - m.probing).max(0.0),
            ..m
        }
    }

    fn book(&self, part: fn(&mut TimeSplit) -> &mut f64, seconds: f64) {
        let mut b = self.0.get();
        *part(&mut b.moving) += seconds;
        self.0.set(b);
    }
}

/// Forwards every call to `inner` and books its time; see the module doc.
pub struct TimedMachine<'a, M: Machine + ?Sized> {
    inner: &'a mut M,
    ledger: TimeLedger,
    /// Where the axes were last seen or sent (to tell a rotary move from a linear one
    /// without asking the machine, which would cost time of its own).
    last: Option<AxisPositions>,
}

impl<'a, M: Machine + ?Sized> TimedMachine<'a, M> {
    /// Starts the clock now.
    pub fn new(inner: &'a mut M) -> Self {
        let start_ns = inner.clock_ns();
        TimedMachine {
            inner,
            ledger: TimeLedger(Rc::new(Cell::new(Booked {
                start_ns,
                moving: TimeSplit::default(),
            }))),
            last: None,
        }
    }

    /// The split up to now: the time no call accounts for is standing.
    pub fn split(&mut self) -> TimeSplit {
        self.ledger.split_at(self.inner.clock_ns())
    }

    /// A reader of what is booked, for the cycle while it runs.
    pub fn ledger(&self) -> TimeLedger {
        self.ledger.clone()
    }

    /// Runs `call` on the inner machine and books its time to `part`.
    fn timed<T>(
        &mut self,
        part: fn(&mut TimeSplit) -> &mut f64,
        call: impl FnOnce(&mut M) -> T,
    ) -> T {
        let t0 = self.inner.clock_ns();
        let out = call(self.inner);
        let t1 = self.inner.clock_ns();
        self.ledger.book(part, elapsed_s(t0, t1));
        out
    }
}

fn elapsed_s(from_ns: u64, to_ns: u64) -> f64 {
    to_ns.saturating_sub(from_ns) as f64 * 1e-9
}

impl<M: Machine + ?Sized> Machine for TimedMachine<'_, M> {
    type Error = M::Error;

    fn axes(&self) -> u8 {
        self.inner.axes()
    }

    fn positions(&mut self) -> Result<AxisPositions, Self::Error> {
        let p = self.inner.positions()?;
        self.last = Some(p);
        Ok(p)
    }

    fn move_to(&mut self, target: &AxisPositions, feed: f64) -> Result<(), Self::Error> {
        let part: fn(&mut TimeSplit) -> &mut f64 = if moves_linear(self.last.as_ref(), target) {
            |s| &mut s.positioning
        } else {
            |s| &mut s.rotary
        };
        let done = self.timed(part, |m| m.move_to(target, feed));
        self.last = match done {
            Ok(()) => Some(self.last.map_or(*target, |l| l.merged(target))),
            Err(_) => None,
        };
        done
    }

    fn probe(&mut self, mv: &ProbeMove) -> Result<Contact, Self::Error> {
        let contact = self.timed(|s| &mut s.probing, |m| m.probe(mv));
        // The axes stand beyond the contact by the braking distance: not known here.
        self.last = None;
        contact
    }

    fn set_run(&mut self, run_id: u64) {
        self.inner.set_run(run_id);
    }

    fn health(&mut self) -> Result<(), Self::Error> {
        self.inner.health()
    }

    fn orient_spindle(&mut self, angle_deg: f64) -> Result<bool, Self::Error> {
        self.timed(|s| &mut s.rotary, |m| m.orient_spindle(angle_deg))
    }

    fn clock_ns(&mut self) -> u64 {
        self.inner.clock_ns()
    }
}
