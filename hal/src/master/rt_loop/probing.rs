//! The state of a probing move as the loop keeps it: the move as commanded, the
//! stage of arming the drives' touch probes, and the contact whose latches are still
//! coming in. `mod.rs` holds them in its activity, `latch` and `motion` act on them.

use crate::axis::{Axis, MAX_AXES};

#[derive(Clone, Copy, Debug)]
pub(super) enum ArmStage {
    Disarm,
    Enable,
    WaitArmed,
}

/// A probing move as commanded.
#[derive(Clone, Copy, Debug)]
pub(super) struct ProbeRequest {
    pub(super) direction: [f64; 3],
    pub(super) feed: f64,
    pub(super) max_distance: f64,
    pub(super) run_id: u64,
}

impl ProbeRequest {
    /// Does the probing move move `axis`? (Only linear axes probe.)
    pub(super) fn moves(&self, axis: Axis) -> bool {
        self.direction.get(axis.index()).is_some_and(|&d| d != 0.0)
    }
}

/// A contact whose stop is under way while latches of moving axes are still to come.
#[derive(Clone, Copy, Debug)]
pub(super) struct PendingContact {
    pub(super) request: ProbeRequest,
    /// The SYNC of the cycle in which the first latch frame arrived.
    pub(super) sync_ns: u64,
    /// Each drive's (actual, setpoint) increments when it arrived: the step of the
    /// period in which the drives latched (the stop changes both afterwards).
    pub(super) step_inc: [(i32, i32); MAX_AXES],
}
