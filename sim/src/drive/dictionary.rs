//! The drive's object dictionary behind its SDO server: the objects of the
//! communication and drive profile areas as the master reads and writes them, 0x1001
//! and the EMCYs that carry it.

use super::{
    abort_connection, Application, Communication, Objects, CYCLIC_SYNCHRONOUS_POSITION,
    DEVICE_NAME, DEVICE_TYPE, EMCY_QUEUE, PRODUCT_CODE, PROFILE_POSITION, REVISION,
    SUPPORTED_DRIVE_MODES, VENDOR_ID,
};
use hal::canopen::emcy::{error_register, Emcy};
use hal::canopen::object as obj;
use hal::canopen::pdo::{COB_ID_EXTENDED, COB_ID_INVALID};
use hal::canopen::sdo::{ObjectDictionary, SdoAbortCode};

impl Objects {
    pub(super) fn new(node: u8, position_inc: i32) -> Self {
        Self {
            node,
            supported_modes: SUPPORTED_DRIVE_MODES,
            device_name: DEVICE_NAME,
            comm: Communication::new(node),
            app: Application::new(position_inc),
            actual: position_inc,
            pdo_length_error: false,
            heartbeat_lost: false,
            consumer_restart: true,
            quick_stop_until_us: None,
            emcy: [Emcy {
                error_code: 0,
                error_register: 0,
                manufacturer: [0; 5],
            }; EMCY_QUEUE],
            emcy_len: 0,
            heartbeat_restart: true,
        }
    }

    /// 0x1001: generic bit with any error, plus the class of each active one.
    pub(super) fn error_register(&self) -> u8 {
        let mut r = 0;
        if let Some(code) = self.app.fault {
            r |= error_register::GENERIC
                | match code >> 8 {
                    0x20..=0x2F => error_register::CURRENT,
                    0x30..=0x3F => error_register::VOLTAGE,
                    0x40..=0x4F => error_register::TEMPERATURE,
                    0x81 | 0x82 => error_register::COMMUNICATION,
                    0xFF => error_register::MANUFACTURER,
                    _ => 0,
                };
        }
        if self.pdo_length_error || self.heartbeat_lost {
            r |= error_register::GENERIC | error_register::COMMUNICATION;
        }
        r
    }

    /// Queues an EMCY whose error register byte is 0x1001 as it is now (code 0x0000:
    /// an error went away). A full queue drops the oldest.
    pub(super) fn push_emcy(&mut self, code: u16) {
        if self.emcy_len == EMCY_QUEUE {
            self.emcy.copy_within(1.., 0);
            self.emcy_len -= 1;
        }
        self.emcy[self.emcy_len] = Emcy {
            error_code: code,
            error_register: self.error_register(),
            manufacturer: [0; 5],
        };
        self.emcy_len += 1;
    }

    /// Value of a mappable object as raw bits.
    pub(super) fn mapped_value(&self, index: u16, sub: u8) -> Option<u64> {
        Some(match (index, sub) {
            (obj::CONTROLWORD, 0) => self.app.controlword as u64,
            (obj::STATUSWORD, 0) => self.statusword() as u64,
            (obj::MODES_OF_OPERATION, 0) | (obj::MODES_OF_OPERATION_DISPLAY, 0) => {
                self.app.mode as u8 as u64
            }
            (obj::POSITION_ACTUAL_VALUE, 0) => self.actual as u32 as u64,
            (obj::TARGET_POSITION, 0) => self.app.target as u32 as u64,
            (obj::ERROR_CODE, 0) => self.app.fault.unwrap_or(0) as u64,
            (obj::TOUCH_PROBE_FUNCTION, 0) => self.app.tp_function as u64,
            (obj::TOUCH_PROBE_STATUS, 0) => self.app.tp_status as u64,
            (obj::TOUCH_PROBE_1_POSITIVE_EDGE, 0) => self.app.tp_pos_edge as u32 as u64,
            _ => return None,
        })
    }

    /// Writes an object the master may write through an RPDO or SDO, with its effect:
    /// a controlword steps the state machine, a touch probe function (re)arms.
    pub(super) fn write_mapped(&mut self, index: u16, sub: u8, v: u64) -> Result<(), SdoAbortCode> {
        match (index, sub) {
            (obj::CONTROLWORD, 0) => self.apply_controlword(v as u16),
            (obj::TARGET_POSITION, 0) => self.app.target = v as u32 as i32,
            (obj::MODES_OF_OPERATION, 0) => self.app.mode = v as u8 as i8,
            (obj::TOUCH_PROBE_FUNCTION, 0) => {
                self.app.tp_function = v as u16;
                self.apply_touch_probe_function();
            }
            _ => return Err(SdoAbortCode::CANNOT_BE_MAPPED),
        }
        Ok(())
    }

    pub(super) fn object_bits(index: u16, sub: u8) -> Option<u8> {
        Some(match (index, sub) {
            (obj::CONTROLWORD | obj::STATUSWORD | obj::ERROR_CODE, 0) => 16,
            (obj::TOUCH_PROBE_FUNCTION | obj::TOUCH_PROBE_STATUS, 0) => 16,
            (obj::MODES_OF_OPERATION | obj::MODES_OF_OPERATION_DISPLAY, 0) => 8,
            (
                obj::POSITION_ACTUAL_VALUE
                | obj::TARGET_POSITION
                | obj::TOUCH_PROBE_1_POSITIVE_EDGE,
                0,
            ) => 32,
            _ => return None,
        })
    }
}

fn le(data: &[u8], n: usize) -> Result<u64, SdoAbortCode> {
    if data.len() < n {
        return Err(SdoAbortCode::LENGTH_TOO_LOW);
    }
    if data.len() > n {
        return Err(SdoAbortCode::LENGTH_TOO_HIGH);
    }
    let mut b = [0u8; 8];
    b[..n].copy_from_slice(&data[..n]);
    Ok(u64::from_le_bytes(b))
}

fn put(buf: &mut [u8], v: u64, n: usize) -> Result<usize, SdoAbortCode> {
    if buf.len() < n {
        return Err(SdoAbortCode::OUT_OF_MEMORY);
    }
    buf[..n].copy_from_slice(&v.to_le_bytes()[..n]);
    Ok(n)
}

/// A simple variable: only sub-index 0 exists.
fn var(sub: u8, v: u64, n: usize) -> Result<(u64, usize), SdoAbortCode> {
    if sub == 0 {
        Ok((v, n))
    } else {
        Err(SdoAbortCode::SUB_INDEX_DOES_NOT_EXIST)
    }
}

/// A write to a read-only simple variable.
fn read_only(sub: u8) -> Result<(), SdoAbortCode> {
    var(sub, 0, 0).and(Err(SdoAbortCode::READ_ONLY))
}

/// A COB-ID entry (0x1005, 0x1014): 11-bit identifier, no bits in 11..=28, no 29-bit
/// frames; a valid entry's identifier changes only through an invalid one (CiA 301).
fn cob_id_entry(old: u32, data: &[u8], reserved: u32) -> Result<u32, SdoAbortCode> {
    let v = le(data, 4)? as u32;
    if v & (COB_ID_EXTENDED | reserved | 0x1FFF_F800) != 0 {
        return Err(SdoAbortCode::VALUE_RANGE_EXCEEDED);
    }
    let both_valid = old & COB_ID_INVALID == 0 && v & COB_ID_INVALID == 0;
    if both_valid && (old & 0x7FF) != (v & 0x7FF) {
        return Err(SdoAbortCode::VALUE_RANGE_EXCEEDED);
    }
    Ok(v)
}

impl ObjectDictionary for Objects {
    fn read(&mut self, index: u16, sub: u8, buf: &mut [u8]) -> Result<usize, SdoAbortCode> {
        if let Some(p) = self.pdo_mut(index) {
            return p.read(index, sub, buf);
        }
        let (v, n) = match index {
            obj::DEVICE_TYPE => var(sub, DEVICE_TYPE as u64, 4)?,
            obj::ERROR_REGISTER => var(sub, self.error_register() as u64, 1)?,
            obj::COB_ID_SYNC => var(sub, self.comm.sync_cob_id as u64, 4)?,
            obj::COMMUNICATION_CYCLE_PERIOD => var(sub, self.comm.cycle_period_us as u64, 4)?,
            obj::MANUFACTURER_DEVICE_NAME => {
                var(sub, 0, 0)?;
                let name = self.device_name;
                buf.get_mut(..name.len())
                    .ok_or(SdoAbortCode::OUT_OF_MEMORY)?
                    .copy_from_slice(name);
                return Ok(name.len());
            }
            obj::COB_ID_EMCY => var(sub, self.comm.emcy_cob_id as u64, 4)?,
            obj::PRODUCER_HEARTBEAT_TIME => var(sub, self.comm.heartbeat_ms as u64, 2)?,
            obj::CONSUMER_HEARTBEAT_TIME => match sub {
                0 => (1, 1),
                1 => (self.comm.heartbeat_consumer as u64, 4),
                _ => return Err(SdoAbortCode::SUB_INDEX_DOES_NOT_EXIST),
            },
            obj::ABORT_CONNECTION_OPTION_CODE => {
                var(sub, self.app.abort_connection as u16 as u64, 2)?
            }
            obj::IDENTITY => match sub {
                0 => (4, 1),
                1 => (VENDOR_ID as u64, 4),
                2 => (PRODUCT_CODE as u64, 4),
                3 => (REVISION as u64, 4),
                4 => (self.node as u64, 4),
                _ => return Err(SdoAbortCode::SUB_INDEX_DOES_NOT_EXIST),
            },
            obj::SUPPORTED_DRIVE_MODES => var(sub, self.supported_modes as u64, 4)?,
            // An axis drive has no profile modes, so none of their objects.
            obj::PROFILE_VELOCITY if self.has_profile_position() => {
                var(sub, self.app.profile_velocity as u64, 4)?
            }
            obj::PROFILE_ACCELERATION if self.has_profile_position() => {
                var(sub, self.app.profile_acceleration as u64, 4)?
            }
            obj::PROFILE_DECELERATION if self.has_profile_position() => {
                var(sub, self.app.profile_deceleration as u64, 4)?
            }
            _ => match (self.mapped_value(index, 0), Self::object_bits(index, 0)) {
                (Some(v), Some(bits)) => var(sub, v, bits as usize / 8)?,
                _ => return Err(SdoAbortCode::OBJECT_DOES_NOT_EXIST),
            },
        };
        put(buf, v, n)
    }

    fn write(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), SdoAbortCode> {
        if let Some(p) = self.pdo_mut(index) {
            let direction = p.direction();
            return p.write(index, sub, data, |e| Self::mappable(direction, e));
        }
        match index {
            obj::DEVICE_TYPE
            | obj::ERROR_REGISTER
            | obj::MANUFACTURER_DEVICE_NAME
            | obj::SUPPORTED_DRIVE_MODES
            | obj::STATUSWORD
            | obj::MODES_OF_OPERATION_DISPLAY
            | obj::POSITION_ACTUAL_VALUE
            | obj::ERROR_CODE
            | obj::TOUCH_PROBE_STATUS
            | obj::TOUCH_PROBE_1_POSITIVE_EDGE => read_only(sub),
            obj::IDENTITY => match sub {
                0..=4 => Err(SdoAbortCode::READ_ONLY),
                _ => Err(SdoAbortCode::SUB_INDEX_DOES_NOT_EXIST),
            },
            obj::CONSUMER_HEARTBEAT_TIME => match sub {
                0 => Err(SdoAbortCode::READ_ONLY),
                1 => {
                    let v = le(data, 4)? as u32;
                    // Bits 24-31 are reserved; a node ID is 1..=127 (0 with time 0:
                    // the entry is off).
                    let node = (v >> 16) & 0xFF;
                    if v >> 24 != 0 || node > 127 || (node == 0 && v & 0xFFFF != 0) {
                        return Err(SdoAbortCode::VALUE_RANGE_EXCEEDED);
                    }
                    self.comm.heartbeat_consumer = v;
                    self.consumer_restart = true;
                    Ok(())
                }
                _ => Err(SdoAbortCode::SUB_INDEX_DOES_NOT_EXIST),
            },
            obj::ABORT_CONNECTION_OPTION_CODE => {
                var(sub, 0, 0)?;
                let v = le(data, 2)? as u16 as i16;
                if !(abort_connection::NO_ACTION..=abort_connection::QUICK_STOP).contains(&v) {
                    return Err(SdoAbortCode::VALUE_RANGE_EXCEEDED);
                }
                self.app.abort_connection = v;
                Ok(())
            }
            obj::COB_ID_SYNC => {
                var(sub, 0, 0)?;
                // Bit 30 would make this drive the SYNC producer: it is not one.
                self.comm.sync_cob_id = cob_id_entry(self.comm.sync_cob_id, data, 1 << 30)?;
                Ok(())
            }
            obj::COB_ID_EMCY => {
                var(sub, 0, 0)?;
                self.comm.emcy_cob_id = cob_id_entry(self.comm.emcy_cob_id, data, 1 << 30)?;
                Ok(())
            }
            obj::COMMUNICATION_CYCLE_PERIOD => {
                var(sub, 0, 0)?;
                self.comm.cycle_period_us = le(data, 4)? as u32;
                Ok(())
            }
            obj::PRODUCER_HEARTBEAT_TIME => {
                var(sub, 0, 0)?;
                self.comm.heartbeat_ms = le(data, 2)? as u16;
                self.heartbeat_restart = true;
                Ok(())
            }
            obj::MODES_OF_OPERATION => {
                var(sub, 0, 0)?;
                let m = le(data, 1)? as u8 as i8;
                // Only the modes 0x6502 names: an axis drive cyclic synchronous
                // position, a spindle drive profile position.
                let bit = match m {
                    CYCLIC_SYNCHRONOUS_POSITION => 1 << 7,
                    PROFILE_POSITION => 1 << 0,
                    _ => 0,
                };
                if self.supported_modes & bit == 0 {
                    return Err(SdoAbortCode::VALUE_RANGE_EXCEEDED);
                }
                self.app.mode = m;
                Ok(())
            }
            obj::PROFILE_VELOCITY | obj::PROFILE_ACCELERATION | obj::PROFILE_DECELERATION => {
                var(sub, 0, 0)?;
                if !self.has_profile_position() {
                    return Err(SdoAbortCode::OBJECT_DOES_NOT_EXIST);
                }
                let v = le(data, 4)? as u32;
                match index {
                    obj::PROFILE_VELOCITY => self.app.profile_velocity = v,
                    obj::PROFILE_ACCELERATION => self.app.profile_acceleration = v,
                    _ => self.app.profile_deceleration = v,
                }
                Ok(())
            }
            obj::CONTROLWORD | obj::TARGET_POSITION | obj::TOUCH_PROBE_FUNCTION => {
                var(sub, 0, 0)?;
                let bits = Self::object_bits(index, sub).unwrap_or(16);
                let v = le(data, bits as usize / 8)?;
                self.write_mapped(index, sub, v)
            }
            _ => Err(SdoAbortCode::OBJECT_DOES_NOT_EXIST),
        }
    }
}
