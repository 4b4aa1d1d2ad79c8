//! Runs any number of generated operators (issue 34) and prints the summary line and
//! each violation with its shrunk case: `scripts/operator-trials --cases N --seed S`.

use probebridge_tests::operator_trials::{self, draw::Shares, ShrinkPolicy};

fn arg(args: &[String], name: &str, default: f64) -> Result<f64, String> {
    match args.iter().position(|a| a == name) {
        None => Ok(default),
        Some(i) => args
            .get(i + 1)
            .ok_or(format!("{name} needs a value"))?
            .parse()
            .map_err(|e| format!("{name}: {e}")),
    }
}

/// One case: its genes, its program, what the docs promise, its verdict.
fn show(case: &operator_trials::Case) {
    println!("{case:?}");
    if let Ok(s) = operator_trials::setup::build(case) {
        println!("{}\nbeyond: {:?}\ntruth: {:?}", s.text, s.beyond, s.truth);
    }
    let t = operator_trials::trial(case);
    println!("{}: {:?}\n{:#?}", t.outcome.name(), t.message, t.violations);
}

/// Ends the process with `code`, removing the folder the trials wrote their files in
/// (`pbtest-<pid>` under the temp folder, `probebridge_tests::process_temp_dir`): run
/// outside `scripts/with-test-root`, nothing else would until the next test process.
fn finish(code: i32) -> ! {
    let dir = std::env::temp_dir().join(format!("pbtest-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(dir);
    std::process::exit(code)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.iter().any(|a| a == "--help" || a == "-h") {
        println!(
            "operator-trials [--cases N] [--seed S] [--can F] [--modbus F] [--shrink K] [--budget B] [--jobs J] [--verbose]\n\
             operator-trials --seed S --case I | --genes name=value,... | --nominal\n\
             N cases (default 200) of seed S (default 1); fractions F of them over CANopen and Modbus\n\
             (default 0.03 each); K violations of each kind shrunk (default 1) with at most B trials each (default 150);\n\
             the cases on J threads (default 1; the summary is the same but for its duration)."
        );
        return;
    }
    let parsed = (|| -> Result<_, String> {
        Ok((
            arg(&args, "--cases", 200.0)? as u64,
            arg(&args, "--seed", 1.0)? as u64,
            arg(&args, "--can", 0.03)?,
            arg(&args, "--modbus", 0.03)?,
            arg(&args, "--shrink", 1.0)? as usize,
            arg(&args, "--budget", 150.0)? as usize,
            arg(&args, "--jobs", 1.0)? as usize,
        ))
    })();
    let (cases, seed, can, modbus, per_kind, budget, jobs) = match parsed {
        Ok(p) => p,
        Err(e) => {
            eprintln!("operator-trials: {e}");
            std::process::exit(2);
        }
    };
    let verbose = args.iter().any(|a| a == "--verbose");
    if let Some(i) = args.iter().position(|a| a == "--genes") {
        // A case written as genes: `--genes cycle=451,q408=310,rise=-1`.
        let mut case = operator_trials::Case::nominal();
        for pair in args.get(i + 1).map(String::as_str).unwrap_or("").split(',') {
            let Some((name, v)) = pair.split_once('=') else {
                continue;
            };
            match (
                operator_trials::Case::NAMES.iter().position(|n| *n == name),
                v.parse::<f64>(),
            ) {
                (Some(k), Ok(v)) => case.set(k, v),
                _ => {
                    eprintln!("operator-trials: --genes: {pair}: no such gene or not a number");
                    std::process::exit(2);
                }
            }
        }
        show(&case);
        finish(0);
    }
    if args.iter().any(|a| a == "--case") {
        // One case of the seed, with its program.
        let i = arg(&args, "--case", 0.0).unwrap_or(0.0) as u64;
        show(&operator_trials::draw::draw(
            seed,
            i,
            &Shares { can, modbus },
        ));
        finish(0);
    }
    if args.iter().any(|a| a == "--nominal") {
        // Every cycle on every machine with nominal genes: all must be ok.
        let mut bad = 0;
        for cycle in operator_trials::draw::CYCLES {
            for machine in 0..4 {
                let case = operator_trials::Case {
                    cycle: f64::from(cycle),
                    machine: f64::from(machine),
                    ..operator_trials::Case::nominal()
                };
                let t = operator_trials::trial(&case);
                println!(
                    "nominal {cycle} on {}: {} {:?} {:?}",
                    operator_trials::draw::MACHINES[machine as usize],
                    t.outcome.name(),
                    t.message,
                    t.violations
                );
                bad += usize::from(
                    !t.violations.is_empty() || t.outcome != operator_trials::Outcome::Ok,
                );
            }
        }
        finish(i32::from(bad > 0));
    }
    let shares = Shares { can, modbus };
    let policy = ShrinkPolicy { per_kind, budget };
    let summary =
        operator_trials::run_on_threads(seed, cases, &shares, &policy, jobs, |i, case, t| {
            if verbose || !t.violations.is_empty() {
                eprintln!(
                    "case {i}: cycle {} machine {} backend {}: {} {}{}",
                    case.cycle,
                    case.machine,
                    case.backend,
                    t.outcome.name(),
                    t.message.as_deref().unwrap_or(""),
                    if t.violations.is_empty() {
                        String::new()
                    } else {
                        format!(" [{} violations]", t.violations.len())
                    }
                );
            }
        });
    print!("{}", summary.report());
    println!("{}", summary.line());
    finish(i32::from(!summary.findings.is_empty()));
}
