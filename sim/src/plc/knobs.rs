//! What a test can make the simulated PLC (and its Modbus server) do wrong.

use hal::modbus::CaptureKind;
use tokio_modbus::ExceptionCode;

/// Misbehaviour, turned on by a test (shared with the running PLC and server).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Knobs {
    /// How the PLC captures a contact (default: the bus config's `capture`).
    pub capture: Option<CaptureKind>,
    /// The next N requests are answered this late (past the client's timeout), ms.
    pub late_replies: u32,
    pub late_ms: u64,
    /// The first status read after the next command write closes the connection
    /// instead of answering (the client is polling a command the PLC is carrying out).
    pub drop_connection_mid_move: bool,
    /// Set by the server when the command write came in.
    pub drop_armed: bool,
    /// The next N requests are answered with this exception.
    pub exceptions: u32,
    pub exception: Option<ExceptionCode>,
    /// A bouncing stylus: a second edge latched right after the first, without waiting
    /// for the acknowledge (a PLC that re-arms too early).
    pub bounce: bool,
    /// The next contact is followed by this many spurious latches (more than the ring
    /// holds overflows it).
    pub extra_latches: u16,
    /// The program lacks command 5, orient spindle (answers rejected), whatever the
    /// bus configuration says: an integrator who did not implement it.
    pub no_orient_spindle: bool,
}

impl Knobs {
    /// Takes one pending exception, if any.
    pub fn take_exception(&mut self) -> Option<ExceptionCode> {
        if self.exceptions == 0 {
            return None;
        }
        self.exceptions -= 1;
        self.exception
    }

    /// Takes one pending late reply: its delay.
    pub fn take_late(&mut self) -> Option<u64> {
        if self.late_replies == 0 {
            return None;
        }
        self.late_replies -= 1;
        Some(self.late_ms)
    }
}
