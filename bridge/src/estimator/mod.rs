//! The estimator process: collects contact samples per run and answers fit requests.
//!
//! It sleeps in an iceoryx2 `WaitSet` on two events (`<prefix>/contacts/event`, a new
//! sample; `<prefix>/requests/event`, a new request) with a periodic timeout
//! ([`STOP_POLL`]) to look at the stop flag. During a probing move it may poll the
//! contact subscriber instead (the armed receive, [`armed`]).

use core::sync::atomic::{AtomicBool, Ordering};
use core::time::Duration;
use std::io::Write;

use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::server::Server;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use nalgebra::Vector3;

use hal::contact_sample::{FLAG_END_OF_RUN, FLAG_HW_LATCH};
use hal::ContactSample;

pub mod armed;
mod receive_times;

pub use armed::{watch, ArmedReceive, ArmedStats, WindowEnd, MAX_ARMED};
pub use receive_times::{ReceiveTime, ReceiveTimes};

use std::time::Instant;

use crate::ipc::{
    create_node, listener, notifier, open_event_service, open_request_service,
    remove_stale_resources, ContactSubscriber, EstimatorReply, EstimatorRequest, IpcError,
    ReplyStatus, RequestKind, ServiceNames, SphereResult, Svc,
};

/// Runs kept at most; a new run beyond this drops the oldest one (with a log line).
pub const MAX_RUNS: usize = 64;
/// Samples kept per run; later samples of the run are dropped (with one log line).
pub const MAX_SAMPLES_PER_RUN: usize = 4096;
/// How often the wait wakes up to look at the stop flag.
pub const STOP_POLL: Duration = Duration::from_millis(100);
/// How long start-up waits for another process that is cleaning the same dead node.
const CLEANUP_TIMEOUT: Duration = Duration::from_secs(1);

#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum EstimatorError {
    #[error(transparent)]
    Ipc(#[from] IpcError),
    #[error("estimator wait failed: {0}")]
    Wait(String),
}

/// Options of [`run_estimator_with`].
#[derive(Clone, Debug, Default)]
pub struct EstimatorOptions {
    /// One log line per received sample.
    pub verbose: bool,
    /// Stop on SIGINT/SIGTERM (iceoryx2 installs handlers for the whole process: only
    /// for the estimator process itself, not when it runs in a thread of the bridge).
    pub handle_signals: bool,
    /// Record when each sample arrived (for `probebridge bench trigger`): written to
    /// this file when the estimator stops, see [`ReceiveTimes`].
    pub record_times: Option<std::path::PathBuf>,
    /// Records kept in memory without reallocating (more are kept, at the cost of a
    /// reallocation in the receive path).
    pub record_capacity: usize,
    /// Poll for the contact during probing moves (config `[estimator] armed_receive`).
    pub armed_receive: ArmedReceive,
    /// Keep off this CPU (the real-time loop's, where it is pinned); `None`: anywhere.
    pub avoid_cpu: Option<usize>,
}

/// [`run_estimator_with`] with default options (quiet, no signal handlers).
pub fn run_estimator(
    prefix: &str,
    stop: &AtomicBool,
    log: impl Write,
) -> Result<(), EstimatorError> {
    run_estimator_with(prefix, &EstimatorOptions::default(), stop, log)
}

/// Serves the estimator on `prefix` until `stop` is set, a `Shutdown` request arrives
/// or (with `handle_signals`) SIGINT/SIGTERM. Log lines go to `log` (write errors are
/// ignored: losing the log must not stop the estimator).
pub fn run_estimator_with(
    prefix: &str,
    options: &EstimatorOptions,
    stop: &AtomicBool,
    mut log: impl Write,
) -> Result<(), EstimatorError> {
    let names = ServiceNames::new(prefix)?;

    let report = remove_stale_resources(CLEANUP_TIMEOUT)?;
    if report.dead_nodes > 0 {
        let _ = writeln!(
            log,
            "estimator: removed stale iceoryx2 resources of {} of {} dead node(s)",
            report.cleaned, report.dead_nodes
        );
    }
    for failure in &report.failed {
        let _ = writeln!(log, "estimator: could not clean up {failure}");
    }

    let node = create_node("probebridge-estimator")?;
    let server: Server<Svc, EstimatorRequest, (), EstimatorReply, ()> =
        open_request_service(&node, &names)?
            .server_builder()
            .create()
            .map_err(|e| {
                IpcError::iox(
                    "create the estimator server (is another estimator running on this prefix?)",
                    e,
                )
            })?;
    let request_listener = listener(&open_event_service(&node, &names.requests_event)?)?;
    let result_notifier = notifier(&open_event_service(&node, &names.results_event)?)?;
    let contacts = ContactSubscriber::with_node(node, prefix)?;

    let mode = if options.handle_signals {
        SignalHandlingMode::HandleTerminationRequests
    } else {
        SignalHandlingMode::Disabled
    };
    let waitset = WaitSetBuilder::new()
        .signal_handling_mode(mode)
        .create::<Svc>()
        .map_err(|e| IpcError::iox("create waitset", e))?;
    let _contact_guard = waitset
        .attach_notification(contacts.listener())
        .map_err(|e| IpcError::iox("attach the contact listener", e))?;
    let _request_guard = waitset
        .attach_notification(&request_listener)
        .map_err(|e| IpcError::iox("attach the request listener", e))?;

    let _ = writeln!(
        log,
        "estimator: serving {} (contacts on {}, requests on {})",
        names.prefix, names.contacts, names.requests
    );

    let armed = options.armed_receive.enabled();
    // Asleep or spinning, off the real-time loop's CPU where it has one.
    let cpus = options
        .avoid_cpu
        .map_or_else(|| "on any CPU".to_string(), armed::leave_cpu);
    let _ = writeln!(
        log,
        "estimator: armed receive {}",
        match (armed, options.armed_receive) {
            (true, _) => format!("on (polls the contacts during probing moves; {cpus})"),
            (false, ArmedReceive::Off) => format!("off (armed_receive = \"off\"; {cpus})"),
            (false, ArmedReceive::Auto) => format!("off (auto: no CPU to spare for it; {cpus})"),
        }
    );
    let mut intake = Intake {
        store: RunStore::default(),
        times: Vec::with_capacity(if options.record_times.is_some() {
            options.record_capacity
        } else {
            0
        }),
        record: options.record_times.is_some(),
        verbose: options.verbose,
    };
    let mut armed_stats = ArmedStats::default();
    let ports = Ports {
        contacts: &contacts,
        server: &server,
        request_listener: &request_listener,
        result_notifier: &result_notifier,
        waitset: &waitset,
    };
    let result = serve(
        &ports,
        options,
        armed.then_some(&mut armed_stats),
        stop,
        &mut intake,
        &mut log,
    );
    if armed {
        let s = armed_stats;
        let _ = writeln!(
            log,
            "estimator: armed windows {}: {} ended by the contact, {} by the move's end, {} timed out",
            s.windows, s.contacts, s.move_ends, s.timeouts
        );
    }
    let times = intake.times;
    if let Some(path) = &options.record_times {
        match ReceiveTimes::write(path, &times) {
            Ok(()) => {
                let _ = writeln!(
                    log,
                    "estimator: {} receive times written to {}",
                    times.len(),
                    path.display()
                );
            }
            Err(e) => {
                let _ = writeln!(log, "estimator: cannot write {}: {e}", path.display());
            }
        }
    }
    let _ = writeln!(log, "estimator: stopped");
    result
}

/// The estimator's ports.
struct Ports<'a> {
    contacts: &'a ContactSubscriber,
    server: &'a Server<Svc, EstimatorRequest, (), EstimatorReply, ()>,
    request_listener: &'a iceoryx2::port::listener::Listener<Svc>,
    result_notifier: &'a Notifier<Svc>,
    waitset: &'a WaitSet<Svc>,
}

/// Where received contacts go: the run store, and their receive times when recorded.
struct Intake {
    store: RunStore,
    times: Vec<ReceiveTime>,
    record: bool,
    verbose: bool,
}

impl Intake {
    fn take(&mut self, sample: &ContactSample, mut log: &mut dyn Write) {
        if self.record {
            self.times.push(ReceiveTime {
                run_id: sample.run_id,
                sequence: sample.sequence,
                trigger_ns: sample.trigger_ns,
                receive_ns: sample.receive_ns,
                publish_ns: sample.publish_ns,
                t1_ns: hal::clock::monotonic_ns(),
            });
        }
        self.store.add(sample, self.verbose, &mut log);
    }

    /// Everything the subscriber holds.
    fn drain(&mut self, contacts: &ContactSubscriber, log: &mut dyn Write) -> Result<(), IpcError> {
        while let Some(sample) = contacts.try_receive()? {
            self.take(&sample, &mut *log);
        }
        Ok(())
    }
}

/// The estimator's loop; `armed`: the armed receive is on, with its counters.
fn serve(
    ports: &Ports,
    options: &EstimatorOptions,
    mut armed: Option<&mut ArmedStats>,
    stop: &AtomicBool,
    intake: &mut Intake,
    log: &mut dyn Write,
) -> Result<(), EstimatorError> {
    let contacts = ports.contacts;
    while !stop.load(Ordering::Relaxed) {
        // The contact first, right after the wake-up: no syscall before it is read.
        // Then the wake-up events are consumed, and whatever arrived meanwhile is
        // read (its event is gone with them, so it would not wake the next wait).
        intake.drain(contacts, &mut *log)?;
        contacts.clear_events()?;
        ports
            .request_listener
            .try_wait(|_| {})
            .map_err(|e| IpcError::iox("read request events", e))?;
        intake.drain(contacts, &mut *log)?;
        if serve_requests(ports, intake, &mut *log)? {
            let _ = writeln!(log, "estimator: shutdown requested");
            break;
        }
        if let Some(stats) = armed.as_deref_mut() {
            // A probing move announced and not yet ended by its contact: poll.
            while let Some(window) = contacts.take_window() {
                watch(
                    window,
                    Instant::now(),
                    stats,
                    || contacts.try_receive(),
                    Instant::now,
                    |s| intake.take(s, &mut *log),
                )?;
            }
        }
        match ports
            .waitset
            .wait_and_process_once_with_timeout(|_| CallbackProgression::Continue, STOP_POLL)
        {
            Ok(WaitSetRunResult::TerminationRequest) | Ok(WaitSetRunResult::Interrupt)
                if options.handle_signals =>
            {
                let _ = writeln!(log, "estimator: signal received, stopping");
                break;
            }
            Ok(_) => {}
            Err(e) => return Err(EstimatorError::Wait(format!("{e:?}"))),
        }
    }
    Ok(())
}

/// Answers every pending request; true when one asked the estimator to shut down.
/// What it has to say of a request is written after the reply is sent: a log that
/// blocks (a full pipe, a stalled file system: a VM's shared folder once held a line
/// for over 10 s) must not hold up the answer a cycle waits for.
fn serve_requests(
    ports: &Ports,
    intake: &mut Intake,
    log: &mut dyn Write,
) -> Result<bool, EstimatorError> {
    let mut shutdown = false;
    while let Some(active) = ports
        .server
        .receive()
        .map_err(|e| IpcError::iox("receive request", e))?
    {
        let request = *active.payload();
        let mut said: Vec<u8> = Vec::new();
        // A request that was sent before the samples it is about were drained.
        if let Err(e) = intake.drain(ports.contacts, &mut said) {
            let _ = log.write_all(&said);
            return Err(e.into());
        }
        let mut reply = intake.store.answer(&request, &mut said);
        reply.server_pid = std::process::id();
        shutdown |= request.request_kind() == Some(RequestKind::Shutdown);
        let sent = active
            .loan_uninit()
            .map_err(|e| IpcError::iox("loan reply", e))
            .and_then(|r| {
                r.write_payload(reply)
                    .send()
                    .map_err(|e| IpcError::iox("send reply", e))
            });
        if let Err(e) = sent {
            let _ = writeln!(said, "estimator: {e}");
        }
        drop(active);
        notify(ports.result_notifier, &mut said);
        let _ = log.write_all(&said);
        let _ = log.flush();
    }
    Ok(shutdown)
}

fn notify(notifier: &Notifier<Svc>, log: &mut dyn Write) {
    if let Err(e) = notifier.notify() {
        let _ = writeln!(log, "estimator: could not notify the client: {e:?}");
    }
}

/// Samples of one run, in arrival order.
struct Run {
    run_id: u64,
    samples: Vec<ContactSample>,
    dropped: u64,
    closed: bool,
}

/// The bounded sample store: at most [`MAX_RUNS`] runs of [`MAX_SAMPLES_PER_RUN`].
#[derive(Default)]
struct RunStore {
    /// Oldest first.
    runs: Vec<Run>,
    last_sequence: Option<u64>,
    /// Cycle 451's identifications in progress.
    identify: crate::ipc::IdentifySessions,
}

impl RunStore {
    fn add(&mut self, s: &ContactSample, verbose: bool, log: &mut impl Write) {
        if verbose {
            let _ = writeln!(log, "{}", format_sample(s));
        }
        if let Some(last) = self.last_sequence {
            if s.sequence > last + 1 {
                let _ = writeln!(
                    log,
                    "estimator: {} sample(s) lost before sequence {} (buffer overflow?)",
                    s.sequence - last - 1,
                    s.sequence
                );
            }
        }
        self.last_sequence = Some(s.sequence);

        let idx = match self.runs.iter().position(|r| r.run_id == s.run_id) {
            Some(i) => i,
            None => {
                if self.runs.len() >= MAX_RUNS {
                    let old = self.runs.remove(0);
                    let _ = writeln!(
                        log,
                        "estimator: more than {MAX_RUNS} runs, dropped the oldest run {} ({} samples)",
                        old.run_id,
                        old.samples.len()
                    );
                }
                self.runs.push(Run {
                    run_id: s.run_id,
                    samples: Vec::new(),
                    dropped: 0,
                    closed: false,
                });
                self.runs.len() - 1
            }
        };
        let run = &mut self.runs[idx];
        if run.samples.len() >= MAX_SAMPLES_PER_RUN {
            if run.dropped == 0 {
                let _ = writeln!(
                    log,
                    "estimator: run {} has {MAX_SAMPLES_PER_RUN} samples, dropping further ones",
                    run.run_id
                );
            }
            run.dropped += 1;
        } else {
            run.samples.push(*s);
        }
        if s.flags & FLAG_END_OF_RUN != 0 && !run.closed {
            run.closed = true;
            let _ = writeln!(
                log,
                "estimator: run {} ended with {} samples",
                run.run_id,
                run.samples.len()
            );
        }
    }

    fn get(&self, run_id: u64) -> Option<&Run> {
        self.runs.iter().find(|r| r.run_id == run_id)
    }

    fn answer(&mut self, request: &EstimatorRequest, log: &mut impl Write) -> EstimatorReply {
        match request.request_kind() {
            Some(RequestKind::Ping) | Some(RequestKind::Shutdown) => {
                EstimatorReply::new(request, ReplyStatus::Ok)
            }
            Some(RequestKind::FitSphere) => {
                let result = self.fit_sphere(request.run_id);
                let _ = if result.ok {
                    writeln!(
                        log,
                        "estimator: run {} ball-centre sphere (radius = sphere Q407 + stylus R): centre ({:.6}, {:.6}, {:.6}) radius {:.6} rms {:.2e} from {} points",
                        result.run_id,
                        result.centre[0],
                        result.centre[1],
                        result.centre[2],
                        result.radius,
                        result.rms,
                        result.n_points
                    )
                } else {
                    writeln!(
                        log,
                        "estimator: run {} sphere fit failed: {} ({} points)",
                        result.run_id, result.error, result.n_points
                    )
                };
                result.to_reply(request)
            }
            Some(RequestKind::IdentifyData)
            | Some(RequestKind::Identify)
            | Some(RequestKind::IdentifyResult) => self.identify.answer(request, log),
            Some(RequestKind::Forget) => {
                match self.runs.iter().position(|r| r.run_id == request.run_id) {
                    Some(i) => {
                        let run = self.runs.remove(i);
                        let mut reply = EstimatorReply::new(request, ReplyStatus::Ok);
                        reply.n_points = run.samples.len() as u64;
                        reply
                    }
                    None => EstimatorReply::new(request, ReplyStatus::UnknownRun),
                }
            }
            None => {
                let _ = writeln!(log, "estimator: unknown request kind {}", request.kind);
                EstimatorReply::new(request, ReplyStatus::UnknownRequest)
            }
        }
    }

    fn fit_sphere(&self, run_id: u64) -> SphereResult {
        let Some(run) = self.get(run_id) else {
            return SphereResult::failed(run_id, 0, ReplyStatus::UnknownRun);
        };
        const XYZ: u32 = 0b111;
        let points: Vec<Vector3<f64>> = run
            .samples
            .iter()
            .filter(|s| s.axis_mask & XYZ == XYZ)
            .map(|s| Vector3::new(s.positions[0], s.positions[1], s.positions[2]))
            .collect();
        let n = points.len() as u64;
        match cycles::geometry::sphere_fit::fit_sphere(&points) {
            Ok(fit) => SphereResult {
                run_id,
                ok: true,
                centre: [fit.centre.x, fit.centre.y, fit.centre.z],
                radius: fit.radius,
                rms: fit.rms,
                max_residual: fit.max_residual,
                n_points: n,
                error: ReplyStatus::Ok,
            },
            Err(e) => SphereResult::failed(run_id, n, fit_error_status(&e)),
        }
    }
}

fn fit_error_status(e: &cycles::geometry::sphere_fit::FitError) -> ReplyStatus {
    use cycles::geometry::sphere_fit::FitError;
    match e {
        FitError::TooFewPoints(_) => ReplyStatus::TooFewPoints,
        FitError::NotFinite(_) => ReplyStatus::NotFinite,
        FitError::Degenerate(_) => ReplyStatus::Degenerate,
        FitError::NoConvergence { .. } => ReplyStatus::NoConvergence,
    }
}

/// One readable line per sample.
pub fn format_sample(s: &ContactSample) -> String {
    use core::fmt::Write as _;
    const NAMES: [&str; 6] = ["X", "Y", "Z", "A", "B", "C"];
    let mut line = format!(
        "contact #{} run {} t={:.6} ms (+{} ns to rx)",
        s.sequence,
        s.run_id,
        s.trigger_ns as f64 * 1e-6,
        s.receive_ns.saturating_sub(s.trigger_ns)
    );
    for (i, (name, v)) in NAMES.iter().zip(s.positions.iter()).enumerate() {
        if s.axis_mask & (1 << i) != 0 {
            let _ = write!(line, " {name}={v:.4}");
        }
    }
    let _ = write!(
        line,
        " dir=({:.4}, {:.4}, {:.4}) F{:.0}",
        s.direction[0], s.direction[1], s.direction[2], s.feed
    );
    if s.flags & FLAG_HW_LATCH != 0 {
        line.push_str(" latch");
    }
    if s.flags & FLAG_END_OF_RUN != 0 {
        line.push_str(" end-of-run");
    }
    line
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(seq: u64, run: u64, p: [f64; 3]) -> ContactSample {
        let mut s = ContactSample::zeroed();
        s.sequence = seq;
        s.run_id = run;
        s.positions[..3].copy_from_slice(&p);
        s.axis_mask = 0b111;
        s
    }

    #[test]
    fn store_is_bounded_and_drops_the_oldest_run() {
        let mut store = RunStore::default();
        let mut log = Vec::new();
        for run in 0..(MAX_RUNS as u64 + 1) {
            store.add(&sample(run, run, [0.0; 3]), false, &mut log);
        }
        assert_eq!(store.runs.len(), MAX_RUNS);
        assert!(store.get(0).is_none());
        assert!(store.get(MAX_RUNS as u64).is_some());
        let log = String::from_utf8(log).unwrap();
        assert!(log.contains("dropped the oldest run 0"), "{log}");

        let mut store = RunStore::default();
        let mut log = Vec::new();
        for i in 0..(MAX_SAMPLES_PER_RUN as u64 + 10) {
            store.add(&sample(i, 1, [0.0; 3]), false, &mut log);
        }
        assert_eq!(store.get(1).unwrap().samples.len(), MAX_SAMPLES_PER_RUN);
        assert_eq!(store.get(1).unwrap().dropped, 10);
    }

    #[test]
    fn gaps_in_the_sequence_are_logged() {
        let mut store = RunStore::default();
        let mut log = Vec::new();
        store.add(&sample(1, 1, [0.0; 3]), false, &mut log);
        store.add(&sample(5, 1, [0.0; 3]), false, &mut log);
        let log = String::from_utf8(log).unwrap();
        assert!(log.contains("3 sample(s) lost before sequence 5"), "{log}");
    }

    #[test]
    fn sample_line_is_readable() {
        let mut s = sample(3, 9, [1.5, -2.0, 30.25]);
        s.flags = FLAG_HW_LATCH | FLAG_END_OF_RUN;
        let line = format_sample(&s);
        assert!(line.starts_with("contact #3 run 9"), "{line}");
        assert!(line.contains("X=1.5000 Y=-2.0000 Z=30.2500"), "{line}");
        assert!(!line.contains(" A="), "{line}");
        assert!(line.ends_with("latch end-of-run"), "{line}");
    }
}
