//! The [`Machine`] calls over the mailbox: each move is checked by the motion guard,
//! then written as one command and run until the PLC reports it done.

use super::ModbusMachine;
use crate::axis::{Axis, AxisPositions};
use crate::machine::{Contact, ErrorKind, Machine, MachineError, ProbeMove};
use crate::modbus::config::CaptureKind;
use crate::modbus::mailbox::{bits, CommandCode, ResultCode};
use crate::motion_guard::{deflected_before_move, deflected_before_probing, may_start_deflected};

impl Machine for ModbusMachine {
    type Error = MachineError;

    fn axes(&self) -> u8 {
        self.config.axis_mask()
    }

    /// The PLC's own clock, read now (the last reading when the read fails: the
    /// command that needs the PLC will say why).
    fn clock_ns(&mut self) -> u64 {
        let _ = self.read_status();
        self.plc_clock.ns()
    }

    fn positions(&mut self) -> Result<AxisPositions, MachineError> {
        let s = self.read_status()?;
        Ok(AxisPositions::from_raw(
            self.scale.positions(&s.actual),
            self.config.axis_mask(),
        ))
    }

    fn move_to(&mut self, target: &AxisPositions, feed: f64) -> Result<(), MachineError> {
        // From where the last status read saw the axes (every command ends with one):
        // the same checks as every backend, the move's duration included.
        let here = AxisPositions::from_raw(
            self.scale.positions(&self.status.actual),
            self.config.axis_mask(),
        );
        self.guard.check_move_from(&here, target, feed)?;
        let mut linear = [0.0; 3];
        let mut rotary = false;
        for (axis, v) in target.iter() {
            let d = v - here.get(axis).unwrap_or(v);
            match axis.index() {
                i @ 0..=2 => linear[i] = d,
                _ => rotary |= d != 0.0,
            }
        }
        // A stylus already in contact from this bridge's last contact or collision
        // gives no rising edge: the PLC would not see a collision, only the broken
        // stylus. (A contact from before this bridge started, whose direction is
        // unknown, is left to the PLC.)
        if self.status.has(bits::DEFLECTED)
            && self.contact_along.is_some()
            && !may_start_deflected(self.contact_along, linear, rotary)
        {
            return Err(MachineError::new(
                ErrorKind::AlreadyDeflected,
                deflected_before_move(here.xyz()),
            ));
        }
        let (s, _) = self.run(CommandCode::Move, target, feed)?;
        match ResultCode::from_u16(s.result) {
            Some(ResultCode::Ok) => {
                if !s.has(bits::DEFLECTED) {
                    self.contact_along = None;
                }
                Ok(())
            }
            Some(ResultCode::Collision) => {
                self.contact_along = Some(linear);
                Err(self.result_error(&s, "move", 0.0))
            }
            _ => Err(self.result_error(&s, "move", 0.0)),
        }
    }

    fn probe(&mut self, mv: &ProbeMove) -> Result<Contact, MachineError> {
        if self.bus.capture == CaptureKind::Poll && !self.bus.allow_poll {
            return Err(MachineError::new(
                ErrorKind::InvalidRequest,
                format!(
                    "{}: bus.capture = \"poll\" is for set-up only: polled positions are not a latch; \
                     set bus.allow_poll = true to measure with it anyway; nothing moved",
                    self.config.path.display()
                ),
            ));
        }
        let here = self.positions()?;
        let dir = self.guard.check_probe(&here, mv)?.direction;
        let mut end = here;
        for (i, a) in Axis::LINEAR.iter().enumerate() {
            end.set(*a, here.get(*a).unwrap_or(0.0) + dir[i] * mv.max_distance);
        }
        // Latches left from before (a stray edge) are acknowledged first, so the PLC
        // re-arms; a deflected probe refuses before anything is written.
        if self.tracker.pending(self.status.latch_count) != 0 {
            self.take_latches(0)?;
        }
        if self.status.has(bits::DEFLECTED) {
            return Err(MachineError::new(
                ErrorKind::AlreadyDeflected,
                deflected_before_probing(here.xyz()),
            ));
        }
        self.contact_along = Some(dir);
        let window = self.probe_window(mv);
        self.sink.probing_move(window);
        let (s, latch) = self.run(CommandCode::Probe, &end, mv.feed)?;
        match (ResultCode::from_u16(s.result), latch) {
            (Some(ResultCode::Contact), None) => {
                // Counted after the status was read: one more look at the ring.
                let s = self.read_status()?;
                match self.take_latches(s.acked)? {
                    Some(slot) => Ok(self.contact(&slot, dir, mv.feed)),
                    None => Err(self.result_error(&s, "probing move", mv.max_distance)),
                }
            }
            (Some(ResultCode::Contact), Some(slot)) => Ok(self.contact(&slot, dir, mv.feed)),
            _ => Err(self.result_error(&s, "probing move", mv.max_distance)),
        }
    }

    fn set_run(&mut self, run_id: u64) {
        self.run_id = run_id;
    }

    /// Command 5, where `[bus] spindle_orientation` says the PLC has it; `Ok(false)`
    /// (nothing asked) where it does not.
    fn orient_spindle(&mut self, angle_deg: f64) -> Result<bool, MachineError> {
        if !self.bus.spindle_orientation {
            return Ok(false);
        }
        if !angle_deg.is_finite() {
            return Err(MachineError::new(
                ErrorKind::InvalidRequest,
                format!("spindle angle {angle_deg} is not a number; nothing moved"),
            ));
        }
        // Turning the spindle drags a stylus in contact across the surface.
        if self.status.has(bits::DEFLECTED) {
            return Err(MachineError::new(
                ErrorKind::AlreadyDeflected,
                "the stylus is in contact: the spindle is not turned with it deflected; retract first",
            ));
        }
        let milli = (angle_deg.rem_euclid(360.0) * 1000.0).round() as i32 % 360_000;
        let mut counts = [0i32; crate::axis::MAX_AXES];
        counts[0] = milli;
        let (s, _) = self.run_block(CommandCode::OrientSpindle, counts, 0, 0.0)?;
        match ResultCode::from_u16(s.result) {
            Some(ResultCode::Ok) => Ok(true),
            Some(ResultCode::Rejected) => Err(MachineError::new(
                ErrorKind::InvalidRequest,
                format!(
                    "the PLC rejected orient spindle (command 5) to {angle_deg:.3}°: its program has no orientable spindle. \
                     Implement command 5 (docs/modbus.md) or set spindle_orientation = false in [bus]"
                ),
            )),
            _ => Err(self.result_error(&s, "orient spindle", 0.0)),
        }
    }

    /// One status read: the connection (after the client's retries and reconnects),
    /// and the PLC's fault bit.
    fn health(&mut self) -> Result<(), MachineError> {
        let s = self.read_status()?;
        if s.has(bits::FAULT) {
            return Err(MachineError::new(
                ErrorKind::DriveFault,
                "the PLC reports a fault (acknowledge it at the PLC)",
            ));
        }
        Ok(())
    }
}
