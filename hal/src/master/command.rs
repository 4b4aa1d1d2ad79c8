//! What the blocking `Machine` side asks of the real-time loop, and what it answers.
//! All `Copy`: passed through bounded channels without allocating in the loop.

use crate::axis::MAX_AXES;
use crate::contact_sample::ContactSample;
use crate::machine::{ErrorKind, MachineError};

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Command {
    /// Straight line to `target` (axes outside `mask` keep their position).
    MoveTo {
        target: [f64; MAX_AXES],
        mask: u8,
        feed: f64,
    },
    /// Probing move from the current position.
    Probe {
        direction: [f64; 3],
        feed: f64,
        max_distance: f64,
        run_id: u64,
    },
    /// An oriented spindle stop at `angle_deg` (modulo 360°); the axes hold.
    OrientSpindle { angle_deg: f64 },
    /// Current actual positions.
    Positions,
    /// Brake the motion under way (if any) and fail its command as aborted; the drives
    /// stay enabled and the loop takes commands. Accepted while busy.
    Stop,
    /// Stop the loop (axes held, drives disabled).
    Shutdown,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Reply {
    /// Drives are in Operation enabled and the loop takes commands.
    Ready {
        positions: [f64; MAX_AXES],
    },
    /// Motion finished; actual positions.
    Done {
        positions: [f64; MAX_AXES],
    },
    Contact(ContactSample),
    Error(RtError),
}

/// Why a command failed, without allocating; turned into a [`MachineError`] on the
/// caller's side.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RtError {
    pub kind: ErrorKind,
    pub node: Option<u8>,
    pub code: Option<u16>,
    pub detail: Detail,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Detail {
    NotTriggered {
        distance: f64,
    },
    /// The probing move was to start with the probe signal high, at `at` (machine
    /// X, Y, Z).
    Deflected {
        at: [f64; 3],
    },
    /// A positioning move was to start from `at` with the stylus in contact, other
    /// than straight out of it.
    DeflectedBeforeMove {
        at: [f64; 3],
    },
    Collision,
    Emcy,
    FaultBit,
    HeartbeatLost {
        silent_ms: f64,
    },
    NotInPosition {
        axis: u8,
        error: f64,
    },
    NotEnabled {
        state: u16,
        waited_ms: f64,
    },
    /// Touch probe 1 of the node did not report armed within `waited_ms` of loop
    /// time, after `enables` touch probe functions sent; `status`: the last touch
    /// probe status (0x60B9) it reported since the last one, `None` if none came.
    ArmTimeout {
        waited_ms: f64,
        enables: u32,
        status: Option<u16>,
    },
    Transport,
    Busy,
    Stopped,
    Aborted,
    /// The node sent a boot-up: it restarted and lost its configuration.
    Restarted,
    /// The probe signal stopped the axes, but this moving axis's latch frame never
    /// came (lost on the bus): no contact is measured from the others alone.
    LatchLost,
    /// An oriented stop on a machine configured without a spindle drive.
    NoSpindle,
    /// An oriented stop at an angle that is not a number.
    InvalidAngle,
    /// An oriented stop with the stylus in contact.
    SpindleDeflected,
    /// The spindle did not stand at `to_deg` in time (it stood at `at_deg`);
    /// `acknowledged`: the drive had taken the set-point.
    NotOriented {
        to_deg: f64,
        at_deg: f64,
        acknowledged: bool,
    },
}

impl RtError {
    pub fn new(kind: ErrorKind, detail: Detail) -> Self {
        Self {
            kind,
            node: None,
            code: None,
            detail,
        }
    }

    pub fn node(mut self, node: u8) -> Self {
        self.node = Some(node);
        self
    }
}

impl From<RtError> for MachineError {
    fn from(e: RtError) -> Self {
        let message = match e.detail {
            Detail::NotTriggered { distance } => {
                format!("no contact within {distance:.3} mm; axes stopped at the end of the path")
            }
            Detail::Deflected { at } => crate::motion_guard::deflected_before_probing(at),
            Detail::DeflectedBeforeMove { at } => crate::motion_guard::deflected_before_move(at),
            Detail::Collision => {
                "the stylus touched something while positioning; all axes braked. Retract away from the contact".into()
            }
            Detail::Emcy => "emergency message received; all axes stopped".into(),
            Detail::FaultBit => "statusword reports Fault; all axes stopped".into(),
            Detail::HeartbeatLost { silent_ms } => {
                format!("no heartbeat for {silent_ms:.0} ms; all axes stopped")
            }
            Detail::NotInPosition { axis, error } => format!(
                "axis {} did not reach its position (error {error:.4}); axes stopped",
                crate::Axis::from_index(axis as usize).map_or("?", |a| a.name())
            ),
            Detail::NotEnabled { state, waited_ms } => format!(
                "drive did not reach Operation enabled in {waited_ms:.0} ms (statusword 0x{state:04X}: {})",
                crate::cia402::state::State::from_statusword(state)
                    .map_or_else(|| "no valid state".to_string(), |s| format!("{s:?}"))
            ),
            Detail::ArmTimeout {
                waited_ms,
                enables,
                status,
            } => {
                let node = e.node.unwrap_or(0);
                let answer = match status {
                    None => "no touch probe status (TPDO2) came since the last".to_string(),
                    Some(s) => {
                        let st = crate::cia402::touch_probe::TouchProbeStatus::from_bits(s);
                        let probe = crate::cia402::touch_probe::Probe::One;
                        format!(
                            "its touch probe status 0x{s:04X} (probe 1 {}, {}) answered the last",
                            if st.enabled(probe) { "enabled" } else { "disabled" },
                            if st.positive_edge_stored(probe) {
                                "an edge stored"
                            } else {
                                "no edge stored"
                            }
                        )
                    }
                };
                format!(
                    "touch probe 1 of node {node} did not report armed in {waited_ms:.0} ms: {answer} of {enables} enables sent; nothing moved"
                )
            }
            Detail::Transport => "CAN transport failed; all axes stopped".into(),
            Detail::Busy => "a command is already running".into(),
            Detail::Stopped => "the real-time loop has stopped".into(),
            Detail::Aborted => "stop requested; all axes braked".into(),
            Detail::Restarted => format!(
                "node {} restarted (boot-up received): its configuration is lost; all axes stopped",
                e.node.unwrap_or(0)
            ),
            Detail::NoSpindle => {
                "this machine has no spindle drive ([spindle] in the machine configuration)".into()
            }
            Detail::InvalidAngle => "the spindle angle is not a number; nothing moved".into(),
            Detail::SpindleDeflected => {
                "the stylus is in contact: the spindle is not turned with it deflected; retract first".into()
            }
            Detail::NotOriented {
                to_deg,
                at_deg,
                acknowledged,
            } => {
                if acknowledged {
                    format!("the spindle did not reach {to_deg:.3}° in time (it stands at {at_deg:.3}°); it was halted")
                } else {
                    format!("the spindle drive did not acknowledge the set-point {to_deg:.3}° (statusword bit 12; profile position mode 0x6060 = 1?); it was halted at {at_deg:.3}°")
                }
            }
            Detail::LatchLost => format!(
                "the probe signal stopped the axes, but the latch frame of node {} did not arrive (lost on the bus); no contact measured",
                e.node.unwrap_or(0)
            ),
        };
        let mut m = MachineError::new(e.kind, message);
        m.node = e.node;
        m.code = e.code;
        m
    }
}
