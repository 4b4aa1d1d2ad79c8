//! A bus with exactly two nodes, the master and a simulated machine, where the machine
//! answers inside `transmit`: everything runs in the caller's thread, deterministic,
//! and without allocating (fixed-capacity queue), so a test can count every
//! allocation of the master and the simulation together.

use hal::can::{CanFrame, CanTransport, TransportError, TransportErrorKind};
use sim::machine::SimMachine;
use std::time::Duration;

pub struct Loopback {
    pub machine: SimMachine,
    queue: heapless::Deque<CanFrame, 1024>,
    overrun: bool,
}

impl Loopback {
    /// Powers `machine` on: its boot-ups are the first frames to receive.
    pub fn new(mut machine: SimMachine) -> Self {
        let mut queue = heapless::Deque::new();
        machine.power_on(&mut |f| {
            let _ = queue.push_back(*f);
        });
        Self {
            machine,
            queue,
            overrun: false,
        }
    }
}

impl CanTransport for Loopback {
    fn transmit(&mut self, frame: &CanFrame) -> Result<(), TransportError> {
        let queue = &mut self.queue;
        let overrun = &mut self.overrun;
        self.machine.on_frame(frame, &mut |r| {
            if queue.push_back(*r).is_err() {
                *overrun = true;
            }
        });
        Ok(())
    }

    fn receive(&mut self, _timeout: Duration) -> Result<Option<CanFrame>, TransportError> {
        if self.overrun {
            return Err(TransportError::new(
                TransportErrorKind::Overrun,
                "loopback queue full",
            ));
        }
        Ok(self.queue.pop_front())
    }
}
