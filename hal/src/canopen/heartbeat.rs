//! Heartbeat and boot-up (COB-ID 0x700 + node, one byte: NMT state) and the
//! heartbeat consumer that notices silent nodes.

use super::{check_data, check_node_id, cob_id, frame, DecodeError, InvalidNodeId, NmtState};
use crate::can::CanFrame;

const SERVICE: &str = "heartbeat";

/// Heartbeat frame of `node` in `state`.
pub fn encode(node: u8, state: NmtState) -> CanFrame {
    frame(cob_id::heartbeat_cob(node), &[state as u8])
}

/// The boot-up frame a node sends once on entering pre-operational.
pub fn boot_up(node: u8) -> CanFrame {
    encode(node, NmtState::BootUp)
}

/// Node and state; bit 7 (the node-guarding toggle) is ignored.
pub fn decode(f: &CanFrame) -> Result<(u8, NmtState), DecodeError> {
    let cobid = f.cob_id();
    let super::CobKind::Heartbeat { node } = cob_id::classify(cobid) else {
        return Err(DecodeError::WrongCobId {
            service: SERVICE,
            cob_id: cobid,
        });
    };
    // A remote frame here is a node-guarding request, not a heartbeat.
    check_data(SERVICE, f, 1, 1)?;
    Ok((node, NmtState::try_from(f.data()[0])?))
}

/// What the consumer learned from a frame or from the passing of time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HeartbeatEvent {
    /// The node (re)booted: its configuration is back to defaults.
    BootUp { node: u8 },
    /// The reported NMT state differs from the last one (`old` is `None` for the
    /// first heartbeat seen from this node).
    StateChanged {
        node: u8,
        old: Option<NmtState>,
        new: NmtState,
    },
    /// A heartbeat arrived again after [`HeartbeatEvent::Lost`] was reported.
    Resumed { node: u8, state: NmtState },
    /// A watched node sent nothing for longer than its timeout.
    Lost { node: u8, silent_for_ns: u64 },
}

#[derive(Clone, Copy, Debug)]
struct Slot {
    /// 0 = not watched (CiA 301 0x1016: heartbeat time 0 disables the consumer).
    timeout_ns: u64,
    last_seen_ns: Option<u64>,
    state: Option<NmtState>,
    lost_reported: bool,
}

const EMPTY: Slot = Slot {
    timeout_ns: 0,
    last_seen_ns: None,
    state: None,
    lost_reported: false,
};

/// Heartbeat consumer for node-IDs 1..=127, storage fixed at compile time.
///
/// As CiA 301 specifies, monitoring of a node starts with its first heartbeat: a node
/// that never speaks is the caller's boot timeout, not a heartbeat loss.
#[derive(Clone, Debug)]
pub struct HeartbeatConsumer {
    slots: [Slot; 128],
}

impl Default for HeartbeatConsumer {
    fn default() -> Self {
        Self::new()
    }
}

impl HeartbeatConsumer {
    pub const fn new() -> Self {
        Self {
            slots: [EMPTY; 128],
        }
    }

    /// Watches `node` with `timeout_ns` (0 stops watching). Re-arms the loss report.
    pub fn watch(&mut self, node: u8, timeout_ns: u64) -> Result<(), InvalidNodeId> {
        let s = &mut self.slots[check_node_id(node)? as usize];
        s.timeout_ns = timeout_ns;
        s.lost_reported = false;
        Ok(())
    }

    pub fn unwatch(&mut self, node: u8) -> Result<(), InvalidNodeId> {
        self.watch(node, 0)
    }

    /// Records heartbeats and boot-ups (of any node, watched or not); `None` for other
    /// frames and for heartbeats that repeat the known state.
    pub fn on_frame(&mut self, f: &CanFrame, now_ns: u64) -> Option<HeartbeatEvent> {
        let (node, state) = decode(f).ok()?;
        let s = &mut self.slots[node as usize];
        let old = s.state;
        let was_lost = s.lost_reported;
        s.last_seen_ns = Some(now_ns);
        s.state = Some(state);
        s.lost_reported = false;
        if state == NmtState::BootUp {
            Some(HeartbeatEvent::BootUp { node })
        } else if was_lost {
            Some(HeartbeatEvent::Resumed { node, state })
        } else if old != Some(state) {
            Some(HeartbeatEvent::StateChanged {
                node,
                old,
                new: state,
            })
        } else {
            None
        }
    }

    /// The first watched node whose last heartbeat is older than its timeout and
    /// whose loss was not yet reported. Call in a loop until `None` to get all.
    pub fn check(&mut self, now_ns: u64) -> Option<HeartbeatEvent> {
        for (node, s) in self.slots.iter_mut().enumerate().skip(1) {
            if s.timeout_ns == 0 || s.lost_reported {
                continue;
            }
            let Some(last) = s.last_seen_ns else { continue };
            let silent = now_ns.saturating_sub(last);
            if silent > s.timeout_ns {
                s.lost_reported = true;
                return Some(HeartbeatEvent::Lost {
                    node: node as u8,
                    silent_for_ns: silent,
                });
            }
        }
        None
    }

    /// Last NMT state `node` reported, if any.
    pub fn state(&self, node: u8) -> Option<NmtState> {
        self.slots.get(node as usize).and_then(|s| s.state)
    }

    /// When the last heartbeat of `node` arrived.
    pub fn last_seen_ns(&self, node: u8) -> Option<u64> {
        self.slots.get(node as usize).and_then(|s| s.last_seen_ns)
    }

    /// Whether a loss of `node` is currently reported and not yet resolved.
    pub fn is_lost(&self, node: u8) -> bool {
        self.slots
            .get(node as usize)
            .is_some_and(|s| s.lost_reported)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn toggle_bit_ignored() {
        let f = CanFrame::new(0x705, &[0x85]).unwrap();
        assert_eq!(decode(&f).unwrap(), (5, NmtState::Operational));
        let guard = CanFrame::remote(0x705, 1).unwrap();
        assert!(matches!(
            decode(&guard),
            Err(DecodeError::RemoteFrame { .. })
        ));
    }

    #[test]
    fn events() {
        let mut c = HeartbeatConsumer::new();
        c.watch(5, 100).unwrap();
        assert!(c.watch(0, 100).is_err());
        assert!(c.watch(128, 100).is_err());
        assert_eq!(
            c.on_frame(&boot_up(5), 0),
            Some(HeartbeatEvent::BootUp { node: 5 })
        );
        assert_eq!(
            c.on_frame(&encode(5, NmtState::PreOperational), 10),
            Some(HeartbeatEvent::StateChanged {
                node: 5,
                old: Some(NmtState::BootUp),
                new: NmtState::PreOperational
            })
        );
        assert_eq!(c.on_frame(&encode(5, NmtState::PreOperational), 20), None);
        assert_eq!(c.check(120), None);
        assert!(c.check(121).is_some());
        assert_eq!(
            c.on_frame(&encode(5, NmtState::PreOperational), 130),
            Some(HeartbeatEvent::Resumed {
                node: 5,
                state: NmtState::PreOperational
            })
        );
        assert!(!c.is_lost(5));
    }
}
