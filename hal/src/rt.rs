//! Real-time settings: SCHED_FIFO for the threads on the hot trigger path (the
//! real-time loop, the sample forwarder, benchmark stand-ins for hardware), locked
//! memory, and the CPU wake-up latency request the loop holds.

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

/// The CPUs the calling thread may run on (its affinity mask), lowest first; empty
/// when not reported.
pub fn allowed_cpus() -> Vec<usize> {
    // SAFETY: a zeroed cpu_set_t is valid; sched_getaffinity fills it for this thread.
    unsafe {
        let mut set: libc::cpu_set_t = core::mem::zeroed();
        if libc::sched_getaffinity(0, core::mem::size_of::<libc::cpu_set_t>(), &mut set) != 0 {
            return Vec::new();
        }
        (0..libc::CPU_SETSIZE as usize)
            .filter(|&c| libc::CPU_ISSET(c, &set))
            .collect()
    }
}

/// The CPUs online (`_SC_NPROCESSORS_ONLN`: 0..n), whatever this thread's mask: a
/// process whose parent was pinned may widen its own mask within its cpuset.
pub fn online_cpus() -> Vec<usize> {
    // SAFETY: sysconf has no preconditions.
    let n = unsafe { libc::sysconf(libc::_SC_NPROCESSORS_ONLN) };
    (0..n.max(1) as usize).collect()
}

/// The CPU the real-time loop takes: the last of `allowed` when there are two or more
/// (the others are left to the estimator's armed receive and everything else, so a
/// spinning estimator and the loop never share a CPU); `None` on one CPU.
pub fn realtime_cpu_of(allowed: &[usize]) -> Option<usize> {
    (allowed.len() >= 2).then(|| allowed[allowed.len() - 1])
}

/// Restricts the calling thread to `cpus`; `false` when refused (or `cpus` is empty).
pub fn pin_thread(cpus: &[usize]) -> bool {
    if cpus.is_empty() {
        return false;
    }
    // SAFETY: a zeroed cpu_set_t is valid; CPU_SET for CPUs below CPU_SETSIZE, then
    // sched_setaffinity on the calling thread (pid 0).
    unsafe {
        let mut set: libc::cpu_set_t = core::mem::zeroed();
        for &c in cpus.iter().filter(|&&c| c < libc::CPU_SETSIZE as usize) {
            libc::CPU_SET(c, &mut set);
        }
        libc::sched_setaffinity(0, core::mem::size_of::<libc::cpu_set_t>(), &set) == 0
    }
}

/// Locks the process's memory, current and future (no page faults in a real-time
/// loop). `false` when not permitted (no CAP_IPC_LOCK / RLIMIT_MEMLOCK too low).
pub fn lock_memory() -> bool {
    // SAFETY: plain syscall; failure is reported, not fatal.
    unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) == 0 }
}

/// A PM QoS request holding every CPU's wake-up latency at 0 µs while it lives: the
/// kernel keeps idle CPUs out of deep C-states, whose exit takes tens to hundreds of µs
/// on gateway-class CPUs and would land on the first frame after an idle SYNC gap.
/// The request is the open file; dropping it releases it (as cyclictest does).
#[derive(Debug)]
pub struct CpuLatencyRequest {
    _file: std::fs::File,
}

/// Where the kernel takes CPU wake-up latency requests.
pub const CPU_DMA_LATENCY: &str = "/dev/cpu_dma_latency";

/// Asks for 0 µs CPU wake-up latency; `Err` says why not (typically: not root).
pub fn hold_cpu_latency_zero() -> Result<CpuLatencyRequest, String> {
    use std::io::Write;
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .open(CPU_DMA_LATENCY)
        .map_err(|e| format!("{CPU_DMA_LATENCY}: {e}"))?;
    file.write_all(&0i32.to_ne_bytes())
        .map_err(|e| format!("{CPU_DMA_LATENCY}: {e}"))?;
    Ok(CpuLatencyRequest { _file: file })
}

/// The kernel's cpuidle driver (`none` in VMs without one, where idle CPUs halt to the
/// hypervisor whatever is requested); `None` when not reported.
pub fn cpuidle_driver() -> Option<String> {
    std::fs::read_to_string("/sys/devices/system/cpu/cpuidle/current_driver")
        .ok()
        .map(|s| s.trim().to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_real_time_loop_takes_the_last_cpu_of_two_or_more_and_none_of_one() {
        assert_eq!(realtime_cpu_of(&[0, 1]), Some(1));
        assert_eq!(realtime_cpu_of(&[2, 5, 7]), Some(7));
        assert_eq!(realtime_cpu_of(&[3]), None);
        assert_eq!(realtime_cpu_of(&[]), None);
    }

    #[test]
    fn a_thread_pinned_to_one_allowed_cpu_is_allowed_that_one_only() {
        let allowed = allowed_cpus();
        assert!(!allowed.is_empty(), "the affinity mask is readable");
        let last = *allowed.last().unwrap();
        std::thread::spawn(move || {
            assert!(pin_thread(&[last]));
            assert_eq!(allowed_cpus(), [last]);
            assert!(!pin_thread(&[]), "an empty set is refused");
            assert_eq!(allowed_cpus(), [last], "and changes nothing");
        })
        .join()
        .unwrap();
    }

    #[test]
    fn the_cpu_latency_request_is_held_while_it_lives() {
        // SAFETY: geteuid has no preconditions.
        let root = unsafe { libc::geteuid() } == 0;
        let present = std::path::Path::new(CPU_DMA_LATENCY).exists();
        match hold_cpu_latency_zero() {
            Ok(req) => {
                // Reading the device gives the strictest request in force: ours.
                let v = std::fs::read(CPU_DMA_LATENCY).unwrap();
                assert_eq!(i32::from_ne_bytes(v[..4].try_into().unwrap()), 0);
                drop(req);
            }
            Err(why) => {
                assert!(
                    !(root && present),
                    "root and {CPU_DMA_LATENCY} exists: {why}"
                );
                assert!(why.starts_with(CPU_DMA_LATENCY), "{why}");
            }
        }
    }
}
