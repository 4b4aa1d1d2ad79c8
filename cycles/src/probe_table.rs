//! The touch-probe table (the TNC's tchprobe.tp): `[[probe]]` entries of the machine
//! TOML. Read and validated here, not by hal, which accepts the section unread.

use serde::Deserialize;

/// One entry of the touch-probe table.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ProbeEntry {
    /// Tool name as in `TOOL CALL "NAME"`.
    pub name: String,
    /// Stylus ball radius R, mm.
    pub radius: f64,
    /// Clearance added to Q320, mm.
    pub set_up: f64,
    /// Positioning feed, mm/min.
    pub fmax: f64,
    /// Probing feed, mm/min.
    pub f: f64,
    /// Most probing travel beyond the nominal point, mm.
    pub dist: f64,
    /// Spindle orientation tracking (recorded).
    #[serde(default)]
    pub track: bool,
    /// Retract distance after a contact, mm.
    pub mb: f64,
}

impl ProbeEntry {
    /// The first field out of range, as (key, reason).
    pub fn invalid_field(&self) -> Option<(&'static str, &'static str)> {
        for (f, v) in [
            ("radius", self.radius),
            ("fmax", self.fmax),
            ("f", self.f),
            ("dist", self.dist),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Some((f, "must be > 0"));
            }
        }
        for (f, v) in [("set_up", self.set_up), ("mb", self.mb)] {
            if !(v.is_finite() && v >= 0.0) {
                return Some((f, "must be >= 0"));
            }
        }
        None
    }
}
