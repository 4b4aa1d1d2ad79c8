//! A simulated PLC that owns the axes and latches the probe, reached over Modbus TCP
//! or RTU: the mailbox of `hal::modbus` implemented on the simulated physics.
//!
//! - [`program`]: the PLC program (registers, motion, latch ring), no I/O.
//! - [`server`]: the program's task thread and its tokio-modbus server.
//! - [`knobs`]: misbehaviour a test can turn on.

pub mod knobs;
pub mod program;
pub mod server;

pub use knobs::Knobs;
pub use program::PlcProgram;
pub use server::{PlcPacing, SimPlc};
