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
