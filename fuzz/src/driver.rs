//! The driver: runs a target on its seeds, then on mutations of its corpus until the
//! time or the iteration budget is spent. Each input runs under `catch_unwind` with a
//! quiet panic hook that records where it panicked; an input whose thread CPU time
//! exceeds the timeout is a finding too (CPU, not wall time: the runs share a busy
//! machine). A watchdog ends the process when one input runs far beyond it (a hang),
//! and an abort (stack overflow, failed allocation) writes the input before the
//! process dies. Every finding is saved as a file that `--reproduce` replays.
//!
//! There is no coverage instrumentation on stable: an input is kept when its outcome
//! has a signature (the error, with numbers and quoted text blanked; the events of a
//! frame sequence) no earlier input had, which steers the mutations towards every
//! error a parser can give.

use crate::mutate::{self, Context};
use crate::rng::Rng;
use crate::sig::{fnv, Sig};
use std::cell::{Cell, RefCell};
use std::collections::{HashMap, HashSet};
use std::ffi::CString;
use std::panic::{self, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, Once};
use std::time::{Duration, Instant};

/// One fuzz target.
pub struct Target {
    pub name: &'static str,
    pub about: &'static str,
    /// The longest input tried, bytes.
    pub max_len: usize,
    /// Loads what the target needs (machine configurations) before the first input.
    pub prepare: fn(),
    pub seeds: fn() -> Vec<Vec<u8>>,
    /// Tokens for the mutator besides the words of the seeds.
    pub dictionary: &'static [&'static str],
    /// Runs one input; returns the features of its outcome.
    pub run: fn(&[u8]) -> Sig,
}

/// How long and how a target runs.
#[derive(Clone, Debug)]
pub struct Budget {
    /// Wall-clock seconds of mutated inputs (after the seeds).
    pub seconds: f64,
    /// Stop after this many mutated inputs, if sooner.
    pub iterations: Option<u64>,
    pub seed: u64,
    /// CPU time of one input beyond which it is a finding.
    pub timeout: Duration,
    /// CPU time of one input beyond which the watchdog ends the process.
    pub hang: Duration,
    /// Where findings are saved (`DIR/TARGET/KIND-HASH`); `None`: kept in the report only.
    pub crash_dir: Option<PathBuf>,
    pub max_corpus: usize,
    /// A status line on stderr every minute.
    pub progress: bool,
}

impl Default for Budget {
    fn default() -> Self {
        Self {
            seconds: 60.0,
            iterations: None,
            seed: 0,
            timeout: Duration::from_secs(1),
            hang: Duration::from_secs(20),
            crash_dir: None,
            max_corpus: 4096,
            progress: false,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FindingKind {
    Panic,
    /// One input took longer than the timeout.
    Slow,
}

impl FindingKind {
    pub fn name(self) -> &'static str {
        match self {
            FindingKind::Panic => "panic",
            FindingKind::Slow => "slow",
        }
    }
}

#[derive(Clone, Debug)]
pub struct Finding {
    pub kind: FindingKind,
    /// The panic message, or the time taken.
    pub message: String,
    /// `file:line:column` of the panic.
    pub location: String,
    pub input: Vec<u8>,
    pub saved: Option<PathBuf>,
}

impl std::fmt::Display for Finding {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} at {}: {}",
            self.kind.name(),
            self.location,
            self.message
        )?;
        match &self.saved {
            Some(p) => write!(f, " (input: {})", p.display()),
            None => write!(f, " (input: {:?})", String::from_utf8_lossy(&self.input)),
        }
    }
}

#[derive(Clone, Debug)]
pub struct Report {
    pub target: &'static str,
    pub seconds: f64,
    /// Inputs run, seeds included.
    pub executions: u64,
    pub seeds: usize,
    /// Mutated inputs kept in the corpus for a new feature (seeds not counted).
    pub kept: usize,
    pub findings: Vec<Finding>,
}

impl std::fmt::Display for Report {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "RESULT target={} seconds={:.1} execs={} execs_per_s={:.0} seeds={} kept={} findings={}",
            self.target,
            self.seconds,
            self.executions,
            self.executions as f64 / self.seconds.max(1e-9),
            self.seeds,
            self.kept,
            self.findings.len()
        )
    }
}

thread_local! {
    /// Set while an input runs on this thread: its panics are recorded, not printed.
    static CAPTURE: Cell<bool> = const { Cell::new(false) };
    static LAST_PANIC: RefCell<Option<(String, String)>> = const { RefCell::new(None) };
}

/// The input running now and the file an abort writes it to (read by the signal
/// handler, which may only try the locks).
static CURRENT_INPUT: Mutex<Vec<u8>> = Mutex::new(Vec::new());
static ABORT_FILE: Mutex<Option<CString>> = Mutex::new(None);

fn install_hooks() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let previous = panic::take_hook();
        panic::set_hook(Box::new(move |info| {
            if !CAPTURE.with(Cell::get) {
                return previous(info);
            }
            let location = info
                .location()
                .map(|l| format!("{}:{}:{}", l.file(), l.line(), l.column()))
                .unwrap_or_else(|| "unknown".into());
            let payload = info.payload();
            let message = payload
                .downcast_ref::<&str>()
                .copied()
                .or_else(|| payload.downcast_ref::<String>().map(String::as_str))
                .unwrap_or("(non-string payload)");
            LAST_PANIC.with(|p| *p.borrow_mut() = Some((message.to_string(), location)));
        }));
        // SAFETY: installs a handler that only calls async-signal-safe functions
        // (open, write, close, signal, raise) and never blocks on a lock.
        unsafe {
            libc::signal(libc::SIGABRT, on_abort as *const () as libc::sighandler_t);
        }
    });
}

extern "C" fn on_abort(_: libc::c_int) {
    if let (Ok(input), Ok(path)) = (CURRENT_INPUT.try_lock(), ABORT_FILE.try_lock()) {
        if let Some(path) = path.as_ref() {
            // SAFETY: plain system calls on a valid NUL-terminated path and buffer.
            unsafe {
                let fd = libc::open(
                    path.as_ptr(),
                    libc::O_WRONLY | libc::O_CREAT | libc::O_TRUNC,
                    0o644,
                );
                if fd >= 0 {
                    libc::write(fd, input.as_ptr().cast(), input.len());
                    libc::close(fd);
                }
                let note = b"\nprobebridge-fuzz: aborted; the input is in the abort file of the crash folder\n";
                libc::write(2, note.as_ptr().cast(), note.len());
            }
        }
    }
    // SAFETY: back to the default action, then die of the same signal.
    unsafe {
        libc::signal(libc::SIGABRT, libc::SIG_DFL);
        libc::raise(libc::SIGABRT);
    }
}

/// CPU time of a thread's clock, ns.
fn cpu_ns(clock: libc::clockid_t) -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid out-pointer; `clock` came from pthread_getcpuclockid.
    unsafe { libc::clock_gettime(clock, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

fn this_thread_clock() -> libc::clockid_t {
    let mut clock: libc::clockid_t = libc::CLOCK_THREAD_CPUTIME_ID;
    // SAFETY: asks for the CPU clock of the calling thread into a valid out-pointer.
    unsafe { libc::pthread_getcpuclockid(libc::pthread_self(), &mut clock) };
    clock
}

const IDLE: u64 = u64::MAX;

/// What the watchdog sees of the fuzzing thread.
struct Watch {
    clock: libc::clockid_t,
    /// CPU time at the start of the running input; `IDLE` between inputs.
    started: AtomicU64,
    done: AtomicBool,
}

fn watchdog(watch: Arc<Watch>, hang: Duration, target: &'static str, dir: Option<PathBuf>) {
    while !watch.done.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(100));
        let started = watch.started.load(Ordering::Relaxed);
        if started == IDLE || cpu_ns(watch.clock).saturating_sub(started) < hang.as_nanos() as u64 {
            continue;
        }
        let input = CURRENT_INPUT.lock().map(|i| i.clone()).unwrap_or_default();
        let finding = Finding {
            kind: FindingKind::Slow,
            message: format!("hang: still running after {} s of CPU", hang.as_secs()),
            location: "-".into(),
            saved: dir
                .as_deref()
                .and_then(|d| save(d, target, "hang", &input, "hang")),
            input,
        };
        eprintln!("FINDING target={target} {finding}");
        eprintln!("RESULT target={target} hang=1 findings=1");
        std::process::exit(1);
    }
}

/// Writes a finding's input (and a note beside it); the input's path.
fn save(dir: &Path, target: &str, kind: &str, input: &[u8], note: &str) -> Option<PathBuf> {
    let dir = dir.join(target);
    std::fs::create_dir_all(&dir).ok()?;
    let path = dir.join(format!("{kind}-{:016x}", fnv(input)));
    std::fs::write(&path, input).ok()?;
    let text = format!(
        "{note}\n\nreplay: probebridge-fuzz {target} --reproduce {}\n",
        path.display()
    );
    std::fs::write(path.with_extension("txt"), text).ok()?;
    Some(path)
}

enum Outcome {
    Ok { features: Vec<u64>, cpu: Duration },
    Panicked { message: String, location: String },
}

fn exec(target: &Target, input: &[u8], watch: &Watch) -> Outcome {
    if let Ok(mut current) = CURRENT_INPUT.lock() {
        current.clear();
        current.extend_from_slice(input);
    }
    let before = cpu_ns(watch.clock);
    watch.started.store(before, Ordering::Relaxed);
    CAPTURE.with(|c| c.set(true));
    let result = panic::catch_unwind(AssertUnwindSafe(|| (target.run)(input)));
    CAPTURE.with(|c| c.set(false));
    watch.started.store(IDLE, Ordering::Relaxed);
    let cpu = Duration::from_nanos(cpu_ns(watch.clock).saturating_sub(before));
    match result {
        Ok(sig) => Outcome::Ok {
            features: sig.features(),
            cpu,
        },
        Err(_) => {
            let (message, location) = LAST_PANIC
                .with(|p| p.borrow_mut().take())
                .unwrap_or_else(|| ("(no message)".into(), "unknown".into()));
            Outcome::Panicked { message, location }
        }
    }
}

/// Runs `target` within `budget`.
pub fn run(target: &Target, budget: &Budget) -> Report {
    install_hooks();
    (target.prepare)();
    if let (Some(dir), Ok(mut file)) = (&budget.crash_dir, ABORT_FILE.lock()) {
        let d = dir.join(target.name);
        let _ = std::fs::create_dir_all(&d);
        *file = CString::new(d.join("abort-input").into_os_string().into_encoded_bytes()).ok();
    }
    let watch = Arc::new(Watch {
        clock: this_thread_clock(),
        started: AtomicU64::new(IDLE),
        done: AtomicBool::new(false),
    });
    let dog = {
        let (w, hang, dir) = (watch.clone(), budget.hang, budget.crash_dir.clone());
        let name: &'static str = target.name;
        std::thread::spawn(move || watchdog(w, hang, name, dir))
    };
    let mut run = Run {
        target,
        budget,
        watch: &watch,
        corpus: Vec::new(),
        seen: HashSet::new(),
        places: HashMap::new(),
        findings: Vec::new(),
        executions: 0,
        kept: 0,
    };
    let start = Instant::now();
    let mut seeds = (target.seeds)();
    if seeds.is_empty() {
        seeds.push(Vec::new());
    }
    seeds.iter_mut().for_each(|s| s.truncate(target.max_len));
    let dictionary = mutate::tokens_of(&seeds, target.dictionary);
    for s in &seeds {
        run.one(s.clone(), true);
    }
    let seed_count = run.corpus.len();
    let mut rng = Rng::new(budget.seed);
    let deadline = start + Duration::from_secs_f64(budget.seconds.max(0.0));
    let mut mutated = 0u64;
    let mut next_status = start + Duration::from_secs(60);
    while Instant::now() < deadline && budget.iterations.is_none_or(|n| mutated < n) {
        let parent = &run.corpus[rng.below(run.corpus.len())];
        let cx = Context {
            corpus: &run.corpus,
            dictionary: &dictionary,
            max_len: target.max_len,
        };
        let child = mutate::mutate(&mut rng, parent, &cx);
        if run.one(child, false) && run.corpus.len() > budget.max_corpus {
            // Full: the newcomer replaces a random earlier non-seed entry.
            let last = run.corpus.pop().unwrap_or_default();
            let at = seed_count + rng.below(run.corpus.len() - seed_count);
            run.corpus[at] = last;
        }
        mutated += 1;
        if budget.progress && Instant::now() >= next_status {
            next_status += Duration::from_secs(60);
            eprintln!(
                "# {} {:.0} s: {} execs, {} kept, {} findings",
                target.name,
                start.elapsed().as_secs_f64(),
                run.executions,
                run.kept,
                run.findings.len()
            );
        }
    }
    watch.done.store(true, Ordering::Relaxed);
    let _ = dog.join();
    Report {
        target: target.name,
        seconds: start.elapsed().as_secs_f64(),
        executions: run.executions,
        seeds: seeds.len(),
        kept: run.kept,
        findings: run.findings,
    }
}

struct Run<'a> {
    target: &'a Target,
    budget: &'a Budget,
    watch: &'a Watch,
    corpus: Vec<Vec<u8>>,
    seen: HashSet<u64>,
    /// Findings by place (panic location and gist; "slow" once per first feature).
    places: HashMap<String, usize>,
    findings: Vec<Finding>,
    executions: u64,
    /// Mutated inputs with a new signature.
    kept: usize,
}

impl Run<'_> {
    /// Runs one input; true when it joined the corpus.
    fn one(&mut self, input: Vec<u8>, is_seed: bool) -> bool {
        self.executions += 1;
        match exec(self.target, &input, self.watch) {
            Outcome::Ok { features, cpu } => {
                if cpu > self.budget.timeout {
                    let message = format!(
                        "took {:.2} s of CPU (limit {:.2} s)",
                        cpu.as_secs_f64(),
                        self.budget.timeout.as_secs_f64()
                    );
                    let place = format!("{:x}", features.first().copied().unwrap_or(0));
                    self.finding(FindingKind::Slow, message, place, &input);
                }
                let mut new = false;
                for f in features {
                    new |= self.seen.insert(f);
                }
                self.kept += usize::from(new && !is_seed);
                if new || is_seed {
                    self.corpus.push(input);
                }
                new || is_seed
            }
            Outcome::Panicked { message, location } => {
                self.finding(FindingKind::Panic, message, location, &input);
                false
            }
        }
    }

    fn finding(&mut self, kind: FindingKind, message: String, location: String, input: &[u8]) {
        // One finding per place and gist: an invariant checked in one place (a
        // non-finite number in any field) can fail for several reasons.
        let place = format!("{}@{location}@{}", kind.name(), gist(&message));
        if self.places.contains_key(&place) {
            // Keep the shortest input of each place: the easiest to read.
            let i = self.places[&place];
            if input.len() < self.findings[i].input.len() {
                self.findings[i].input = input.to_vec();
                self.findings[i].saved = self.save(kind, input, &message, &location);
            }
            return;
        }
        let saved = self.save(kind, input, &message, &location);
        let f = Finding {
            kind,
            message,
            location,
            input: input.to_vec(),
            saved,
        };
        if self.budget.progress {
            eprintln!("FINDING target={} {f}", self.target.name);
        }
        self.places.insert(place, self.findings.len());
        self.findings.push(f);
    }

    fn save(&self, kind: FindingKind, input: &[u8], message: &str, at: &str) -> Option<PathBuf> {
        let dir = self.budget.crash_dir.as_deref()?;
        let note = format!("{} at {at}: {message}", kind.name());
        save(dir, self.target.name, kind.name(), input, &note)
    }
}

/// The first line of a panic message without numbers and quoted parts (inputs).
fn gist(message: &str) -> String {
    let mut out = String::new();
    let mut quoted = None;
    for c in message.lines().next().unwrap_or("").chars() {
        match quoted {
            Some(q) if c == q => quoted = None,
            Some(_) => {}
            None if c == '"' || c == '`' => quoted = Some(c),
            None if !c.is_ascii_digit() => out.push(c),
            None => {}
        }
    }
    out
}

/// Runs one input with the normal panic hook (a panic prints and unwinds to the
/// caller); the features of its outcome and its CPU time.
pub fn reproduce(target: &Target, input: &[u8]) -> (Vec<u64>, Duration) {
    (target.prepare)();
    let clock = this_thread_clock();
    let before = cpu_ns(clock);
    let features = (target.run)(input).features();
    (
        features,
        Duration::from_nanos(cpu_ns(clock).saturating_sub(before)),
    )
}
