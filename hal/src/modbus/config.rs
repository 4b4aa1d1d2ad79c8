//! The `[bus]` section of a machine whose axes a PLC moves, reached over Modbus
//! (`kind = "modbus"`). Shaped like LinuxCNC's mb2hal: transport, unit, timeouts,
//! word order, scale, and where the mailbox's blocks sit (zero-based PDU addresses,
//! never 40001-style). Validated before anything is opened.

use super::mailbox::{Layout, COMMAND_LEN, SLOT_LEN, STATUS_LEN};
use super::named_values::named_values;
use super::word_order::WordOrder;
use serde::Deserialize;

/// Modbus allows at most 125 registers in one read (FC3) ...
pub const MODBUS_MAX_READ: u16 = 125;
/// ... and 123 in one write (FC16).
pub const MODBUS_MAX_WRITE: u16 = 123;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Transport {
    Tcp,
    Rtu,
}

named_values!(Transport, "transport", { "tcp" => Transport::Tcp, "rtu" => Transport::Rtu });

named_values!(Parity, "parity", {
    "none" => Parity::None,
    "even" => Parity::Even,
    "odd" => Parity::Odd,
});

named_values!(CaptureKind, "capture", {
    "hw_latch" => CaptureKind::HwLatch,
    "plc_cycle" => CaptureKind::PlcCycle,
    "poll" => CaptureKind::Poll,
});

#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Parity {
    #[default]
    None,
    Even,
    Odd,
}

/// How the PLC captures the axis positions of a contact.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum CaptureKind {
    /// A hardware latch (drive touch probe, encoder latch, time-stamped input).
    #[default]
    HwLatch,
    /// Positions sampled in the PLC task cycle in which the input was seen: up to one
    /// cycle late along the probing direction.
    PlcCycle,
    /// Positions polled: set-up only.
    Poll,
}

impl CaptureKind {
    pub const fn name(self) -> &'static str {
        match self {
            CaptureKind::HwLatch => "hw_latch",
            CaptureKind::PlcCycle => "plc_cycle",
            CaptureKind::Poll => "poll",
        }
    }
}

#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModbusBusConfig {
    pub transport: Transport,
    /// `host:port` of the PLC (tcp).
    #[serde(default)]
    pub address: Option<String>,
    /// Serial device (rtu), e.g. `/dev/ttyUSB0`.
    #[serde(default)]
    pub device: Option<String>,
    #[serde(default = "default_baud")]
    pub baud: u32,
    #[serde(default)]
    pub parity: Parity,
    /// Silence after a timeout before the next RTU frame, µs (default: 3.5 characters
    /// at the baud rate, at least 1750 µs as the RTU spec fixes above 19200 baud).
    #[serde(default)]
    pub frame_gap_us: Option<u32>,
    /// Modbus unit (slave) id.
    #[serde(default = "default_unit")]
    pub unit: u8,
    /// Every request is abandoned after this long, ms.
    #[serde(default = "default_timeout_ms")]
    pub timeout_ms: u32,
    /// Status poll period while a command runs, ms.
    #[serde(default = "default_poll_ms")]
    pub poll_ms: u32,
    /// Retries of a request answered with ServerDeviceBusy.
    #[serde(default = "default_busy_retries")]
    pub busy_retries: u32,
    /// Word order of every 32-bit field: "ABCD", "CDAB", "BADC" or "DCBA".
    #[serde(default)]
    pub word_order: WordOrder,
    /// Position counts per mm (X, Y, Z) and per degree (A, B, C) in the registers.
    #[serde(default = "default_counts")]
    pub counts_per_mm: f64,
    #[serde(default = "default_counts")]
    pub counts_per_deg: f64,
    /// Registers per read / write the device accepts (at most 125 / 123).
    #[serde(default = "default_max_read")]
    pub max_read: u16,
    #[serde(default = "default_max_write")]
    pub max_write: u16,
    /// Zero-based PDU address of the command block.
    pub command_base: u16,
    /// Zero-based PDU address of the status block.
    pub status_base: u16,
    /// Zero-based PDU address of the latch ring.
    pub ring_base: u16,
    /// Slots of the latch ring.
    pub ring_slots: u16,
    #[serde(default)]
    pub capture: CaptureKind,
    /// The PLC task cycle, µs: the capture period of `plc_cycle`, and the motion cycle
    /// of the simulated PLC.
    #[serde(default = "default_plc_cycle_us")]
    pub plc_cycle_us: u32,
    /// Let `poll` capture measure (set-up only; probing moves are refused otherwise).
    #[serde(default)]
    pub allow_poll: bool,
    /// The PLC implements command 5, orient spindle (cycle 460 measures the stylus
    /// centre offset with it; without, the offset is kept and the cycle says so).
    #[serde(default)]
    pub spindle_orientation: bool,
}

fn default_baud() -> u32 {
    115_200
}
fn default_unit() -> u8 {
    1
}
fn default_timeout_ms() -> u32 {
    200
}
fn default_poll_ms() -> u32 {
    2
}
fn default_busy_retries() -> u32 {
    5
}
fn default_counts() -> f64 {
    1_000_000.0
}
fn default_max_read() -> u16 {
    MODBUS_MAX_READ
}
fn default_max_write() -> u16 {
    MODBUS_MAX_WRITE
}
fn default_plc_cycle_us() -> u32 {
    2000
}

/// A bad key: which one, and why.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Invalid {
    /// Key under `[bus]`, e.g. `ring_slots`.
    pub key: &'static str,
    pub reason: String,
}

impl ModbusBusConfig {
    /// The default mailbox at `command_base` 0, status 100, ring 200 with 4 slots, on
    /// TCP at `address`.
    pub fn tcp(address: impl Into<String>) -> Self {
        Self {
            transport: Transport::Tcp,
            address: Some(address.into()),
            device: None,
            baud: default_baud(),
            parity: Parity::None,
            frame_gap_us: None,
            unit: default_unit(),
            timeout_ms: default_timeout_ms(),
            poll_ms: default_poll_ms(),
            busy_retries: default_busy_retries(),
            word_order: WordOrder::ABCD,
            counts_per_mm: default_counts(),
            counts_per_deg: default_counts(),
            max_read: MODBUS_MAX_READ,
            max_write: MODBUS_MAX_WRITE,
            command_base: 0,
            status_base: 100,
            ring_base: 200,
            ring_slots: 4,
            capture: CaptureKind::HwLatch,
            plc_cycle_us: default_plc_cycle_us(),
            allow_poll: false,
            spindle_orientation: false,
        }
    }

    /// The same mailbox on RTU at `device`.
    pub fn rtu(device: impl Into<String>, baud: u32) -> Self {
        Self {
            transport: Transport::Rtu,
            address: None,
            device: Some(device.into()),
            baud,
            ..Self::tcp("")
        }
    }

    pub fn layout(&self) -> Layout {
        Layout {
            command_base: self.command_base,
            status_base: self.status_base,
            ring_base: self.ring_base,
            ring_slots: self.ring_slots,
            word_order: self.word_order,
        }
    }

    /// Silence to keep after an RTU timeout, µs.
    pub fn frame_gap_us(&self) -> u32 {
        self.frame_gap_us.unwrap_or_else(|| {
            // 11 bits per character, 3.5 characters; fixed 1750 µs above 19200 baud.
            if self.baud > 19_200 {
                1750
            } else {
                (3.5 * 11.0 * 1e6 / self.baud.max(1) as f64).ceil() as u32
            }
        })
    }

    pub fn validate(&self) -> Result<(), Invalid> {
        self.validate_link()?;
        self.validate_blocks()
    }

    /// Transport, timing and scale.
    fn validate_link(&self) -> Result<(), Invalid> {
        let bad = |key, reason: String| Err(Invalid { key, reason });
        match self.transport {
            Transport::Tcp => match &self.address {
                None => {
                    return bad(
                        "address",
                        "transport \"tcp\" needs an address host:port".into(),
                    )
                }
                Some(a) if !a.contains(':') => {
                    return bad("address", format!("{a:?} is not host:port"))
                }
                _ => {}
            },
            Transport::Rtu => {
                if self.device.as_deref().is_none_or(str::is_empty) {
                    return bad("device", "transport \"rtu\" needs a serial device".into());
                }
                if !(300..=4_000_000).contains(&self.baud) {
                    return bad("baud", format!("{} is not a serial baud rate", self.baud));
                }
                if self.unit == 0 || self.unit > 247 {
                    return bad(
                        "unit",
                        format!("{} is not an RTU unit id (1..247)", self.unit),
                    );
                }
            }
        }
        if self.timeout_ms == 0 || self.timeout_ms > 60_000 {
            return bad("timeout_ms", "must be 1..60000".into());
        }
        if self.poll_ms == 0 || self.poll_ms > 1000 {
            return bad("poll_ms", "must be 1..1000".into());
        }
        for (key, v) in [
            ("counts_per_mm", self.counts_per_mm),
            ("counts_per_deg", self.counts_per_deg),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return bad(key, "must be > 0".into());
            }
        }
        if self.plc_cycle_us == 0 {
            return bad("plc_cycle_us", "must be > 0".into());
        }
        Ok(())
    }

    /// Request sizes, the ring, and where the blocks sit.
    fn validate_blocks(&self) -> Result<(), Invalid> {
        let bad = |key, reason: String| Err(Invalid { key, reason });
        if self.max_read == 0 || self.max_read > MODBUS_MAX_READ {
            return bad(
                "max_read",
                format!("{} registers: Modbus reads 1..125 at once", self.max_read),
            );
        }
        if self.max_write == 0 || self.max_write > MODBUS_MAX_WRITE {
            return bad(
                "max_write",
                format!("{} registers: Modbus writes 1..123 at once", self.max_write),
            );
        }
        if self.ring_slots == 0 {
            return bad("ring_slots", "a latch ring needs at least one slot".into());
        }
        if !self.ring_slots.is_power_of_two() {
            return bad(
                "ring_slots",
                format!(
                    "{} slots: the count must divide 65536 (1, 2, 4, ...) so the slot of contact n stays n mod slots when n wraps",
                    self.ring_slots
                ),
            );
        }
        if COMMAND_LEN > self.max_write {
            return bad(
                "max_write",
                format!(
                    "the command block ({COMMAND_LEN} registers) must go out in one write of at most {}",
                    self.max_write
                ),
            );
        }
        if STATUS_LEN > self.max_read {
            return bad(
                "max_read",
                format!(
                    "the status block ({STATUS_LEN} registers) must be read in one request of at most {}",
                    self.max_read
                ),
            );
        }
        let ring = self.ring_slots as u32 * SLOT_LEN as u32;
        if ring > self.max_read as u32 {
            return bad(
                "ring_slots",
                format!(
                    "{} slots of {SLOT_LEN} registers = {ring} registers, more than one read of {} \
                     (the ring is read whole in one request)",
                    self.ring_slots, self.max_read
                ),
            );
        }
        let blocks = [
            ("command_base", self.command_base as u32, COMMAND_LEN as u32),
            ("status_base", self.status_base as u32, STATUS_LEN as u32),
            ("ring_base", self.ring_base as u32, ring),
        ];
        for (key, start, len) in blocks {
            if start + len > 0x1_0000 {
                return bad(
                    key,
                    format!("block {start}..{} runs past address 65535", start + len - 1),
                );
            }
        }
        for (i, (ka, sa, la)) in blocks.iter().enumerate() {
            for (kb, sb, lb) in &blocks[i + 1..] {
                if sa < &(sb + lb) && sb < &(sa + la) {
                    return bad(
                        kb,
                        format!(
                            "registers {sb}..{} overlap {ka} ({sa}..{})",
                            sb + lb - 1,
                            sa + la - 1
                        ),
                    );
                }
            }
        }
        Ok(())
    }
}
