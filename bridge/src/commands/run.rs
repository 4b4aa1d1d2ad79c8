//! `probebridge run PROGRAM`: every measuring cycle of an NC program, in order, on the
//! configured machine; results as a table, protocols in the machine's state folder
//! (or in `--out`), and JSON with `--json`. The preset table and the kinematics are
//! the machine's state ([`crate::machine_state`]), never the shipped `configs/`.

use crate::ipc::{EstimatorChild, EstimatorClient, IpcEstimator};
use crate::machine_state::machine_files;
use crate::output::write_atomic;
use crate::session::options::MachineOptions;
use crate::session::{cycles_config_with_presets, resolve_machine, Session};
use cycles::program::{Program, ProgramError};
use cycles::progress::ProgressEvent;
use cycles::runner::{
    check_complete, preflight_program, program_warnings, run_program, RunOptions,
};
use std::io::{BufRead, IsTerminal, Write};
use std::path::PathBuf;
use std::time::Duration;

/// Longest wait for one answer of the estimator process.
const ESTIMATOR_TIMEOUT: Duration = Duration::from_secs(10);

pub struct RunArgs {
    pub program: PathBuf,
    pub machine: MachineOptions,
    pub out: Option<PathBuf>,
    pub json: Option<PathBuf>,
    /// Go on without asking where a cycle asks for confirmation.
    pub yes: bool,
    /// The active kinematics file (cycles 450/451); default: in the machine's state
    /// folder.
    pub kinematics: Option<PathBuf>,
    /// Record the run in this history file.
    pub history: Option<PathBuf>,
    /// The preset table (cycles 247, 451); default: in the machine's state folder.
    pub presets: Option<PathBuf>,
    /// The state directory (`--state-dir`); default: [`crate::state_dir`]'s.
    pub state_dir: Option<PathBuf>,
}

/// Exit status: 0 every cycle succeeded, 1 a cycle failed or stopped the program,
/// 2 the program is invalid (nothing moved).
pub fn run(args: &RunArgs) -> Result<u8, String> {
    let (machine_cfg, scenario) = resolve_machine(&args.machine).map_err(|e| e.to_string())?;
    // The machine's state (preset table, kinematics) is never the shipped
    // configuration: it lives in the state folder, seeded from configs/ on first use,
    // which is once the program is found valid (a refused program writes nothing).
    let files = |seed: bool| {
        machine_files(
            &machine_cfg,
            args.state_dir.as_deref(),
            args.presets.as_deref(),
            args.kinematics.as_deref(),
            seed,
        )
    };
    let read_only = files(false)?;
    let mut cfg = state_cycles_config(&machine_cfg, scenario.as_ref(), &read_only)?;
    let Some(program) = validated(args, &cfg, &read_only.kinematics)? else {
        return Ok(2);
    };
    // Valid: the state files this run reads and writes (seeded now, the same contents).
    let files = files(true)?;
    for n in &files.notes {
        tell!("state: {n}");
    }
    cfg.presets = cycles::preset_table::PresetTable::load(&files.presets, &cfg.machine)
        .map_err(|e| e.to_string())?;
    use_state_probes(&mut cfg, &files.probes, &program)?;
    if let Some(n) = scenario.as_ref().and_then(|sc| sc.preset) {
        cfg.start_with_preset(n)?;
    }
    let out_dir = args.out.clone().unwrap_or_else(|| files.protocols_dir());
    std::fs::create_dir_all(&out_dir)
        .map_err(|e| format!("cannot create {}: {e}", out_dir.display()))?;
    crate::output::check_output(args.json.as_deref())?;

    // The session first: it claims the `--service` prefix, so a second run on the
    // same prefix is refused before it looks for an estimator.
    let mut session = Session::open(&args.machine).map_err(|e| e.to_string())?;
    // Cycle 451 fits its spheres and solves its identification in the estimator
    // process: use the one serving this prefix, or start one. It must subscribe before
    // the first contact is published (no probing move has run yet).
    let mut estimator = if program.cycles().any(|c| c.head.cycle == 451) {
        estimator_link(&args.machine.service)
    } else {
        None
    };
    for note in &session.notes {
        tell!("note: {note}");
    }
    let total = cycles::program_flow::cycle_count(&program);
    let mut done = 0usize;
    let mut progress = |ev: ProgressEvent| match ev {
        ProgressEvent::CycleStarted { block, cycle, line } => {
            done += 1;
            let count = progress_count(done, total);
            tell!("[{count}] block {block} (line {line}): cycle {cycle}");
        }
        ProgressEvent::Contact { centre, .. } => {
            tell!(
                "    contact at X{:+.4} Y{:+.4} Z{:+.4}",
                centre[0],
                centre[1],
                centre[2]
            );
        }
        ProgressEvent::Note { text, .. } => tell!("    {text}"),
        ProgressEvent::MeasuringLog { path, .. } => tell!("    protocol {}", path.display()),
        ProgressEvent::CycleFinished { status, .. } => tell!("    {status:?}"),
        _ => {}
    };
    let yes = args.yes;
    let mut confirm = |asked: &cycles::confirmation::Confirmation| -> bool {
        say!("{asked}");
        if yes {
            return true;
        }
        say_raw!("Press Enter to go on, or type n and Enter to stop: ");
        let _ = std::io::stdout().flush();
        let stdin = std::io::stdin();
        if !stdin.is_terminal() {
            // Without an operator there is nobody to confirm: stop (use --yes).
            say!();
        }
        let mut line = String::new();
        match stdin.lock().read_line(&mut line) {
            Ok(0) | Err(_) => false,
            Ok(_) => !line.trim().eq_ignore_ascii_case("n"),
        }
    };
    let mut opts = RunOptions {
        out_dir,
        confirm: &mut confirm,
        progress: &mut progress,
        kinematics: Some(files.kinematics.clone()),
        estimator: None,
    };
    let mut ipc = estimator.as_mut().map(|e| match e {
        EstimatorLink::Running(c) => IpcEstimator::new(c, ESTIMATOR_TIMEOUT),
        // Ours: started again if it dies during a request.
        EstimatorLink::Child(c) => IpcEstimator::restartable(c, ESTIMATOR_TIMEOUT),
    });
    if let Some(e) = ipc.as_mut() {
        opts.estimator = Some(e);
    }
    let mut history = crate::history::record_run_start(args.history.as_deref(), &cfg, &program)?;
    let before = files.snapshot();
    let report = run_program(&program, &mut session.machine, &cfg, &mut opts);
    drop(opts);
    // The drives are disabled before anything else is said or written.
    let closed = session.close();
    if let Some((h, id)) = history.as_mut() {
        use crate::history::RunStatus;
        let status = if report.aborted {
            RunStatus::Aborted
        } else if report.completed() {
            RunStatus::Done
        } else {
            RunStatus::Error
        };
        h.finish(*id, status, &report).map_err(|e| e.to_string())?;
    }
    say_raw!("{}", report.to_text());
    if let Some(path) = &args.json {
        write_atomic(path, report.to_json().as_bytes())?;
    }
    for w in files.written_since(&before) {
        tell!("state: {w}");
    }
    if let Some(why) = &report.stopped {
        tell!("program stopped: {why}");
    }
    closed?;
    Ok(if report.completed() { 0 } else { 1 })
}

/// `2/3` for the second cycle of a program that runs each cycle block once
/// (`total`); in a loop or a subprogram the count of cycles started so far, `cycle 5`.
fn progress_count(done: usize, total: Option<usize>) -> String {
    match total {
        Some(n) => format!("{done}/{n}"),
        None => format!("cycle {done}"),
    }
}

/// The machine as the cycles see it with the preset table and the probes' calibration
/// rows of the machine's state `files` (cycle 460 writes there).
fn state_cycles_config(
    machine_cfg: &hal::config::MachineConfig,
    scenario: Option<&sim::Scenario>,
    files: &crate::machine_state::MachineFiles,
) -> Result<cycles::CyclesConfig, String> {
    let mut cfg = cycles_config_with_presets(machine_cfg, scenario, Some(&files.presets))
        .map_err(|e| e.to_string())?;
    cfg.use_calibrations(&files.probes)
        .map_err(|e| e.to_string())?;
    Ok(cfg)
}

/// The probes' calibration rows of the machine's state at `probes` for `cfg` (cycle
/// 460 writes its row there, at its end: with a 460 in `program` a file that could not
/// be written is refused now, before anything moves).
fn use_state_probes(
    cfg: &mut cycles::CyclesConfig,
    probes: &std::path::Path,
    program: &Program,
) -> Result<(), String> {
    cfg.use_calibrations(probes).map_err(|e| e.to_string())?;
    if program.cycles().any(|c| c.head.cycle == 460) {
        crate::output::check_output(Some(probes))
            .map_err(|e| format!("probe table (cycle 460): {e}"))?;
    }
    Ok(())
}

/// The program, loaded and refused (`None`, said on stderr) as `check` refuses it:
/// invalid text, then what `run` would refuse before the machine is opened.
fn validated(
    args: &RunArgs,
    cfg: &cycles::CyclesConfig,
    kinematics: &std::path::Path,
) -> Result<Option<Program>, String> {
    let program = match Program::load(&args.program, cfg) {
        Ok(p) => p,
        Err(ProgramError::Invalid { path, errors }) => {
            super::tell_errors(&path, &errors.0);
            tell!(
                "{}: {} error(s); nothing moved",
                path.display(),
                errors.0.len()
            );
            return Ok(None);
        }
        Err(e) => return Err(e.to_string()),
    };
    // As `check` says them: they do not stop the run.
    super::tell_errors(&args.program, &program_warnings(&program, cfg));
    if let Err(e) = check_complete(&program).and_then(|()| {
        preflight_program(&program, cfg.machine.axis_mask(), cfg, kinematics)
            .map_err(|e| e.to_string())
    }) {
        tell!("{}: {e}", args.program.display());
        tell!("{}: 1 error(s); nothing moved", args.program.display());
        return Ok(None);
    }
    Ok(Some(program))
}

/// The estimator process cycle 451 talks to.
enum EstimatorLink {
    /// Already serving the prefix (a daemon, or another bridge's).
    Running(EstimatorClient),
    /// Started by this run; stops with it.
    Child(EstimatorChild),
}

/// Connects to the estimator on `prefix`, or starts one as a child process. Without
/// either the cycle computes in this process (said on stderr).
fn estimator_link(prefix: &str) -> Option<EstimatorLink> {
    if let Ok(c) = EstimatorClient::connect(prefix, Duration::from_millis(300)) {
        tell!("estimator: using the estimator process serving {prefix}");
        return Some(EstimatorLink::Running(c));
    }
    let t0 = std::time::Instant::now();
    match EstimatorChild::spawn(prefix, crate::ipc::START_TIMEOUT) {
        Ok(child) => {
            tell!(
                "estimator: started the estimator process (pid {}) on {prefix}, answering after {} ms",
                child.id(),
                t0.elapsed().as_millis()
            );
            Some(EstimatorLink::Child(child))
        }
        Err(e) => {
            tell!(
                "estimator: cannot start the estimator process ({e}); cycle 451 computes in this process"
            );
            None
        }
    }
}
