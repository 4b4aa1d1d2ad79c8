//! The mailbox an integrator implements in the PLC: a command block the bridge writes
//! (one FC16, sequence number last), a status block it reads (one FC3) and a latch
//! ring (see [`super::latch_ring`]). Offsets are relative to each block's zero-based
//! PDU base address; every 32-bit field is two registers in the configured
//! [`WordOrder`]. Codec only: registers in, values out, no I/O. The tables of
//! docs/modbus.md ("The mailbox") are this file.

use super::word_order::WordOrder;
use crate::axis::{Axis, MAX_AXES};

/// Registers of the command block.
pub const COMMAND_LEN: u16 = 20;
/// Registers of the status block.
pub const STATUS_LEN: u16 = 22;
/// Registers of one latch-ring slot.
pub const SLOT_LEN: u16 = 18;

/// Command block offsets.
pub mod cmd {
    pub const COMMAND: usize = 0;
    pub const AXIS_MASK: usize = 1;
    /// u32, 0.001 mm/min (deg/min for a rotary-only move).
    pub const FEED: usize = 2;
    /// 6 x i32 counts, X Y Z A B C.
    pub const TARGETS: usize = 4;
    /// Orient spindle: i32, 0.001°, 0 <= angle < 360 000, in the registers of the
    /// first target (the axis mask is 0, the feed 0).
    pub const SPINDLE_ANGLE: usize = TARGETS;
    pub const PROBE_EDGE: usize = 16;
    pub const LATCH_ACK: usize = 17;
    pub const HEARTBEAT: usize = 18;
    /// Written last (highest address of the one FC16).
    pub const SEQUENCE: usize = 19;
}

/// Status block offsets.
pub mod status {
    pub const SEQUENCE: usize = 0;
    pub const ACKED: usize = 1;
    pub const DONE: usize = 2;
    pub const BITS: usize = 3;
    pub const RESULT: usize = 4;
    pub const FAULT_CODE: usize = 5;
    pub const LATCH_COUNT: usize = 6;
    pub const LATCH_ACK: usize = 7;
    /// 6 x i32 counts.
    pub const ACTUAL: usize = 8;
    /// u32 µs, free running.
    pub const PLC_TIME: usize = 20;
}

/// What the bridge asks the PLC to do.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u16)]
pub enum CommandCode {
    None = 0,
    /// Straight line to the targets of the axes in the mask, all arriving together.
    Move = 1,
    /// Arm the latch, move towards the targets (the end of the probing path), stop on
    /// the latch.
    Probe = 2,
    /// Brake all axes.
    Stop = 3,
    /// Clear a fault (the PLC decides whether it can).
    AcknowledgeFault = 4,
    /// Turn the spindle to [`cmd::SPINDLE_ANGLE`] (an oriented spindle stop; the
    /// stylus turns with it) and report done when it stands there. A PLC without an
    /// orientable spindle answers rejected; with the probe deflected, already deflected.
    OrientSpindle = 5,
}

impl CommandCode {
    pub const fn from_u16(v: u16) -> Option<Self> {
        Some(match v {
            0 => CommandCode::None,
            1 => CommandCode::Move,
            2 => CommandCode::Probe,
            3 => CommandCode::Stop,
            4 => CommandCode::AcknowledgeFault,
            5 => CommandCode::OrientSpindle,
            _ => return None,
        })
    }
}

/// Status bits (register `status::BITS`).
pub mod bits {
    pub const READY: u16 = 1 << 0;
    pub const BUSY: u16 = 1 << 1;
    pub const IN_POSITION: u16 = 1 << 2;
    /// Probe input level.
    pub const DEFLECTED: u16 = 1 << 3;
    pub const ARMED: u16 = 1 << 4;
    pub const FAULT: u16 = 1 << 5;
    pub const LIMIT: u16 = 1 << 6;
}

/// How the command `done` names ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u16)]
pub enum ResultCode {
    Ok = 0,
    /// Probing move stopped on a latch (in the ring).
    Contact = 1,
    NotTriggered = 2,
    AlreadyDeflected = 3,
    /// Probe deflected during a positioning move; axes braked.
    Collision = 4,
    /// The PLC's own limits refused or stopped the move.
    Limit = 5,
    /// A drive or the PLC faulted; `fault_code` says which.
    Fault = 6,
    /// The PLC refused the command (unknown code, bad value).
    Rejected = 7,
    /// Stopped by a stop command.
    Stopped = 8,
}

impl ResultCode {
    pub const fn from_u16(v: u16) -> Option<Self> {
        Some(match v {
            0 => ResultCode::Ok,
            1 => ResultCode::Contact,
            2 => ResultCode::NotTriggered,
            3 => ResultCode::AlreadyDeflected,
            4 => ResultCode::Collision,
            5 => ResultCode::Limit,
            6 => ResultCode::Fault,
            7 => ResultCode::Rejected,
            8 => ResultCode::Stopped,
            _ => return None,
        })
    }
}

/// Where the blocks are and how 32-bit fields are laid out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout {
    pub command_base: u16,
    pub status_base: u16,
    pub ring_base: u16,
    pub ring_slots: u16,
    pub word_order: WordOrder,
}

impl Layout {
    /// Registers of the whole ring.
    pub const fn ring_len(&self) -> u16 {
        self.ring_slots * SLOT_LEN
    }

    /// Address of the latch acknowledge register.
    pub const fn latch_ack_address(&self) -> u16 {
        self.command_base + cmd::LATCH_ACK as u16
    }
}

/// Counts per mm (linear axes) and per degree (rotary axes).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scale {
    pub per_mm: f64,
    pub per_deg: f64,
}

impl Scale {
    fn per_unit(&self, axis: Axis) -> f64 {
        if axis.is_rotary() {
            self.per_deg
        } else {
            self.per_mm
        }
    }

    /// Position in counts, rounded; `None` when it does not fit an i32.
    pub fn to_counts(&self, axis: Axis, v: f64) -> Option<i32> {
        let c = (v * self.per_unit(axis)).round();
        (c.is_finite() && c >= i32::MIN as f64 && c <= i32::MAX as f64).then_some(c as i32)
    }

    pub fn from_counts(&self, axis: Axis, c: i32) -> f64 {
        c as f64 / self.per_unit(axis)
    }

    pub fn positions(&self, counts: &[i32; MAX_AXES]) -> [f64; MAX_AXES] {
        let mut p = [0.0; MAX_AXES];
        for a in Axis::ALL {
            p[a.index()] = self.from_counts(a, counts[a.index()]);
        }
        p
    }
}

fn get32(o: WordOrder, r: &[u16], at: usize) -> u32 {
    o.decode_u32([r[at], r[at + 1]])
}

fn put32(o: WordOrder, r: &mut [u16], at: usize, v: u32) {
    r[at..at + 2].copy_from_slice(&o.encode_u32(v));
}

fn get_axes(o: WordOrder, r: &[u16], at: usize) -> [i32; MAX_AXES] {
    core::array::from_fn(|i| get32(o, r, at + 2 * i) as i32)
}

fn put_axes(o: WordOrder, r: &mut [u16], at: usize, v: &[i32; MAX_AXES]) {
    for (i, c) in v.iter().enumerate() {
        put32(o, r, at + 2 * i, *c as u32);
    }
}

/// The command block's values.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CommandBlock {
    pub command: u16,
    pub axis_mask: u16,
    /// 0.001 mm/min.
    pub feed_milli: u32,
    pub targets: [i32; MAX_AXES],
    /// 1 = rising edge (probe deflects), 2 = falling edge.
    pub probe_edge: u16,
    pub latch_ack: u16,
    pub heartbeat: u16,
    pub sequence: u16,
}

impl CommandBlock {
    pub fn encode(&self, o: WordOrder) -> [u16; COMMAND_LEN as usize] {
        let mut r = [0u16; COMMAND_LEN as usize];
        r[cmd::COMMAND] = self.command;
        r[cmd::AXIS_MASK] = self.axis_mask;
        put32(o, &mut r, cmd::FEED, self.feed_milli);
        put_axes(o, &mut r, cmd::TARGETS, &self.targets);
        r[cmd::PROBE_EDGE] = self.probe_edge;
        r[cmd::LATCH_ACK] = self.latch_ack;
        r[cmd::HEARTBEAT] = self.heartbeat;
        r[cmd::SEQUENCE] = self.sequence;
        r
    }

    /// `r` must hold the whole block.
    pub fn decode(o: WordOrder, r: &[u16]) -> Self {
        Self {
            command: r[cmd::COMMAND],
            axis_mask: r[cmd::AXIS_MASK],
            feed_milli: get32(o, r, cmd::FEED),
            targets: get_axes(o, r, cmd::TARGETS),
            probe_edge: r[cmd::PROBE_EDGE],
            latch_ack: r[cmd::LATCH_ACK],
            heartbeat: r[cmd::HEARTBEAT],
            sequence: r[cmd::SEQUENCE],
        }
    }
}

/// The status block's values.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct StatusBlock {
    pub sequence: u16,
    pub acked: u16,
    pub done: u16,
    pub bits: u16,
    pub result: u16,
    pub fault_code: u16,
    pub latch_count: u16,
    pub latch_ack: u16,
    pub actual: [i32; MAX_AXES],
    pub plc_time_us: u32,
}

impl StatusBlock {
    pub fn encode(&self, o: WordOrder) -> [u16; STATUS_LEN as usize] {
        let mut r = [0u16; STATUS_LEN as usize];
        r[status::SEQUENCE] = self.sequence;
        r[status::ACKED] = self.acked;
        r[status::DONE] = self.done;
        r[status::BITS] = self.bits;
        r[status::RESULT] = self.result;
        r[status::FAULT_CODE] = self.fault_code;
        r[status::LATCH_COUNT] = self.latch_count;
        r[status::LATCH_ACK] = self.latch_ack;
        put_axes(o, &mut r, status::ACTUAL, &self.actual);
        put32(o, &mut r, status::PLC_TIME, self.plc_time_us);
        r
    }

    /// `None` when `r` is not the whole block.
    pub fn decode(o: WordOrder, r: &[u16]) -> Option<Self> {
        (r.len() == STATUS_LEN as usize).then(|| Self {
            sequence: r[status::SEQUENCE],
            acked: r[status::ACKED],
            done: r[status::DONE],
            bits: r[status::BITS],
            result: r[status::RESULT],
            fault_code: r[status::FAULT_CODE],
            latch_count: r[status::LATCH_COUNT],
            latch_ack: r[status::LATCH_ACK],
            actual: get_axes(o, r, status::ACTUAL),
            plc_time_us: get32(o, r, status::PLC_TIME),
        })
    }

    pub const fn has(&self, bit: u16) -> bool {
        self.bits & bit != 0
    }
}

/// One latch-ring slot.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct LatchSlot {
    /// Latch number `n` (counted from 1, wraps at 65536), written first ...
    pub sequence_head: u16,
    /// Sequence of the command (the probing move) during which it latched.
    pub command_sequence: u16,
    pub axis_mask: u16,
    pub positions: [i32; MAX_AXES],
    /// PLC time of the latch, µs.
    pub latch_time_us: u32,
    /// ... and the same number written last: equal copies mean a whole slot.
    pub sequence_tail: u16,
}

/// Slot offsets.
pub mod slot {
    pub const SEQUENCE_HEAD: usize = 0;
    pub const COMMAND_SEQUENCE: usize = 1;
    pub const AXIS_MASK: usize = 2;
    pub const POSITIONS: usize = 3;
    pub const LATCH_TIME: usize = 15;
    pub const SEQUENCE_TAIL: usize = 17;
}

impl LatchSlot {
    pub fn encode(&self, o: WordOrder) -> [u16; SLOT_LEN as usize] {
        let mut r = [0u16; SLOT_LEN as usize];
        r[slot::SEQUENCE_HEAD] = self.sequence_head;
        r[slot::COMMAND_SEQUENCE] = self.command_sequence;
        r[slot::AXIS_MASK] = self.axis_mask;
        put_axes(o, &mut r, slot::POSITIONS, &self.positions);
        put32(o, &mut r, slot::LATCH_TIME, self.latch_time_us);
        r[slot::SEQUENCE_TAIL] = self.sequence_tail;
        r
    }

    /// `r` must hold the whole slot.
    pub fn decode(o: WordOrder, r: &[u16]) -> Self {
        Self {
            sequence_head: r[slot::SEQUENCE_HEAD],
            command_sequence: r[slot::COMMAND_SEQUENCE],
            axis_mask: r[slot::AXIS_MASK],
            positions: get_axes(o, r, slot::POSITIONS),
            latch_time_us: get32(o, r, slot::LATCH_TIME),
            sequence_tail: r[slot::SEQUENCE_TAIL],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn command_block_golden_registers_abcd_and_cdab() {
        let c = CommandBlock {
            command: CommandCode::Probe as u16,
            axis_mask: 0b111,
            feed_milli: 200_000,
            // X 12.3 mm, Y -4.5 mm, Z 1 mm at 1e6 counts/mm.
            targets: [12_300_000, -4_500_000, 1_000_000, 0, 0, 0],
            probe_edge: 1,
            latch_ack: 7,
            heartbeat: 0x0102,
            sequence: 42,
        };
        let r = c.encode(WordOrder::ABCD);
        #[rustfmt::skip]
        let want = [
            2, 7, 0x0003, 0x0D40,
            0x00BB, 0xAEE0, 0xFFBB, 0x55E0, 0x000F, 0x4240, 0, 0, 0, 0, 0, 0,
            1, 7, 0x0102, 42,
        ];
        assert_eq!(r, want);
        let r = c.encode(WordOrder::CDAB);
        assert_eq!(&r[2..8], &[0x0D40, 0x0003, 0xAEE0, 0x00BB, 0x55E0, 0xFFBB]);
        assert_eq!(r[cmd::SEQUENCE], 42, "sequence is the last register");
        assert_eq!(CommandBlock::decode(WordOrder::CDAB, &r), c);
    }

    #[test]
    fn status_block_decodes_golden_registers() {
        #[rustfmt::skip]
        let r: [u16; 22] = [
            9, 5, 4, bits::READY | bits::IN_POSITION, ResultCode::Contact as u16, 0, 3, 2,
            // X 1.5 mm, Y -0.000001 mm, Z 95.5, A 0, B 0, C 90 deg (DCBA)
            0x60E3, 0x1600, 0xFFFF, 0xFFFF, 0xE036, 0xB105, 0, 0, 0, 0, 0x804A, 0x5D05,
            // PLC time 0x01020304 µs
            0x0403, 0x0201,
        ];
        let s = StatusBlock::decode(WordOrder::DCBA, &r).unwrap();
        assert_eq!(s.sequence, 9);
        assert_eq!((s.acked, s.done, s.latch_count, s.latch_ack), (5, 4, 3, 2));
        assert!(s.has(bits::IN_POSITION) && !s.has(bits::BUSY));
        assert_eq!(ResultCode::from_u16(s.result), Some(ResultCode::Contact));
        assert_eq!(s.actual, [1_500_000, -1, 95_500_000, 0, 0, 90_000_000]);
        assert_eq!(s.plc_time_us, 0x0102_0304);
        assert_eq!(s.encode(WordOrder::DCBA), r);
        let scale = Scale {
            per_mm: 1e6,
            per_deg: 1e6,
        };
        let p = scale.positions(&s.actual);
        assert_eq!(p[0], 1.5);
        assert_eq!(p[5], 90.0);
        assert!(StatusBlock::decode(WordOrder::DCBA, &r[..21]).is_none());
    }

    #[test]
    fn slot_round_trips_and_keeps_its_sequence_at_both_ends() {
        let s = LatchSlot {
            sequence_head: 65535,
            command_sequence: 12,
            axis_mask: 0b10_0111,
            positions: [1, -2, 3, 0, 0, -4],
            latch_time_us: 4_000_000_123,
            sequence_tail: 65535,
        };
        for o in WordOrder::ALL {
            let r = s.encode(o);
            assert_eq!((r[0], r[17]), (65535, 65535));
            assert_eq!(LatchSlot::decode(o, &r), s);
        }
    }

    #[test]
    fn scale_refuses_what_does_not_fit_32_bits() {
        let s = Scale {
            per_mm: 1e6,
            per_deg: 1e4,
        };
        assert_eq!(s.to_counts(Axis::X, 2147.0), Some(2_147_000_000));
        assert_eq!(s.to_counts(Axis::X, 2148.0), None);
        assert_eq!(s.to_counts(Axis::C, 2148.0), Some(21_480_000));
        assert_eq!(s.to_counts(Axis::Y, f64::NAN), None);
    }
}
