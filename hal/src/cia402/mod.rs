//! CiA 402 drive profile: state machine, controlword/statusword, touch probe.
//!
//! Both sides use it: the master decides the next controlword from the statusword,
//! the simulated drive moves its state on the controlword it receives.

pub mod controlword;
pub mod mode;
pub mod state;
pub mod statusword;
pub mod touch_probe;

pub use controlword::{Command, Controlword};
pub use mode::ModeOfOperation;
pub use state::State;
pub use statusword::Statusword;
pub use touch_probe::{Probe, TouchProbeFunction, TouchProbeStatus, TriggerSource};
