//! `probebridge bench cycles`: the machine time of the shipped examples, as `check`
//! predicts it and as `run` takes it on the simulator's clock, beside the plan's lower
//! bound, one row per cycle: the table of docs/cycles.md ("Machine time"), from the
//! current tree, so that the next change can be measured against it. Each example runs
//! in a fresh state folder of its own, by this very binary (`check --json`, then
//! `run --json`), as a user would. With `--realtime` each also runs paced in real time
//! (`run --realtime`), and the wall time of each cycle, from the line that starts it
//! to the one that ends it on `run`'s stderr, stands beside the machine time it
//! reported: a measurement that prints, not a test (the machines are shared).

use std::io::BufRead as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

/// The shipped examples and the scenario each is written for (docs/cycles.md,
/// "Example programs").
pub const EXAMPLES: [(&str, &str); 11] = [
    ("431-plane.h", "tilted-plane.toml"),
    ("431-plane-y.h", "tilted-plane-y.toml"),
    ("444-freeform.h", "freeform.toml"),
    ("444-seed.h", "seed-444.toml"),
    ("451-optimise.h", "demo-sphere.toml"),
    ("451-check.h", "demo-sphere.toml"),
    ("451-preset-set.h", "demo-sphere.toml"),
    ("451-preset-247.h", "demo-sphere.toml"),
    ("451-head-b.h", "head-b-table-c.toml"),
    ("450-save-restore.h", "demo-sphere.toml"),
    ("460-calibrate.h", "demo-sphere.toml"),
];

#[derive(clap::Args, Clone, Debug)]
pub struct CyclesBenchArgs {
    /// The folder holding `programs/` and `scenarios/`.
    #[arg(long, default_value = "configs")]
    pub configs: PathBuf,
    /// Only the examples whose program name contains this.
    #[arg(long)]
    pub only: Option<String>,
    /// Write the rows as JSON too.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Also run each example paced in real time (`run --realtime`) and print each
    /// cycle's wall time beside the machine time that run reported; takes as long as
    /// the examples keep the machine (about 16 minutes for all).
    #[arg(long)]
    pub realtime: bool,
}

/// One cycle of one example.
#[derive(Clone, Debug, serde::Serialize)]
struct Row {
    program: String,
    block: u64,
    cycle: u64,
    predicted_s: f64,
    measured_s: f64,
    lower_bound_s: f64,
    /// `--realtime`: the machine time the paced run reported, and the cycle's wall time.
    #[serde(skip_serializing_if = "Option::is_none")]
    paced: Option<Paced>,
}

/// One cycle of a run paced in real time.
#[derive(Clone, Copy, Debug, serde::Serialize)]
struct Paced {
    machine_time_s: f64,
    wall_time_s: f64,
}

pub fn run(args: &CyclesBenchArgs) -> Result<(), String> {
    let exe = std::env::current_exe().map_err(|e| format!("this program's path: {e}"))?;
    let scratch =
        std::env::temp_dir().join(format!("probebridge-bench-cycles-{}", std::process::id()));
    let mut rows = Vec::new();
    let mut failed = None;
    for (i, (program, scenario)) in EXAMPLES.iter().enumerate() {
        if args.only.as_deref().is_some_and(|o| !program.contains(o)) {
            continue;
        }
        let ex = Example {
            exe: &exe,
            configs: &args.configs,
            program,
            scenario,
            index: i,
        };
        let rows_of = example(&ex, &scratch.join(format!("{i}"))).and_then(|r| {
            if args.realtime {
                paced(&ex, &scratch.join(format!("{i}-realtime")), r)
            } else {
                Ok(r)
            }
        });
        match rows_of {
            Ok(mut r) => rows.append(&mut r),
            Err(e) => {
                failed = Some(format!("{program}: {e}"));
                break;
            }
        }
    }
    let _ = std::fs::remove_dir_all(&scratch);
    say!("{}", table(&rows));
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&rows).expect("numbers and strings serialise");
        std::fs::write(path, text).map_err(|e| format!("{}: {e}", path.display()))?;
    }
    failed.map_or(Ok(()), Err)
}

/// One shipped example, run by this very binary.
struct Example<'a> {
    exe: &'a Path,
    configs: &'a Path,
    program: &'a str,
    scenario: &'a str,
    /// Its place in [`EXAMPLES`]: names its iceoryx2 services.
    index: usize,
}

impl Example<'_> {
    /// `probebridge VERB PROGRAM --scenario SCENARIO --state-dir STATE`; a `run` gets
    /// an iceoryx2 service prefix of its own (`tag` tells the runs of one example apart).
    fn command(&self, verb: &str, state: &Path, tag: &str) -> Command {
        let mut cmd = Command::new(self.exe);
        cmd.arg(verb)
            .arg(self.configs.join("programs").join(self.program))
            .arg("--scenario")
            .arg(self.configs.join("scenarios").join(self.scenario))
            .arg("--state-dir")
            .arg(state);
        if verb == "run" {
            let service = format!("pb-bench-cycles-{tag}{}-{}", std::process::id(), self.index);
            cmd.args(["--yes", "--service", &service]);
        }
        cmd
    }
}

/// The cycles of a `run --json` file.
fn ran_cycles(json: &Path) -> Result<Vec<serde_json::Value>, String> {
    let text = std::fs::read_to_string(json).map_err(|e| format!("{}: {e}", json.display()))?;
    let ran: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| format!("run --json: {e}"))?;
    ran["cycles"]
        .as_array()
        .cloned()
        .ok_or_else(|| format!("{}: no cycles", json.display()))
}

/// `check --json` then `run --json` of one example in the state folder `state`.
fn example(ex: &Example, state: &Path) -> Result<Vec<Row>, String> {
    let out = ex
        .command("check", state, "")
        .arg("--json")
        .output()
        .map_err(|e| format!("check: {e}"))?;
    if !out.status.success() {
        return Err(format!(
            "check failed: {}",
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    let planned: serde_json::Value =
        serde_json::from_slice(&out.stdout).map_err(|e| format!("check --json: {e}"))?;
    let json = state.join("run.json");
    let out = ex
        .command("run", state, "")
        .arg("--json")
        .arg(&json)
        .output()
        .map_err(|e| format!("run: {e}"))?;
    if !out.status.success() {
        return Err(format!(
            "run failed: {}",
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    let r = ran_cycles(&json)?;
    let Some(p) = planned["cycles"].as_array() else {
        return Err("check --json: no cycles".into());
    };
    if p.len() != r.len() {
        return Err(format!(
            "check planned {} cycles, run ran {}",
            p.len(),
            r.len()
        ));
    }
    let f = |v: &serde_json::Value, k: &str| v[k].as_f64().unwrap_or(f64::NAN);
    Ok(p.iter()
        .zip(&r)
        .map(|(p, r)| Row {
            program: ex.program.to_string(),
            block: p["block"].as_u64().unwrap_or(0),
            cycle: p["cycle"].as_u64().unwrap_or(0),
            predicted_s: f(p, "predicted_machine_time_s"),
            measured_s: f(r, "machine_time_s"),
            lower_bound_s: f(p, "lower_bound_s"),
            paced: None,
        })
        .collect())
}

/// `run --realtime --json` of one example in the state folder `state`: each cycle's
/// wall time, from its `[k/n] block B (line L): cycle C` line on stderr to its status
/// line (`    Ok`, `    Error`, `    Aborted`), beside the machine time it reported.
fn paced(ex: &Example, state: &Path, mut rows: Vec<Row>) -> Result<Vec<Row>, String> {
    let json = state.join("run.json");
    std::fs::create_dir_all(state).map_err(|e| format!("{}: {e}", state.display()))?;
    let mut child = ex
        .command("run", state, "rt-")
        .arg("--json")
        .arg(&json)
        .arg("--realtime")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("run --realtime: {e}"))?;
    let stderr = child.stderr.take().expect("piped");
    let mut walls = Vec::new();
    let mut started = None;
    let mut said = Vec::new();
    for line in std::io::BufReader::new(stderr).lines() {
        let line = line.map_err(|e| format!("run --realtime's stderr: {e}"))?;
        let now = Instant::now();
        if line.starts_with('[') && line.contains("] block ") && line.contains("): cycle ") {
            started = Some(now);
        } else if let ("    Ok" | "    Error" | "    Aborted", Some(t0)) = (line.as_str(), started)
        {
            walls.push(now.duration_since(t0).as_secs_f64());
            started = None;
        }
        said.push(line);
    }
    let status = child.wait().map_err(|e| format!("run --realtime: {e}"))?;
    if !status.success() {
        return Err(format!("run --realtime failed: {}", said.join("\n")));
    }
    let cycles = ran_cycles(&json)?;
    if cycles.len() != rows.len() || walls.len() != rows.len() {
        return Err(format!(
            "run --realtime: {} cycles in its JSON, {} ended on its stderr, {} planned",
            cycles.len(),
            walls.len(),
            rows.len()
        ));
    }
    for ((row, c), wall) in rows.iter_mut().zip(&cycles).zip(walls) {
        row.paced = Some(Paced {
            machine_time_s: c["machine_time_s"].as_f64().unwrap_or(f64::NAN),
            wall_time_s: wall,
        });
    }
    Ok(rows)
}

/// The rows as a Markdown table (docs/cycles.md's form), with the paced runs' columns
/// when there are any.
fn table(rows: &[Row]) -> String {
    let realtime = rows.iter().any(|r| r.paced.is_some());
    let mut s = String::from(
        "| program | block | cycle | predicted | measured | predicted - measured | lower bound | measured / lower bound |",
    );
    s.push_str(if realtime {
        " paced: machine time | paced: wall time | wall - machine |\n|---|---|---|---|---|---|---|---|---|---|---|\n"
    } else {
        "\n|---|---|---|---|---|---|---|---|\n"
    });
    for r in rows {
        let ratio = if r.lower_bound_s > 0.0 {
            format!("{:.2}", r.measured_s / r.lower_bound_s)
        } else {
            "-".into()
        };
        let off = if r.measured_s > 0.0 {
            format!(
                "{:+.1} %",
                (r.predicted_s - r.measured_s) / r.measured_s * 100.0
            )
        } else {
            "-".into()
        };
        s.push_str(&format!(
            "| `{}` | {} | {} | {:.2} s | {:.2} s | {off} | {:.2} s | {ratio} |",
            r.program, r.block, r.cycle, r.predicted_s, r.measured_s, r.lower_bound_s
        ));
        match r.paced {
            // A cycle that moves nothing (450) takes milliseconds: no ratio there.
            Some(p) if p.machine_time_s >= 0.05 => s.push_str(&format!(
                " {:.2} s | {:.2} s | {:+.1} % |\n",
                p.machine_time_s,
                p.wall_time_s,
                (p.wall_time_s - p.machine_time_s) / p.machine_time_s * 100.0
            )),
            Some(p) => s.push_str(&format!(
                " {:.2} s | {:.2} s | - |\n",
                p.machine_time_s, p.wall_time_s
            )),
            None if realtime => s.push_str(" - | - | - |\n"),
            None => s.push('\n'),
        }
    }
    s
}
