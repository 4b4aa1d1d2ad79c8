//! The alarm of the trend pages: a change between two runs larger than a threshold.

/// Default alarm: a change of the identified position error between two runs, µm.
pub const DEFAULT_ALARM_UM: f64 = 5.0;
/// Default alarm: a change of an identified orientation error, arcsec.
pub const DEFAULT_ALARM_ARCSEC: f64 = 10.0;

/// A change between two consecutive runs larger than this is marked.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Alarm {
    pub um: f64,
    pub arcsec: f64,
}

impl Default for Alarm {
    fn default() -> Self {
        Self {
            um: DEFAULT_ALARM_UM,
            arcsec: DEFAULT_ALARM_ARCSEC,
        }
    }
}
