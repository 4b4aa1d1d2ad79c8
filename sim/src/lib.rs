//! probebridge-sim: the simulated machine.
//!
//! See `ARCHITECTURE.md#sim` in the repository root.
//!
//! - [`scenario`]: the TOML file that adds the truth (errors, probe, artefacts,
//!   faults) to a machine configuration.
//! - [`kinematics`]: the kinematic chain with the true ISO 230-7 errors (its module
//!   doc fixes the convention the cycles' model shares).
//! - [`backlash`]: dead band of a rotary axis.
//! - [`artefact`]: plane, sphere, cylinder; exact segment contact.
//! - [`probe`]: ball radius, pre-travel, noise, signal state.
//! - [`stylus`]: the real stylus: direction-dependent pre-travel (lobing), the ball
//!   centre's offset from the spindle axis and its length error.
//! - [`world`]: all of it, stepped once per simulation step by the drive simulation.
//! - [`drive`]: a simulated CiA 402 drive on CANopen (same codec as the master).
//! - [`machine`]: all drives of a machine on a bus, stepped together per SYNC.
//! - [`plc`]: a PLC owning the axes, with its mailbox on Modbus TCP/RTU.

pub mod artefact;
pub mod backlash;
pub mod drive;
pub mod kinematics;
pub mod machine;
pub mod plc;
pub mod probe;
pub mod scenario;
pub mod stylus;
pub mod world;

pub use scenario::{Scenario, ScenarioError};
pub use world::World;
