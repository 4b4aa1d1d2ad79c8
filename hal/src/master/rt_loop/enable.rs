//! Start-up: the CiA 402 enable sequence of every drive.

use super::{Activity, RtLoop};
use crate::cia402::controlword::Controlword;
use crate::cia402::state::State;
use crate::contact_sample::SampleSink;
use crate::machine::ErrorKind;
use crate::master::command::{Detail, Reply, RtError};

/// While enabling, a drive that has not sent its TPDO1 for this long gets the NMT
/// start again (the first may have been lost on the bus; a started node ignores it).
const NMT_START_REPEAT_NS: u64 = 100_000_000;

impl<S: SampleSink> RtLoop<S> {
    /// Start-up: walk every drive to Operation enabled, holding where it is.
    pub(super) fn enable(&mut self, now: u64, since_ns: u64) {
        let mut all = true;
        for d in self.drives.iter_mut() {
            if !d.seen_tpdo1 {
                all = false;
                continue;
            }
            // Hold where the drive is: enabling must not move anything.
            d.target_inc = d.actual_inc;
            all &= step_towards_enabled(d.statusword, &mut d.controlword);
        }
        if let Some(s) = self.spindle.as_mut() {
            if s.seen_tpdo1 {
                // Its set-point is where it stands (profile position moves only on a
                // new set-point, which enabling never sends).
                s.target_inc = s.actual_inc;
                all &= step_towards_enabled(s.statusword, &mut s.controlword);
            } else {
                all = false;
            }
        }
        let spindle_missing = self.spindle.is_some_and(|s| !s.seen_tpdo1);
        if !all
            && (self.drives.iter().any(|d| !d.seen_tpdo1) || spindle_missing)
            && now.saturating_sub(self.nmt_start_at_ns) >= NMT_START_REPEAT_NS
        {
            self.nmt_start_at_ns = now;
            self.nmt_start_due = true;
        }
        if all {
            self.hold_all();
            self.activity = Activity::Idle;
            self.reply = Some(Reply::Ready {
                positions: self.actual_positions(),
            });
        } else if now - since_ns > self.cfg.enable_timeout_ns {
            let not_enabled = |sw: u16| State::from_statusword(sw) != Some(State::OperationEnabled);
            let (node, sw) = self
                .drives
                .iter()
                .map(|d| (d.node, d.statusword))
                .chain(self.spindle.map(|s| (s.node, s.statusword)))
                .find(|&(_, sw)| not_enabled(sw))
                .unwrap_or((0, 0));
            let kind = if self.drives.iter().any(|d| !d.seen_tpdo1) || spindle_missing {
                ErrorKind::NodeLost
            } else {
                ErrorKind::DriveFault
            };
            let err = RtError::new(
                kind,
                Detail::NotEnabled {
                    state: sw,
                    waited_ms: (now - since_ns) as f64 / 1e6,
                },
            )
            .node(node);
            self.fault = Some(err);
            self.reply = Some(Reply::Error(err));
            self.activity = Activity::Idle;
        }
    }
}

/// One step of a drive towards Operation enabled: the controlword for its state;
/// whether it is there.
fn step_towards_enabled(statusword: u16, controlword: &mut u16) -> bool {
    let state = State::from_statusword(statusword);
    match state.and_then(|s| s.command_towards_operation_enabled()) {
        Some(cw) => {
            *controlword = cw;
            false
        }
        None if state == Some(State::OperationEnabled) => {
            *controlword = Controlword::ENABLE_OPERATION_CMD;
            true
        }
        None => false,
    }
}
