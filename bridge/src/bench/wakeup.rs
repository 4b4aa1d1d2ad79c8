//! The host's own floor: how long one process takes to wake another that sleeps in
//! the kernel on another CPU. A bare eventfd ping between a parent and a forked child
//! (no iceoryx2, no bus, no payload): the child blocks in `read`, the parent stamps
//! CLOCK_MONOTONIC and writes, the child stamps when it runs again and answers. Every
//! path that hands a contact from one process to another pays at least this.

use core::sync::atomic::{AtomicU64, Ordering};

/// What the ping measured.
pub struct Wakeup {
    /// One-way wake-up latencies, ns.
    pub latencies_ns: Vec<u64>,
    /// Parent and child pinned to different CPUs.
    pub cross_cpu: bool,
    /// Both ran under SCHED_FIFO at the requested priority.
    pub fifo: bool,
}

/// Closes a file descriptor on drop.
struct Fd(i32);

impl Drop for Fd {
    fn drop(&mut self) {
        // SAFETY: we own the descriptor.
        unsafe { libc::close(self.0) };
    }
}

/// One shared page between parent and child.
struct SharedPage(*mut libc::c_void);

impl SharedPage {
    fn new() -> Result<Self, String> {
        // SAFETY: an anonymous shared mapping of one page; checked below.
        let p = unsafe {
            libc::mmap(
                core::ptr::null_mut(),
                4096,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_SHARED | libc::MAP_ANONYMOUS,
                -1,
                0,
            )
        };
        if p == libc::MAP_FAILED {
            return Err(format!("mmap: {}", std::io::Error::last_os_error()));
        }
        Ok(Self(p))
    }

    /// The child's wake-up stamp.
    fn stamp(&self) -> &AtomicU64 {
        // SAFETY: the page is zeroed, aligned, lives as long as self, and is only
        // accessed atomically by both processes.
        unsafe { &*(self.0 as *const AtomicU64) }
    }
}

impl Drop for SharedPage {
    fn drop(&mut self) {
        // SAFETY: the mapping made in `new`.
        unsafe { libc::munmap(self.0, 4096) };
    }
}

fn eventfd() -> Result<Fd, String> {
    // SAFETY: plain syscall.
    let fd = unsafe { libc::eventfd(0, libc::EFD_CLOEXEC) };
    if fd < 0 {
        return Err(format!("eventfd: {}", std::io::Error::last_os_error()));
    }
    Ok(Fd(fd))
}

fn signal(fd: &Fd) -> bool {
    let one: u64 = 1;
    // SAFETY: writes 8 bytes we own to an eventfd.
    unsafe { libc::write(fd.0, (&one as *const u64).cast(), 8) == 8 }
}

fn wait(fd: &Fd) -> bool {
    let mut v: u64 = 0;
    // SAFETY: reads 8 bytes into a value we own from an eventfd (blocks until set).
    unsafe { libc::read(fd.0, (&mut v as *mut u64).cast(), 8) == 8 }
}

/// Pins the calling thread to `cpu`; false when not possible.
fn pin(cpu: usize) -> bool {
    // SAFETY: a zeroed cpu_set_t is valid; CPU_SET and sched_setaffinity on it.
    unsafe {
        let mut set: libc::cpu_set_t = core::mem::zeroed();
        libc::CPU_SET(cpu, &mut set);
        libc::sched_setaffinity(0, core::mem::size_of::<libc::cpu_set_t>(), &set) == 0
    }
}

/// The calling thread's CPU affinity, to restore.
fn affinity() -> Option<libc::cpu_set_t> {
    // SAFETY: as in `pin`.
    unsafe {
        let mut set: libc::cpu_set_t = core::mem::zeroed();
        (libc::sched_getaffinity(0, core::mem::size_of::<libc::cpu_set_t>(), &mut set) == 0)
            .then_some(set)
    }
}

/// `count` pings (after `warmup` not kept), the child under SCHED_FIFO at `priority`
/// (0: ordinary), parent and child on different CPUs when there are two.
pub fn measure(count: usize, warmup: usize, priority: i32) -> Result<Wakeup, String> {
    let page = SharedPage::new()?;
    let (ping, pong) = (eventfd()?, eventfd()?);
    let two_cpus = std::thread::available_parallelism().map_or(1, |n| n.get()) >= 2;
    let saved = affinity();
    let total = count + warmup;
    let parent_cpu = two_cpus && pin(0);
    // SAFETY: plain syscalls reading the calling thread's scheduling, to restore.
    let (policy, param) = unsafe {
        let mut param = libc::sched_param { sched_priority: 0 };
        libc::sched_getparam(0, &mut param);
        (libc::sched_getscheduler(0), param)
    };
    let parent_fifo = priority > 0 && hal::rt::set_fifo_priority(priority);
    let stamp = page.stamp();
    // SAFETY: fork in a process with other threads: the child only makes
    // async-signal-safe calls (sched_setaffinity, sched_setscheduler, read, write,
    // clock_gettime, _exit) on memory that exists before the fork, and allocates
    // nothing.
    let pid = unsafe { libc::fork() };
    if pid < 0 {
        return Err(format!("fork: {}", std::io::Error::last_os_error()));
    }
    if pid == 0 {
        let pinned = two_cpus && pin(1);
        let fifo = priority > 0 && hal::rt::set_fifo_priority(priority);
        // The child's settings, in the stamp before the first ping: bit 2 says it is
        // there, bit 0 pinned, bit 1 SCHED_FIFO.
        stamp.store(4 | pinned as u64 | (fifo as u64) << 1, Ordering::Release);
        signal(&pong);
        for _ in 0..total {
            if !wait(&ping) {
                break;
            }
            stamp.store(hal::clock::monotonic_ns(), Ordering::Release);
            if !signal(&pong) {
                break;
            }
        }
        // SAFETY: leaves the child at once, running no destructors or atexit
        // handlers of the parent's state.
        unsafe { libc::_exit(0) };
    }
    let mut latencies_ns = Vec::with_capacity(count);
    let child = if wait(&pong) {
        stamp.load(Ordering::Acquire)
    } else {
        0
    };
    for i in 0..total {
        let t0 = hal::clock::monotonic_ns();
        if !signal(&ping) || !wait(&pong) {
            break;
        }
        let t1 = stamp.load(Ordering::Acquire);
        if i >= warmup {
            latencies_ns.push(t1.saturating_sub(t0));
        }
    }
    let mut status = 0;
    // SAFETY: reaps the child we forked.
    unsafe { libc::waitpid(pid, &mut status, 0) };
    // Back to the thread's own scheduling.
    if parent_fifo && policy >= 0 {
        // SAFETY: plain syscall on the calling thread, with what it had.
        unsafe { libc::sched_setscheduler(0, policy, &param) };
    }
    if let Some(set) = saved {
        // SAFETY: restores the affinity read above.
        unsafe { libc::sched_setaffinity(0, core::mem::size_of::<libc::cpu_set_t>(), &set) };
    }
    if latencies_ns.len() != count {
        return Err(format!(
            "the wake-up ping stopped after {} of {count}",
            latencies_ns.len()
        ));
    }
    Ok(Wakeup {
        latencies_ns,
        cross_cpu: parent_cpu && child & 0b101 == 0b101,
        fifo: parent_fifo && child & 0b110 == 0b110,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ping_measures_every_wake_up() {
        let w = measure(200, 10, 0).unwrap();
        assert_eq!(w.latencies_ns.len(), 200);
        assert!(w.latencies_ns.iter().all(|&ns| ns > 0));
    }
}
