//! The process data layout the master configures on every drive, and what it costs on
//! the bus.
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
use crate::canopen::pdo::{MapEntry, PdoMapping};
use crate::config::MachineConfig;

pub const RPDO1_TRANSMISSION: u8 = 1;
pub const RPDO2_TRANSMISSION: u8 = 255;
pub const TPDO1_TRANSMISSION: u8 = 1;
pub const TPDO2_TRANSMISSION: u8 = 255;

const fn entry(index: u16, sub: u8, bits: u8) -> MapEntry {
    MapEntry { index, sub, bits }
}

pub const RPDO1: [MapEntry; 2] = [entry(0x6040, 0, 16), entry(0x607A, 0, 32)];
pub const RPDO2: [MapEntry; 1] = [entry(0x60B8, 0, 16)];
pub const TPDO1: [MapEntry; 2] = [entry(0x6041, 0, 16), entry(0x6064, 0, 32)];
pub const TPDO2: [MapEntry; 2] = [entry(0x60B9, 0, 16), entry(0x60BA, 0, 32)];

pub fn mapping(entries: &[MapEntry]) -> PdoMapping {
    let mut m = PdoMapping::new();
    for e in entries {
        // The layouts above are well within 64 bits and 8 entries.
        m.push(*e).expect("static PDO layout fits");
    }
    m
}

fn bytes(entries: &[MapEntry]) -> usize {
    entries.iter().map(|e| e.bits as usize).sum::<usize>() / 8
}

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
    pub fn of(cfg: &MachineConfig) -> Self {
        let n = cfg.axes.len();
        let b = &cfg.canopen_or_default();
        let period_bits = b.bitrate as f64 * b.sync_period_us as f64 * 1e-6;
        let sync = CanFrame::wire_bits_worst_case(0) as f64;
        let per_drive = (CanFrame::wire_bits_worst_case(bytes(&RPDO1))
            + CanFrame::wire_bits_worst_case(bytes(&TPDO1))) as f64;
        let heartbeat = CanFrame::wire_bits_worst_case(1) as f64 * b.sync_period_us as f64
            / (b.heartbeat_producer_ms as f64 * 1000.0);
        let cyclic_bits = sync + n as f64 * (per_drive + heartbeat);
        let latch_burst_bits = n as f64
            * (CanFrame::wire_bits_worst_case(bytes(&RPDO2))
                + CanFrame::wire_bits_worst_case(bytes(&TPDO2))) as f64;
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

impl core::fmt::Display for BusLoad {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "{} drives, SYNC every {} us at {} kbit/s: {:.0} bits per cycle = {:.1} % bus load \
             ({:.1} % in the cycle where all drives latch)",
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

    #[test]
    fn five_drives_at_2ms_fit_1mbit() {
        let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/machines/table-ac.toml");
        let cfg = MachineConfig::load(&p).unwrap();
        let load = BusLoad::of(&cfg);
        // SYNC 55 + 5 * (2 * 115 + 65 * 2000/50000) = 1218 bits per 2000.
        assert!((load.cyclic_bits - 1218.0).abs() < 1e-9, "{load}");
        assert!((load.percent - 60.9).abs() < 1e-9, "{load}");
    }
}
