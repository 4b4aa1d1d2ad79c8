//! The real-time loop allocates nothing: 10 000 probing moves (latch frame in, stop,
//! ContactSample out) with a counting global allocator. The master and the simulated
//! drives run in this one thread over a synchronous loopback bus, so every allocation
//! either of them makes is counted.

use hal::{ContactSample, SampleSink, SinkError};
use probebridge_tests::alloc_count::{count, Counting};
use probebridge_tests::probing_loop::{start, trigger, CONTACT_Z};

#[global_allocator]
static GLOBAL: Counting = Counting;

#[derive(Default)]
struct Collect {
    n: u64,
    last: Option<ContactSample>,
}

impl SampleSink for Collect {
    fn publish(&mut self, s: &ContactSample) -> Result<(), SinkError> {
        self.n += 1;
        self.last = Some(*s);
        Ok(())
    }
}

#[test]
fn ten_thousand_triggers_allocate_nothing() {
    let mut rt = start(Collect::default());
    // One round outside the count: first use of thread-locals and the like.
    trigger(&mut rt);

    const TRIGGERS: u64 = 10_000;
    let published_before = rt.sink_mut().n;
    let (worst, counts) = count(|| {
        let mut worst = 0.0f64;
        for _ in 0..TRIGGERS {
            let s = trigger(&mut rt);
            worst = worst.max((s.positions[2] - CONTACT_Z).abs());
        }
        worst
    });
    let allocations = counts.this_thread_allocs + counts.this_thread_frees;

    assert_eq!(
        rt.sink_mut().n - published_before,
        TRIGGERS,
        "one sample per trigger"
    );
    assert!(worst < 1e-6, "a contact was off by {worst} mm");
    assert_eq!(
        allocations, 0,
        "the real-time loop allocated {allocations} times over {TRIGGERS} triggers"
    );
    println!(
        "{TRIGGERS} triggers, {} cycles, {allocations} allocations",
        rt.stats().cycles
    );
}

/// The in-process bus with wire time allocates nothing either: a SYNC period's
/// traffic (five RPDO1 and SYNC out, five TPDO2 and TPDO1 back) scheduled by id on
/// both clocks, sent and received in this thread.
#[test]
fn the_wire_time_bus_allocates_nothing() {
    use hal::can::inproc::{InprocBus, WireClock};
    use hal::can::{CanFrame, CanTransport};
    use std::time::Duration;

    let master_frames: Vec<CanFrame> = (1..=5u16)
        .map(|n| CanFrame::new(0x200 + n, &[0x0F, 0, 1, 2, 3, 4]).unwrap())
        .chain([CanFrame::new(0x080, &[]).unwrap()])
        .collect();
    let drive_frames: Vec<CanFrame> = (1..=5u16)
        .flat_map(|n| {
            [
                CanFrame::new(0x280 + n, &[0x83, 0, 1, 2, 3, 4]).unwrap(),
                CanFrame::new(0x180 + n, &[0x37, 0x12, 1, 2, 3, 4]).unwrap(),
            ]
        })
        .collect();
    for (clock, rounds) in [(WireClock::Virtual, 10_000u64), (WireClock::Monotonic, 200)] {
        let bus = InprocBus::with_wire_time(1_000_000, clock);
        let mut master = bus.endpoint();
        let mut drives = bus.endpoint_for_devices();
        let mut period = |k: u64| {
            master.advance_virtual_clock(k * 2_000_000);
            master.transmit_all(&master_frames).unwrap();
            for _ in &master_frames {
                drives.receive(Duration::from_secs(5)).unwrap().unwrap();
            }
            drives.transmit_all(&drive_frames).unwrap();
            for _ in &drive_frames {
                master.receive(Duration::from_secs(5)).unwrap().unwrap();
            }
            master.arrival_ns().unwrap()
        };
        period(0);
        let (last, counts) = count(|| (1..=rounds).map(&mut period).last());
        let allocations = counts.this_thread_allocs + counts.this_thread_frees;
        assert!(last.is_some());
        assert_eq!(
            allocations, 0,
            "{clock:?}: the bus allocated {allocations} times over {rounds} periods"
        );
    }
}
