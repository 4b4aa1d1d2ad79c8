//! Probe arming (touch probe 1 on every drive, see [`RtLoop::arm`]) and latch
//! collection: the first latch frame starts the stop of every axis, the contact is
//! published once every moving axis's latch is in.

use super::probing::{ArmStage, PendingContact, ProbeRequest};
use super::{Activity, DriveLink, RtLoop};
use crate::axis::MAX_AXES;
use crate::cia402::touch_probe::{Probe, TouchProbeFunction, TouchProbeStatus};
use crate::contact_sample::{ContactSample, ProbeWindow, SampleSink, FLAG_HW_LATCH};
use crate::machine::ErrorKind;
use crate::master::command::{Detail, Reply, RtError};
use crate::master::process_data::Tpdo2;
use crate::motion::Profile;
use crate::motion_guard::ProbeInput;

/// The drive reported touch probe 1 enabled with no edge stored, since it was last
/// enabled.
pub(super) fn is_armed(d: &DriveLink) -> bool {
    let s = TouchProbeStatus::from_bits(d.tp_status);
    d.tp_status_fresh && s.enabled(Probe::One) && !s.positive_edge_stored(Probe::One)
}

impl<S: SampleSink> RtLoop<S> {
    /// Latch handling: a drive's touch probe status (TPDO2). A rising probe signal
    /// while positioning is a collision; an edge stored while probing is this drive's
    /// latch. The first latch frame stops every axis (the probe signal is wired to all
    /// drives: they have all latched); the contact is complete once every moving
    /// axis's latch is in.
    pub(super) fn on_latch(&mut self, i: usize, pd: Tpdo2, now_ns: u64) {
        let d = &mut self.drives[i];
        d.tp_status = pd.touch_probe_status;
        d.tp_status_fresh = true;
        let st = TouchProbeStatus::from_bits(pd.touch_probe_status);
        let level = st.input_level(Probe::One);
        let rising = d.probe_input.update(level);
        // The probe is wired to every drive, so the first rise is the contact; the
        // others may report it after the brake began, or late: a drive's on-change
        // frame (TPDO2) can be lost, leaving its level stale until the next change.
        // So the signal falls only when most drives report it low (a tie keeps it
        // high, the safe side).
        let first = rising && !self.probe_signal;
        if first {
            self.probe_signal = true;
            // The motion that made the contact (see `deflected_move`).
            self.deflected_along = match &self.activity {
                Activity::Moving { profile, .. } | Activity::Probing { profile, .. } => {
                    let dir = profile.direction();
                    Some([dir[0], dir[1], dir[2]])
                }
                _ => None,
            };
        } else if !level && self.probe_signal {
            let high = self
                .drives
                .iter()
                .filter(|d| d.probe_input.is_high())
                .count();
            self.probe_signal = 2 * high >= self.drives.len();
        }
        let d = &mut self.drives[i];
        let positioning = matches!(self.activity, Activity::Moving { .. });
        if ProbeInput::is_collision(first, positioning) {
            self.abort_motion(RtError::new(ErrorKind::ProbeCollision, Detail::Collision));
            return;
        }
        if st.enabled(Probe::One)
            && st.positive_edge_stored(Probe::One)
            && d.tp_function != 0
            && d.latch_inc.is_none()
        {
            d.latch_inc = Some(pd.probe1_positive_edge);
            self.first_latch(now_ns);
            self.try_complete_contact(now_ns);
        }
    }

    /// The first latch frame of a probing move: brake every axis with the next SYNC.
    pub(super) fn first_latch(&mut self, receive_ns: u64) {
        let Activity::Probing {
            profile,
            t,
            request,
        } = self.activity
        else {
            return;
        };
        let mut step_inc = [(0, 0); MAX_AXES];
        for (s, d) in step_inc.iter_mut().zip(&self.drives) {
            *s = (d.actual_inc, d.target_inc);
        }
        self.contact = Some(PendingContact {
            request,
            sync_ns: self.sync_ns,
            step_inc,
        });
        self.stop_pending_since = Some((receive_ns, self.sync_ns));
        // The answer is set when the contact is complete (see `try_complete_contact`);
        // until then the stop does not answer (see `settle`).
        let placeholder = Reply::Error(RtError::new(ErrorKind::ContactLost, Detail::LatchLost));
        self.begin_stop(profile, t, placeholder);
    }

    /// Every moving axis has reported its latch: publish the contact, disarm, and let
    /// the stop under way answer with it.
    pub(super) fn try_complete_contact(&mut self, receive_ns: u64) {
        let Some(PendingContact {
            request,
            sync_ns,
            step_inc,
        }) = self.contact
        else {
            return;
        };
        if self
            .drives
            .iter()
            .any(|d| request.moves(d.axis) && d.latch_inc.is_none())
        {
            return;
        }
        self.contact = None;
        let mut positions = [0.0; MAX_AXES];
        // The fraction of the last period at which the latch happened, from the axis
        // that moved most: the drives latch position, not time.
        let mut best = 0.0;
        let mut fraction = 1.0;
        for (d, &(from, to)) in self.drives.iter().zip(&step_inc) {
            // An axis that does not move has not moved since: its position is its
            // latch (whose frame may still be on the way).
            let latched = d.latch_inc.unwrap_or(from);
            positions[d.axis.index()] = latched as f64 / d.scale;
            let span = (to as f64 - from as f64).abs();
            if span > best {
                best = span;
                fraction =
                    ((latched as f64 - from as f64) / (to as f64 - from as f64)).clamp(0.0, 1.0);
            }
        }
        self.sequence += 1;
        let d = request.direction;
        let sample = ContactSample {
            sequence: self.sequence,
            run_id: request.run_id,
            trigger_ns: sync_ns + (fraction * self.cfg.period_ns as f64) as u64,
            receive_ns,
            publish_ns: 0,
            positions,
            direction: [d[0], d[1], d[2]],
            feed: request.feed,
            axis_mask: self.mask as u32,
            flags: FLAG_HW_LATCH,
        };
        match self.sink.publish(&sample) {
            Ok(()) => self.stats.samples_published += 1,
            Err(_) => self.stats.publish_failures += 1,
        }
        self.disarm_all();
        match &mut self.activity {
            Activity::Stopping { then, .. } | Activity::Settling { then, .. } => {
                *then = Reply::Contact(sample);
            }
            _ => {}
        }
    }

    /// Arming touch probe 1 on every drive (disarm, enable, wait until every drive
    /// reports it enabled with no edge stored), then the probing move starts.
    pub(super) fn arm(&mut self, stage: ArmStage, since_ns: u64, request: ProbeRequest, now: u64) {
        let next = match stage {
            ArmStage::Disarm => {
                let retry = self.arm_retry;
                for d in self.drives.iter_mut().filter(|d| !(retry && is_armed(d))) {
                    d.tp_function = 0;
                    d.latch_inc = None;
                }
                ArmStage::Enable
            }
            ArmStage::Enable => {
                let retry = self.arm_retry;
                for d in self.drives.iter_mut().filter(|d| !(retry && is_armed(d))) {
                    d.tp_function = TouchProbeFunction::probe1_first_positive_edge();
                    d.tp_status_fresh = false;
                }
                self.arm_waits = 0;
                self.arm_enables += 1;
                ArmStage::WaitArmed
            }
            ArmStage::WaitArmed => {
                self.arm_waits += 1;
                // The touch probe function or the drive's answer (both sent once, on
                // change) may have been lost: disarm and enable again the drives that
                // did not report armed, which makes them report their status anew.
                if u64::from(self.arm_waits) * self.cfg.period_ns >= self.cfg.arm_timeout_ns / 4 {
                    self.arm_retry = true;
                    ArmStage::Disarm
                } else {
                    ArmStage::WaitArmed
                }
            }
        };
        let armed = matches!(stage, ArmStage::WaitArmed) && self.drives.iter().all(is_armed);
        if armed {
            if let Some(d) = self
                .drives
                .iter()
                .find(|d| TouchProbeStatus::from_bits(d.tp_status).input_level(Probe::One))
            {
                let at = [self.setpoint[0], self.setpoint[1], self.setpoint[2]];
                let err = RtError::new(ErrorKind::AlreadyDeflected, Detail::Deflected { at })
                    .node(d.node);
                self.disarm_all();
                self.reply = Some(Reply::Error(err));
                self.activity = Activity::Idle;
                return;
            }
            let from = self.setpoint;
            let mut to = from;
            for (to, d) in to.iter_mut().zip(request.direction) {
                *to += d * request.max_distance;
            }
            let profile = Profile::line(from, to, request.feed, &self.limits);
            // The contact comes within the path, its latch frame within two periods
            // after it.
            let longest = (profile.duration() * 1e9) as u64 + 2 * self.cfg.period_ns;
            self.window_due = Some(ProbeWindow {
                run_id: request.run_id,
                start_ns: self.sync_ns,
                end_ns: self.sync_ns + longest,
            });
            self.activity = Activity::Probing {
                profile,
                t: 0.0,
                request,
            };
        } else if now - since_ns > self.cfg.arm_timeout_ns {
            // The first drive that did not report armed, with what it last reported.
            let late = self.drives.iter().find(|d| !is_armed(d));
            let detail = Detail::ArmTimeout {
                waited_ms: (now - since_ns) as f64 / 1e6,
                enables: self.arm_enables,
                status: late.filter(|d| d.tp_status_fresh).map(|d| d.tp_status),
            };
            let mut err = RtError::new(ErrorKind::Timeout, detail);
            err.node = late.map(|d| d.node);
            self.disarm_all();
            self.reply = Some(Reply::Error(err));
            self.activity = Activity::Idle;
        } else {
            self.activity = Activity::Arming {
                stage: next,
                since_ns,
                request,
            };
        }
    }
}
