//! Opening a machine whose axes a PLC moves, over Modbus: the built-in simulated PLC
//! on loopback (port 0), a PLC (or `probebridge sim --modbus`) at `--modbus ADDR`, or
//! the PLC a machine configuration with `[bus] kind = "modbus"` names.

use super::options::{MachineOptions, SessionError};
use hal::config::{BusConfig, MachineConfig};
use hal::modbus::{ModbusBusConfig, ModbusMachine, ModbusOptions, Transport};
use hal::{MachineError, SampleSink};
use sim::plc::{PlcPacing, PlcProgram, SimPlc};
use sim::Scenario;

/// Does this session go over Modbus?
pub fn wanted(opts: &MachineOptions, config: &MachineConfig) -> bool {
    opts.modbus.is_some() || config.modbus_bus().is_some()
}

/// Starts the simulated PLC of `scenario` (when the session runs on the simulator),
/// connects, and returns the machine, the PLC and notes for the operator. `config`'s
/// bus becomes the Modbus settings actually used.
pub fn open(
    opts: &MachineOptions,
    config: &mut MachineConfig,
    scenario: Option<&Scenario>,
    sink: impl SampleSink + 'static,
    run_id: u64,
) -> Result<(ModbusMachine, Option<SimPlc>, Vec<String>), SessionError> {
    let mut bus = config
        .modbus_bus()
        .cloned()
        .unwrap_or_else(|| ModbusBusConfig::tcp(""));
    let mut plc = None;
    let mut notes = Vec::new();
    match (opts.modbus.as_deref(), scenario) {
        (Some(addr), _) if !addr.is_empty() => {
            bus.transport = Transport::Tcp;
            bus.address = Some(addr.to_string());
        }
        (_, Some(scenario)) => {
            let program = PlcProgram::new(scenario, &bus);
            let pacing = if opts.realtime {
                PlcPacing::RealTime
            } else {
                PlcPacing::Virtual
            };
            let server = SimPlc::serve_tcp(
                program,
                bus.unit,
                "127.0.0.1:0".parse().expect("loopback address"),
                pacing,
            )
            .map_err(|e| SessionError::Scenario(format!("cannot start the simulated PLC: {e}")))?;
            let addr = server
                .local_addr()
                .map_or_else(String::new, |a| a.to_string());
            notes.push(format!("simulated PLC on Modbus TCP {addr}"));
            bus.transport = Transport::Tcp;
            bus.address = Some(addr);
            plc = Some(server);
        }
        (_, None) if config.modbus_bus().is_some() => {}
        (_, None) => {
            return Err(SessionError::Scenario(
                "--modbus without an address runs the simulated PLC: give a --scenario, or --modbus HOST:PORT".into(),
            ))
        }
    }
    bus.validate().map_err(|e| {
        SessionError::Scenario(format!(
            "{}: bus.{}: {}",
            config.path.display(),
            e.key,
            e.reason
        ))
    })?;
    notes.push(format!(
        "PLC capture: {}{}",
        bus.capture.name(),
        match bus.capture {
            hal::modbus::CaptureKind::HwLatch => String::new(),
            hal::modbus::CaptureKind::PlcCycle => format!(
                " (cycle {} us: half-cycle bias removed, uncertainty +- half a cycle of travel)",
                bus.plc_cycle_us
            ),
            hal::modbus::CaptureKind::Poll => " (set-up only)".into(),
        }
    ));
    config.bus = BusConfig::Modbus(bus);
    // A `[spindle]` drive is on the CANopen bus the PLC replaces: over Modbus the PLC
    // orients the spindle, as `bus.spindle_orientation` says.
    config.spindle = None;
    let options = ModbusOptions {
        run_id,
        abort: opts.abort,
        ..ModbusOptions::default()
    };
    let machine = ModbusMachine::start(config, sink, options).map_err(|e: MachineError| e)?;
    Ok((machine, plc, notes))
}
