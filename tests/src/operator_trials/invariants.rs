//! The four invariants of issue 34, checked on one trial's check result, run report,
//! recorded motion and state folder:
//! - **I1** no contact outside a probing move within the documented reach and
//!   tolerances; beyond them the contact is caught, nothing moves after it, and the
//!   message names what to check;
//! - **I2** every result within 4 u + 0.5 µm of the truth (plus what the docs say a
//!   result does not cover), or a refusal / stop whose message names what to check;
//! - **I3** `check` refuses what `run` refuses, at the same block with the same
//!   message; what `check` accepts, `run` does not refuse before moving nor stop at a
//!   move `check` planned;
//! - **I4** the state folder is byte for byte as before the cycle that failed.

use super::recorder::Act;
use super::setup::{Setup, Truth};
use cycles::results::{ProgramReport, Status};
use hal::ErrorKind;

/// 0.5 µm, the absolute slack of I2, mm.
pub const SLACK: f64 = 0.0005;
/// The same slack as an angle over the 60 mm a 431's points span, deg.
const ANGLE_SLACK: f64 = SLACK / 60.0 * 57.295_779_513;

#[derive(Clone, Debug, PartialEq)]
pub struct Violation {
    /// "I1" .. "I4".
    pub invariant: &'static str,
    /// The known defect class of issue 34 this matches, or "NEW".
    pub class: &'static str,
    pub detail: String,
}

/// Everything one trial left to judge.
pub struct Seen<'a> {
    pub setup: &'a Setup,
    /// `check`'s refusal (its message), `None` when it accepted the program.
    pub check: Option<String>,
    pub report: &'a ProgramReport,
    pub acts: &'a [Act],
    /// The state folder before the run and at each cycle's start.
    pub before: Vec<(String, Vec<u8>)>,
    pub at_cycle_start: Vec<Vec<(String, Vec<u8>)>>,
    pub after: Vec<(String, Vec<u8>)>,
}

/// Why the run ended early: the program's stop, else a failed cycle's message.
pub fn run_message(report: &ProgramReport) -> Option<String> {
    report.stopped.clone().or_else(|| {
        report
            .cycles
            .iter()
            .find(|c| c.status != Status::Ok)
            .and_then(|c| c.message.clone())
    })
}

/// The message names something the operator can check: a parameter (`Q407`), a
/// position (`X+12.5`), the preset, the probe table or where to put the probe.
pub fn names_what_to_check(msg: &str) -> bool {
    // The runner's note on the program's coordinates and the machine's own words on
    // where a move went name nothing the operator typed wrong.
    let msg = msg
        .split(" (the program's coordinates were relative to")
        .next()
        .unwrap_or(msg);
    let msg = without_where_it_went(msg);
    let b = msg.as_bytes();
    let parameter = b.windows(2).any(|w| w[0] == b'Q' && w[1].is_ascii_digit());
    let position = b.windows(3).any(|w| {
        b"XYZABC".contains(&w[0]) && (w[1] == b'+' || w[1] == b'-') && w[2].is_ascii_digit()
    });
    parameter
        || position
        || [
            "position the probe",
            "preset",
            "probe table",
            "TOOL CALL",
            "LBL",
            "software limits",
        ]
        .iter()
        .any(|k| msg.contains(k))
}

/// `msg` without the world machine's words on where a positioning move went (`the
/// probe touched while positioning to [x, y, z]`, tests/src/world_machine.rs): they
/// name the move, not what to check. What the cycle adds after them stays.
fn without_where_it_went(msg: &str) -> String {
    const WENT: &str = "touched while positioning to [";
    match msg.split_once(WENT) {
        Some((before, after)) => {
            let rest = after.split_once(']').map_or("", |(_, r)| r);
            format!("{before}{rest}")
        }
        None => msg.to_string(),
    }
}

fn is_contact(a: &Act) -> bool {
    !a.probing
        && matches!(
            a.failed,
            Some(ErrorKind::ProbeCollision) | Some(ErrorKind::AlreadyDeflected)
        )
}

fn v(invariant: &'static str, detail: String) -> Violation {
    Violation {
        invariant,
        class: "NEW",
        detail,
    }
}

pub fn check(seen: &Seen) -> Vec<Violation> {
    let mut out = Vec::new();
    let msg = run_message(seen.report);
    let collision = seen.acts.iter().position(is_contact);
    i1(seen, collision, msg.as_deref(), &mut out);
    i2(seen, collision.is_some(), msg.as_deref(), &mut out);
    i3(seen, collision.is_some(), msg.as_deref(), &mut out);
    i4(seen, &mut out);
    out
}

fn i1(seen: &Seen, collision: Option<usize>, msg: Option<&str>, out: &mut Vec<Violation>) {
    let Some(at) = collision else { return };
    let msg = msg.unwrap_or("(no message)");
    if seen.acts.len() > at + 1 {
        out.push(v(
            "I1",
            format!(
                "{} more moves after the contact: {msg}",
                seen.acts.len() - at - 1
            ),
        ));
    }
    if seen.setup.beyond.is_empty() {
        out.push(v(
            "I1",
            format!("a contact outside a probing move, within the documented reach: {msg}"),
        ));
    } else if !names_what_to_check(msg) {
        out.push(v(
            "I1",
            format!(
                "beyond the docs ({}): the contact was caught, but the message names nothing to check: {msg}",
                seen.setup.beyond.join("; ")
            ),
        ));
    }
}

fn i2(seen: &Seen, collision: bool, msg: Option<&str>, out: &mut Vec<Violation>) {
    let s = seen.setup;
    let results: Vec<_> = seen
        .report
        .cycles
        .iter()
        .filter(|c| c.cycle == s.cycle)
        .collect();
    if seen.report.completed() && seen.check.is_none() && results.len() < s.runs {
        out.push(v(
            "I2",
            format!(
                "the program ran to its end without a word, but cycle {} ran {} times of {}",
                s.cycle,
                results.len(),
                s.runs
            ),
        ));
    }
    if !seen.report.completed() && !collision {
        let m = msg.or(seen.check.as_deref()).unwrap_or("(no message)");
        if !names_what_to_check(m) {
            out.push(v(
                "I2",
                format!("stopped with a message that names nothing to check: {m}"),
            ));
        }
    }
    for (k, c) in results
        .iter()
        .enumerate()
        .filter(|(_, c)| c.status == Status::Ok)
    {
        against_truth(s, c, k == 0, out);
    }
}

/// One result of the cycle under test against the truth (I2).
/// `first`: the program's first run of the cycle (Q431 = 2 moves the preset to the
/// sphere after it: a repeat measures from there).
fn against_truth(
    s: &Setup,
    c: &cycles::results::CycleResult,
    first: bool,
    out: &mut Vec<Violation>,
) {
    {
        let against = |name: &str, got: f64, want: f64, u: Option<f64>, slack: f64| {
            let Some(u) = u else {
                return Some(v(
                    "I2",
                    format!("{name} = {got:+.6} carries no uncertainty"),
                ));
            };
            let d = (got - want).abs();
            (d.is_nan() || d > 4.0 * u + slack).then(|| {
                v(
                    "I2",
                    format!(
                        "{name} = {got:+.6}, the truth {want:+.6}: off by {d:.6}, more than 4 u ({u:.6}) + {slack:.6}"
                    ),
                )
            })
        };
        match &s.truth {
            Truth::Kinematics {
                check_errors,
                centre,
                check_preset,
                q147,
                allow_pos,
                allow_preset,
            } => {
                let Some(k) = c.kinematics.as_ref() else {
                    out.push(v("I2", "451 without its kinematics report".into()));
                    return;
                };
                let u_pos = k
                    .errors_u
                    .iter()
                    .filter(|(n, _)| {
                        n.starts_with("EX") || n.starts_with("EY") || n.starts_with("EZ")
                    })
                    .map(|(_, u)| *u)
                    .fold(0.0, f64::max);
                if *check_errors {
                    // Errors without u were not identified (kept from the file).
                    for (name, got) in k
                        .errors_after
                        .iter()
                        .filter(|(n, _)| k.errors_u.contains_key(*n))
                    {
                        let want = s.sc.truth.get(name).unwrap_or(0.0);
                        let angle = name.starts_with("EA")
                            || name.starts_with("EB")
                            || name.starts_with("EC");
                        let slack = if angle {
                            ANGLE_SLACK + (allow_pos / 100.0).to_degrees()
                        } else {
                            SLACK + allow_pos
                        };
                        out.extend(against(
                            name,
                            *got,
                            want,
                            k.errors_u.get(name).copied(),
                            slack,
                        ));
                    }
                }
                let tol = SLACK + allow_preset + 4.0 * u_pos;
                if *check_preset {
                    for (i, axis) in ["X", "Y", "Z"].iter().enumerate() {
                        let name = format!("preset {axis}");
                        out.extend(against(&name, k.preset_after[i], centre[i], Some(0.0), tol));
                    }
                }
                for (i, q) in ["Q147", "Q148", "Q149"]
                    .iter()
                    .enumerate()
                    .filter(|_| first)
                {
                    if let Some(got) = c.q.get(*q) {
                        out.extend(against(q, *got, q147[i], Some(0.0), tol));
                    }
                }
            }
            Truth::Calibration(cols) | Truth::Plane(cols) => {
                for (name, want, allow) in cols {
                    let Some(got) = c.q.get(*name) else {
                        out.push(v("I2", format!("no {name} in the result")));
                        continue;
                    };
                    let u = c.u.get(*name).copied();
                    if u.is_none() && name.starts_with("CAL_OF") {
                        // Not measured (no orientable spindle): kept, and said.
                        continue;
                    }
                    let angle = *name == "Q158" || *name == "Q159";
                    let slack = if angle { ANGLE_SLACK } else { SLACK + allow };
                    out.extend(against(name, *got, *want, u, slack));
                }
            }
            Truth::Point(want, allow) => match c.q.get("Q164") {
                Some(got) => out.extend(against(
                    "Q164",
                    *got,
                    *want,
                    c.u.get("Q164").copied(),
                    SLACK + allow,
                )),
                None => out.push(v("I2", "no Q164 in the result".into())),
            },
        }
    }
}

fn i3(seen: &Seen, collision: bool, msg: Option<&str>, out: &mut Vec<Violation>) {
    match &seen.check {
        Some(check) => {
            let said = check.split_once("): ").map_or(check.as_str(), |(_, m)| m);
            let said = said.strip_suffix("; nothing moved").unwrap_or(said);
            let run = msg.unwrap_or("");
            if !seen.acts.is_empty() {
                out.push(v(
                    "I3",
                    format!(
                        "check refused ({check}), but run moved {} times: {run}",
                        seen.acts.len()
                    ),
                ));
            } else if !run.contains(said) {
                out.push(v("I3", format!("check: {check}\nrun: {run}")));
            }
        }
        None if !seen.report.completed() && !collision => {
            let run = msg.unwrap_or("(no message)");
            if seen.acts.is_empty() {
                out.push(v(
                    "I3",
                    format!("check accepted; run refused before moving: {run}"),
                ));
            } else if let Some(a) = seen.acts.last().filter(|a| {
                !a.probing
                    && matches!(
                        a.failed,
                        Some(ErrorKind::SoftwareLimit) | Some(ErrorKind::InvalidRequest)
                    )
            }) {
                out.push(v(
                    "I3",
                    format!("check accepted; run stopped at a positioning move the machine refused ({:?}): {run}", a.failed),
                ));
            }
        }
        None => {}
    }
}

fn i4(seen: &Seen, out: &mut Vec<Violation>) {
    if seen.report.completed() {
        return;
    }
    let before = seen.at_cycle_start.last().unwrap_or(&seen.before);
    if *before != seen.after {
        let names = |s: &[(String, Vec<u8>)]| s.iter().map(|(n, _)| n.clone()).collect::<Vec<_>>();
        let changed: Vec<String> = seen
            .after
            .iter()
            .filter(|f| !before.contains(f))
            .map(|(n, _)| n.clone())
            .chain(
                names(before)
                    .into_iter()
                    .filter(|n| !seen.after.iter().any(|(m, _)| m == n)),
            )
            .collect();
        out.push(v(
            "I4",
            format!("written after a refusal or a stop: {}", changed.join(", ")),
        ));
    }
}
