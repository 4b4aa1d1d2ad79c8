//! The simulated drives speak the master's typed process data: configured by the
//! master's start-up, they take `Rpdo1`/`Rpdo2` frames encoded by the shared codec and
//! answer with frames that `Tpdo1`/`Tpdo2` decode.

mod common;

use hal::can::{CanFrame, CanTransport, TransportError};
use hal::canopen::cob_id::{classify, CobKind};
use hal::canopen::sync;
use hal::cia402::controlword::Controlword;
use hal::cia402::touch_probe::{TouchProbeFunction, TouchProbeStatus};
use hal::cia402::State;
use hal::master::process_data::{ProcessData, Rpdo1, Rpdo2, Tpdo1, Tpdo2};
use hal::master::startup;
use probebridge_sim::machine::SimMachine;
use std::collections::VecDeque;
use std::time::Duration;

/// The simulated machine answering inside `transmit`, in the caller's thread.
struct Direct {
    machine: SimMachine,
    queue: VecDeque<CanFrame>,
}

impl CanTransport for Direct {
    fn transmit(&mut self, frame: &CanFrame) -> Result<(), TransportError> {
        let queue = &mut self.queue;
        self.machine.on_frame(frame, &mut |r| queue.push_back(*r));
        Ok(())
    }

    fn receive(&mut self, _timeout: Duration) -> Result<Option<CanFrame>, TransportError> {
        Ok(self.queue.pop_front())
    }
}

impl Direct {
    /// Sends `frames` then SYNC; the drives' answers.
    fn cycle(&mut self, frames: &[CanFrame]) -> Vec<CanFrame> {
        for f in frames {
            self.transmit(f).unwrap();
        }
        self.transmit(&sync::encode()).unwrap();
        self.queue.drain(..).collect()
    }
}

fn tpdo<P: ProcessData>(answers: &[CanFrame], node: u8) -> Option<P> {
    answers
        .iter()
        .filter(|f| {
            classify(f.cob_id())
                == CobKind::Tpdo {
                    num: P::NUMBER,
                    node,
                }
        })
        .map(|f| P::decode(f).unwrap())
        .next_back()
}

#[test]
fn simulated_drives_answer_the_typed_process_data() {
    let sc = common::scenario("table-ac", "[probe]\nball_radius = 3.0\n");
    let cfg = sc.machine.clone();
    let mut bus = Direct {
        machine: SimMachine::new(&sc),
        queue: VecDeque::new(),
    };
    startup::boot(&mut bus, &cfg).unwrap();
    startup::configure(&mut bus, &cfg).unwrap();
    let z = cfg.axis(hal::Axis::Z).unwrap();
    let node = z.canopen_node();
    let home =
        (SimMachine::home(&cfg).get(hal::Axis::Z).unwrap() * z.increments_per_unit).round() as i32;

    let first = bus.cycle(&[]);
    let t1: Tpdo1 = tpdo(&first, node).expect("TPDO1 at SYNC");
    assert_eq!(t1.position_actual, home);
    assert_eq!(
        State::from_statusword(t1.statusword),
        Some(State::SwitchOnDisabled)
    );

    // Walk the drive to Operation enabled, holding the position.
    let mut state = None;
    for cw in [
        Controlword::SHUTDOWN,
        Controlword::SWITCH_ON_CMD,
        Controlword::ENABLE_OPERATION_CMD,
    ] {
        let rpdo1 = Rpdo1 {
            controlword: cw,
            target_position: home,
        };
        let answers = bus.cycle(&[rpdo1.encode(node)]);
        state = tpdo::<Tpdo1>(&answers, node).and_then(|t| State::from_statusword(t.statusword));
    }
    assert_eq!(state, Some(State::OperationEnabled));

    // Arm touch probe 1: TPDO2 reports it enabled, no edge stored.
    let arm = Rpdo2 {
        touch_probe_function: TouchProbeFunction::probe1_first_positive_edge(),
    };
    let hold = Rpdo1 {
        controlword: Controlword::ENABLE_OPERATION_CMD,
        target_position: home,
    };
    let answers = bus.cycle(&[hold.encode(node), arm.encode(node)]);
    let t2: Tpdo2 = tpdo(&answers, node).expect("TPDO2 on change");
    assert_eq!(
        t2.touch_probe_status
            & (TouchProbeStatus::ENABLED | TouchProbeStatus::POSITIVE_EDGE_STORED),
        TouchProbeStatus::ENABLED
    );
}
