//! The spool: the ends of runs the history could not take when they happened, kept on
//! the gateway's own disk until they are replayed into it. An append-only file, one
//! record per line, each line fsynced before the PLC is told the run has ended:
//!
//! ```text
//! {"spool":"probebridge-history","version":1,"history":"...","id":7,"rows":{...}} crc32=1a2b3c4d
//! ```
//!
//! Each line names its format and version and carries the CRC-32 of its JSON, so a
//! line torn by a crash mid-write (or damaged on disk) is found when the spool is
//! opened. Such a line is never dropped silently: it is reported and moved, byte for
//! byte, to `SPOOL.damaged` beside the spool.

use super::{NewRun, Rows};
use serde::{Deserialize, Serialize};
use std::fs::{File, OpenOptions};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

pub const FORMAT: &str = "probebridge-history";
pub const VERSION: u32 = 1;

/// The end of one run, for the history it belongs to.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SpoolRecord {
    pub spool: String,
    pub version: u32,
    /// The history (file or URL without its password) the run was begun in.
    pub history: String,
    pub id: i64,
    pub rows: Rows,
    /// The run as it was begun: the replay finds the run by it, or begins it in a
    /// history that lost it (a fresh file in place of a corrupted one). None in records
    /// spooled before it was kept, and for runs this gateway did not begin.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub start: Option<SpooledStart>,
}

/// A run's start, as the history had it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SpooledStart {
    pub run: NewRun,
    /// ISO 8601 UTC, the `started` of its row.
    pub started: String,
}

impl SpoolRecord {
    pub fn new(history: String, id: i64, rows: Rows, start: Option<SpooledStart>) -> Self {
        Self {
            spool: FORMAT.into(),
            version: VERSION,
            history,
            id,
            rows,
            start,
        }
    }

    fn line(&self) -> String {
        let json = serde_json::to_string(self).expect("records serialise");
        format!("{json} crc32={:08x}\n", crc32(json.as_bytes()))
    }

    /// One line (without its newline) back into a record, or why not.
    fn parse(line: &str) -> Result<Self, String> {
        let (json, sum) = line
            .rsplit_once(" crc32=")
            .ok_or("no checksum at the end of the line")?;
        let want = u32::from_str_radix(sum, 16).map_err(|_| "unreadable checksum")?;
        if crc32(json.as_bytes()) != want {
            return Err("checksum mismatch".into());
        }
        let r: SpoolRecord = serde_json::from_str(json).map_err(|e| e.to_string())?;
        if r.spool != FORMAT || r.version != VERSION {
            return Err(format!(
                "format {:?} version {}, this gateway reads {FORMAT:?} version {VERSION}",
                r.spool, r.version
            ));
        }
        Ok(r)
    }
}

pub struct Spool {
    path: PathBuf,
    file: File,
    records: Vec<SpoolRecord>,
}

fn io(path: &Path, what: &str, e: std::io::Error) -> String {
    format!("spool {}: {what}: {e}", path.display())
}

impl Spool {
    /// Opens (creating) the spool at `path` and reads the records in it. Lines that
    /// are torn or damaged are moved to `SPOOL.damaged`; each is described in the
    /// returned list, for the log.
    pub fn open(path: &Path) -> Result<(Self, Vec<String>), String> {
        let mut bytes = Vec::new();
        match File::open(path) {
            Ok(mut f) => {
                f.read_to_end(&mut bytes)
                    .map_err(|e| io(path, "cannot read it", e))?;
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(io(path, "cannot open it", e)),
        }
        let mut records = Vec::new();
        let mut damaged = Vec::new();
        let mut problems = Vec::new();
        let mut rest = &bytes[..];
        let mut number = 0;
        while !rest.is_empty() {
            number += 1;
            let (line, complete) = match rest.iter().position(|&b| b == b'\n') {
                Some(n) => (&rest[..n], true),
                None => (rest, false),
            };
            rest = &rest[(line.len() + usize::from(complete)).min(rest.len())..];
            let parsed = match (complete, std::str::from_utf8(line)) {
                (false, _) => {
                    Err("torn: no end of line (the gateway stopped while writing it)".to_string())
                }
                (true, Err(_)) => Err("not UTF-8".to_string()),
                (true, Ok(text)) => SpoolRecord::parse(text),
            };
            match parsed {
                Ok(r) => records.push(r),
                Err(why) => {
                    problems.push(format!(
                        "spool {} line {number} ({} bytes): {why}; moved to {}",
                        path.display(),
                        line.len(),
                        damaged_path(path).display()
                    ));
                    damaged.extend_from_slice(line);
                    damaged.push(b'\n');
                }
            }
        }
        if !damaged.is_empty() {
            let d = damaged_path(path);
            let mut f = OpenOptions::new()
                .create(true)
                .append(true)
                .open(&d)
                .map_err(|e| io(&d, "cannot open it", e))?;
            f.write_all(&damaged)
                .and_then(|()| f.sync_all())
                .map_err(|e| io(&d, "cannot write it", e))?;
        }
        let file = OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)
            .map_err(|e| io(path, "cannot open it for appending", e))?;
        let mut spool = Self {
            path: path.to_path_buf(),
            file,
            records,
        };
        if !damaged.is_empty() {
            // Only whole records stay, so that appends start on a line of their own.
            spool.rewrite()?;
        }
        sync_dir(path);
        Ok((spool, problems))
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn records(&self) -> &[SpoolRecord] {
        &self.records
    }

    pub fn len(&self) -> usize {
        self.records.len()
    }

    pub fn is_empty(&self) -> bool {
        self.records.is_empty()
    }

    /// Appends `record` and fsyncs it. A record of the same run already there is not
    /// written twice. On failure nothing of it stays in the file.
    pub fn append(&mut self, record: SpoolRecord) -> Result<(), String> {
        if self
            .records
            .iter()
            .any(|r| r.id == record.id && r.history == record.history)
        {
            return Ok(());
        }
        let before = self
            .file
            .metadata()
            .map_err(|e| io(&self.path, "cannot stat it", e))?
            .len();
        let written = self
            .file
            .write_all(record.line().as_bytes())
            .and_then(|()| self.file.sync_data());
        if let Err(e) = written {
            // A partial line would be torn: cut it off again.
            let _ = self
                .file
                .set_len(before)
                .and_then(|()| self.file.sync_data());
            return Err(io(&self.path, "cannot append to it", e));
        }
        self.records.push(record);
        Ok(())
    }

    /// Drops the records of runs `(history, id)` (replayed): the file is written anew
    /// beside it, fsynced, and renamed over it.
    pub fn remove(&mut self, done: &[(String, i64)]) -> Result<(), String> {
        let before = self.records.len();
        self.records
            .retain(|r| !done.iter().any(|(h, id)| *h == r.history && *id == r.id));
        if self.records.len() == before {
            return Ok(());
        }
        self.rewrite()
    }

    fn rewrite(&mut self) -> Result<(), String> {
        let tmp = self
            .path
            .with_extension(format!("tmp{}", std::process::id()));
        let text: String = self.records.iter().map(SpoolRecord::line).collect();
        let written = File::create(&tmp)
            .and_then(|mut f| f.write_all(text.as_bytes()).and_then(|()| f.sync_all()))
            .and_then(|()| std::fs::rename(&tmp, &self.path));
        if let Err(e) = written {
            let _ = std::fs::remove_file(&tmp);
            return Err(io(&self.path, "cannot write it anew", e));
        }
        sync_dir(&self.path);
        self.file = OpenOptions::new()
            .append(true)
            .open(&self.path)
            .map_err(|e| io(&self.path, "cannot open it for appending", e))?;
        Ok(())
    }
}

pub fn damaged_path(spool: &Path) -> PathBuf {
    let mut s = spool.as_os_str().to_owned();
    s.push(".damaged");
    PathBuf::from(s)
}

/// A created or renamed file survives a crash only once its folder is synced too.
fn sync_dir(path: &Path) {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        if let Ok(d) = File::open(dir) {
            let _ = d.sync_all();
        }
    }
}

/// CRC-32 (IEEE 802.3, as zlib's `crc32`).
pub fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows(status: &str) -> Rows {
        Rows {
            finished: "2026-11-25T12:00:00Z".into(),
            status: status.parse().unwrap(),
            message: None,
            protocols: "[]".into(),
            machine_time_s: Some(6.875),
            results: vec![(
                0,
                super::super::ResultRow {
                    block: 6,
                    cycle: 431,
                    name: "Q158".into(),
                    value: 0.5,
                    u: Some(0.0003),
                },
            )],
            iso_errors: Vec::new(),
            dispersion: Vec::new(),
        }
    }

    fn dir(name: &str) -> crate::history::TestDir {
        crate::history::TestDir::new(&format!("spool-{name}"))
    }

    #[test]
    fn crc32_is_zlibs() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    }

    #[test]
    fn records_survive_a_reopen_and_a_run_is_kept_once() {
        let d = dir("reopen");
        let p = d.join("history.spool");
        let (mut s, problems) = Spool::open(&p).unwrap();
        assert!(problems.is_empty() && s.is_empty());
        s.append(SpoolRecord::new("h".into(), 1, rows("done"), None))
            .unwrap();
        s.append(SpoolRecord::new("h".into(), 1, rows("done"), None))
            .unwrap();
        s.append(SpoolRecord::new("h".into(), 2, rows("aborted"), None))
            .unwrap();
        drop(s);
        let (mut s, problems) = Spool::open(&p).unwrap();
        assert!(problems.is_empty(), "{problems:?}");
        assert_eq!(s.len(), 2);
        assert_eq!(
            s.records()[1].rows.status,
            crate::history::RunStatus::Aborted
        );
        s.remove(&[("h".into(), 1)]).unwrap();
        let (s, _) = Spool::open(&p).unwrap();
        assert_eq!(s.records().iter().map(|r| r.id).collect::<Vec<_>>(), [2]);
    }

    #[test]
    fn a_torn_last_line_and_a_damaged_line_are_reported_and_kept_aside() {
        let d = dir("torn");
        let p = d.join("history.spool");
        let (mut s, _) = Spool::open(&p).unwrap();
        for id in 1..=3 {
            s.append(SpoolRecord::new("h".into(), id, rows("done"), None))
                .unwrap();
        }
        drop(s);
        let mut text = std::fs::read_to_string(&p).unwrap();
        // Damage record 2 (one digit of a value), and tear a fourth record.
        text = text.replacen("\"id\":2,", "\"id\":9,", 1);
        let torn = SpoolRecord::new("h".into(), 4, rows("done"), None).line();
        text.push_str(&torn[..torn.len() / 2]);
        std::fs::write(&p, &text).unwrap();
        let (mut s, problems) = Spool::open(&p).unwrap();
        assert_eq!(problems.len(), 2, "{problems:?}");
        assert!(problems[0].contains("line 2") && problems[0].contains("checksum"));
        assert!(problems[1].contains("line 4") && problems[1].contains("torn"));
        assert_eq!(s.records().iter().map(|r| r.id).collect::<Vec<_>>(), [1, 3]);
        let damaged = std::fs::read_to_string(damaged_path(&p)).unwrap();
        assert!(damaged.contains("\"id\":9,") && damaged.contains("\"id\":4,"));
        // Appending goes on after the whole records.
        s.append(SpoolRecord::new("h".into(), 5, rows("done"), None))
            .unwrap();
        let (s, problems) = Spool::open(&p).unwrap();
        assert!(problems.is_empty(), "{problems:?}");
        assert_eq!(
            s.records().iter().map(|r| r.id).collect::<Vec<_>>(),
            [1, 3, 5]
        );
    }
}
