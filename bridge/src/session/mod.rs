//! Opening "the machine" for a command: the built-in simulator on the in-process bus,
//! or real drives (or `probebridge sim` in another process) on a SocketCAN interface;
//! or, over Modbus, a PLC that moves the axes ([`modbus`]).

use crate::configs;
use crate::ipc::{ContactPublisher, ServiceLock};
use cycles::CyclesConfig;
use hal::can::inproc::{InprocBus, WireClock};
use hal::can::record::RecordHealth;
use hal::can::socketcan::SocketCanTransport;
use hal::can::CanTransport;
use hal::config::MachineConfig;
use hal::master::{CanMachine, MasterOptions, Pacing, StartupReport};
use hal::{Machine, MachineError};
use sim::machine::{SimClock, SimMachine, SimRunner};
use sim::plc::SimPlc;
use sim::scenario::Scenario;
use std::path::{Path, PathBuf};
use std::time::Duration;

pub mod modbus;
pub mod options;

use options::{MachineOptions, SessionError};

/// Any backend, as the commands drive it.
pub type DynMachine = Box<dyn Machine<Error = MachineError> + Send>;

pub struct Session {
    /// Declared first, so dropped first: the backend stops its loop and disables the
    /// drives before the simulator (`sim`) goes away.
    pub machine: DynMachine,
    pub config: MachineConfig,
    /// The simulation scenario, when the machine is (or runs as) the simulator.
    pub scenario: Option<Scenario>,
    /// What the CANopen start-up found (bus load, drives); `None` over Modbus.
    pub startup: Option<StartupReport>,
    /// What the operator should know about the session.
    pub notes: Vec<String>,
    pub sim: Option<SimRunner>,
    pub plc: Option<SimPlc>,
    /// The candump log and whether its recording is whole.
    pub candump: Option<(PathBuf, RecordHealth)>,
    /// This session's claim on its iceoryx2 service prefix; declared last, so freed
    /// after the machine is closed.
    _service: ServiceLock,
}

pub fn load_scenario(path: Option<&Path>) -> Result<Scenario, SessionError> {
    let path = path.map_or_else(configs::default_scenario, Path::to_path_buf);
    Scenario::load(&path, Some(&configs::machines_dir()))
        .map_err(|e| SessionError::Scenario(e.to_string()))
}

/// The machine configuration of a scenario.
pub fn machine_config(scenario: &Scenario) -> MachineConfig {
    scenario.machine.clone()
}

/// The machine as the cycles see it: `cfg` with the probe table and the cycles'
/// machine parameters of the same file. On the simulator the probe table's R is the
/// scenario's (a perfectly calibrated probe unless the scenario says otherwise).
pub fn cycles_config(
    cfg: &MachineConfig,
    scenario: Option<&Scenario>,
) -> Result<CyclesConfig, SessionError> {
    cycles_config_with_presets(cfg, scenario, None)
}

/// As [`cycles_config`], with the preset table read from `presets` when given (else
/// the one beside the machine configuration); the scenario's `preset` is its active
/// row.
pub fn cycles_config_with_presets(
    cfg: &MachineConfig,
    scenario: Option<&Scenario>,
    presets: Option<&std::path::Path>,
) -> Result<CyclesConfig, SessionError> {
    let mut c = CyclesConfig::of(cfg.clone()).map_err(|e| SessionError::Scenario(e.to_string()))?;
    if let Some(path) = presets {
        c.presets = cycles::preset_table::PresetTable::load(path, cfg)
            .map_err(|e| SessionError::Scenario(e.to_string()))?;
    }
    if let Some(sc) = scenario {
        for p in &mut c.probes {
            p.radius = sc.probe_table_radius();
        }
        if let Some(n) = sc.preset {
            c.start_with_preset(n).map_err(|e| {
                SessionError::Scenario(format!("{}: preset: {e}", sc.path.display()))
            })?;
        }
    }
    Ok(c)
}

/// The machine configuration a command works with: `--machine` when given (real
/// drives), else the scenario's machine with the scenario's probe radius.
pub fn resolve_machine(
    opts: &MachineOptions,
) -> Result<(MachineConfig, Option<Scenario>), SessionError> {
    match (&opts.machine, &opts.scenario) {
        (Some(m), None) => {
            let cfg = MachineConfig::load(m).map_err(|e| SessionError::Scenario(e.to_string()))?;
            Ok((cfg, None))
        }
        (Some(_), Some(_)) => Err(SessionError::Scenario(
            "give either --machine (real drives) or --scenario (simulator), not both".into(),
        )),
        (None, sc) => {
            let scenario = load_scenario(sc.as_deref())?;
            Ok((machine_config(&scenario), Some(scenario)))
        }
    }
}

impl Session {
    pub fn open(opts: &MachineOptions) -> Result<Self, SessionError> {
        if let Some(path) = &opts.candump {
            // A device, FIFO or symlink, or a missing folder, is refused before the
            // machine opens.
            hal::atomic_write::check_writable(path)
                .map_err(|e| SessionError::Scenario(format!("--candump: {e}")))?;
        }
        // Before anything is opened: a second session on the same prefix is refused.
        let service = ServiceLock::acquire(&opts.service)?;
        let (mut config, scenario) = resolve_machine(opts)?;
        let sink =
            ContactPublisher::new(&opts.service).map_err(|e| SessionError::Ipc(e.to_string()))?;
        let run_id = hal::clock::monotonic_ns();
        if modbus::wanted(opts, &config) {
            let (machine, plc, notes) =
                modbus::open(opts, &mut config, scenario.as_ref(), sink, run_id)?;
            return Ok(Self {
                machine: Box::new(machine),
                config,
                scenario,
                startup: None,
                notes,
                sim: None,
                plc,
                candump: None,
                _service: service,
            });
        }
        let (transport, sim, pacing): (Box<dyn CanTransport>, Option<SimRunner>, Pacing) =
            match &opts.can {
                Some(iface) => {
                    let t = SocketCanTransport::open(iface)
                        .map_err(|e| MachineError::new(hal::ErrorKind::Bus, e.to_string()))?;
                    (Box::new(t), None, Pacing::RealTime)
                }
                None => {
                    let Some(scenario) = &scenario else {
                        return Err(SessionError::Scenario(
                            "--machine describes real drives: give --can IFACE, or a --scenario for the simulator".into(),
                        ));
                    };
                    let mut machine = SimMachine::new(scenario);
                    let (pacing, clock) = if opts.realtime {
                        machine.set_clock(SimClock::Monotonic);
                        (Pacing::RealTime, WireClock::Monotonic)
                    } else {
                        let answer_timeout = Duration::from_millis(200);
                        (Pacing::Lockstep { answer_timeout }, WireClock::Virtual)
                    };
                    // The bus has the machine's bit rate: frames take their wire time.
                    let bitrate = config
                        .canopen_bus()
                        .unwrap_or(&hal::config::CanOpenBusConfig::DEFAULT)
                        .bitrate;
                    let bus = InprocBus::with_wire_time(bitrate, clock);
                    // In real time the simulated drives stand in for hardware, which a
                    // loaded gateway never starves: just below the real-time loop (as
                    // `bench trigger` runs them), so their heartbeats keep time.
                    let drives_priority = if opts.realtime {
                        MasterOptions::default().rt_priority - 1
                    } else {
                        0
                    };
                    let drives = bus.endpoint_for_devices();
                    let sim = SimRunner::spawn_with_init(machine, drives, move || {
                        if drives_priority > 0 {
                            hal::rt::set_fifo_priority(drives_priority);
                        }
                    });
                    (Box::new(bus.endpoint()), Some(sim), pacing)
                }
            };
        let mut notes = Vec::new();
        // Below the recorder: the log shows what the master sent and received.
        let transport: Box<dyn CanTransport> = match &opts.bus_faults {
            Some(faults) => {
                notes.push(format!(
                    "bus faults injected (seed {}): transmit {:?}, receive {:?}",
                    faults.seed, faults.transmit, faults.receive
                ));
                Box::new(hal::can::fault_injection::FaultyTransport::new(
                    transport,
                    faults.clone(),
                ))
            }
            None => transport,
        };
        let mut candump = None;
        let transport: Box<dyn CanTransport> = match &opts.candump {
            Some(path) => {
                let file = std::fs::File::create(path).map_err(|e| {
                    SessionError::Scenario(format!("cannot create {}: {e}", path.display()))
                })?;
                let iface = opts.can.as_deref().unwrap_or("inproc");
                let recorder = hal::can::record::Recorder::new(transport, file, iface);
                candump = Some((path.clone(), recorder.health()));
                Box::new(recorder)
            }
            None => transport,
        };
        let options = MasterOptions {
            pacing,
            run_id,
            abort: opts.abort,
            ..MasterOptions::default()
        };
        let (machine, startup) = CanMachine::start(&config, transport, sink, options)?;
        notes.extend(startup.notes.iter().cloned());
        Ok(Self {
            machine: Box::new(machine),
            config,
            scenario,
            notes,
            startup: Some(startup),
            plc: None,
            sim,
            candump,
            _service: service,
        })
    }

    /// Closes the machine (the drives disabled, the loop stopped, the candump log
    /// flushed) and says whether every file the session wrote is whole.
    pub fn close(self) -> Result<(), String> {
        let candump = self.candump.clone();
        drop(self);
        match candump {
            Some((path, health)) => match health.error() {
                Some(e) => Err(format!(
                    "candump log {}: write failed ({e}); the recording is incomplete",
                    path.display()
                )),
                None => Ok(()),
            },
            None => Ok(()),
        }
    }
}
