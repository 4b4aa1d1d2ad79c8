//! The touch-probe table (the TNC's tchprobe.tp): `[[probe]]` entries of the machine
//! TOML, read and validated here, not by hal, which accepts the section unread; and
//! each probe's calibration ([`calibration`]), which cycle 460 measures and keeps in
//! `<machine>.probes.toml` beside it ([`probes_file`]).

pub mod calibration;
pub mod probes_file;

use calibration::Calibration;
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
    /// The probe's row of `probes.toml` (cycle 460), when it has one.
    #[serde(skip)]
    pub calibration: Option<Calibration>,
    /// The probe's repeatability as its maker states it: 2 σ of one contact along the
    /// probing direction, mm. Half of it is the floor of every result's standard
    /// uncertainty where the fit has few degrees of freedom ([`crate::uncertainty`]).
    #[serde(default = "default_repeatability")]
    pub repeatability_2sigma: f64,
}

/// Kinematic touch probes (TS 460, OMP40 class) state 1 µm (2 σ).
pub const DEFAULT_REPEATABILITY_2SIGMA: f64 = 0.001;

fn default_repeatability() -> f64 {
    DEFAULT_REPEATABILITY_2SIGMA
}

/// The largest repeatability taken as plausible, mm (2 σ).
pub const MAX_REPEATABILITY: f64 = 1.0;

/// The plausible range of each length of an entry, mm: a stylus ball up to 50 mm
/// radius ([`RADIUS_MM`]); clearances and paths up to 1 m.
pub use calibration::RADIUS_MM;
pub const PATH_MM: f64 = 1000.0;

impl ProbeEntry {
    /// What the cycles probe with: the calibrated row, else the nominal probe (R the
    /// table's radius, no offset, no length correction).
    pub fn calibration(&self) -> Calibration {
        self.calibration
            .clone()
            .unwrap_or_else(|| Calibration::nominal(self.radius))
    }

    /// The standard uncertainty (1 σ) of one contact: half the stated repeatability.
    pub fn repeatability(&self) -> f64 {
        self.repeatability_2sigma / 2.0
    }

    /// The first field out of range, as (key, reason). Feeds are checked against the
    /// machine by [`crate::cycles_config::CyclesConfig`].
    pub fn invalid_field(&self) -> Option<(&'static str, String)> {
        let (lo, hi) = RADIUS_MM;
        if !(lo..=hi).contains(&self.radius) {
            return Some((
                "radius",
                format!("{} is outside {lo} .. {hi} mm", self.radius),
            ));
        }
        if !(self.dist > 0.0 && self.dist <= PATH_MM) {
            return Some((
                "dist",
                format!("{} is outside (0, {PATH_MM}] mm", self.dist),
            ));
        }
        if !(self.repeatability_2sigma > 0.0 && self.repeatability_2sigma <= MAX_REPEATABILITY) {
            return Some((
                "repeatability_2sigma",
                format!(
                    "{} is outside (0, {MAX_REPEATABILITY}] mm",
                    self.repeatability_2sigma
                ),
            ));
        }
        for (f, v) in [("set_up", self.set_up), ("mb", self.mb)] {
            if !(0.0..=PATH_MM).contains(&v) {
                return Some((f, format!("{v} is outside 0 .. {PATH_MM} mm")));
            }
        }
        None
    }
}
