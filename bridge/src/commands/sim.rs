//! `probebridge sim`: the simulated drives alone, on a SocketCAN interface, for a
//! bridge in another process (or on another machine) to drive.

use crate::session::load_scenario;
use hal::can::socketcan::SocketCanTransport;
use sim::machine::{SimClock, SimMachine, SimRunner};
use std::path::PathBuf;

pub fn run(scenario: Option<PathBuf>, iface: &str) -> Result<(), String> {
    let sc = load_scenario(scenario.as_deref()).map_err(|e| e.to_string())?;
    let transport = SocketCanTransport::open(iface).map_err(|e| e.to_string())?;
    let nodes: Vec<String> = sc
        .machine
        .axes
        .iter()
        .map(|a| format!("{}={}", a.name, a.canopen_node()))
        .collect();
    eprintln!(
        "probebridge sim: machine {} ({}), drives {} on {iface}; stop with Ctrl-C",
        sc.machine.name,
        sc.path.display(),
        nodes.join(" ")
    );
    // Drives standing for hardware: their heartbeats run on the wall clock.
    let mut machine = SimMachine::new(&sc);
    machine.set_clock(SimClock::Monotonic);
    let runner = SimRunner::spawn(machine, transport);
    // Runs until the transport fails or the process is stopped.
    runner
        .wait()
        .map(|_| ())
        .map_err(|e| format!("simulation stopped: {e}"))
}
