//! `[[fault]]`: the drive faults the drive simulation injects.

use super::error::{check_range, invalid, ScenarioError};
use hal::config::MachineConfig;
use serde::Deserialize;
use std::path::Path;

/// What the drive simulation does to a node.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FaultKind {
    /// The drive reports an emergency (EMCY) and goes to Fault.
    Emcy,
    /// The node stops answering (no heartbeat, no PDO, no SDO).
    Silent,
    /// The node restarts (as after a watchdog reset or a power dip): boot-up frame,
    /// configuration back to defaults, pre-operational.
    Reboot,
}

/// A fault the drive simulation injects.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fault {
    /// CANopen node of an axis of the machine.
    pub node: u8,
    pub kind: FaultKind,
    /// Time after the simulation starts, ms.
    pub after_ms: f64,
    /// EMCY error code (emcy only); `None` = the drive simulation's default.
    pub code: Option<u16>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawFault {
    node: u8,
    kind: FaultKind,
    after_ms: f64,
    code: Option<u16>,
}

/// `[[fault]]`: each on a node of the machine.
pub(super) fn build_faults(
    raw: &[RawFault],
    path: &Path,
    machine: &MachineConfig,
) -> Result<Vec<Fault>, ScenarioError> {
    let bad = |key: &str, message: String| invalid(path, key, message);
    let mut faults = Vec::with_capacity(raw.len());
    for (i, f) in raw.iter().enumerate() {
        if !machine.axes.iter().any(|a| a.node == Some(f.node)) {
            return Err(bad(
                &format!("fault[{i}].node"),
                format!(
                    "no axis of machine \"{}\" is on node {}",
                    machine.name, f.node
                ),
            ));
        }
        check_range(
            path,
            &format!("fault[{i}].after_ms"),
            f.after_ms,
            0.0,
            1e9,
            true,
        )?;
        if f.code.is_some() && f.kind != FaultKind::Emcy {
            return Err(bad(
                &format!("fault[{i}].code"),
                "only an \"emcy\" fault has an error code".into(),
            ));
        }
        faults.push(Fault {
            node: f.node,
            kind: f.kind,
            after_ms: f.after_ms,
            code: f.code,
        });
    }
    Ok(faults)
}
