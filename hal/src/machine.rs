//! The machine as the measuring cycles see it: blocking moves, probing moves that stop
//! on the probe's hardware latch, and errors with a kind (shaped like embedded-hal).

use crate::axis::AxisPositions;

/// What went wrong, in terms a cycle can react to. Backends map their own failures
/// onto these kinds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum ErrorKind {
    /// The probe did not trigger within the allowed distance.
    NotTriggered,
    /// The probe was already deflected when the probing move was to start.
    AlreadyDeflected,
    /// The probe was deflected during a positioning move (a collision); the axes
    /// were braked.
    ProbeCollision,
    /// A drive reported a fault (EMCY or fault bit in the statusword).
    DriveFault,
    /// A node stopped sending its heartbeat, or never came up.
    NodeLost,
    /// The bus or a device did not answer in time.
    Timeout,
    /// A move would leave an axis's software limits; nothing moved.
    SoftwareLimit,
    /// The transport failed (socket error, bus off, queue overrun).
    Bus,
    /// The probe touched, but the data of the contact was lost on its way (a latch
    /// frame lost on the bus): the axes were braked and the machine is fine, so the
    /// probing move may be made again from where it started.
    ContactLost,
    /// The request itself is invalid (unknown axis, zero direction, bad feed).
    InvalidRequest,
    /// The operator stopped the machine (a signal, a stop request): motion was braked,
    /// or refused before it started.
    Aborted,
    /// Anything else.
    Other,
}

impl ErrorKind {
    pub const fn describe(self) -> &'static str {
        match self {
            ErrorKind::NotTriggered => "probe did not trigger",
            ErrorKind::AlreadyDeflected => "probe already deflected at start",
            ErrorKind::ProbeCollision => "probe deflected during a positioning move",
            ErrorKind::DriveFault => "drive fault",
            ErrorKind::NodeLost => "node lost",
            ErrorKind::Timeout => "timeout",
            ErrorKind::SoftwareLimit => "software limit",
            ErrorKind::Bus => "bus error",
            ErrorKind::ContactLost => "contact lost in transfer",
            ErrorKind::InvalidRequest => "invalid request",
            ErrorKind::Aborted => "aborted",
            ErrorKind::Other => "error",
        }
    }
}

/// Errors of a [`Machine`] implementation.
pub trait Error: core::fmt::Debug + core::fmt::Display {
    fn kind(&self) -> ErrorKind;
}

/// A general-purpose machine error carrying the kind, the node and device error code
/// where known, and a message for the operator.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MachineError {
    pub kind: ErrorKind,
    /// CANopen node ID (or Modbus unit) the error came from, if any.
    pub node: Option<u8>,
    /// Device error code (CiA 402 0x603F / EMCY error code), if any.
    pub code: Option<u16>,
    pub message: String,
}

impl MachineError {
    pub fn new(kind: ErrorKind, message: impl Into<String>) -> Self {
        Self {
            kind,
            node: None,
            code: None,
            message: message.into(),
        }
    }

    pub fn with_node(mut self, node: u8) -> Self {
        self.node = Some(node);
        self
    }

    pub fn with_code(mut self, code: u16) -> Self {
        self.code = Some(code);
        self
    }
}

impl core::fmt::Display for MachineError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{}", self.kind.describe())?;
        if let Some(n) = self.node {
            write!(f, " (node {n}")?;
            if let Some(c) = self.code {
                write!(f, ", error code 0x{c:04X}")?;
            }
            f.write_str(")")?;
        } else if let Some(c) = self.code {
            write!(f, " (error code 0x{c:04X})")?;
        }
        if !self.message.is_empty() {
            write!(f, ": {}", self.message)?;
        }
        Ok(())
    }
}

impl std::error::Error for MachineError {}

impl Error for MachineError {
    fn kind(&self) -> ErrorKind {
        self.kind
    }
}

/// A probing move: from the current position along `direction` (unit vector in machine
/// X/Y/Z) at `feed` mm/min, at most `max_distance` mm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProbeMove {
    pub direction: [f64; 3],
    pub feed: f64,
    pub max_distance: f64,
}

/// A probe contact: the positions of all axes latched by the drives at the instant the
/// probe triggered (the stylus ball centre for X/Y/Z), not a polled position.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Contact {
    pub positions: AxisPositions,
    /// Trigger instant, ns on the bridge's monotonic clock (virtual in simulation).
    pub trigger_ns: u64,
    /// Sequence number of the [`crate::ContactSample`] published for this contact.
    pub sequence: u64,
    /// The probing direction (unit vector).
    pub direction: [f64; 3],
}

/// A machine that cycles can measure with. All calls block until the motion is done.
///
/// Contract every implementation keeps (and the conformance suite checks):
/// - software limits are checked before any motion; a refused move moves nothing;
/// - `probe` checks the probe is not deflected before moving, stops the axes on the
///   latch and returns the latched positions; the axes are left stopped where the stop
///   ended (beyond the contact by the braking distance); retracting is the caller's job;
/// - on any error the axes are stopped.
pub trait Machine {
    type Error: Error;

    /// Axes this machine has (mask over [`crate::Axis::index`]).
    fn axes(&self) -> u8;

    /// Current actual positions of all axes.
    fn positions(&mut self) -> Result<AxisPositions, Self::Error>;

    /// Straight-line move in machine coordinates; all axes arrive together. Axes not in
    /// `target` keep their position. `feed` in mm/min (deg/min for rotary-only moves).
    fn move_to(&mut self, target: &AxisPositions, feed: f64) -> Result<(), Self::Error>;

    /// Probing move from the current position; see [`ProbeMove`].
    fn probe(&mut self, mv: &ProbeMove) -> Result<Contact, Self::Error>;

    /// The samples of the following probing moves belong to run `run_id` (a backend
    /// that publishes [`crate::ContactSample`]s tags them with it, so that an estimator
    /// can tell one measurement from the next). No default: a wrapper that forgot to
    /// forward it would silently drop the tag.
    fn set_run(&mut self, run_id: u64);

    /// Is the machine able to move, without moving it: `Err` when its bus or a drive
    /// has failed (heartbeat lost, emergency, fault, transport or connection lost) and
    /// the backend must be opened again before it can measure. Cheap enough to ask
    /// every few hundred milliseconds between commands. The default reads the
    /// positions.
    fn health(&mut self) -> Result<(), Self::Error> {
        self.positions().map(|_| ())
    }

    /// Turns the spindle to `angle_deg` (an oriented spindle stop) and waits until it
    /// stands there: `Ok(true)`. `Ok(false)`: this machine has no spindle it can
    /// orient, nothing moved (the default); a cycle that needs one (460's stylus
    /// offset) says so.
    fn orient_spindle(&mut self, angle_deg: f64) -> Result<bool, Self::Error> {
        let _ = angle_deg;
        Ok(false)
    }

    /// The machine's own clock, ns: what the cycles' machine time is read from. On
    /// CANopen the time of the last SYNC (SYNCs times the period on a simulator's
    /// virtual clock, so a lockstep run reports the time the machine would have
    /// taken); CLOCK_MONOTONIC where the gateway has no clock of the machine's. No
    /// default: a wrapper that forgot to forward it would report no time.
    fn clock_ns(&mut self) -> u64;
}

/// Forwards every method to the machine behind a pointer (`**self`).
macro_rules! forward_machine {
    ($($pointer:ty),*) => {$(
        impl<M: Machine + ?Sized> Machine for $pointer {
            type Error = M::Error;
            fn axes(&self) -> u8 {
                (**self).axes()
            }
            fn positions(&mut self) -> Result<AxisPositions, Self::Error> {
                (**self).positions()
            }
            fn move_to(&mut self, target: &AxisPositions, feed: f64) -> Result<(), Self::Error> {
                (**self).move_to(target, feed)
            }
            fn probe(&mut self, mv: &ProbeMove) -> Result<Contact, Self::Error> {
                (**self).probe(mv)
            }
            fn set_run(&mut self, run_id: u64) {
                (**self).set_run(run_id)
            }
            fn health(&mut self) -> Result<(), Self::Error> {
                (**self).health()
            }
            fn orient_spindle(&mut self, angle_deg: f64) -> Result<bool, Self::Error> {
                (**self).orient_spindle(angle_deg)
            }
            fn clock_ns(&mut self) -> u64 {
                (**self).clock_ns()
            }
        }
    )*};
}

// A backend behind a box (the CLI holds whichever backend the configuration names),
// or borrowed.
forward_machine!(Box<M>, &mut M);
