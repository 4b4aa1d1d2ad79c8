//! The Modbus TCP server of the PLC face: a thin loop around [`super::gateway::Core`].
//! Holding registers only (FC3, FC6, FC16); other functions get IllegalFunction.

use super::gateway::{lock, Shared, WriteRefusal};
use super::register_map::MapException;
use std::future::Future;
use std::io;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::atomic::{AtomicU64, Ordering};
use std::thread::JoinHandle;
use tokio::net::TcpStream;
use tokio_modbus::server::Service;
use tokio_modbus::{ExceptionCode, Request, Response, SlaveRequest};

pub struct PlcFace {
    pub local_addr: SocketAddr,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<JoinHandle<io::Result<()>>>,
}

impl PlcFace {
    pub fn start(shared: Shared, bind: SocketAddr) -> io::Result<Self> {
        let listener = std::net::TcpListener::bind(bind)?;
        listener.set_nonblocking(true)?;
        let local_addr = listener.local_addr()?;
        let (tx, rx) = tokio::sync::oneshot::channel::<()>();
        let next_id = std::sync::Arc::new(AtomicU64::new(1));
        let thread = std::thread::Builder::new()
            .name("probebridge-plc-face".into())
            .spawn(move || {
                tokio::runtime::Builder::new_current_thread()
                    .enable_all()
                    .build()?
                    .block_on(async move {
                        let listener = tokio::net::TcpListener::from_std(listener)?;
                        let server = tokio_modbus::server::tcp::Server::new(listener);
                        let on_connected = |stream: TcpStream, addr: SocketAddr| {
                            let shared = shared.clone();
                            let id = next_id.fetch_add(1, Ordering::Relaxed);
                            async move {
                                tracing::info!(%addr, connection = id, "PLC face: connected");
                                Ok(Some((Connection { shared, id, addr }, stream)))
                            }
                        };
                        let abort = async move {
                            let _ = rx.await;
                        };
                        server
                            .serve_until(&on_connected, |e| tracing::warn!("PLC face: {e}"), abort)
                            .await
                            .map(|_| ())
                    })
            })?;
        Ok(Self {
            local_addr,
            stop: Some(tx),
            thread: Some(thread),
        })
    }
}

impl Drop for PlcFace {
    fn drop(&mut self) {
        if let Some(tx) = self.stop.take() {
            let _ = tx.send(());
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// One client connection.
struct Connection {
    shared: Shared,
    id: u64,
    addr: SocketAddr,
}

impl Drop for Connection {
    fn drop(&mut self) {
        tracing::info!(addr = %self.addr, connection = self.id, "PLC face: disconnected");
        lock(&self.shared).disconnected(self.id);
    }
}

fn exception(e: MapException) -> ExceptionCode {
    match e {
        MapException::IllegalDataAddress => ExceptionCode::IllegalDataAddress,
        MapException::IllegalDataValue => ExceptionCode::IllegalDataValue,
    }
}

fn write_refusal(e: WriteRefusal) -> ExceptionCode {
    match e {
        WriteRefusal::Busy => ExceptionCode::ServerDeviceBusy,
        WriteRefusal::Map(m) => exception(m),
    }
}

type Answer = Result<Option<Response>, ExceptionCode>;

impl Service for Connection {
    type Request = SlaveRequest<'static>;
    type Response = Option<Response>;
    type Exception = ExceptionCode;
    type Future = Pin<Box<dyn Future<Output = Answer> + Send>>;

    fn call(&self, req: Self::Request) -> Self::Future {
        let mut core = lock(&self.shared);
        let answer: Answer = match req.request {
            Request::ReadHoldingRegisters(addr, count) => core
                .map
                .read(addr, count)
                .map(|r| Some(Response::ReadHoldingRegisters(r)))
                .map_err(exception),
            Request::WriteMultipleRegisters(addr, values) => core
                .write(self.id, addr, &values)
                .map(|()| Some(Response::WriteMultipleRegisters(addr, values.len() as u16)))
                .map_err(write_refusal),
            Request::WriteSingleRegister(addr, value) => core
                .write(self.id, addr, &[value])
                .map(|()| Some(Response::WriteSingleRegister(addr, value)))
                .map_err(write_refusal),
            _ => Err(ExceptionCode::IllegalFunction),
        };
        Box::pin(std::future::ready(answer))
    }
}
