//! SIGINT, SIGTERM and SIGHUP during `run`, `probe` and `demo`: the first raises the
//! stop flag that the master's waits poll (the move under way is braked, the cycle
//! ends as aborted, the results are written, the drives are disabled on the way out)
//! and the process then exits with 128 + signal; a second signal exits at once.
//!
//! The handler does only async-signal-safe things: atomic stores and `_exit`.

use hal::AbortFlag;
use std::sync::atomic::{AtomicI32, AtomicU64, Ordering};

/// The state of [`hal::AbortFlag`] (raised bit and generation).
static STOP: AtomicU64 = AtomicU64::new(0);
static SIGNAL: AtomicI32 = AtomicI32::new(0);

/// The signals that stop the machine.
pub const SIGNALS: [libc::c_int; 3] = [libc::SIGINT, libc::SIGTERM, libc::SIGHUP];

extern "C" fn on_signal(sig: libc::c_int) {
    if SIGNAL
        .compare_exchange(0, sig, Ordering::AcqRel, Ordering::Acquire)
        .is_err()
    {
        // The second signal: the operator insists. SAFETY: _exit is async-signal-safe.
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
        // SAFETY: a zeroed sigaction is valid; the handler only touches atomics and
        // calls _exit; SA_RESTART keeps blocking reads of other threads going.
        let rc = unsafe {
            let mut sa: libc::sigaction = std::mem::zeroed();
            sa.sa_sigaction = on_signal as extern "C" fn(libc::c_int) as usize;
            sa.sa_flags = libc::SA_RESTART;
            libc::sigemptyset(&mut sa.sa_mask);
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
