//! The armed receive: while a probing move runs, the estimator polls the contact
//! subscriber (a bounded spin with `spin_loop` hints) instead of sleeping in the
//! WaitSet, so the contact is read without a wake-up: no `epoll_wait` return, no
//! scheduler hand-over, the CPU already awake. The real-time loop announces each
//! probing move with its longest duration ([`hal::contact_sample::ProbeWindow`], published on the
//! contacts service); the spin ends with the contact, at the move's end or after
//! [`MAX_ARMED`], and the estimator sleeps in the WaitSet again.
//!
//! A contact that arrives as a window ends is not lost: the spin only ever takes
//! samples out of the subscriber, and whatever it did not take is still there (and
//! its event still pending) for the receive after the next wake-up.

use core::time::Duration;
use std::time::Instant;

use hal::contact_sample::ProbeWindow;
use hal::ContactSample;

/// Config `[estimator] armed_receive`: poll during probing moves where the machine
/// has a CPU for it ("auto"), or always sleep ("off").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum ArmedReceive {
    #[default]
    Auto,
    Off,
}

impl ArmedReceive {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::Off => "off",
        }
    }

    /// Whether the estimator spins here: "auto" on a process allowed at least two
    /// CPUs (one for the real-time loop, one for the spin).
    pub fn enabled(self) -> bool {
        self.enabled_with(cpus())
    }

    pub fn enabled_with(self, cpus: usize) -> bool {
        self == Self::Auto && cpus >= 2
    }
}

/// CPUs this process may run on.
fn cpus() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// Keeps this thread (the estimator's, which may spin) off `rt`, the CPU the real-time
/// loop is pinned to: sharing it, the loop preempts the spin on every wake-up and the
/// contact waits for the loop to sleep again (measured: 10 to 13 us at p50 from the
/// publish to the estimator sharing, 7.7 apart). Says what it did.
pub fn leave_cpu(rt: usize) -> String {
    // Every online CPU but `rt`: the mask inherited from the parent may be narrower.
    let allowed = hal::rt::online_cpus();
    let others: Vec<usize> = allowed.into_iter().filter(|&c| c != rt).collect();
    let list = others
        .iter()
        .map(|c| c.to_string())
        .collect::<Vec<_>>()
        .join(",");
    if hal::rt::pin_thread(&others) {
        format!("on CPU {list}, CPU {rt} left to the real-time loop")
    } else {
        format!("could not leave CPU {rt} to the real-time loop: it may share it")
    }
}

/// The longest spin, whatever the announced window (a window from a clock the
/// estimator does not share, or a very slow probing move).
pub const MAX_ARMED: Duration = Duration::from_secs(2);

/// How an armed window ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WindowEnd {
    /// A contact was read.
    Contact,
    /// The probing move's longest duration passed.
    MoveEnd,
    /// [`MAX_ARMED`] passed.
    Timeout,
}

/// Counters of the armed receive (logged when the estimator stops).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ArmedStats {
    pub windows: u64,
    pub contacts: u64,
    pub move_ends: u64,
    pub timeouts: u64,
}

impl ArmedStats {
    fn count(&mut self, end: WindowEnd) {
        self.windows += 1;
        match end {
            WindowEnd::Contact => self.contacts += 1,
            WindowEnd::MoveEnd => self.move_ends += 1,
            WindowEnd::Timeout => self.timeouts += 1,
        }
    }
}

/// Spins for the window announced at `seen` (when the estimator read it): `poll`
/// takes the next contact out of the subscriber; the first one goes to `on_contact`
/// and ends the window. `now` is the clock (a parameter for the tests).
pub fn watch<E>(
    window: ProbeWindow,
    seen: Instant,
    stats: &mut ArmedStats,
    mut poll: impl FnMut() -> Result<Option<ContactSample>, E>,
    mut now: impl FnMut() -> Instant,
    mut on_contact: impl FnMut(&ContactSample),
) -> Result<WindowEnd, E> {
    let move_end = seen + Duration::from_nanos(window.duration_ns());
    let timeout = seen + MAX_ARMED;
    let end = loop {
        if let Some(s) = poll()? {
            on_contact(&s);
            break WindowEnd::Contact;
        }
        let t = now();
        if t >= move_end.min(timeout) {
            break if move_end <= timeout {
                WindowEnd::MoveEnd
            } else {
                WindowEnd::Timeout
            };
        }
        core::hint::spin_loop();
    };
    stats.count(end);
    Ok(end)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::{Cell, RefCell};
    use std::collections::VecDeque;

    fn contact(sequence: u64) -> ContactSample {
        ContactSample {
            sequence,
            ..ContactSample::zeroed()
        }
    }

    const WINDOW: ProbeWindow = ProbeWindow {
        run_id: 1,
        start_ns: 1_000,
        end_ns: 1_000 + 5_000_000,
    };

    /// The subscriber as a queue, and a clock that steps 1 ms per reading; `arrive`
    /// puts a contact into the queue at the given clock reading.
    struct Rig {
        queue: RefCell<VecDeque<ContactSample>>,
        readings: Cell<u32>,
        start: Instant,
    }

    impl Rig {
        fn new() -> Self {
            Self {
                queue: RefCell::new(VecDeque::new()),
                readings: Cell::new(0),
                start: Instant::now(),
            }
        }

        fn poll(&self) -> Result<Option<ContactSample>, ()> {
            Ok(self.queue.borrow_mut().pop_front())
        }

        fn clock(&self, arrive: Option<(u32, ContactSample)>) -> Instant {
            let n = self.readings.get() + 1;
            self.readings.set(n);
            if let Some((at, s)) = arrive.filter(|(at, _)| *at == n) {
                let _ = at;
                self.queue.borrow_mut().push_back(s);
            }
            self.start + Duration::from_millis(n as u64)
        }

        /// The receive after the next wake-up: everything still in the subscriber.
        fn drain(&self, into: &mut Vec<u64>) {
            while let Ok(Some(s)) = self.poll() {
                into.push(s.sequence);
            }
        }
    }

    #[test]
    fn a_contact_during_the_window_ends_it_and_is_read_once() {
        let rig = Rig::new();
        let mut got = Vec::new();
        let mut stats = ArmedStats::default();
        let end = watch(
            WINDOW,
            rig.start,
            &mut stats,
            || rig.poll(),
            || rig.clock(Some((2, contact(7)))),
            |s| got.push(s.sequence),
        )
        .unwrap();
        assert_eq!(end, WindowEnd::Contact);
        rig.drain(&mut got);
        assert_eq!(got, [7]);
        assert_eq!((stats.windows, stats.contacts), (1, 1));
    }

    #[test]
    fn a_contact_arriving_as_the_window_ends_is_neither_lost_nor_read_twice() {
        // The clock reading that ends the window (5 ms: the move's end) is the moment
        // the contact lands in the subscriber: the spin has stopped polling.
        let rig = Rig::new();
        let mut got = Vec::new();
        let mut stats = ArmedStats::default();
        let end = watch(
            WINDOW,
            rig.start,
            &mut stats,
            || rig.poll(),
            || rig.clock(Some((5, contact(9)))),
            |s| got.push(s.sequence),
        )
        .unwrap();
        assert_eq!(end, WindowEnd::MoveEnd);
        assert!(got.is_empty(), "the spin did not take it");
        rig.drain(&mut got);
        assert_eq!(got, [9], "the next receive does, once");
        assert_eq!((stats.move_ends, stats.contacts), (1, 0));
    }

    #[test]
    fn a_window_longer_than_the_limit_times_out() {
        let rig = Rig::new();
        let long = ProbeWindow {
            end_ns: WINDOW.start_ns + 60_000_000_000,
            ..WINDOW
        };
        let mut stats = ArmedStats::default();
        let end = watch(
            long,
            rig.start,
            &mut stats,
            || rig.poll(),
            || rig.clock(None),
            |_| {},
        )
        .unwrap();
        assert_eq!(end, WindowEnd::Timeout);
        assert_eq!(rig.readings.get(), MAX_ARMED.as_millis() as u32);
    }

    #[test]
    fn auto_arms_only_with_a_cpu_to_spare_and_off_never() {
        assert!(ArmedReceive::Auto.enabled_with(2));
        assert!(!ArmedReceive::Auto.enabled_with(1));
        assert!(!ArmedReceive::Off.enabled_with(64));
    }
}
