//! Emergency (EMCY, COB-ID 0x080 + node, 8 bytes): error code (u16 LE), error
//! register (0x1001), 5 manufacturer-specific bytes.

use super::{check_data, cob_id, frame, CobKind, DecodeError};
use crate::can::CanFrame;

const SERVICE: &str = "EMCY";

/// Error register (0x1001) bits, as carried in byte 2.
pub mod error_register {
    pub const GENERIC: u8 = 1 << 0;
    pub const CURRENT: u8 = 1 << 1;
    pub const VOLTAGE: u8 = 1 << 2;
    pub const TEMPERATURE: u8 = 1 << 3;
    pub const COMMUNICATION: u8 = 1 << 4;
    pub const DEVICE_PROFILE: u8 = 1 << 5;
    pub const MANUFACTURER: u8 = 1 << 7;
}

/// Error codes used by name in this project (CiA 301 / CiA 402).
pub mod code {
    pub const NO_ERROR: u16 = 0x0000;
    pub const GENERIC: u16 = 0x1000;
    pub const CAN_OVERRUN: u16 = 0x8110;
    pub const CAN_ERROR_PASSIVE: u16 = 0x8120;
    pub const HEARTBEAT_ERROR: u16 = 0x8130;
    pub const RECOVERED_FROM_BUS_OFF: u16 = 0x8140;
    pub const PDO_LENGTH_ERROR: u16 = 0x8210;
    pub const PDO_LENGTH_EXCEEDED: u16 = 0x8220;
    pub const RPDO_TIMEOUT: u16 = 0x8250;
    pub const FOLLOWING_ERROR: u16 = 0x8611;
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Emcy {
    pub error_code: u16,
    pub error_register: u8,
    pub manufacturer: [u8; 5],
}

impl Emcy {
    /// The EMCY frame `node` sends.
    pub fn encode(&self, node: u8) -> CanFrame {
        let c = self.error_code.to_le_bytes();
        let m = self.manufacturer;
        frame(
            cob_id::emcy_cob(node),
            &[
                c[0],
                c[1],
                self.error_register,
                m[0],
                m[1],
                m[2],
                m[3],
                m[4],
            ],
        )
    }

    /// The emergency in an EMCY frame (the sender is in the COB-ID, see
    /// [`Emcy::decode_with_node`]).
    pub fn decode(f: &CanFrame) -> Result<Emcy, DecodeError> {
        Self::decode_with_node(f).map(|(_, e)| e)
    }

    /// Sending node and the emergency.
    pub fn decode_with_node(f: &CanFrame) -> Result<(u8, Emcy), DecodeError> {
        let CobKind::Emcy { node } = cob_id::classify(f.cob_id()) else {
            return Err(DecodeError::WrongCobId {
                service: SERVICE,
                cob_id: f.cob_id(),
            });
        };
        check_data(SERVICE, f, 8, 8)?;
        let d = f.data();
        Ok((
            node,
            Emcy {
                error_code: u16::from_le_bytes([d[0], d[1]]),
                error_register: d[2],
                manufacturer: [d[3], d[4], d[5], d[6], d[7]],
            },
        ))
    }

    /// Error code 0x0000: the node's errors are gone.
    pub const fn is_reset(&self) -> bool {
        self.error_code == code::NO_ERROR
    }

    pub const fn describe(&self) -> &'static str {
        describe(self.error_code)
    }
}

/// Text for an error code: the specific code when known, else its class.
pub const fn describe(error_code: u16) -> &'static str {
    match error_code {
        0x0000 => "error reset or no error",
        0x1000 => "generic error",
        0x2310 => "continuous over-current",
        0x3210 => "DC link over-voltage",
        0x3220 => "DC link under-voltage",
        0x4210 => "excess temperature device",
        0x5530 => "data storage (non-volatile memory) error",
        0x6100 => "internal software error",
        0x6200 => "user software error",
        0x6300 => "data set error",
        0x7300 => "sensor error",
        0x7305 => "incremental sensor 1 fault",
        0x8100 => "communication error",
        0x8110 => "CAN overrun (objects lost)",
        0x8120 => "CAN in error passive mode",
        0x8130 => "life guard error or heartbeat error",
        0x8140 => "recovered from bus off",
        0x8150 => "CAN-ID collision",
        0x8200 => "protocol error",
        0x8210 => "PDO not processed due to length error",
        0x8220 => "PDO length exceeded",
        0x8240 => "unexpected SYNC data length",
        0x8250 => "RPDO timeout",
        0x8611 => "following error",
        0x8612 => "reference limit",
        0x9000 => "external error",
        _ => match error_code >> 12 {
            0x1 => "generic error",
            0x2 => "current",
            0x3 => "voltage",
            0x4 => "temperature",
            0x5 => "device hardware",
            0x6 => "device software",
            0x7 => "additional modules",
            0x8 if error_code >> 8 == 0x81 => "communication",
            0x8 if error_code >> 8 == 0x82 => "protocol error",
            0x8 => "monitoring",
            0x9 => "external error",
            0xF if error_code >> 8 == 0xFF => "device specific",
            0xF => "additional functions",
            _ => "unknown error code",
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout() {
        let e = Emcy {
            error_code: 0x8611,
            error_register: 0x21,
            manufacturer: [1, 2, 3, 4, 5],
        };
        let f = e.encode(3);
        assert_eq!(format!("{f:?}"), "083#1186210102030405");
        assert_eq!(Emcy::decode_with_node(&f).unwrap(), (3, e));
        assert_eq!(Emcy::decode(&f).unwrap(), e);
        assert_eq!(e.describe(), "following error");
        assert_eq!(describe(0x2345), "current");
        assert_eq!(describe(0xFF01), "device specific");
        assert_eq!(describe(0x8101), "communication");
        let short = CanFrame::new(0x083, &[0, 0]).unwrap();
        assert!(Emcy::decode(&short).is_err());
        assert!(Emcy::decode(&CanFrame::new(0x080, &[0; 8]).unwrap()).is_err());
    }
}
