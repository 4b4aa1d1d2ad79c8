//! SIGINT, SIGTERM and SIGHUP during `run`, `probe` and `demo`: the first raises the
//! stop flag that the master's waits poll (the move under way is braked, the cycle
//! ends as aborted, the results are written, the drives are disabled on the way out)
//! and the process then exits with 128 + the first signal. More signals within
//! [`REPEAT_WINDOW`] of the first are the same stop request, delivered again: `timeout
//! -s INT` signals the process and then its process group, so the process gets two at
//! once, and a `kill` of the group does the same; the orderly end goes on and writes
//! the aborted result. A signal after the window is the operator insisting (the
//! orderly end is stuck): the process exits at once, writing nothing.
//!
//! The handler does only async-signal-safe things: `clock_gettime`, atomics and
//! `_exit`.

use hal::AbortFlag;
use std::sync::atomic::{AtomicI32, AtomicU64, Ordering};
use std::time::Duration;

/// The state of [`hal::AbortFlag`] (raised bit and generation).
static STOP: AtomicU64 = AtomicU64::new(0);
static SIGNAL: AtomicI32 = AtomicI32::new(0);
/// When the first signal came (monotonic clock, ns; 0: none yet).
static FIRST_AT: AtomicU64 = AtomicU64::new(0);

/// The signals that stop the machine.
pub const SIGNALS: [libc::c_int; 3] = [libc::SIGINT, libc::SIGTERM, libc::SIGHUP];

/// How long after the first signal another one is taken as the same request delivered
/// again (see the module's text), not as the operator insisting.
pub const REPEAT_WINDOW: Duration = Duration::from_secs(2);

/// The monotonic clock in ns (at least 1, so that 0 means "not yet").
fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime is async-signal-safe and writes only `ts`.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    let ns = u64::try_from(ts.tv_sec).unwrap_or(0) * 1_000_000_000
        + u64::try_from(ts.tv_nsec).unwrap_or(0);
    ns.max(1)
}

/// Whether a signal at `now_ns` repeats the stop request of the first, at `first_ns`.
fn repeats_first(first_ns: u64, now_ns: u64) -> bool {
    u128::from(now_ns.saturating_sub(first_ns)) <= REPEAT_WINDOW.as_nanos()
}

extern "C" fn on_signal(sig: libc::c_int) {
    let now = monotonic_ns();
    // Only the first signal sets the time, before it claims SIGNAL: a later handler
    // always finds it.
    let _ = FIRST_AT.compare_exchange(0, now, Ordering::AcqRel, Ordering::Acquire);
    if SIGNAL
        .compare_exchange(0, sig, Ordering::AcqRel, Ordering::Acquire)
        .is_err()
    {
        if repeats_first(FIRST_AT.load(Ordering::Acquire), now) {
            // The same request again: the orderly end is under way.
            return;
        }
        // Later: the operator insists. SAFETY: _exit is async-signal-safe.
        unsafe { libc::_exit(128 + sig) };
    }
    flag().raise();
}

/// The flag the handler raises, for the master's options.
pub fn flag() -> AbortFlag {
    AbortFlag::new(&STOP)
}

/// Installs the handler for [`SIGNALS`].
pub fn install() -> Result<(), String> {
    for sig in SIGNALS {
        // SAFETY: a zeroed sigaction is valid; the handler only reads the clock,
        // touches atomics and calls _exit; SA_RESTART keeps blocking reads of other threads going.
        let rc = unsafe {
            let mut sa: libc::sigaction = std::mem::zeroed();
            sa.sa_sigaction = on_signal as extern "C" fn(libc::c_int) as usize;
            sa.sa_flags = libc::SA_RESTART;
            // The stop signals wait for each other's handler to end.
            libc::sigemptyset(&mut sa.sa_mask);
            for other in SIGNALS {
                libc::sigaddset(&mut sa.sa_mask, other);
            }
            libc::sigaction(sig, &sa, std::ptr::null_mut())
        };
        if rc != 0 {
            return Err(format!(
                "cannot install the handler of signal {sig}: {}",
                std::io::Error::last_os_error()
            ));
        }
    }
    Ok(())
}

/// The stop signal received so far, if any.
pub fn received() -> Option<i32> {
    match SIGNAL.load(Ordering::Acquire) {
        0 => None,
        s => Some(s),
    }
}

/// The conventional exit status after a stop signal (128 + signal).
pub fn exit_status() -> Option<u8> {
    received().and_then(|s| u8::try_from(128 + s).ok())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_signal_within_the_window_repeats_the_first_and_a_later_one_insists() {
        let first = 5_000_000_000;
        assert!(repeats_first(first, first));
        assert!(repeats_first(first, first + 40_000));
        assert!(repeats_first(first, first + 1_999_000_000));
        assert!(!repeats_first(first, first + 2_000_000_001));
        assert!(!repeats_first(first, first + 30_000_000_000));
        // A clock read before the first (another thread's handler) is within it.
        assert!(repeats_first(first, first - 10));
    }
}
