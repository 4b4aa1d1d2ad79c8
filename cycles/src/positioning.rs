//! The probe's positioning logic shared by the cycles: up to the safe height along the
//! tool axis, across in the working plane, down to the start point; probing moves.
//! Every machine call reports a progress event and maps errors to [`CycleError`].

use crate::error::CycleError;
use crate::probe_axis::ProbeAxis;
use crate::progress::{ProgressEvent, ProgressSink};
use hal::{AxisPositions, Contact, Machine, ProbeMove};

pub(crate) struct Positioner<'a, M: Machine> {
    pub machine: &'a mut M,
    pub axis: ProbeAxis,
    /// Positioning feed (the probe table's FMAX), mm/min.
    pub fmax: f64,
    pub block: u32,
    pub progress: &'a mut ProgressSink<'a>,
}

impl<M: Machine> Positioner<'_, M> {
    fn move_to(&mut self, step: &str, target: AxisPositions) -> Result<(), CycleError> {
        (self.progress)(ProgressEvent::Move {
            block: self.block,
            target,
            feed: self.fmax,
        });
        self.machine
            .move_to(&target, self.fmax)
            .map_err(|e| CycleError::machine(step, &e))
    }

    /// Only the tool axis moves, to `height`.
    pub fn safe_height(&mut self, height: f64) -> Result<(), CycleError> {
        let target = AxisPositions::new().with(self.axis.axis(), height);
        self.move_to("moving to the safe height", target)
    }

    /// At the current tool-axis height, over `point` (machine XYZ) in the working plane.
    pub fn over(&mut self, point: [f64; 3]) -> Result<(), CycleError> {
        let [main, minor, _] = self.axis.indices();
        let mut target = AxisPositions::new();
        for i in [main, minor] {
            target.set(hal::Axis::LINEAR[i], point[i]);
        }
        self.move_to("positioning in the working plane", target)
    }

    /// Straight to `point` (machine XYZ).
    pub fn to(&mut self, step: &str, point: [f64; 3]) -> Result<(), CycleError> {
        self.move_to(step, AxisPositions::linear(point))
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
