//! probebridge: the gateway between HEIDENHAIN-style touch-probe measuring cycles and
//! fieldbus drives. This library holds what the `probebridge` binary is made of, so the
//! integration tests can drive the same code.

pub mod bench;
pub mod commands;
pub mod configs;
pub mod estimator;
pub mod ipc;
pub mod modbus_session;
pub mod output;
pub mod session;
pub mod stop_signal;
