//! Frames in ([`RtLoop::on_frame`]) and the frames of each tick ([`RtLoop::tick`]):
//! setpoints, touch probe functions, the master's heartbeat, SYNC, the goodbye.

use super::{Activity, RtLoop, TickFrames, SHUTDOWN_TICKS};
use crate::can::CanFrame;
use crate::canopen::cob_id::{self, CobKind};
use crate::canopen::emcy::Emcy;
use crate::canopen::heartbeat::{self, HeartbeatEvent};
use crate::canopen::nmt::{self, NmtCommand, NmtState};
use crate::canopen::sync;
use crate::cia402::controlword::Controlword;
use crate::contact_sample::SampleSink;
use crate::machine::ErrorKind;
use crate::master::command::{Detail, RtError};
use crate::master::process_data::{ProcessData, Rpdo1, Rpdo2, Tpdo1, Tpdo2};

impl<S: SampleSink> RtLoop<S> {
    /// One SYNC period at `now_ns` (the time this SYNC goes out): supervise, advance
    /// the motion, and put the setpoints and the SYNC into `out` (cleared first), to be
    /// sent in order.
    pub fn tick(&mut self, now_ns: u64, out: &mut TickFrames) {
        let elapsed = now_ns.saturating_sub(self.sync_ns);
        self.supervised_ns += elapsed.min(2 * self.cfg.period_ns);
        self.sync_ns = now_ns;
        if self.is_shut_down() {
            self.shutdown_ticks = self.shutdown_ticks.saturating_add(1);
            if self.shutdown_ticks > SHUTDOWN_TICKS {
                self.goodbye_frames(out);
                return;
            }
        }
        self.supervise();
        self.interpolate();
        self.sync_frames(out);
        self.stats.cycles += 1;
    }

    /// The end of an orderly shutdown: NMT reset communication to every drive, once.
    /// It returns their communication objects to power-on values, 0x1016 included, so
    /// the drives stop watching the master's heartbeat: an orderly exit is not a lost
    /// master. (A killed master sends nothing; the drives notice and stop.)
    pub(super) fn goodbye_frames(&mut self, out: &mut TickFrames) {
        out.clear();
        if self.shutdown_ticks != SHUTDOWN_TICKS + 1 {
            return;
        }
        for d in &self.drives {
            let _ = out.push(nmt::encode(NmtCommand::ResetCommunication, d.node));
        }
        if let Some(s) = &self.spindle {
            let _ = out.push(nmt::encode(NmtCommand::ResetCommunication, s.node));
        }
    }

    /// The master's heartbeat (state operational) into `out` when it is due at the
    /// tick time: every `master_heartbeat_ns` on the SYNC grid; after a stall, one, not
    /// a burst.
    pub(super) fn heartbeat_frame(&mut self, out: &mut TickFrames) {
        let period = self.cfg.master_heartbeat_ns;
        if period == 0 {
            return;
        }
        let now = self.sync_ns;
        let due = self.heartbeat_due_ns.unwrap_or(now);
        if now < due {
            return;
        }
        let next = due + period;
        self.heartbeat_due_ns = Some(if now >= next { now + period } else { next });
        let _ = out.push(heartbeat::encode(
            self.cfg.master_node,
            NmtState::Operational,
        ));
    }

    /// The driver sent the frames of the last tick at `sent_ns`: the stop latency of a
    /// contact is measured up to here. A probing move that started with this tick is
    /// told to the sink now, so its SYNC did not wait for that.
    pub fn frames_sent(&mut self, sent_ns: u64) {
        if let Some(w) = self.window_due.take() {
            self.sink.probing_move(w);
        }
        if let Some((rx, rx_sync)) = self.stop_pending_since.take() {
            self.stats.last_stop_latency_ns = sent_ns.saturating_sub(rx);
            // SYNC periods between the cycle of the latch and this one (rounded: in real
            // time a SYNC goes out a little off its slot).
            let periods = (self.sync_ns.saturating_sub(rx_sync) as f64 / self.cfg.period_ns as f64)
                .round() as u64;
            self.stats.last_stop_latency_cycles = periods.max(1);
        }
    }

    pub(super) fn drive_index(&self, node: u8) -> Option<usize> {
        self.drives.iter().position(|d| d.node == node)
    }

    fn is_spindle(&self, node: u8) -> bool {
        self.spindle.is_some_and(|s| s.node == node)
    }

    /// A frame from the bus, received at `now_ns`.
    pub fn on_frame(&mut self, f: &CanFrame, now_ns: u64) {
        match cob_id::classify(f.cob_id()) {
            CobKind::Tpdo {
                num: Tpdo1::NUMBER,
                node,
            } => {
                if let (Some(s), Ok(pd)) = (self.spindle.as_mut(), Tpdo1::decode(f)) {
                    if s.node == node {
                        s.statusword = pd.statusword;
                        s.actual_inc = pd.position_actual;
                        s.seen_tpdo1 = true;
                        s.answered = true;
                        s.silent = false;
                        return;
                    }
                }
                if let (Some(i), Ok(pd)) = (self.drive_index(node), Tpdo1::decode(f)) {
                    let d = &mut self.drives[i];
                    d.statusword = pd.statusword;
                    d.actual_inc = pd.position_actual;
                    d.seen_tpdo1 = true;
                    d.answered = true;
                    d.silent = false;
                }
            }
            CobKind::Tpdo {
                num: Tpdo2::NUMBER,
                node,
            } => {
                if let (Some(i), Ok(pd)) = (self.drive_index(node), Tpdo2::decode(f)) {
                    self.on_latch(i, pd, now_ns);
                }
            }
            CobKind::Emcy { node } => {
                let Ok(e) = Emcy::decode(f) else {
                    return;
                };
                if e.error_code == 0 {
                    return;
                }
                // An axis's drive or the spindle's.
                let last = match self.drive_index(node) {
                    Some(i) => Some(&mut self.drives[i].last_emcy),
                    None => self
                        .spindle
                        .as_mut()
                        .filter(|s| s.node == node)
                        .map(|s| &mut s.last_emcy),
                };
                if let Some(last) = last {
                    *last = Some(e.error_code);
                    let mut err = RtError::new(ErrorKind::DriveFault, Detail::Emcy).node(node);
                    err.code = Some(e.error_code);
                    self.set_fault(err);
                }
            }
            CobKind::Heartbeat { .. } => {
                if let Some(HeartbeatEvent::BootUp { node }) =
                    self.heartbeat.on_frame(f, self.supervised_ns)
                {
                    // A drive of ours booted again: its PDO mapping and cycle settings
                    // are back to defaults and it is no longer operational. Nothing it
                    // reports from now on can be trusted.
                    if self.drive_index(node).is_some() || self.is_spindle(node) {
                        self.set_fault(
                            RtError::new(ErrorKind::NodeLost, Detail::Restarted).node(node),
                        );
                    }
                }
            }
            _ => {}
        }
    }

    /// SYNC: every drive's RPDO1 (controlword, setpoint), its RPDO2 when the touch
    /// probe function changed, the master's heartbeat when due, then the SYNC itself,
    /// into `out`.
    pub fn sync_frames(&mut self, out: &mut TickFrames) {
        out.clear();
        let enabled = !matches!(self.activity, Activity::Enabling { .. });
        let shutdown = matches!(self.activity, Activity::Shutdown);
        for d in self.drives.iter_mut() {
            if enabled {
                d.target_inc = d.increments(self.setpoint[d.axis.index()]);
                if !shutdown {
                    d.controlword = Controlword::ENABLE_OPERATION_CMD;
                }
            }
            d.answered = false;
            let rpdo1 = Rpdo1 {
                controlword: d.controlword,
                target_position: d.target_inc,
            };
            // Capacity: two frames per drive (at most MAX_AXES) plus SYNC.
            let _ = out.push(rpdo1.encode(d.node));
            if d.tp_function_sent != Some(d.tp_function) {
                d.tp_function_sent = Some(d.tp_function);
                let rpdo2 = Rpdo2 {
                    touch_probe_function: d.tp_function,
                };
                let _ = out.push(rpdo2.encode(d.node));
            }
        }
        let busy = matches!(
            self.activity,
            Activity::Enabling { .. } | Activity::Orienting { .. } | Activity::Shutdown
        );
        if let Some(s) = self.spindle.as_mut() {
            // Its controlword is the oriented stop's (see `spindle`); its target is
            // the set-point of the last one, or where enabling found it.
            s.answered = false;
            if s.rpdo1_due(busy) {
                let rpdo1 = Rpdo1 {
                    controlword: s.controlword,
                    target_position: s.target_inc,
                };
                let _ = out.push(rpdo1.encode(s.node));
            }
        }
        if core::mem::take(&mut self.nmt_start_due) {
            let _ = out.push(nmt::encode(NmtCommand::Start, 0));
        }
        self.heartbeat_frame(out);
        let _ = out.push(sync::encode());
    }
}
