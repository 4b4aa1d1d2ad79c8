//! The rig of the zero-allocation tests: the master's real-time loop on the virtual
//! clock over the synchronous loopback bus, the simulated table-ac drives, and a plane
//! at Z 10 probed from just above, so one trigger is a few hundred cycles.

use crate::loopback::Loopback;
use crate::{machine_config, table_ac_plane};
use hal::master::command::{Command, Reply};
use hal::master::{startup, LoopConfig, PacedLoop, Pacing};
use hal::{ContactSample, SampleSink};
use sim::machine::SimMachine;
use std::time::Duration;

/// Z of the ball centre at every contact: the plane at 10 plus the ball radius 3.
pub const CONTACT_Z: f64 = 13.0;

/// Boots and configures the drives, starts the loop with `sink` and waits until every
/// drive is in Operation enabled.
pub fn start<S: SampleSink>(sink: S) -> PacedLoop<Loopback, S> {
    let sc = table_ac_plane(10.0, "");
    let cfg = machine_config(&sc);
    let mut bus = Loopback::new(SimMachine::new(&sc));
    startup::boot(&mut bus, &cfg).unwrap();
    startup::configure(&mut bus, &cfg).unwrap();
    let pacing = Pacing::Lockstep {
        answer_timeout: Duration::from_millis(50),
    };
    let mut rt = PacedLoop::new(&cfg, LoopConfig::from_machine(&cfg, pacing), bus, sink);
    assert!(matches!(until_reply(&mut rt), Reply::Ready { .. }));
    rt
}

/// Cycles until the loop answers the command it is carrying out.
pub fn until_reply<S: SampleSink>(rt: &mut PacedLoop<Loopback, S>) -> Reply {
    for _ in 0..100_000 {
        rt.cycle().expect("loopback does not fail");
        if let Some(r) = rt.take_reply() {
            return r;
        }
    }
    panic!("no reply within 100 000 cycles");
}

/// One trigger: move 0.4 mm over the contact height, probe down, return the contact.
pub fn trigger<S: SampleSink>(rt: &mut PacedLoop<Loopback, S>) -> ContactSample {
    let mut above = [0.0; 6];
    above[2] = CONTACT_Z + 0.4;
    rt.submit(Command::MoveTo {
        target: above,
        mask: 0b111,
        feed: 3000.0,
    });
    assert!(matches!(until_reply(rt), Reply::Done { .. }));
    rt.submit(Command::Probe {
        direction: [0.0, 0.0, -1.0],
        feed: 600.0,
        max_distance: 2.0,
        run_id: 7,
    });
    match until_reply(rt) {
        Reply::Contact(s) => s,
        other => panic!("expected a contact, got {other:?}"),
    }
}
