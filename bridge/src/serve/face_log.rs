//! What a face (the PLC face, the web face) says about its connections, without
//! flooding the journal: each connection's lines at debug, every line a peer can cause
//! (refusals, accept errors, a page that failed) at warn at most once per
//! [`WARN_EVERY`] per kind (with the count held back, [`Limiter`]), and a summary at
//! info every [`SUMMARY_EVERY`] in which anything happened. A peer's connect loop or
//! slowloris then costs a few lines a minute, not one per connection, and journald's
//! rate limit keeps the service's own lines.

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
    /// Refused: `plc.max_connections_per_peer` open from its address.
    RefusedPerPeer,
}

const EVENTS: usize = 7;

fn index(e: Event) -> usize {
    e as usize
}

/// One warning kind: the first at once, then at most one per [`WARN_EVERY`].
#[derive(Debug, Default)]
pub struct Limiter {
    last: Option<Instant>,
    held: u64,
}

impl Limiter {
    /// `Some(n)`: log now, `n` more happened since the last line.
    pub fn pass(&mut self, now: Instant) -> Option<u64> {
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
    /// The face's name, first in the summary ("PLC face", "web face").
    face: &'static str,
    counts: [u64; EVENTS],
    limiters: [Limiter; EVENTS],
    since: Instant,
}

impl FaceLog {
    /// The PLC face's (the name its summary has always had).
    pub fn new(now: Instant) -> Self {
        Self::named("PLC face", now)
    }

    /// For the face `face` ("web face"): its name first in the summary.
    pub fn named(face: &'static str, now: Instant) -> Self {
        Self {
            face,
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

    /// Logs the summary line at info, when [`FaceLog::summary`] has one.
    pub fn log_summary(&mut self, now: Instant, open: usize, max: usize) {
        if let Some(line) = self.summary(now, open, max) {
            tracing::info!("{line}");
        }
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
        let limit = format!("refused at the limit of {max}");
        let said: Vec<String> = [
            (Event::Accepted, "connections"),
            (Event::Closed, "closed"),
            (Event::Evicted, "closed for a new one"),
            (Event::RefusedFull, limit.as_str()),
            (Event::RefusedPerPeer, "refused at the limit per address"),
            (Event::RefusedPeer, "refused by plc.allow"),
            (Event::AcceptError, "accept errors"),
        ]
        .into_iter()
        .filter(|(e, _)| c[index(*e)] > 0)
        .map(|(e, what)| format!("{} {what}", c[index(e)]))
        .collect();
        Some(format!(
            "{}, last {secs} s: {}; {open} open",
            self.face,
            said.join(", ")
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_limiter_passes_one_line_per_period_and_counts_the_rest() {
        let t0 = Instant::now();
        let mut l = Limiter::default();
        assert_eq!(l.pass(t0), Some(0));
        // A slowloris' refusals, 3872 in 60 s: six lines, each with those held back.
        let passed: Vec<(u64, u64)> = (1..3872u64)
            .filter_map(|i| {
                let at = i * 60_000 / 3872;
                l.pass(t0 + Duration::from_millis(at))
                    .map(|held| (at, held))
            })
            .collect();
        assert_eq!(passed.len(), 5, "{passed:?}");
        assert!(passed.iter().all(|(_, held)| *held >= 600), "{passed:?}");
        let total: u64 = 1 + passed.len() as u64 + passed.iter().map(|(_, h)| h).sum::<u64>();
        assert!(total < 3872, "some still held: {total}");
    }

    #[test]
    fn the_web_face_summary_names_its_face_and_only_what_happened() {
        let t0 = Instant::now();
        let mut log = FaceLog::named("web face", t0);
        log.count(Event::Accepted, t0);
        log.count(Event::RefusedFull, t0);
        log.count(Event::RefusedFull, t0);
        let s = log.summary(t0 + SUMMARY_EVERY, 200, 200).unwrap();
        assert_eq!(
            s,
            "web face, last 60 s: 1 connections, 2 refused at the limit of 200; 200 open"
        );
    }

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
