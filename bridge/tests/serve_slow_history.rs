//! No face waits on I/O: while a start is prepared (the machine's state read again,
//! the program resolved, the run's `running` row written into the history), the
//! faces go on answering. `probebridge serve` on the simulator with a SQLite history
//! that the test holds in an exclusive transaction (another process, as any program
//! could), and a PLC (`tests/gateway/polling_plc.py`) that starts 431 and reads its
//! state every 10 ms: the reads are answered while the history is held, and the start
//! is acknowledged only after the test lets the history go.
//!
//! Python with pymodbus: `PROBEBRIDGE_PYTHON`, else `/opt/probebridge-venv/bin/python`;
//! skipped with a message where it is missing, never in CI.

#[allow(dead_code)]
mod common;
#[path = "common/pymodbus_venv.rs"]
mod pymodbus_venv;
use pymodbus_venv::python;
#[path = "common/serve.rs"]
mod serve;
use serve::{copy_programs, Serve};
#[path = "common/sqlite_lock.rs"]
mod sqlite_lock;
use sqlite_lock::lock_sqlite;

use common::*;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};

const START: u64 = 1;
const DONE: u64 = 2;
/// Reads the PLC must see answered while the history is held (10 ms apart).
const READS_WHILE_HELD: u32 = 50;

#[test]
fn the_plc_is_answered_while_a_start_waits_for_a_slow_history() {
    let Some(py) = python() else { return };
    let dir = tmpdir("slow-history");
    copy_programs(&dir, &[(431, "431-plane.h")]);
    let db = dir.join("history.sqlite");
    let config = dir.join("gateway.toml");
    // The statement timeout is long: the history answers when the test lets it, not
    // when the gateway gives up.
    std::fs::write(
        &config,
        format!(
            "[machine]\nscenario = {:?}\nservice = \"pbslow-{}\"\n\
             [programs]\nfolder = \"programs\"\n\
             [plc]\nlisten = \"127.0.0.1:0\"\nheartbeat_timeout_ms = 0\n\
             [history]\nsqlite = {db:?}\nstatement_timeout_ms = 10000\n",
            configs()
                .join("scenarios/tilted-plane.toml")
                .to_str()
                .unwrap(),
            std::process::id(),
        ),
    )
    .unwrap();
    let serve = Serve::spawn(bin(), &dir, &config);
    let held = lock_sqlite(&py, &db);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/gateway/polling_plc.py");
    let mut plc = Command::new(&py)
        .arg(script)
        .args(["127.0.0.1", &serve.port.to_string(), "431"])
        .arg(READS_WHILE_HELD.to_string())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut out = BufReader::new(plc.stdout.take().unwrap());
    let mut line = String::new();
    out.read_line(&mut line).unwrap();
    // Before the history is let go: the PLC's reads were answered meanwhile. A face
    // that waited on the history would answer the start (refused, reason 9, after the
    // statement timeout) before any of them.
    assert_eq!(
        line.trim(),
        format!("pending {READS_WHILE_HELD}"),
        "the PLC's reads were not answered while the history was held\n{}",
        serve.log()
    );
    drop(held);
    line.clear();
    out.read_line(&mut line).unwrap();
    assert!(plc.wait().unwrap().success(), "{line}\n{}", serve.log());
    let end: serde_json::Value = serde_json::from_str(&line).unwrap();
    eprintln!("PLC: {end}");
    assert!(
        end["pending_reads"].as_u64().unwrap() >= u64::from(READS_WHILE_HELD),
        "{end}"
    );
    // Taken once the history had the row, and measured.
    assert_eq!(end["ack_code"], START, "{end}\n{}", serve.log());
    assert_eq!(end["state"], DONE, "{end}\n{}", serve.log());
}
