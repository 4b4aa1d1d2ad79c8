//! A master that dies without its orderly shutdown (a killed process: no Shutdown
//! controlword, no goodbye) is noticed by the simulated drives through the heartbeat
//! they consume (0x1016): each sends EMCY 8130 and leaves Operation enabled. In
//! process, on the in-process bus, the drives on the wall clock as `probebridge sim`
//! runs them; the VM step does the same with a SIGKILLed `probebridge run` on vcan0.

use hal::can::inproc::InprocBus;
use hal::can::{CanFrame, CanTransport, TransportError};
use hal::canopen::cob_id::{classify, CobKind};
use hal::canopen::emcy::{code, Emcy};
use hal::clock::monotonic_ns;
use hal::master::command::Reply;
use hal::master::{startup, LoopConfig, PacedLoop, Pacing};
use hal::NullSink;
use probebridge_tests::{machine_config, scenario};
use sim::machine::{SimClock, SimMachine, SimRunner};
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// The master's transport, noting when its last heartbeat went out.
struct Spy<T> {
    inner: T,
    heartbeat_cob: u16,
    last_heartbeat_ns: Arc<AtomicU64>,
}

impl<T: CanTransport> CanTransport for Spy<T> {
    fn transmit(&mut self, frame: &CanFrame) -> Result<(), TransportError> {
        self.inner.transmit(frame)?;
        if frame.cob_id() == self.heartbeat_cob {
            self.last_heartbeat_ns
                .store(monotonic_ns(), Ordering::Release);
        }
        Ok(())
    }

    fn receive(&mut self, timeout: Duration) -> Result<Option<CanFrame>, TransportError> {
        self.inner.receive(timeout)
    }
}

/// 0x6041 of `node`, uploaded by SDO.
fn statusword<T: CanTransport>(t: &mut T, node: u8) -> u16 {
    let rq = CanFrame::new(0x600 + u16::from(node), &[0x40, 0x41, 0x60, 0, 0, 0, 0, 0]).unwrap();
    t.transmit(&rq).unwrap();
    loop {
        let f = t
            .receive(Duration::from_secs(2))
            .unwrap()
            .unwrap_or_else(|| panic!("node {node}: no answer to the 0x6041 upload"));
        if f.cob_id() == 0x580 + u16::from(node) {
            let d = f.data();
            assert_eq!(&d[..4], &[0x4B, 0x41, 0x60, 0], "node {node}: {f:?}");
            return u16::from_le_bytes([d[4], d[5]]);
        }
    }
}

#[test]
fn a_master_gone_without_shutdown_is_noticed_by_every_drive_which_stops() {
    let sc = scenario(
        "machine = \"table-ac\"\n[probe]\nball_radius = 3.0\n[[plane]]\npoint = [0.0, 0.0, -150.0]\nnormal = [0.0, 0.0, 1.0]\n",
    );
    let cfg = machine_config(&sc);
    let bus_cfg = cfg.canopen_bus().unwrap().clone();
    let consumer_ms = bus_cfg.master_heartbeat_consumer_ms();
    assert!(
        consumer_ms > 0,
        "the shipped machine has a master heartbeat"
    );
    // The axes' drives and the spindle's: every drive watches the master.
    let nodes: Vec<u8> = cfg
        .axes
        .iter()
        .map(|a| a.canopen_node())
        .chain(cfg.spindle.as_ref().map(|s| s.node))
        .collect();

    let bus = InprocBus::new();
    let mut drives = SimMachine::new(&sc);
    drives.set_clock(SimClock::Monotonic);
    let sim = SimRunner::spawn(drives, bus.endpoint());
    let last_heartbeat_ns = Arc::new(AtomicU64::new(0));
    let mut t = Spy {
        inner: bus.endpoint(),
        heartbeat_cob: 0x700 + u16::from(bus_cfg.master_node),
        last_heartbeat_ns: last_heartbeat_ns.clone(),
    };
    startup::boot(&mut t, &cfg).unwrap();
    startup::configure(&mut t, &cfg).unwrap();
    let mut rt = PacedLoop::new(
        &cfg,
        LoopConfig::from_machine(&cfg, Pacing::RealTime),
        t,
        NullSink,
    );
    let ready = loop {
        rt.cycle().unwrap();
        if let Some(r) = rt.take_reply() {
            break r;
        }
    };
    assert!(matches!(ready, Reply::Ready { .. }), "{ready:?}");
    // Enabled and holding for a few of the master's heartbeat periods.
    let until = monotonic_ns() + 3 * u64::from(bus_cfg.master_heartbeat_ms) * 1_000_000;
    while monotonic_ns() < until {
        rt.cycle().unwrap();
    }
    // The master dies: from here on it sends nothing, not even a Shutdown.
    let mut listener = bus.endpoint();
    std::mem::forget(rt);
    let died_ns = last_heartbeat_ns.load(Ordering::Acquire);
    assert!(died_ns > 0, "the master sent heartbeats");

    // Every drive's EMCY 8130, when it arrives.
    let mut emcy_at: BTreeMap<u8, u64> = BTreeMap::new();
    let give_up = monotonic_ns() + 20 * u64::from(consumer_ms) * 1_000_000;
    while emcy_at.len() < nodes.len() && monotonic_ns() < give_up {
        let Some(f) = listener.receive(Duration::from_millis(50)).unwrap() else {
            continue;
        };
        if let (CobKind::Emcy { node }, Ok(e)) = (classify(f.cob_id()), Emcy::decode(&f)) {
            if e.error_code == code::HEARTBEAT_ERROR {
                emcy_at.entry(node).or_insert_with(monotonic_ns);
            }
        }
    }
    for n in &nodes {
        let at = emcy_at
            .get(n)
            .unwrap_or_else(|| panic!("node {n}: no EMCY 8130 after the master died"));
        eprintln!(
            "node {n}: EMCY 8130 {:.1} ms after the master's last heartbeat (0x1016 time {consumer_ms} ms)",
            at.saturating_sub(died_ns) as f64 / 1e6
        );
    }

    // Each drive's statusword (0x6041 by SDO, as any tool would ask): out of
    // Operation enabled, in Quick stop active (0x0217) until the stop is over (a
    // cycle), then Switch on disabled (0x0240).
    for n in &nodes {
        let mut seen = Vec::new();
        let deadline = monotonic_ns() + 2_000_000_000;
        while seen.last() != Some(&0x0240) && monotonic_ns() < deadline {
            let sw = statusword(&mut listener, *n);
            assert!(
                [0x0217, 0x0240].contains(&sw),
                "node {n}: statusword {sw:04X} after the loss ({seen:04X?})"
            );
            if seen.last() != Some(&sw) {
                seen.push(sw);
            }
            // Ask again a little later (the quick stop lasts a cycle period).
            let _ = listener.receive(Duration::from_millis(1)).unwrap();
        }
        assert_eq!(seen.last(), Some(&0x0240), "node {n}: {seen:04X?}");
    }

    // What the drives recorded themselves.
    let drives = sim.stop().unwrap();
    let losses = drives.heartbeat_losses();
    assert_eq!(losses.len(), nodes.len(), "{losses:?}");
    for (n, l) in &losses {
        assert_eq!(l.node, bus_cfg.master_node, "node {n}");
        assert_eq!(l.consumer_ms, consumer_ms, "node {n}");
        assert!(
            l.silent_us > u64::from(consumer_ms) * 1000,
            "node {n}: lost after {} us of silence, the consumer time is {consumer_ms} ms",
            l.silent_us
        );
        assert_eq!(l.from, hal::cia402::State::OperationEnabled, "node {n}");
        assert_eq!(l.to, hal::cia402::State::QuickStopActive, "node {n}");
    }
}

#[test]
fn an_orderly_shutdown_ends_the_drives_watch_on_the_master() {
    let sc = scenario(
        "machine = \"table-ac\"\n[probe]\nball_radius = 3.0\n[[plane]]\npoint = [0.0, 0.0, -150.0]\nnormal = [0.0, 0.0, 1.0]\n",
    );
    let cfg = machine_config(&sc);
    let entry = cfg.canopen_bus().unwrap().master_heartbeat_consumer_entry();
    let bus = InprocBus::new();
    let sim = SimRunner::spawn(SimMachine::new(&sc), bus.endpoint());
    let mut listener = bus.endpoint();
    let consumer = |t: &mut hal::can::inproc::InprocEndpoint, node: u8| {
        let rq =
            CanFrame::new(0x600 + u16::from(node), &[0x40, 0x16, 0x10, 1, 0, 0, 0, 0]).unwrap();
        t.transmit(&rq).unwrap();
        loop {
            let f = t.receive(Duration::from_secs(2)).unwrap().unwrap();
            if f.cob_id() == 0x580 + u16::from(node) && f.data()[0] != 0x80 {
                let d = f.data();
                return u32::from_le_bytes([d[4], d[5], d[6], d[7]]);
            }
        }
    };
    let options = hal::master::MasterOptions {
        pacing: Pacing::Lockstep {
            answer_timeout: Duration::from_millis(500),
        },
        ..Default::default()
    };
    let (machine, _) =
        hal::master::CanMachine::start(&cfg, bus.endpoint(), NullSink, options).unwrap();
    // Drain what the start-up sent, then ask: every drive watches the master.
    while listener.receive(Duration::ZERO).unwrap().is_some() {}
    for a in &cfg.axes {
        assert_eq!(
            consumer(&mut listener, a.canopen_node()),
            entry,
            "{}",
            a.name
        );
    }
    drop(machine);
    // The goodbye (NMT reset communication) set 0x1016 back to 0: nothing watched.
    while listener.receive(Duration::ZERO).unwrap().is_some() {}
    for a in &cfg.axes {
        assert_eq!(consumer(&mut listener, a.canopen_node()), 0, "{}", a.name);
    }
    let drives = sim.stop().unwrap();
    assert!(drives.heartbeat_losses().is_empty());
}
