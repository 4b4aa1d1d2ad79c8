//! `probebridge sim`: the simulated drives alone, on a SocketCAN interface, or the
//! simulated PLC on Modbus TCP/RTU, for a bridge in another process (or on another
//! machine) to drive.

use crate::session::load_scenario;
use hal::can::socketcan::SocketCanTransport;
use hal::master::MasterOptions;
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
    tell!(
        "probebridge sim: machine {} ({}), drives {} on {iface}; stop with Ctrl-C",
        sc.machine.name,
        sc.path.display(),
        nodes.join(" ")
    );
    // Drives standing for hardware: their heartbeats run on the wall clock.
    let mut machine = SimMachine::new(&sc);
    machine.set_clock(SimClock::Monotonic);
    // Hardware drives are never starved of CPU: just below a master's real-time loop
    // (as the simulator of `run --realtime` and `bench trigger` runs them). At normal
    // priority on a CPU a SCHED_FIFO master shares, the SYNCs queue for the drives,
    // which then move for each in a burst: a probing move runs on past its contact
    // before the latch can reach the master (in CI's VM, past the 5 mm overtravel).
    let priority = MasterOptions::default().rt_priority - 1;
    let (granted_tx, granted_rx) = std::sync::mpsc::channel();
    let runner = SimRunner::spawn_with_init(machine, transport, move || {
        let _ = granted_tx.send(hal::rt::set_fifo_priority(priority));
    });
    if granted_rx.recv().unwrap_or(false) {
        tell!("probebridge sim: the drives run at SCHED_FIFO priority {priority}");
    } else {
        tell!(
            "probebridge sim: the drives run at normal priority (SCHED_FIFO {priority} refused: \
             needs root or CAP_SYS_NICE); on a loaded host their answers may queue behind a \
             real-time master"
        );
    }
    // Runs until the transport fails or the process is stopped.
    runner
        .wait()
        .map(|_| ())
        .map_err(|e| format!("simulation stopped: {e}"))
}

fn plc_program(
    scenario: Option<PathBuf>,
) -> Result<
    (
        sim::Scenario,
        sim::plc::PlcProgram,
        hal::modbus::ModbusBusConfig,
    ),
    String,
> {
    let sc = load_scenario(scenario.as_deref()).map_err(|e| e.to_string())?;
    let bus = sc
        .machine
        .modbus_bus()
        .cloned()
        .unwrap_or_else(|| hal::modbus::ModbusBusConfig::tcp(""));
    let program = sim::plc::PlcProgram::new(&sc, &bus);
    Ok((sc, program, bus))
}

fn pacing(realtime: bool) -> sim::plc::PlcPacing {
    if realtime {
        sim::plc::PlcPacing::RealTime
    } else {
        sim::plc::PlcPacing::Virtual
    }
}

/// The simulated PLC on Modbus TCP at `addr` (port 0: any free port, printed).
pub fn run_plc_tcp(scenario: Option<PathBuf>, addr: &str, realtime: bool) -> Result<(), String> {
    let (sc, program, bus) = plc_program(scenario)?;
    let bind: std::net::SocketAddr = addr
        .parse()
        .map_err(|e| format!("--modbus {addr}: not HOST:PORT ({e})"))?;
    let plc = sim::plc::SimPlc::serve_tcp(program, bus.unit, bind, pacing(realtime))
        .map_err(|e| format!("--modbus {addr}: {e}"))?;
    let at = plc.local_addr().map_or_else(String::new, |a| a.to_string());
    // The address on stdout, alone on its line, for a script that started us on port 0.
    say!("modbus tcp {at}");
    tell!(
        "probebridge sim: machine {} ({}), simulated PLC unit {} on Modbus TCP {at}, word order {}, capture {}; stop with Ctrl-C",
        sc.machine.name,
        sc.path.display(),
        bus.unit,
        bus.word_order,
        bus.capture.name()
    );
    plc.wait()
        .map_err(|e| format!("simulated PLC stopped: {e}"))
}

/// The simulated PLC on Modbus RTU at the serial device `dev`.
pub fn run_plc_rtu(scenario: Option<PathBuf>, dev: &str, realtime: bool) -> Result<(), String> {
    let (sc, program, bus) = plc_program(scenario)?;
    let plc = sim::plc::SimPlc::serve_rtu(program, bus.unit, dev, bus.baud, pacing(realtime))
        .map_err(|e| format!("--modbus-rtu {dev}: {e}"))?;
    tell!(
        "probebridge sim: machine {} ({}), simulated PLC unit {} on Modbus RTU {dev} at {} baud; stop with Ctrl-C",
        sc.machine.name,
        sc.path.display(),
        bus.unit,
        bus.baud
    );
    plc.wait()
        .map_err(|e| format!("simulated PLC stopped: {e}"))
}
