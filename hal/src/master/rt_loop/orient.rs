//! An oriented spindle stop by the spindle's drive in profile position. The master
//! sends the target with controlword bit 4 (new set-point); once the drive acknowledges
//! (statusword bit 12) bit 4 goes low again, and the stop is done when the drive
//! reports target reached (bit 10) at the target. The axes hold their positions
//! meanwhile.

use super::spindle::OrientStage;
use super::{Activity, RtLoop};
use crate::cia402::controlword::Controlword;
use crate::cia402::statusword::Statusword;
use crate::contact_sample::SampleSink;
use crate::machine::ErrorKind;
use crate::master::command::{Detail, Reply, RtError};

/// The spindle stands at its orientation within this angle, deg.
const IN_POSITION_DEG: f64 = 0.01;

impl<S: SampleSink> RtLoop<S> {
    /// Starts an oriented stop at `angle_deg` (taken modulo 360°).
    pub(super) fn begin_orient(&mut self, angle_deg: f64) {
        let Some(sp) = self.spindle.as_mut() else {
            self.reply = Some(Reply::Error(RtError::new(
                ErrorKind::InvalidRequest,
                Detail::NoSpindle,
            )));
            return;
        };
        if !angle_deg.is_finite() {
            self.reply = Some(Reply::Error(RtError::new(
                ErrorKind::InvalidRequest,
                Detail::InvalidAngle,
            )));
            return;
        }
        if self.probe_signal {
            // Turning the spindle drags a stylus in contact across the surface.
            self.reply = Some(Reply::Error(
                RtError::new(ErrorKind::AlreadyDeflected, Detail::SpindleDeflected).node(sp.node),
            ));
            return;
        }
        // Within the turn the drive stands in: a spindle that counts turns (it may have
        // run before) is not unwound to turn 0.
        let turn = sp.increments_per_turn;
        let base = (f64::from(sp.actual_inc) / turn).floor() * turn;
        let target = base + (angle_deg.rem_euclid(360.0) / 360.0 * turn).round();
        sp.target_inc = target.clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32;
        sp.controlword = Controlword::ENABLE_OPERATION_CMD | Controlword::NEW_SET_POINT;
        self.activity = Activity::Orienting {
            stage: OrientStage::SetPoint,
            since_ns: self.supervised_ns,
        };
    }

    /// One period of an oriented stop.
    pub(super) fn orient(&mut self, stage: OrientStage, since_ns: u64, now: u64) {
        let Some(sp) = self.spindle.as_mut() else {
            self.activity = Activity::Idle;
            return;
        };
        let sw = Statusword(sp.statusword);
        let acknowledged = sw.has(Statusword::SET_POINT_ACKNOWLEDGE);
        match stage {
            OrientStage::SetPoint if acknowledged => {
                sp.controlword = Controlword::ENABLE_OPERATION_CMD;
                self.activity = Activity::Orienting {
                    stage: OrientStage::Turning,
                    since_ns,
                };
                return;
            }
            OrientStage::Turning => {
                let error = sp.degrees(sp.actual_inc - sp.target_inc).abs();
                if !acknowledged && sw.target_reached() && error <= IN_POSITION_DEG {
                    self.reply = Some(Reply::Done {
                        positions: self.actual_positions(),
                    });
                    self.activity = Activity::Idle;
                    return;
                }
            }
            OrientStage::SetPoint => {}
        }
        if now.saturating_sub(since_ns) > sp.orient_timeout_ns {
            // Halted where it is: a drive that did not turn there must not turn on
            // its own later.
            sp.controlword = Controlword::ENABLE_OPERATION_CMD | Controlword::HALT;
            let err = RtError::new(
                ErrorKind::Timeout,
                Detail::NotOriented {
                    to_deg: sp.degrees(sp.target_inc),
                    at_deg: sp.degrees(sp.actual_inc),
                    acknowledged: stage == OrientStage::Turning,
                },
            )
            .node(sp.node);
            self.reply = Some(Reply::Error(err));
            self.activity = Activity::Idle;
        }
    }

    /// Stops the spindle where it is (halt): the operator's stop, or a fault.
    pub(super) fn halt_spindle(&mut self) {
        if let Some(sp) = self.spindle.as_mut() {
            if sp.controlword & Controlword::ENABLE_OPERATION != 0 {
                sp.controlword = Controlword::ENABLE_OPERATION_CMD | Controlword::HALT;
            }
        }
    }
}
