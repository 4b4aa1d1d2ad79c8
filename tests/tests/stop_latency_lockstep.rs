//! The stop goes out in the cycle right after the first latch frame arrives: the
//! CANopen master and the simulated table-ac drives (five of them latching together)
//! on the in-process bus with wire time at 1 Mbit/s, on the virtual clock, where the
//! count is deterministic. Also: every contact is exact although its latch frames
//! take their wire time.

use hal::{AxisPositions, Machine, ProbeMove};
use probebridge_tests::conformance::{Backend, CanInproc};
use probebridge_tests::table_ac_plane;

#[test]
fn the_stop_goes_out_in_the_cycle_after_the_first_latch_frame_p99_le_1() {
    let sc = table_ac_plane(10.0, "");
    let mut m = CanInproc::open(&sc);
    let above = AxisPositions::linear([10.0, 10.0, 13.4]);
    let probe = ProbeMove {
        direction: [0.0, 0.0, -1.0],
        feed: 600.0,
        max_distance: 2.0,
    };
    let mut cycles = Vec::new();
    let mut worst = 0.0f64;
    for _ in 0..50 {
        m.move_to(&above, 3000.0).unwrap();
        let c = m.probe(&probe).unwrap();
        worst = worst.max((c.positions.get(hal::Axis::Z).unwrap() - 13.0).abs());
        let s = m.machine.stats();
        cycles.push(s.last_stop_latency_cycles);
        // The latch frame's arrival is stamped on the virtual clock: the stop is sent
        // less than a period after it.
        assert!(
            s.last_stop_latency_ns > 0 && s.last_stop_latency_ns < 2_000_000,
            "{s:?}"
        );
    }
    cycles.sort_unstable();
    let p99 = cycles[(cycles.len() * 99).div_ceil(100) - 1];
    println!(
        "stop latency over {} contacts: p50 {} cycle(s), p99 {p99}, worst contact error {worst:e} mm",
        cycles.len(),
        cycles[cycles.len() / 2 - 1]
    );
    assert!(cycles[0] >= 1, "counted: {cycles:?}");
    assert!(p99 <= 1, "stop latency p99 {p99} cycles: {cycles:?}");
    assert!(worst < 1e-6, "a contact was off by {worst} mm");
}
