//! The CiA 402 power drive system state machine, named as the standard names it.

use super::controlword::{fault_reset_edge, Command, Controlword};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum State {
    NotReadyToSwitchOn,
    SwitchOnDisabled,
    ReadyToSwitchOn,
    SwitchedOn,
    OperationEnabled,
    QuickStopActive,
    FaultReactionActive,
    Fault,
}

impl State {
    /// The state a statusword shows (CiA 402 masks 0x004F / 0x006F); `None` for
    /// combinations the standard does not define.
    pub const fn from_statusword(sw: u16) -> Option<State> {
        match sw & 0x004F {
            0x0000 => return Some(State::NotReadyToSwitchOn),
            0x0040 => return Some(State::SwitchOnDisabled),
            0x000F => return Some(State::FaultReactionActive),
            0x0008 => return Some(State::Fault),
            _ => {}
        }
        match sw & 0x006F {
            0x0021 => Some(State::ReadyToSwitchOn),
            0x0023 => Some(State::SwitchedOn),
            0x0027 => Some(State::OperationEnabled),
            0x0007 => Some(State::QuickStopActive),
            _ => None,
        }
    }

    /// The state bits (0-3, 5, 6) of the drive's statusword. Voltage enabled, remote,
    /// target reached and the other flags are the drive's to add.
    pub const fn statusword_bits(self) -> u16 {
        match self {
            State::NotReadyToSwitchOn => 0x0000,
            State::SwitchOnDisabled => 0x0040,
            State::ReadyToSwitchOn => 0x0021,
            State::SwitchedOn => 0x0023,
            State::OperationEnabled => 0x0027,
            State::QuickStopActive => 0x0007,
            State::FaultReactionActive => 0x000F,
            State::Fault => 0x0008,
        }
    }

    /// Master side: the controlword that moves the drive one step towards Operation
    /// enabled; `None` once there.
    ///
    /// In Fault this is the fault reset (0x0080), which acts only on a rising edge:
    /// the previous controlword must have had bit 7 clear. [`State::next_controlword`]
    /// takes care of that. Not ready to switch on and Fault reaction active pass on
    /// by themselves; Disable voltage is sent meanwhile, which also prepares the edge.
    pub const fn command_towards_operation_enabled(self) -> Option<u16> {
        Some(match self {
            State::NotReadyToSwitchOn | State::FaultReactionActive => Controlword::DISABLE_VOLTAGE,
            State::Fault => Controlword::FAULT_RESET_CMD,
            State::SwitchOnDisabled => Controlword::SHUTDOWN,
            State::ReadyToSwitchOn => Controlword::SWITCH_ON_CMD,
            State::SwitchedOn => Controlword::ENABLE_OPERATION_CMD,
            State::QuickStopActive => Controlword::DISABLE_VOLTAGE,
            State::OperationEnabled => return None,
        })
    }

    /// [`State::command_towards_operation_enabled`], but in Fault sends 0x0000 first
    /// when `previous_cw` already had bit 7 set, so the reset gets its rising edge.
    pub const fn next_controlword(self, previous_cw: u16) -> Option<u16> {
        if matches!(self, State::Fault) && previous_cw & Controlword::FAULT_RESET != 0 {
            return Some(Controlword::DISABLE_VOLTAGE);
        }
        self.command_towards_operation_enabled()
    }

    /// Drive side: the state after receiving `cw` (previous controlword
    /// `previous_cw`), with `fault_present` whether a fault condition exists now.
    ///
    /// Automatic transitions take one call: Not ready to switch on goes to Switch on
    /// disabled (transition 1), Fault reaction active to Fault (14). A present fault
    /// leads from any other state to Fault reaction active (13). Fault reset (15)
    /// needs a rising edge of bit 7 and the fault gone. Quick stop active stays until
    /// Disable voltage (12) or Enable operation (16), as with quick stop option codes
    /// 5..=8.
    pub const fn on_controlword(self, cw: u16, previous_cw: u16, fault_present: bool) -> State {
        match self {
            State::NotReadyToSwitchOn => return State::SwitchOnDisabled,
            State::FaultReactionActive => return State::Fault,
            State::Fault => {
                return if !fault_present && fault_reset_edge(cw, previous_cw) {
                    State::SwitchOnDisabled
                } else {
                    State::Fault
                };
            }
            _ => {}
        }
        if fault_present {
            return State::FaultReactionActive;
        }
        let Some(cmd) = Command::decode(cw) else {
            return self;
        };
        match (self, cmd) {
            // 2
            (State::SwitchOnDisabled, Command::Shutdown) => State::ReadyToSwitchOn,
            // 3, and 3 + 4 for "switch on + enable operation"
            (State::ReadyToSwitchOn, Command::SwitchOn) => State::SwitchedOn,
            (State::ReadyToSwitchOn, Command::EnableOperation) => State::OperationEnabled,
            // 7
            (State::ReadyToSwitchOn, Command::DisableVoltage | Command::QuickStop) => {
                State::SwitchOnDisabled
            }
            // 4, 6, 10
            (State::SwitchedOn, Command::EnableOperation) => State::OperationEnabled,
            (State::SwitchedOn, Command::Shutdown) => State::ReadyToSwitchOn,
            (State::SwitchedOn, Command::DisableVoltage | Command::QuickStop) => {
                State::SwitchOnDisabled
            }
            // 5 (0x0007 is disable operation here), 8, 9, 11
            (State::OperationEnabled, Command::SwitchOn | Command::DisableOperation) => {
                State::SwitchedOn
            }
            (State::OperationEnabled, Command::Shutdown) => State::ReadyToSwitchOn,
            (State::OperationEnabled, Command::DisableVoltage) => State::SwitchOnDisabled,
            (State::OperationEnabled, Command::QuickStop) => State::QuickStopActive,
            // 12, 16
            (State::QuickStopActive, Command::DisableVoltage) => State::SwitchOnDisabled,
            (State::QuickStopActive, Command::EnableOperation) => State::OperationEnabled,
            (s, _) => s,
        }
    }

    /// Power is applied to the motor (Operation enabled or Quick stop active).
    pub const fn is_powered(self) -> bool {
        matches!(self, State::OperationEnabled | State::QuickStopActive)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ALL: [State; 8] = [
        State::NotReadyToSwitchOn,
        State::SwitchOnDisabled,
        State::ReadyToSwitchOn,
        State::SwitchedOn,
        State::OperationEnabled,
        State::QuickStopActive,
        State::FaultReactionActive,
        State::Fault,
    ];

    #[test]
    fn statusword_bits_round_trip() {
        for s in ALL {
            assert_eq!(State::from_statusword(s.statusword_bits()), Some(s));
            // Flags outside the masks do not change the state.
            assert_eq!(
                State::from_statusword(s.statusword_bits() | 0x3E90),
                Some(s)
            );
        }
        assert_eq!(State::from_statusword(0x0001), None);
    }

    /// The standard's sequence with literal values (CiA 402 controlword and statusword
    /// encodings), not this module's constants on both sides: from Switch on disabled,
    /// Shutdown 0x0006 -> Ready to switch on (statusword 0x0021 under mask 0x006F),
    /// Switch on 0x0007 -> Switched on (0x0023), Enable operation 0x000F -> Operation
    /// enabled (0x0027); from Fault (0x0008 under 0x004F), Fault reset 0x0080 on its
    /// rising edge -> Switch on disabled (0x0040 under 0x004F).
    #[test]
    fn the_standards_controlword_statusword_sequence() {
        let enable: [(u16, u16, u16); 3] = [
            (0x0006, 0x006F, 0x0021),
            (0x0007, 0x006F, 0x0023),
            (0x000F, 0x006F, 0x0027),
        ];
        let (mut s, mut prev) = (State::SwitchOnDisabled, 0x0000u16);
        assert_eq!(s.statusword_bits() & 0x004F, 0x0040);
        for (cw, mask, sw) in enable {
            // The master asks for exactly the standard's command at each step.
            assert_eq!(s.command_towards_operation_enabled(), Some(cw), "{s:?}");
            s = s.on_controlword(cw, prev, false);
            prev = cw;
            assert_eq!(s.statusword_bits() & mask, sw, "after 0x{cw:04X}: {s:?}");
            assert_eq!(State::from_statusword(sw), Some(s));
        }
        assert_eq!(s.command_towards_operation_enabled(), None);
        // A drive that also sets voltage enabled (bit 4), remote (bit 9) and target
        // reached (bit 10) still reads as Operation enabled: 0x0637.
        assert_eq!(
            State::from_statusword(0x0637),
            Some(State::OperationEnabled)
        );

        let fault = State::Fault;
        assert_eq!(fault.statusword_bits() & 0x004F, 0x0008);
        assert_eq!(State::from_statusword(0x0218), Some(State::Fault));
        assert_eq!(fault.command_towards_operation_enabled(), Some(0x0080));
        // Bit 7 already high: no edge, the master first sends 0x0000.
        assert_eq!(fault.next_controlword(0x0080), Some(0x0000));
        assert_eq!(fault.on_controlword(0x0080, 0x0080, false), State::Fault);
        let reset = fault.on_controlword(0x0080, 0x0000, false);
        assert_eq!(reset.statusword_bits() & 0x004F, 0x0040);
    }

    #[test]
    fn master_drives_slave_to_operation_enabled_from_fault() {
        let (mut s, mut prev_cw) = (State::Fault, 0x0080u16);
        for _ in 0..8 {
            let Some(cw) = s.next_controlword(prev_cw) else {
                break;
            };
            s = s.on_controlword(cw, prev_cw, false);
            prev_cw = cw;
        }
        assert_eq!(s, State::OperationEnabled);
    }

    #[test]
    fn quick_stop_and_fault() {
        let s = State::OperationEnabled.on_controlword(0x0002, 0x000F, false);
        assert_eq!(s, State::QuickStopActive);
        assert_eq!(
            s.on_controlword(0x0002, 0x0002, false),
            State::QuickStopActive
        );
        assert_eq!(
            s.on_controlword(0x0000, 0x0002, false),
            State::SwitchOnDisabled
        );
        let s = State::OperationEnabled.on_controlword(0x000F, 0x000F, true);
        assert_eq!(s, State::FaultReactionActive);
        assert_eq!(s.on_controlword(0x000F, 0x000F, true), State::Fault);
        // Fault still present: a reset edge does not leave Fault.
        assert_eq!(State::Fault.on_controlword(0x0080, 0, true), State::Fault);
    }
}
