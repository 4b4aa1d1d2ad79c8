//! Statusword (0x6041): state bits (see [`super::State`]) and the status flags.

/// A statusword value; the associated constants name its bits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Statusword(pub u16);

impl Statusword {
    pub const READY_TO_SWITCH_ON: u16 = 1 << 0;
    pub const SWITCHED_ON: u16 = 1 << 1;
    pub const OPERATION_ENABLED: u16 = 1 << 2;
    pub const FAULT: u16 = 1 << 3;
    pub const VOLTAGE_ENABLED: u16 = 1 << 4;
    /// Active low: 0 while a quick stop is in progress.
    pub const QUICK_STOP: u16 = 1 << 5;
    pub const SWITCH_ON_DISABLED: u16 = 1 << 6;
    pub const WARNING: u16 = 1 << 7;
    /// The controlword is processed (the drive listens to the bus).
    pub const REMOTE: u16 = 1 << 9;
    pub const TARGET_REACHED: u16 = 1 << 10;
    pub const INTERNAL_LIMIT_ACTIVE: u16 = 1 << 11;
    /// Mode specific; in cyclic synchronous position: 1 = the drive follows the target
    /// position, 0 = it ignores it.
    pub const OP_MODE_SPECIFIC: u16 = 1 << 12;
    /// [`Self::OP_MODE_SPECIFIC`] as cyclic synchronous position names it.
    pub const TARGET_POSITION_FOLLOWED: u16 = Self::OP_MODE_SPECIFIC;
    /// [`Self::OP_MODE_SPECIFIC`] as profile position names it: the drive took the new
    /// set-point (controlword bit 4); cleared after bit 4 is.
    pub const SET_POINT_ACKNOWLEDGE: u16 = Self::OP_MODE_SPECIFIC;
    pub const FOLLOWING_ERROR: u16 = 1 << 13;

    pub const fn bits(self) -> u16 {
        self.0
    }

    pub const fn has(self, bit: u16) -> bool {
        self.0 & bit == bit
    }

    /// Sets or clears `bit` (for the drive side building its statusword).
    pub const fn with(self, bit: u16, on: bool) -> Self {
        if on {
            Self(self.0 | bit)
        } else {
            Self(self.0 & !bit)
        }
    }

    pub const fn state(self) -> Option<super::State> {
        super::State::from_statusword(self.0)
    }

    pub const fn fault(self) -> bool {
        self.has(Self::FAULT)
    }

    pub const fn warning(self) -> bool {
        self.has(Self::WARNING)
    }

    pub const fn remote(self) -> bool {
        self.has(Self::REMOTE)
    }

    pub const fn target_reached(self) -> bool {
        self.has(Self::TARGET_REACHED)
    }

    pub const fn internal_limit_active(self) -> bool {
        self.has(Self::INTERNAL_LIMIT_ACTIVE)
    }

    pub const fn target_position_followed(self) -> bool {
        self.has(Self::TARGET_POSITION_FOLLOWED)
    }

    pub const fn following_error(self) -> bool {
        self.has(Self::FOLLOWING_ERROR)
    }
}
