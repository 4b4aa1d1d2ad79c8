//! A seeded fault layer around any [`CanTransport`] (the in-process bus, SocketCAN, a
//! recorder): it drops, duplicates, delays or reorders frames at given rates, and can
//! fail the transport for a while (a bus-off), so tests see how the master copes with
//! an unreliable bus.
//!
//! Deterministic: every frame the layer judges takes the next draws of one generator
//! seeded from [`BusFaults::seed`], so the same traffic meets the same faults. Delays
//! are counted in frames, not time: a delayed frame is passed on after the next 1 to
//! `max_delay_frames` frames of its direction (a reorder is a delay of one frame), or
//! as soon as the traffic pauses (the sender listens, or a receive would time out).
//! That keeps delays within the burst of one SYNC period, as on a real bus, whether
//! the loop runs in real time or in lockstep. Holding frames costs no allocation.

use super::{CanFrame, CanTransport, TransportError, TransportErrorKind};
use crate::clock::monotonic_ns;
use core::ops::RangeInclusive;
use core::time::Duration;
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

/// How often each fault happens to a frame, as probabilities (0.01 = 1 %).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FaultRates {
    pub drop: f64,
    pub duplicate: f64,
    /// Held back by 1 to [`BusFaults::max_delay_frames`] frames.
    pub delay: f64,
    /// Swapped with the frame after it.
    pub reorder: f64,
}

impl FaultRates {
    /// Frames lost at `rate`, nothing else.
    pub const fn loss(rate: f64) -> Self {
        Self {
            drop: rate,
            duplicate: 0.0,
            delay: 0.0,
            reorder: 0.0,
        }
    }

    fn total(&self) -> f64 {
        self.drop + self.duplicate + self.delay + self.reorder
    }
}

/// What the layer does to the frames of one node.
#[derive(Clone, Debug, PartialEq)]
pub struct BusFaults {
    pub seed: u64,
    /// Frames this node sends.
    pub transmit: FaultRates,
    /// Frames this node receives.
    pub receive: FaultRates,
    /// Longest delay, in frames of the same direction (at least 1).
    pub max_delay_frames: u8,
    /// Only frames with these identifiers are judged (default: all).
    pub cob_ids: RangeInclusive<u16>,
}

impl BusFaults {
    /// No faults (yet): set the rates you want.
    pub fn new(seed: u64) -> Self {
        Self {
            seed,
            transmit: FaultRates::default(),
            receive: FaultRates::default(),
            max_delay_frames: 3,
            cob_ids: 0..=0x7FF,
        }
    }

    /// The same rates in both directions.
    pub fn both(seed: u64, rates: FaultRates) -> Self {
        Self {
            transmit: rates,
            receive: rates,
            ..Self::new(seed)
        }
    }

    /// Checks the rates: each in 0..=1, their sum at most 1, per direction.
    pub fn validate(&self) -> Result<(), String> {
        for (dir, r) in [("transmit", &self.transmit), ("receive", &self.receive)] {
            for (name, v) in [
                ("drop", r.drop),
                ("duplicate", r.duplicate),
                ("delay", r.delay),
                ("reorder", r.reorder),
            ] {
                if !(0.0..=1.0).contains(&v) {
                    return Err(format!("{dir} {name} rate {v} is not within 0..=1"));
                }
            }
            if r.total() > 1.0 + 1e-12 {
                return Err(format!("{dir} rates add up to {} (more than 1)", r.total()));
            }
        }
        if self.max_delay_frames == 0 {
            return Err("max_delay_frames must be at least 1".into());
        }
        Ok(())
    }

    /// Parses `drop=0.01,duplicate=0.001,delay=0,reorder=0,seed=7` (any subset, in
    /// any order; rates apply to both directions; `tx-`/`rx-` prefixes set one
    /// direction only, e.g. `rx-duplicate=1`).
    pub fn parse(text: &str) -> Result<Self, String> {
        let mut f = Self::new(1);
        for item in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (key, value) = item
                .split_once('=')
                .ok_or_else(|| format!("{item:?}: expected KEY=VALUE"))?;
            let key = key.trim();
            let value = value.trim();
            let number = || -> Result<f64, String> {
                value
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| format!("{key}: {value:?} is not a number"))
            };
            match key {
                "seed" => {
                    f.seed = value
                        .parse()
                        .map_err(|_| format!("seed: {value:?} is not a whole number"))?
                }
                "max_delay_frames" => {
                    f.max_delay_frames = value
                        .parse()
                        .map_err(|_| format!("max_delay_frames: {value:?} is not 1..=255"))?
                }
                _ => {
                    let (dirs, name): (&[bool], &str) = if let Some(n) = key.strip_prefix("tx-") {
                        (&[true], n)
                    } else if let Some(n) = key.strip_prefix("rx-") {
                        (&[false], n)
                    } else {
                        (&[true, false], key)
                    };
                    let v = number()?;
                    for &tx in dirs {
                        let r = if tx { &mut f.transmit } else { &mut f.receive };
                        match name {
                            "drop" => r.drop = v,
                            "duplicate" => r.duplicate = v,
                            "delay" => r.delay = v,
                            "reorder" => r.reorder = v,
                            _ => return Err(format!(
                                "{key:?}: unknown; use drop, duplicate, delay, reorder (optionally tx-/rx-), seed, max_delay_frames"
                            )),
                        }
                    }
                }
            }
        }
        f.validate()?;
        Ok(f)
    }
}

/// How many frames met which fault (shared with [`FaultControl`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FaultCounts {
    pub transmitted: u64,
    pub received: u64,
    pub dropped: u64,
    pub duplicated: u64,
    pub delayed: u64,
    pub reordered: u64,
    /// Calls failed by an injected outage.
    pub failed_calls: u64,
}

#[derive(Clone, Copy, Debug)]
struct Outage {
    /// The outage starts once this many frames were transmitted.
    after_transmits: u64,
    /// How many transmit/receive calls fail (`u64::MAX`: for good).
    calls: u64,
    kind: TransportErrorKind,
}

#[derive(Default)]
struct Shared {
    transmitted: AtomicU64,
    received: AtomicU64,
    dropped: AtomicU64,
    duplicated: AtomicU64,
    delayed: AtomicU64,
    reordered: AtomicU64,
    failed_calls: AtomicU64,
    outage: Mutex<Option<Outage>>,
}

/// A handle on a [`FaultyTransport`] from another thread: counters, and a transport
/// failure to inject.
#[derive(Clone)]
pub struct FaultControl(Arc<Shared>);

impl FaultControl {
    pub fn counts(&self) -> FaultCounts {
        let s = &self.0;
        FaultCounts {
            transmitted: s.transmitted.load(Ordering::Relaxed),
            received: s.received.load(Ordering::Relaxed),
            dropped: s.dropped.load(Ordering::Relaxed),
            duplicated: s.duplicated.load(Ordering::Relaxed),
            delayed: s.delayed.load(Ordering::Relaxed),
            reordered: s.reordered.load(Ordering::Relaxed),
            failed_calls: s.failed_calls.load(Ordering::Relaxed),
        }
    }

    /// Once `after_transmits` frames in all were transmitted, the next `calls` calls of
    /// transmit or receive fail with `kind` (`u64::MAX`: the transport stays failed),
    /// as a bus-off or an unplugged cable would.
    pub fn fail_after(&self, after_transmits: u64, calls: u64, kind: TransportErrorKind) {
        *self.0.outage.lock().unwrap_or_else(|e| e.into_inner()) = Some(Outage {
            after_transmits,
            calls,
            kind,
        });
    }
}

/// Frames held back in one direction: (frames still to pass before it goes, frame).
const HELD: usize = 32;
type Held = heapless::Vec<(u8, CanFrame), HELD>;

enum Verdict {
    Pass,
    Drop,
    Duplicate,
    Hold(u8),
}

/// Wraps a transport and injects the faults of a [`BusFaults`].
pub struct FaultyTransport<T> {
    inner: T,
    faults: BusFaults,
    rng: SmallRng,
    shared: Arc<Shared>,
    tx_held: Held,
    rx_held: Held,
    /// Received frames due before anything new (duplicates, released holds).
    rx_ready: heapless::Deque<CanFrame, HELD>,
}

impl<T: CanTransport> FaultyTransport<T> {
    /// `faults` must be valid (see [`BusFaults::validate`]); invalid rates are clamped.
    pub fn new(inner: T, faults: BusFaults) -> Self {
        Self {
            inner,
            rng: SmallRng::seed_from_u64(faults.seed),
            faults,
            shared: Arc::new(Shared::default()),
            tx_held: Held::new(),
            rx_held: Held::new(),
            rx_ready: heapless::Deque::new(),
        }
    }

    pub fn control(&self) -> FaultControl {
        FaultControl(self.shared.clone())
    }

    pub fn inner_mut(&mut self) -> &mut T {
        &mut self.inner
    }

    fn judge(&mut self, f: &CanFrame, transmit: bool) -> Verdict {
        if !self.faults.cob_ids.contains(&f.cob_id()) {
            return Verdict::Pass;
        }
        let r = if transmit {
            self.faults.transmit
        } else {
            self.faults.receive
        };
        let x: f64 = self.rng.random();
        let s = &self.shared;
        if x < r.drop {
            s.dropped.fetch_add(1, Ordering::Relaxed);
            return Verdict::Drop;
        }
        if x < r.drop + r.duplicate {
            s.duplicated.fetch_add(1, Ordering::Relaxed);
            return Verdict::Duplicate;
        }
        if x < r.drop + r.duplicate + r.delay {
            s.delayed.fetch_add(1, Ordering::Relaxed);
            let n = self
                .rng
                .random_range(1..=self.faults.max_delay_frames.max(1));
            return Verdict::Hold(n);
        }
        if x < r.total() {
            s.reordered.fetch_add(1, Ordering::Relaxed);
            return Verdict::Hold(1);
        }
        Verdict::Pass
    }

    /// An injected outage, when one is due.
    fn outage(&self) -> Result<(), TransportError> {
        let mut o = self.shared.outage.lock().unwrap_or_else(|e| e.into_inner());
        let Some(out) = o.as_mut() else {
            return Ok(());
        };
        if self.shared.transmitted.load(Ordering::Relaxed) < out.after_transmits {
            return Ok(());
        }
        if out.calls == 0 {
            *o = None;
            return Ok(());
        }
        if out.calls != u64::MAX {
            out.calls -= 1;
        }
        self.shared.failed_calls.fetch_add(1, Ordering::Relaxed);
        Err(TransportError::new(
            out.kind,
            "injected by the fault layer (a bus-off, as if the cable were pulled)",
        ))
    }

    /// Counts one frame passing in a direction: held frames whose count is used up
    /// are returned into `due` (in the order they were held).
    fn age(held: &mut Held, due: &mut Held) {
        let mut i = 0;
        while i < held.len() {
            held[i].0 = held[i].0.saturating_sub(1);
            if held[i].0 == 0 {
                let _ = due.push(held.remove(i));
            } else {
                i += 1;
            }
        }
    }

    fn send(&mut self, f: &CanFrame) -> Result<(), TransportError> {
        self.inner.transmit(f)?;
        self.shared.transmitted.fetch_add(1, Ordering::Relaxed);
        let mut due = Held::new();
        Self::age(&mut self.tx_held, &mut due);
        for (_, d) in &due {
            self.inner.transmit(d)?;
        }
        Ok(())
    }

    /// The sender pauses (it listens now): whatever it held back goes out.
    fn flush_transmit(&mut self) -> Result<(), TransportError> {
        while !self.tx_held.is_empty() {
            let (_, f) = self.tx_held.remove(0);
            self.inner.transmit(&f)?;
        }
        Ok(())
    }

    /// A frame arrives from the bus: passed on, or held, duplicated or lost.
    fn arrive(&mut self, f: CanFrame) {
        match self.judge(&f, false) {
            Verdict::Drop => {}
            Verdict::Pass | Verdict::Duplicate | Verdict::Hold(_) if self.rx_held.is_full() => {
                let _ = self.rx_ready.push_back(f);
            }
            Verdict::Pass => self.deliver(f),
            Verdict::Duplicate => {
                self.deliver(f);
                let _ = self.rx_ready.push_back(f);
            }
            Verdict::Hold(n) => {
                let _ = self.rx_held.push((n, f));
            }
        }
    }

    fn deliver(&mut self, f: CanFrame) {
        let _ = self.rx_ready.push_back(f);
        let mut due = Held::new();
        Self::age(&mut self.rx_held, &mut due);
        for (_, d) in due {
            let _ = self.rx_ready.push_back(d);
        }
    }
}

impl<T: CanTransport> CanTransport for FaultyTransport<T> {
    fn transmit(&mut self, frame: &CanFrame) -> Result<(), TransportError> {
        self.outage()?;
        match self.judge(frame, true) {
            Verdict::Drop => Ok(()),
            Verdict::Pass => self.send(frame),
            Verdict::Duplicate => {
                self.send(frame)?;
                self.send(frame)
            }
            Verdict::Hold(n) => {
                if self.tx_held.push((n, *frame)).is_err() {
                    return self.send(frame);
                }
                Ok(())
            }
        }
    }

    fn receive(&mut self, timeout: Duration) -> Result<Option<CanFrame>, TransportError> {
        self.outage()?;
        self.flush_transmit()?;
        let deadline = monotonic_ns().saturating_add(timeout.as_nanos() as u64);
        loop {
            if let Some(f) = self.rx_ready.pop_front() {
                self.shared.received.fetch_add(1, Ordering::Relaxed);
                return Ok(Some(f));
            }
            let left = deadline.saturating_sub(monotonic_ns());
            // Nothing new in the wait: the traffic paused, held frames are released.
            let wait = if self.rx_held.is_empty() {
                Duration::from_nanos(left)
            } else {
                Duration::ZERO
            };
            match self.inner.receive(wait)? {
                Some(f) => self.arrive(f),
                None if !self.rx_held.is_empty() => {
                    let (_, f) = self.rx_held.remove(0);
                    let _ = self.rx_ready.push_back(f);
                }
                None if left == 0 => return Ok(None),
                None => {}
            }
        }
    }

    // The clock belongs to the wrapped bus: a faulty link is still on its time. A
    // frame held back and released later reports the inner bus's latest arrival,
    // which is when it was let through.
    fn arrival_ns(&self) -> Option<u64> {
        self.inner.arrival_ns()
    }

    fn virtual_now_ns(&self) -> Option<u64> {
        self.inner.virtual_now_ns()
    }

    fn advance_virtual_clock(&mut self, now_ns: u64) {
        self.inner.advance_virtual_clock(now_ns)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::inproc::InprocBus;

    fn frames(n: u16) -> Vec<CanFrame> {
        (0..n)
            .map(|i| CanFrame::new(0x181 + (i % 5), &i.to_le_bytes()).unwrap())
            .collect()
    }

    /// Sends `n` frames through a faulty sender and returns what arrived.
    fn through(faults: BusFaults, n: u16) -> (Vec<CanFrame>, FaultCounts) {
        let bus = InprocBus::new();
        let mut tx = FaultyTransport::new(bus.endpoint(), faults);
        let control = tx.control();
        let mut rx = bus.endpoint();
        for f in frames(n) {
            tx.transmit(&f).unwrap();
        }
        tx.receive(Duration::ZERO).unwrap();
        let mut got = Vec::new();
        while let Some(f) = rx.receive(Duration::ZERO).unwrap() {
            got.push(f);
        }
        (got, control.counts())
    }

    #[test]
    fn the_same_seed_gives_the_same_faults_and_another_seed_other_ones() {
        let rates = FaultRates {
            drop: 0.05,
            duplicate: 0.05,
            delay: 0.05,
            reorder: 0.05,
        };
        let a = through(BusFaults::both(7, rates), 2000);
        let b = through(BusFaults::both(7, rates), 2000);
        let c = through(BusFaults::both(8, rates), 2000);
        assert_eq!(a, b);
        assert_ne!(a.0, c.0);
        let n = a.1;
        // Each fault near its rate of 2000 frames (5 % = 100; binomial sd = 10).
        for (name, k) in [
            ("dropped", n.dropped),
            ("duplicated", n.duplicated),
            ("delayed", n.delayed),
            ("reordered", n.reordered),
        ] {
            assert!((60..=140).contains(&k), "{name}: {k} of 2000");
        }
        assert_eq!(a.0.len() as u64, 2000 - n.dropped + n.duplicated);
    }

    #[test]
    fn drops_lose_frames_and_keep_the_order_of_the_rest() {
        let (got, n) = through(BusFaults::both(3, FaultRates::loss(0.1)), 1000);
        assert!(n.dropped > 50, "{n:?}");
        assert_eq!(got.len() as u64, 1000 - n.dropped);
        let seq: Vec<u16> = got
            .iter()
            .map(|f| u16::from_le_bytes([f.data()[0], f.data()[1]]))
            .collect();
        assert!(seq.windows(2).all(|w| w[0] < w[1]), "order kept");
    }

    #[test]
    fn a_delayed_frame_comes_within_its_frame_budget_and_none_is_lost() {
        let mut faults = BusFaults::new(11);
        faults.transmit.delay = 0.2;
        faults.max_delay_frames = 3;
        let (got, n) = through(faults, 500);
        assert!(n.delayed > 50, "{n:?}");
        assert_eq!(got.len(), 500);
        let mut late = 0;
        for (pos, f) in got.iter().enumerate() {
            let i = u16::from_le_bytes([f.data()[0], f.data()[1]]) as usize;
            // Later by 3 frames that went out, and by the frames held meanwhile.
            assert!(pos <= i + 8, "frame {i} arrived as {pos}");
            late += usize::from(pos > i);
        }
        assert!(late > 50, "{late} frames arrived late");
        let mut sorted: Vec<_> = got.iter().map(|f| f.data().to_vec()).collect();
        sorted.sort();
        sorted.dedup();
        assert_eq!(sorted.len(), 500, "each frame exactly once");
    }

    #[test]
    fn received_duplicates_and_reorders_reach_the_reader() {
        let bus = InprocBus::new();
        let mut tx = bus.endpoint();
        let mut faults = BusFaults::new(5);
        faults.receive.duplicate = 1.0;
        faults.cob_ids = 0x281..=0x2FF;
        let mut rx = FaultyTransport::new(bus.endpoint(), faults);
        tx.transmit(&CanFrame::new(0x181, &[1]).unwrap()).unwrap();
        tx.transmit(&CanFrame::new(0x281, &[2]).unwrap()).unwrap();
        let mut got = Vec::new();
        while let Some(f) = rx.receive(Duration::ZERO).unwrap() {
            got.push(f.cob_id());
        }
        // Only the filtered identifier is doubled.
        assert_eq!(got, [0x181, 0x281, 0x281]);

        let mut faults = BusFaults::new(5);
        faults.receive.reorder = 0.3;
        let mut rx = FaultyTransport::new(bus.endpoint(), faults);
        for i in 0..40u8 {
            tx.transmit(&CanFrame::new(0x181, &[i]).unwrap()).unwrap();
        }
        let mut got = Vec::new();
        while let Some(f) = rx.receive(Duration::ZERO).unwrap() {
            got.push(f.data()[0]);
        }
        assert_eq!(got.len(), 40);
        assert!(got.windows(2).any(|w| w[0] > w[1]), "reordered: {got:?}");
        got.sort_unstable();
        assert_eq!(got, (0..40).collect::<Vec<u8>>(), "each frame once");
    }

    #[test]
    fn an_injected_outage_fails_calls_then_the_transport_recovers() {
        let bus = InprocBus::new();
        let mut t = FaultyTransport::new(bus.endpoint(), BusFaults::new(1));
        let control = t.control();
        control.fail_after(2, 3, TransportErrorKind::BusOff);
        let f = CanFrame::new(0x80, &[]).unwrap();
        t.transmit(&f).unwrap();
        t.transmit(&f).unwrap();
        for _ in 0..3 {
            assert_eq!(t.transmit(&f).unwrap_err().kind, TransportErrorKind::BusOff);
        }
        t.transmit(&f).unwrap();
        assert_eq!(control.counts().failed_calls, 3);
        assert_eq!(control.counts().transmitted, 3);
    }

    #[test]
    fn the_text_form_is_parsed_and_bad_rates_are_refused() {
        let f = BusFaults::parse("drop=0.01, seed=42, rx-duplicate=0.5").unwrap();
        assert_eq!(f.seed, 42);
        assert_eq!(f.transmit, FaultRates::loss(0.01));
        assert_eq!(f.receive.duplicate, 0.5);
        for (bad, why) in [
            ("drop=2", "not within 0..=1"),
            ("drop=0.7,duplicate=0.7", "add up to"),
            ("lose=0.1", "unknown"),
            ("drop", "KEY=VALUE"),
            ("drop=NaN", "not a number"),
            ("max_delay_frames=0", "at least 1"),
        ] {
            let e = BusFaults::parse(bad).unwrap_err();
            assert!(e.contains(why), "{bad}: {e}");
        }
    }
}
