//! `[probe]`: the real probe.

use super::error::{check_range, invalid, ScenarioError};
use serde::Deserialize;
use std::path::Path;

/// The real probe (what the probe table only approximates).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProbeTruth {
    /// True stylus ball radius, mm.
    pub ball_radius: f64,
    /// Trigger noise, 1 sigma along the probing direction, mm.
    pub noise: f64,
    /// Deflection beyond first touch before the signal switches, mm.
    pub pretravel: f64,
    /// R written into the probe table; `None` = `ball_radius` (a calibrated probe).
    pub table_radius: Option<f64>,
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
}

const MAX_BALL_RADIUS: f64 = 50.0;
const MAX_NOISE: f64 = 1.0;

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
    if !(p.pretravel.is_finite() && p.pretravel >= 0.0 && p.pretravel < p.ball_radius) {
        return Err(bad(
            "probe.pretravel",
            format!(
                "{} must be >= 0 and smaller than ball_radius ({})",
                p.pretravel, p.ball_radius
            ),
        ));
    }
    if let Some(r) = p.table_radius {
        check_range(path, "probe.table_radius", r, 0.0, MAX_BALL_RADIUS, false)?;
    }
    Ok(ProbeTruth {
        ball_radius: p.ball_radius,
        noise: p.noise,
        pretravel: p.pretravel,
        table_radius: p.table_radius,
    })
}
