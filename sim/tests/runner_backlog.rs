//! A host too slow for its bus (an emulated CPU under load) takes frames late: the
//! master's heartbeat waits in the queue behind others. A real drive takes each frame
//! as it arrives, so the simulated drives take everything queued before their
//! heartbeat consumer judges: a backlog is not silence, a real silence still is.

mod common;

use hal::can::{CanFrame, CanTransport, TransportError};
use hal::canopen::cob_id::{classify, CobKind};
use hal::canopen::emcy::{code, Emcy};
use hal::clock::monotonic_ns;
use probebridge_sim::machine::{SimClock, SimMachine, SimRunner};
use std::collections::VecDeque;
use std::sync::mpsc;
use std::time::Duration;

const MASTER: u8 = 127;
const CONSUMER_MS: u64 = 300;
/// How long the slow host takes for each frame: less than the consumer's 100 ms
/// step, so the consumer's clock keeps real time while the host works.
const PER_FRAME_NS: u64 = 80_000_000;

/// Frames already queued when the runner starts; each one taken costs the host
/// `PER_FRAME_NS`. Reports when the queue ran dry, and the drives' EMCYs.
struct SlowHost {
    queue: VecDeque<CanFrame>,
    events: mpsc::Sender<Event>,
    drained: bool,
}

enum Event {
    Drained { at_ns: u64 },
    Emcy { node: u8, code: u16, at_ns: u64 },
}

impl CanTransport for SlowHost {
    fn transmit(&mut self, frame: &CanFrame) -> Result<(), TransportError> {
        if let CobKind::Emcy { node } = classify(frame.cob_id()) {
            let e = Emcy::decode(frame).expect("EMCY of 8 bytes");
            let _ = self.events.send(Event::Emcy {
                node,
                code: e.error_code,
                at_ns: monotonic_ns(),
            });
        }
        Ok(())
    }

    fn receive(&mut self, timeout: Duration) -> Result<Option<CanFrame>, TransportError> {
        if let Some(f) = self.queue.pop_front() {
            // The slow host: busy for a while with every frame.
            let until = monotonic_ns() + PER_FRAME_NS;
            while monotonic_ns() < until {
                std::hint::spin_loop();
            }
            return Ok(Some(f));
        }
        if !self.drained {
            self.drained = true;
            let _ = self.events.send(Event::Drained {
                at_ns: monotonic_ns(),
            });
        }
        // Nothing more comes: the master has fallen silent.
        std::thread::park_timeout(timeout);
        Ok(None)
    }
}

#[test]
fn a_heartbeat_queued_behind_a_backlog_is_not_a_loss_but_silence_is() {
    let sc = common::scenario("table-ac", "[probe]\nball_radius = 3.0\n");
    let node = sc.machine.axes[0].canopen_node();
    let mut machine = SimMachine::new(&sc);
    machine.set_clock(SimClock::Monotonic);

    // 0x1016:1 = master node, consumer time: the drive watches the master.
    let entry = (u32::from(MASTER) << 16) | CONSUMER_MS as u32;
    let mut sdo = [0x23, 0x16, 0x10, 1, 0, 0, 0, 0];
    sdo[4..].copy_from_slice(&entry.to_le_bytes());
    let heartbeat = CanFrame::new(0x700 + u16::from(MASTER), &[0x05]).unwrap();
    // Another node's heartbeat: a frame the watching drive has no use for.
    let other = CanFrame::new(0x700 + 0x70, &[0x05]).unwrap();
    let mut queue = VecDeque::new();
    queue.push_back(CanFrame::new(0x600 + u16::from(node), &sdo).unwrap());
    // Three heartbeats, each 5 frames (400 ms of the slow host's work) apart: more
    // than the consumer time between two of them as the host takes them, while the
    // master sent them on time.
    for _ in 0..3 {
        queue.push_back(heartbeat);
        queue.extend(std::iter::repeat_n(other, 5));
    }
    let backlog_ns = queue.len() as u64 * PER_FRAME_NS;
    let (tx, rx) = mpsc::channel();
    let start_ns = monotonic_ns();
    let runner = SimRunner::spawn(
        machine,
        SlowHost {
            queue,
            events: tx,
            drained: false,
        },
    );

    // The backlog is taken without a loss; then the master stays silent, and after
    // the consumer time the drive says so (EMCY 8130).
    let mut drained_ns = None;
    let loss = loop {
        match rx
            .recv_timeout(Duration::from_secs(30))
            .expect("no EMCY 8130 30 s after the master fell silent")
        {
            Event::Drained { at_ns } => drained_ns = Some(at_ns),
            Event::Emcy {
                node: n,
                code: c,
                at_ns,
            } if n == node && c == code::HEARTBEAT_ERROR => break at_ns,
            Event::Emcy { .. } => {}
        }
    };
    let drained_ns =
        drained_ns.expect("the drive reported a heartbeat loss while the backlog was taken");
    assert!(
        drained_ns - start_ns >= backlog_ns,
        "the backlog took {} ms, less than its {} ms of work",
        (drained_ns - start_ns) / 1_000_000,
        backlog_ns / 1_000_000
    );
    assert!(
        loss - drained_ns >= CONSUMER_MS / 2 * 1_000_000,
        "EMCY 8130 {} ms after the backlog was taken: far sooner than the consumer time ({CONSUMER_MS} ms)",
        (loss - drained_ns) / 1_000_000
    );
    let drives = runner.stop().unwrap();
    let losses = drives.heartbeat_losses();
    assert_eq!(losses.len(), 1, "{losses:?}");
    assert_eq!(losses[0].0, node);
    assert_eq!(losses[0].1.node, MASTER);
}
