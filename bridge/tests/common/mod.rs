//! What the CLI tests share: the binary, the shipped configurations, a scratch folder
//! per test, and `probebridge run` with its JSON.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The binary, with a state directory of its own for each command (a fresh folder:
/// the machine's state seeded from `configs/` as on a first run), so that tests never
/// share state with each other or with the user's `~/.local/state`. The folders live
/// in `pb-cli-state-<pid>/` in the temporary folder (the test root under
/// `scripts/with-test-root`); a test process removes the ones of processes that no
/// longer run, so they do not pile up even outside a test root.
pub fn bin() -> Command {
    use std::sync::atomic::{AtomicUsize, Ordering};
    static N: AtomicUsize = AtomicUsize::new(0);
    static DIR: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    let dir = DIR.get_or_init(|| {
        let tmp = std::env::temp_dir();
        for entry in std::fs::read_dir(&tmp).into_iter().flatten().flatten() {
            let name = entry.file_name();
            let Some(pid) = name.to_str().and_then(|n| n.strip_prefix("pb-cli-state-")) else {
                continue;
            };
            if pid.parse::<u32>().is_ok() && !Path::new("/proc").join(pid).exists() {
                let _ = std::fs::remove_dir_all(entry.path());
            }
        }
        tmp.join(format!("pb-cli-state-{}", std::process::id()))
    });
    let state = dir.join(N.fetch_add(1, Ordering::Relaxed).to_string());
    let _ = std::fs::remove_dir_all(&state);
    let mut c = Command::new(env!("CARGO_BIN_EXE_probebridge"));
    c.env("XDG_STATE_HOME", &state)
        .env_remove("STATE_DIRECTORY");
    c
}

/// The `[history]` line the faces' tests give `serve`: 10 s for a statement, not 2. CI
/// runs these tests beside a VM, and a start refused because an fsync took 2.5 s on
/// the loaded machine (reason 9, in `serve_plc.rs`) says nothing of what they try. The
/// budget itself is tried where it is the point: `history_faults.rs`,
/// `serve_slow_history.rs`.
#[allow(dead_code)]
pub const HISTORY_TIMEOUT: &str = "statement_timeout_ms = 10000\n";

pub fn configs() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs")
}

/// An empty folder for one test of this process.
pub fn tmpdir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("pb-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Runs the command; on failure prints what it said, for the test log.
pub fn run(cmd: &mut Command) -> Output {
    let out = cmd.output().expect("run probebridge");
    if !out.status.success() {
        eprintln!("stdout:\n{}", String::from_utf8_lossy(&out.stdout));
        eprintln!("stderr:\n{}", String::from_utf8_lossy(&out.stderr));
    }
    out
}

/// `probebridge run PROGRAM --scenario SCENARIO --out DIR --json DIR/r.json` on an
/// iceoryx2 service of its own, on a fresh machine state of its own ([`bin`]: what
/// cycle 451 with Q431 != 0 or mode 1 writes goes there, never into `configs/`), plus
/// `extra`: the output and the JSON written (`None`: none was).
pub fn run_program(
    program: &Path,
    scenario: &Path,
    dir: &Path,
    extra: &[&str],
) -> (Output, Option<serde_json::Value>) {
    let json = dir.join("r.json");
    let service = format!(
        "pb-cli-{}-{}",
        dir.file_name().unwrap().to_string_lossy(),
        std::process::id()
    );
    let out = run(bin()
        .args(["run", program.to_str().unwrap()])
        .args(["--scenario", scenario.to_str().unwrap()])
        .args(["--out", dir.to_str().unwrap()])
        .args(["--json", json.to_str().unwrap()])
        .args(["--service", &service])
        .args(extra));
    let v = std::fs::read_to_string(&json)
        .ok()
        .map(|t| serde_json::from_str(&t).expect("the JSON run wrote"));
    (out, v)
}

/// Overwrites `len` bytes of `path` from `at` (to its end if shorter) with pseudo-random
/// bytes (xorshift, seeded): a disk, a stray `dd` or a bad copy, as the history may
/// meet them. The file keeps its length.
#[allow(dead_code, reason = "the history tests' alone")]
pub fn overwrite_with_noise(path: &Path, at: u64, len: u64) {
    use std::io::{Seek, SeekFrom, Write};
    let size = std::fs::metadata(path).unwrap().len();
    let len = len.min(size.saturating_sub(at));
    let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
    let noise: Vec<u8> = (0..len)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x as u8
        })
        .collect();
    let mut f = std::fs::OpenOptions::new().write(true).open(path).unwrap();
    f.seek(SeekFrom::Start(at)).unwrap();
    f.write_all(&noise).unwrap();
    f.sync_all().unwrap();
}
