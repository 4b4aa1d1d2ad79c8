//! probebridge: the gateway between HEIDENHAIN-style touch-probe measuring cycles and
//! fieldbus drives. This library holds what the `probebridge` binary is made of, so the
//! integration tests can drive the same code.
//!
//! See `ARCHITECTURE.md#bridge` in the repository root.

/// A line on stdout that never panics: a closed pipe (`| head`) or a full device ends
/// the output, not the command (the measurement goes on and its files are written).
#[macro_export]
macro_rules! say {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout().lock(), $($t)*);
    }};
}

/// As [`say!`], without the newline.
#[macro_export]
macro_rules! say_raw {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = write!(std::io::stdout().lock(), $($t)*);
    }};
}

/// A line on stderr that never panics (see [`say!`]).
#[macro_export]
macro_rules! tell {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr().lock(), $($t)*);
    }};
}

pub mod bench;
pub mod commands;
pub mod configs;
pub mod estimator;
pub mod history;
pub mod ipc;
pub mod machine_state;
pub mod output;
pub mod serve;
pub mod session;
pub mod state_dir;
pub mod stop_signal;
