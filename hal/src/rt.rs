//! Real-time scheduling of the calling thread, for threads on the hot trigger path
//! besides the real-time loop (which sets itself up in `master`): the sample forwarder,
//! benchmark stand-ins for hardware.

/// Puts the calling thread under SCHED_FIFO at `priority` (1..99). `false` when not
/// permitted (no CAP_SYS_NICE / RLIMIT_RTPRIO) or `priority` is out of range; the
/// thread then keeps its scheduling.
pub fn set_fifo_priority(priority: i32) -> bool {
    if !(1..=99).contains(&priority) {
        return false;
    }
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: plain syscall on the calling thread (pid 0) with a parameter we own.
    unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) == 0 }
}
