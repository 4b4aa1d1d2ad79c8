//! What the PLC face says about its connections, without flooding the journal: each
//! connection's lines at debug, refusals and accept errors at warn at most once per
//! [`WARN_EVERY`] (with the count held back), and a summary at info every
//! [`SUMMARY_EVERY`] in which anything happened. A peer's connect loop then costs a
//! few lines a minute, not a million, and journald's rate limit keeps the rest.

use std::time::{Duration, Instant};

pub const WARN_EVERY: Duration = Duration::from_secs(10);
pub const SUMMARY_EVERY: Duration = Duration::from_secs(60);

/// The things counted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Event {
    Accepted,
    Closed,
    /// Closed to make room for a new one (silent for the owner timeout).
    Evicted,
    /// Refused: `plc.max_connections` open, none silent long enough.
    RefusedFull,
    /// Refused: not in `plc.allow`.
    RefusedPeer,
    AcceptError,
}

const EVENTS: usize = 6;

fn index(e: Event) -> usize {
    e as usize
}

/// One warning kind: the first at once, then at most one per [`WARN_EVERY`].
#[derive(Debug, Default)]
struct Limiter {
    last: Option<Instant>,
    held: u64,
}

impl Limiter {
    /// `Some(n)`: log now, `n` more happened since the last line.
    fn pass(&mut self, now: Instant) -> Option<u64> {
        if self
            .last
            .is_some_and(|l| now.saturating_duration_since(l) < WARN_EVERY)
        {
            self.held += 1;
            return None;
        }
        self.last = Some(now);
        Some(std::mem::take(&mut self.held))
    }
}

#[derive(Debug)]
pub struct FaceLog {
    counts: [u64; EVENTS],
    limiters: [Limiter; EVENTS],
    since: Instant,
}

impl FaceLog {
    pub fn new(now: Instant) -> Self {
        Self {
            counts: [0; EVENTS],
            limiters: Default::default(),
            since: now,
        }
    }

    /// Counts `e`; for the warning kinds, whether to log it now and how many were held
    /// back since the last line.
    pub fn count(&mut self, e: Event, now: Instant) -> Option<u64> {
        self.counts[index(e)] += 1;
        self.limiters[index(e)].pass(now)
    }

    /// The summary line once per [`SUMMARY_EVERY`], if anything happened; the counts
    /// start again.
    pub fn summary(&mut self, now: Instant, open: usize, max: usize) -> Option<String> {
        if now.saturating_duration_since(self.since) < SUMMARY_EVERY {
            return None;
        }
        let c = std::mem::replace(&mut self.counts, [0; EVENTS]);
        let secs = now.saturating_duration_since(self.since).as_secs();
        self.since = now;
        if c.iter().all(|&n| n == 0) {
            return None;
        }
        let n = |e| c[index(e)];
        Some(format!(
            "PLC face, last {secs} s: {} connections, {} closed, {} closed for a new one, \
             {} refused at the limit of {max}, {} refused by plc.allow, {} accept errors; \
             {open} open",
            n(Event::Accepted),
            n(Event::Closed),
            n(Event::Evicted),
            n(Event::RefusedFull),
            n(Event::RefusedPeer),
            n(Event::AcceptError),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_flood_gives_one_warning_per_period_and_one_summary() {
        let t0 = Instant::now();
        let mut log = FaceLog::new(t0);
        let mut lines = Vec::new();
        // 10 000 refusals over 30 s.
        for i in 0..10_000u64 {
            let now = t0 + Duration::from_millis(i * 3);
            if let Some(held) = log.count(Event::RefusedPeer, now) {
                lines.push(held);
            }
            log.count(Event::Accepted, now);
        }
        assert_eq!(lines.len(), 3, "at 0, 10 and 20 s: {lines:?}");
        assert_eq!(lines[0], 0);
        assert!(lines[1] > 3000, "{lines:?}");
        assert_eq!(log.summary(t0 + Duration::from_secs(30), 1, 8), None);
        let s = log
            .summary(t0 + Duration::from_secs(60), 1, 8)
            .expect("a summary after 60 s");
        assert!(
            s.contains("10000 connections") && s.contains("10000 refused by plc.allow"),
            "{s}"
        );
        // Nothing happened since: no line.
        assert_eq!(log.summary(t0 + Duration::from_secs(120), 1, 8), None);
    }
}
