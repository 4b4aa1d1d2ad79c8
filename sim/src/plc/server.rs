//! The simulated PLC on Modbus: its program stepped in a thread of its own (in real
//! time, or on a virtual clock as fast as it runs while a command is active), and a
//! tokio-modbus server (TCP or RTU) reading and writing its registers. The knobs of
//! [`super::Knobs`] make the server answer late, with exceptions, or hang up.

use super::program::PlcProgram;
use std::future::Future;
use std::io;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::task::{Context, Poll};
use std::thread::JoinHandle;
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::TcpStream;
use tokio_modbus::server::Service;
use tokio_modbus::{ExceptionCode, Request, Response, SlaveRequest};

/// How the PLC's clock runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlcPacing {
    /// One PLC cycle per cycle time of CLOCK_MONOTONIC.
    RealTime,
    /// Cycles run back to back while a command is active; time stands still between
    /// commands.
    Virtual,
}

struct Shared {
    plc: Mutex<PlcProgram>,
    wake: Condvar,
    stop: AtomicBool,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, PlcProgram> {
        self.plc.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// A running simulated PLC and its Modbus server.
pub struct SimPlc {
    shared: Arc<Shared>,
    task: Option<JoinHandle<()>>,
    server: Option<JoinHandle<io::Result<()>>>,
    stop_server: Option<tokio::sync::oneshot::Sender<()>>,
    local_addr: Option<SocketAddr>,
}

impl SimPlc {
    /// Serves Modbus TCP on `bind` (port 0: any free port, see [`SimPlc::local_addr`]).
    pub fn serve_tcp(
        program: PlcProgram,
        unit: u8,
        bind: SocketAddr,
        pacing: PlcPacing,
    ) -> io::Result<Self> {
        let listener = std::net::TcpListener::bind(bind)?;
        listener.set_nonblocking(true)?;
        let local_addr = listener.local_addr()?;
        let mut plc = Self::start(program, pacing);
        let shared = plc.shared.clone();
        let (tx, rx) = tokio::sync::oneshot::channel::<()>();
        plc.stop_server = Some(tx);
        plc.local_addr = Some(local_addr);
        plc.server = Some(spawn_runtime("probebridge-plc-tcp", async move {
            let listener = tokio::net::TcpListener::from_std(listener)?;
            let server = tokio_modbus::server::tcp::Server::new(listener);
            let on_connected = |stream: TcpStream, _addr: SocketAddr| {
                let shared = shared.clone();
                async move {
                    let kill = Arc::new(AtomicBool::new(false));
                    let service = PlcService {
                        shared,
                        unit,
                        kill: Some(kill.clone()),
                    };
                    Ok(Some((
                        service,
                        Killable {
                            inner: stream,
                            kill,
                        },
                    )))
                }
            };
            let abort = async move {
                let _ = rx.await;
            };
            server
                .serve_until(&on_connected, |_e| {}, abort)
                .await
                .map(|_| ())
        })?);
        Ok(plc)
    }

    /// Serves Modbus RTU on the serial device `path` (one end of a pty pair in tests).
    pub fn serve_rtu(
        program: PlcProgram,
        unit: u8,
        path: &str,
        baud: u32,
        pacing: PlcPacing,
    ) -> io::Result<Self> {
        let mut plc = Self::start(program, pacing);
        let shared = plc.shared.clone();
        let (tx, rx) = tokio::sync::oneshot::channel::<()>();
        plc.stop_server = Some(tx);
        let path = path.to_string();
        plc.server = Some(spawn_runtime("probebridge-plc-rtu", async move {
            let serial = tokio_serial::SerialStream::open(&tokio_serial::new(&path, baud))
                .map_err(io::Error::other)?;
            let server = tokio_modbus::server::rtu::Server::new(serial);
            let service = PlcService {
                shared,
                unit,
                kill: None,
            };
            let abort = async move {
                let _ = rx.await;
            };
            server.serve_until(service, abort).await.map(|_| ())
        })?);
        Ok(plc)
    }

    fn start(program: PlcProgram, pacing: PlcPacing) -> Self {
        let shared = Arc::new(Shared {
            plc: Mutex::new(program),
            wake: Condvar::new(),
            stop: AtomicBool::new(false),
        });
        let task = {
            let shared = shared.clone();
            std::thread::Builder::new()
                .name("probebridge-plc".into())
                .spawn(move || run_task(&shared, pacing))
                .expect("spawn the PLC task")
        };
        Self {
            shared,
            task: Some(task),
            server: None,
            stop_server: None,
            local_addr: None,
        }
    }

    /// Where the TCP server listens.
    pub fn local_addr(&self) -> Option<SocketAddr> {
        self.local_addr
    }

    /// Runs `f` on the PLC program (turn knobs, look at the world).
    pub fn with_program<R>(&self, f: impl FnOnce(&mut PlcProgram) -> R) -> R {
        f(&mut self.shared.lock())
    }

    /// Runs until the server fails (the `sim` command).
    pub fn wait(mut self) -> io::Result<()> {
        match self.server.take().map(JoinHandle::join) {
            Some(Ok(r)) => r,
            _ => Err(io::Error::other("the Modbus server thread panicked")),
        }
    }
}

impl Drop for SimPlc {
    fn drop(&mut self) {
        if let Some(tx) = self.stop_server.take() {
            let _ = tx.send(());
        }
        if let Some(s) = self.server.take() {
            let _ = s.join();
        }
        self.shared.stop.store(true, Ordering::Release);
        self.shared.wake.notify_all();
        if let Some(t) = self.task.take() {
            let _ = t.join();
        }
    }
}

fn spawn_runtime(
    name: &str,
    fut: impl Future<Output = io::Result<()>> + Send + 'static,
) -> io::Result<JoinHandle<io::Result<()>>> {
    std::thread::Builder::new()
        .name(name.into())
        .spawn(move || {
            tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()?
                .block_on(fut)
        })
}

fn run_task(shared: &Shared, pacing: PlcPacing) {
    let cycle_ns = shared.lock().cycle_ns();
    let mut deadline = hal::clock::monotonic_ns();
    while !shared.stop.load(Ordering::Acquire) {
        match pacing {
            PlcPacing::Virtual => {
                let mut plc = shared.lock();
                if !plc.is_busy() {
                    plc = shared
                        .wake
                        .wait_timeout(plc, Duration::from_millis(20))
                        .unwrap_or_else(|e| e.into_inner())
                        .0;
                    if !plc.is_busy() {
                        continue;
                    }
                }
                // A batch per lock, so the server gets its turn between batches.
                for _ in 0..64 {
                    plc.step();
                    if !plc.is_busy() {
                        break;
                    }
                }
            }
            PlcPacing::RealTime => {
                deadline += cycle_ns;
                hal::clock::sleep_until_ns(deadline);
                let now = hal::clock::monotonic_ns();
                if now > deadline + 10 * cycle_ns {
                    deadline = now;
                }
                shared.lock().step();
            }
        }
    }
}

/// One connection's view of the PLC.
struct PlcService {
    shared: Arc<Shared>,
    unit: u8,
    /// Set to hang up this connection (TCP only).
    kill: Option<Arc<AtomicBool>>,
}

type Answer = Result<Option<Response>, ExceptionCode>;

impl Service for PlcService {
    type Request = SlaveRequest<'static>;
    type Response = Option<Response>;
    type Exception = ExceptionCode;
    type Future = Pin<Box<dyn Future<Output = Answer> + Send>>;

    fn call(&self, req: Self::Request) -> Self::Future {
        if req.slave != self.unit {
            // Not addressed to us: a real unit stays silent.
            return Box::pin(std::future::ready(Ok(None)));
        }
        let mut plc = self.shared.lock();
        let late = plc.knobs.take_late();
        if let Some(kill) = &self.kill {
            let layout = plc.layout();
            match req.request {
                Request::WriteMultipleRegisters(a, _)
                    if a == layout.command_base && plc.knobs.drop_connection_mid_move =>
                {
                    plc.knobs.drop_armed = true;
                }
                Request::ReadHoldingRegisters(a, _)
                    if a == layout.status_base && plc.knobs.drop_armed =>
                {
                    plc.knobs.drop_armed = false;
                    plc.knobs.drop_connection_mid_move = false;
                    kill.store(true, Ordering::Release);
                    return Box::pin(std::future::ready(Ok(None)));
                }
                _ => {}
            }
        }
        let answer: Answer = match plc.knobs.take_exception() {
            Some(e) => Err(e),
            None => match req.request {
                Request::ReadHoldingRegisters(addr, count) => plc
                    .read(addr, count)
                    .map(|r| Some(Response::ReadHoldingRegisters(r))),
                Request::WriteMultipleRegisters(addr, values) => plc
                    .write(addr, &values)
                    .map(|()| Some(Response::WriteMultipleRegisters(addr, values.len() as u16))),
                Request::WriteSingleRegister(addr, value) => plc
                    .write(addr, &[value])
                    .map(|()| Some(Response::WriteSingleRegister(addr, value))),
                _ => Err(ExceptionCode::IllegalFunction),
            },
        };
        drop(plc);
        self.shared.wake.notify_all();
        match late {
            Some(ms) => Box::pin(async move {
                tokio::time::sleep(Duration::from_millis(ms)).await;
                answer
            }),
            None => Box::pin(std::future::ready(answer)),
        }
    }
}

/// A TCP stream the server can hang up from inside a request.
struct Killable {
    inner: TcpStream,
    kill: Arc<AtomicBool>,
}

impl AsyncRead for Killable {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        if self.kill.load(Ordering::Acquire) {
            return Poll::Ready(Err(io::Error::new(
                io::ErrorKind::ConnectionAborted,
                "simulated PLC hung up",
            )));
        }
        Pin::new(&mut self.inner).poll_read(cx, buf)
    }
}

impl AsyncWrite for Killable {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        Pin::new(&mut self.inner).poll_write(cx, buf)
    }
    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }
    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}
