//! `[probe]`: the real probe. The ball radius, pre-travel and noise of the ideal
//! model, and (all off by default) what makes a kinematic probe real: a pre-travel
//! along the stylus that differs from the one across it, the three lobes of its seat,
//! a ball centre off the spindle axis and a stylus longer or shorter than the table
//! says. [`crate::stylus`] holds the physics.

use super::error::{check_abs, check_range, invalid, ScenarioError};
use hal::Axis;
use serde::Deserialize;
use std::path::Path;

/// The real probe (what the probe table only approximates).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProbeTruth {
    /// True stylus ball radius, mm.
    pub ball_radius: f64,
    /// Trigger noise, 1 sigma along the probing direction, mm.
    pub noise: f64,
    /// Deflection beyond first touch before the signal switches, mm: across the
    /// stylus, the mean over the directions.
    pub pretravel: f64,
    /// R written into the probe table; `None` = `ball_radius` (a calibrated probe).
    pub table_radius: Option<f64>,
    /// The spindle's tool axis: the stylus points along it (X, Y or Z).
    pub axis: Axis,
    /// Pre-travel when the contact pushes the ball along the stylus, mm; `None`: the
    /// same as across it.
    pub pretravel_axial: Option<f64>,
    /// Amplitude of the three lobes of the pre-travel across the stylus, mm.
    pub lobing: f64,
    /// Azimuth of the first lobe's maximum from the working plane's main axis, with
    /// the spindle at 0°, deg.
    pub lobing_phase: f64,
    /// Ball centre off the spindle axis along the working plane's main and minor axis
    /// with the spindle at 0°, mm.
    pub offset: [f64; 2],
    /// How much further from the spindle the ball centre lies than the probe table
    /// says, mm (a longer stylus: positive).
    pub length_error: f64,
}

impl ProbeTruth {
    /// The ideal probe of the tool table: ball radius `r`, no pre-travel, no noise,
    /// nothing off.
    pub fn ideal(ball_radius: f64) -> Self {
        Self {
            ball_radius,
            noise: 0.0,
            pretravel: 0.0,
            table_radius: None,
            axis: Axis::Z,
            pretravel_axial: None,
            lobing: 0.0,
            lobing_phase: 0.0,
            offset: [0.0, 0.0],
            length_error: 0.0,
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawProbe {
    ball_radius: f64,
    #[serde(default)]
    noise: f64,
    #[serde(default)]
    pretravel: f64,
    table_radius: Option<f64>,
    axis: Option<String>,
    pretravel_axial: Option<f64>,
    #[serde(default)]
    lobing: f64,
    #[serde(default)]
    lobing_phase: f64,
    #[serde(default)]
    offset: [f64; 2],
    #[serde(default)]
    length_error: f64,
}

const MAX_BALL_RADIUS: f64 = 50.0;
const MAX_NOISE: f64 = 1.0;
/// Beyond these a stylus is broken or mis-mounted, not off by its calibration, mm.
const MAX_OFFSET: f64 = 1.0;
const MAX_LENGTH_ERROR: f64 = 5.0;

/// `[probe]`: the real probe.
pub(super) fn build_probe(p: &RawProbe, path: &Path) -> Result<ProbeTruth, ScenarioError> {
    let bad = |key: &str, message: String| invalid(path, key, message);
    check_range(
        path,
        "probe.ball_radius",
        p.ball_radius,
        0.0,
        MAX_BALL_RADIUS,
        false,
    )?;
    check_range(path, "probe.noise", p.noise, 0.0, MAX_NOISE, true)?;
    for (key, v) in [
        ("probe.pretravel", Some(p.pretravel)),
        ("probe.pretravel_axial", p.pretravel_axial),
    ] {
        let Some(v) = v else { continue };
        if !(v.is_finite() && v >= 0.0 && v < p.ball_radius) {
            return Err(bad(
                key,
                format!(
                    "{v} must be >= 0 and smaller than ball_radius ({})",
                    p.ball_radius
                ),
            ));
        }
    }
    // The lobes swing the pre-travel by ±lobing around `pretravel`: it must stay >= 0
    // (a probe does not switch before it touches).
    if !(p.lobing.is_finite() && p.lobing >= 0.0 && p.lobing <= p.pretravel) {
        return Err(bad(
            "probe.lobing",
            format!(
                "{} must be >= 0 and at most pretravel ({}): the pre-travel swings by ±lobing around it",
                p.lobing, p.pretravel
            ),
        ));
    }
    check_abs(path, "probe.lobing_phase", p.lobing_phase, 360.0, "deg")?;
    for (i, v) in p.offset.into_iter().enumerate() {
        check_abs(path, &format!("probe.offset[{i}]"), v, MAX_OFFSET, "mm")?;
    }
    check_abs(
        path,
        "probe.length_error",
        p.length_error,
        MAX_LENGTH_ERROR,
        "mm",
    )?;
    if let Some(r) = p.table_radius {
        check_range(path, "probe.table_radius", r, 0.0, MAX_BALL_RADIUS, false)?;
    }
    let axis = match p.axis.as_deref() {
        None | Some("Z") => Axis::Z,
        Some("X") => Axis::X,
        Some("Y") => Axis::Y,
        Some(other) => {
            return Err(bad(
                "probe.axis",
                format!("\"{other}\" is not a tool axis; X, Y or Z"),
            ))
        }
    };
    Ok(ProbeTruth {
        ball_radius: p.ball_radius,
        noise: p.noise,
        pretravel: p.pretravel,
        table_radius: p.table_radius,
        axis,
        pretravel_axial: p.pretravel_axial,
        lobing: p.lobing,
        lobing_phase: p.lobing_phase,
        offset: p.offset,
        length_error: p.length_error,
    })
}
