//! The probe's positioning logic shared by the cycles: up to the safe height along the
//! tool axis, across in the working plane, down to the start point; probing moves.
//! Every machine call reports a progress event and maps errors to [`CycleError`]; a
//! contact during a positioning move says which move it was and what to check
//! ([`Leg`]).

use crate::error::CycleError;
use crate::probe_axis::ProbeAxis;
use crate::progress::{ProgressEvent, ProgressSink};
use hal::{AxisPositions, Contact, ErrorKind, Machine, ProbeMove};

/// A positioning move as the operator reads it. The cycle plans it from what the block
/// says (the points, Q320, Q260); where the part is not where the block says, the probe
/// touches it on the way, the axes brake and the cycle stops. The machine knows only
/// where the axes were going: the message must say which move of the cycle it was and
/// what the operator checks.
pub(crate) struct Leg {
    /// The step every message of this move names (`approaching point 2`), as the
    /// planned moves name it.
    pub step: String,
    /// Where the move goes, in the program's coordinates, added to the step on a
    /// contact (`down from the clearance height Q260=+60.0000 to ...`).
    pub route: String,
    /// What to check after a contact on this move (the parameters, the point, the
    /// preset).
    pub check: String,
}

impl Leg {
    /// The first move of a cycle: along the tool axis from where the blocks before it
    /// left the probe to the clearance height Q260 = `q260` (program coordinates).
    pub fn up_to_q260(q260: f64) -> Self {
        Leg {
            step: "moving to the safe height".into(),
            route: format!(
                "along the tool axis from where the probe stood to the clearance height Q260={q260:+.4}"
            ),
            check: "the way from where the blocks before the cycle left the probe to Q260 is not free: check Q260 (a tool-axis coordinate in the active preset, above the part) and those blocks".into(),
        }
    }

    /// This move's error: a contact names the route and what to check.
    fn error<E: hal::machine::Error>(&self, e: &E) -> CycleError {
        contact_names(CycleError::machine(&self.step, e), &self.route, || {
            self.check.clone()
        })
    }
}

/// A positioning move's error `e`: a contact (the probe deflected on the way, or
/// already before it) gets `route` added to its step and what to check (`check`,
/// made only then) added to its message; any other error is returned as it is.
pub(crate) fn contact_names(
    e: CycleError,
    route: &str,
    check: impl FnOnce() -> String,
) -> CycleError {
    match e {
        CycleError::Machine {
            step,
            kind: kind @ (ErrorKind::ProbeCollision | ErrorKind::AlreadyDeflected),
            message,
        } => CycleError::Machine {
            step: format!("{step}, {route}"),
            kind,
            message: format!("{message}; {}", check()),
        },
        other => other,
    }
}

/// `p` (machine X, Y, Z) as a program writes a position: `X+1.0000 Y+2.0000 Z+3.0000`.
pub(crate) fn xyz(p: [f64; 3]) -> String {
    format!("X{:+.4} Y{:+.4} Z{:+.4}", p[0], p[1], p[2])
}

pub(crate) struct Positioner<'a, M: Machine> {
    pub machine: &'a mut M,
    pub axis: ProbeAxis,
    /// Positioning feed (the probe table's FMAX), mm/min.
    pub fmax: f64,
    pub block: u32,
    pub progress: &'a mut ProgressSink<'a>,
}

impl<M: Machine> Positioner<'_, M> {
    fn move_to(&mut self, leg: &Leg, target: AxisPositions) -> Result<(), CycleError> {
        (self.progress)(ProgressEvent::Move {
            block: self.block,
            target,
            feed: self.fmax,
        });
        self.machine
            .move_to(&target, self.fmax)
            .map_err(|e| leg.error(&e))
    }

    /// Only the tool axis moves, to `height`.
    pub fn safe_height(&mut self, height: f64, leg: &Leg) -> Result<(), CycleError> {
        let target = AxisPositions::new().with(self.axis.axis(), height);
        self.move_to(leg, target)
    }

    /// At the current tool-axis height, over `point` (machine XYZ) in the working plane.
    pub fn over(&mut self, point: [f64; 3], leg: &Leg) -> Result<(), CycleError> {
        let [main, minor, _] = self.axis.indices();
        let mut target = AxisPositions::new();
        for i in [main, minor] {
            target.set(hal::Axis::LINEAR[i], point[i]);
        }
        self.move_to(leg, target)
    }

    /// Straight to `point` (machine XYZ).
    pub fn to(&mut self, point: [f64; 3], leg: &Leg) -> Result<(), CycleError> {
        self.move_to(leg, AxisPositions::linear(point))
    }

    pub fn probe(
        &mut self,
        step: &str,
        direction: [f64; 3],
        feed: f64,
        max_distance: f64,
    ) -> Result<Contact, CycleError> {
        let mv = ProbeMove {
            direction,
            feed,
            max_distance,
        };
        (self.progress)(ProgressEvent::Probe {
            block: self.block,
            direction,
            max_distance,
        });
        let contact =
            probe_again_if_lost(self.machine, &mv).map_err(|e| CycleError::machine(step, &e))?;
        (self.progress)(ProgressEvent::Contact {
            block: self.block,
            centre: contact.positions.xyz(),
        });
        Ok(contact)
    }
}

/// A probing move. When the probe touched but the contact's data was lost on its way
/// ([`hal::ErrorKind::ContactLost`]: the machine braked and is fine), back along the
/// path to where the move started, at the probing feed, and probe once more. A second
/// loss, or any other error, is the caller's.
pub(crate) fn probe_again_if_lost<M: Machine + ?Sized>(
    machine: &mut M,
    mv: &ProbeMove,
) -> Result<Contact, M::Error> {
    use hal::machine::Error as _;
    let start = machine.positions()?;
    match machine.probe(mv) {
        Err(e) if e.kind() == hal::ErrorKind::ContactLost => {
            machine.move_to(&start, mv.feed)?;
            machine.probe(mv)
        }
        r => r,
    }
}
