//! `[spindle]`: the spindle's own CiA 402 drive on the CANopen bus, in profile position
//! mode, for oriented spindle stops (cycle 460 turns the stylus to 0° and 180° to
//! separate its centre offset). Not an axis: it is never interpolated with X..C.

use serde::Deserialize;

/// The spindle drive.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SpindleConfig {
    /// CANopen node ID of the spindle drive, 1..=127, not an axis's or the master's.
    pub node: u8,
    /// Drive position increments per degree of spindle angle.
    pub increments_per_degree: f64,
    /// Speed of an oriented stop, rpm (the drive's profile velocity, 0x6081).
    #[serde(default = "default_orient_rpm")]
    pub orient_rpm: f64,
    /// Acceleration and deceleration of an oriented stop, deg/s² (0x6083, 0x6084).
    #[serde(default = "default_orient_acceleration")]
    pub orient_acceleration: f64,
}

fn default_orient_rpm() -> f64 {
    SpindleConfig::DEFAULT_ORIENT_RPM
}
fn default_orient_acceleration() -> f64 {
    SpindleConfig::DEFAULT_ORIENT_ACCELERATION
}

impl SpindleConfig {
    /// 300 rpm: half a turn in 0.1 s, as the simulated PLC's oriented stop.
    pub const DEFAULT_ORIENT_RPM: f64 = 300.0;
    /// 36 000 deg/s²: 300 rpm reached within 50 ms.
    pub const DEFAULT_ORIENT_ACCELERATION: f64 = 36_000.0;

    /// 0x6081: the orienting speed in increments/s.
    pub fn profile_velocity(&self) -> u32 {
        (self.orient_rpm * 6.0 * self.increments_per_degree).round() as u32
    }

    /// 0x6083 and 0x6084: the orienting acceleration in increments/s².
    pub fn profile_acceleration(&self) -> u32 {
        (self.orient_acceleration * self.increments_per_degree).round() as u32
    }

    /// What is wrong with the values, as (key, why).
    pub(super) fn check(&self) -> Result<(), (&'static str, String)> {
        let ipd = self.increments_per_degree;
        if !(ipd.is_finite() && ipd > 0.0) {
            return Err((
                "spindle.increments_per_degree",
                format!("{ipd}: must be > 0"),
            ));
        }
        if 360.0 * ipd > f64::from(i32::MAX) {
            return Err((
                "spindle.increments_per_degree",
                format!("{ipd}: a turn overflows the drive's 32-bit position"),
            ));
        }
        let rpm = self.orient_rpm;
        if !(rpm.is_finite() && rpm > 0.0 && rpm <= 10_000.0) {
            return Err((
                "spindle.orient_rpm",
                format!("{rpm} is outside (0, 10000] rpm"),
            ));
        }
        if rpm * 6.0 * ipd > f64::from(u32::MAX) || self.profile_velocity() == 0 {
            return Err((
                "spindle.orient_rpm",
                format!("{rpm} rpm is not a profile velocity (0x6081, 1 .. 2^32-1 increments/s) at {ipd} increments/deg"),
            ));
        }
        let acc = self.orient_acceleration;
        if !(acc.is_finite() && acc > 0.0 && acc * ipd <= f64::from(u32::MAX))
            || self.profile_acceleration() == 0
        {
            return Err((
                "spindle.orient_acceleration",
                format!("{acc} deg/s² is not a profile acceleration (0x6083, 1 .. 2^32-1 increments/s²)"),
            ));
        }
        Ok(())
    }
}
