//! Cycle results as the CLI prints and saves them:
//! `{"cycles": [{"block": 13, "cycle": 444, "q": {"Q151": 0.0}, "qs": {}, "status": "ok",
//! "message": null}]}`.

use crate::cycle451::report::KinematicsReport;
use crate::cycle460::report::CalibrationReport;
use crate::machine_time::TimeSplit;
use crate::q_params::QValue;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::PathBuf;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    Ok,
    Error,
    /// The operator stopped the machine while the cycle ran (a signal): the axes were
    /// braked, nothing was written back.
    Aborted,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CycleResult {
    /// NC block number (the line when the block has none).
    pub block: u32,
    pub cycle: u16,
    /// Result Q parameters, mm and degrees; cycle 460: the probe table row's columns
    /// R, CAL_OF1, CAL_OF2 and L after it (mm).
    pub q: BTreeMap<String, f64>,
    pub qs: BTreeMap<String, String>,
    pub status: Status,
    /// Why it failed, or why the program stopped after it (Q309, no confirmation).
    pub message: Option<String>,
    /// The standard uncertainty (k = 1) of results in `q`, by the same name, mm and
    /// degrees (see `docs/cycles.md`, "Uncertainty").
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub u: BTreeMap<String, f64>,
    /// Cycle 451: every measuring position, its sphere, the errors before and after.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kinematics: Option<Box<KinematicsReport>>,
    /// Cycle 460: the probe table row before and after, what was kept and why.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration: Option<Box<CalibrationReport>>,
    /// How long the cycle kept the machine, s, on the machine's own clock
    /// ([`hal::Machine::clock_ns`]), whatever its status.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub machine_time_s: Option<f64>,
    /// Where that time went.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub machine_time_split_s: Option<TimeSplit>,
}

impl CycleResult {
    /// The cycle was cut short by the operator's stop.
    pub fn aborted(block: u32, cycle: u16, message: impl Into<String>) -> Self {
        CycleResult {
            status: Status::Aborted,
            ..Self::error(block, cycle, message)
        }
    }

    pub fn error(block: u32, cycle: u16, message: impl Into<String>) -> Self {
        CycleResult {
            block,
            cycle,
            q: BTreeMap::new(),
            qs: BTreeMap::new(),
            status: Status::Error,
            message: Some(message.into()),
            u: BTreeMap::new(),
            kinematics: None,
            calibration: None,
            machine_time_s: None,
            machine_time_split_s: None,
        }
    }

    /// With the machine time `split` measured.
    pub fn timed(self, split: TimeSplit) -> Self {
        CycleResult {
            machine_time_s: Some(split.total()),
            machine_time_split_s: Some(split),
            ..self
        }
    }
}

/// What a cycle gives the report.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CycleOutput {
    pub q: BTreeMap<String, f64>,
    pub qs: BTreeMap<String, String>,
    /// The standard uncertainty (k = 1) of results in `q`, by name.
    pub u: BTreeMap<String, f64>,
    /// The program stops after this cycle, with this message (Q309, no confirmation).
    pub stop: Option<String>,
    /// Cycle 451's report.
    pub kinematics: Option<Box<KinematicsReport>>,
    /// Cycle 460's report.
    pub calibration: Option<Box<CalibrationReport>>,
    /// Measuring logs written.
    pub logs: Vec<PathBuf>,
}

impl CycleOutput {
    pub fn new(q: BTreeMap<String, f64>, stop: Option<String>) -> Self {
        Self {
            q,
            stop,
            ..Self::default()
        }
    }
}

/// All cycles that ran, in order; `stopped` says why the program ended early.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ProgramReport {
    pub cycles: Vec<CycleResult>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stopped: Option<String>,
    /// The operator stopped the program (a signal): the axes were braked.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub aborted: bool,
    /// Measuring logs written.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub protocols: Vec<PathBuf>,
    /// `FN 14: ERROR = n` stopped the program.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<ErrorStop>,
    /// The final value of every parameter the run wrote (its assignments and its
    /// cycles' results), by name: `"Q10": 12.5`, `"QS0": "text"`.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub parameters: BTreeMap<String, QValue>,
}

/// `FN 14: ERROR = n`: where the program stopped, the number, and the text the
/// machine configuration gives it (`[cycles.errors]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ErrorStop {
    pub line: usize,
    pub number: u32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub text: Option<String>,
}

impl ProgramReport {
    /// The program ran to its end and every cycle is ok.
    pub fn completed(&self) -> bool {
        self.stopped.is_none()
            && !self.aborted
            && self.cycles.iter().all(|c| c.status == Status::Ok)
    }

    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self)
            .expect("a report of strings and finite numbers serialises")
    }

    /// One `Qnnn = value` line per result, grouped by block (the text form).
    pub fn to_text(&self) -> String {
        let mut out = String::new();
        for c in &self.cycles {
            let status = match c.status {
                Status::Ok => "ok",
                Status::Error => "error",
                Status::Aborted => "aborted",
            };
            out.push_str(&format!("block {} cycle {}: {status}", c.block, c.cycle));
            if let Some(m) = &c.message {
                out.push_str(&format!(" ({m})"));
            }
            out.push('\n');
            for (k, v) in &c.q {
                match c.u.get(k) {
                    Some(u) => out.push_str(&format!("  {k} = {v:+.4} ± {u:.5}\n")),
                    None => out.push_str(&format!("  {k} = {v:+.4}\n")),
                }
            }
            for (k, v) in &c.qs {
                out.push_str(&format!("  {k} = \"{v}\"\n"));
            }
            if let Some(k) = &c.kinematics {
                out.push_str(&k.summary());
            }
            if let Some(k) = &c.calibration {
                out.push_str(&k.summary());
            }
            if let Some(t) = &c.machine_time_split_s {
                out.push_str(&format!("  machine time {t}\n"));
            }
        }
        // The parameters the cycles above do not already show with their final value
        // (a cycle's results are parameters too: listing them again doubled them).
        let mut shown: BTreeMap<&str, QValue> = BTreeMap::new();
        for c in &self.cycles {
            shown.extend(c.q.iter().map(|(k, v)| (k.as_str(), QValue::Number(*v))));
            shown.extend(
                c.qs.iter()
                    .map(|(k, v)| (k.as_str(), QValue::Text(v.clone()))),
            );
        }
        let rest: Vec<_> = self
            .parameters
            .iter()
            .filter(|(k, v)| shown.get(k.as_str()) != Some(*v))
            .collect();
        if !rest.is_empty() {
            out.push_str("parameters\n");
            for (k, v) in rest {
                out.push_str(&format!("  {k} = {v}\n"));
            }
        }
        if let Some(s) = &self.stopped {
            out.push_str(&format!("program stopped: {s}\n"));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_result_is_printed_once() {
        let mut q = BTreeMap::new();
        q.insert("Q150".to_string(), 1.25);
        let mut report = ProgramReport {
            cycles: vec![CycleResult {
                block: 3,
                cycle: 451,
                q,
                qs: BTreeMap::new(),
                status: Status::Ok,
                message: None,
                u: BTreeMap::new(),
                kinematics: None,
                calibration: None,
                machine_time_s: None,
                machine_time_split_s: None,
            }],
            ..Default::default()
        };
        report
            .parameters
            .insert("Q150".into(), QValue::Number(1.25));
        report.parameters.insert("Q10".into(), QValue::Number(2.0));
        let text = report.to_text();
        assert_eq!(text.matches("Q150 = +1.2500").count(), 1, "{text}");
        assert!(text.contains("parameters\n  Q10 = +2.0000\n"), "{text}");
    }
}
