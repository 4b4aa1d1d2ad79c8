//! `probebridge demo`: the simulated table-ac machine with a calibration sphere, the
//! estimator as a child process, the sphere's pole and four points around it probed in
//! real time, and the sphere fitted by the estimator from the published contacts.

use crate::ipc::EstimatorChild;
use crate::session::{MachineOptions, Session};
use hal::{AxisPositions, Machine, ProbeMove};
use std::time::Duration;

pub fn run(machine: &MachineOptions) -> Result<(), String> {
    let mut opts = machine.clone();
    opts.realtime = true;
    if opts.service == super::default_service() {
        // A demo must not collide with a bridge already running on this gateway.
        opts.service = format!("probebridge-demo-{}", std::process::id());
    }
    println!("probebridge demo: starting the estimator process ...");
    let estimator = EstimatorChild::spawn(&opts.service, Duration::from_secs(10))
        .map_err(|e| format!("cannot start the estimator: {e}"))?;
    println!("starting the simulated machine and bringing the drives up over CANopen ...");
    let mut s = Session::open(&opts).map_err(|e| e.to_string())?;
    println!("  machine {}: {}", s.config.name, s.config.description);
    for d in &s.startup.drives {
        println!("  {d}");
    }
    println!("  {}", s.startup.bus_load);
    for note in &s.startup.notes {
        println!("  note: {note}");
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
    let probe = s
        .config
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
    println!(
        "  sphere: nominal centre ({:.3}, {:.3}, {:.3}), radius {r:.3}; stylus R = {:.3}",
        c[0], c[1], c[2], probe.radius
    );
    let run_id = hal::clock::monotonic_ns();
    s.machine.set_run_id(run_id);

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
    println!("probing 5 points (ball centre at the latch, all axes):");
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
        println!("  {}: {}", i + 1, contact.positions);
        s.machine
            .move_to(&AxisPositions::linear(*start), probe.fmax)
            .map_err(|e| e.to_string())?;
        s.machine
            .move_to(&over, probe.fmax)
            .map_err(|e| e.to_string())?;
    }
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
    let radius = fit.radius - probe.radius;
    let dev = [
        fit.centre[0] - c[0],
        fit.centre[1] - c[1],
        fit.centre[2] - c[2],
    ];
    let dev_len = (dev[0] * dev[0] + dev[1] * dev[1] + dev[2] * dev[2]).sqrt();
    println!(
        "sphere fitted by the estimator process from {} contacts:",
        fit.n_points
    );
    println!(
        "  centre ({:+.6}, {:+.6}, {:+.6}) mm, radius {radius:.6} mm (rms residual {:.2e} mm)",
        fit.centre[0], fit.centre[1], fit.centre[2], fit.rms
    );
    println!(
        "  truth  ({:+.6}, {:+.6}, {:+.6}) mm, radius {r:.6} mm: centre off by {:.2e} mm, radius by {:.2e} mm",
        c[0],
        c[1],
        c[2],
        dev_len,
        (radius - r).abs()
    );
    Ok(())
}
