//! `probebridge probe`: one probing move, reported with the latched positions of all
//! axes.

use crate::session::options::MachineOptions;
use crate::session::{cycles_config, resolve_machine, Session};
use hal::{AxisPositions, Machine, ProbeMove};
use std::path::PathBuf;

pub struct ProbeArgs {
    pub machine: MachineOptions,
    pub start: [f64; 3],
    pub dir: [f64; 3],
    pub dist: f64,
    pub feed: f64,
    pub json: Option<PathBuf>,
}

pub fn run(args: &ProbeArgs) -> Result<(), String> {
    let n = (args.dir[0].powi(2) + args.dir[1].powi(2) + args.dir[2].powi(2)).sqrt();
    if n.is_nan() || n <= 1e-9 {
        return Err("--dir: the probing direction must not be zero".into());
    }
    if !args.dist.is_finite() || args.dist <= 0.0 {
        return Err(format!("--dist {}: must be > 0", args.dist));
    }
    if !args.feed.is_finite() || args.feed <= 0.0 {
        return Err(format!("--feed {}: must be > 0", args.feed));
    }
    crate::output::check_output(args.json.as_deref())?;
    // The probing move is checked against the machine before anything moves (also
    // the move to the start).
    let (cfg, _) = resolve_machine(&args.machine).map_err(|e| e.to_string())?;
    hal::motion_guard::MotionGuard::new(&cfg)
        .check_probe_request(&ProbeMove {
            direction: args.dir,
            feed: args.feed,
            max_distance: args.dist,
        })
        .map_err(|e| format!("probing: {e}"))?;
    let mut s = Session::open(&args.machine).map_err(|e| e.to_string())?;
    for note in &s.notes {
        tell!("note: {note}");
    }
    let probes = cycles_config(&s.config, s.scenario.as_ref()).map_err(|e| e.to_string())?;
    let rapid = probes.probes.first().map_or(3000.0, |p| p.fmax);
    let start = AxisPositions::linear(args.start);
    s.machine
        .move_to(&start, rapid)
        .map_err(|e| format!("moving to the start: {e}"))?;
    let dir = [args.dir[0] / n, args.dir[1] / n, args.dir[2] / n];
    let contact = s
        .machine
        .probe(&ProbeMove {
            direction: dir,
            feed: args.feed,
            max_distance: args.dist,
        })
        .map_err(|e| format!("probing: {e}"))?;
    // Back off to the start so the stylus is free again.
    s.machine
        .move_to(&start, rapid)
        .map_err(|e| format!("retracting: {e}"))?;
    s.close()?;
    say!("contact (stylus ball centre, machine coordinates, latched by the drives):");
    for (axis, v) in contact.positions.iter() {
        let unit = if axis.is_rotary() { "deg" } else { "mm" };
        say!("  {axis} {v:+14.6} {unit}");
    }
    say!("  trigger at {} ns", contact.trigger_ns);
    if let Some(path) = &args.json {
        let mut c = serde_json::Map::new();
        for (axis, v) in contact.positions.iter() {
            c.insert(axis.name().into(), serde_json::json!(v));
        }
        let doc = serde_json::json!({ "contact": c, "trigger_ns": contact.trigger_ns });
        crate::output::write_json(path, &doc)?;
    }
    Ok(())
}
