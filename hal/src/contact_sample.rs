//! The sample every latched contact becomes on its way to the estimator process.
//! `#[repr(C)]` and self-contained so iceoryx2 can move it through shared memory.

use crate::axis::{AxisPositions, MAX_AXES};
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;

/// `flags` bit: positions come from the drives' hardware latch (always set by the
/// CANopen backend; a backend that could only poll would leave it clear).
pub const FLAG_HW_LATCH: u32 = 1 << 0;
/// `flags` bit: this sample ends a run (the estimator closes the run's set).
pub const FLAG_END_OF_RUN: u32 = 1 << 1;
/// `flags` bit: not a contact but a probing move's announcement ([`ProbeWindow`]):
/// `trigger_ns` is when the move starts, `receive_ns` when it ends at the latest.
pub const FLAG_PROBE_WINDOW: u32 = 1 << 2;

/// A probing move about to start, told to the sink by the real-time loop: the
/// receiver may watch for its contact until `end_ns` (same clock as the samples; the
/// estimator uses only the duration, on its own clock).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ProbeWindow {
    pub run_id: u64,
    pub start_ns: u64,
    /// The longest the move can take to its contact or its end, from `start_ns`.
    pub end_ns: u64,
}

impl ProbeWindow {
    pub fn duration_ns(&self) -> u64 {
        self.end_ns.saturating_sub(self.start_ns)
    }

    /// The announcement as a sample ([`FLAG_PROBE_WINDOW`]).
    pub fn to_sample(&self) -> ContactSample {
        ContactSample {
            run_id: self.run_id,
            trigger_ns: self.start_ns,
            receive_ns: self.end_ns,
            flags: FLAG_PROBE_WINDOW,
            ..ContactSample::zeroed()
        }
    }

    /// The window a sample announces (`None`: a contact).
    pub fn of_sample(s: &ContactSample) -> Option<Self> {
        (s.flags & FLAG_PROBE_WINDOW != 0).then_some(Self {
            run_id: s.run_id,
            start_ns: s.trigger_ns,
            end_ns: s.receive_ns,
        })
    }
}

#[derive(Clone, Copy, Debug, PartialEq, ZeroCopySend)]
#[type_name("probebridge::ContactSample/2")]
#[repr(C)]
pub struct ContactSample {
    /// Increments by one per sample published by one bridge.
    pub sequence: u64,
    /// Groups samples of one measuring run (one program run, one `probe` call).
    pub run_id: u64,
    /// Trigger instant, ns, monotonic clock of the bridge (virtual in simulation).
    pub trigger_ns: u64,
    /// When the bridge's real-time loop received the latch, ns, same clock.
    pub receive_ns: u64,
    /// When the publisher handed the sample to iceoryx2, ns, the host's monotonic
    /// clock (0: not published over IPC). With `receive_ns` and the estimator's receive
    /// time it splits the software path into the loop's part and the hop's.
    pub publish_ns: u64,
    /// Latched positions: X, Y, Z in mm (stylus ball centre), A, B, C in deg.
    pub positions: [f64; MAX_AXES],
    /// Probing direction, unit vector in machine X/Y/Z.
    pub direction: [f64; 3],
    /// Probing feed, mm/min.
    pub feed: f64,
    /// Which entries of `positions` are valid (bit i = axis i).
    pub axis_mask: u32,
    pub flags: u32,
}

impl ContactSample {
    pub const fn zeroed() -> Self {
        Self {
            sequence: 0,
            run_id: 0,
            trigger_ns: 0,
            receive_ns: 0,
            publish_ns: 0,
            positions: [0.0; MAX_AXES],
            direction: [0.0; 3],
            feed: 0.0,
            axis_mask: 0,
            flags: 0,
        }
    }

    pub fn axis_positions(&self) -> AxisPositions {
        AxisPositions::from_raw(self.positions, self.axis_mask as u8)
    }
}

/// Where the real-time loop hands each contact, in the same cycle as the latch. Called
/// from the real-time thread: implementations must not block and should not allocate
/// (the iceoryx2 publisher in the bridge loans, writes, sends).
pub trait SampleSink: Send {
    /// Publishes one sample. A failure is reported back to the loop, which counts it
    /// and goes on: a lost IPC sample must never stop the machine mid-move.
    fn publish(&mut self, sample: &ContactSample) -> Result<(), SinkError>;

    /// A probing move starts (called once the drives are armed, after the tick's
    /// frames went out): the sink may prepare the contact's publication and tell the
    /// receiver to watch. Must not block either. Default: nothing.
    fn probing_move(&mut self, _window: ProbeWindow) {}
}

/// A sample could not be handed on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SinkError;

/// Discards samples (a bridge with no estimator attached).
pub struct NullSink;

impl SampleSink for NullSink {
    fn publish(&mut self, _sample: &ContactSample) -> Result<(), SinkError> {
        Ok(())
    }
}

impl<S: SampleSink + ?Sized> SampleSink for Box<S> {
    fn publish(&mut self, sample: &ContactSample) -> Result<(), SinkError> {
        (**self).publish(sample)
    }

    fn probing_move(&mut self, window: ProbeWindow) {
        (**self).probing_move(window)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_window_round_trips_through_a_sample_and_a_contact_is_none() {
        let w = ProbeWindow {
            run_id: 4,
            start_ns: 10,
            end_ns: 25,
        };
        assert_eq!(ProbeWindow::of_sample(&w.to_sample()), Some(w));
        assert_eq!(w.duration_ns(), 15);
        assert_eq!(ProbeWindow::of_sample(&ContactSample::zeroed()), None);
    }

    #[test]
    fn layout_is_fixed() {
        // 5 u64 + 6 f64 + 3 f64 + 1 f64 + 2 u32, no padding: the size is part of the
        // IPC contract between bridge and estimator (its type name carries a version).
        assert_eq!(core::mem::size_of::<ContactSample>(), 5 * 8 + 10 * 8 + 8);
        assert_eq!(core::mem::align_of::<ContactSample>(), 8);
    }
}
