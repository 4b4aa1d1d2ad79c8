//! Headless Chromium for the page tests: the DOM it builds, the console it logs, a
//! screenshot. `PROBEBRIDGE_CHROMIUM`, else `chromium` on the PATH
//! (`scripts/install-test-peers` installs Debian's); skipped with a line saying why
//! where it is missing, never in CI.

use std::path::{Path, PathBuf};
use std::process::Command;

pub struct Browser {
    exe: PathBuf,
    profile: PathBuf,
}

/// What the browser made of a page.
pub struct Loaded {
    pub dom: String,
    /// Console messages and uncaught errors (CSP refusals among them).
    pub console: Vec<String>,
}

impl Browser {
    pub fn find(profile: &Path) -> Option<Self> {
        let exe = std::env::var_os("PROBEBRIDGE_CHROMIUM")
            .map_or_else(|| PathBuf::from("chromium"), PathBuf::from);
        if Command::new(&exe)
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success())
        {
            return Some(Self {
                exe,
                profile: profile.to_path_buf(),
            });
        }
        assert!(
            std::env::var_os("CI").is_none(),
            "no chromium in CI; scripts/install-test-peers installs it"
        );
        eprintln!("SKIPPED: no chromium (run scripts/install-test-peers)");
        None
    }

    fn command(&self) -> Command {
        let mut c = Command::new(&self.exe);
        c.args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-background-networking",
            "--disable-component-update",
            "--no-first-run",
            "--disable-sync",
            "--enable-logging=stderr",
            "--v=0",
        ])
        .arg(format!("--user-data-dir={}", self.profile.display()));
        c
    }

    pub fn load(&self, url: &str) -> Loaded {
        let out = self.command().arg("--dump-dom").arg(url).output().unwrap();
        let log = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{url}: {log}");
        Loaded {
            dom: String::from_utf8_lossy(&out.stdout).into_owned(),
            console: log
                .lines()
                .filter(|l| {
                    l.contains("CONSOLE")
                        || l.contains("Uncaught")
                        || l.contains("Content Security Policy")
                })
                .map(str::to_string)
                .collect(),
        }
    }

    /// A PNG of the page at `size` ("W,H"); copied to the file the environment
    /// variable `keep` names, if set (the screenshots in docs/).
    pub fn screenshot(&self, url: &str, shot: &Path, size: &str, keep: &str) {
        let out = self
            .command()
            .arg(format!("--screenshot={}", shot.display()))
            .arg(format!("--window-size={size}"))
            .arg("--hide-scrollbars")
            .arg(url)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let png = std::fs::read(shot).unwrap();
        assert!(
            png.len() > 10_000 && png.starts_with(b"\x89PNG"),
            "screenshot"
        );
        if let Some(to) = std::env::var_os(keep) {
            std::fs::copy(shot, to).unwrap();
        }
    }
}
