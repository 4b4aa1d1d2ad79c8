//! `[[axis]]`: one axis of the machine and the drive that moves it.

use crate::axis::Axis;
use serde::Deserialize;

/// One axis and the CiA 402 drive that moves it.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct AxisConfig {
    pub name: Axis,
    /// CANopen node ID of the drive, 1..=127: required on a CANopen machine (see
    /// [`BusConfig`](super::BusConfig)), meaningless on other buses.
    #[serde(default)]
    pub node: Option<u8>,
    /// Drive position increments per mm (linear) or per degree (rotary).
    pub increments_per_unit: f64,
    /// Software limits, mm or deg.
    pub min: f64,
    pub max: f64,
    /// mm/min (deg/min).
    pub max_feed: f64,
    /// mm/s^2 (deg/s^2).
    pub max_acceleration: f64,
    /// Hirth coupling grid in degrees (rotary axes only); 0 = none.
    #[serde(default)]
    pub hirth: f64,
}

impl AxisConfig {
    /// The CANopen node ID of the drive. Present on every axis of a validated CANopen
    /// machine; 0 (the NMT broadcast address, never a drive) otherwise, which the
    /// CANopen master never sees: it refuses a machine on another bus.
    pub fn canopen_node(&self) -> u8 {
        self.node.unwrap_or(0)
    }
}
