//! The CiA 402 drive state machine: the controlword steps it, the statusword shows it,
//! a fault or a lost connection (0x6007) stops it.

use super::{abort_connection, Application, Objects, SimDrive, CYCLIC_SYNCHRONOUS_POSITION};
use hal::canopen::emcy::code as emcy_code;
use hal::cia402::controlword::{fault_reset_edge, Command};
use hal::cia402::{State, Statusword};

impl Application {
    pub(super) fn new(position_inc: i32) -> Self {
        Self {
            mode: 0,
            controlword: 0,
            target: position_inc,
            tp_function: 0,
            tp_status: 0,
            tp_pos_edge: 0,
            state: State::SwitchOnDisabled,
            fault: None,
            abort_connection: abort_connection::QUICK_STOP,
            profile_velocity: 0,
            profile_acceleration: 0,
            profile_deceleration: 0,
            pp_set_point: None,
            pp_acknowledged: false,
            pp_bit4_seen: false,
        }
    }
}

impl Objects {
    /// 0x6041: the state bits, remote (the controlword is obeyed), voltage enabled
    /// while the power stage is switched on, and in cyclic synchronous position with
    /// operation enabled bit 12: the drive follows the target position (profile
    /// position: bits 10 and 12 of [`Objects::profile_position_status`]).
    pub(super) fn statusword(&self) -> u16 {
        let s = self.app.state;
        Statusword(s.statusword_bits() | Statusword::REMOTE)
            .with(
                Statusword::VOLTAGE_ENABLED,
                matches!(
                    s,
                    State::ReadyToSwitchOn
                        | State::SwitchedOn
                        | State::OperationEnabled
                        | State::QuickStopActive
                ),
            )
            .with(
                Statusword::TARGET_POSITION_FOLLOWED,
                s == State::OperationEnabled && self.app.mode == CYCLIC_SYNCHRONOUS_POSITION,
            )
            .bits()
            | self.profile_position_status()
    }

    /// The state machine takes `cw`. A fault reset (bit 7 rising) in Fault clears the
    /// fault (its cause is gone in the simulation; a collision that persists comes
    /// back at the next step) and sends the EMCY "error reset".
    pub(super) fn apply_controlword(&mut self, cw: u16) {
        let prev = self.app.controlword;
        if self.quick_stop_until_us.is_some() {
            // Quick stop option code 2: no way back to Operation enabled (CiA 402
            // transition 16 needs 5..8); Disable voltage ends the stop early.
            if Command::decode(cw) == Some(Command::DisableVoltage) {
                self.app.state = State::SwitchOnDisabled;
                self.quick_stop_until_us = None;
            }
            self.app.controlword = cw;
            return;
        }
        if self.app.state == State::Fault && self.app.fault.is_some() && fault_reset_edge(cw, prev)
        {
            self.app.fault = None;
            self.push_emcy(emcy_code::NO_ERROR);
        }
        self.app.state = self
            .app
            .state
            .on_controlword(cw, prev, self.app.fault.is_some());
        self.app.controlword = cw;
    }
}

impl SimDrive {
    /// The reaction of 0x6007 to a lost connection, with its EMCY 0x8130.
    pub(super) fn abort_connection(&mut self) {
        let app = &mut self.od.app;
        match app.abort_connection {
            abort_connection::FAULT => {
                // Fault reaction: the EMCY carries the fault's own error register.
                app.fault.get_or_insert(emcy_code::HEARTBEAT_ERROR);
                app.state = State::Fault;
            }
            abort_connection::DISABLE_VOLTAGE if app.state != State::Fault => {
                app.state = State::SwitchOnDisabled;
            }
            abort_connection::QUICK_STOP => match app.state {
                // The axis stops where it is (the simulation brakes within a cycle),
                // then the drive is disabled.
                State::OperationEnabled | State::QuickStopActive => {
                    app.state = State::QuickStopActive;
                    self.od.quick_stop_until_us =
                        Some(self.now_us + u64::from(self.od.comm.cycle_period_us));
                }
                State::ReadyToSwitchOn | State::SwitchedOn => app.state = State::SwitchOnDisabled,
                _ => {}
            },
            _ => {}
        }
        self.od.push_emcy(emcy_code::HEARTBEAT_ERROR);
    }

    /// The quick stop of a lost connection is over: Switch on disabled.
    pub(super) fn end_quick_stop(&mut self) {
        if let Some(until) = self.od.quick_stop_until_us {
            if self.now_us >= until {
                self.od.quick_stop_until_us = None;
                if self.od.app.state == State::QuickStopActive {
                    self.od.app.state = State::SwitchOnDisabled;
                }
            }
        }
    }

    /// Puts the drive into Fault with an EMCY `code` (sent with the next answer).
    pub fn raise_fault(&mut self, code: u16) {
        if self.od.app.fault.is_none() {
            self.od.app.fault = Some(code);
            self.od.app.state = State::Fault;
            self.od.push_emcy(code);
        }
    }
}
