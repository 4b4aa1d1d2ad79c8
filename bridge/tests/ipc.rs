//! iceoryx2 IPC between the bridge and the estimator: contact samples, requests, the
//! estimator process, stale-resource cleanup.
//!
//! Every test uses its own service prefix, so tests run in parallel (and next to other
//! test processes) without seeing each other. Waiting is always on an event or a reply
//! with a deadline, never a fixed sleep.
//!
//! Some tests re-run this test binary as a child process (the `child_entry` test,
//! steered by the `PB_IPC_CHILD` environment variable) to get a second process: an
//! estimator process, or a process that dies holding iceoryx2 resources.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use hal::contact_sample::{ProbeWindow, FLAG_END_OF_RUN, FLAG_HW_LATCH};
use hal::{ContactSample, SampleSink};
use probebridge::estimator::{run_estimator, run_estimator_with, EstimatorOptions};
use probebridge::ipc::{
    remove_stale_resources, ContactPublisher, ContactSubscriber, EstimatorChild, EstimatorClient,
    EstimatorRequest, IpcError, ReplyStatus, ServiceNames, CONTACT_BUFFER,
};

const T: Duration = Duration::from_secs(10);

// ---------------------------------------------------------------------------------------
// Counting allocator (per thread, so parallel tests do not disturb the count).

struct Counting;

thread_local! {
    static ALLOCS: Cell<u64> = const { Cell::new(0) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCS.try_with(|c| c.set(c.get() + 1));
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let _ = ALLOCS.try_with(|c| c.set(c.get() + 1));
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn allocs() -> u64 {
    ALLOCS.with(|c| c.get())
}

// ---------------------------------------------------------------------------------------
// Helpers

fn unique_prefix(test: &str) -> String {
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    format!(
        "pbtest/{test}/{}/{}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    )
}

/// A received sample as it was sent: the publisher stamps `publish_ns` (checked set,
/// and no earlier than the sample's receive), the rest is the sender's.
fn as_sent(mut s: ContactSample) -> ContactSample {
    assert!(
        s.publish_ns >= s.receive_ns && s.publish_ns > 0,
        "publish_ns not stamped: {s:?}"
    );
    s.publish_ns = 0;
    s
}

fn sample(sequence: u64, run_id: u64, xyz: [f64; 3]) -> ContactSample {
    let mut s = ContactSample::zeroed();
    s.sequence = sequence;
    s.run_id = run_id;
    s.trigger_ns = 1_000_000 * sequence + 17;
    s.receive_ns = s.trigger_ns + 250_000;
    s.positions = [xyz[0], xyz[1], xyz[2], 0.5 * sequence as f64, -1.25, 90.0];
    s.direction = [0.0, 0.0, -1.0];
    s.feed = 150.0 + sequence as f64;
    s.axis_mask = 0b11_1111;
    s.flags = FLAG_HW_LATCH;
    s
}

/// `n` points spread over the upper half of a sphere (as a 451 cap would be, wider).
fn sphere_points(centre: [f64; 3], radius: f64, n: usize) -> Vec<[f64; 3]> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - (i as f64 + 0.5) / n as f64; // 1 .. 0: upper hemisphere
            let r = (1.0 - z * z).sqrt();
            let phi = golden * i as f64;
            [
                centre[0] + radius * r * phi.cos(),
                centre[1] + radius * r * phi.sin(),
                centre[2] + radius * z,
            ]
        })
        .collect()
}

/// The estimator in a thread of this process; stopped and joined on drop.
struct EstimatorThread {
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<String>>,
}

impl EstimatorThread {
    fn start(prefix: &str, verbose: bool) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let prefix = prefix.to_string();
        let flag = stop.clone();
        let handle = std::thread::spawn(move || {
            let mut log = Vec::new();
            let options = EstimatorOptions {
                verbose,
                handle_signals: false,
                ..EstimatorOptions::default()
            };
            let result = run_estimator_with(&prefix, &options, &flag, &mut log);
            let mut log = String::from_utf8(log).unwrap();
            if let Err(e) = result {
                log.push_str(&format!("ESTIMATOR ERROR: {e}\n"));
            }
            log
        });
        Self {
            stop,
            handle: Some(handle),
        }
    }

    fn stop(mut self) -> String {
        self.stop.store(true, Ordering::Relaxed);
        self.handle.take().unwrap().join().unwrap()
    }
}

impl Drop for EstimatorThread {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

// ---------------------------------------------------------------------------------------
// Contacts

#[test]
fn a_thousand_samples_arrive_complete_and_in_order() {
    let prefix = unique_prefix("thousand");
    let subscriber = ContactSubscriber::new(&prefix).unwrap();
    let mut publisher = ContactPublisher::new(&prefix).unwrap();

    let sent: Vec<ContactSample> = (0..1000u64)
        .map(|i| {
            sample(
                i + 1,
                1 + i / 100,
                [i as f64 * 0.001, -(i as f64), 1e6 / (i + 1) as f64],
            )
        })
        .collect();
    // All of them before the first receive: the subscriber buffer must hold a burst.
    assert!(sent.len() <= CONTACT_BUFFER);
    for s in &sent {
        SampleSink::publish(&mut publisher, s).unwrap();
    }
    let stats = publisher.stats();
    assert_eq!(stats.published, 1000);
    assert_eq!(stats.failed, 0);
    assert_eq!(stats.unreceived, 0);

    for (i, want) in sent.iter().enumerate() {
        let got = subscriber
            .receive_timeout(T)
            .unwrap()
            .unwrap_or_else(|| panic!("sample {i} did not arrive"));
        assert_eq!(&as_sent(got), want, "sample {i}");
    }
    assert_eq!(subscriber.try_receive().unwrap(), None);
}

#[test]
fn the_event_wakes_a_waiting_subscriber() {
    let prefix = unique_prefix("wake");
    let subscriber = ContactSubscriber::new(&prefix).unwrap();
    let mut publisher = ContactPublisher::new(&prefix).unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    let waiter = std::thread::spawn(move || {
        tx.send(()).unwrap();
        // Without the event this would sleep for the whole minute.
        let t0 = Instant::now();
        let got = subscriber.receive_timeout(Duration::from_secs(60)).unwrap();
        (got, t0.elapsed())
    });
    rx.recv().unwrap();
    let s = sample(1, 1, [1.0, 2.0, 3.0]);
    publisher.publish(&s).unwrap();
    let (got, waited) = waiter.join().unwrap();
    assert_eq!(got.map(as_sent), Some(s));
    assert!(
        waited < Duration::from_secs(30),
        "woke only after {waited:?}"
    );
}

/// What publish allocates, per sample, after construction: nothing. iceoryx2 0.10
/// creates an `Arc` per loan; the publisher's service flavour (`PooledSvc`) recycles
/// its block. Windows (each probing move's announcement and preloan) included.
#[test]
fn publish_allocates_nothing() {
    let prefix = unique_prefix("alloc");
    let subscriber = ContactSubscriber::new(&prefix).unwrap();
    let mut publisher = ContactPublisher::new(&prefix).unwrap();
    publisher.update_connections().unwrap();
    // Warm up: first send after connections, thread-locals of the logger and clock,
    // the first blocks of the recycling slots.
    for i in 0..10 {
        publisher.probing_move(window(i));
        publisher.publish(&sample(i, 1, [0.0; 3])).unwrap();
    }
    while subscriber.try_receive().unwrap().is_some() {}

    const N: u64 = 200;
    let s = sample(100, 1, [1.0, 2.0, 3.0]);
    let before = allocs();
    for i in 0..N {
        publisher.probing_move(window(i));
        publisher.publish(&s).unwrap();
        // Keep the subscriber buffer from filling (receive happens on this thread too,
        // so count it separately).
        let a = allocs();
        assert!(subscriber.try_receive().unwrap().is_some());
        let b = allocs();
        ALLOCS.with(|c| c.set(c.get() - (b - a)));
    }
    let during = allocs() - before;
    assert_eq!(
        during, 0,
        "publish allocated {during} times over {N} samples"
    );
    assert_eq!(publisher.stats().preloaned, N + 10);
}

fn window(i: u64) -> ProbeWindow {
    ProbeWindow {
        run_id: 1,
        start_ns: i,
        end_ns: i + 1_000_000,
    }
}

/// One hop: the publisher starts no thread of its own; the sample goes from the
/// caller's thread to the subscriber. Windows are not returned as samples, and a
/// contact ends its window.
#[test]
fn the_publisher_is_one_hop_and_windows_are_not_contacts() {
    let prefix = unique_prefix("onehop");
    // Its threads are counted in a child process that runs nothing else: here the
    // other tests' threads come and go meanwhile (they did, on a loaded CI machine).
    let out = child_command("publisher-threads", &format!("{prefix}-threads"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let counts: Vec<usize> = stdout
        .lines()
        .find_map(|l| l.split_once("PB_THREADS ").map(|(_, counts)| counts))
        .unwrap_or_else(|| panic!("no PB_THREADS line from the child: {stdout}"))
        .split(' ')
        .map(|n| n.parse().unwrap())
        .collect();
    assert_eq!(counts[1], counts[0], "the publisher started a thread");
    let subscriber = ContactSubscriber::new(&prefix).unwrap();
    let mut publisher = ContactPublisher::new(&prefix).unwrap();
    publisher.probing_move(window(5));
    assert_eq!(
        subscriber.try_receive().unwrap(),
        None,
        "a window is no contact"
    );
    assert_eq!(subscriber.take_window(), Some(window(5)));
    assert_eq!(subscriber.take_window(), None, "taken once");
    publisher.probing_move(window(6));
    publisher.publish(&sample(1, 1, [1.0, 0.0, 0.0])).unwrap();
    assert_eq!(
        subscriber.try_receive().unwrap().map(as_sent),
        Some(sample(1, 1, [1.0, 0.0, 0.0]))
    );
    assert_eq!(
        subscriber.take_window(),
        None,
        "the contact ended its window"
    );
    assert_eq!(publisher.stats().preloaned, 1);
}

// ---------------------------------------------------------------------------------------
// Estimator in a thread

#[test]
fn the_estimator_fits_a_sphere_and_answers_over_ipc() {
    let prefix = unique_prefix("fit");
    let estimator = EstimatorThread::start(&prefix, true);
    let client = EstimatorClient::connect(&prefix, T).unwrap();
    let mut publisher = ContactPublisher::new(&prefix).unwrap();
    publisher.update_connections().unwrap();

    let centre = [120.5, -40.25, 310.0];
    let radius = 12.5 + 1.5; // sphere + stylus ball
    let points = sphere_points(centre, radius, 25);
    let run = 4511;
    for (i, p) in points.iter().enumerate() {
        let mut s = sample(i as u64 + 1, run, *p);
        if i + 1 == points.len() {
            s.flags |= FLAG_END_OF_RUN;
        }
        publisher.publish(&s).unwrap();
    }
    // Another run on a different sphere must not mix in.
    for (i, p) in sphere_points([0.0; 3], 5.0, 8).iter().enumerate() {
        publisher
            .publish(&sample(100 + i as u64, run + 1, *p))
            .unwrap();
    }
    assert_eq!(publisher.stats().unreceived, 0);

    let r = client.fit_sphere(run, T).unwrap();
    assert!(r.ok, "{r:?}");
    assert_eq!(r.error, ReplyStatus::Ok);
    assert_eq!(r.run_id, run);
    assert_eq!(r.n_points, 25);
    for (got, want) in r.centre.iter().zip(centre) {
        assert!((got - want).abs() < 1e-9, "{r:?}");
    }
    assert!((r.radius - radius).abs() < 1e-9, "{r:?}");
    assert!(r.rms < 1e-9 && r.max_residual < 1e-9, "{r:?}");

    let r2 = client.fit_sphere(run + 1, T).unwrap();
    assert!(r2.ok && (r2.radius - 5.0).abs() < 1e-9, "{r2:?}");

    // Forget drops the run; afterwards it is unknown.
    assert_eq!(client.forget(run, T).unwrap(), (ReplyStatus::Ok, 25));
    let r = client.fit_sphere(run, T).unwrap();
    assert_eq!((r.ok, r.error), (false, ReplyStatus::UnknownRun));

    drop(publisher);
    drop(client);
    let log = estimator.stop();
    assert!(!log.contains("ESTIMATOR ERROR"), "{log}");
    assert!(
        log.contains("contact #1 run 4511"),
        "verbose sample line missing:\n{log}"
    );
    assert!(log.contains("run 4511 ended with 25 samples"), "{log}");
    assert!(log.contains("estimator: stopped"), "{log}");
}

/// A log that blocks, as a full pipe or a stalled file system does, at the first write
/// holding `stall_at` (it says so on `stalled`), until `release` says go.
struct StallingLog {
    stall_at: &'static str,
    release: std::sync::mpsc::Receiver<()>,
    stalled: Option<std::sync::mpsc::Sender<()>>,
    text: Vec<u8>,
}

impl std::io::Write for StallingLog {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if self.stalled.is_some() && String::from_utf8_lossy(buf).contains(self.stall_at) {
            if let Some(said) = self.stalled.take() {
                let _ = said.send(());
            }
            let _ = self.release.recv();
        }
        self.text.extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// The reply goes out before the estimator logs the fit: a log that blocks (the vcan
/// VM's shared folder once held a line for over 10 s) does not time the cycle out.
#[test]
fn a_log_that_blocks_does_not_hold_up_the_reply() {
    let prefix = unique_prefix("stalled-log");
    let stop = Arc::new(AtomicBool::new(false));
    let (stalled_tx, stalled) = std::sync::mpsc::channel();
    let (go, release) = std::sync::mpsc::channel();
    let handle = {
        let (stop, prefix) = (stop.clone(), prefix.clone());
        std::thread::spawn(move || {
            let mut log = StallingLog {
                stall_at: "ball-centre sphere",
                release,
                stalled: Some(stalled_tx),
                text: Vec::new(),
            };
            let options = EstimatorOptions {
                handle_signals: false,
                ..EstimatorOptions::default()
            };
            let result = run_estimator_with(&prefix, &options, &stop, &mut log);
            (result.map_err(|e| e.to_string()), log.text)
        })
    };
    let client = EstimatorClient::connect(&prefix, T).unwrap();
    let mut publisher = ContactPublisher::new(&prefix).unwrap();
    publisher.update_connections().unwrap();
    let run = 4512;
    let points = sphere_points([10.0, 20.0, 30.0], 14.0, 9);
    for (i, p) in points.iter().enumerate() {
        let mut s = sample(i as u64 + 1, run, *p);
        if i + 1 == points.len() {
            s.flags |= FLAG_END_OF_RUN;
        }
        publisher.publish(&s).unwrap();
    }
    // The log is released only after the reply is in: the reply cannot have waited
    // for it. Then the estimator does write the fit's line (and blocks there).
    let r = client.fit_sphere(run, T);
    let stalled = stalled.recv_timeout(T);
    go.send(()).unwrap();
    let r = r.unwrap();
    assert!(r.ok && (r.radius - 14.0).abs() < 1e-9, "{r:?}");
    assert!(stalled.is_ok(), "the fit's log line was never written");
    stop.store(true, Ordering::Relaxed);
    drop(publisher);
    drop(client);
    let (result, text) = handle.join().unwrap();
    result.unwrap();
    let text = String::from_utf8(text).unwrap();
    assert!(text.contains("run 4512 ball-centre sphere"), "{text}");
}

#[test]
fn unknown_runs_and_bad_requests_get_error_replies_not_hangs() {
    let prefix = unique_prefix("unknown");
    let _estimator = EstimatorThread::start(&prefix, false);
    let client = EstimatorClient::connect(&prefix, T).unwrap();

    let t0 = Instant::now();
    let r = client.fit_sphere(987_654, T).unwrap();
    assert!(!r.ok);
    assert_eq!(r.error, ReplyStatus::UnknownRun);
    assert_eq!(r.run_id, 987_654);
    assert!(t0.elapsed() < T / 2, "took {:?}", t0.elapsed());

    assert_eq!(
        client.forget(987_654, T).unwrap(),
        (ReplyStatus::UnknownRun, 0)
    );

    // Too few points is an answer too.
    let mut publisher = ContactPublisher::new(&prefix).unwrap();
    for i in 0..3 {
        publisher
            .publish(&sample(i + 1, 5, [i as f64, 0.0, 0.0]))
            .unwrap();
    }
    let r = client.fit_sphere(5, T).unwrap();
    assert_eq!(
        (r.ok, r.error, r.n_points),
        (false, ReplyStatus::TooFewPoints, 3)
    );

    // A request kind from a newer bridge.
    let mut future = EstimatorRequest::ping();
    future.kind = 999;
    let reply = client.request(future, T).unwrap();
    assert_eq!(reply.reply_status(), ReplyStatus::UnknownRequest);

    assert!(client.ping(T).unwrap() < T);
}

#[test]
fn without_an_estimator_requests_fail_fast() {
    let prefix = unique_prefix("none");
    let t0 = Instant::now();
    match EstimatorClient::connect(&prefix, Duration::from_millis(200)) {
        Err(IpcError::Timeout { .. }) => {}
        other => panic!("expected a timeout, got {other:?}"),
    }
    assert!(t0.elapsed() < Duration::from_secs(5));
    let client = EstimatorClient::open(&prefix).unwrap();
    match client.fit_sphere(1, T) {
        Err(IpcError::NoEstimator(p)) => assert_eq!(p, prefix),
        other => panic!("expected NoEstimator, got {other:?}"),
    }
}

#[test]
fn an_estimator_that_stops_does_not_leave_the_client_hanging() {
    let prefix = unique_prefix("stopped");
    let estimator = EstimatorThread::start(&prefix, false);
    let client = EstimatorClient::connect(&prefix, T).unwrap();
    let log = estimator.stop();
    assert!(log.contains("estimator: stopped"), "{log}");
    let t0 = Instant::now();
    match client.ping(Duration::from_secs(2)) {
        Err(IpcError::NoEstimator(_)) | Err(IpcError::Timeout { .. }) => {}
        other => panic!("expected an error, got {other:?}"),
    }
    assert!(t0.elapsed() < Duration::from_secs(5));
}

#[test]
fn a_second_estimator_on_the_same_prefix_is_refused() {
    let prefix = unique_prefix("second");
    let _first = EstimatorThread::start(&prefix, false);
    let _client = EstimatorClient::connect(&prefix, T).unwrap();
    let stop = AtomicBool::new(false);
    let mut log = Vec::new();
    let err = run_estimator(&prefix, &stop, &mut log).unwrap_err();
    assert!(
        err.to_string().contains("another estimator"),
        "unexpected error: {err}"
    );
}

#[test]
fn service_names_hang_off_the_prefix() {
    let n = ServiceNames::new("pb/x/").unwrap();
    assert_eq!(n.contacts, "pb/x/contacts");
    assert_eq!(n.contacts_event, "pb/x/contacts/event");
    assert_eq!(n.requests, "pb/x/requests");
    assert_eq!(n.results_event, "pb/x/results/event");
    assert!(ServiceNames::new("").is_err());
}

// ---------------------------------------------------------------------------------------
// Child processes and stale resources

const CHILD_ENV: &str = "PB_IPC_CHILD";

/// Not a test of its own: the body of child processes the other tests start. Without
/// `PB_IPC_CHILD` it does nothing.
#[test]
fn child_entry() {
    let Ok(role) = std::env::var(CHILD_ENV) else {
        return;
    };
    let (what, prefix) = role.split_once(':').expect("role:prefix");
    match what {
        "estimator" => {
            let stop = AtomicBool::new(false);
            run_estimator(prefix, &stop, std::io::stderr()).unwrap();
        }
        "publisher" => {
            let _publisher = ContactPublisher::new(prefix).unwrap();
            let _subscriber = ContactSubscriber::new(prefix).unwrap();
            println!("PB_READY");
            // Hold the resources until killed.
            loop {
                std::thread::park();
            }
        }
        "publisher-threads" => {
            // The threads of this process (libtest's, with one test thread) before
            // and after a publisher is made.
            let threads = || std::fs::read_dir("/proc/self/task").unwrap().count();
            let _subscriber = ContactSubscriber::new(prefix).unwrap();
            let before = threads();
            let _publisher = ContactPublisher::new(prefix).unwrap();
            println!("PB_THREADS {before} {}", threads());
        }
        "parent" => {
            let estimator = format!("{prefix}/estimator");
            let child = EstimatorChild::spawn_command(
                child_command("estimator", &estimator),
                &estimator,
                T,
            )
            .unwrap();
            println!("PB_PID {}", child.id());
            loop {
                std::thread::park();
            }
        }
        "pings-then-dies" => {
            // An estimator that answers pings (so it counts as started) and crashes
            // on any other request.
            use probebridge::ipc::{
                create_node, open_event_service, open_request_service, EstimatorReply, RequestKind,
            };
            let node = create_node("pb-test-mortal-estimator").unwrap();
            let names = ServiceNames::new(prefix).unwrap();
            let server = open_request_service(&node, &names)
                .unwrap()
                .server_builder()
                .create()
                .unwrap();
            let results = open_event_service(&node, &names.results_event)
                .unwrap()
                .notifier_builder()
                .create()
                .unwrap();
            loop {
                while let Some(active) = server.receive().unwrap() {
                    let request = *active.payload();
                    if request.request_kind() != Some(RequestKind::Ping) {
                        std::process::abort();
                    }
                    let mut reply = EstimatorReply::new(&request, ReplyStatus::Ok);
                    reply.server_pid = std::process::id();
                    active
                        .loan_uninit()
                        .unwrap()
                        .write_payload(reply)
                        .send()
                        .unwrap();
                    drop(active);
                    results.notify().unwrap();
                }
                std::thread::sleep(Duration::from_millis(1));
            }
        }
        other => panic!("unknown child role {other}"),
    }
}

fn child_command(role: &str, prefix: &str) -> Command {
    let mut c = Command::new(std::env::current_exe().unwrap());
    c.args(["child_entry", "--exact", "--nocapture", "--test-threads=1"])
        .env(CHILD_ENV, format!("{role}:{prefix}"));
    c
}

#[test]
fn stale_cleanup_succeeds_when_nothing_is_stale() {
    let report = remove_stale_resources(Duration::from_secs(1)).unwrap();
    assert_eq!(
        report.cleaned + report.failed.len(),
        report.dead_nodes,
        "{report:?}"
    );
    // Whatever was stale is gone now; a second pass has nothing to fail on.
    let again = remove_stale_resources(Duration::from_secs(1)).unwrap();
    assert!(again.failed.is_empty(), "{again:?}");
}

#[test]
fn stale_resources_of_a_killed_process_are_removed() {
    let prefix = unique_prefix("stale");
    let mut child = child_command("publisher", &prefix)
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let stdout = child.stdout.take().unwrap();
    let mut ready = false;
    for line in BufReader::new(stdout).lines() {
        if line.unwrap().contains("PB_READY") {
            ready = true;
            break;
        }
    }
    assert!(ready, "child never became ready");
    // The child's subscriber receives.
    let mut publisher = ContactPublisher::new(&prefix).unwrap();
    assert_eq!(publisher.send(&sample(1, 1, [0.0; 3])).unwrap(), 1);
    let pid = child.id();
    child.kill().unwrap(); // SIGKILL: no destructor runs
    child.wait().unwrap();
    // (Without a cleanup the dead subscriber stays registered and keeps "receiving".)

    // Other tests' estimators clean up at start too, so the count may be theirs: check
    // the outcome, not who did it.
    let report = remove_stale_resources(Duration::from_secs(2)).unwrap();
    assert!(report.failed.is_empty(), "{report:?}");
    assert_eq!(dead_nodes_of(pid), 0, "{report:?}");
    // The killed subscriber is gone from the service: a publisher sees nobody.
    assert_eq!(publisher.send(&sample(2, 1, [0.0; 3])).unwrap(), 0);
}

fn dead_nodes_of(pid: u32) -> usize {
    use iceoryx2::node::NodeView;
    use iceoryx2::prelude::*;
    let mut n = 0;
    Node::<probebridge::ipc::Svc>::list(Config::global_config(), |state| {
        if let NodeState::Dead(view) = state {
            if view
                .details()
                .as_ref()
                .is_some_and(|d| d.process_id().value() as u32 == pid)
            {
                n += 1;
            }
        }
        CallbackProgression::Continue
    })
    .unwrap();
    n
}

#[test]
fn an_estimator_child_process_answers_and_exits_on_drop() {
    let prefix = unique_prefix("child");
    let child =
        EstimatorChild::spawn_command(child_command("estimator", &prefix), &prefix, T).unwrap();
    let pid = child.id();

    let mut publisher = ContactPublisher::new(&prefix).unwrap();
    let centre = [-5.0, 7.0, 100.0];
    for (i, p) in sphere_points(centre, 20.0, 12).iter().enumerate() {
        publisher.publish(&sample(i as u64 + 1, 77, *p)).unwrap();
    }
    let r = child.client().fit_sphere(77, T).unwrap();
    assert!(r.ok, "{r:?}");
    assert!((r.radius - 20.0).abs() < 1e-9, "{r:?}");
    assert!((r.centre[2] - 100.0).abs() < 1e-9, "{r:?}");

    drop(child);
    // The child was reaped by drop: its /proc entry is gone.
    assert!(
        !std::path::Path::new(&format!("/proc/{pid}")).exists(),
        "estimator child {pid} still exists"
    );
}

#[test]
fn a_killed_estimator_ends_a_pending_request_at_once_not_at_its_timeout() {
    let prefix = unique_prefix("killed");
    let child =
        EstimatorChild::spawn_command(child_command("estimator", &prefix), &prefix, T).unwrap();
    // The ping of spawn told the client which process answers.
    let pid = child.id();
    // SAFETY: SIGKILL to the child we started.
    assert_eq!(unsafe { libc::kill(pid as i32, libc::SIGKILL) }, 0);
    // Without the liveness watch this would end as a Timeout after a minute.
    match child.client().fit_sphere(1, Duration::from_secs(60)) {
        Err(IpcError::Died { pid: p, what, .. }) => {
            assert_eq!(p, pid);
            assert_eq!(what, "a sphere fit request");
        }
        other => panic!("expected the estimator's death, got {other:?}"),
    }
    // Dropping the handle neither hangs nor leaves the zombie behind.
    drop(child);
    assert!(!std::path::Path::new(&format!("/proc/{pid}")).exists());
}

/// A process that ends before it answers is said at once (a `run` then computes 451
/// in its own process and says why), not after the start timeout.
#[test]
fn an_estimator_that_exits_before_answering_is_said_at_once() {
    let prefix = unique_prefix("exits");
    let t0 = Instant::now();
    let Err(e) = EstimatorChild::spawn_command(Command::new("true"), &prefix, T) else {
        panic!("nothing answers, yet the start succeeded");
    };
    assert!(e.to_string().contains("exited before answering"), "{e}");
    assert!(t0.elapsed() < T, "noticed at once, not at the timeout");
}

/// A process that never answers: a timeout that names the prefix, and the process is
/// not left behind.
#[test]
fn an_estimator_that_never_answers_times_out_and_is_killed() {
    let prefix = unique_prefix("silent");
    // A duration nobody else uses, to find the process afterwards.
    let marker = format!("{}.{}", 600 + std::process::id() % 100, line!());
    let mut sleeper = Command::new("sleep");
    sleeper.arg(&marker);
    let timeout = Duration::from_millis(300);
    let t0 = Instant::now();
    let Err(e) = EstimatorChild::spawn_command(sleeper, &prefix, timeout) else {
        panic!("nothing answers, yet the start succeeded");
    };
    assert!(matches!(e, IpcError::Timeout { .. }), "{e:?}");
    assert!(e.to_string().contains(&prefix), "{e}");
    assert!(t0.elapsed() >= timeout);
    let left: Vec<_> = std::fs::read_dir("/proc")
        .unwrap()
        .filter_map(|d| std::fs::read(d.ok()?.path().join("cmdline")).ok())
        .filter(|c| c.split(|b| *b == 0).any(|a| a == marker.as_bytes()))
        .collect();
    assert!(left.is_empty(), "the silent process was left running");
}

/// Contacts on a sphere of radius 20 around (0, 0, 100), as a cycle holds them.
fn sphere_contacts() -> Vec<hal::Contact> {
    let mut out = Vec::new();
    for (i, (a, b)) in [
        (0.0f64, 0.0f64),
        (90.0, 0.0),
        (180.0, 0.0),
        (270.0, 0.0),
        (0.0, 60.0),
        (120.0, 45.0),
    ]
    .into_iter()
    .enumerate()
    {
        let (a, b) = (a.to_radians(), b.to_radians());
        let p = [
            20.0 * b.cos() * a.cos(),
            20.0 * b.cos() * a.sin(),
            100.0 + 20.0 * b.sin(),
        ];
        out.push(hal::Contact {
            positions: hal::AxisPositions::linear(p),
            trigger_ns: i as u64,
            sequence: i as u64 + 1,
            direction: [0.0, 0.0, -1.0],
        });
    }
    out
}

/// The estimator child died (killed here, before the request): the request finds
/// it dead, starts it again, sends the run's contacts again and gets the same sphere.
#[test]
fn a_dead_estimator_child_is_restarted_and_the_request_repeated() {
    use cycles::kinematics::Estimator;
    let prefix = unique_prefix("restart");
    let mut child =
        EstimatorChild::spawn_command(child_command("estimator", &prefix), &prefix, T).unwrap();
    let first = child.id();
    // SAFETY: SIGKILL to the child we started.
    assert_eq!(unsafe { libc::kill(first as i32, libc::SIGKILL) }, 0);
    let contacts = sphere_contacts();
    let mut est = probebridge::ipc::IpcEstimator::restartable(&mut child, T);
    let fit = est.fit_sphere(42, &contacts).unwrap();
    assert_eq!(est.restarts, 1);
    assert!((fit.radius - 20.0).abs() < 1e-9, "{fit:?}");
    assert!((fit.centre.z - 100.0).abs() < 1e-9, "{fit:?}");
    drop(est);
    assert_ne!(child.id(), first, "a new process serves");
    assert!(!std::path::Path::new(&format!("/proc/{first}")).exists());
}

/// A restarted estimator that dies again in the same request: the request fails and
/// says so; there is no third try.
#[test]
fn a_second_death_in_the_same_request_fails_it_clearly() {
    use cycles::kinematics::Estimator;
    let prefix = unique_prefix("restart2");
    let mut child =
        EstimatorChild::spawn_command(child_command("pings-then-dies", &prefix), &prefix, T)
            .unwrap();
    // SAFETY: SIGKILL to the child we started.
    assert_eq!(unsafe { libc::kill(child.id() as i32, libc::SIGKILL) }, 0);
    let mut est = probebridge::ipc::IpcEstimator::restartable(&mut child, T);
    let t0 = Instant::now();
    // The restarted one crashes on the repeated request.
    let e = est
        .fit_sphere(43, &sphere_contacts())
        .unwrap_err()
        .to_string();
    assert_eq!(est.restarts, 1);
    assert!(e.contains("already been restarted once"), "{e}");
    assert!(t0.elapsed() < T, "noticed at once, not at the timeout");
}

#[test]
fn the_estimator_child_dies_with_a_killed_parent() {
    let prefix = unique_prefix("orphan");
    let mut parent = child_command("parent", &prefix)
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(parent.stdout.take().unwrap()).lines();
    let pid: i32 = loop {
        let line = lines.next().expect("the parent's estimator pid").unwrap();
        // libtest may have printed "test child_entry ... " on the same line.
        if let Some((_, p)) = line.split_once("PB_PID ") {
            break p.trim().parse().unwrap();
        }
    };
    // SAFETY: pidfd_open of the grandchild, which is running.
    let fd = unsafe { libc::syscall(libc::SYS_pidfd_open, pid, 0) } as i32;
    assert!(fd >= 0, "pidfd_open: {}", std::io::Error::last_os_error());
    parent.kill().unwrap();
    parent.wait().unwrap();
    let mut p = libc::pollfd {
        fd,
        events: libc::POLLIN,
        revents: 0,
    };
    // SAFETY: one pollfd we own; returns when the estimator ends, or after 20 s.
    let ended = unsafe { libc::poll(&mut p, 1, 20_000) };
    // SAFETY: closing the descriptor we opened.
    unsafe { libc::close(fd) };
    assert_eq!(ended, 1, "the orphaned estimator {pid} is still running");
    let _ = probebridge::ipc::remove_stale_resources(T);
}

#[test]
fn an_estimator_child_that_cannot_start_is_reported() {
    let prefix = unique_prefix("nochild");
    let mut c = Command::new("/bin/false");
    c.arg("estimator");
    let t0 = Instant::now();
    match EstimatorChild::spawn_command(c, &prefix, T) {
        Err(IpcError::Process(msg)) => assert!(msg.contains("exited"), "{msg}"),
        other => panic!("expected a process error, got {other:?}"),
    }
    assert!(t0.elapsed() < T / 2);
}
