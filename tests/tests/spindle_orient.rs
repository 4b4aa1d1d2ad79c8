//! The spindle's own drive on the CANopen bus (`[spindle]`, CiA 402 profile position):
//! the master's oriented stop against the simulated spindle drive, what it refuses, and
//! a spindle drive without profile position refused at start-up, before anything moves.

use hal::can::inproc::{InprocBus, WireClock};
use hal::master::{CanMachine, MasterOptions, Pacing};
use hal::{ErrorKind, Machine, NullSink};
use probebridge_tests::conformance::{Backend, CanInproc};
use probebridge_tests::{scenario, table_ac_plane};
use sim::machine::{SimMachine, SimRunner};
use std::time::Duration;

/// An oriented stop turns the spindle drive to the angle (modulo 360°) and nothing
/// else: the axes stand where they stood.
#[test]
fn an_oriented_stop_turns_the_spindle_drive_and_the_axes_hold() {
    let sc = table_ac_plane(-50.0, "");
    assert_eq!(sc.machine.spindle.as_ref().map(|s| s.node), Some(6));
    let mut m = CanInproc::open(&sc);
    let before = m.positions().unwrap();
    assert_eq!(m.orient_spindle(180.0), Ok(true));
    assert_eq!(m.positions().unwrap(), before);
    // -90° is 270°: the drive's position is taken modulo a turn.
    assert_eq!(m.orient_spindle(-90.0), Ok(true));
    assert_eq!(m.positions().unwrap(), before);
    drop(m.machine);
    let sim = m.keep.stop().expect("the simulation ran");
    assert_eq!(sim.spindle_deg(), Some(270.0));
    assert_eq!(
        sim.world().spindle_deg(),
        270.0,
        "the stylus turned with it"
    );
}

/// An angle that is not a number is refused before anything is sent.
#[test]
fn an_angle_that_is_not_a_number_is_refused() {
    let sc = table_ac_plane(-50.0, "");
    let mut m = CanInproc::open(&sc);
    let e = m.orient_spindle(f64::NAN).unwrap_err();
    assert_eq!(e.kind, ErrorKind::InvalidRequest, "{e}");
    assert!(e.to_string().contains("not a number"), "{e}");
    // The machine is fine: the next stop turns.
    assert_eq!(m.orient_spindle(90.0), Ok(true));
}

/// A machine configured without `[spindle]` has no spindle it can orient: `Ok(false)`,
/// nothing sent (460 then keeps the offset, and says so).
#[test]
fn a_machine_without_a_spindle_drive_answers_that_it_has_none() {
    let sc = scenario(
        "machine = \"head-b-table-c\"\n[probe]\nball_radius = 3.0\n[[plane]]\npoint = [0.0, 0.0, -50.0]\nnormal = [0.0, 0.0, 1.0]\n",
    );
    assert!(sc.machine.spindle.is_none());
    let mut m = CanInproc::open(&sc);
    assert_eq!(m.orient_spindle(180.0), Ok(false));
}

/// The master's configuration names node 6 as the spindle drive, but node 6 is an axis
/// drive (cyclic synchronous position only, 0x6502 = 0x80): start-up refuses it, naming
/// the node and the object, before any drive is enabled.
#[test]
fn a_spindle_drive_without_profile_position_is_refused_at_start_up() {
    let sc = table_ac_plane(-50.0, "");
    let master_cfg = sc.machine.clone();
    let mut on_the_bus = sc.clone();
    on_the_bus.machine.spindle = None;
    let mut b = on_the_bus.machine.axes[3].clone();
    b.name = hal::Axis::B;
    b.node = Some(6);
    on_the_bus.machine.axes.push(b);
    let bus = InprocBus::with_wire_time(1_000_000, WireClock::Virtual);
    let _sim = SimRunner::spawn(SimMachine::new(&on_the_bus), bus.endpoint_for_devices());
    let options = MasterOptions {
        pacing: Pacing::Lockstep {
            answer_timeout: Duration::from_millis(500),
        },
        ..MasterOptions::default()
    };
    let Err(e) = CanMachine::start(&master_cfg, bus.endpoint(), NullSink, options) else {
        panic!("a spindle drive without profile position started");
    };
    assert_eq!(e.node, Some(6), "{e}");
    assert!(
        e.to_string().contains("no profile position mode") && e.to_string().contains("0x6502"),
        "{e}"
    );
}

/// The operator's stop during an oriented stop halts the spindle drive where it is
/// (controlword bit 8) and fails the command as aborted; it stays halted while the axes
/// move on, and the next oriented stop turns it again.
#[test]
fn the_operators_stop_halts_the_spindle_where_it_is() {
    use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
    use std::sync::Arc;
    let mut sc = table_ac_plane(-50.0, "");
    // 1 rpm: half a turn takes 30 s of the drive's time; the stop is raised 40 ms in
    // (and reaches the loop within 5 ms of wall time, a second or so of lockstep).
    if let Some(s) = sc.machine.spindle.as_mut() {
        s.orient_rpm = 1.0;
    }
    let abort = hal::AbortFlag::fresh();
    let armed = Arc::new(AtomicBool::new(false));
    let steps = Arc::new(AtomicU32::new(0));
    let watch: sim::machine::MotionWatch = {
        let (abort, armed, steps) = (abort, armed.clone(), steps.clone());
        Arc::new(move |_| {
            if armed.load(Ordering::Acquire) && steps.fetch_add(1, Ordering::AcqRel) == 20 {
                abort.raise();
            }
        })
    };
    let mut m = CanInproc::open_abortable(&sc, abort, watch);
    armed.store(true, Ordering::Release);
    let e = m.orient_spindle(180.0).unwrap_err();
    armed.store(false, Ordering::Release);
    assert_eq!(e.kind, ErrorKind::Aborted, "{e}");
    abort.rearm();
    // 1 mm at 1 mm/min: a minute of the drive's time, in which a spindle that was not
    // halted would reach 180°.
    let mut to = m.positions().unwrap();
    to.set(hal::Axis::X, to.get(hal::Axis::X).unwrap() + 1.0);
    m.move_to(&to, 1.0).unwrap();
    drop(m.machine);
    let sim = m.keep.stop().expect("the simulation ran");
    let at = sim.spindle_deg().unwrap();
    assert!(at > 0.0 && at < 90.0, "the spindle stands at {at}°");
}

/// With the operator's stop raised an oriented stop is refused before anything is
/// sent; re-armed, it turns the spindle.
#[test]
fn an_oriented_stop_is_refused_while_the_stop_is_raised() {
    let sc = table_ac_plane(-50.0, "");
    let abort = hal::AbortFlag::fresh();
    let mut m = CanInproc::open_abortable(&sc, abort, std::sync::Arc::new(|_| {}));
    abort.raise();
    let e = m.orient_spindle(90.0).unwrap_err();
    assert_eq!(
        e.kind,
        ErrorKind::Aborted,
        "refused before anything moved: {e}"
    );
    abort.rearm();
    assert_eq!(m.orient_spindle(90.0), Ok(true));
    drop(m.machine);
    let sim = m.keep.stop().expect("the simulation ran");
    assert_eq!(sim.spindle_deg(), Some(90.0));
}
