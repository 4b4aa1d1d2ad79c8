//! The OPC UA face's door: the port clients connect to. The server itself listens on
//! a loopback port of its own; this loop takes each connection, refuses those beyond
//! `opcua.max_connections` at once (the OPC UA stack has no connection cap of its
//! own, only a session cap), and joins the others to the server. Accept errors are
//! logged and retried; they never end the face.

use crate::serve::face_log::{Event, FaceLog, SUMMARY_EVERY};
use std::net::SocketAddr;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::net::{TcpListener, TcpStream};

const ACCEPT_RETRY_FIRST: Duration = Duration::from_millis(50);
const ACCEPT_RETRY_MAX: Duration = Duration::from_secs(1);

/// Counts a connection while it is open.
struct Open(Arc<AtomicUsize>);

impl Drop for Open {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::AcqRel);
    }
}

/// Serves until the listener's task is dropped.
pub async fn serve(listener: TcpListener, server: SocketAddr, max_connections: usize) {
    let open = Arc::new(AtomicUsize::new(0));
    let log = Arc::new(Mutex::new(FaceLog::new(Instant::now())));
    let mut retry = ACCEPT_RETRY_FIRST;
    let mut summary = tokio::time::interval(SUMMARY_EVERY / 4);
    loop {
        let accepted = tokio::select! {
            _ = summary.tick() => {
                let n = open.load(Ordering::Acquire);
                let mut l = log.lock().unwrap_or_else(|e| e.into_inner());
                if let Some(line) = l.summary(Instant::now(), n, max_connections) {
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
                let mut l = log.lock().unwrap_or_else(|e| e.into_inner());
                if open.load(Ordering::Acquire) >= max_connections {
                    if let Some(held) = l.count(Event::RefusedFull, now) {
                        tracing::warn!(
                            %peer,
                            "OPC UA face: refused {peer}: {max_connections} connections open \
                             (opcua.max_connections; {held} more refused since the last such line)"
                        );
                    }
                    drop(client);
                    continue;
                }
                l.count(Event::Accepted, now);
                drop(l);
                open.fetch_add(1, Ordering::AcqRel);
                let guard = Open(open.clone());
                let log = log.clone();
                tokio::spawn(async move {
                    let why = join(client, server).await;
                    drop(guard);
                    let mut l = log.lock().unwrap_or_else(|e| e.into_inner());
                    l.count(Event::Closed, Instant::now());
                    tracing::debug!("OPC UA face: connection of {peer} closed ({why})");
                });
            }
            Err(e) => {
                let held = log
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .count(Event::AcceptError, now);
                if let Some(held) = held {
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

/// Joins a client to the server until either side closes.
async fn join(mut client: TcpStream, server: SocketAddr) -> String {
    crate::serve::modbus_face::keepalive(&client, server);
    let _ = client.set_nodelay(true);
    let mut upstream = match TcpStream::connect(server).await {
        Ok(s) => s,
        Err(e) => return format!("cannot reach the server: {e}"),
    };
    let _ = upstream.set_nodelay(true);
    match tokio::io::copy_bidirectional(&mut client, &mut upstream).await {
        Ok(_) => "closed".into(),
        Err(e) => e.to_string(),
    }
}
