//! The whole hot trigger path allocates nothing: 100 000 probing moves, each one a latch
//! frame in, the stop started in the same cycle, and a `ContactSample` published over
//! iceoryx2 by the sink the bridge really uses (`ContactPublisher`), in the real-time
//! thread itself (one hop), to a subscriber in another thread. Each probing move is
//! also announced (its window) and its contact's sample loaned before it starts.
//!
//! What is counted, precisely:
//! - **The real-time thread** (this test's thread): every allocation, reallocation and
//!   free while the triggers run, through a counting global allocator gated by a
//!   thread-local flag. This thread runs the master's `RtLoop` (frame decoding, CiA 402,
//!   the latch, the stop, building the sample, the window, the iceoryx2 loan, send and
//!   notify of `ContactPublisher`) *and* the
//!   simulated drives (the synchronous `Loopback` bus answers inside `transmit`), so
//!   their code is counted too. Asserted: 0 allocations, 0 frees.
//! - **All threads** (printed, not asserted): the same counters without the gate, over
//!   the same window: the subscriber thread's receive. (iceoryx2 0.10 would allocate
//!   an `Arc` per loan; the publisher's service flavour recycles it, see
//!   `probebridge::ipc::PooledSvc`.)
//!
//! The loop runs on the virtual clock (lockstep pacing) so 100 000 triggers take
//! seconds; the code on the hot path (`RtLoop::on_frame`, the latch, `RtLoop::tick`, the
//! sink) is the same under real-time pacing, whose driver only adds clock reads and
//! timed waits.

use probebridge::ipc::{ContactPublisher, ContactSubscriber};
use probebridge_tests::alloc_count::{count, Counting};
use probebridge_tests::probing_loop::{start, trigger, CONTACT_Z};
use probebridge_tests::unique_service;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

#[global_allocator]
static GLOBAL: Counting = Counting;

const TRIGGERS: u64 = 100_000;
/// The real-time thread waits (yielding, without allocating) when the subscriber is
/// this many contacts behind, so the subscriber buffer (1024 samples: a window and a
/// contact per trigger) cannot overflow on a busy machine.
const MAX_IN_FLIGHT: u64 = 256;

#[test]
fn hundred_thousand_triggers_published_by_the_rt_thread_allocate_nothing_there() {
    let service = unique_service("hotpath");

    // The estimator's side: a subscriber woken by the event, in its own thread.
    let received = Arc::new(AtomicU64::new(0));
    let worst = Arc::new(AtomicU64::new(0));
    let stop = Arc::new(AtomicBool::new(false));
    let subscriber = ContactSubscriber::new(&service).expect("subscriber");
    let sub_thread = {
        let (received, worst, stop) = (received.clone(), worst.clone(), stop.clone());
        std::thread::spawn(move || {
            while !stop.load(Ordering::Acquire) {
                if let Some(s) = subscriber
                    .receive_timeout(Duration::from_millis(50))
                    .expect("receive")
                {
                    let err_nm = ((s.positions[2] - CONTACT_Z).abs() * 1e6) as u64;
                    worst.fetch_max(err_nm, Ordering::Relaxed);
                    received.fetch_add(1, Ordering::Release);
                }
            }
        })
    };

    let sink = ContactPublisher::new(&service).expect("contact publisher");
    sink.update_connections().expect("connections");
    let mut rt = start(sink);

    // Warm-up outside the count: first use of thread-locals, iceoryx2 connections.
    trigger(&mut rt);
    let deadline = Instant::now() + Duration::from_secs(10);
    while received.load(Ordering::Acquire) < 1 && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(1));
    }
    assert_eq!(received.load(Ordering::Acquire), 1, "the warm-up sample");

    let published_before = rt.stats().samples_published;
    let started = Instant::now();
    let ((), counts) = count(|| {
        for n in 1..=TRIGGERS {
            let s = trigger(&mut rt);
            assert!(s.sequence > 0);
            // Back-pressure without allocating: yield while the subscriber lags.
            while n + 1 - received.load(Ordering::Acquire) > MAX_IN_FLIGHT {
                std::thread::yield_now();
            }
        }
    });
    let elapsed = started.elapsed();
    let (rt_allocs, rt_frees) = (counts.this_thread_allocs, counts.this_thread_frees);
    let (all_allocs, all_frees) = (counts.all_allocs, counts.all_frees);

    let stats = rt.stats();
    // Everything queued reaches the subscriber.
    let deadline = Instant::now() + Duration::from_secs(30);
    while received.load(Ordering::Acquire) < TRIGGERS + 1 && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(1));
    }
    stop.store(true, Ordering::Release);
    sub_thread.join().unwrap();
    let publisher = rt.sink_mut().stats();

    println!(
        "{TRIGGERS} triggers in {:.1} s ({} cycles): real-time thread {rt_allocs} allocations, \
         {rt_frees} frees; all threads {all_allocs} allocations, {all_frees} frees \
         ({:.2} per sample); {} samples received",
        elapsed.as_secs_f64(),
        stats.cycles,
        all_allocs as f64 / TRIGGERS as f64,
        received.load(Ordering::Acquire)
    );
    assert_eq!(
        stats.samples_published - published_before,
        TRIGGERS,
        "one sample per trigger"
    );
    assert_eq!(stats.publish_failures, 0);
    assert_eq!(publisher.failed, 0, "every publish succeeded");
    // One hop: each contact went out from the sample loaned when its move started.
    assert!(
        publisher.preloaned >= TRIGGERS,
        "{} of {TRIGGERS} contacts from a preloaned sample",
        publisher.preloaned
    );
    assert_eq!(
        received.load(Ordering::Acquire),
        TRIGGERS + 1,
        "every sample reached the subscriber"
    );
    let worst_nm = worst.load(Ordering::Relaxed);
    assert!(worst_nm <= 1, "a contact was off by {worst_nm} nm");
    assert_eq!(
        (rt_allocs, rt_frees),
        (0, 0),
        "the real-time thread allocated {rt_allocs} times and freed {rt_frees} times over {TRIGGERS} triggers"
    );
}
