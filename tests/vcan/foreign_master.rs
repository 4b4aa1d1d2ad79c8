//! Our master against a CiA 402 drive that is not ours: python-canopen's `LocalNode`
//! serving `tests/vcan/cia402-drive.eds` (`tests/vcan/foreign_device.py`), on a
//! SocketCAN interface inside the VM step. The master's start-up (NMT reset, boot-up,
//! the SDO configuration of `hal::master::startup`) must be accepted, every download
//! must read back as written, and our SDO client must handle what such a device
//! answers: segmented uploads, aborts.
//!
//! Prints one line per check, `CHECK <name>: <observed> -> ok|FAIL`; exits 1 when
//! any failed.
//!
//! Usage: vcan-foreign-master --can IFACE --machine FILE --name NAME
//!   FILE: a machine configuration; only its first axis is used (the device's node).
//!   NAME: what the device answers for 0x1008.

use hal::can::socketcan::SocketCanTransport;
use hal::can::{CanFrame, CanTransport, TransportError};
use hal::canopen::cob_id::{self, CobKind};
use hal::canopen::sdo::{SdoAbortCode, SdoClient, SdoClientEvent, SdoOutcome};
use hal::config::MachineConfig;
use hal::master::startup;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// The transport, recording every expedited SDO download the master sends:
/// (node, index, sub) -> the bytes last written.
struct Recording<T> {
    inner: T,
    downloads: BTreeMap<(u8, u16, u8), Vec<u8>>,
    segmented: usize,
}

impl<T: CanTransport> CanTransport for Recording<T> {
    fn transmit(&mut self, f: &CanFrame) -> Result<(), TransportError> {
        if let CobKind::SdoRequest { node } = cob_id::classify(f.cob_id()) {
            let d = f.data();
            // Initiate download (ccs 1): expedited (e) or segmented.
            if d.len() == 8 && d[0] & 0xE0 == 0x20 {
                if d[0] & 0x02 != 0 {
                    let n = if d[0] & 0x01 != 0 {
                        4 - ((d[0] >> 2) & 3) as usize
                    } else {
                        4
                    };
                    let key = (node, u16::from_le_bytes([d[1], d[2]]), d[3]);
                    self.downloads.insert(key, d[4..4 + n].to_vec());
                } else {
                    self.segmented += 1;
                }
            }
        }
        self.inner.transmit(f)
    }

    fn receive(&mut self, timeout: Duration) -> Result<Option<CanFrame>, TransportError> {
        self.inner.receive(timeout)
    }
}

/// One SDO transfer with our client, to its end (5 s per answer).
fn transfer(
    t: &mut impl CanTransport,
    client: &mut SdoClient,
    first: CanFrame,
) -> Result<SdoOutcome, String> {
    t.transmit(&first).map_err(|e| e.to_string())?;
    let mut deadline = Instant::now() + Duration::from_secs(5);
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            if let Some(f) = client.abort(SdoAbortCode::TIMEOUT) {
                let _ = t.transmit(&f);
            }
            return Err("no SDO answer within 5 s".into());
        }
        let Some(f) = t.receive(left).map_err(|e| e.to_string())? else {
            continue;
        };
        match client.on_frame(&f) {
            SdoClientEvent::Ignored => {}
            SdoClientEvent::Transmit(next) => {
                t.transmit(&next).map_err(|e| e.to_string())?;
                deadline = Instant::now() + Duration::from_secs(5);
            }
            SdoClientEvent::Done(outcome) => return Ok(outcome),
            SdoClientEvent::Aborting { frame, code } => {
                t.transmit(&frame).map_err(|e| e.to_string())?;
                return Err(format!("our client aborted: {code}"));
            }
        }
    }
}

fn upload(t: &mut impl CanTransport, node: u8, index: u16, sub: u8) -> Result<SdoOutcome, String> {
    let mut c = SdoClient::new(node);
    let first = c.upload(index, sub).map_err(|e| e.to_string())?;
    transfer(t, &mut c, first)
}

fn download(
    t: &mut impl CanTransport,
    node: u8,
    index: u16,
    sub: u8,
    data: &[u8],
) -> Result<SdoOutcome, String> {
    let mut c = SdoClient::new(node);
    let first = c.download(index, sub, data).map_err(|e| e.to_string())?;
    transfer(t, &mut c, first)
}

#[derive(Default)]
struct Report {
    failed: Vec<&'static str>,
}

impl Report {
    fn check(&mut self, name: &'static str, ok: bool, observed: String) {
        println!(
            "CHECK {name}: {observed} -> {}",
            if ok { "ok" } else { "FAIL" }
        );
        if !ok {
            self.failed.push(name);
        }
    }
}

fn args() -> Result<(String, PathBuf, String), String> {
    let (mut can, mut machine, mut name) = (None, None, None);
    let mut a = std::env::args().skip(1);
    while let Some(k) = a.next() {
        match k.as_str() {
            "--can" => can = a.next(),
            "--machine" => machine = a.next().map(PathBuf::from),
            "--name" => name = a.next(),
            _ => return Err(format!("unknown argument {k}")),
        }
    }
    match (can, machine, name) {
        (Some(c), Some(m), Some(n)) => Ok((c, m, n)),
        _ => Err("usage: vcan-foreign-master --can IFACE --machine FILE --name NAME".into()),
    }
}

#[allow(
    clippy::too_many_lines,
    reason = "a test program: one check after another, read top to bottom"
)]
fn main() -> ExitCode {
    let (iface, machine, name) = match args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::from(2);
        }
    };
    let mut cfg = match MachineConfig::load(&machine) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::from(2);
        }
    };
    // One drive: the foreign device is node 1 (no spindle drive on this bus).
    cfg.axes.truncate(1);
    cfg.spindle = None;
    let inner = match SocketCanTransport::open(&iface) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("cannot open {iface}: {e}");
            return ExitCode::from(2);
        }
    };
    let mut t = Recording {
        inner,
        downloads: BTreeMap::new(),
        segmented: 0,
    };
    let mut r = Report::default();

    let started = startup::boot(&mut t, &cfg).and_then(|()| startup::configure(&mut t, &cfg));
    match &started {
        Ok(drives) => r.check(
            "foreign_startup_accepted",
            drives.len() == 1 && drives[0].ends_with(&format!(": {name}")),
            format!(
                "boot-up seen, {} SDO downloads accepted, 0x1008 read (segmented) as {:?}",
                t.downloads.len(),
                drives
            ),
        ),
        Err(e) => r.check("foreign_startup_accepted", false, e.to_string()),
    }
    let downloads = t.downloads.clone();
    let mut wrong = Vec::new();
    for (&(node, index, sub), written) in &downloads {
        match upload(&mut t, node, index, sub) {
            Ok(SdoOutcome::Uploaded(v)) if v.as_slice() == written.as_slice() => {}
            other => wrong.push(format!(
                "{index:04X}:{sub:02X} written {written:02X?}, read {other:?}"
            )),
        }
    }
    r.check(
        "foreign_downloads_read_back",
        downloads.len() >= 20 && t.segmented == 0 && wrong.is_empty(),
        format!(
            "{} objects written by the start-up, read back over SDO: {}",
            downloads.len(),
            if wrong.is_empty() {
                "all as written".to_string()
            } else {
                wrong.join("; ")
            }
        ),
    );
    // Node of the device: the one the start-up wrote to.
    let node = downloads.keys().next().map_or(1, |k| k.0);
    let named = upload(&mut t, node, 0x1008, 0);
    r.check(
        "foreign_segmented_upload_0x1008",
        matches!(&named, Ok(SdoOutcome::Uploaded(v)) if v.as_slice() == name.as_bytes()),
        match &named {
            Ok(SdoOutcome::Uploaded(v)) => {
                format!("{} bytes: {:?}", v.len(), String::from_utf8_lossy(v))
            }
            other => format!("{other:?}"),
        },
    );
    let product = upload(&mut t, node, 0x1018, 2);
    r.check(
        "foreign_expedited_upload_0x1018",
        matches!(&product, Ok(SdoOutcome::Uploaded(v)) if v.as_slice() == [0x02, 0x04, 0, 0]),
        format!("0x1018:2 {product:?}"),
    );
    for (check, outcome, want) in [
        (
            "foreign_abort_no_object",
            upload(&mut t, node, 0x2000, 0),
            SdoAbortCode::OBJECT_DOES_NOT_EXIST,
        ),
        (
            "foreign_abort_no_sub_index",
            upload(&mut t, node, 0x1018, 9),
            SdoAbortCode::SUB_INDEX_DOES_NOT_EXIST,
        ),
        (
            "foreign_abort_read_only",
            download(&mut t, node, 0x1000, 0, &[0, 0, 0, 0]),
            SdoAbortCode::READ_ONLY,
        ),
        (
            "foreign_abort_length",
            download(&mut t, node, 0x1006, 0, &[1, 2]),
            SdoAbortCode::LENGTH_MISMATCH,
        ),
    ] {
        r.check(
            check,
            outcome == Ok(SdoOutcome::Aborted(want)),
            format!("{outcome:?}, expected the abort {want}"),
        );
    }
    // After the aborts the channel still works.
    let after = upload(&mut t, node, 0x1006, 0);
    r.check(
        "foreign_sdo_after_aborts",
        matches!(&after, Ok(SdoOutcome::Uploaded(v)) if v.len() == 4),
        format!("0x1006 {after:?}"),
    );
    println!(
        "foreign master: {} failed: {}",
        r.failed.len(),
        if r.failed.is_empty() {
            "-".to_string()
        } else {
            r.failed.join(" ")
        }
    );
    if r.failed.is_empty() {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}
