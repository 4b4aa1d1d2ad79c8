//! Replay of captured CAN traffic (candump log format): a probing session of the master
//! against the simulated drives was recorded into `tests/data/probe-plane.log`; played
//! back, the master must send exactly the recorded frames, byte for byte, and arrive at
//! the same contact. Re-record after an intended change of the master's traffic with
//! `PROBEBRIDGE_RECORD=1 cargo test -p probebridge-tests --test candump_replay`.

use hal::can::record::{Recorder, Replay};
use hal::can::CanTransport;
use hal::master::command::{Command, Reply};
use hal::master::{startup, LoopConfig, PacedLoop, Pacing};
use hal::{ContactSample, NullSink};
use probebridge_tests::loopback::Loopback;
use probebridge_tests::{machine_config, scenario};
use sim::machine::SimMachine;
use std::path::PathBuf;
use std::time::Duration;

fn log_path() -> PathBuf {
    probebridge_tests::configs_dir().join("../tests/data/probe-plane.log")
}

fn plane() -> sim::Scenario {
    // The simulated machine starts at Z 350: the plane is just below.
    scenario(
        "machine = \"table-ac\"\n[probe]\nball_radius = 3.0\n[[plane]]\npoint = [0.0, 0.0, 340.0]\nnormal = [0.0, 0.0, 1.0]\n",
    )
}

/// Start-up, enabling, one probing move down; the contact.
fn session<T: CanTransport>(transport: T) -> (ContactSample, PacedLoop<T, NullSink>) {
    let cfg = machine_config(&plane());
    let mut t = transport;
    startup::boot(&mut t, &cfg).unwrap();
    startup::configure(&mut t, &cfg).unwrap();
    let pacing = Pacing::Lockstep {
        answer_timeout: Duration::from_millis(50),
    };
    let mut rt = PacedLoop::new(&cfg, LoopConfig::from_machine(&cfg, pacing), t, NullSink);
    let next = |rt: &mut PacedLoop<T, NullSink>| loop {
        rt.cycle().unwrap();
        if let Some(r) = rt.take_reply() {
            break r;
        }
    };
    assert!(matches!(next(&mut rt), Reply::Ready { .. }));
    rt.submit(Command::Probe {
        direction: [0.0, 0.0, -1.0],
        feed: 3000.0,
        max_distance: 10.0,
        run_id: 1,
    });
    match next(&mut rt) {
        Reply::Contact(s) => (s, rt),
        other => panic!("expected a contact, got {other:?}"),
    }
}

#[test]
fn captured_probing_session_replays_byte_for_byte() {
    if std::env::var_os("PROBEBRIDGE_RECORD").is_some() {
        let file = std::fs::File::create(log_path()).unwrap();
        let bus = Recorder::new(Loopback::new(SimMachine::new(&plane())), file, "vcan0");
        let (s, _) = session(bus);
        assert!((s.positions[2] - 343.0).abs() < 1e-6);
    }
    let text = std::fs::read_to_string(log_path())
        .unwrap_or_else(|e| panic!("{}: {e}", log_path().display()));
    let master = machine_config(&plane())
        .canopen_bus()
        .map(|b| b.master_node);
    let replay = Replay::from_log_of(&text, master)
        .unwrap_or_else(|e| panic!("{}: {e}", log_path().display()));
    let total = replay.remaining();
    assert!(
        total > 500,
        "the capture is too short to mean anything: {total} frames"
    );
    let (s, mut rt) = session(replay);
    assert!(
        (s.positions[2] - 343.0).abs() < 1e-6,
        "contact at Z {}",
        s.positions[2]
    );
    assert_eq!(
        rt.transport_mut().remaining(),
        0,
        "the master stopped before the end of the capture"
    );
}
