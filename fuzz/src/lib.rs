//! Fuzzing for probebridge on the stable toolchain: every parser and frame decoder
//! as a [`driver::Target`], and a driver that mutates a corpus seeded from the
//! project's own files within a time or iteration budget (see docs/testing.md,
//! "Fuzzing", and `probebridge-fuzz --help`).
//!
//! See `ARCHITECTURE.md#fuzz` in the repository root.

pub mod corpus;
pub mod driver;
pub mod mutate;
pub mod rng;
pub mod sig;
pub mod targets;

pub use driver::{Budget, Finding, Report, Target};
