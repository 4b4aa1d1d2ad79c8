//! The real-time loop allocates nothing: 10 000 probing moves (latch frame in, stop,
//! ContactSample out) with a counting global allocator. The master and the simulated
//! drives run in this one thread over a synchronous loopback bus, so every allocation
//! either of them makes is counted.

use hal::master::command::{Command, Reply};
use hal::master::{startup, LoopConfig, Pacing, RtLoop};
use hal::{ContactSample, SampleSink, SinkError};
use probebridge_tests::alloc_count::{count, Counting};
use probebridge_tests::loopback::Loopback;
use probebridge_tests::{machine_config, scenario};
use sim::machine::SimMachine;
use std::time::Duration;

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

fn until_reply(rt: &mut RtLoop<Loopback, Collect>) -> Reply {
    for _ in 0..100_000 {
        rt.cycle().expect("loopback does not fail");
        if let Some(r) = rt.take_reply() {
            return r;
        }
    }
    panic!("no reply within 100 000 cycles");
}

#[test]
fn ten_thousand_triggers_allocate_nothing() {
    let sc = scenario(
        r#"
machine = "table-ac"
[probe]
ball_radius = 3.0
[[plane]]
point = [0.0, 0.0, 10.0]
normal = [0.0, 0.0, 1.0]
"#,
    );
    let cfg = machine_config(&sc);
    let mut bus = Loopback::new(SimMachine::new(&sc));
    startup::boot(&mut bus, &cfg).unwrap();
    startup::configure(&mut bus, &cfg).unwrap();
    let pacing = Pacing::Lockstep {
        answer_timeout: Duration::from_millis(50),
    };
    let mut rt = RtLoop::new(
        &cfg,
        LoopConfig::from_machine(&cfg, pacing),
        bus,
        Collect::default(),
    );
    assert!(matches!(until_reply(&mut rt), Reply::Ready { .. }));

    let above = {
        let mut p = [0.0; 6];
        p[2] = 13.4;
        p
    };
    let cycle_once = |rt: &mut RtLoop<Loopback, Collect>| {
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
    };
    // One round outside the count: first use of thread-locals and the like.
    cycle_once(&mut rt);

    const TRIGGERS: u64 = 10_000;
    let published_before = rt.sink_mut().n;
    let (worst, counts) = count(|| {
        let mut worst = 0.0f64;
        for _ in 0..TRIGGERS {
            let s = cycle_once(&mut rt);
            worst = worst.max((s.positions[2] - 13.0).abs());
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
