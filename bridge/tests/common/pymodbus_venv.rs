//! The Python that plays the PLC in the gateway tests (and the PLC double of
//! `tests/tests/modbus_pymodbus.rs`, which includes this file): the venv that
//! `scripts/install-test-peers` makes, with pymodbus (and sqlite3, which the history
//! tests read the database with). Missing in CI: the test fails; elsewhere it is skipped
//! with a message.

use std::path::PathBuf;
use std::process::Command;

pub fn python() -> Option<PathBuf> {
    let p = std::env::var_os("PROBEBRIDGE_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("/opt/probebridge-venv/bin/python"));
    let ok = Command::new(&p)
        .args(["-c", "import pymodbus, sqlite3"])
        .output()
        .is_ok_and(|o| o.status.success());
    if ok {
        return Some(p);
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "{}: no pymodbus in CI; scripts/install-test-peers should have made the venv",
        p.display()
    );
    eprintln!(
        "SKIPPED: {} has no pymodbus (run scripts/install-test-peers)",
        p.display()
    );
    None
}
