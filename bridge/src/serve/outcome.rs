//! How a request is answered and how a run ends, in the PLC's registers' values: the
//! reason of a refusal, the reason of an abort, the error kinds, and the outcome of a
//! run. Every face reports these (the OPC UA face as `Reason` and its text).

use crate::history::RunStatus;

/// Why a request was refused (the reason register).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u16)]
pub enum Refusal {
    /// A measurement is running.
    Busy = 1,
    /// The request code is none of start, abort, acknowledge.
    UnknownCode = 2,
    /// No program NNN.h in the program folder.
    UnknownProgram = 3,
    /// The program does not parse or does not fit the machine (nothing moved).
    InvalidProgram = 4,
    /// The last run ended in an error: acknowledge it first.
    ErrorPending = 5,
    /// Abort without a running measurement.
    NotBusy = 6,
    /// Flags with unknown bits, or a parameter that is not a finite number.
    BadRequest = 7,
    /// The machine is not up.
    MachineNotReady = 8,
    /// The run's `running` row could not be written (nothing moved).
    HistoryUnavailable = 9,
}

impl Refusal {
    /// The reason in words, as the README's reason table says it.
    pub fn describe(self) -> &'static str {
        match self {
            Refusal::Busy => "a measurement is running",
            Refusal::UnknownCode => "unknown request code",
            Refusal::UnknownProgram => "no such program in the program folder",
            Refusal::InvalidProgram => "the program does not parse or does not fit the machine",
            Refusal::ErrorPending => "the last run ended in an error: acknowledge it first",
            Refusal::NotBusy => "no measurement is running",
            Refusal::BadRequest => "a parameter is not a finite number",
            Refusal::MachineNotReady => "the machine is not up",
            Refusal::HistoryUnavailable => "the run could not be recorded in the history",
        }
    }
}

/// Why a running measurement was aborted (the error kind register).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum AbortReason {
    Request = 1,
    PlcHeartbeat = 2,
    Shutdown = 3,
}

impl AbortReason {
    pub fn from_u8(v: u8) -> Option<Self> {
        match v {
            1 => Some(Self::Request),
            2 => Some(Self::PlcHeartbeat),
            3 => Some(Self::Shutdown),
            _ => None,
        }
    }
    pub fn describe(self) -> &'static str {
        match self {
            AbortReason::Request => "abort requested by the PLC",
            AbortReason::PlcHeartbeat => "PLC heartbeat lost",
            AbortReason::Shutdown => "gateway shutting down",
        }
    }
    /// The error kind register value.
    pub fn error_kind(self) -> u16 {
        match self {
            AbortReason::Request => ERROR_KIND_ABORT_REQUEST,
            AbortReason::PlcHeartbeat => ERROR_KIND_PLC_HEARTBEAT,
            AbortReason::Shutdown => ERROR_KIND_SHUTDOWN,
        }
    }
}

/// Error kind register values: 1..=10 are the machine's `hal::ErrorKind`s (see
/// [`machine_error_kind`]), these are the gateway's.
pub const ERROR_KIND_ABORT_REQUEST: u16 = 20;
pub const ERROR_KIND_PLC_HEARTBEAT: u16 = 21;
pub const ERROR_KIND_SHUTDOWN: u16 = 22;
/// The run ended but its end could be kept neither in the history nor in the spool:
/// its results are not shown.
pub const ERROR_KIND_NOT_KEPT: u16 = 23;
/// A cycle failed without a machine error (its own checks, tolerance stop, Q309).
pub const ERROR_KIND_CYCLE: u16 = 30;
/// The program stopped itself with `FN 14: ERROR = n`; the error code register holds n.
pub const ERROR_KIND_PROGRAM: u16 = 31;

pub fn machine_error_kind(k: hal::ErrorKind) -> u16 {
    use hal::ErrorKind::*;
    match k {
        NotTriggered => 1,
        AlreadyDeflected => 2,
        ProbeCollision => 3,
        DriveFault => 4,
        NodeLost => 5,
        Timeout => 6,
        SoftwareLimit => 7,
        Bus => 8,
        InvalidRequest => 9,
        _ => 10,
    }
}

/// How a run ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    Done,
    Error { kind: u16, code: u16 },
    Aborted(AbortReason),
}

impl Outcome {
    /// The run's status in the history: done, error or aborted.
    pub fn history_status(self) -> RunStatus {
        match self {
            Outcome::Done => RunStatus::Done,
            Outcome::Error { .. } => RunStatus::Error,
            Outcome::Aborted(_) => RunStatus::Aborted,
        }
    }
}
