//! The PLC backend: a PLC owns the axes and latches the probe in its own real-time
//! task; the bridge commands moves and reads latched positions and status over Modbus
//! TCP or RTU.
//!
//! - [`word_order`], [`mailbox`], [`latch_ring`]: the register map as a codec that
//!   does no I/O.
//! - [`config`]: the `[bus] kind = "modbus"` section.
//! - [`client`]: the I/O thread (tokio-modbus on a current-thread runtime).
//! - [`machine`]: [`ModbusMachine`], the `Machine` over the mailbox.
//! - [`exception`]: exceptions and transport failures as error kinds.

pub mod client;
pub mod config;
pub mod exception;
pub mod latch_ring;
pub mod machine;
pub mod mailbox;
mod named_values;
pub mod word_order;

pub use config::{CaptureKind, ModbusBusConfig, Transport};
pub use machine::{ModbusMachine, ModbusOptions};
pub use word_order::WordOrder;
