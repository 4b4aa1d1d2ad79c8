//! The run IDs the bench gives its contacts, which tell the estimator's records of
//! the triggers and of the floors apart.

/// The measured triggers (and the warm-up).
pub(super) const TRIGGER_RUN: u64 = 1;
/// The floors' bare hops, one after each trigger.
pub(super) const FLOOR_RUN: u64 = 2;
/// The hot floors, back to back after the triggers.
pub(super) const HOT_RUN: u64 = 3;
