//! The Modbus client as a thread: a current-thread tokio runtime running tokio-modbus
//! (not its sync wrappers, which panic inside a runtime), talked to through channels so
//! the `Machine` side stays blocking. Client hygiene lives here:
//! - every request under the configured timeout;
//! - after a TCP timeout the connection is dropped and opened anew (a late reply would
//!   otherwise be taken for the answer to the next transaction);
//! - after an RTU timeout the port is reopened and the line drained for another
//!   timeout and until it has been silent for a frame gap;
//! - a `ServerDeviceBusy` answer is retried after a poll period, `busy_retries` times.
//!
//! Exceptions come back as data (`Ok(Err(code))`); only transport failures are `Err`.

use super::config::{ModbusBusConfig, Parity, Transport};
use crate::machine::{ErrorKind, MachineError};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;
use tokio_modbus::client::{Context, Reader, Writer};
use tokio_modbus::{ExceptionCode, Slave};

enum Request {
    Read { addr: u16, count: u16 },
    Write { addr: u16, values: Vec<u16> },
}

/// A device's answer: registers or nothing, or the exception it answered with.
pub type Answer<T> = Result<Result<T, ExceptionCode>, MachineError>;

/// What the client went through (read by tests and the CLI).
#[derive(Debug, Default)]
pub struct ClientCounters {
    pub requests: AtomicU64,
    pub timeouts: AtomicU64,
    pub reconnects: AtomicU64,
    pub busy_retries: AtomicU64,
    pub transport_errors: AtomicU64,
}

/// Snapshot of [`ClientCounters`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ClientStats {
    pub requests: u64,
    pub timeouts: u64,
    pub reconnects: u64,
    pub busy_retries: u64,
    pub transport_errors: u64,
}

pub struct ModbusClient {
    requests: Option<SyncSender<Request>>,
    answers: Receiver<Answer<Vec<u16>>>,
    thread: Option<JoinHandle<()>>,
    counters: Arc<ClientCounters>,
    /// Longest wait for the thread's answer: every retry's timeout plus slack.
    patience: Duration,
}

impl ModbusClient {
    /// Starts the I/O thread and connects; fails when the device cannot be reached.
    pub fn open(bus: &ModbusBusConfig) -> Result<Self, MachineError> {
        let (req_tx, req_rx) = sync_channel::<Request>(1);
        let (ans_tx, ans_rx) = sync_channel::<Answer<Vec<u16>>>(1);
        let counters = Arc::new(ClientCounters::default());
        let bus2 = bus.clone();
        let c2 = counters.clone();
        let thread = std::thread::Builder::new()
            .name("probebridge-modbus".into())
            .spawn(move || io_thread(&bus2, &c2, &req_rx, &ans_tx))
            .map_err(|e| {
                MachineError::new(
                    ErrorKind::Other,
                    format!("cannot start the Modbus thread: {e}"),
                )
            })?;
        let timeout = Duration::from_millis(bus.timeout_ms as u64);
        let client = Self {
            requests: Some(req_tx),
            answers: ans_rx,
            thread: Some(thread),
            counters,
            patience: timeout * (bus.busy_retries + 2) * 2
                + Duration::from_millis(bus.poll_ms as u64) * (bus.busy_retries + 1)
                + Duration::from_secs(1),
        };
        // The thread answers the connection attempt first.
        match client.answers.recv_timeout(client.patience) {
            Ok(Ok(_)) => Ok(client),
            Ok(Err(e)) => Err(e),
            Err(_) => Err(MachineError::new(
                ErrorKind::Timeout,
                "the Modbus thread did not start",
            )),
        }
    }

    pub fn stats(&self) -> ClientStats {
        let c = &self.counters;
        ClientStats {
            requests: c.requests.load(Ordering::Relaxed),
            timeouts: c.timeouts.load(Ordering::Relaxed),
            reconnects: c.reconnects.load(Ordering::Relaxed),
            busy_retries: c.busy_retries.load(Ordering::Relaxed),
            transport_errors: c.transport_errors.load(Ordering::Relaxed),
        }
    }

    fn call(&self, req: Request) -> Answer<Vec<u16>> {
        let stopped = || MachineError::new(ErrorKind::Bus, "the Modbus thread has stopped");
        self.requests
            .as_ref()
            .ok_or_else(stopped)?
            .send(req)
            .map_err(|_| stopped())?;
        self.answers
            .recv_timeout(self.patience)
            .map_err(|_| stopped())?
    }

    /// FC3: `count` holding registers from `addr`.
    pub fn read(&self, addr: u16, count: u16) -> Answer<Vec<u16>> {
        match self.call(Request::Read { addr, count })? {
            Ok(r) if r.len() != count as usize => Err(MachineError::new(
                ErrorKind::Bus,
                format!("asked for {count} registers at {addr}, got {}", r.len()),
            )),
            other => Ok(other),
        }
    }

    /// FC16 (FC6 for one register).
    pub fn write(&self, addr: u16, values: &[u16]) -> Answer<()> {
        Ok(self
            .call(Request::Write {
                addr,
                values: values.to_vec(),
            })?
            .map(|_| ()))
    }
}

impl Drop for ModbusClient {
    fn drop(&mut self) {
        self.requests = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn transport_error(what: &str, e: impl std::fmt::Display) -> MachineError {
    MachineError::new(ErrorKind::Bus, format!("{what}: {e}"))
}

/// Opens the connection. RTU: the line is drained first, for at least `quiet_for`
/// (after a timeout: the time a late answer may still take).
async fn connect(bus: &ModbusBusConfig, quiet_for: Duration) -> Result<Context, MachineError> {
    let slave = Slave(bus.unit);
    let timeout = Duration::from_millis(bus.timeout_ms as u64);
    match bus.transport {
        Transport::Tcp => {
            let addr = bus.address.as_deref().unwrap_or_default();
            let sock: std::net::SocketAddr = tokio::net::lookup_host(addr)
                .await
                .map_err(|e| transport_error(addr, e))?
                .next()
                .ok_or_else(|| transport_error(addr, "no address"))?;
            match tokio::time::timeout(
                timeout,
                tokio_modbus::client::tcp::connect_slave(sock, slave),
            )
            .await
            {
                Ok(Ok(ctx)) => Ok(ctx),
                Ok(Err(e)) => Err(transport_error(&format!("cannot connect to {addr}"), e)),
                Err(_) => Err(MachineError::new(
                    ErrorKind::Timeout,
                    format!("no connection to {addr} within {} ms", bus.timeout_ms),
                )),
            }
        }
        Transport::Rtu => {
            use tokio_serial::SerialPort;
            let dev = bus.device.as_deref().unwrap_or_default();
            let parity = match bus.parity {
                Parity::None => tokio_serial::Parity::None,
                Parity::Even => tokio_serial::Parity::Even,
                Parity::Odd => tokio_serial::Parity::Odd,
            };
            let mut port =
                tokio_serial::SerialStream::open(&tokio_serial::new(dev, bus.baud).parity(parity))
                    .map_err(|e| transport_error(&format!("cannot open {dev}"), e))?;
            // Whatever a previous session (or a late answer) left on the line is not an
            // answer of ours: drain until the line has been silent for a frame gap.
            let _ = port.clear(tokio_serial::ClearBuffer::All);
            drain(&mut port, bus, quiet_for).await;
            Ok(tokio_modbus::client::rtu::attach_slave(port, slave))
        }
    }
}

/// Reads and discards until `window` has passed and nothing arrived for a frame gap
/// (at most `window` + `timeout_ms`).
async fn drain(port: &mut tokio_serial::SerialStream, bus: &ModbusBusConfig, window: Duration) {
    use tokio::io::AsyncReadExt;
    let gap = Duration::from_micros(bus.frame_gap_us() as u64);
    let start = tokio::time::Instant::now();
    let give_up = start + window + Duration::from_millis(bus.timeout_ms as u64);
    let mut buf = [0u8; 256];
    while tokio::time::Instant::now() < give_up {
        match tokio::time::timeout(gap, port.read(&mut buf)).await {
            Ok(Ok(n)) if n > 0 => continue,
            _ if start.elapsed() >= window => break,
            _ => {}
        }
    }
}

async fn once(ctx: &mut Context, req: &Request) -> tokio_modbus::Result<Vec<u16>> {
    match req {
        Request::Read { addr, count } => ctx.read_holding_registers(*addr, *count).await,
        Request::Write { addr, values } if values.len() == 1 => ctx
            .write_single_register(*addr, values[0])
            .await
            .map(|r| r.map(|()| Vec::new())),
        Request::Write { addr, values } => ctx
            .write_multiple_registers(*addr, values)
            .await
            .map(|r| r.map(|()| Vec::new())),
    }
}

async fn serve(
    bus: &ModbusBusConfig,
    counters: &ClientCounters,
    conn: &mut Option<Context>,
    req: &Request,
) -> Answer<Vec<u16>> {
    let timeout = Duration::from_millis(bus.timeout_ms as u64);
    let mut busy = 0;
    loop {
        if conn.is_none() {
            counters.reconnects.fetch_add(1, Ordering::Relaxed);
            // Connections are only dropped after a failure: on RTU a late answer may
            // still be on its way.
            *conn = Some(connect(bus, timeout).await?);
        }
        let Some(ctx) = conn.as_mut() else {
            continue;
        };
        counters.requests.fetch_add(1, Ordering::Relaxed);
        match tokio::time::timeout(timeout, once(ctx, req)).await {
            Ok(Ok(Ok(r))) => return Ok(Ok(r)),
            Ok(Ok(Err(ExceptionCode::ServerDeviceBusy))) if busy < bus.busy_retries => {
                busy += 1;
                counters.busy_retries.fetch_add(1, Ordering::Relaxed);
                tokio::time::sleep(Duration::from_millis(bus.poll_ms as u64)).await;
            }
            Ok(Ok(Err(e))) => return Ok(Err(e)),
            Ok(Err(e)) => {
                // A broken stream or an answer to another transaction / unit: start over
                // on a fresh connection.
                counters.transport_errors.fetch_add(1, Ordering::Relaxed);
                *conn = None;
                return Err(transport_error("Modbus transport", e));
            }
            Err(_) => {
                counters.timeouts.fetch_add(1, Ordering::Relaxed);
                *conn = None;
                // RTU: the port is reopened and drained for another timeout (see
                // `connect`) before the next request, which starts after a silent gap.
                return Err(MachineError::new(
                    ErrorKind::Timeout,
                    format!("no Modbus answer within {} ms", bus.timeout_ms),
                ));
            }
        }
    }
}

fn io_thread(
    bus: &ModbusBusConfig,
    counters: &ClientCounters,
    requests: &Receiver<Request>,
    answers: &SyncSender<Answer<Vec<u16>>>,
) {
    let rt = match tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            let _ = answers.send(Err(transport_error("cannot start the tokio runtime", e)));
            return;
        }
    };
    let mut conn = match rt.block_on(connect(bus, Duration::ZERO)) {
        Ok(c) => Some(c),
        Err(e) => {
            let _ = answers.send(Err(e));
            return;
        }
    };
    if answers.send(Ok(Ok(Vec::new()))).is_err() {
        return;
    }
    // Blocking between requests is fine: nothing else runs on this runtime.
    while let Ok(req) = requests.recv() {
        let a = rt.block_on(serve(bus, counters, &mut conn, &req));
        if answers.send(a).is_err() {
            return;
        }
    }
    if let Some(mut c) = conn {
        let _ = rt.block_on(tokio_modbus::client::Client::disconnect(&mut c));
    }
}
