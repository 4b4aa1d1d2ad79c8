//! Profile position (CiA 402 mode 1), as a spindle drive orients: the master writes the
//! target (0x607A) and raises controlword bit 4; the drive takes it as its set-point,
//! answers with statusword bit 12, and moves there on its own at the profile velocity
//! (0x6081); statusword bit 10 tells when it stands there. Halt (bit 8) stops it where
//! it is. The set-point is taken once per SYNC, after the RPDO of that cycle took effect,
//! so a target and its bit 4 sent together belong together.

use super::{Objects, SimDrive, PROFILE_POSITION, SPINDLE_DRIVE_MODES};
use hal::cia402::{Controlword, State, Statusword};

impl Objects {
    /// Whether this drive has profile position (0x6502 bit 0).
    pub(super) fn has_profile_position(&self) -> bool {
        self.supported_modes & SPINDLE_DRIVE_MODES != 0
    }

    fn in_profile_position(&self) -> bool {
        let a = &self.app;
        a.mode == PROFILE_POSITION && a.state == State::OperationEnabled && a.fault.is_none()
    }

    /// The start of a step: a rising edge of controlword bit 4 takes the target as the
    /// new set-point (relative to the last one with bit 6); bit 4 low clears the
    /// acknowledge. Outside profile position with operation enabled there is none: a
    /// drive enabled again does not resume an old move.
    pub(super) fn take_set_point(&mut self) {
        let in_pp = self.in_profile_position();
        let a = &mut self.app;
        let bit4 = a.controlword & Controlword::NEW_SET_POINT != 0;
        if !in_pp {
            a.pp_set_point = None;
            a.pp_acknowledged = false;
            a.pp_bit4_seen = bit4;
            return;
        }
        if bit4 && !a.pp_bit4_seen {
            let base = a.pp_set_point.unwrap_or(self.actual);
            a.pp_set_point = Some(if a.controlword & Controlword::RELATIVE != 0 {
                base.saturating_add(a.target)
            } else {
                a.target
            });
            a.pp_acknowledged = true;
        }
        if !bit4 {
            a.pp_acknowledged = false;
        }
        a.pp_bit4_seen = bit4;
    }

    /// Statusword bits 10 (target reached: at the set-point, or halted) and 12
    /// (set-point acknowledge) in profile position; 0 otherwise.
    pub(super) fn profile_position_status(&self) -> u16 {
        if !self.in_profile_position() {
            return 0;
        }
        let a = &self.app;
        let halted = a.controlword & Controlword::HALT != 0;
        let reached = halted || a.pp_set_point.is_none_or(|sp| sp == self.actual);
        let mut bits = 0;
        if reached {
            bits |= Statusword::TARGET_REACHED;
        }
        if a.pp_acknowledged {
            bits |= Statusword::SET_POINT_ACKNOWLEDGE;
        }
        bits
    }
}

impl SimDrive {
    /// Profile position: one cycle's travel at the profile velocity towards the
    /// set-point (none while halted, or with velocity 0).
    pub(super) fn profile_position_next(&self) -> i32 {
        let a = &self.od.app;
        let actual = self.od.actual;
        let Some(sp) = a.pp_set_point else {
            return actual;
        };
        if a.controlword & Controlword::HALT != 0 {
            return actual;
        }
        let step = (f64::from(a.profile_velocity) * f64::from(self.od.comm.cycle_period_us) * 1e-6)
            .floor() as i64;
        let delta = (i64::from(sp) - i64::from(actual)).clamp(-step, step);
        (i64::from(actual) + delta) as i32
    }
}
