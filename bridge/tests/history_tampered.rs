//! A tampered history (names with markup and terminal escape codes written into the
//! database by hand, or by a hostile gateway on a shared server) lists and renders
//! inert: `probebridge history` prints the stored strings escaped, the trend page
//! escapes them in text and in attributes, and Chromium builds no element from them.

// Not every helper of the shared test modules is used here.
#[allow(dead_code)]
#[path = "common/browser.rs"]
mod browser;
#[allow(dead_code)]
mod common;
#[path = "common/stored_history.rs"]
mod stored_history;

use common::*;
use stored_history::{store, StoredRun};

const MACHINE: &str = "m\x1b[31m\x1b]0;owned\x07<img src=x onerror=alert(1)>";
const ERROR: &str = "EX0C\" onload=\"alert(2)\"><script>alert(3)</script>";
const AXIS: &str = "C' onmouseover='alert(4)";

fn tampered(db: &std::path::Path) {
    let errors = [(ERROR, 0.0, 0.01), ("EY0C", 0.0, -0.004)];
    let dispersion = [(AXIS, 0.002, 0.001)];
    let run = |started| StoredRun {
        machine: MACHINE,
        started,
        errors: &errors,
        dispersion: &dispersion,
        max_modification: 0.05,
        program: "/p/\x1b[2J451\u{202e}.h",
    };
    store(
        db,
        &[run("2026-11-18T08:00:00Z"), run("2026-11-25T08:00:00Z")],
    );
}

#[test]
fn the_listing_prints_stored_strings_escaped() {
    let dir = tmpdir("tampered-listing");
    let db = dir.join("history.sqlite");
    tampered(&db);
    let out = run(bin().args(["history", "--db", db.to_str().unwrap()]));
    assert!(out.status.success());
    assert!(
        !out.stdout.iter().any(|&b| b == 0x1b || b == 0x07),
        "terminal escape codes reached stdout: {:?}",
        String::from_utf8_lossy(&out.stdout)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    assert_eq!(text.lines().count(), 2, "{text}");
    assert!(
        text.contains(r"m\u{1b}[31m\u{1b}]0;owned\u{7}<img"),
        "{text}"
    );
    assert!(text.contains(r"\u{1b}[2J451\u{202e}.h"), "{text}");
    assert!(!text.contains('\u{202e}'));
}

#[test]
fn the_trend_page_of_a_tampered_history_renders_inert() {
    let dir = tmpdir("tampered-page");
    let db = dir.join("history.sqlite");
    tampered(&db);
    let page = dir.join("trend.html");
    let out = run(bin().args([
        "history",
        "--db",
        db.to_str().unwrap(),
        "--html",
        page.to_str().unwrap(),
    ]));
    assert!(out.status.success());
    let html = std::fs::read_to_string(&page).unwrap();
    for bad in ["<script", "<img", "onload=\"", "onmouseover='", "\x1b"] {
        assert!(!html.contains(bad), "{bad:?} in the page:\n{html}");
    }
    let Some(browser) = browser::Browser::find(&dir.join("chromium-profile")) else {
        return;
    };
    let page = browser.load(&format!("file://{}", page.display()));
    assert!(
        page.console.is_empty(),
        "the page logged: {:?}",
        page.console
    );
    for bad in ["<script", "<img"] {
        assert!(!page.dom.contains(bad), "{bad:?} in the DOM:\n{}", page.dom);
    }
    // The serialised DOM escapes `<` and `>` in text: what lies between them is a tag.
    for tag in page
        .dom
        .split('<')
        .filter_map(|t| t.split_once('>'))
        .map(|t| t.0)
    {
        for attr in [" onload=", " onerror=", " onmouseover="] {
            assert!(!tag.contains(attr), "an element with {attr}: <{tag}>");
        }
    }
    // The names are there, as text.
    assert!(page.dom.contains("&lt;script&gt;alert(3)&lt;/script&gt;"));
    assert_eq!(page.dom.matches("<svg class=\"trend\"").count(), 3);
}
