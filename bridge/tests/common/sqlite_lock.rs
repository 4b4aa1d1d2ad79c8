//! A SQLite history held by another process for the gateway tests (history_faults,
//! serve_slow_history): python3's sqlite3 in an exclusive transaction, as any other
//! program could hold it; released when dropped.

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};

/// Another process holding an exclusive transaction on the SQLite file (python3's
/// sqlite3, as any other program could); released on drop.
pub struct SqliteLock(Child);

pub fn lock_sqlite(py: &Path, db: &Path) -> SqliteLock {
    let mut child = Command::new(py)
        .args([
            "-c",
            "import sqlite3, sys\n\
             c = sqlite3.connect(sys.argv[1], isolation_level=None, timeout=30)\n\
             c.execute('BEGIN EXCLUSIVE')\n\
             print('locked', flush=True)\n\
             sys.stdin.read()\n\
             c.execute('ROLLBACK')\n",
        ])
        .arg(db)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    assert_eq!(line.trim(), "locked");
    SqliteLock(child)
}

impl Drop for SqliteLock {
    fn drop(&mut self) {
        drop(self.0.stdin.take());
        let _ = self.0.wait();
    }
}
