//! CAN frames and transports. The CANopen code above works on [`CanFrame`] values and
//! never touches a socket; a transport only moves frames.

pub mod candump;
pub mod fault_injection;
mod frame;
pub mod inproc;
pub mod record;
pub mod socketcan;
pub mod wire_time;

pub use frame::CanFrame;

use core::time::Duration;

/// What failed in a transport.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum TransportErrorKind {
    /// The interface does not exist or could not be opened.
    Open,
    /// A receive queue overflowed; frames were lost.
    Overrun,
    /// The interface went down or reports bus-off.
    BusOff,
    /// The bus this endpoint belonged to was closed.
    Closed,
    /// Any other I/O error.
    Io,
}

#[derive(Debug, thiserror::Error)]
#[error("CAN transport {kind:?}: {message}")]
pub struct TransportError {
    pub kind: TransportErrorKind,
    pub message: String,
}

impl TransportError {
    pub fn new(kind: TransportErrorKind, message: impl Into<String>) -> Self {
        Self {
            kind,
            message: message.into(),
        }
    }
}

/// A CAN interface: send a frame, receive the next frame from other nodes.
pub trait CanTransport: Send {
    /// Queues one frame for transmission.
    fn transmit(&mut self, frame: &CanFrame) -> Result<(), TransportError>;

    /// Next frame from the bus, waiting at most `timeout` (`Duration::ZERO`: do not
    /// wait). `Ok(None)` when none arrived in time.
    fn receive(&mut self, timeout: Duration) -> Result<Option<CanFrame>, TransportError>;

    /// Queues `frames` in order, as one batch (a bus with wire time arbitrates them
    /// together).
    fn transmit_all(&mut self, frames: &[CanFrame]) -> Result<(), TransportError> {
        frames.iter().try_for_each(|f| self.transmit(f))
    }

    /// When the frame last returned by [`Self::receive`] arrived (its last bit), ns, on
    /// the transport's own clock: CLOCK_MONOTONIC, or the virtual clock of a simulated
    /// bus. `None`: the transport does not model it (the receiver stamps the frame).
    fn arrival_ns(&self) -> Option<u64> {
        None
    }

    /// A transport on a virtual clock (a simulated bus with wire time): this
    /// endpoint's now, ns. `None` on a real-time transport.
    fn virtual_now_ns(&self) -> Option<u64> {
        None
    }

    /// On a virtual clock: frames sent from now on leave no earlier than `now_ns`.
    fn advance_virtual_clock(&mut self, _now_ns: u64) {}
}

impl<T: CanTransport + ?Sized> CanTransport for Box<T> {
    fn transmit(&mut self, frame: &CanFrame) -> Result<(), TransportError> {
        (**self).transmit(frame)
    }
    fn receive(&mut self, timeout: Duration) -> Result<Option<CanFrame>, TransportError> {
        (**self).receive(timeout)
    }
    fn transmit_all(&mut self, frames: &[CanFrame]) -> Result<(), TransportError> {
        (**self).transmit_all(frames)
    }
    fn arrival_ns(&self) -> Option<u64> {
        (**self).arrival_ns()
    }
    fn virtual_now_ns(&self) -> Option<u64> {
        (**self).virtual_now_ns()
    }
    fn advance_virtual_clock(&mut self, now_ns: u64) {
        (**self).advance_virtual_clock(now_ns)
    }
}
