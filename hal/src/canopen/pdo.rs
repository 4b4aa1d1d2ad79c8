//! Process data objects (CiA 301): mapping entries, packing mapped values into the up
//! to 8 data bytes (little-endian, bit-packed in mapping order), the SDO sequence that
//! configures a PDO, and the device-side objects that accept that sequence.

use heapless::Vec;

use super::sdo::SdoAbortCode;
use super::{check_data, cob_id, object, DecodeError};

/// One mapping entry as stored in 0x1600.. / 0x1A00..: `index << 16 | sub << 8 | bits`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct MapEntry {
    pub index: u16,
    pub sub: u8,
    pub bits: u8,
}

impl MapEntry {
    pub const fn new(index: u16, sub: u8, bits: u8) -> Self {
        Self { index, sub, bits }
    }

    pub const fn to_u32(self) -> u32 {
        (self.index as u32) << 16 | (self.sub as u32) << 8 | self.bits as u32
    }

    pub const fn from_u32(v: u32) -> Self {
        Self {
            index: (v >> 16) as u16,
            sub: (v >> 8) as u8,
            bits: v as u8,
        }
    }
}

/// Maximum entries in one PDO mapping (one per byte of a classic CAN frame).
pub const MAX_ENTRIES: usize = 8;

#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum PdoMappingError {
    #[error("a PDO maps at most {MAX_ENTRIES} objects")]
    TooManyEntries,
    #[error("the mapped objects need {total_bits} bits, a PDO carries at most 64")]
    TooManyBits { total_bits: u32 },
    #[error("mapping entry {index:#06X}:{sub} has length 0 or more than 64 bits ({bits})")]
    InvalidLength { index: u16, sub: u8, bits: u8 },
    #[error("PDO number {0} is outside 1..=4")]
    InvalidPdoNumber(u8),
}

/// The objects one PDO carries, in order; at most 8 entries and 64 bits.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PdoMapping {
    entries: Vec<MapEntry, MAX_ENTRIES>,
}

const SERVICE: &str = "PDO";

impl PdoMapping {
    pub const fn new() -> Self {
        Self {
            entries: Vec::new(),
        }
    }

    pub fn from_entries(entries: &[MapEntry]) -> Result<Self, PdoMappingError> {
        let mut m = Self::new();
        for &e in entries {
            m.push(e)?;
        }
        Ok(m)
    }

    pub fn push(&mut self, e: MapEntry) -> Result<(), PdoMappingError> {
        if e.bits == 0 || e.bits > 64 {
            return Err(PdoMappingError::InvalidLength {
                index: e.index,
                sub: e.sub,
                bits: e.bits,
            });
        }
        let total_bits = self.total_bits() + u32::from(e.bits);
        if total_bits > 64 {
            return Err(PdoMappingError::TooManyBits { total_bits });
        }
        self.entries
            .push(e)
            .map_err(|_| PdoMappingError::TooManyEntries)
    }

    pub fn entries(&self) -> &[MapEntry] {
        &self.entries
    }

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    pub fn total_bits(&self) -> u32 {
        self.entries.iter().map(|e| u32::from(e.bits)).sum()
    }

    /// Data bytes of the PDO frame.
    pub fn byte_len(&self) -> usize {
        self.total_bits().div_ceil(8) as usize
    }

    /// Packs `values` (one per entry, in order, each truncated to its entry's width)
    /// into the PDO data; returns the bytes and the frame length. Missing values are
    /// sent as 0. Signed values go in as their two's-complement bits (`i32 as u32`).
    pub fn pack(&self, values: &[u64]) -> ([u8; 8], usize) {
        debug_assert_eq!(values.len(), self.entries.len(), "one value per entry");
        pack(&self.entries, values)
    }

    /// Splits PDO data into one value per entry (zero-extended; sign-extend with
    /// [`sign_extend`]). Longer data is accepted (CiA 301: extra bytes are ignored),
    /// shorter is an error.
    pub fn unpack(&self, data: &[u8]) -> Result<Vec<u64, MAX_ENTRIES>, DecodeError> {
        unpack(&self.entries, data)
    }

    /// [`PdoMapping::unpack`] of a received frame, rejecting remote frames.
    pub fn unpack_frame(
        &self,
        f: &crate::can::CanFrame,
    ) -> Result<Vec<u64, MAX_ENTRIES>, DecodeError> {
        unpack_frame(&self.entries, f)
    }
}

/// Data bytes of a PDO carrying `entries`.
pub fn byte_len(entries: &[MapEntry]) -> usize {
    entries
        .iter()
        .map(|e| u32::from(e.bits))
        .sum::<u32>()
        .div_ceil(8) as usize
}

/// [`PdoMapping::pack`] over a list of entries (a layout known at compile time).
pub fn pack(entries: &[MapEntry], values: &[u64]) -> ([u8; 8], usize) {
    let mut acc = 0u64;
    let mut offset = 0u32;
    for (i, e) in entries.iter().enumerate() {
        let v = values.get(i).copied().unwrap_or(0) & mask(e.bits);
        // A mapping of 64 bits ends at offset 64: nothing is shifted past it.
        if offset < 64 {
            acc |= v << offset;
        }
        offset += u32::from(e.bits);
    }
    (acc.to_le_bytes(), byte_len(entries))
}

/// [`PdoMapping::unpack`] over a list of entries.
pub fn unpack(entries: &[MapEntry], data: &[u8]) -> Result<Vec<u64, MAX_ENTRIES>, DecodeError> {
    let need = byte_len(entries);
    if data.len() < need {
        return Err(DecodeError::WrongLength {
            service: SERVICE,
            found: data.len(),
            min: need,
            max: 8,
        });
    }
    let mut raw = [0u8; 8];
    let n = data.len().min(8);
    raw[..n].copy_from_slice(&data[..n]);
    let acc = u64::from_le_bytes(raw);
    let mut out = Vec::new();
    let mut offset = 0u32;
    for e in entries.iter().take(MAX_ENTRIES) {
        let v = if offset < 64 { acc >> offset } else { 0 };
        // At most MAX_ENTRIES entries: never exceeds the capacity.
        let _ = out.push(v & mask(e.bits));
        offset += u32::from(e.bits);
    }
    Ok(out)
}

/// [`unpack`] of a received frame, rejecting remote frames and short data.
pub fn unpack_frame(
    entries: &[MapEntry],
    f: &crate::can::CanFrame,
) -> Result<Vec<u64, MAX_ENTRIES>, DecodeError> {
    check_data(SERVICE, f, byte_len(entries), 8)?;
    unpack(entries, f.data())
}

const fn mask(bits: u8) -> u64 {
    if bits >= 64 {
        u64::MAX
    } else {
        (1u64 << bits) - 1
    }
}

/// Sign-extends the low `bits` of `v` (for signed mapped objects).
pub const fn sign_extend(v: u64, bits: u8) -> i64 {
    if bits == 0 || bits >= 64 {
        return v as i64;
    }
    let shift = 64 - bits as u32;
    ((v << shift) as i64) >> shift
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PdoDirection {
    /// Received by the device (master to drive).
    Rpdo,
    /// Transmitted by the device (drive to master).
    Tpdo,
}

fn check_num(num: u8) -> Result<u16, PdoMappingError> {
    match num {
        1..=4 => Ok(u16::from(num - 1)),
        _ => Err(PdoMappingError::InvalidPdoNumber(num)),
    }
}

/// Communication parameter index (0x1400 + n - 1 / 0x1800 + n - 1).
pub fn communication_index(direction: PdoDirection, num: u8) -> Result<u16, PdoMappingError> {
    let base = match direction {
        PdoDirection::Rpdo => object::RPDO_COMMUNICATION,
        PdoDirection::Tpdo => object::TPDO_COMMUNICATION,
    };
    Ok(base + check_num(num)?)
}

/// Mapping parameter index (0x1600 + n - 1 / 0x1A00 + n - 1).
pub fn mapping_index(direction: PdoDirection, num: u8) -> Result<u16, PdoMappingError> {
    let base = match direction {
        PdoDirection::Rpdo => object::RPDO_MAPPING,
        PdoDirection::Tpdo => object::TPDO_MAPPING,
    };
    Ok(base + check_num(num)?)
}

/// COB-ID entry bit 31: PDO does not exist / is not valid.
pub const COB_ID_INVALID: u32 = 1 << 31;
/// COB-ID entry bit 30 (TPDO): no RTR allowed on this PDO.
pub const COB_ID_NO_RTR: u32 = 1 << 30;
/// COB-ID entry bit 29: 29-bit identifier (not used by this project).
pub const COB_ID_EXTENDED: u32 = 1 << 29;

/// The COB-ID entry value (sub 1) for the predefined connection set, enabled. TPDOs
/// get "no RTR" set: nothing here polls PDOs and CiA recommends against RTR.
pub fn default_cob_id_entry(
    direction: PdoDirection,
    num: u8,
    node: u8,
) -> Result<u32, PdoMappingError> {
    check_num(num)?;
    Ok(match direction {
        PdoDirection::Rpdo => u32::from(cob_id::rpdo_cob(num, node)),
        PdoDirection::Tpdo => u32::from(cob_id::tpdo_cob(num, node)) | COB_ID_NO_RTR,
    })
}

/// One SDO download of a configuration sequence: `size` bytes of `value`, LE.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SdoWrite {
    pub index: u16,
    pub sub: u8,
    pub value: u32,
    pub size: u8,
}

impl SdoWrite {
    pub const fn new(index: u16, sub: u8, value: u32, size: u8) -> Self {
        Self {
            index,
            sub,
            value,
            size,
        }
    }

    /// The `size` low bytes of `value`, little-endian.
    pub fn payload(&self) -> Vec<u8, 4> {
        let b = self.value.to_le_bytes();
        let n = usize::from(self.size.min(4));
        let mut v = Vec::new();
        let _ = v.extend_from_slice(&b[..n]);
        v
    }
}

/// The CiA 301 sequence that (re)configures PDO `num` of `node`: invalidate the
/// COB-ID, transmission type, mapping count 0, the entries, the count, COB-ID valid.
///
/// # Panics
/// If `num` is not 1..=4.
pub fn configuration_writes(
    direction: PdoDirection,
    num: u8,
    node: u8,
    mapping: &PdoMapping,
    transmission_type: u8,
) -> Vec<SdoWrite, 16> {
    assert!((1..=4).contains(&num), "PDO number must be 1..=4");
    let off = u16::from(num - 1);
    let (comm, map) = match direction {
        PdoDirection::Rpdo => (object::RPDO_COMMUNICATION + off, object::RPDO_MAPPING + off),
        PdoDirection::Tpdo => (object::TPDO_COMMUNICATION + off, object::TPDO_MAPPING + off),
    };
    let cob = match direction {
        PdoDirection::Rpdo => u32::from(cob_id::rpdo_cob(num, node)),
        PdoDirection::Tpdo => u32::from(cob_id::tpdo_cob(num, node)) | COB_ID_NO_RTR,
    };
    let mut w: Vec<SdoWrite, 16> = Vec::new();
    // At most 5 + MAX_ENTRIES = 13 writes: never exceeds the capacity.
    let _ = w.push(SdoWrite::new(comm, 1, cob | COB_ID_INVALID, 4));
    let _ = w.push(SdoWrite::new(comm, 2, u32::from(transmission_type), 1));
    let _ = w.push(SdoWrite::new(map, 0, 0, 1));
    for (i, e) in mapping.entries().iter().enumerate() {
        let _ = w.push(SdoWrite::new(map, i as u8 + 1, e.to_u32(), 4));
    }
    let _ = w.push(SdoWrite::new(map, 0, mapping.entries().len() as u32, 1));
    let _ = w.push(SdoWrite::new(comm, 1, cob, 4));
    w
}

/// Device side of one PDO: its communication (0x1400../0x1800..) and mapping
/// (0x1600../0x1A00..) objects, accepting exactly what CiA 301 allows, so a simulated
/// drive rejects what a real one would.
#[derive(Clone, Debug)]
pub struct PdoParameters {
    direction: PdoDirection,
    comm_index: u16,
    map_index: u16,
    cob_id: u32,
    transmission_type: u8,
    inhibit_time_100us: u16,
    event_timer_ms: u16,
    staged: [u32; MAX_ENTRIES],
    count: u8,
    mapping: PdoMapping,
}

impl PdoParameters {
    /// Predefined connection set COB-ID, enabled, empty mapping, transmission type
    /// 255 (event driven, device profile).
    pub fn new(direction: PdoDirection, num: u8, node: u8) -> Result<Self, PdoMappingError> {
        Ok(Self {
            direction,
            comm_index: communication_index(direction, num)?,
            map_index: mapping_index(direction, num)?,
            cob_id: default_cob_id_entry(direction, num, node)?,
            transmission_type: 255,
            inhibit_time_100us: 0,
            event_timer_ms: 0,
            staged: [0; MAX_ENTRIES],
            count: 0,
            mapping: PdoMapping::new(),
        })
    }

    pub fn direction(&self) -> PdoDirection {
        self.direction
    }

    /// Valid: COB-ID entry bit 31 clear.
    pub fn is_enabled(&self) -> bool {
        self.cob_id & COB_ID_INVALID == 0
    }

    /// The 11-bit identifier the PDO uses.
    pub fn cob_id(&self) -> u16 {
        (self.cob_id & 0x7FF) as u16
    }

    pub fn transmission_type(&self) -> u8 {
        self.transmission_type
    }

    pub fn event_timer_ms(&self) -> u16 {
        self.event_timer_ms
    }

    /// Least time between two transmissions of an event-driven TPDO, 100 µs units.
    pub fn inhibit_time_100us(&self) -> u16 {
        self.inhibit_time_100us
    }

    /// The active mapping (changes only when the count is written).
    pub fn mapping(&self) -> &PdoMapping {
        &self.mapping
    }

    /// Whether `index` is one of this PDO's two objects.
    pub fn handles(&self, index: u16) -> bool {
        index == self.comm_index || index == self.map_index
    }

    pub fn read(&self, index: u16, sub: u8, buf: &mut [u8]) -> Result<usize, SdoAbortCode> {
        let (v, size): (u32, usize) = if index == self.comm_index {
            match sub {
                0 => (5, 1),
                1 => (self.cob_id, 4),
                2 => (self.transmission_type.into(), 1),
                3 => (self.inhibit_time_100us.into(), 2),
                5 => (self.event_timer_ms.into(), 2),
                _ => return Err(SdoAbortCode::SUB_INDEX_DOES_NOT_EXIST),
            }
        } else if index == self.map_index {
            match sub {
                0 => (self.count.into(), 1),
                1..=8 => (self.staged[usize::from(sub - 1)], 4),
                _ => return Err(SdoAbortCode::SUB_INDEX_DOES_NOT_EXIST),
            }
        } else {
            return Err(SdoAbortCode::OBJECT_DOES_NOT_EXIST);
        };
        let dst = buf.get_mut(..size).ok_or(SdoAbortCode::GENERAL_ERROR)?;
        dst.copy_from_slice(&v.to_le_bytes()[..size]);
        Ok(size)
    }

    /// `mappable` says whether the device can map an entry (object exists, may be
    /// mapped in this direction, length matches).
    pub fn write(
        &mut self,
        index: u16,
        sub: u8,
        data: &[u8],
        mappable: impl Fn(MapEntry) -> bool,
    ) -> Result<(), SdoAbortCode> {
        if index == self.comm_index {
            match sub {
                0 => Err(SdoAbortCode::READ_ONLY),
                1 => self.write_cob_id(value(data, 4)?),
                2 => {
                    let tt = value(data, 1)? as u8;
                    // 241..=251 reserved; 252/253 (RTR) exist only for TPDOs.
                    let ok = match self.direction {
                        PdoDirection::Rpdo => tt <= 240 || tt >= 254,
                        PdoDirection::Tpdo => tt <= 240 || tt >= 252,
                    };
                    if !ok {
                        return Err(SdoAbortCode::VALUE_RANGE_EXCEEDED);
                    }
                    self.transmission_type = tt;
                    Ok(())
                }
                3 => {
                    // CiA 301: inhibit time may change only while the PDO is invalid.
                    if self.is_enabled() {
                        return Err(SdoAbortCode::UNSUPPORTED_ACCESS);
                    }
                    self.inhibit_time_100us = value(data, 2)? as u16;
                    Ok(())
                }
                5 => {
                    self.event_timer_ms = value(data, 2)? as u16;
                    Ok(())
                }
                _ => Err(SdoAbortCode::SUB_INDEX_DOES_NOT_EXIST),
            }
        } else if index == self.map_index {
            // CiA 301: the mapping changes only with the PDO invalid, entries only
            // with the count at 0.
            if sub > 8 {
                return Err(SdoAbortCode::SUB_INDEX_DOES_NOT_EXIST);
            }
            if self.is_enabled() {
                return Err(SdoAbortCode::UNSUPPORTED_ACCESS);
            }
            if sub == 0 {
                return self.write_count(value(data, 1)? as u8);
            }
            if self.count != 0 {
                return Err(SdoAbortCode::UNSUPPORTED_ACCESS);
            }
            let raw = value(data, 4)?;
            let e = MapEntry::from_u32(raw);
            if e.bits == 0 || e.bits > 64 || !mappable(e) {
                return Err(SdoAbortCode::CANNOT_BE_MAPPED);
            }
            self.staged[usize::from(sub - 1)] = raw;
            Ok(())
        } else {
            Err(SdoAbortCode::OBJECT_DOES_NOT_EXIST)
        }
    }

    fn write_cob_id(&mut self, v: u32) -> Result<(), SdoAbortCode> {
        if v & COB_ID_EXTENDED != 0 || v & 0x1FFF_F800 != 0 {
            return Err(SdoAbortCode::VALUE_RANGE_EXCEEDED);
        }
        // CiA 301: a valid PDO's identifier cannot change without invalidating first.
        let both_valid = self.is_enabled() && v & COB_ID_INVALID == 0;
        if both_valid && (v & 0x7FF) != (self.cob_id & 0x7FF) {
            return Err(SdoAbortCode::VALUE_RANGE_EXCEEDED);
        }
        self.cob_id = v;
        Ok(())
    }

    fn write_count(&mut self, count: u8) -> Result<(), SdoAbortCode> {
        if usize::from(count) > MAX_ENTRIES {
            return Err(SdoAbortCode::VALUE_RANGE_EXCEEDED);
        }
        let mut m = PdoMapping::new();
        for &raw in &self.staged[..usize::from(count)] {
            m.push(MapEntry::from_u32(raw)).map_err(|e| match e {
                PdoMappingError::TooManyBits { .. } => SdoAbortCode::PDO_LENGTH_EXCEEDED,
                _ => SdoAbortCode::CANNOT_BE_MAPPED,
            })?;
        }
        self.mapping = m;
        self.count = count;
        Ok(())
    }
}

/// A value of exactly `size` bytes, LE.
fn value(data: &[u8], size: usize) -> Result<u32, SdoAbortCode> {
    if data.len() > size {
        return Err(SdoAbortCode::LENGTH_TOO_HIGH);
    }
    if data.len() < size {
        return Err(SdoAbortCode::LENGTH_TOO_LOW);
    }
    let mut b = [0u8; 4];
    b[..size].copy_from_slice(data);
    Ok(u32::from_le_bytes(b))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bit_packing() {
        let m = PdoMapping::from_entries(&[
            MapEntry::new(0x6041, 0, 16),
            MapEntry::new(0x0001, 0, 4),
            MapEntry::new(0x2000, 1, 12),
        ])
        .unwrap();
        let (d, n) = m.pack(&[0x1234, 0xF, 0xABC]);
        assert_eq!(n, 4);
        assert_eq!(&d[..4], &[0x34, 0x12, 0xCF, 0xAB]);
        assert_eq!(m.unpack(&d[..4]).unwrap().as_slice(), &[0x1234, 0xF, 0xABC]);
        assert_eq!(sign_extend(0xFFF, 12), -1);
        assert_eq!(sign_extend(0x7FF, 12), 0x7FF);
        let full = PdoMapping::from_entries(&[MapEntry::new(0x2000, 0, 64)]).unwrap();
        let (d, n) = full.pack(&[u64::MAX - 1]);
        assert_eq!((n, d[0], d[7]), (8, 0xFE, 0xFF));
    }

    #[test]
    fn mapping_limits() {
        let mut m = PdoMapping::new();
        for _ in 0..8 {
            m.push(MapEntry::new(0x2000, 0, 8)).unwrap();
        }
        assert_eq!(
            m.push(MapEntry::new(0x2000, 0, 1)),
            Err(PdoMappingError::TooManyBits { total_bits: 65 })
        );
        let mut m = PdoMapping::new();
        for _ in 0..8 {
            m.push(MapEntry::new(0x2000, 0, 1)).unwrap();
        }
        assert_eq!(
            m.push(MapEntry::new(0x2000, 0, 1)),
            Err(PdoMappingError::TooManyEntries)
        );
        assert!(m.push(MapEntry::new(0x2000, 0, 0)).is_err());
    }

    #[test]
    fn device_objects_follow_cia301_procedure() {
        let mut p = PdoParameters::new(PdoDirection::Tpdo, 1, 3).unwrap();
        let any = |_: MapEntry| true;
        // Mapping locked while valid.
        assert_eq!(
            p.write(0x1A00, 0, &[0], any),
            Err(SdoAbortCode::UNSUPPORTED_ACCESS)
        );
        // Identifier of a valid PDO cannot change.
        assert_eq!(
            p.write(0x1800, 1, &0x4000_0184u32.to_le_bytes(), any),
            Err(SdoAbortCode::VALUE_RANGE_EXCEEDED)
        );
        p.write(0x1800, 1, &0xC000_0183u32.to_le_bytes(), any)
            .unwrap();
        p.write(0x1A00, 0, &[0], any).unwrap();
        p.write(0x1A00, 1, &0x6064_0020u32.to_le_bytes(), any)
            .unwrap();
        p.write(0x1A00, 2, &0x6064_0020u32.to_le_bytes(), any)
            .unwrap();
        p.write(0x1A00, 3, &0x6041_0010u32.to_le_bytes(), any)
            .unwrap();
        assert_eq!(
            p.write(0x1A00, 0, &[3], any),
            Err(SdoAbortCode::PDO_LENGTH_EXCEEDED)
        );
        p.write(0x1A00, 0, &[2], any).unwrap();
        assert_eq!(
            p.write(0x1A00, 1, &0x6041_0010u32.to_le_bytes(), any),
            Err(SdoAbortCode::UNSUPPORTED_ACCESS)
        );
        assert_eq!(
            p.write(0x1A00, 4, &0x6041_0010u32.to_le_bytes(), |_| false),
            Err(SdoAbortCode::UNSUPPORTED_ACCESS)
        );
        assert_eq!(
            p.write(0x1800, 2, &[0, 0], any),
            Err(SdoAbortCode::LENGTH_TOO_HIGH)
        );
        assert_eq!(
            p.write(0x1800, 2, &[245], any),
            Err(SdoAbortCode::VALUE_RANGE_EXCEEDED)
        );
        p.write(0x1800, 2, &[1], any).unwrap();
        p.write(0x1800, 1, &0x4000_0183u32.to_le_bytes(), any)
            .unwrap();
        assert!(p.is_enabled());
        assert_eq!(p.cob_id(), 0x183);
        assert_eq!(p.mapping().total_bits(), 64);
        let mut buf = [0u8; 8];
        assert_eq!(p.read(0x1A00, 2, &mut buf), Ok(4));
        assert_eq!(&buf[..4], &0x6064_0020u32.to_le_bytes());
        assert_eq!(
            p.read(0x1A01, 0, &mut buf),
            Err(SdoAbortCode::OBJECT_DOES_NOT_EXIST)
        );
    }
}
