//! The host's own floor: how long one process takes to wake another that sleeps in
//! the kernel. A bare eventfd ping between a parent and a forked child
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

    /// Set by the parent when the child is to leave.
    fn quit(&self) -> &AtomicU64 {
        // SAFETY: as `stamp`, the next word of the page.
        unsafe { &*(self.0 as *const AtomicU64).add(1) }
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

/// Stamp word values before the first ping: bit 2 says the child is there, bit 0
/// pinned, bit 1 SCHED_FIFO.
const CHILD_THERE: u64 = 4;
/// Written to the quit word: the child leaves after its next wake-up.
const QUIT: u64 = 1;

/// A forked partner process asleep in `read` on an eventfd, woken by [`Pinger::ping`]:
/// once per trigger in the bench (cold: it slept as long as the estimator), or back
/// to back ([`measure`], hot).
pub struct Pinger {
    page: SharedPage,
    ping: Fd,
    pong: Fd,
    pid: libc::pid_t,
    /// The child is pinned to another CPU than the caller's.
    pub cross_cpu: bool,
    /// The child runs under SCHED_FIFO.
    pub fifo: bool,
}

impl Pinger {
    /// Forks the partner, under SCHED_FIFO at `priority` (0: ordinary); with `cpus`
    /// = (caller's, partner's), each pinned there (the caller stays pinned).
    pub fn start(priority: i32, cpus: Option<(usize, usize)>) -> Result<Self, String> {
        let page = SharedPage::new()?;
        let (ping, pong) = (eventfd()?, eventfd()?);
        let parent_cpu = cpus.is_some_and(|(caller, _)| pin(caller));
        let partner_cpu = cpus.map(|(_, p)| p);
        // SAFETY: fork in a process with other threads: the child only makes
        // async-signal-safe calls (sched_setaffinity, sched_setscheduler, read, write,
        // clock_gettime, _exit) on memory that exists before the fork, and allocates
        // nothing.
        let pid = unsafe { libc::fork() };
        if pid < 0 {
            return Err(format!("fork: {}", std::io::Error::last_os_error()));
        }
        if pid == 0 {
            partner(&page, &ping, &pong, partner_cpu, priority);
        }
        let child = if wait(&pong) {
            page.stamp().load(Ordering::Acquire)
        } else {
            0
        };
        Ok(Self {
            cross_cpu: parent_cpu && child & 0b101 == 0b101,
            fifo: child & 0b110 == 0b110,
            page,
            ping,
            pong,
            pid,
        })
    }

    /// One wake-up: CLOCK_MONOTONIC before the write to when the partner ran, ns.
    pub fn ping(&mut self) -> Option<u64> {
        let t0 = hal::clock::monotonic_ns();
        if !signal(&self.ping) || !wait(&self.pong) {
            return None;
        }
        Some(self.page.stamp().load(Ordering::Acquire).saturating_sub(t0))
    }
}

impl Drop for Pinger {
    fn drop(&mut self) {
        self.page.quit().store(QUIT, Ordering::Release);
        signal(&self.ping);
        let mut status = 0;
        // SAFETY: reaps the child we forked.
        unsafe { libc::waitpid(self.pid, &mut status, 0) };
    }
}

/// The forked partner: answers pings until told to quit, then leaves.
fn partner(page: &SharedPage, ping: &Fd, pong: &Fd, cpu: Option<usize>, priority: i32) -> ! {
    let pinned = cpu.is_some_and(pin);
    let fifo = priority > 0 && hal::rt::set_fifo_priority(priority);
    let stamp = page.stamp();
    stamp.store(
        CHILD_THERE | pinned as u64 | (fifo as u64) << 1,
        Ordering::Release,
    );
    signal(pong);
    while wait(ping) {
        stamp.store(hal::clock::monotonic_ns(), Ordering::Release);
        if page.quit().load(Ordering::Acquire) == QUIT || !signal(pong) {
            break;
        }
    }
    // SAFETY: leaves the child at once, running no destructors or atexit handlers of
    // the parent's state.
    unsafe { libc::_exit(0) }
}

/// `count` pings back to back (after `warmup` not kept): the hot figure. The partner
/// under SCHED_FIFO at `priority` (0: ordinary), caller and partner on different
/// CPUs when there are two; this thread runs at `priority` meanwhile.
pub fn measure(count: usize, warmup: usize, priority: i32) -> Result<Wakeup, String> {
    let saved = affinity();
    // SAFETY: plain syscalls reading the calling thread's scheduling, to restore.
    let (policy, param) = unsafe {
        let mut param = libc::sched_param { sched_priority: 0 };
        libc::sched_getparam(0, &mut param);
        (libc::sched_getscheduler(0), param)
    };
    let parent_fifo = priority > 0 && hal::rt::set_fifo_priority(priority);
    let mut latencies_ns = Vec::with_capacity(count);
    let two_cpus = std::thread::available_parallelism().map_or(1, |n| n.get()) >= 2;
    let started = Pinger::start(priority, two_cpus.then_some((0, 1)));
    let (cross_cpu, fifo) = match started {
        Ok(mut pinger) => {
            for i in 0..count + warmup {
                let Some(ns) = pinger.ping() else { break };
                if i >= warmup {
                    latencies_ns.push(ns);
                }
            }
            (pinger.cross_cpu, pinger.fifo)
        }
        Err(_) => (false, false),
    };
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
        cross_cpu,
        fifo: parent_fifo && fifo,
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

    #[test]
    fn a_pinger_answers_each_ping_and_its_partner_leaves_when_dropped() {
        let mut p = Pinger::start(0, None).unwrap();
        for _ in 0..3 {
            assert!(p.ping().is_some_and(|ns| ns > 0));
        }
        let pid = p.pid;
        drop(p);
        // SAFETY: probes whether the reaped child still exists.
        assert_eq!(unsafe { libc::kill(pid, 0) }, -1, "the partner is gone");
    }
}
