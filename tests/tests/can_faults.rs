//! Faults on the CANopen backend: a drive's EMCY mid-move, a node falling silent, and a
//! bus configuration that would overload the bus.

use hal::can::inproc::InprocBus;
use hal::can::CanTransport;
use hal::master::{CanMachine, MasterOptions, Pacing};
use hal::{Axis, AxisPositions, ErrorKind, Machine, NullSink};
use probebridge_tests::conformance::{Backend, CanInproc};
use probebridge_tests::{machine_config, table_ac_plane};
use std::time::Duration;

const LONG_MOVE: [f64; 3] = [300.0, 200.0, 100.0];

/// The move was cut short on every axis, and the machine stays where it stopped.
fn assert_stopped_short(m: &mut impl Machine<Error = hal::MachineError>) {
    let p = m.positions().unwrap();
    for (i, a) in Axis::LINEAR.iter().enumerate() {
        let v = p.get(*a).unwrap();
        assert!(
            (v - LONG_MOVE[i]).abs() > 1.0,
            "{a} reached {v}: the move was not stopped"
        );
    }
    // A faulted machine refuses further motion, and nothing moves.
    let e = m
        .move_to(&AxisPositions::linear([0.0, 0.0, 300.0]), 1000.0)
        .unwrap_err();
    assert!(
        matches!(e.kind, ErrorKind::DriveFault | ErrorKind::NodeLost),
        "{e}"
    );
    assert_eq!(m.positions().unwrap(), p);
}

#[test]
fn emcy_mid_move_aborts_with_all_axes_stopped() {
    let sc = table_ac_plane(
        -150.0,
        "[[fault]]
node = 1\nkind = \"emcy\"\nafter_ms = 1500.0\ncode = 0x2310",
    );
    let mut m = CanInproc::open(&sc);
    let e = m
        .move_to(&AxisPositions::linear(LONG_MOVE), 6000.0)
        .unwrap_err();
    assert_eq!(e.kind, ErrorKind::DriveFault, "{e}");
    assert_eq!(e.node, Some(1), "{e}");
    assert_eq!(e.code, Some(0x2310), "{e}");
    assert_stopped_short(&mut m);
}

#[test]
fn heartbeat_loss_is_detected_within_the_timeout() {
    let sc = table_ac_plane(
        -150.0,
        "[[fault]]
node = 2\nkind = \"silent\"\nafter_ms = 1000.0",
    );
    let bus = sc.machine.canopen_bus().expect("a CANopen machine");
    let timeout_ms = bus.heartbeat_timeout_ms as f64;
    let producer_ms = bus.heartbeat_producer_ms as f64;
    let period_ms = bus.sync_period_us as f64 / 1000.0;
    let mut m = CanInproc::open(&sc);
    let e = m
        .move_to(&AxisPositions::linear(LONG_MOVE), 6000.0)
        .unwrap_err();
    assert_eq!(e.kind, ErrorKind::NodeLost, "{e}");
    assert_eq!(e.node, Some(2), "{e}");
    // "no heartbeat for N ms": the loss is seen one check after the timeout, at most
    // a cycle late, counted from the last heartbeat the node sent.
    let silent: f64 = e
        .message
        .split("no heartbeat for ")
        .nth(1)
        .and_then(|s| s.split(' ').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no duration in {e}"));
    assert!(
        silent > timeout_ms && silent <= timeout_ms + period_ms,
        "detected after {silent} ms"
    );
    // The node went silent at most one heartbeat period after its last heartbeat.
    assert!(silent - producer_ms <= timeout_ms, "{silent}");
    assert_stopped_short(&mut m);
}

#[test]
fn overloaded_bus_configuration_is_refused_before_anything_is_sent() {
    let sc = table_ac_plane(
        -150.0,
        "[[fault]]
node = 1\nkind = \"silent\"\nafter_ms = 1.0e9",
    );
    let mut cfg = machine_config(&sc);
    cfg.canopen_bus_mut()
        .expect("a CANopen machine")
        .sync_period_us = 1000;
    let bus = InprocBus::new();
    let mut listener = bus.endpoint();
    let options = MasterOptions {
        pacing: Pacing::Lockstep {
            answer_timeout: Duration::from_millis(100),
        },
        ..MasterOptions::default()
    };
    let e = match CanMachine::start(&cfg, bus.endpoint(), NullSink, options) {
        Ok(_) => panic!("a 133 % bus load was accepted"),
        Err(e) => e,
    };
    let msg = e.to_string();
    assert!(
        // Five axes' drives (121.2 %) and the spindle's (11.8 %) at 1 ms.
        msg.contains("133.0 % bus load") && msg.contains("limit is 70 %"),
        "{msg}"
    );
    assert!(
        listener.receive(Duration::ZERO).unwrap().is_none(),
        "a frame was sent"
    );
}
