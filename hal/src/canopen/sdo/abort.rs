//! SDO abort codes (CiA 301 table 22). An abort is an answer, not a failure of ours:
//! it travels as data to whoever asked.

use core::fmt;

#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct SdoAbortCode(pub u32);

impl SdoAbortCode {
    pub const TOGGLE_BIT_NOT_ALTERNATED: Self = Self(0x0503_0000);
    pub const TIMEOUT: Self = Self(0x0504_0000);
    pub const COMMAND_SPECIFIER_INVALID: Self = Self(0x0504_0001);
    pub const OUT_OF_MEMORY: Self = Self(0x0504_0005);
    pub const UNSUPPORTED_ACCESS: Self = Self(0x0601_0000);
    pub const WRITE_ONLY: Self = Self(0x0601_0001);
    pub const READ_ONLY: Self = Self(0x0601_0002);
    pub const OBJECT_DOES_NOT_EXIST: Self = Self(0x0602_0000);
    pub const CANNOT_BE_MAPPED: Self = Self(0x0604_0041);
    pub const PDO_LENGTH_EXCEEDED: Self = Self(0x0604_0042);
    pub const PARAMETER_INCOMPATIBLE: Self = Self(0x0604_0043);
    pub const LENGTH_MISMATCH: Self = Self(0x0607_0010);
    pub const LENGTH_TOO_HIGH: Self = Self(0x0607_0012);
    pub const LENGTH_TOO_LOW: Self = Self(0x0607_0013);
    pub const SUB_INDEX_DOES_NOT_EXIST: Self = Self(0x0609_0011);
    pub const VALUE_RANGE_EXCEEDED: Self = Self(0x0609_0030);
    pub const GENERAL_ERROR: Self = Self(0x0800_0000);
    pub const CANNOT_BE_STORED: Self = Self(0x0800_0020);
    pub const DEVICE_STATE: Self = Self(0x0800_0022);

    /// CiA 301 text for the known codes.
    pub const fn description(self) -> Option<&'static str> {
        Some(match self.0 {
            0x0503_0000 => "toggle bit not alternated",
            0x0504_0000 => "SDO protocol timed out",
            0x0504_0001 => "client/server command specifier not valid or unknown",
            0x0504_0005 => "out of memory",
            0x0601_0000 => "unsupported access to an object",
            0x0601_0001 => "attempt to read a write only object",
            0x0601_0002 => "attempt to write a read only object",
            0x0602_0000 => "object does not exist in the object dictionary",
            0x0604_0041 => "object cannot be mapped to the PDO",
            0x0604_0042 => "the number and length of the objects to be mapped would exceed PDO length",
            0x0604_0043 => "general parameter incompatibility reason",
            0x0607_0010 => "data type does not match, length of service parameter does not match",
            0x0607_0012 => "data type does not match, length of service parameter too high",
            0x0607_0013 => "data type does not match, length of service parameter too low",
            0x0609_0011 => "sub-index does not exist",
            0x0609_0030 => "invalid value for parameter (download only)",
            0x0800_0000 => "general error",
            0x0800_0020 => "data cannot be transferred or stored to the application",
            0x0800_0022 => {
                "data cannot be transferred or stored to the application because of the present device state"
            }
            _ => return None,
        })
    }
}

impl fmt::Display for SdoAbortCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.description() {
            Some(d) => write!(f, "SDO abort {:#010X}: {d}", self.0),
            None => write!(f, "SDO abort {:#010X}", self.0),
        }
    }
}

impl fmt::Debug for SdoAbortCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "SdoAbortCode({:#010X})", self.0)
    }
}

impl From<SdoAbortCode> for u32 {
    fn from(c: SdoAbortCode) -> u32 {
        c.0
    }
}
