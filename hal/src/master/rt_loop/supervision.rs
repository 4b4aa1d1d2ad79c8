//! Supervision: heartbeats, EMCYs, fault bits and transport failures fault the
//! machine and stop everything.

use super::{Activity, RtLoop};
use crate::canopen::heartbeat::HeartbeatEvent;
use crate::cia402::statusword::Statusword;
use crate::contact_sample::SampleSink;
use crate::machine::ErrorKind;
use crate::master::command::{Detail, Reply, RtError};

impl<S: SampleSink> RtLoop<S> {
    /// A fault stops everything: brake any motion, answer the command with `err`, and
    /// refuse motion from now on.
    pub(super) fn set_fault(&mut self, err: RtError) {
        if self.fault.is_some() {
            return;
        }
        self.fault = Some(err);
        self.contact = None;
        self.disarm_all();
        self.halt_spindle();
        match self.activity {
            Activity::Moving { profile, t } | Activity::Probing { profile, t, .. } => {
                self.begin_stop(profile, t, Reply::Error(err));
            }
            Activity::Stopping { profile, t, .. } => {
                self.activity = Activity::Stopping {
                    profile,
                    t,
                    then: Reply::Error(err),
                };
            }
            Activity::Arming { .. }
            | Activity::Settling { .. }
            | Activity::Enabling { .. }
            | Activity::Orienting { .. } => {
                self.reply = Some(Reply::Error(err));
                self.activity = Activity::Idle;
            }
            Activity::Idle | Activity::Shutdown => {}
        }
    }

    /// The transport failed (bus-off, overrun, socket error): frames may be lost in
    /// both directions, so stop everything as for a drive fault; the braking setpoints
    /// go out as soon as the transport takes frames again.
    pub fn transport_failed(&mut self) {
        self.set_fault(RtError::new(ErrorKind::Bus, Detail::Transport));
    }

    /// Supervision: a node whose heartbeat is missing, or a drive showing the fault
    /// bit (EMCYs are handled as they arrive), faults the machine.
    pub fn supervise(&mut self) {
        if let Some(HeartbeatEvent::Lost {
            node,
            silent_for_ns,
        }) = self.heartbeat.check(self.supervised_ns)
        {
            self.set_fault(
                RtError::new(
                    ErrorKind::NodeLost,
                    Detail::HeartbeatLost {
                        silent_ms: silent_for_ns as f64 / 1e6,
                    },
                )
                .node(node),
            );
        }
        if matches!(self.activity, Activity::Enabling { .. }) {
            return;
        }
        // The axes' drives, then the spindle's: (node, seen, statusword, last EMCY).
        let faulted = self
            .drives
            .iter()
            .map(|d| (d.node, d.seen_tpdo1, d.statusword, d.last_emcy))
            .chain(
                self.spindle
                    .map(|s| (s.node, s.seen_tpdo1, s.statusword, s.last_emcy)),
            )
            .find(|&(_, seen, sw, _)| seen && sw & Statusword::FAULT != 0);
        if let Some((node, _, _, code)) = faulted {
            let mut err = RtError::new(ErrorKind::DriveFault, Detail::FaultBit).node(node);
            err.code = code;
            self.set_fault(err);
        }
    }
}
