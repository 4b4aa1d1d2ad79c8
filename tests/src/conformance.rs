//! The `Machine` conformance suite: every backend (CANopen with simulated drives on the
//! in-process bus, on SocketCAN, Modbus, ...) must pass the same checks. Instantiate
//! it for a backend with [`crate::machine_conformance!`].

use hal::can::inproc::{InprocBus, WireClock};
use hal::master::{CanMachine, MasterOptions, Pacing};
use hal::{
    AbortFlag, Axis, AxisPositions, Contact, ErrorKind, Machine, MachineError, NullSink, ProbeMove,
};
use sim::machine::{MotionWatch, SimClock, SimMachine, SimRunner};
use sim::Scenario;
use std::time::Duration;

/// A way to get a machine for a scenario.
pub trait Backend {
    type M: Machine<Error = MachineError>;
    fn open(scenario: &Scenario) -> Self::M;
    /// As `open`, with the operator's stop `abort` in the backend's options and `watch`
    /// called by the simulator with the axes' positions as they move; paced so that a
    /// stop raised from `watch` reaches the backend while the move is under way.
    fn open_abortable(scenario: &Scenario, abort: AbortFlag, watch: MotionWatch) -> Self::M;
    /// `Err(why)` when this backend cannot run here (the suite's tests then pass with a
    /// "skipped" message instead of failing): e.g. no CAN interface on this kernel.
    fn available() -> Result<(), String> {
        Ok(())
    }
}

/// A CAN machine together with whatever must live as long as it (the simulator).
pub struct Held<T> {
    pub machine: CanMachine,
    pub keep: T,
}

impl<T> Machine for Held<T> {
    type Error = MachineError;
    fn axes(&self) -> u8 {
        self.machine.axes()
    }
    fn positions(&mut self) -> Result<AxisPositions, MachineError> {
        self.machine.positions()
    }
    fn move_to(&mut self, target: &AxisPositions, feed: f64) -> Result<(), MachineError> {
        self.machine.move_to(target, feed)
    }
    fn probe(&mut self, mv: &ProbeMove) -> Result<Contact, MachineError> {
        self.machine.probe(mv)
    }
    fn set_run(&mut self, run_id: u64) {
        self.machine.set_run(run_id)
    }
    fn clock_ns(&mut self) -> u64 {
        self.machine.clock_ns()
    }
    fn health(&mut self) -> Result<(), MachineError> {
        self.machine.health()
    }
    fn orient_spindle(&mut self, angle_deg: f64) -> Result<bool, MachineError> {
        self.machine.orient_spindle(angle_deg)
    }
}

/// CANopen master and simulated drives on the in-process bus with the machine's bit
/// rate (wire time on the virtual clock).
pub struct CanInproc;

impl CanInproc {
    fn open_with(
        scenario: &Scenario,
        abort: Option<AbortFlag>,
        watch: Option<MotionWatch>,
    ) -> Held<SimRunner> {
        let bitrate = crate::machine_config(scenario)
            .canopen_bus()
            .map_or(1_000_000, |b| b.bitrate);
        let bus = InprocBus::with_wire_time(bitrate, WireClock::Virtual);
        let mut drives = SimMachine::new(scenario);
        if let Some(w) = watch {
            drives.set_motion_watch(w);
        }
        let sim = SimRunner::spawn(drives, bus.endpoint_for_devices());
        let options = MasterOptions {
            pacing: Pacing::Lockstep {
                answer_timeout: Duration::from_millis(500),
            },
            abort,
            ..MasterOptions::default()
        };
        let (machine, _) = CanMachine::start(
            &crate::machine_config(scenario),
            bus.endpoint(),
            NullSink,
            options,
        )
        .unwrap_or_else(|e| panic!("CAN machine did not start: {e}"));
        Held { machine, keep: sim }
    }
}

impl Backend for CanInproc {
    type M = Held<SimRunner>;
    fn open(scenario: &Scenario) -> Self::M {
        Self::open_with(scenario, None, None)
    }
    /// On the virtual clock too: the master polls the stop every 5 ms of wall time,
    /// and a move long enough on the simulated clock is still under way by then.
    fn open_abortable(scenario: &Scenario, abort: AbortFlag, watch: MotionWatch) -> Self::M {
        Self::open_with(scenario, Some(abort), Some(watch))
    }
}

/// Environment variable naming the SocketCAN interface for [`SocketCan`] (`vcan0` in
/// the CI VM). Without it the SocketCAN suite is skipped.
pub const CAN_IFACE_ENV: &str = "PROBEBRIDGE_TEST_CAN";
/// Optional: SYNC period (µs) for [`SocketCan`] instead of the machine's (the CI VM
/// emulates its CPU and cannot hold 2 ms; only behaviour is checked there).
pub const CAN_SYNC_US_ENV: &str = "PROBEBRIDGE_TEST_CAN_SYNC_US";
/// Optional: heartbeat timeout (ms) for [`SocketCan`] instead of the machine's.
pub const CAN_HEARTBEAT_TIMEOUT_MS_ENV: &str = "PROBEBRIDGE_TEST_CAN_HEARTBEAT_TIMEOUT_MS";
/// Optional: the master's heartbeat period (ms) for [`SocketCan`] instead of the
/// machine's (the drives stop when it is missing 3 periods: a stalling VM needs more).
pub const CAN_MASTER_HEARTBEAT_MS_ENV: &str = "PROBEBRIDGE_TEST_CAN_MASTER_HEARTBEAT_MS";

/// CANopen master and simulated drives on a real SocketCAN interface (`vcan0`), each on
/// its own socket in this process (two sockets on one interface see each other's
/// frames, as two nodes on a bus do), paced in real time as on a gateway.
///
/// Tests of this backend share the bus: a lock serialises them (run them with
/// `--test-threads=1` all the same, so a test's time is its own).
pub struct SocketCan;

static SOCKETCAN_BUS: std::sync::Mutex<()> = std::sync::Mutex::new(());

impl SocketCan {
    fn iface() -> Option<String> {
        std::env::var(CAN_IFACE_ENV).ok().filter(|s| !s.is_empty())
    }
}

impl Backend for SocketCan {
    /// The simulator stops (and the bus is released) after the machine shut down.
    type M = Held<(SimRunner, std::sync::MutexGuard<'static, ()>)>;

    fn available() -> Result<(), String> {
        match Self::iface() {
            Some(_) => Ok(()),
            None => Err(format!(
                "set {CAN_IFACE_ENV}=vcan0 (a SocketCAN interface that is up) to run this suite; \
                 this kernel may have no AF_CAN at all: CI runs it inside a VM (.ci/vcan/run)"
            )),
        }
    }

    fn open(scenario: &Scenario) -> Self::M {
        Self::open_with(scenario, None, None)
    }
    fn open_abortable(scenario: &Scenario, abort: AbortFlag, watch: MotionWatch) -> Self::M {
        Self::open_with(scenario, Some(abort), Some(watch))
    }
}

impl SocketCan {
    fn open_with(
        scenario: &Scenario,
        abort: Option<AbortFlag>,
        watch: Option<MotionWatch>,
    ) -> Held<(SimRunner, std::sync::MutexGuard<'static, ()>)> {
        use hal::can::socketcan::SocketCanTransport;
        let iface = Self::iface().expect("SocketCan::available() was checked");
        let bus = SOCKETCAN_BUS.lock().unwrap_or_else(|e| e.into_inner());
        let open = |who: &str| {
            SocketCanTransport::open(&iface)
                .unwrap_or_else(|e| panic!("{who}: cannot open {iface}: {e}"))
        };
        let mut cfg = crate::machine_config(scenario);
        let env = |name: &str| std::env::var(name).ok().and_then(|v| v.parse().ok());
        let timing = cfg
            .canopen_bus_mut()
            .expect("the scenarios' machines are on CANopen");
        if let Some(us) = env(CAN_SYNC_US_ENV) {
            timing.sync_period_us = us;
        }
        if let Some(ms) = env(CAN_HEARTBEAT_TIMEOUT_MS_ENV) {
            timing.heartbeat_timeout_ms = ms as u16;
        }
        if let Some(ms) = env(CAN_MASTER_HEARTBEAT_MS_ENV) {
            timing.master_heartbeat_ms = ms as u16;
        }
        let mut drives = SimMachine::new(scenario);
        drives.set_clock(SimClock::Monotonic);
        if let Some(w) = watch {
            drives.set_motion_watch(w);
        }
        let sim = SimRunner::spawn(drives, open("simulated drives"));
        let options = MasterOptions {
            pacing: Pacing::RealTime,
            abort,
            ..MasterOptions::default()
        };
        let (machine, _) = CanMachine::start(&cfg, open("master"), NullSink, options)
            .unwrap_or_else(|e| panic!("CAN machine on {iface} did not start: {e}"));
        Held {
            machine,
            keep: (sim, bus),
        }
    }
}

fn plane_scenario(z0: f64, r: f64) -> Scenario {
    crate::scenario(&format!(
        r#"
machine = "table-ac"
[probe]
ball_radius = {r}
[[plane]]
point = [0.0, 0.0, {z0}]
normal = [0.0, 0.0, 1.0]
"#
    ))
}

fn probe_down(
    m: &mut impl Machine<Error = MachineError>,
    start: [f64; 3],
    dist: f64,
) -> Result<Contact, MachineError> {
    m.move_to(&AxisPositions::linear(start), 5000.0)?;
    m.probe(&ProbeMove {
        direction: [0.0, 0.0, -1.0],
        feed: 200.0,
        max_distance: dist,
    })
}

fn assert_near(what: &str, got: f64, want: f64, tol: f64) {
    assert!(
        (got - want).abs() <= tol,
        "{what}: got {got:.9}, want {want:.9} (tolerance {tol:e})"
    );
}

/// A plane `z = z0` probed from above with ball radius R gives Z = z0 + R (noise 0).
pub fn probes_plane_at_known_height<B: Backend>() {
    for (z0, r) in [(10.0, 3.0), (-25.5, 2.0), (47.123456, 1.5)] {
        let mut m = B::open(&plane_scenario(z0, r));
        let c = probe_down(&mut m, [12.3, -4.5, z0 + r + 5.0], 10.0).unwrap();
        assert_near("Z", c.positions.get(Axis::Z).unwrap(), z0 + r, 1e-6);
        assert_near("X", c.positions.get(Axis::X).unwrap(), 12.3, 1e-6);
        assert_near("Y", c.positions.get(Axis::Y).unwrap(), -4.5, 1e-6);
        // Every axis of the machine is latched, rotary ones too.
        assert_eq!(c.positions.mask(), m.axes());
    }
}

/// A probing move in any direction stops on the sphere at centre - d (r + R).
pub fn probes_sphere_along_oblique_direction<B: Backend>() {
    let sc = crate::scenario(
        r#"
machine = "table-ac"
[probe]
ball_radius = 2.5
[[sphere]]
center = [20.0, 10.0, 60.0]
radius = 15.0
"#,
    );
    let mut m = B::open(&sc);
    let d: [f64; 3] = [0.6, -0.48, -0.64];
    let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let d = [d[0] / n, d[1] / n, d[2] / n];
    let reach = 15.0 + 2.5;
    let start = [
        20.0 - d[0] * (reach + 4.0),
        10.0 - d[1] * (reach + 4.0),
        60.0 - d[2] * (reach + 4.0),
    ];
    m.move_to(&AxisPositions::linear([start[0], start[1], 100.0]), 5000.0)
        .unwrap();
    m.move_to(&AxisPositions::linear(start), 5000.0).unwrap();
    let c = m
        .probe(&ProbeMove {
            direction: d,
            feed: 150.0,
            max_distance: 10.0,
        })
        .unwrap();
    let want = [
        20.0 - d[0] * reach,
        10.0 - d[1] * reach,
        60.0 - d[2] * reach,
    ];
    for (i, a) in Axis::LINEAR.iter().enumerate() {
        assert_near(a.name(), c.positions.get(*a).unwrap(), want[i], 1e-6);
    }
}

/// No surface within the distance: NotTriggered, axes stopped at the end of the path.
pub fn not_triggered_within_max_distance<B: Backend>() {
    let mut m = B::open(&plane_scenario(0.0, 3.0));
    let e = probe_down(&mut m, [0.0, 0.0, 50.0], 10.0).unwrap_err();
    assert_eq!(e.kind, ErrorKind::NotTriggered, "{e}");
    let p = m.positions().unwrap();
    assert_near(
        "Z after a probing move without contact",
        p.get(Axis::Z).unwrap(),
        40.0,
        1e-3,
    );
}

/// A deflected probe refuses to start, and nothing moves.
pub fn deflected_at_start_moves_nothing<B: Backend>() {
    let mut m = B::open(&plane_scenario(10.0, 3.0));
    // Pushing the stylus into the plane is a collision: the axes brake with the
    // stylus pressed in, which is the deflected start this check needs.
    m.move_to(&AxisPositions::linear([5.0, 5.0, 30.0]), 5000.0)
        .unwrap();
    let e = m
        .move_to(&AxisPositions::linear([5.0, 5.0, 12.0]), 5000.0)
        .unwrap_err();
    assert_eq!(e.kind, ErrorKind::ProbeCollision, "{e}");
    let before = m.positions().unwrap();
    let e = m
        .probe(&ProbeMove {
            direction: [1.0, 0.0, 0.0],
            feed: 100.0,
            max_distance: 5.0,
        })
        .unwrap_err();
    assert_eq!(e.kind, ErrorKind::AlreadyDeflected, "{e}");
    assert_eq!(m.positions().unwrap(), before);
}

/// With the stylus pressed in (after a collision) no rising edge can tell a further
/// collision: a positioning move deeper or sideways is refused with the point before
/// anything moves; the retraction straight out of the contact runs. Before this rule
/// the move deeper ran until the probe's overtravel was used up and the drives
/// faulted (EMCY 0xFF01 on CANopen, a PLC fault over Modbus).
pub fn moves_deeper_from_a_contact_are_refused<B: Backend>() {
    let mut m = B::open(&plane_scenario(10.0, 3.0));
    m.move_to(&AxisPositions::linear([5.0, 5.0, 30.0]), 5000.0)
        .unwrap();
    let e = m
        .move_to(&AxisPositions::linear([5.0, 5.0, 12.0]), 5000.0)
        .unwrap_err();
    assert_eq!(e.kind, ErrorKind::ProbeCollision, "{e}");
    let before = m.positions().unwrap();
    for target in [[5.0, 5.0, 0.0], [40.0, 5.0, before.get(Axis::Z).unwrap()]] {
        let e = m
            .move_to(&AxisPositions::linear(target), 1000.0)
            .unwrap_err();
        assert_eq!(e.kind, ErrorKind::AlreadyDeflected, "{e}");
        assert!(
            e.to_string()
                .contains("already triggered at the start of the positioning move at X+5.0000"),
            "{e}"
        );
        assert_eq!(m.positions().unwrap(), before);
    }
    m.move_to(&AxisPositions::linear([5.0, 5.0, 30.0]), 5000.0)
        .unwrap();
}

/// A positioning move that runs the stylus into material brakes with ProbeCollision
/// well within the probe's overtravel; retracting from there works.
pub fn positioning_into_material_is_a_collision<B: Backend>() {
    let mut m = B::open(&plane_scenario(10.0, 3.0));
    m.move_to(&AxisPositions::linear([0.0, 0.0, 40.0]), 5000.0)
        .unwrap();
    let e = m
        .move_to(&AxisPositions::linear([0.0, 0.0, 0.0]), 5000.0)
        .unwrap_err();
    assert_eq!(e.kind, ErrorKind::ProbeCollision, "{e}");
    let z = m.positions().unwrap().get(Axis::Z).unwrap();
    // Touching height is 13; braking from 5000 mm/min must end far above Z 8.
    assert!(z < 13.0 && z > 10.0, "stopped at Z {z}");
    m.move_to(&AxisPositions::linear([0.0, 0.0, 40.0]), 5000.0)
        .unwrap();
    // And the machine probes normally afterwards.
    let c = probe_down(&mut m, [0.0, 0.0, 20.0], 10.0).unwrap();
    assert_near("Z", c.positions.get(Axis::Z).unwrap(), 13.0, 1e-6);
}

/// Moves outside the software limits are refused before anything moves.
pub fn software_limits_refuse_before_moving<B: Backend>() {
    let mut m = B::open(&plane_scenario(-150.0, 3.0));
    let before = m.positions().unwrap();
    let e = m
        .move_to(&AxisPositions::linear([10_000.0, 0.0, 0.0]), 1000.0)
        .unwrap_err();
    assert_eq!(e.kind, ErrorKind::SoftwareLimit, "{e}");
    assert!(e.to_string().contains("X+10000"), "{e}");
    assert_eq!(m.positions().unwrap(), before);
    // A probing path that would run past the limit is refused too.
    let z = before.get(Axis::Z).unwrap();
    let e = m
        .probe(&ProbeMove {
            direction: [0.0, 0.0, 1.0],
            feed: 100.0,
            max_distance: 1000.0 - z,
        })
        .unwrap_err();
    assert_eq!(e.kind, ErrorKind::SoftwareLimit, "{e}");
    assert_eq!(m.positions().unwrap(), before);
    // A feed below the minimum, and a move that would take longer than any move may
    // (300 mm at 1 mm/min), are refused the same way on every backend.
    let inside = AxisPositions::linear([0.0, 0.0, z]);
    let e = m.move_to(&inside, 0.5).unwrap_err();
    assert_eq!(e.kind, ErrorKind::InvalidRequest, "{e}");
    let far = AxisPositions::linear([before.get(Axis::X).unwrap() + 300.0, 0.0, z]);
    let e = m.move_to(&far, 1.0).unwrap_err();
    assert_eq!(e.kind, ErrorKind::InvalidRequest, "{e}");
    assert_eq!(m.positions().unwrap(), before);
}

/// A move with linear and rotary axes arrives exactly.
pub fn move_arrives_on_all_axes<B: Backend>() {
    let mut m = B::open(&plane_scenario(-150.0, 3.0));
    let target = AxisPositions::linear([12.5, -7.25, 80.0])
        .with(Axis::A, -15.0)
        .with(Axis::C, 123.456);
    m.move_to(&target, 4000.0).unwrap();
    let p = m.positions().unwrap();
    for (a, v) in target.iter() {
        assert_near(a.name(), p.get(a).unwrap(), v, 1e-6);
    }
}

/// The machine's clock ([`Machine::clock_ns`], what the cycles' machine time is read
/// from) runs with the moves: a move advances it by what its profile takes, as
/// `check` predicts it, and by no more than the wall clock saw (a real-time bus), or a
/// few SYNC periods more (a virtual clock).
pub fn clock_runs_with_the_moves<B: Backend>() {
    let scenario = plane_scenario(-150.0, 3.0);
    let mut m = B::open(&scenario);
    let start = AxisPositions::linear([0.0, 0.0, 50.0]);
    m.move_to(&start, 5000.0).unwrap();
    let from = m.positions().unwrap();
    let to = AxisPositions::linear([25.0, 0.0, 50.0]);
    let model = cycles::machine_time::MotionModel::new(&crate::machine_config(&scenario));
    let want = model.move_s(&from, &to, 1500.0);
    let wall = std::time::Instant::now();
    let t0 = m.clock_ns();
    m.move_to(&to, 1500.0).unwrap();
    let t1 = m.clock_ns();
    let wall = wall.elapsed().as_secs_f64();
    let got = t1.saturating_sub(t0) as f64 * 1e-9;
    assert!(
        got >= 0.95 * want && got <= wall.max(1.05 * want) + 0.05,
        "the clock advanced {got:.4} s for a move of {want:.4} s (wall {wall:.4} s)"
    );
}

/// Rotary axes are latched with the linear ones: probing with C at 30 deg reports 30.
pub fn contact_latches_rotary_axes<B: Backend>() {
    let mut m = B::open(&plane_scenario(10.0, 3.0));
    m.move_to(
        &AxisPositions::linear([0.0, 0.0, 30.0]).with(Axis::C, 30.0),
        4000.0,
    )
    .unwrap();
    let c = m
        .probe(&ProbeMove {
            direction: [0.0, 0.0, -1.0],
            feed: 100.0,
            max_distance: 30.0,
        })
        .unwrap();
    assert_near("C", c.positions.get(Axis::C).unwrap(), 30.0, 1e-6);
    assert_near("A", c.positions.get(Axis::A).unwrap(), 0.0, 1e-6);
    assert_near("Z", c.positions.get(Axis::Z).unwrap(), 13.0, 1e-6);
}

/// The operator's stop brakes a move under way: the move fails as aborted with the
/// axes at rest past the point where the stop came and short of the target; while the
/// stop is raised no motion starts; once re-armed the same machine moves again.
pub fn abort_brakes_a_move_and_rearm_moves_again<B: Backend>() {
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::Arc;
    const STOP_PAST_X: f64 = -95.0;
    let abort = AbortFlag::fresh();
    let armed = Arc::new(AtomicBool::new(false));
    let watch: MotionWatch = {
        let armed = armed.clone();
        Arc::new(move |p: &AxisPositions| {
            if p.get(Axis::X).is_some_and(|x| x > STOP_PAST_X)
                && armed.swap(false, Ordering::AcqRel)
            {
                abort.raise();
            }
        })
    };
    let mut m = B::open_abortable(&plane_scenario(30.0, 3.0), abort, watch);
    let start = AxisPositions::linear([-100.0, 0.0, 50.0]);
    let target = AxisPositions::linear([250.0, 0.0, 50.0]);
    m.move_to(&start, 5000.0).unwrap();
    armed.store(true, Ordering::Release);
    let e = m.move_to(&target, 3000.0).unwrap_err();
    assert_eq!(e.kind, ErrorKind::Aborted, "{e}");
    assert!(abort.is_raised());
    let braked = m.positions().unwrap();
    let x = braked.get(Axis::X).unwrap();
    assert!(x > STOP_PAST_X && x < 240.0, "braked at X {x}");
    // At rest: asked again, the same place.
    assert_eq!(m.positions().unwrap(), braked);
    // No motion while the stop is raised.
    let e = m.move_to(&start, 5000.0).unwrap_err();
    assert_eq!(e.kind, ErrorKind::Aborted, "{e}");
    assert_eq!(m.positions().unwrap(), braked);
    // Re-armed: the next moves run to their end, and probing works.
    abort.rearm();
    m.move_to(&start, 5000.0).unwrap();
    assert_near(
        "X",
        m.positions().unwrap().get(Axis::X).unwrap(),
        -100.0,
        1e-6,
    );
    let c = probe_down(&mut m, [-100.0, 0.0, 40.0], 10.0).unwrap();
    assert_near("Z", c.positions.get(Axis::Z).unwrap(), 33.0, 1e-6);
}

/// True (after saying why on stderr) when `B` cannot run here.
pub fn skipped<B: Backend>(test: &str) -> bool {
    match B::available() {
        Ok(()) => false,
        Err(why) => {
            eprintln!("{test}: SKIPPED on this host: {why}");
            true
        }
    }
}

/// Instantiates the suite for a backend: `machine_conformance!(path::ToBackend);`
#[macro_export]
macro_rules! machine_conformance {
    ($backend:ty) => {
        $crate::machine_conformance!(@tests $backend:
            probes_plane_at_known_height,
            probes_sphere_along_oblique_direction,
            not_triggered_within_max_distance,
            deflected_at_start_moves_nothing,
            positioning_into_material_is_a_collision,
            moves_deeper_from_a_contact_are_refused,
            software_limits_refuse_before_moving,
            move_arrives_on_all_axes,
            contact_latches_rotary_axes,
            abort_brakes_a_move_and_rearm_moves_again,
            clock_runs_with_the_moves,
        );
    };
    (@tests $backend:ty: $($name:ident),* $(,)?) => {
        $(
            #[test]
            fn $name() {
                if $crate::conformance::skipped::<$backend>(stringify!($name)) {
                    return;
                }
                $crate::conformance::$name::<$backend>()
            }
        )*
    };
}
