//! The machine as the gateway holds it: up (a session whose health is asked between
//! measurements) or down (closed, and opened again with a growing wait between
//! attempts). The PLC's "machine ok" bit follows it, and a start while it is down is
//! refused with the reason "machine not ok".

use super::gateway::{lock, Shared};
use crate::session::options::MachineOptions;
use crate::session::Session;
use std::time::{Duration, Instant};

/// The wait before the first reopen attempt; doubled after every failed one.
const RECONNECT_FIRST: Duration = Duration::from_millis(500);
/// The longest wait between two reopen attempts.
const RECONNECT_MAX: Duration = Duration::from_secs(10);

pub enum MachineLink {
    Up(Box<Session>),
    Down(Reconnect),
}

pub struct Reconnect {
    attempt: u32,
    next: Instant,
    wait: Duration,
}

impl MachineLink {
    pub fn session(&mut self) -> Option<&mut Session> {
        match self {
            MachineLink::Up(s) => Some(s),
            MachineLink::Down(_) => None,
        }
    }

    /// Up: asks the machine's health; a failure closes the session (the drives are
    /// disabled, a simulator stops) and clears "machine ok". Down: opens the machine
    /// again once the wait has passed (the CANopen start-up runs again, a Modbus
    /// connection is made again), and sets "machine ok" when it comes up.
    pub fn supervise(&mut self, shared: &Shared, opts: &MachineOptions) {
        match self {
            MachineLink::Up(session) => {
                if let Err(e) = session.machine.health() {
                    tracing::error!(kind = ?e.kind, "machine not ok: {e}; closing it to open it again");
                    lock(shared).service.set_machine_ok(false);
                    *self = MachineLink::Down(Reconnect {
                        attempt: 0,
                        next: Instant::now(),
                        wait: RECONNECT_FIRST,
                    });
                }
            }
            MachineLink::Down(r) => {
                let now = Instant::now();
                if now < r.next {
                    return;
                }
                r.attempt += 1;
                tracing::info!(attempt = r.attempt, "opening the machine again");
                match Session::open(opts) {
                    Ok(s) => {
                        for n in &s.notes {
                            tracing::info!("{n}");
                        }
                        tracing::info!(attempt = r.attempt, "machine ok again");
                        lock(shared).service.set_machine_ok(true);
                        *self = MachineLink::Up(Box::new(s));
                    }
                    Err(e) => {
                        tracing::warn!(
                            attempt = r.attempt,
                            retry_in_ms = r.wait.as_millis() as u64,
                            "cannot open the machine: {e}"
                        );
                        r.next = now + r.wait;
                        r.wait = (r.wait * 2).min(RECONNECT_MAX);
                    }
                }
            }
        }
    }
}
