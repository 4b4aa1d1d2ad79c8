//! The OPC UA face's door: the port clients connect to. The server itself listens on
//! a loopback port of its own; this loop takes each connection and joins it to the
//! server once it has sent an OPC UA Hello (OPC 10000-6 §7.1.2.3: the first message of
//! a connection). The OPC UA stack has no connection cap of its own, only a session
//! cap, so the cap is here, with what keeps it from being held by silent sockets:
//!
//! - a connection that has not sent a Hello within [`HELLO_TIMEOUT`] is closed, and
//!   one still waiting for its Hello is closed at once to make room for a new one when
//!   `opcua.max_connections` are open (a real client sends its Hello as it connects);
//! - a connection is closed when either side closes it (the server ends one without
//!   an OpenSecureChannel soon after the Hello, or whose channel token was not
//!   renewed) and when nothing crossed it for the session timeout (no session outlives
//!   that silence anyway).
//!
//! Accept errors are logged and retried; they never end the face.

use crate::serve::face_log::{Event, FaceLog, SUMMARY_EVERY};
use std::collections::VecDeque;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::Notify;

const ACCEPT_RETRY_FIRST: Duration = Duration::from_millis(50);
const ACCEPT_RETRY_MAX: Duration = Duration::from_secs(1);
/// How long a new connection may take to send its Hello (the OPC UA stack's own
/// default for the same wait).
pub const HELLO_TIMEOUT: Duration = Duration::from_secs(5);
/// A message header: its type (`HEL`), the chunk type (`F`) and its size.
const HEADER_LEN: usize = 8;
const HELLO: &[u8; 4] = b"HELF";
const PIPE_BUFFER: usize = 16 * 1024;

/// The door's limits (from `[opcua]`).
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    pub max_connections: usize,
    /// Nothing crossed the connection for this long: it is closed.
    pub idle_timeout: Duration,
}

/// Counts a connection while it is open.
struct Open(Arc<AtomicUsize>);

impl Drop for Open {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::AcqRel);
    }
}

/// The connections still waiting for their Hello, oldest first: the ones closed to
/// make room.
#[derive(Default)]
struct Waiting {
    next: u64,
    queue: VecDeque<(u64, Arc<Notify>)>,
}

impl Waiting {
    fn add(&mut self) -> (u64, Arc<Notify>) {
        let (id, close) = (self.next, Arc::new(Notify::new()));
        self.next += 1;
        self.queue.push_back((id, close.clone()));
        (id, close)
    }

    fn remove(&mut self, id: u64) {
        self.queue.retain(|(i, _)| *i != id);
    }

    /// Closes the oldest waiting connection; false: none waits.
    fn evict_oldest(&mut self) -> bool {
        match self.queue.pop_front() {
            Some((_, close)) => {
                close.notify_one();
                true
            }
            None => false,
        }
    }
}

fn locked<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// Serves until the listener's task is dropped.
pub async fn serve(listener: TcpListener, server: SocketAddr, limits: Limits) {
    let max_connections = limits.max_connections;
    let open = Arc::new(AtomicUsize::new(0));
    let waiting = Arc::new(Mutex::new(Waiting::default()));
    let log = Arc::new(Mutex::new(FaceLog::named("OPC UA face", Instant::now())));
    let mut retry = ACCEPT_RETRY_FIRST;
    let mut summary = tokio::time::interval(SUMMARY_EVERY / 4);
    loop {
        let accepted = tokio::select! {
            _ = summary.tick() => {
                let n = open.load(Ordering::Acquire);
                if let Some(line) = locked(&log).summary(Instant::now(), n, max_connections) {
                    // The counts' line is the PLC face's; the face's name is ours.
                    tracing::info!("{}", line.replacen("PLC face", "OPC UA face", 1));
                }
                continue;
            }
            a = listener.accept() => a,
        };
        let now = Instant::now();
        match accepted {
            Ok((client, peer)) => {
                retry = ACCEPT_RETRY_FIRST;
                let mut l = locked(&log);
                if open.load(Ordering::Acquire) >= max_connections {
                    if locked(&waiting).evict_oldest() {
                        if let Some(held) = l.count(Event::Evicted, now) {
                            tracing::warn!(
                                %peer,
                                "OPC UA face: {max_connections} connections open \
                                 (opcua.max_connections): closed one that had sent no Hello \
                                 to take {peer} ({held} more since the last such line)"
                            );
                        }
                    } else {
                        if let Some(held) = l.count(Event::RefusedFull, now) {
                            tracing::warn!(
                                %peer,
                                "OPC UA face: refused {peer}: {max_connections} connections \
                                 open (opcua.max_connections; {held} more refused since the \
                                 last such line)"
                            );
                        }
                        drop(client);
                        continue;
                    }
                }
                l.count(Event::Accepted, now);
                drop(l);
                open.fetch_add(1, Ordering::AcqRel);
                let guard = Open(open.clone());
                let (log, waiting) = (log.clone(), waiting.clone());
                tokio::spawn(async move {
                    let why = connection(client, server, limits, &waiting).await;
                    drop(guard);
                    locked(&log).count(Event::Closed, Instant::now());
                    tracing::debug!("OPC UA face: connection of {peer} closed ({why})");
                });
            }
            Err(e) => {
                if let Some(held) = locked(&log).count(Event::AcceptError, now) {
                    tracing::warn!(
                        "OPC UA face: accept failed: {e}; retrying ({held} more since the last \
                         such line)"
                    );
                }
                tokio::time::sleep(retry).await;
                retry = (retry * 2).min(ACCEPT_RETRY_MAX);
            }
        }
    }
}

/// One connection: its Hello, then joined to the server; why it ended.
async fn connection(
    mut client: TcpStream,
    server: SocketAddr,
    limits: Limits,
    waiting: &Mutex<Waiting>,
) -> String {
    let (id, close) = locked(waiting).add();
    let mut header = [0u8; HEADER_LEN];
    let hello = tokio::select! {
        r = tokio::time::timeout(HELLO_TIMEOUT, client.read_exact(&mut header)) => Some(r),
        () = close.notified() => None,
    };
    locked(waiting).remove(id);
    match hello {
        None => return "closed for a new connection: no Hello yet".into(),
        Some(Err(_)) => return format!("no Hello within {HELLO_TIMEOUT:?}"),
        Some(Ok(Err(e))) => return format!("before its Hello: {e}"),
        Some(Ok(Ok(_))) if &header[..4] != HELLO => {
            return format!("its first message is not a Hello: {:?}", &header[..4])
        }
        Some(Ok(Ok(_))) => {}
    }
    crate::serve::tcp_keepalive::set(&client, server);
    let _ = client.set_nodelay(true);
    let mut upstream = match TcpStream::connect(server).await {
        Ok(s) => s,
        Err(e) => return format!("cannot reach the server: {e}"),
    };
    let _ = upstream.set_nodelay(true);
    if let Err(e) = upstream.write_all(&header).await {
        return format!("the server: {e}");
    }
    pipe(client, upstream, limits.idle_timeout).await
}

/// Copies both ways until either side closes or nothing crosses for `idle`.
async fn pipe(client: TcpStream, upstream: TcpStream, idle: Duration) -> String {
    let (mut client_in, mut client_out) = client.into_split();
    let (mut server_in, mut server_out) = upstream.into_split();
    let (mut up, mut down) = (vec![0u8; PIPE_BUFFER], vec![0u8; PIPE_BUFFER]);
    loop {
        // Reads are cancel-safe: the one not taken loses nothing.
        let (n, upward) = tokio::select! {
            r = client_in.read(&mut up) => match r {
                Ok(0) => return "the client closed it".into(),
                Ok(n) => (n, true),
                Err(e) => return format!("the client: {e}"),
            },
            r = server_in.read(&mut down) => match r {
                Ok(0) => return "the server closed it".into(),
                Ok(n) => (n, false),
                Err(e) => return format!("the server: {e}"),
            },
            () = tokio::time::sleep(idle) => return format!("nothing crossed it for {idle:?}"),
        };
        let (to, bytes) = if upward {
            (&mut server_out, &up[..n])
        } else {
            (&mut client_out, &down[..n])
        };
        // A peer that does not read is as silent as one that does not write.
        match tokio::time::timeout(idle, to.write_all(bytes)).await {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return e.to_string(),
            Err(_) => return format!("a write took longer than {idle:?}"),
        }
    }
}
