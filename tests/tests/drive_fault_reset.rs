//! The `drive-fault` scenario's fault (node 5, EMCY 0x8611 after 100 ms) is cleared by
//! the standard CiA 402 controlword sequence, and the drive is back in Operation
//! enabled. The simulated machine runs in its own thread on the in-process bus; this
//! test is the master, frame by frame (our own master refuses motion after a fault
//! until it is restarted, so it does not reset faults itself).

use hal::can::inproc::{InprocBus, InprocEndpoint};
use hal::can::{CanFrame, CanTransport};
use hal::canopen::cob_id::{self, CobKind};
use hal::canopen::{sync, Emcy};
use hal::cia402::State;
use hal::master::startup;
use probebridge_tests::{configs_dir, machine_config};
use sim::machine::{SimMachine, SimRunner};
use std::collections::BTreeMap;
use std::time::Duration;

const FAULTY: u8 = 5;

/// The master side: last statusword and position per node, EMCYs seen.
struct Master {
    bus: InprocEndpoint,
    nodes: Vec<u8>,
    statusword: BTreeMap<u8, u16>,
    actual: BTreeMap<u8, i32>,
    emcy: Vec<(u8, Emcy)>,
}

impl Master {
    /// One SYNC period: RPDO1 (controlword, target = where the axis is) to every
    /// node, SYNC, then every node's TPDO1.
    fn cycle(&mut self, controlword: impl Fn(u8) -> u16) {
        for &n in &self.nodes {
            if let Some(&pos) = self.actual.get(&n) {
                let mut d = [0u8; 6];
                d[..2].copy_from_slice(&controlword(n).to_le_bytes());
                d[2..].copy_from_slice(&pos.to_le_bytes());
                let f = CanFrame::new(cob_id::rpdo_cob(1, n), &d).unwrap();
                self.bus.transmit(&f).unwrap();
            }
        }
        self.bus.transmit(&sync::encode()).unwrap();
        let mut answered = Vec::new();
        while answered.len() < self.nodes.len() {
            let f = self
                .bus
                .receive(Duration::from_secs(5))
                .unwrap()
                .expect("every drive answers SYNC with its TPDO1");
            match cob_id::classify(f.cob_id()) {
                CobKind::Tpdo { num: 1, node } => {
                    let d = f.data();
                    self.statusword
                        .insert(node, u16::from_le_bytes([d[0], d[1]]));
                    self.actual
                        .insert(node, i32::from_le_bytes([d[2], d[3], d[4], d[5]]));
                    answered.push(node);
                }
                CobKind::Emcy { node } => self.emcy.push((node, Emcy::decode(&f).unwrap())),
                _ => {}
            }
        }
    }

    fn state(&self, node: u8) -> Option<State> {
        State::from_statusword(self.statusword[&node])
    }
}

#[test]
fn drive_fault_is_reset_by_the_standard_sequence_and_the_drive_enables_again() {
    let mut sc = sim::Scenario::load(
        &configs_dir().join("scenarios/drive-fault.toml"),
        Some(&configs_dir().join("machines")),
    )
    .unwrap();
    // The axes' drives, SYNC by SYNC: the spindle's (profile position, its own RPDO
    // timing) is not this master's.
    sc.machine.spindle = None;
    let cfg = machine_config(&sc);
    let bus = InprocBus::new();
    let mut master_bus = bus.endpoint();
    let sim = SimRunner::spawn(SimMachine::new(&sc), bus.endpoint());
    startup::boot(&mut master_bus, &cfg).unwrap();
    startup::configure(&mut master_bus, &cfg).unwrap();
    let mut m = Master {
        bus: master_bus,
        nodes: cfg.axes.iter().filter_map(|a| a.node).collect(),
        statusword: BTreeMap::new(),
        actual: BTreeMap::new(),
        emcy: Vec::new(),
    };
    // Every drive to Operation enabled: shutdown, switch on, enable operation.
    m.cycle(|_| 0);
    for cw in [0x06, 0x07, 0x0F] {
        m.cycle(|_| cw);
    }
    for &n in &m.nodes {
        assert_eq!(m.state(n), Some(State::OperationEnabled), "node {n}");
    }
    // The scenario's fault: node 5 after 100 ms (2 ms SYNC: 50 periods).
    for _ in 0..60 {
        m.cycle(|_| 0x0F);
    }
    let fault: Vec<_> = m.emcy.iter().filter(|(n, _)| *n == FAULTY).collect();
    assert_eq!(fault.len(), 1, "{:?}", m.emcy);
    assert_eq!(fault[0].1.error_code, 0x8611);
    assert_eq!(m.state(FAULTY), Some(State::Fault));

    // Fault reset: bit 7 rising (from 0x000F), then shutdown, switch on, enable.
    let sequence = [0x80, 0x06, 0x07, 0x0F];
    let expect = [
        State::SwitchOnDisabled,
        State::ReadyToSwitchOn,
        State::SwitchedOn,
        State::OperationEnabled,
    ];
    for (cw, state) in sequence.into_iter().zip(expect) {
        m.cycle(|n| if n == FAULTY { cw } else { 0x0F });
        assert_eq!(m.state(FAULTY), Some(state), "after controlword {cw:#06X}");
    }
    // Bit 12: the drive follows the target position again.
    assert_eq!(m.statusword[&FAULTY], 0x1237);
    let reset: Vec<_> = m
        .emcy
        .iter()
        .filter(|(n, e)| *n == FAULTY && e.is_reset())
        .collect();
    assert_eq!(reset.len(), 1, "one EMCY error reset: {:?}", m.emcy);
    assert_eq!(reset[0].1.error_register, 0);
    // The other drives stayed enabled throughout.
    for &n in m.nodes.iter().filter(|&&n| n != FAULTY) {
        assert_eq!(m.state(n), Some(State::OperationEnabled), "node {n}");
    }
    drop(sim);
}
