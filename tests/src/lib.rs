//! Software-in-the-loop test support: the `Machine` conformance suite (written once,
//! run against every backend), scenario helpers and a synchronous loopback bus.
//!
//! See `ARCHITECTURE.md#tests` in the repository root.

pub mod alloc_count;
pub mod conformance;
pub mod conformance_modbus;
pub mod kinematic_machine;
pub mod loopback;
pub mod operator_trials;
pub mod probing_loop;
pub mod spec451;
pub mod world_machine;

use sim::Scenario;
use std::path::{Path, PathBuf};

pub fn configs_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs")
}

/// A scenario written in the test, resolved against the shipped machines.
pub fn scenario(text: &str) -> Scenario {
    let path = configs_dir().join("scenarios/test-inline.toml");
    Scenario::parse(text, &path, Some(&configs_dir().join("machines")))
        .unwrap_or_else(|e| panic!("test scenario invalid: {e}"))
}

/// `table-ac` over a flat face at height `z` (normal +Z), with `extra` TOML appended
/// (faults, say): the scenario of most single-probe tests.
pub fn table_ac_plane(z: f64, extra: &str) -> Scenario {
    scenario(&format!(
        r#"
machine = "table-ac"
[probe]
ball_radius = 3.0
[[plane]]
point = [0.0, 0.0, {z:?}]
normal = [0.0, 0.0, 1.0]
{extra}
"#
    ))
}

/// Runs the shipped program `configs/programs/<program>` on `m` through the cycles
/// runner, confirming every prompt, with its protocols and kinematics in a temporary
/// folder of its own (`tag` keeps tests running in parallel apart).
pub fn run_shipped_program(
    m: &mut impl hal::Machine<Error = hal::MachineError>,
    program: &str,
    sc: &Scenario,
    tag: &str,
) -> cycles::results::ProgramReport {
    let cfg = cycles_config(sc);
    let path = configs_dir().join("programs").join(program);
    let text = std::fs::read_to_string(&path).unwrap();
    let program = cycles::program::Program::parse(&text, &cfg).unwrap_or_else(|e| panic!("{e}"));
    static RUNS: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
    let n = RUNS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let out: PathBuf = std::env::temp_dir().join(format!(
        "pb-program-{tag}-{}-{}-{n}",
        path.file_stem().unwrap().to_string_lossy(),
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&out);
    std::fs::create_dir_all(&out).unwrap();
    let mut confirm = |_: &cycles::confirmation::Confirmation| true;
    // A long run (451 on a lossy bus: minutes) says where it is every PROGRESS_EVERY.
    let (name, mut said, mut probes) = (program_name(&path), std::time::Instant::now(), 0u32);
    let mut on_event = |ev: cycles::progress::ProgressEvent| {
        use cycles::progress::ProgressEvent;
        probes += u32::from(matches!(ev, ProgressEvent::Probe { .. }));
        if said.elapsed() >= PROGRESS_EVERY {
            said = std::time::Instant::now();
            let at = match ev {
                ProgressEvent::Note { text, .. } => text,
                _ => "running".into(),
            };
            progress(
                "run_shipped_program",
                format_args!("{name} ({tag}): {probes} probing moves so far; {at}"),
            );
        }
    };
    let mut opts = cycles::runner::RunOptions {
        out_dir: out.clone(),
        confirm: &mut confirm,
        progress: &mut on_event,
        kinematics: Some(out.join("kinematics.toml")),
        estimator: None,
    };
    let report = cycles::runner::run_program(&program, m, &cfg, &mut opts);
    let _ = std::fs::remove_dir_all(&out);
    report
}

/// The machine configuration of a scenario.
pub fn machine_config(sc: &Scenario) -> hal::config::MachineConfig {
    sc.machine.clone()
}

/// The machine as the cycles see it, with the probe table as the bridge sets it up for
/// a scenario (R = the scenario's).
pub fn cycles_config(sc: &Scenario) -> cycles::CyclesConfig {
    let mut cfg = cycles::CyclesConfig::of(sc.machine.clone())
        .unwrap_or_else(|e| panic!("machine configuration invalid: {e}"));
    for p in &mut cfg.probes {
        p.radius = sc.probe_table_radius();
    }
    if let Some(n) = sc.preset {
        cfg.start_with_preset(n)
            .unwrap_or_else(|e| panic!("scenario preset: {e}"));
    }
    // Cycles that set a preset write a temporary copy, never the shipped table.
    cfg.presets.path = temp_presets_path(&cfg.presets.path);
    // So does cycle 460 with its probe table row.
    cfg.calibrations.path = temp_presets_path(&cfg.calibrations.path);
    cfg
}

/// A fresh folder per call for a preset table the test may write, inside
/// [`process_temp_dir`].
fn temp_presets_path(shipped: &Path) -> PathBuf {
    use std::sync::atomic::{AtomicU32, Ordering};
    static N: AtomicU32 = AtomicU32::new(0);
    let dir = process_temp_dir().join(format!("presets-{}", N.fetch_add(1, Ordering::Relaxed)));
    std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    dir.join(shipped.file_name().unwrap_or_default())
}

/// This test process's folder for the files its tests write:
/// `pbtest-<pid>/` in [`std::env::temp_dir`] (the test root under
/// `scripts/with-test-root`). The first call removes the folders of test processes
/// that no longer run, so a run that cannot clean up after itself (a test binary
/// ends without a hook) is cleaned up by the next one at the latest.
pub fn process_temp_dir() -> &'static Path {
    static DIR: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    DIR.get_or_init(|| {
        let tmp = std::env::temp_dir();
        remove_dead_process_dirs(&tmp, "pbtest-");
        let dir = tmp.join(format!("pbtest-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
        dir
    })
}

/// Removes the folders `<prefix><pid>` in `tmp` whose process no longer runs.
pub fn remove_dead_process_dirs(tmp: &Path, prefix: &str) {
    for entry in std::fs::read_dir(tmp).into_iter().flatten().flatten() {
        let name = entry.file_name();
        let Some(pid) = name.to_str().and_then(|n| n.strip_prefix(prefix)) else {
            continue;
        };
        if pid.parse::<u32>().is_ok() && !Path::new("/proc").join(pid).exists() {
            let _ = std::fs::remove_dir_all(entry.path());
        }
    }
}

/// A unique name per test (and process) for iceoryx2 services.
pub fn unique_service(test: &str) -> String {
    use std::sync::atomic::{AtomicU32, Ordering};
    static N: AtomicU32 = AtomicU32::new(0);
    format!(
        "pbtest-{test}-{}-{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    )
}

/// How often [`run_shipped_program`] says where a long run is.
const PROGRESS_EVERY: std::time::Duration = std::time::Duration::from_secs(20);

fn program_name(path: &Path) -> String {
    path.file_name()
        .unwrap_or_default()
        .to_string_lossy()
        .into_owned()
}

/// A progress line of a long test on the terminal, also when libtest captures the
/// test's output (it captures `println!`/`eprintln!`, not writes to the stderr handle):
/// `scripts/test` is never silent for a minute. `file` names the test file.
pub fn progress(file: &str, line: std::fmt::Arguments<'_>) {
    use std::io::Write as _;
    let _ = writeln!(std::io::stderr().lock(), "    [{file}] {line}");
}
