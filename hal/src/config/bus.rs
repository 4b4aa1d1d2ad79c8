//! `[bus]`: the fieldbus the axes are reached over, and the CANopen bus's timing (the
//! Modbus keys are [`crate::modbus::config`]'s).

use crate::modbus::config::ModbusBusConfig;
use serde::Deserialize;

/// The fieldbus the axes are reached over: `[bus]` with `kind = "canopen"` (CiA 402
/// drives) or `kind = "modbus"` (a PLC that owns the axes, see [`crate::modbus`]) and
/// that bus's keys. Without a `[bus]` section a machine is on CANopen with the default
/// timing.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(tag = "kind", rename_all = "lowercase")]
#[non_exhaustive]
pub enum BusConfig {
    /// CiA 402 drives over CANopen; every axis names its drive's node.
    #[serde(rename = "canopen")]
    CanOpen(CanOpenBusConfig),
    /// A PLC reached over Modbus TCP or RTU moves the axes and latches the probe.
    Modbus(ModbusBusConfig),
}

impl Default for BusConfig {
    fn default() -> Self {
        BusConfig::CanOpen(CanOpenBusConfig::default())
    }
}

impl BusConfig {
    /// The `kind` as written in the file.
    pub fn kind(&self) -> &'static str {
        match self {
            BusConfig::CanOpen(_) => "canopen",
            BusConfig::Modbus(_) => "modbus",
        }
    }
}

/// CANopen bus timing.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CanOpenBusConfig {
    /// Bit rate in bit/s.
    #[serde(default = "default_bitrate")]
    pub bitrate: u32,
    /// SYNC period, microseconds.
    #[serde(default = "default_sync_period_us")]
    pub sync_period_us: u32,
    /// Heartbeat period the drives are configured to produce (0x1017), ms.
    #[serde(default = "default_heartbeat_ms")]
    pub heartbeat_producer_ms: u16,
    /// A node whose heartbeat is missing this long is lost, ms.
    #[serde(default = "default_heartbeat_timeout_ms")]
    pub heartbeat_timeout_ms: u16,
    /// The master's own node ID: its heartbeat goes out on 0x700 + this ID.
    #[serde(default = "default_master_node")]
    pub master_node: u8,
    /// Period of the master's heartbeat, ms (0: none). The drives consume it (0x1016)
    /// with [`CanOpenBusConfig::MASTER_HEARTBEAT_CONSUMER_FACTOR`] times this period
    /// and stop when it is missing that long.
    #[serde(default = "default_master_heartbeat_ms")]
    pub master_heartbeat_ms: u16,
    /// SDO answer timeout, ms.
    #[serde(default = "default_sdo_timeout_ms")]
    pub sdo_timeout_ms: u16,
    /// Most bus load the cyclic PDO traffic may take, percent.
    #[serde(default = "default_max_load")]
    pub max_load_percent: f64,
}

fn default_bitrate() -> u32 {
    CanOpenBusConfig::DEFAULT.bitrate
}
fn default_sync_period_us() -> u32 {
    CanOpenBusConfig::DEFAULT.sync_period_us
}
fn default_heartbeat_ms() -> u16 {
    CanOpenBusConfig::DEFAULT.heartbeat_producer_ms
}
fn default_heartbeat_timeout_ms() -> u16 {
    CanOpenBusConfig::DEFAULT.heartbeat_timeout_ms
}
fn default_master_node() -> u8 {
    CanOpenBusConfig::DEFAULT.master_node
}
fn default_master_heartbeat_ms() -> u16 {
    CanOpenBusConfig::DEFAULT.master_heartbeat_ms
}
fn default_sdo_timeout_ms() -> u16 {
    CanOpenBusConfig::DEFAULT.sdo_timeout_ms
}
fn default_max_load() -> f64 {
    CanOpenBusConfig::DEFAULT.max_load_percent
}

impl CanOpenBusConfig {
    /// The defaults of every key.
    pub const DEFAULT: Self = Self {
        bitrate: 1_000_000,
        sync_period_us: 2000,
        heartbeat_producer_ms: 50,
        heartbeat_timeout_ms: 150,
        master_node: 127,
        master_heartbeat_ms: 100,
        sdo_timeout_ms: 200,
        max_load_percent: 70.0,
    };
}

impl CanOpenBusConfig {
    /// The drives' heartbeat consumer time (0x1016) is this many master heartbeat
    /// periods: two heartbeats may be late or lost before a drive stops.
    pub const MASTER_HEARTBEAT_CONSUMER_FACTOR: u16 = 3;

    /// The drives' consumer time for the master's heartbeat, ms (0: not consumed).
    pub fn master_heartbeat_consumer_ms(&self) -> u16 {
        self.master_heartbeat_ms
            .saturating_mul(Self::MASTER_HEARTBEAT_CONSUMER_FACTOR)
    }

    /// The 0x1016 sub 1 entry every drive gets: master node ID in bits 16-23, the
    /// consumer time in ms in bits 0-15 (CiA 301); 0 when the master sends no
    /// heartbeat.
    pub fn master_heartbeat_consumer_entry(&self) -> u32 {
        match self.master_heartbeat_consumer_ms() {
            0 => 0,
            ms => (u32::from(self.master_node) << 16) | u32::from(ms),
        }
    }
}

impl Default for CanOpenBusConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}
