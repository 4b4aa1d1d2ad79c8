//! The process data layout the master configures on every drive, as typed values
//! ([`Rpdo1`], [`Tpdo1`], [`Rpdo2`], [`Tpdo2`]), and what it costs on the bus. Each
//! type's mapping is the only description of its layout: the SDO configuration, the
//! encoding and the decoding are derived from it, on the master and in the tests.
//!
//! Cyclic (every SYNC):
//! - RPDO1: controlword 0x6040 (16) + target position 0x607A (32), applied at SYNC;
//! - TPDO1: statusword 0x6041 (16) + position actual value 0x6064 (32), sampled at SYNC.
//!
//! Event-driven (sent when the value changes, so they cost nothing while idle):
//! - RPDO2: touch probe function 0x60B8 (16);
//! - TPDO2: touch probe status 0x60B9 (16) + touch probe 1 positive edge 0x60BA (32).
//!   This is the latch frame: one frame carries "edge stored" and the latched value.

use crate::can::CanFrame;
use crate::canopen::object;
use crate::canopen::pdo::{self, MapEntry, PdoDirection, PdoMapping, MAX_ENTRIES};
use crate::canopen::{cob_id, DecodeError};
use crate::config::{CanOpenBusConfig, MachineConfig};

/// One PDO of the layout the master configures: where it goes, what it maps, and the
/// typed value it carries. The mapping is the single description of the layout: the
/// SDO configuration, the encoding and the decoding are all derived from it.
pub trait ProcessData: Sized + Copy {
    const DIRECTION: PdoDirection;
    /// PDO number, 1..=4.
    const NUMBER: u8;
    /// CiA 301 transmission type (1: every SYNC, 255: on change).
    const TRANSMISSION_TYPE: u8;
    /// The mapped objects, in frame order.
    const MAPPING: &'static [MapEntry];

    /// One raw value per mapping entry, in order (signed values as their bits).
    fn to_values(&self) -> [u64; MAX_ENTRIES];

    /// The inverse of [`ProcessData::to_values`]; `v` has one value per entry.
    fn from_values(v: &[u64]) -> Self;

    /// The PDO's identifier for `node` (predefined connection set).
    fn cob_id(node: u8) -> u16 {
        match Self::DIRECTION {
            PdoDirection::Rpdo => cob_id::rpdo_cob(Self::NUMBER, node),
            PdoDirection::Tpdo => cob_id::tpdo_cob(Self::NUMBER, node),
        }
    }

    /// The frame `node` receives (RPDO) or sends (TPDO).
    fn encode(&self, node: u8) -> CanFrame {
        let (data, len) = pdo::pack(Self::MAPPING, &self.to_values()[..Self::MAPPING.len()]);
        crate::canopen::frame(Self::cob_id(node), &data[..len])
    }

    /// The value of a received PDO (the caller matched its identifier). Longer data is
    /// accepted (CiA 301), shorter data and remote frames are not.
    fn decode(f: &CanFrame) -> Result<Self, DecodeError> {
        let v = pdo::unpack_frame(Self::MAPPING, f)?;
        Ok(Self::from_values(&v))
    }
}

/// The bits of a signed mapped value.
const fn bits_i32(v: i32) -> u64 {
    v as u32 as u64
}

/// A signed 32-bit mapped value from its bits.
const fn from_bits_i32(v: u64) -> i32 {
    v as u32 as i32
}

/// RPDO1, every SYNC: controlword and target position (cyclic synchronous position).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Rpdo1 {
    pub controlword: u16,
    /// Increments.
    pub target_position: i32,
}

impl ProcessData for Rpdo1 {
    const DIRECTION: PdoDirection = PdoDirection::Rpdo;
    const NUMBER: u8 = 1;
    const TRANSMISSION_TYPE: u8 = 1;
    const MAPPING: &'static [MapEntry] = &[
        MapEntry::new(object::CONTROLWORD, 0, 16),
        MapEntry::new(object::TARGET_POSITION, 0, 32),
    ];

    fn to_values(&self) -> [u64; MAX_ENTRIES] {
        let mut v = [0; MAX_ENTRIES];
        v[0] = u64::from(self.controlword);
        v[1] = bits_i32(self.target_position);
        v
    }

    fn from_values(v: &[u64]) -> Self {
        Self {
            controlword: v[0] as u16,
            target_position: from_bits_i32(v[1]),
        }
    }
}

/// TPDO1, sampled at every SYNC: statusword and position actual value.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Tpdo1 {
    pub statusword: u16,
    /// Increments.
    pub position_actual: i32,
}

impl ProcessData for Tpdo1 {
    const DIRECTION: PdoDirection = PdoDirection::Tpdo;
    const NUMBER: u8 = 1;
    const TRANSMISSION_TYPE: u8 = 1;
    const MAPPING: &'static [MapEntry] = &[
        MapEntry::new(object::STATUSWORD, 0, 16),
        MapEntry::new(object::POSITION_ACTUAL_VALUE, 0, 32),
    ];

    fn to_values(&self) -> [u64; MAX_ENTRIES] {
        let mut v = [0; MAX_ENTRIES];
        v[0] = u64::from(self.statusword);
        v[1] = bits_i32(self.position_actual);
        v
    }

    fn from_values(v: &[u64]) -> Self {
        Self {
            statusword: v[0] as u16,
            position_actual: from_bits_i32(v[1]),
        }
    }
}

/// RPDO2, on change: the touch probe function.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Rpdo2 {
    pub touch_probe_function: u16,
}

impl ProcessData for Rpdo2 {
    const DIRECTION: PdoDirection = PdoDirection::Rpdo;
    const NUMBER: u8 = 2;
    const TRANSMISSION_TYPE: u8 = 255;
    const MAPPING: &'static [MapEntry] = &[MapEntry::new(object::TOUCH_PROBE_FUNCTION, 0, 16)];

    fn to_values(&self) -> [u64; MAX_ENTRIES] {
        let mut v = [0; MAX_ENTRIES];
        v[0] = u64::from(self.touch_probe_function);
        v
    }

    fn from_values(v: &[u64]) -> Self {
        Self {
            touch_probe_function: v[0] as u16,
        }
    }
}

/// TPDO2, on change: the touch probe status and the position latched at probe 1's
/// positive edge. The latch frame: one frame carries "edge stored" and the value.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Tpdo2 {
    pub touch_probe_status: u16,
    /// Increments.
    pub probe1_positive_edge: i32,
}

impl ProcessData for Tpdo2 {
    const DIRECTION: PdoDirection = PdoDirection::Tpdo;
    const NUMBER: u8 = 2;
    const TRANSMISSION_TYPE: u8 = 255;
    const MAPPING: &'static [MapEntry] = &[
        MapEntry::new(object::TOUCH_PROBE_STATUS, 0, 16),
        MapEntry::new(object::TOUCH_PROBE_1_POSITIVE_EDGE, 0, 32),
    ];

    fn to_values(&self) -> [u64; MAX_ENTRIES] {
        let mut v = [0; MAX_ENTRIES];
        v[0] = u64::from(self.touch_probe_status);
        v[1] = bits_i32(self.probe1_positive_edge);
        v
    }

    fn from_values(v: &[u64]) -> Self {
        Self {
            touch_probe_status: v[0] as u16,
            probe1_positive_edge: from_bits_i32(v[1]),
        }
    }
}

/// One PDO of the layout as the start-up configures it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PdoLayout {
    pub direction: PdoDirection,
    pub number: u8,
    pub transmission_type: u8,
    pub mapping: &'static [MapEntry],
}

impl PdoLayout {
    /// The mapping as written to the drive over SDO.
    pub fn mapping(&self) -> PdoMapping {
        // Every layout here is well within 64 bits and 8 entries (tested below).
        PdoMapping::from_entries(self.mapping).expect("static PDO layout fits")
    }

    const fn of<P: ProcessData>() -> Self {
        Self {
            direction: P::DIRECTION,
            number: P::NUMBER,
            transmission_type: P::TRANSMISSION_TYPE,
            mapping: P::MAPPING,
        }
    }
}

/// Every PDO the master configures on each drive, in configuration order.
pub const LAYOUT: [PdoLayout; 4] = [
    PdoLayout::of::<Rpdo1>(),
    PdoLayout::of::<Rpdo2>(),
    PdoLayout::of::<Tpdo1>(),
    PdoLayout::of::<Tpdo2>(),
];

/// The PDOs of a spindle drive: controlword and target, statusword and actual
/// position (it has no probe input to arm). Its RPDO1 is asynchronous (255: taken on
/// arrival), sent when it changes and every [`SPINDLE_REFRESH_CYCLES`]: a spindle in
/// profile position needs no setpoint per SYNC, and the bus of five axes has no room
/// for one. Its TPDO1 answers every SYNC, as the axes' do.
pub const SPINDLE_LAYOUT: [PdoLayout; 2] = [
    PdoLayout {
        transmission_type: 255,
        ..PdoLayout::of::<Rpdo1>()
    },
    PdoLayout::of::<Tpdo1>(),
];

/// The spindle drive's unchanged RPDO1 goes out again after this many SYNC periods
/// (a lost frame is repaired; the drive needs nothing more often).
pub const SPINDLE_REFRESH_CYCLES: u32 = 50;

/// Bus load of the cyclic traffic, worst-case bit stuffing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BusLoad {
    pub drives: usize,
    pub bitrate: u32,
    pub period_us: u32,
    /// Bits per SYNC period: SYNC + RPDO1 and TPDO1 of every drive + heartbeats
    /// averaged over the period.
    pub cyclic_bits: f64,
    /// Extra bits in the period where every drive latches (RPDO2 + TPDO2 each).
    pub latch_burst_bits: f64,
    pub percent: f64,
    pub burst_percent: f64,
}

impl BusLoad {
    /// The load of `cfg`'s CANopen bus (default timing on another bus).
    pub fn of(cfg: &MachineConfig) -> Self {
        let n = cfg.axes.len() + usize::from(cfg.spindle.is_some());
        let b = cfg.canopen_bus().unwrap_or(&CanOpenBusConfig::DEFAULT);
        let period_bits = b.bitrate as f64 * b.sync_period_us as f64 * 1e-6;
        let sync = CanFrame::wire_bits_worst_case(0) as f64;
        let per_drive = (CanFrame::wire_bits_worst_case(pdo::byte_len(Rpdo1::MAPPING))
            + CanFrame::wire_bits_worst_case(pdo::byte_len(Tpdo1::MAPPING)))
            as f64;
        let heartbeat = CanFrame::wire_bits_worst_case(1) as f64 * b.sync_period_us as f64
            / (b.heartbeat_producer_ms as f64 * 1000.0);
        // The spindle's drive answers every SYNC (TPDO1); its RPDO1 is sent on change
        // and as a refresh (`SPINDLE_REFRESH_CYCLES`).
        let spindle = if cfg.spindle.is_some() {
            (CanFrame::wire_bits_worst_case(pdo::byte_len(Tpdo1::MAPPING))
                + CanFrame::wire_bits_worst_case(pdo::byte_len(Rpdo1::MAPPING))
                    / SPINDLE_REFRESH_CYCLES) as f64
                + heartbeat
        } else {
            0.0
        };
        let cyclic_bits = sync + cfg.axes.len() as f64 * (per_drive + heartbeat) + spindle;
        let latch_burst_bits = cfg.axes.len() as f64
            * (CanFrame::wire_bits_worst_case(pdo::byte_len(Rpdo2::MAPPING))
                + CanFrame::wire_bits_worst_case(pdo::byte_len(Tpdo2::MAPPING)))
                as f64;
        Self {
            drives: n,
            bitrate: b.bitrate,
            period_us: b.sync_period_us,
            cyclic_bits,
            latch_burst_bits,
            percent: 100.0 * cyclic_bits / period_bits,
            burst_percent: 100.0 * (cyclic_bits + latch_burst_bits) / period_bits,
        }
    }
}

impl BusLoad {
    /// The shortest SYNC period, µs (50 .. 100 000), at which the cyclic traffic of
    /// `cfg`'s drives loads the bus no more than `limit_percent`; `None` when none does.
    pub fn shortest_period_us(cfg: &MachineConfig, limit_percent: f64) -> Option<u32> {
        let mut c = cfg.clone();
        let mut load_at = |period_us: u32| {
            if let Some(b) = c.canopen_bus_mut() {
                b.sync_period_us = period_us;
            }
            Self::of(&c).percent
        };
        let (mut lo, mut hi) = (50u32, 100_000u32);
        if load_at(hi) > limit_percent {
            return None;
        }
        // The load falls as the period grows: the first period within the limit.
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            if load_at(mid) <= limit_percent {
                hi = mid;
            } else {
                lo = mid + 1;
            }
        }
        Some(lo)
    }
}

impl core::fmt::Display for BusLoad {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "{} drives, SYNC every {} us at {} kbit/s: {:.0} bits per cycle = {:.1} % bus load \
             ({:.1} % in the cycle where every axis latches)",
            self.drives,
            self.period_us,
            self.bitrate / 1000,
            self.cyclic_bits,
            self.percent,
            self.burst_percent
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn frame(cob_id: u16, data: &[u8]) -> CanFrame {
        CanFrame::new(cob_id, data).unwrap()
    }

    #[test]
    fn rpdo1_golden_bytes() {
        // Enable operation, target -2 increments, node 3: 203#0F00FEFFFFFF.
        let f = Rpdo1 {
            controlword: 0x000F,
            target_position: -2,
        }
        .encode(3);
        assert_eq!(f, frame(0x203, &[0x0F, 0x00, 0xFE, 0xFF, 0xFF, 0xFF]));
        assert_eq!(
            Rpdo1::decode(&f),
            Ok(Rpdo1 {
                controlword: 0x000F,
                target_position: -2
            })
        );
    }

    #[test]
    fn tpdo1_golden_bytes() {
        // Operation enabled + remote (0x1237), actual 0x12345678, node 1: 181#3712785634 12.
        let f = frame(0x181, &[0x37, 0x12, 0x78, 0x56, 0x34, 0x12]);
        let t = Tpdo1::decode(&f).unwrap();
        assert_eq!(
            t,
            Tpdo1 {
                statusword: 0x1237,
                position_actual: 0x1234_5678
            }
        );
        assert_eq!(t.encode(1), f);
        // Extra bytes are ignored (CiA 301), missing ones are an error.
        let long = frame(0x181, &[0x37, 0x12, 0x78, 0x56, 0x34, 0x12, 0xAA, 0xBB]);
        assert_eq!(Tpdo1::decode(&long), Ok(t));
        assert!(matches!(
            Tpdo1::decode(&frame(0x181, &[0x37, 0x12, 0x78, 0x56, 0x34])),
            Err(DecodeError::WrongLength { found: 5, .. })
        ));
        assert!(Tpdo1::decode(&CanFrame::remote(0x181, 6).unwrap()).is_err());
    }

    #[test]
    fn rpdo2_golden_bytes() {
        // Probe 1 enabled, positive edge, first event (0x0011), node 5: 305#1100.
        let f = Rpdo2 {
            touch_probe_function: 0x0011,
        }
        .encode(5);
        assert_eq!(f, frame(0x305, &[0x11, 0x00]));
        assert_eq!(Rpdo2::decode(&f).unwrap().touch_probe_function, 0x0011);
    }

    #[test]
    fn tpdo2_golden_bytes() {
        // Enabled + edge stored + input high (0x0083), latched at -1000, node 2.
        let f = frame(0x282, &[0x83, 0x00, 0x18, 0xFC, 0xFF, 0xFF]);
        let t = Tpdo2::decode(&f).unwrap();
        assert_eq!(
            t,
            Tpdo2 {
                touch_probe_status: 0x0083,
                probe1_positive_edge: -1000
            }
        );
        assert_eq!(t.encode(2), f);
    }

    #[test]
    fn the_layout_is_the_one_the_start_up_writes() {
        let raw: Vec<(u8, Vec<u32>)> = LAYOUT
            .iter()
            .map(|l| {
                (
                    l.transmission_type,
                    l.mapping.iter().map(|e| e.to_u32()).collect(),
                )
            })
            .collect();
        assert_eq!(
            raw,
            vec![
                (1, vec![0x6040_0010, 0x607A_0020]),
                (255, vec![0x60B8_0010]),
                (1, vec![0x6041_0010, 0x6064_0020]),
                (255, vec![0x60B9_0010, 0x60BA_0020]),
            ]
        );
    }

    #[test]
    fn five_drives_at_2ms_fit_1mbit() {
        let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/machines/table-ac.toml");
        let mut cfg = MachineConfig::load(&p).unwrap();
        assert!(cfg.spindle.is_some());
        // With its spindle drive: one TPDO1 per SYNC, its RPDO1 every 50th, a heartbeat:
        // 1218 + 115 + 115 / 50 (2, whole bits) + 2.6 = 1337.6 bits.
        let load = BusLoad::of(&cfg);
        assert!((load.cyclic_bits - 1337.6).abs() < 1e-9, "{load}");
        assert!((load.percent - 66.88).abs() < 1e-9, "{load}");
        assert_eq!(load.drives, 6);
        // The five axes alone: SYNC 55 + 5 * (2 * 115 + 65 * 2000/50000) = 1218 bits
        // per 2000.
        cfg.spindle = None;
        let load = BusLoad::of(&cfg);
        assert!((load.cyclic_bits - 1218.0).abs() < 1e-9, "{load}");
        assert!((load.percent - 60.9).abs() < 1e-9, "{load}");
    }

    #[test]
    fn the_shortest_period_within_70_percent_for_five_drives_is_1738_us() {
        let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/machines/table-ac.toml");
        let mut cfg = MachineConfig::load(&p).unwrap();
        // The five axes' drives (the spindle's is counted in the test above).
        cfg.spindle = None;
        // 55 + 5 * (230 + 65 * P / 50000) = 1205 + 0.0065 P bits per P us <= 70 %:
        // P >= 1205 / 0.6935 = 1737.6, so 1738 us (69.98 %; 1737 us gives 70.02 %).
        assert_eq!(BusLoad::shortest_period_us(&cfg, 70.0), Some(1738));
        // 250 us, what the trigger bench used to run: 55 + 5 * (230 + 0.325) = 1206.625
        // bits per 250 = 482.65 % of 1 Mbit/s.
        let mut fast = cfg.clone();
        fast.canopen_bus_mut().unwrap().sync_period_us = 250;
        assert!((BusLoad::of(&fast).percent - 482.65).abs() < 1e-9);
        assert_eq!(BusLoad::shortest_period_us(&cfg, 0.001), None);
    }
}
