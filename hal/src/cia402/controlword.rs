//! Controlword (0x6040): bits 0-3 and 7 form the device control commands; bit 8 halts.

/// A controlword value; the associated constants name its bits and the commands.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Controlword(pub u16);

impl Controlword {
    // Bits.
    pub const SWITCH_ON: u16 = 1 << 0;
    pub const ENABLE_VOLTAGE: u16 = 1 << 1;
    /// Active low: 0 requests a quick stop.
    pub const QUICK_STOP: u16 = 1 << 2;
    pub const ENABLE_OPERATION: u16 = 1 << 3;
    /// Profile position: the target position is a new set-point, taken on the rising
    /// edge (the drive answers with statusword bit 12).
    pub const NEW_SET_POINT: u16 = 1 << 4;
    /// Profile position: a new set-point replaces the one under way at once.
    pub const CHANGE_SET_IMMEDIATELY: u16 = 1 << 5;
    /// Profile position: the target position is relative to the last set-point.
    pub const RELATIVE: u16 = 1 << 6;
    /// Acts on its rising edge only.
    pub const FAULT_RESET: u16 = 1 << 7;
    pub const HALT: u16 = 1 << 8;

    // Device control commands, as the values the master sends.
    pub const SHUTDOWN: u16 = 0x0006;
    pub const SWITCH_ON_CMD: u16 = 0x0007;
    pub const ENABLE_OPERATION_CMD: u16 = 0x000F;
    pub const DISABLE_VOLTAGE: u16 = 0x0000;
    pub const QUICK_STOP_CMD: u16 = 0x0002;
    /// Same coding as switch on; in Operation enabled it means disable operation.
    pub const DISABLE_OPERATION: u16 = 0x0007;
    /// Bit 7 alone; the previous controlword must have had it clear (rising edge).
    pub const FAULT_RESET_CMD: u16 = 0x0080;

    pub const fn bits(self) -> u16 {
        self.0
    }

    pub const fn has(self, bit: u16) -> bool {
        self.0 & bit == bit
    }

    pub const fn halt(self) -> bool {
        self.has(Self::HALT)
    }

    /// Sets or clears the halt bit, keeping the command bits.
    pub const fn with_halt(self, halt: bool) -> Self {
        if halt {
            Self(self.0 | Self::HALT)
        } else {
            Self(self.0 & !Self::HALT)
        }
    }

    /// The level-coded command (see [`Command::decode`]).
    pub const fn command(self) -> Option<Command> {
        Command::decode(self.0)
    }
}

/// Whether `cw` after `previous` is a fault reset (rising edge of bit 7).
pub const fn fault_reset_edge(cw: u16, previous: u16) -> bool {
    cw & Controlword::FAULT_RESET != 0 && previous & Controlword::FAULT_RESET == 0
}

/// Device control commands (CiA 402 table "command coding"). "Switch on" and
/// "disable operation" share a coding; which applies depends on the state.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Command {
    Shutdown,
    SwitchOn,
    EnableOperation,
    DisableVoltage,
    QuickStop,
    DisableOperation,
    FaultReset,
}

impl Command {
    /// The controlword to send (halt and mode bits clear).
    pub const fn bits(self) -> u16 {
        match self {
            Command::Shutdown => Controlword::SHUTDOWN,
            Command::SwitchOn => Controlword::SWITCH_ON_CMD,
            Command::EnableOperation => Controlword::ENABLE_OPERATION_CMD,
            Command::DisableVoltage => Controlword::DISABLE_VOLTAGE,
            Command::QuickStop => Controlword::QUICK_STOP_CMD,
            Command::DisableOperation => Controlword::DISABLE_OPERATION,
            Command::FaultReset => Controlword::FAULT_RESET_CMD,
        }
    }

    /// The level-coded command in `cw` (bits 0-3, bit 7 clear). Fault reset is an
    /// edge and is not decoded here (see [`fault_reset_edge`]); 0x0007 decodes as
    /// [`Command::SwitchOn`], which means disable operation in Operation enabled.
    pub const fn decode(cw: u16) -> Option<Command> {
        if cw & Controlword::FAULT_RESET != 0 {
            return None;
        }
        if cw & 0x02 == 0x00 {
            Some(Command::DisableVoltage)
        } else if cw & 0x06 == 0x02 {
            Some(Command::QuickStop)
        } else if cw & 0x07 == 0x06 {
            Some(Command::Shutdown)
        } else if cw & 0x0F == 0x07 {
            Some(Command::SwitchOn)
        } else if cw & 0x0F == 0x0F {
            Some(Command::EnableOperation)
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decode_commands() {
        assert_eq!(Command::decode(0x0006), Some(Command::Shutdown));
        assert_eq!(Command::decode(0x000E), Some(Command::Shutdown));
        assert_eq!(Command::decode(0x0007), Some(Command::SwitchOn));
        assert_eq!(Command::decode(0x010F), Some(Command::EnableOperation));
        assert_eq!(Command::decode(0x0000), Some(Command::DisableVoltage));
        assert_eq!(Command::decode(0x000D), Some(Command::DisableVoltage));
        assert_eq!(Command::decode(0x0002), Some(Command::QuickStop));
        assert_eq!(Command::decode(0x000B), Some(Command::QuickStop));
        assert_eq!(Command::decode(0x0086), None);
        for c in [
            Command::Shutdown,
            Command::SwitchOn,
            Command::EnableOperation,
            Command::DisableVoltage,
            Command::QuickStop,
        ] {
            assert_eq!(Command::decode(c.bits()), Some(c));
        }
        assert!(fault_reset_edge(0x80, 0x00));
        assert!(!fault_reset_edge(0x80, 0x80));
        let cw = Controlword(Controlword::ENABLE_OPERATION_CMD).with_halt(true);
        assert_eq!(cw.bits(), 0x010F);
        assert!(cw.halt());
        assert_eq!(cw.command(), Some(Command::EnableOperation));
    }
}
