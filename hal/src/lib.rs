//! probebridge-hal: what the measuring cycles need from a machine, and the fieldbus
//! side that provides it.
//!
//! See `ARCHITECTURE.md#hal` in the repository root.
//!
//! - [`machine`]: the [`Machine`] trait the cycles call (blocking axis moves and
//!   probing moves that stop on the hardware latch), its error kinds.
//! - [`contact_sample`]: the `#[repr(C)]` sample every latched contact becomes.
//! - [`can`]: CAN frames and transports (SocketCAN, in-process bus).
//! - [`canopen`], [`cia402`]: the CANopen master and CiA 402 drive profile as code
//!   that does no I/O (frames in, frames out).
//! - [`motion_guard`]: the checks every backend makes before it moves (software
//!   limits, the probing path plus braking distance, feeds) and the collision rule.
//! - [`modbus`]: the PLC backend over Modbus TCP/RTU (mailbox codec, latch ring).
//! - [`config`]: the machine description (axes, bus mapping, kinematics, probe table).

pub mod abort;
pub mod atomic_write;
pub mod axis;
pub mod can;
pub mod canopen;
pub mod cia402;
pub mod clock;
pub mod config;
pub mod contact_sample;
pub mod machine;
pub mod master;
pub mod modbus;
pub mod motion;
pub mod motion_guard;
pub mod rt;

pub use abort::AbortFlag;
pub use axis::{Axis, AxisPositions};
pub use contact_sample::{ContactSample, NullSink, SampleSink, SinkError};
pub use machine::{Contact, ErrorKind, Machine, MachineError, ProbeMove};
