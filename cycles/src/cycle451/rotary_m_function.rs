//! Rotary axes positioned by an M function (`[cycles] mStrobeRotAxPos`, the TNC's
//! machine parameter 204803): an indexing table the PLC turns. The seeds say the
//! measurement starts only with every rotary axis at 0 deg (collision danger: the NC
//! cannot turn them by itself), measures no backlash, and the TNC hands each target
//! angle to the PLC in Q120 (A), Q121 (B), Q122 (C) before the M function.

use super::plan::KinematicsPlan;
use crate::confirmation::{ConfirmKind, Confirmation};
use crate::cycle::CycleContext;
use crate::cycles_config::CyclesConfig;
use crate::error::CycleError;
use crate::q_params::QName;
use hal::{Axis, AxisPositions, Machine};

/// How far from 0 deg a rotary axis may stand and still count as at 0 (deg): the
/// drives' resolution, not a tolerance of the measurement.
pub const AT_ZERO_DEG: f64 = 1e-4;

/// The parameter the TNC writes a rotary axis's target angle into (`Q120` for A).
pub fn target_param(axis: Axis) -> Option<&'static str> {
    match axis {
        Axis::A => Some("Q120"),
        Axis::B => Some("Q121"),
        Axis::C => Some("Q122"),
        _ => None,
    }
}

/// Before anything of the cycle moves: every rotary axis of the machine at 0 deg, and
/// the operator (or the PLC's start request) confirms it.
pub(super) fn check_start<M: Machine>(
    machine: &mut M,
    plan: &KinematicsPlan,
    m: u32,
    ctx: &mut CycleContext<'_>,
    block: u32,
) -> Result<(), CycleError> {
    let here = machine
        .positions()
        .map_err(|e| CycleError::machine("reading the rotary axes' positions", &e))?;
    let off: Vec<String> = plan
        .present
        .iter()
        .filter_map(|&a| {
            let v = here.get(a).unwrap_or(0.0);
            (v.abs() > AT_ZERO_DEG).then(|| format!("{a} is at {v:+.4} deg"))
        })
        .collect();
    if !off.is_empty() {
        return Err(CycleError::Plan(format!(
            "cycle 451: M{m} positions the rotary axes (mStrobeRotAxPos), and the measurement starts only with every rotary axis at 0 deg: {}; position them at 0 first; nothing moved",
            off.join(", ")
        )));
    }
    let names: Vec<&str> = plan.present.iter().map(|a| a.name()).collect();
    let text = format!(
        "mStrobeRotAxPos: cycle 451 (block {block}): M{m} positions the rotary axes {}; the PLC turns them to each measuring angle (Q120..Q122) while the probe stands at Q408. They read 0 deg: check that they really stand at 0 deg and that the probe clears the sphere at every angle (collision danger). Start the measurement?",
        names.join(", ")
    );
    // The gateway answers it with the PLC's start request (the PLC positions the
    // table); the CLI asks the operator (`--yes` answers it).
    if !(ctx.confirm)(&Confirmation::new(ConfirmKind::RotaryAtZero, text)) {
        return Err(CycleError::Plan(format!(
            "cycle 451: the start with the rotary axes at 0 deg (M{m} positions them, mStrobeRotAxPos) was not confirmed; nothing moved"
        )));
    }
    Ok(())
}

/// What 451 writes besides its results on `cfg`'s machine: with `mStrobeRotAxPos`,
/// Q120..Q122 of its rotary axes (every measurement turns them); none otherwise.
pub fn written_params(cfg: &CyclesConfig) -> Vec<QName> {
    if cfg.parameters.rotary_m_function().is_none() {
        return Vec::new();
    }
    Axis::ROTARY
        .into_iter()
        .filter(|a| cfg.machine.axis(*a).is_some())
        .filter_map(target_param)
        .filter_map(QName::parse)
        .collect()
}

/// The Q120..Q122 values of a rotary positioning to `target`: the angles of the rotary
/// axes it names.
pub fn target_values(target: &AxisPositions) -> Vec<(&'static str, f64)> {
    target
        .iter()
        .filter_map(|(a, v)| target_param(a).map(|q| (q, v)))
        .collect()
}

/// The line of one strobe of M`m`: the target angles as the TNC writes them, then the
/// M function (`M203: Q120=+45.0000 Q122=+0.0000: the PLC positions the rotary axes`).
pub fn strobe_note(m: u32, values: &[(&str, f64)]) -> String {
    let qs: Vec<String> = values.iter().map(|(q, v)| format!("{q}={v:+.4}")).collect();
    format!(
        "M{m} (mStrobeRotAxPos): {}: the PLC positions the rotary axes",
        qs.join(" ")
    )
}
