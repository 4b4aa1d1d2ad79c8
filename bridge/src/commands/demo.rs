//! `probebridge demo`: the simulated table-ac machine with a calibration sphere, the
//! estimator as a child process, the sphere's pole and four points around it probed in
//! real time, and the sphere fitted by the estimator from the published contacts. Then
//! cycle 451 mode 1 on the rotary axes of the scenario (A and C on the default one, with
//! its injected location errors), on the simulator's virtual clock so that the dozens of
//! probing moves take seconds, the spheres fitted and the identification solved by the
//! same estimator process, written to a temporary copy of the kinematics file (the
//! repository's configuration stays as it is): the errors before and after, and where
//! the protocol is.

use crate::ipc::{EstimatorChild, IpcEstimator};
use crate::session::options::MachineOptions;
use crate::session::{cycles_config, Session};
use cycles::kinematics_file::ActiveKinematics;
use cycles::program::Program;
use cycles::progress::ProgressEvent;
use cycles::runner::{run_program, RunOptions};
use cycles::CyclesConfig;
use hal::{Axis, AxisPositions, Machine, ProbeMove};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// What the demo keeps and prints besides its results.
#[derive(Clone, Copy, Debug, Default)]
pub struct DemoOutput {
    /// Keep the temporary folder (`--keep`) and say where it is.
    pub keep: bool,
    /// Also print the estimator process's own lines and the drives' start-up detail
    /// (`--verbose`).
    pub verbose: bool,
}

/// The demo's temporary folder, `probebridge-demo-<pid>` in the temporary folder: its
/// 451 program, the copies it writes, the protocol and the estimator's log. Removed
/// when dropped (at the end, after an error, after a stop signal), unless kept.
struct Scratch {
    dir: PathBuf,
    keep: bool,
}

impl Scratch {
    fn create(keep: bool) -> Result<Self, String> {
        let dir = std::env::temp_dir().join(format!("probebridge-demo-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        Ok(Self { dir, keep })
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if self.keep {
            say!(
                "the demo's files are kept in {} (--keep)",
                self.dir.display()
            );
        } else {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}

pub fn run(machine: &MachineOptions, output: DemoOutput) -> Result<(), String> {
    let scratch = Scratch::create(output.keep)?;
    let log = scratch.dir.join("estimator.log");
    let result = demo(machine, output, &scratch.dir, &log);
    if result.is_err() && !output.verbose {
        // What the estimator said goes with the error (its log is removed with the folder).
        for line in std::fs::read_to_string(&log).unwrap_or_default().lines() {
            crate::tell!("  {line}");
        }
    }
    result
}

/// The estimator process; its own lines (run ids, its fits, its armed windows) go to
/// `log` unless `verbose`.
fn start_estimator(service: &str, verbose: bool, log: &Path) -> Result<EstimatorChild, String> {
    let exe = std::env::current_exe().map_err(|e| format!("cannot start the estimator: {e}"))?;
    let mut command = std::process::Command::new(exe);
    command.args(["estimator", "--service", service]);
    if !verbose {
        let file = std::fs::File::create(log).map_err(|e| format!("{}: {e}", log.display()))?;
        command.stderr(file);
    }
    EstimatorChild::spawn_command(command, service, crate::ipc::START_TIMEOUT)
        .map_err(|e| format!("cannot start the estimator: {e}"))
}

fn demo(
    machine: &MachineOptions,
    output: DemoOutput,
    dir: &Path,
    log: &Path,
) -> Result<(), String> {
    let mut opts = machine.clone();
    opts.realtime = true;
    if opts.service == super::default_service() {
        // A demo must not collide with a bridge already running on this gateway.
        opts.service = format!("probebridge-demo-{}", std::process::id());
    }
    say!("probebridge demo: starting the estimator process ...");
    let estimator = start_estimator(&opts.service, output.verbose, log)?;
    if opts.modbus.is_some() {
        say!("starting the simulated machine behind a PLC and connecting over Modbus ...");
    } else {
        say!("starting the simulated machine and bringing the drives up over CANopen ...");
    }
    let mut s = Session::open(&opts).map_err(|e| e.to_string())?;
    say!("  machine {}: {}", s.config.name, s.config.description);
    if let Some(startup) = s.startup.as_ref().filter(|_| output.verbose) {
        for d in &startup.drives {
            say!("  {d}");
        }
        say!("  {}", startup.bus_load);
    }
    for note in &s.notes {
        say!("  note: {note}");
    }
    let scenario = s
        .scenario
        .as_ref()
        .ok_or("the demo runs on the simulator only")?;
    let sphere = scenario
        .spheres
        .first()
        .copied()
        .ok_or_else(|| format!("{}: the demo needs a [[sphere]]", scenario.path.display()))?;
    let probes = cycles_config(&s.config, Some(scenario)).map_err(|e| e.to_string())?;
    let probe = probes
        .probes
        .first()
        .ok_or_else(|| {
            format!(
                "{}: no [[probe]] in the probe table",
                s.config.path.display()
            )
        })?
        .clone();
    let c = sphere.center;
    let r = sphere.radius;
    let big = r + probe.radius;
    let clearance = 5.0;
    let safe_z = c[2] + big + 10.0;
    say!(
        "  sphere: nominal centre ({:.3}, {:.3}, {:.3}), radius {r:.3}; stylus R = {:.3}",
        c[0],
        c[1],
        c[2],
        probe.radius
    );
    let run_id = hal::clock::monotonic_ns();
    s.machine.set_run(run_id);

    // Pole from above, then four points around the equator toward the centre.
    let mut starts = vec![([c[0], c[1], c[2] + big + clearance], [0.0, 0.0, -1.0])];
    for k in 0..4 {
        let a = (k as f64) * std::f64::consts::FRAC_PI_2;
        let (sn, cs) = a.sin_cos();
        starts.push((
            [
                c[0] + cs * (big + clearance),
                c[1] + sn * (big + clearance),
                c[2],
            ],
            [-cs, -sn, 0.0],
        ));
    }
    say!("probing 5 points (ball centre at the latch, all axes):");
    for (i, (start, dir)) in starts.iter().enumerate() {
        let over = AxisPositions::linear([start[0], start[1], safe_z]);
        s.machine
            .move_to(&over, probe.fmax)
            .map_err(|e| e.to_string())?;
        s.machine
            .move_to(&AxisPositions::linear(*start), probe.fmax)
            .map_err(|e| e.to_string())?;
        let contact = s
            .machine
            .probe(&ProbeMove {
                direction: *dir,
                feed: probe.f,
                max_distance: clearance + probe.dist,
            })
            .map_err(|e| format!("point {}: {e}", i + 1))?;
        say!("  {}: {}", i + 1, contact.positions);
        s.machine
            .move_to(&AxisPositions::linear(*start), probe.fmax)
            .map_err(|e| e.to_string())?;
        s.machine
            .move_to(&over, probe.fmax)
            .map_err(|e| e.to_string())?;
    }
    report_sphere(&estimator, run_id, sphere, probe.radius)?;
    s.close()?;
    kinematics(&opts, &estimator, output, dir)
}

/// The sphere the estimator process fitted from run `run_id`'s contacts, against the
/// scenario's truth.
fn report_sphere(
    estimator: &EstimatorChild,
    run_id: u64,
    sphere: sim::artefact::Sphere,
    stylus_radius: f64,
) -> Result<(), String> {
    let c = sphere.center;
    let r = sphere.radius;
    let fit = estimator
        .client()
        .fit_sphere(run_id, Duration::from_secs(5))
        .map_err(|e| format!("the estimator did not fit the sphere: {e}"))?;
    if !fit.ok {
        return Err(format!(
            "the estimator could not fit the sphere: {}",
            fit.error.describe()
        ));
    }
    let radius = fit.radius - stylus_radius;
    let dev = [
        fit.centre[0] - c[0],
        fit.centre[1] - c[1],
        fit.centre[2] - c[2],
    ];
    let dev_len = (dev[0] * dev[0] + dev[1] * dev[1] + dev[2] * dev[2]).sqrt();
    say!(
        "sphere fitted by the estimator process from {} contacts:",
        fit.n_points
    );
    say!(
        "  centre ({:+.6}, {:+.6}, {:+.6}) mm, radius {radius:.6} mm (rms residual {:.2e} mm)",
        fit.centre[0],
        fit.centre[1],
        fit.centre[2],
        fit.rms
    );
    say!(
        "  truth  ({:+.6}, {:+.6}, {:+.6}) mm, radius {r:.6} mm: centre off by {:.2e} mm, radius by {:.2e} mm",
        c[0],
        c[1],
        c[2],
        dev_len,
        (radius - r).abs()
    );
    Ok(())
}

/// The demo's NC program: tool `tool`, over the sphere, down to `above`, cycle 451
/// mode 1 on the rotary axes the machine has (inside their limits), back up; and the
/// axes it measures.
fn demo451_program(
    cfg: &hal::config::MachineConfig,
    sphere: &sim::artefact::Sphere,
    tool: &str,
    above: f64,
) -> (String, Vec<Axis>) {
    let mut q = String::new();
    let mut measured = Vec::new();
    for (axis, base) in [(Axis::A, 411), (Axis::B, 415), (Axis::C, 419)] {
        let (start, end, n) = demo_range(axis, cfg).unwrap_or((0.0, 0.0, 0));
        if n > 0 {
            measured.push(axis);
        }
        q.push_str(&format!(
            "  Q{}={start:+} ~\n  Q{}={end:+} ~\n  Q{}=+0 ~\n  Q{}={n:+} ~\n",
            base,
            base + 1,
            base + 2,
            base + 3
        ));
    }
    let c = sphere.center;
    let text = format!(
        "0 BEGIN PGM DEMO451 MM\n1 TOOL CALL \"{}\" Z\n2 L Z{:+} R0 FMAX\n3 L X{:+} Y{:+} R0 FMAX\n4 L Z{above:+} R0 FMAX\n\
5 TCH PROBE 451 MEASURE KINEMATICS ~\n  Q406=+1 ;MODE ~\n  Q407={:+} ;SPHERE RADIUS ~\n  Q320=+0 ~\n  Q408=+0 ~\n\
  Q253=+750 ~\n  Q380=+0 ~\n{q}  Q423=+4 ~\n  Q431=+1 ~\n  Q432=+0\n6 L Z{:+} R0 FMAX\n7 END PGM DEMO451 MM\n",
        tool,
        above + 50.0,
        c[0],
        c[1],
        sphere.radius,
        above + 50.0,
    );
    (text, measured)
}

/// The measuring range the demo gives each rotary axis (start, end, points), inside
/// the axis's software limits.
fn demo_range(axis: Axis, cfg: &hal::config::MachineConfig) -> Option<(f64, f64, u32)> {
    let a = cfg.axis(axis)?;
    let (start, end, n): (f64, f64, u32) = match axis {
        Axis::C => (90.0, 270.0, 3),
        Axis::A => (-90.0, 90.0, 4),
        _ => (-60.0, 60.0, 4),
    };
    let (start, end) = (start.max(a.min), end.min(a.max));
    (end > start).then_some((start, end, n))
}

/// Copies in the demo's folder `dir` of what its 451 run writes: the preset table
/// (Q431 = 1 sets the preset; `cfg` is pointed at the copy) and the machine's
/// kinematics file (returned). Nothing under `configs/` changes.
fn scratch_files(cfg: &mut CyclesConfig, dir: &Path) -> Result<PathBuf, String> {
    cfg.presets.path = dir.join(
        cfg.presets
            .path
            .file_name()
            .unwrap_or(std::ffi::OsStr::new("presets.toml")),
    );
    let shipped = ActiveKinematics::default_path(&cfg.machine);
    let kin = dir.join(shipped.file_name().unwrap_or_default());
    if shipped.exists() {
        std::fs::copy(&shipped, &kin).map_err(|e| format!("{}: {e}", shipped.display()))?;
    }
    Ok(kin)
}

/// What mode 1 can and cannot correct, with this scenario's injected errors: it
/// corrects positions only, so injected orientation errors stay, and the positions it
/// writes absorb them ("after" differs from "injected" there).
fn mode1_line(measured: &[Axis], scenario: &sim::scenario::Scenario) -> String {
    let orientation: Vec<&str> = measured
        .iter()
        .flat_map(|a| cycles::iso230_7::error_names(*a).iter().copied())
        // E{A,B,C}0{k} with k another axis: orientation (E{j}0{j} is the zero error).
        .filter(|n| {
            let b = n.as_bytes();
            b"ABC".contains(&b[1]) && b[1] != b[3]
        })
        .filter(|n| scenario.truth.get(n).is_some_and(|v| v != 0.0))
        .collect();
    format!(
        "  mode 1 corrects the axes' position errors only; {}; mode 2 (orientation) and 3 (both) correct those too",
        if orientation.is_empty() {
            "no orientation error is injected, so after equals injected".to_string()
        } else {
            format!(
                "it cannot correct the injected orientation errors {}, which the positions absorb, so after differs from injected",
                orientation.join(", ")
            )
        }
    )
}

/// Cycle 451 mode 1 on the scenario's rotary axes; see the module doc.
fn kinematics(
    opts: &MachineOptions,
    estimator: &EstimatorChild,
    output: DemoOutput,
    dir: &Path,
) -> Result<(), String> {
    let mut opts = opts.clone();
    opts.realtime = false;
    let mut s = Session::open(&opts).map_err(|e| e.to_string())?;
    let scenario = s
        .scenario
        .clone()
        .ok_or("the demo runs on the simulator only")?;
    let sphere = scenario.spheres[0];
    let mut cfg = cycles_config(&s.config, Some(&scenario)).map_err(|e| e.to_string())?;
    let probe = cfg.probes[0].clone();
    let kin = scratch_files(&mut cfg, dir)?;
    let before = ActiveKinematics::load(&kin, &cfg.machine).map_err(|e| e.to_string())?;

    let above = sphere.center[2] + sphere.radius + probe.radius + probe.set_up + 5.0;
    let (text, measured) = demo451_program(&cfg.machine, &sphere, &probe.name, above);
    let program_path = dir.join("demo451.h");
    crate::output::write_atomic(&program_path, text.as_bytes())?;
    let program = Program::load(&program_path, &cfg).map_err(|e| e.to_string())?;
    say!();
    say!(
        "cycle 451 MEASURE KINEMATICS, mode 1 (optimise position) on {} (virtual clock):",
        measured
            .iter()
            .map(|a| a.name())
            .collect::<Vec<_>>()
            .join(" and ")
    );
    say!(
        "  its program, a copy of the kinematics file and the protocol go into {} ({})",
        dir.display(),
        if output.keep {
            "kept at the end: --keep"
        } else {
            "removed at the end; --keep keeps it"
        }
    );
    let mut spheres = 0usize;
    let mut progress = |ev: ProgressEvent| {
        if let ProgressEvent::Note { text, .. } = ev {
            if text.starts_with("measuring") {
                spheres += 1;
                say!("  {spheres:2}. {}", &text["measuring ".len()..]);
            }
        }
    };
    let mut confirm = |_: &cycles::confirmation::Confirmation| true;
    let mut ipc = IpcEstimator::new(estimator.client(), Duration::from_secs(10));
    let t0 = std::time::Instant::now();
    let mut run = RunOptions {
        out_dir: dir.to_path_buf(),
        confirm: &mut confirm,
        progress: &mut progress,
        kinematics: Some(kin.clone()),
        estimator: Some(&mut ipc),
    };
    let report = run_program(&program, &mut s.machine, &cfg, &mut run);
    s.close()?;
    let result = report
        .cycles
        .iter()
        .find(|c| c.cycle == 451)
        .ok_or("cycle 451 did not run")?;
    if let Some(why) = &report.stopped {
        return Err(format!("cycle 451: {why}"));
    }
    let k = result
        .kinematics
        .as_ref()
        .ok_or("cycle 451 gave no kinematics result")?;
    say!(
        "  measured in {:.1} s; spheres fitted and errors identified by the {}\n  machine time {}",
        t0.elapsed().as_secs_f64(),
        k.estimator,
        result.machine_time_split_s.unwrap_or_default()
    );
    say!("  error       before   after ± u (k = 1)       injected (scenario truth)");
    for a in &measured {
        for name in cycles::iso230_7::error_names(*a) {
            let b = before.error(name);
            let after = k.errors_after.get(*name).copied().unwrap_or(b);
            let u = k
                .errors_u
                .get(*name)
                .map_or_else(|| " ".repeat(11), |u| format!(" ± {u:.6}"));
            let truth = scenario.truth.get(name).unwrap_or(0.0);
            say!(
                "  {name}  {b:+10.6}  {after:+10.6}{u}  {truth:+10.6}{}",
                if after != b { "  corrected" } else { "" }
            );
        }
    }
    say!("  (mm and degrees; u: the standard uncertainty the probe's scatter puts into the result, k = 1; an error without one was not identified)");
    for a in &k.axes {
        say!(
            "  axis {}: dispersion {:.6} -> {:.6} mm (Q14x), max deviation {:.6} -> {:.6} mm",
            a.axis,
            a.dispersion_before,
            a.dispersion_after,
            a.max_before,
            a.max_after
        );
    }
    if output.verbose {
        for (name, v) in &result.qs {
            say!("  {name} = \"{v}\"");
        }
    }
    say!("{}", mode1_line(&measured, &scenario));
    say!(
        "  kinematics {}: {}",
        kin.display(),
        if k.written {
            "corrected errors written"
        } else {
            "not changed"
        }
    );
    for p in &report.protocols {
        say!("  protocol: {}", p.display());
    }
    Ok(())
}
