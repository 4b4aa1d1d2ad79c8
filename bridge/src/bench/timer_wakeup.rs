//! The host's timer wake-up, in the trigger's regime: a thread at the real-time loop's
//! priority sleeps to a deadline and records how late it ran. On the in-process bus
//! the real-time thread waits for each frame's last bit the same way (a timed wait),
//! so this is the floor of the software path's first stage.

use std::sync::mpsc::{self, Receiver, Sender};
use std::time::Duration;

/// A thread that, per request, sleeps `sleep` and answers its lateness, ns.
pub struct TimerFloor {
    ask: Sender<Duration>,
    answer: Receiver<u64>,
    /// The thread runs under SCHED_FIFO.
    pub fifo: bool,
}

impl TimerFloor {
    /// Starts the thread under SCHED_FIFO at `priority` (0: ordinary), on `cpu` when
    /// given (the real-time loop's: the same regime).
    pub fn start(priority: i32, cpu: Option<usize>) -> Result<Self, String> {
        let (ask, asked) = mpsc::channel::<Duration>();
        let (answered, answer) = mpsc::channel::<u64>();
        let (ready_tx, ready) = mpsc::channel::<bool>();
        std::thread::Builder::new()
            .name("timer-floor".into())
            .spawn(move || {
                if let Some(c) = cpu {
                    hal::rt::pin_thread(&[c]);
                }
                let fifo = priority > 0 && hal::rt::set_fifo_priority(priority);
                if ready_tx.send(fifo).is_err() {
                    return;
                }
                for sleep in asked {
                    let deadline = hal::clock::monotonic_ns() + sleep.as_nanos() as u64;
                    std::thread::sleep(sleep);
                    let late = hal::clock::monotonic_ns().saturating_sub(deadline);
                    if answered.send(late).is_err() {
                        return;
                    }
                }
            })
            .map_err(|e| format!("timer floor thread: {e}"))?;
        let fifo = ready
            .recv()
            .map_err(|_| "timer floor thread did not start".to_string())?;
        Ok(Self { ask, answer, fifo })
    }

    /// One timed sleep of `sleep`: how late after its deadline the thread ran, ns.
    pub fn sample(&mut self, sleep: Duration) -> Option<u64> {
        self.ask.send(sleep).ok()?;
        self.answer.recv().ok()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_request_sleeps_at_least_its_time_and_reports_no_more_lateness_than_elapsed() {
        let mut t = TimerFloor::start(0, None).unwrap();
        let sleep = Duration::from_micros(300);
        for _ in 0..5 {
            let before = hal::clock::monotonic_ns();
            let late = t.sample(sleep).unwrap();
            let elapsed = hal::clock::monotonic_ns() - before;
            assert!(
                elapsed >= 300_000,
                "answered after {elapsed} ns, before the sleep ended"
            );
            assert!(
                late <= elapsed - 300_000,
                "late {late} ns of {elapsed} ns elapsed"
            );
        }
    }
}
