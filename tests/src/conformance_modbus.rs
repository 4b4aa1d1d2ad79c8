//! `Machine` conformance backends over Modbus: [`ModbusMachine`] against the simulated
//! PLC (`sim::plc`) on Modbus TCP over loopback (port 0), and on Modbus RTU over a
//! pseudo-terminal pair made by `socat`.

use crate::conformance::Backend;
use hal::config::{BusConfig, MachineConfig};
use hal::modbus::{ModbusBusConfig, ModbusMachine, ModbusOptions};
use hal::{
    AbortFlag, AxisPositions, Contact, Machine, MachineError, NullSink, ProbeMove, SampleSink,
};
use sim::machine::MotionWatch;
use sim::plc::{PlcPacing, PlcProgram, SimPlc};
use sim::Scenario;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};

/// A Modbus machine with the simulated PLC it talks to (and the pty pair, for RTU).
/// Fields drop in order: the machine disconnects before the PLC stops.
pub struct PlcHeld {
    pub machine: ModbusMachine,
    pub plc: SimPlc,
    pub socat: Option<SocatPair>,
}

impl Machine for PlcHeld {
    type Error = MachineError;
    fn axes(&self) -> u8 {
        self.machine.axes()
    }
    fn positions(&mut self) -> Result<AxisPositions, MachineError> {
        self.machine.positions()
    }
    fn move_to(&mut self, target: &AxisPositions, feed: f64) -> Result<(), MachineError> {
        self.machine.move_to(target, feed)
    }
    fn probe(&mut self, mv: &ProbeMove) -> Result<Contact, MachineError> {
        self.machine.probe(mv)
    }
    fn set_run(&mut self, run_id: u64) {
        self.machine.set_run(run_id)
    }
    fn clock_ns(&mut self) -> u64 {
        self.machine.clock_ns()
    }
    fn health(&mut self) -> Result<(), MachineError> {
        self.machine.health()
    }
    fn orient_spindle(&mut self, angle_deg: f64) -> Result<bool, MachineError> {
        self.machine.orient_spindle(angle_deg)
    }
}

/// The Modbus settings of `scenario`'s machine, or the default mailbox when its bus is
/// CANopen (the same machine, driven through a PLC). The answer timeout is at least
/// [`LOADED_HOST_TIMEOUT_MS`]: these tests compare results, not timing, and stop 43's CI
/// lost a 451 to one 200 ms answer while the vcan VM shared the two cores. A test of
/// the timeout itself sets its own in `tune`.
pub fn modbus_bus(scenario: &Scenario) -> ModbusBusConfig {
    let mut bus = scenario
        .machine
        .modbus_bus()
        .cloned()
        .unwrap_or_else(|| ModbusBusConfig::tcp("127.0.0.1:0"));
    bus.timeout_ms = bus.timeout_ms.max(LOADED_HOST_TIMEOUT_MS);
    bus
}

/// The Modbus answer timeout of the fixtures: a loaded CI host may stall a thread for
/// hundreds of milliseconds, the simulated PLC answers at once otherwise.
pub const LOADED_HOST_TIMEOUT_MS: u32 = 2000;

/// The bridge's machine configuration with `bus` in `[bus]`.
pub fn with_bus(scenario: &Scenario, bus: ModbusBusConfig) -> MachineConfig {
    let mut cfg = crate::machine_config(scenario);
    cfg.bus = BusConfig::Modbus(bus);
    // The PLC orients the spindle over Modbus (`bus.spindle_orientation`), not a drive.
    cfg.spindle = None;
    cfg
}

/// Starts the simulated PLC of `scenario` on TCP loopback (virtual clock) and connects
/// a [`ModbusMachine`] to it; `tune` may change the bus settings of both first.
pub fn open_tcp(scenario: &Scenario, tune: impl FnOnce(&mut ModbusBusConfig)) -> PlcHeld {
    open_tcp_with(scenario, tune, NullSink)
}

/// As [`open_tcp`], publishing contacts to `sink`.
pub fn open_tcp_with(
    scenario: &Scenario,
    tune: impl FnOnce(&mut ModbusBusConfig),
    sink: impl SampleSink + 'static,
) -> PlcHeld {
    open_tcp_abortable(scenario, tune, sink, None, None)
}

/// As [`open_tcp_with`]; with an operator's stop, the PLC runs in real time (on its
/// virtual clock a move would end before the bridge's next poll could stop it).
fn open_tcp_abortable(
    scenario: &Scenario,
    tune: impl FnOnce(&mut ModbusBusConfig),
    sink: impl SampleSink + 'static,
    abort: Option<AbortFlag>,
    watch: Option<MotionWatch>,
) -> PlcHeld {
    let mut bus = modbus_bus(scenario);
    tune(&mut bus);
    let (program, pacing) = plc_program(scenario, &bus, abort.is_some(), watch);
    let plc = SimPlc::serve_tcp(
        program,
        bus.unit,
        "127.0.0.1:0".parse().expect("loopback address"),
        pacing,
    )
    .unwrap_or_else(|e| panic!("simulated PLC did not start: {e}"));
    let addr = plc.local_addr().expect("a TCP server has an address");
    bus.address = Some(addr.to_string());
    let options = ModbusOptions {
        abort,
        ..ModbusOptions::default()
    };
    let machine = ModbusMachine::start(&with_bus(scenario, bus), sink, options)
        .unwrap_or_else(|e| panic!("Modbus machine did not start: {e}"));
    PlcHeld {
        machine,
        plc,
        socat: None,
    }
}

/// The simulated PLC's program for `bus`, paced in real time when `realtime`.
fn plc_program(
    scenario: &Scenario,
    bus: &ModbusBusConfig,
    realtime: bool,
    watch: Option<MotionWatch>,
) -> (PlcProgram, PlcPacing) {
    let mut program = PlcProgram::new(scenario, bus);
    if let Some(w) = watch {
        program.set_motion_watch(w);
    }
    let pacing = if realtime {
        PlcPacing::RealTime
    } else {
        PlcPacing::Virtual
    };
    (program, pacing)
}

/// ModbusMachine and the simulated PLC over Modbus TCP on loopback.
pub struct ModbusTcp;

impl Backend for ModbusTcp {
    type M = PlcHeld;
    fn open(scenario: &Scenario) -> Self::M {
        open_tcp(scenario, |_| {})
    }
    fn open_abortable(scenario: &Scenario, abort: AbortFlag, watch: MotionWatch) -> Self::M {
        open_tcp_abortable(scenario, |_| {}, NullSink, Some(abort), Some(watch))
    }
}

/// Two pseudo-terminals wired together by `socat`: what one end writes, the other
/// reads, as over an RS-485 pair. The process ends with this value.
pub struct SocatPair {
    child: Child,
    pub ends: [PathBuf; 2],
}

impl SocatPair {
    /// Starts `socat -d -d pty,raw,echo=0 pty,raw,echo=0` and reads the two device
    /// names it reports on stderr (it prints them before it starts relaying).
    pub fn open() -> Result<Self, String> {
        use std::io::{BufRead, BufReader};
        let mut child = Command::new("socat")
            .args(["-d", "-d", "pty,raw,echo=0", "pty,raw,echo=0"])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| format!("cannot run socat: {e}"))?;
        let stderr = child.stderr.take().ok_or("no stderr from socat")?;
        let mut lines = BufReader::new(stderr).lines();
        let mut ends = Vec::new();
        let mut pair = None;
        while ends.len() < 2 {
            let Some(Ok(line)) = lines.next() else {
                let _ = child.kill();
                let _ = child.wait();
                return Err("socat ended before it reported two ptys".into());
            };
            if let Some(at) = line.find("PTY is ") {
                ends.push(PathBuf::from(line[at + 7..].trim()));
            }
        }
        // "starting data transfer loop" follows; socat keeps logging to the pipe, which
        // a thread drains so socat never blocks on it.
        std::thread::spawn(move || for _ in lines.by_ref() {});
        if let [a, b] = &ends[..] {
            pair = Some([a.clone(), b.clone()]);
        }
        match pair {
            Some(ends) => Ok(Self { child, ends }),
            None => Err("socat reported no pty pair".into()),
        }
    }
}

impl Drop for SocatPair {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// ModbusMachine and the simulated PLC over Modbus RTU on a `socat` pty pair.
pub struct ModbusRtu;

impl ModbusRtu {
    pub fn open_with(scenario: &Scenario, tune: impl FnOnce(&mut ModbusBusConfig)) -> PlcHeld {
        Self::open_abortable_with(scenario, tune, None, None)
    }

    fn open_abortable_with(
        scenario: &Scenario,
        tune: impl FnOnce(&mut ModbusBusConfig),
        abort: Option<AbortFlag>,
        watch: Option<MotionWatch>,
    ) -> PlcHeld {
        let pair = SocatPair::open().unwrap_or_else(|e| panic!("{e}"));
        let [plc_end, bridge_end] = pair.ends.clone();
        let mut bus = modbus_bus(scenario);
        bus.transport = hal::modbus::Transport::Rtu;
        bus.address = None;
        bus.device = Some(bridge_end.display().to_string());
        bus.baud = 115_200;
        tune(&mut bus);
        let (program, pacing) = plc_program(scenario, &bus, abort.is_some(), watch);
        let plc = SimPlc::serve_rtu(
            program,
            bus.unit,
            &plc_end.display().to_string(),
            bus.baud,
            pacing,
        )
        .unwrap_or_else(|e| panic!("simulated PLC did not start on {}: {e}", plc_end.display()));
        let options = ModbusOptions {
            abort,
            ..ModbusOptions::default()
        };
        let machine = ModbusMachine::start(&with_bus(scenario, bus), NullSink, options)
            .unwrap_or_else(|e| panic!("Modbus RTU machine did not start: {e}"));
        PlcHeld {
            machine,
            plc,
            socat: Some(pair),
        }
    }
}

impl Backend for ModbusRtu {
    type M = PlcHeld;
    fn available() -> Result<(), String> {
        match Command::new("socat").arg("-V").output() {
            Ok(o) if o.status.success() => Ok(()),
            // CI installs it (scripts/test runs scripts/install-test-peers): never skip there.
            _ if std::env::var_os("CI").is_some() => {
                panic!(
                    "socat is missing in CI: scripts/install-test-peers should have installed it"
                )
            }
            _ => Err("socat is not installed (scripts/install-test-peers installs it)".into()),
        }
    }
    fn open(scenario: &Scenario) -> Self::M {
        Self::open_with(scenario, |_| {})
    }
    fn open_abortable(scenario: &Scenario, abort: AbortFlag, watch: MotionWatch) -> Self::M {
        Self::open_abortable_with(scenario, |_| {}, Some(abort), Some(watch))
    }
}
