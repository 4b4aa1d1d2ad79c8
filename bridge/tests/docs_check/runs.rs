//! Every `probebridge` line of README.md's fenced blocks runs, as a process from the
//! clone's root as the README tells a newcomer to run it, and exits as the README says:
//! 0, unless the line ends in a comment `# exits N`. A line that cannot run here (it
//! needs a running `serve`, a PLC, root or the network) ends in a visible comment
//! `# not run by docs_check: WHY` and is only parsed.
//!
//! The binary is the one the test suite already builds (`target/<profile>/probebridge`
//! beside this test's own executable), so the check costs no build of its own. Each
//! line runs with a fresh `HOME` (the machine state in `~/.local/state/probebridge` as
//! on a first run) and a fresh `TMPDIR`, both under the test's temporary folder, and
//! must leave that `TMPDIR` empty: the demo removes its folder.

use super::commands::{fenced_commands, probebridge_args, shell_words};
use super::root;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Instant, SystemTime};

/// What a README line says about itself in its trailing comment.
#[derive(Debug, PartialEq)]
enum Expect {
    Exits(i32),
    NotRun(String),
}

/// The line's trailing shell comment, read for `# exits N` or
/// `# not run by docs_check: WHY` (default: exits 0).
fn expectation(line: &str) -> Result<Expect, String> {
    let Some((_, comment)) = line.split_once(" #") else {
        return Ok(Expect::Exits(0));
    };
    let comment = comment.trim();
    if let Some(why) = comment.strip_prefix("not run by docs_check:") {
        let why = why.trim();
        if why.is_empty() {
            return Err("`# not run by docs_check:` needs a reason".into());
        }
        return Ok(Expect::NotRun(why.to_string()));
    }
    match comment.strip_prefix("exits ") {
        Some(n) => n
            .trim()
            .parse()
            .map(Expect::Exits)
            .map_err(|_| format!("`# {comment}`: not an exit status")),
        None => Ok(Expect::Exits(0)),
    }
}

/// The CLI this test suite built: `target/<profile>/probebridge`, beside the folder
/// `deps/` that holds this test's executable.
fn binary() -> PathBuf {
    if let Some(exe) = option_env!("CARGO_BIN_EXE_probebridge") {
        return PathBuf::from(exe);
    }
    let me = std::env::current_exe().expect("the test's own executable");
    me.parent()
        .and_then(Path::parent)
        .expect("target/<profile>/deps/")
        .join("probebridge")
}

/// The newest modification time of the sources the binary is built from.
fn newest_source(root: &Path) -> SystemTime {
    let mut newest = SystemTime::UNIX_EPOCH;
    let mut todo: Vec<PathBuf> = ["bridge/src", "cycles/src", "hal/src", "sim/src"]
        .iter()
        .map(|d| root.join(d))
        .collect();
    todo.push(root.join("Cargo.lock"));
    while let Some(p) = todo.pop() {
        let Ok(meta) = std::fs::metadata(&p) else {
            continue;
        };
        if meta.is_dir() {
            todo.extend(
                std::fs::read_dir(&p)
                    .into_iter()
                    .flatten()
                    .flatten()
                    .map(|e| e.path()),
            );
        } else if let Ok(t) = meta.modified() {
            newest = newest.max(t);
        }
    }
    newest
}

/// The binary, built and not older than the sources; else how to build it.
fn fresh_binary(root: &Path) -> PathBuf {
    let bin = binary();
    let built = std::fs::metadata(&bin)
        .and_then(|m| m.modified())
        .unwrap_or_else(|e| {
            panic!(
                "{}: {e}; build it first: `cargo build -p probebridge` \
                 (`cargo test -p probebridge` builds it too)",
                bin.display()
            )
        });
    assert!(
        built >= newest_source(root),
        "{} is older than the sources: `cargo build -p probebridge` first",
        bin.display()
    );
    bin
}

/// Runs the README line `command` (line `n`) as a process from the root; an error
/// says what went wrong.
fn run_line(
    root: &Path,
    bin: &Path,
    n: usize,
    command: &str,
    args: &[String],
    code: i32,
) -> Result<(), String> {
    let scratch = std::env::temp_dir().join(format!("docs-check-{}-{n}", std::process::id()));
    let (home, tmp) = (scratch.join("home"), scratch.join("tmp"));
    let _ = std::fs::remove_dir_all(&scratch);
    for d in [&home, &tmp] {
        std::fs::create_dir_all(d).map_err(|e| format!("{}: {e}", d.display()))?;
    }
    let t0 = Instant::now();
    say(format_args!("README.md:{n}: running `{command}`"));
    let out = output_with_progress(
        Command::new(bin)
            .args(args)
            .current_dir(root)
            .env("HOME", &home)
            .env("TMPDIR", &tmp)
            .env_remove("XDG_STATE_HOME")
            .env_remove("STATE_DIRECTORY"),
        n,
    )
    .map_err(|e| format!("{}: {e}", bin.display()))?;
    say(format_args!(
        "README.md:{n}: `{command}` ended ({}) after {:.1} s",
        out.status,
        t0.elapsed().as_secs_f64()
    ));
    let left: Vec<String> = std::fs::read_dir(&tmp)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    let _ = std::fs::remove_dir_all(&scratch);
    let tail = |b: &[u8]| {
        let t = String::from_utf8_lossy(b);
        let lines: Vec<&str> = t.lines().collect();
        lines[lines.len().saturating_sub(15)..].join("\n")
    };
    if out.status.code() != Some(code) {
        return Err(format!(
            "README.md:{n}: `{command}` exited {}, the README says {code}\nstdout (end):\n{}\nstderr (end):\n{}",
            out.status,
            tail(&out.stdout),
            tail(&out.stderr)
        ));
    }
    if !left.is_empty() {
        return Err(format!(
            "README.md:{n}: `{command}` left {left:?} in its temporary folder"
        ));
    }
    Ok(())
}

/// A line on the terminal also when libtest captures the test's output (it captures
/// `eprintln!`, not writes to the stderr handle): a long command is never silent.
fn say(line: std::fmt::Arguments<'_>) {
    use std::io::Write as _;
    let _ = writeln!(std::io::stderr().lock(), "    [docs_check] {line}");
}

/// Runs `command` to its end like [`Command::output`], saying each of its stdout lines
/// that starts a section (not indented) as it comes.
fn output_with_progress(command: &mut Command, n: usize) -> std::io::Result<std::process::Output> {
    use std::io::{BufRead as _, Read as _};
    let mut child = command
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()?;
    let mut err_pipe = child.stderr.take().expect("piped");
    let stderr = std::thread::spawn(move || {
        let mut b = Vec::new();
        let _ = err_pipe.read_to_end(&mut b);
        b
    });
    let mut stdout = Vec::new();
    for line in std::io::BufReader::new(child.stdout.take().expect("piped")).lines() {
        let line = line?;
        if !line.is_empty() && !line.starts_with(' ') {
            say(format_args!("README.md:{n}:   {line}"));
        }
        stdout.extend_from_slice(line.as_bytes());
        stdout.push(b'\n');
    }
    let status = child.wait()?;
    let stderr = stderr.join().unwrap_or_default();
    Ok(std::process::Output {
        status,
        stdout,
        stderr,
    })
}

/// The README's probebridge lines `pick` selects, run; returns how many ran.
fn run_readme_lines(pick: impl Fn(&[String]) -> bool) -> usize {
    let root = root();
    let readme = std::fs::read_to_string(root.join("README.md")).expect("README.md");
    let bin = fresh_binary(&root);
    let (mut ran, mut errors) = (0, Vec::new());
    for (n, command) in fenced_commands(&readme) {
        let words = shell_words(&command).unwrap_or_else(|e| panic!("README.md:{n}: {e}"));
        let Some(args) = probebridge_args(&words).filter(|a| pick(a)) else {
            continue;
        };
        match expectation(&command) {
            Ok(Expect::NotRun(why)) => {
                say(format_args!("README.md:{n}: not run ({why}): `{command}`"))
            }
            Ok(Expect::Exits(code)) => {
                ran += 1;
                if let Err(e) = run_line(&root, &bin, n, &command, &args, code) {
                    errors.push(e);
                }
            }
            Err(e) => errors.push(format!("README.md:{n}: {e}")),
        }
    }
    assert!(errors.is_empty(), "{}", errors.join("\n\n"));
    ran
}

fn is_demo(args: &[String]) -> bool {
    args.first().is_some_and(|a| a == "demo")
}

/// The README's first command (a minute of the suite's time on its own, so a test of
/// its own: libtest reports it when it ends).
#[test]
fn the_readmes_demo_line_runs_and_leaves_nothing_behind() {
    assert_eq!(
        run_readme_lines(is_demo),
        1,
        "README.md shows the demo once"
    );
}

#[test]
fn every_other_probebridge_line_of_the_readme_runs() {
    let ran = run_readme_lines(|a| !is_demo(a));
    assert!(ran >= 2, "only {ran} probebridge lines of README.md ran");
}

#[test]
fn a_line_says_how_it_exits_or_why_it_does_not_run() {
    assert_eq!(expectation("probebridge demo"), Ok(Expect::Exits(0)));
    assert_eq!(
        expectation("probebridge history # exits 1"),
        Ok(Expect::Exits(1))
    );
    assert_eq!(
        expectation("probebridge serve --config g.toml # not run by docs_check: needs a PLC"),
        Ok(Expect::NotRun("needs a PLC".into()))
    );
    assert!(expectation("probebridge serve # not run by docs_check:").is_err());
    assert!(expectation("probebridge history # exits one").is_err());
}
