//! What a command says about the machine it opens (`--scenario`, `--machine`, `--can`,
//! `--modbus`, ...), and what goes wrong opening it.

use crate::ipc::ServiceLockError;
use hal::MachineError;
use std::path::PathBuf;

/// How to reach the machine.
#[derive(Clone, Debug, Default)]
pub struct MachineOptions {
    /// Simulation scenario (default: the demo scenario). With `can`, it only names the
    /// machine configuration and the probe table radius.
    pub scenario: Option<PathBuf>,
    /// Machine configuration (TOML) for real drives on `can`; without it the
    /// scenario's machine is used.
    pub machine: Option<PathBuf>,
    /// SocketCAN interface; `None` = built-in simulator on the in-process bus.
    pub can: Option<String>,
    /// Modbus: `Some("")` = the built-in simulated PLC on loopback, `Some(ADDR)` = a
    /// PLC at host:port; `None` = Modbus only when the machine's bus kind says so.
    pub modbus: Option<String>,
    /// Pace the built-in simulator in real time instead of a virtual clock.
    pub realtime: bool,
    /// iceoryx2 service prefix for contact samples.
    pub service: String,
    /// Record the master's CAN traffic in candump's log format.
    pub candump: Option<PathBuf>,
    /// The operator's stop (the signal handler's flag): brakes a move under way.
    pub abort: Option<hal::AbortFlag>,
    /// Seeded faults injected between the CANopen master and the bus (drop,
    /// duplicate, delay, reorder), to show how it copes.
    pub bus_faults: Option<hal::can::fault_injection::BusFaults>,
}

#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    #[error("{0}")]
    Scenario(String),
    #[error(transparent)]
    Machine(#[from] MachineError),
    #[error("iceoryx2: {0}")]
    Ipc(String),
    /// Another session holds the `--service` prefix.
    #[error(transparent)]
    ServiceInUse(#[from] ServiceLockError),
}
