//! The heartbeat (CiA 301): the producer (0x1017) on the drive's clock, and the
//! consumer (0x1016) that notices when the master falls silent.

use super::{HeartbeatLoss, SimDrive};
use hal::can::CanFrame;
use hal::canopen::emcy::code as emcy_code;
use hal::canopen::heartbeat;

/// Most a heartbeat consumer's clock advances between two looks, µs. A host looks at
/// least every 50 ms (`SimRunner`), so while it runs the consumer keeps time.
const CONSUMER_LOOK_MAX_US: u64 = 100_000;

impl SimDrive {
    /// 0x1016:1 as (node, consumer time ms).
    pub(super) fn watched(&self) -> (u8, u16) {
        let v = self.od.comm.heartbeat_consumer;
        (((v >> 16) & 0x7F) as u8, v as u16)
    }

    /// A heartbeat (or boot-up) of `node`: if it is the watched one, it is alive; a
    /// reported loss is over (EMCY 0000).
    pub(super) fn on_heartbeat(&mut self, node: u8) {
        self.restart_consumer_if_written();
        let (watched, ms) = self.watched();
        if ms == 0 || node != watched {
            return;
        }
        self.consumer.seen_us = Some(self.consumer.clock_us);
        self.consumer.lost = false;
        if self.od.heartbeat_lost {
            self.od.heartbeat_lost = false;
            // Error reset, unless a fault (0x6007 = 1) outlives the cause.
            if self.od.app.fault.is_none() {
                self.od.push_emcy(emcy_code::NO_ERROR);
            }
        }
    }

    /// 0x1016 was written (or reset): nothing is watched until the first heartbeat.
    pub(super) fn restart_consumer_if_written(&mut self) {
        if self.od.consumer_restart {
            self.od.consumer_restart = false;
            self.consumer.seen_us = None;
            self.consumer.lost = false;
        }
    }

    /// The consumer looks at the time: the watched node silent for longer than the
    /// consumer time is a heartbeat event (CiA 301): EMCY 0x8130, then the reaction
    /// of 0x6007.
    pub(super) fn consume_heartbeat(&mut self) {
        self.restart_consumer_if_written();
        let (node, ms) = self.watched();
        let c = &mut self.consumer;
        let step = c.looked_at_us.map_or(0, |t| self.now_us.saturating_sub(t));
        c.looked_at_us = Some(self.now_us);
        c.clock_us += step.min(u64::from(ms) * 500).min(CONSUMER_LOOK_MAX_US);
        let Some(seen) = c.seen_us else { return };
        let silent_us = c.clock_us - seen;
        if ms == 0 || c.lost || silent_us <= u64::from(ms) * 1000 {
            return;
        }
        c.lost = true;
        let from = self.od.app.state;
        self.od.heartbeat_lost = true;
        self.abort_connection();
        self.heartbeat_loss = Some((
            HeartbeatLoss {
                node,
                consumer_ms: ms,
                silent_us,
                at_us: self.now_us,
                from,
                to: self.od.app.state,
            },
            false,
        ));
    }

    /// The last loss of the watched heartbeat (0x1016), if any.
    pub fn heartbeat_loss(&self) -> Option<HeartbeatLoss> {
        self.heartbeat_loss.map(|(l, _)| l)
    }

    /// A loss not taken before (for the host's log), once.
    pub fn take_heartbeat_loss(&mut self) -> Option<HeartbeatLoss> {
        match &mut self.heartbeat_loss {
            Some((l, taken @ false)) => {
                *taken = true;
                Some(*l)
            }
            _ => None,
        }
    }

    pub(super) fn produce_heartbeat(&mut self, tx: &mut dyn FnMut(&CanFrame)) {
        let period_us = u64::from(self.od.comm.heartbeat_ms) * 1000;
        if self.od.heartbeat_restart {
            self.od.heartbeat_restart = false;
            self.heartbeat_at_us = Some(self.now_us);
        }
        let Some(last) = self.heartbeat_at_us else {
            return;
        };
        if period_us == 0 || self.now_us < last + period_us {
            return;
        }
        // On the period's grid; after a stall of the host, one heartbeat, not a burst.
        let next = last + period_us;
        self.heartbeat_at_us = Some(if self.now_us >= next + period_us {
            self.now_us
        } else {
            next
        });
        tx(&heartbeat::encode(self.od.node, self.nmt));
    }
}
