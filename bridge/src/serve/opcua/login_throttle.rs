//! Failed logins slow the next ones: after [`FREE_FAILURES`] failed logins of a user
//! name, each further login of that name is answered no sooner than a delay after the
//! last, doubling from [`FIRST_DELAY`] to [`MAX_DELAY`]; a success or
//! [`FORGET_AFTER`] without failures starts again. Unknown names share one account, so
//! guessing names gains nothing. At most one guess per [`MAX_DELAY`] and name is left.
//!
//! Keyed by user name, not by the client's address: async-opcua's authenticator is not
//! told the connection a token came on. A guesser thus also delays the user whose name
//! it guesses, by at most [`MAX_DELAY`] a login.
//!
//! The failures are logged as a summary at most once per [`SUMMARY_EVERY`] (the first
//! at once), never a line per guess.

use std::collections::BTreeMap;
use std::sync::Mutex;
use std::time::{Duration, Instant};

pub const FREE_FAILURES: u32 = 3;
pub const FIRST_DELAY: Duration = Duration::from_secs(1);
pub const MAX_DELAY: Duration = Duration::from_secs(60);
pub const FORGET_AFTER: Duration = Duration::from_secs(15 * 60);
pub const SUMMARY_EVERY: Duration = Duration::from_secs(60);
/// The account unknown user names share.
const UNKNOWN: &str = "(unknown user names)";

#[derive(Debug)]
struct Account {
    failures: u32,
    last_failure: Instant,
    /// The next login of this name is answered no sooner.
    next: Instant,
}

#[derive(Debug, Default)]
struct Summary {
    /// Failed logins per account since the last line.
    failed: BTreeMap<String, u64>,
    last_line: Option<Instant>,
}

#[derive(Debug, Default)]
pub struct LoginThrottle {
    accounts: Mutex<BTreeMap<String, Account>>,
    summary: Mutex<Summary>,
}

fn delay(failures: u32) -> Duration {
    match failures.checked_sub(FREE_FAILURES) {
        None => Duration::ZERO,
        Some(n) => FIRST_DELAY.saturating_mul(1u32 << n.min(16)).min(MAX_DELAY),
    }
}

fn locked<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

impl LoginThrottle {
    /// The account a login counts on: the user's name, or the one of unknown names.
    pub fn account(name: &str, known: bool) -> String {
        if known {
            name.to_string()
        } else {
            UNKNOWN.to_string()
        }
    }

    /// How long the login of `account` arriving at `now` waits before it is checked.
    /// It takes its turn: a login arriving meanwhile waits a delay longer.
    pub fn wait(&self, account: &str, now: Instant) -> Duration {
        let mut accounts = locked(&self.accounts);
        let Some(a) = accounts.get_mut(account) else {
            return Duration::ZERO;
        };
        if now.saturating_duration_since(a.last_failure) > FORGET_AFTER {
            accounts.remove(account);
            return Duration::ZERO;
        }
        let d = delay(a.failures);
        if d.is_zero() {
            return d;
        }
        let at = a.next.max(now);
        a.next = at + d;
        at - now
    }

    /// The login's result: a success forgets the account's failures.
    pub fn record(&self, account: &str, ok: bool, now: Instant) {
        let mut accounts = locked(&self.accounts);
        if ok {
            accounts.remove(account);
            return;
        }
        let a = accounts.entry(account.to_string()).or_insert(Account {
            failures: 0,
            last_failure: now,
            next: now,
        });
        a.failures = a.failures.saturating_add(1);
        a.last_failure = now;
        a.next = a.next.max(now + delay(a.failures));
        drop(accounts);
        *locked(&self.summary)
            .failed
            .entry(account.to_string())
            .or_default() += 1;
    }

    /// The summary's line, when one is due: the first failure at once, then at most
    /// one per [`SUMMARY_EVERY`] (called on each failure and periodically).
    pub fn summary(&self, now: Instant) -> Option<String> {
        let mut s = locked(&self.summary);
        if s.failed.is_empty()
            || s.last_line
                .is_some_and(|l| now.saturating_duration_since(l) < SUMMARY_EVERY)
        {
            return None;
        }
        let since = s.last_line.map(|l| now.saturating_duration_since(l));
        s.last_line = Some(now);
        let failed = std::mem::take(&mut s.failed);
        drop(s);
        let accounts = locked(&self.accounts);
        let each: Vec<String> = failed
            .iter()
            .map(|(name, n)| {
                let wait = accounts
                    .get(name)
                    .map_or(Duration::ZERO, |a| a.next.saturating_duration_since(now));
                format!("{name}: {n} (next login waits {} s)", wait.as_secs())
            })
            .collect();
        let total: u64 = failed.values().sum();
        Some(match since {
            Some(d) => format!(
                "OPC UA face: {total} failed logins (unknown user or wrong password) in the \
                 last {} s: {}",
                d.as_secs(),
                each.join(", ")
            ),
            None => format!(
                "OPC UA face: failed login (unknown user or wrong password): {}; further \
                 ones are summed up at most once a minute",
                each.join(", ")
            ),
        })
    }
}

/// Drops the OPC UA stack's own line per refused login (it logs every error it turns
/// into a status, as `opcua_types::encoding`): the summary above says them.
pub struct StackLoginLines;

impl<S: tracing::Subscriber> tracing_subscriber::Layer<S> for StackLoginLines {
    fn event_enabled(
        &self,
        event: &tracing::Event<'_>,
        _: tracing_subscriber::layer::Context<'_, S>,
    ) -> bool {
        if event.metadata().target() != "opcua_types::encoding" {
            return true;
        }
        let mut refused = RefusedLogin(false);
        event.record(&mut refused);
        !refused.0
    }
}

struct RefusedLogin(bool);

impl tracing::field::Visit for RefusedLogin {
    fn record_debug(&mut self, field: &tracing::field::Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            self.0 = format!("{value:?}").starts_with("BadIdentityTokenRejected");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn failures_beyond_the_free_ones_double_the_wait_up_to_the_cap() {
        let t = LoginThrottle::default();
        let mut now = Instant::now();
        let mut waits = Vec::new();
        for _ in 0..12 {
            let w = t.wait("mes", now);
            waits.push(w.as_secs());
            now += w;
            t.record("mes", false, now);
        }
        assert_eq!(waits, [0, 0, 0, 1, 2, 4, 8, 16, 32, 60, 60, 60]);
        // Another name is not slowed; a success forgets.
        assert_eq!(t.wait("other", now), Duration::ZERO);
        t.record("mes", true, now);
        assert_eq!(t.wait("mes", now), Duration::ZERO);
    }

    #[test]
    fn parallel_logins_take_turns_and_quiet_forgets() {
        let t = LoginThrottle::default();
        let now = Instant::now();
        for _ in 0..4 {
            t.record("mes", false, now);
        }
        // 4 failures: 2 s each, one after the other.
        let waits: Vec<u64> = (0..3).map(|_| t.wait("mes", now).as_secs()).collect();
        assert_eq!(waits, [2, 4, 6]);
        assert_eq!(
            t.wait("mes", now + FORGET_AFTER + Duration::from_secs(1)),
            Duration::ZERO
        );
    }

    #[test]
    fn a_flood_of_guesses_is_one_line_per_minute() {
        let t = LoginThrottle::default();
        let t0 = Instant::now();
        let mut lines = Vec::new();
        for i in 0..1000u64 {
            let now = t0 + Duration::from_millis(i * 100);
            let name = LoginThrottle::account(&format!("guess{i}"), i % 2 == 0);
            t.record(&name, false, now);
            lines.extend(t.summary(now));
        }
        // 100 s of guesses: the first at once, one after a minute.
        assert_eq!(lines.len(), 2, "{lines:?}");
        assert!(lines[1].contains("failed logins"), "{}", lines[1]);
        assert!(lines[1].contains(UNKNOWN), "{}", lines[1]);
        let rest = t.summary(t0 + Duration::from_secs(200)).unwrap();
        assert!(rest.contains("failed logins"), "{rest}");
        assert_eq!(t.summary(t0 + Duration::from_secs(400)), None);
    }
}
