//! The history on a real PostgreSQL server, as on SQLite: `probebridge run --history`
//! records the same runs into both, and `probebridge history --json` lists the same
//! rows from either (ids, results, 451's ISO errors and dispersions; only the clock
//! times differ). The server is Debian's `postgresql` (`scripts/install-test-peers`),
//! started by the test in a folder of its own on a free port, as an unprivileged user
//! (PostgreSQL refuses to run as root). Skipped with a line saying why where the
//! binaries are missing, never in CI.

mod common;
#[path = "common/postgres_server.rs"]
mod postgres_server;

use common::*;
use postgres_server::{pg_bin, Server};

fn history_json(target: &str) -> Vec<serde_json::Value> {
    let out = run(bin().args(["history", "--db", target, "--json"]));
    assert!(out.status.success());
    serde_json::from_slice::<serde_json::Value>(&out.stdout)
        .unwrap()
        .as_array()
        .unwrap()
        .clone()
}

/// A run without its clock times (the one thing that differs between the runs).
fn timeless(mut run: serde_json::Value) -> serde_json::Value {
    let o = run.as_object_mut().unwrap();
    for k in ["started", "finished"] {
        assert!(o.remove(k).is_some_and(|v| v.is_string()), "{k}");
    }
    run
}

#[test]
fn postgres_history_lists_what_sqlite_lists() {
    let Some(bin_dir) = pg_bin() else {
        assert!(
            std::env::var("CI").ok().as_deref() != Some("true"),
            "PostgreSQL (initdb, postgres) is missing in CI: scripts/install-test-peers installs Debian's postgresql"
        );
        eprintln!("SKIPPED: no PostgreSQL server binaries (initdb, postgres); scripts/install-test-peers installs them");
        return;
    };
    let server = Server::start(&bin_dir, "pg-server");
    let url = server.url();
    let dir = tmpdir("pg-history");
    let sqlite = dir.join("history.sqlite");
    for (program, scenario) in [
        ("431-plane.h", "tilted-plane.toml"),
        ("451-check.h", "demo-sphere.toml"),
    ] {
        for target in [url.as_str(), sqlite.to_str().unwrap()] {
            // Each run from the same start: no preset row or kinematics of the last.
            for f in [
                "presets.toml",
                "presets.toml.prev",
                "kinematics.toml",
                "kinematics.toml.prev",
            ] {
                let _ = std::fs::remove_file(dir.join(f));
            }
            let (out, _) = run_program(
                &configs().join("programs").join(program),
                &configs().join("scenarios").join(scenario),
                &dir,
                &[
                    "--yes",
                    "--kinematics",
                    dir.join("kinematics.toml").to_str().unwrap(),
                    "--history",
                    target,
                ],
            );
            assert!(out.status.success(), "{program} into {target}");
        }
    }
    let pg = history_json(&url);
    let lite = history_json(sqlite.to_str().unwrap());
    assert_eq!(pg.len(), 2, "{pg:?}");
    assert!(
        !pg[1]["iso_errors"].as_array().unwrap().is_empty(),
        "{}",
        pg[1]
    );
    assert!(
        !pg[1]["dispersion"].as_array().unwrap().is_empty(),
        "{}",
        pg[1]
    );
    let pg: Vec<_> = pg.into_iter().map(timeless).collect();
    let lite: Vec<_> = lite.into_iter().map(timeless).collect();
    assert_eq!(pg, lite);
    // The text listing and the trend page from the server too.
    let text = run(bin().args(["history", "--db", &url]));
    assert!(text.status.success());
    assert_eq!(String::from_utf8_lossy(&text.stdout).lines().count(), 2);
    let page = dir.join("trend.html");
    let out = run(bin().args(["history", "--db", &url, "--html", page.to_str().unwrap()]));
    assert!(out.status.success());
    let html = std::fs::read_to_string(&page).unwrap();
    assert!(html.matches("<svg").count() > 0, "{html}");
    // A wrong password's server message comes through, naming the server without it.
    let bad = url.replace("probebridge@", "nobody:secret@");
    let out = bin().args(["history", "--db", &bad]).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("nobody:***@") && !err.contains("secret"),
        "{err}"
    );
    drop(server);
}
