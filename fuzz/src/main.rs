//! `probebridge-fuzz TARGET|all [--seconds N] [--iterations N] [--seed S]`: runs fuzz
//! targets and prints one `RESULT` line per target; exit 1 when anything was found.

use probebridge_fuzz::driver::{self, Budget};
use probebridge_fuzz::targets;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

const USAGE: &str = "\
usage: probebridge-fuzz --list
       probebridge-fuzz TARGET|all [--seconds N] [--iterations N] [--seed S]
                        [--crashes DIR] [--timeout-ms MS]
       probebridge-fuzz TARGET --reproduce FILE

Runs TARGET (or every target in turn, each for the budget) on its seeds, then on
mutations of its corpus for N seconds (default 60) or N inputs. Findings (a panic, an
input taking more than --timeout-ms of CPU, default 1000) are saved under --crashes
(default fuzz/crashes in the workspace) and listed; the exit status is then 1.
--reproduce runs one saved input with the normal panic output.";

struct Args {
    target: String,
    budget: Budget,
    reproduce: Option<PathBuf>,
}

fn parse_args() -> Result<Option<Args>, String> {
    let mut it = std::env::args().skip(1);
    let mut target = None;
    let mut budget = Budget {
        crash_dir: Some(probebridge_fuzz::corpus::workspace().join("fuzz/crashes")),
        progress: true,
        ..Budget::default()
    };
    let mut reproduce = None;
    while let Some(a) = it.next() {
        let mut value = |name: &str| it.next().ok_or(format!("{name} needs a value"));
        match a.as_str() {
            "-h" | "--help" => {
                println!("{USAGE}");
                return Ok(None);
            }
            "--list" => {
                for t in targets::all() {
                    println!("{:22} {}", t.name, t.about);
                }
                return Ok(None);
            }
            "--seconds" => {
                budget.seconds = value("--seconds")?
                    .parse()
                    .ok()
                    .filter(|s: &f64| s.is_finite() && *s >= 0.0)
                    .ok_or("--seconds: not a number of seconds")?;
            }
            "--iterations" => {
                budget.iterations = Some(
                    value("--iterations")?
                        .parse()
                        .map_err(|_| "--iterations: not a count")?,
                );
            }
            "--seed" => {
                budget.seed = value("--seed")?
                    .parse()
                    .map_err(|_| "--seed: not a number")?;
            }
            "--timeout-ms" => {
                let ms: u64 = value("--timeout-ms")?
                    .parse()
                    .map_err(|_| "--timeout-ms: not a number")?;
                budget.timeout = Duration::from_millis(ms.max(1));
                budget.hang = budget.hang.max(budget.timeout * 10);
            }
            "--crashes" => budget.crash_dir = Some(PathBuf::from(value("--crashes")?)),
            "--reproduce" => reproduce = Some(PathBuf::from(value("--reproduce")?)),
            t if !t.starts_with('-') && target.is_none() => target = Some(t.to_string()),
            other => return Err(format!("unexpected argument {other:?}\n\n{USAGE}")),
        }
    }
    let target = target.ok_or(format!("no target given\n\n{USAGE}"))?;
    Ok(Some(Args {
        target,
        budget,
        reproduce,
    }))
}

fn main() -> ExitCode {
    let args = match parse_args() {
        Ok(Some(a)) => a,
        Ok(None) => return ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("probebridge-fuzz: {e}");
            return ExitCode::from(2);
        }
    };
    let chosen = if args.target == "all" {
        targets::all()
    } else {
        match targets::find(&args.target) {
            Some(t) => vec![t],
            None => {
                eprintln!("probebridge-fuzz: no target {:?} (see --list)", args.target);
                return ExitCode::from(2);
            }
        }
    };
    if let Some(path) = &args.reproduce {
        let input = match std::fs::read(path) {
            Ok(i) => i,
            Err(e) => {
                eprintln!("probebridge-fuzz: {}: {e}", path.display());
                return ExitCode::from(2);
            }
        };
        for t in &chosen {
            let (features, cpu) = driver::reproduce(t, &input);
            println!(
                "{}: no panic, {} outcome features, {:.3} s of CPU",
                t.name,
                features.len(),
                cpu.as_secs_f64()
            );
        }
        return ExitCode::SUCCESS;
    }
    let mut found = 0;
    for t in &chosen {
        let report = driver::run(t, &args.budget);
        for f in &report.findings {
            println!("FINDING target={} {f}", t.name);
        }
        println!("{report}");
        found += report.findings.len();
    }
    if found > 0 {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}
