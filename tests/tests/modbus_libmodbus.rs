//! The Modbus client's error paths against libmodbus's own `unit-test-server` (built
//! from Debian's libmodbus source by `scripts/install-test-peers`): a busy exception, a
//! reply with a wrong transaction id, a reply after 500 ms, a slow byte-by-byte reply.
//! Each must end in a clear error or a clean recovery. The server serves one connection
//! and stops on errors, so every case gets its own server. Skipped with a line saying
//! why where the server is not built, never in CI.

use hal::modbus::client::ModbusClient;
use hal::modbus::exception::exception_kind;
use hal::modbus::ModbusBusConfig;
use hal::ErrorKind;
use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::Instant;
use tokio_modbus::ExceptionCode;

/// libmodbus's unit-test.h: the holding registers and the special addresses.
const UT_REGISTERS_ADDRESS: u16 = 0x160;
const SPECIAL_BUSY: u16 = 0x170;
const INVALID_TID_OR_SLAVE: u16 = 0x171;
const SLEEP_500_MS: u16 = 0x172;
const BYTE_SLEEP_5_MS: u16 = 0x173;

fn server_path() -> Option<PathBuf> {
    let p = std::env::var_os("PROBEBRIDGE_LIBMODBUS_SERVER")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("/opt/probebridge-libmodbus/unit-test-server"));
    if p.exists() {
        return Some(p);
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "{} missing in CI: scripts/install-test-peers should have built it",
        p.display()
    );
    eprintln!(
        "SKIPPED: {} is not built (scripts/install-test-peers)",
        p.display()
    );
    None
}

struct Server(Child);

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A fresh server on a free port and a client connected to it.
fn connect(path: &PathBuf, timeout_ms: u32) -> (Server, ModbusClient) {
    let mut child = Command::new(path)
        .args(["tcp", "0"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("start unit-test-server");
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let port = lines
        .by_ref()
        .find_map(|l| {
            l.ok()?
                .strip_prefix("listening on port ")?
                .parse::<u16>()
                .ok()
        })
        .expect("unit-test-server prints its port");
    // Its debug output goes on; keep the pipe drained.
    std::thread::spawn(move || for _ in lines {});
    let mut bus = ModbusBusConfig::tcp(format!("127.0.0.1:{port}"));
    // libmodbus's TCP server answers unit 0xFF.
    bus.unit = 255;
    bus.timeout_ms = timeout_ms;
    bus.busy_retries = 3;
    let client = ModbusClient::open(&bus).expect("connect to unit-test-server");
    // The link works before the special case (libmodbus's own client writes the
    // table first; here the registers hold their initial zeros).
    assert_eq!(
        client.read(UT_REGISTERS_ADDRESS, 3).unwrap().unwrap(),
        [0; 3]
    );
    (Server(child), client)
}

#[test]
fn busy_exception_is_retried_then_returned_as_data() {
    let Some(path) = server_path() else { return };
    let (_s, c) = connect(&path, 500);
    let a = c.read(SPECIAL_BUSY, 3).unwrap();
    assert_eq!(a, Err(ExceptionCode::ServerDeviceBusy));
    assert_eq!(
        exception_kind(ExceptionCode::ServerDeviceBusy),
        ErrorKind::Timeout
    );
    let s = c.stats();
    println!("libmodbus busy: {s:?}");
    assert_eq!(s.busy_retries, 3, "{s:?}");
    // Clean recovery: the same connection answers the next request.
    assert_eq!(c.read(UT_REGISTERS_ADDRESS, 3).unwrap().unwrap(), [0; 3]);
    assert_eq!(c.stats().transport_errors, 0);
}

#[test]
fn a_reply_with_the_wrong_transaction_id_is_a_transport_error() {
    let Some(path) = server_path() else { return };
    let (_s, c) = connect(&path, 500);
    let e = c.read(INVALID_TID_OR_SLAVE, 1).unwrap_err();
    println!("libmodbus wrong transaction id: {e}");
    assert_eq!(e.kind, ErrorKind::Bus, "{e}");
    assert!(e.to_string().contains("mismatch"), "{e}");
    let s = c.stats();
    assert_eq!(s.transport_errors, 1, "{s:?}");
}

#[test]
fn a_reply_after_500_ms_is_a_timeout_or_waited_for() {
    let Some(path) = server_path() else { return };
    let (_s, c) = connect(&path, 200);
    let t = Instant::now();
    let e = c.read(SLEEP_500_MS, 3).unwrap_err();
    println!(
        "libmodbus 500 ms reply, 200 ms timeout: {e} after {:?}",
        t.elapsed()
    );
    assert_eq!(e.kind, ErrorKind::Timeout, "{e}");
    assert_eq!(c.stats().timeouts, 1);

    let (_s, c) = connect(&path, 1000);
    let t = Instant::now();
    let r = c.read(SLEEP_500_MS, 3).unwrap().unwrap();
    println!(
        "libmodbus 500 ms reply, 1 s timeout: {r:?} after {:?}",
        t.elapsed()
    );
    assert_eq!(r.len(), 3);
    assert!(t.elapsed().as_millis() >= 500);
}

#[test]
fn a_slow_byte_by_byte_reply_is_assembled() {
    let Some(path) = server_path() else { return };
    let (_s, c) = connect(&path, 1000);
    let t = Instant::now();
    let r = c.read(BYTE_SLEEP_5_MS, 1).unwrap().unwrap();
    println!(
        "libmodbus byte-by-byte reply: {r:?} after {:?}",
        t.elapsed()
    );
    assert_eq!(r, [0]);
    let s = c.stats();
    assert_eq!((s.timeouts, s.transport_errors), (0, 0), "{s:?}");
}
