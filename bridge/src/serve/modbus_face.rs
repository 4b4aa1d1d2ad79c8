//! The Modbus TCP server of the PLC face: an accept loop and one task per connection
//! around [`super::plc_registers::PlcRegisters`] (in [`super::gateway::Gateway`]). Holding
//! registers only (FC3, FC6, FC16); other functions get IllegalFunction.
//!
//! The face must stay reachable for its PLC whatever else is on the network:
//! - peers outside `plc.allow` are refused at accept;
//! - at most `plc.max_connections_per_peer` of one address: one host's flood of idle
//!   connections leaves the others room (its own connection silent longest is closed
//!   for its new one once silent for the owner timeout, else the new one is refused);
//! - at most `plc.max_connections` are served; one more is refused at accept, unless
//!   the connection silent longest has been silent for the owner timeout: that one is
//!   closed for the new (a PLC that rebooted gets back in past idle squatters);
//! - the address of the last owner of the request block (the PLC) keeps a place: its
//!   new connection at the limit closes the silent-longest connection of another
//!   address, however recent, and no other address's new connection closes one of it;
//! - an accept error (EMFILE, ENFILE, ENOBUFS, ...) is logged and retried after a
//!   short wait: it never ends the server;
//! - accepted sockets have TCP keepalive (a dead peer is noticed in about 10 s) and a
//!   user timeout for unacknowledged answers;
//! - the face ticks a heartbeat the service loop watches ([`PlcFace::health`]): a face
//!   that stalls or ends stops the service, so systemd restarts it.

use super::face_log::{Event, FaceLog, SUMMARY_EVERY};
use super::face_thread::{FaceHealth, FaceThread, Flavour, Heartbeat};
use super::gateway::{lock, Gateway, Shared};
use super::peer_allow::AllowList;
use super::plc_registers::WriteRefusal;
use super::register_map::MapException;
use std::collections::BTreeMap;
use std::io;
use std::net::{IpAddr, SocketAddr};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio::sync::Notify;

/// MBAP header: transaction, protocol, length, unit.
const MBAP_LEN: usize = 7;
/// The longest length field taken: FC16 with a byte count of 255 (a frame beyond the
/// standard's 253-byte PDU is still read, to answer IllegalDataValue, not to close).
const MAX_LENGTH_FIELD: usize = 1 + 6 + 255;
/// First wait after a failed accept; doubled up to [`ACCEPT_RETRY_MAX`].
const ACCEPT_RETRY_FIRST: Duration = Duration::from_millis(50);
const ACCEPT_RETRY_MAX: Duration = Duration::from_secs(1);
/// An answer the peer does not take within this long ends its connection.
const WRITE_TIMEOUT: Duration = Duration::from_secs(10);

const EXC_ILLEGAL_FUNCTION: u8 = 1;
const EXC_ILLEGAL_DATA_ADDRESS: u8 = 2;
const EXC_ILLEGAL_DATA_VALUE: u8 = 3;
const EXC_SERVER_DEVICE_BUSY: u8 = 6;

/// The PLC face's limits (from `[plc]`).
#[derive(Clone, Debug)]
pub struct FaceOptions {
    pub max_connections: usize,
    /// Connections of one address at most.
    pub max_per_peer: usize,
    /// A connection silent this long may be closed for a new one at the limit.
    pub silence: Duration,
    pub allow: AllowList,
}

/// Binds the face's address (before the machine is opened: a port in use is found at
/// once).
pub fn bind(addr: SocketAddr) -> io::Result<std::net::TcpListener> {
    let listener = std::net::TcpListener::bind(addr)?;
    listener.set_nonblocking(true)?;
    Ok(listener)
}

pub struct PlcFace {
    pub local_addr: SocketAddr,
    thread: FaceThread,
}

/// Fault injection for the tests of the service's supervision (never set in
/// production): `stall` blocks the face's thread, `end` ends it, 1 s after start.
pub const FAULT_ENV: &str = "PROBEBRIDGE_FAULT_PLC_FACE";

impl PlcFace {
    pub fn start(
        shared: Shared,
        listener: std::net::TcpListener,
        opts: FaceOptions,
    ) -> io::Result<Self> {
        let local_addr = listener.local_addr()?;
        let fault = std::env::var(FAULT_ENV).unwrap_or_default();
        let thread = FaceThread::spawn(
            "probebridge-plc-face",
            "PLC face",
            Flavour::CurrentThread,
            move |heartbeat, stop| serve(listener, shared, opts, (heartbeat, stop), fault),
        )?;
        Ok(Self { local_addr, thread })
    }

    pub fn health(&mut self) -> FaceHealth {
        self.thread.health()
    }
}

/// The face's runtime: its heartbeat, the fault injected if asked, then the accept
/// loop until `stop`.
async fn serve(
    listener: std::net::TcpListener,
    shared: Shared,
    opts: FaceOptions,
    (heartbeat, stop): (Heartbeat, tokio::sync::oneshot::Receiver<()>),
    fault: String,
) -> Result<(), String> {
    let listener =
        tokio::net::TcpListener::from_std(listener).map_err(|e| format!("cannot listen: {e}"))?;
    tokio::spawn(heartbeat.run());
    if !fault.is_empty() {
        tokio::time::sleep(Duration::from_secs(1)).await;
        tracing::warn!("{FAULT_ENV}={fault}: injecting the fault");
        match fault.as_str() {
            // Blocks the runtime: no accept, no answer, no tick.
            "stall" => loop {
                std::thread::park();
            },
            _ => return Err(format!("ended by {FAULT_ENV}={fault}")),
        }
    }
    accept_loop(listener, shared, opts, stop).await;
    Ok(())
}

/// The open connections, shared by the accept loop and the connection tasks.
struct Registry {
    conns: BTreeMap<u64, Entry>,
    log: FaceLog,
    /// The address of the last connection that owned the request block.
    last_owner: Option<IpAddr>,
}

struct Entry {
    peer: SocketAddr,
    heard: Instant,
    close: Arc<Notify>,
}

type SharedRegistry = Arc<Mutex<Registry>>;

fn registry(r: &SharedRegistry) -> std::sync::MutexGuard<'_, Registry> {
    r.lock().unwrap_or_else(|e| e.into_inner())
}

async fn accept_loop(
    listener: tokio::net::TcpListener,
    shared: Shared,
    opts: FaceOptions,
    mut stop: tokio::sync::oneshot::Receiver<()>,
) {
    let reg: SharedRegistry = Arc::new(Mutex::new(Registry {
        conns: BTreeMap::new(),
        log: FaceLog::new(Instant::now()),
        last_owner: None,
    }));
    let mut next_id = 1u64;
    let mut retry = ACCEPT_RETRY_FIRST;
    let mut summary = tokio::time::interval(SUMMARY_EVERY / 4);
    loop {
        let accepted = tokio::select! {
            _ = &mut stop => return,
            _ = summary.tick() => {
                let mut r = registry(&reg);
                let open = r.conns.len();
                r.log.log_summary(Instant::now(), open, opts.max_connections);
                continue;
            }
            a = listener.accept() => a,
        };
        match accepted {
            Ok((stream, peer)) => {
                retry = ACCEPT_RETRY_FIRST;
                if let Some((close, id)) = admit(&reg, &opts, peer, &mut next_id) {
                    super::tcp_keepalive::set(&stream, peer);
                    tokio::spawn(connection(
                        stream,
                        peer,
                        id,
                        shared.clone(),
                        reg.clone(),
                        close,
                    ));
                }
            }
            Err(e) => {
                let held = registry(&reg).log.count(Event::AcceptError, Instant::now());
                if let Some(held) = held {
                    tracing::warn!(
                        retry_in_ms = retry.as_millis() as u64,
                        "PLC face: accept failed: {e}; retrying ({held} more since the last \
                         such line; open connections keep being served)"
                    );
                }
                // Out of descriptors or memory: wait for some to be freed instead of
                // spinning on a listener that stays readable.
                tokio::select! {
                    _ = &mut stop => return,
                    _ = tokio::time::sleep(retry) => {}
                }
                retry = (retry * 2).min(ACCEPT_RETRY_MAX);
            }
        }
    }
}

/// The connection silent longest among those `which` picks, and for how long.
fn quietest(r: &Registry, now: Instant, which: impl Fn(&Entry) -> bool) -> Option<(u64, Duration)> {
    r.conns
        .iter()
        .filter(|(_, e)| which(e))
        .map(|(id, e)| (*id, now.saturating_duration_since(e.heard)))
        .max_by_key(|(_, silent)| *silent)
}

/// Takes or refuses a new connection; `Some` with its close signal and id if taken.
fn admit(
    reg: &SharedRegistry,
    opts: &FaceOptions,
    peer: SocketAddr,
    next_id: &mut u64,
) -> Option<(Arc<Notify>, u64)> {
    let now = Instant::now();
    let mut r = registry(reg);
    let ip = peer.ip();
    if !opts.allow.permits(ip) {
        if let Some(held) = r.log.count(Event::RefusedPeer, now) {
            tracing::warn!(
                %peer,
                "PLC face: refused {peer}: not in plc.allow ({held} more refused since the \
                 last such line)"
            );
        }
        return None;
    }
    let owners = r.last_owner == Some(ip);
    let same = r.conns.values().filter(|e| e.peer.ip() == ip).count();
    // (A cap per address as high as the face's is the face's: said as such.)
    let room = if same >= opts.max_per_peer && opts.max_per_peer < opts.max_connections {
        // Its own connection silent longest makes room, once silent long enough.
        quietest(&r, now, |e| e.peer.ip() == ip)
            .filter(|(_, silent)| *silent >= opts.silence)
            .ok_or(Event::RefusedPerPeer)
            .map(Some)
    } else if r.conns.len() >= opts.max_connections {
        let found = if owners {
            // The PLC's address keeps a place: another address's connection goes.
            quietest(&r, now, |e| e.peer.ip() != ip)
        } else {
            quietest(&r, now, |e| Some(e.peer.ip()) != r.last_owner)
                .filter(|(_, silent)| *silent >= opts.silence)
        };
        found.ok_or(Event::RefusedFull).map(Some)
    } else {
        Ok(None)
    };
    match room {
        Ok(Some((id, silent))) => {
            if let Some(e) = r.conns.remove(&id) {
                e.close.notify_one();
                r.log.count(Event::Evicted, now);
                tracing::debug!(
                    "PLC face: closing connection {id} of {}, silent for {} ms, for a new \
                     one from {peer}",
                    e.peer,
                    silent.as_millis()
                );
            }
        }
        Ok(None) => {}
        Err(refusal) => {
            if let Some(held) = r.log.count(refusal, now) {
                let (max, key) = match refusal {
                    Event::RefusedPerPeer => (opts.max_per_peer, "plc.max_connections_per_peer"),
                    _ => (opts.max_connections, "plc.max_connections"),
                };
                tracing::warn!(
                    %peer,
                    "PLC face: refused {peer}: {max} connections open ({key}), none silent for \
                     the owner timeout ({held} more refused since the last such line)"
                );
            }
            return None;
        }
    }
    let id = *next_id;
    *next_id += 1;
    let close = Arc::new(Notify::new());
    r.conns.insert(
        id,
        Entry {
            peer,
            heard: now,
            close: close.clone(),
        },
    );
    r.log.count(Event::Accepted, now);
    tracing::debug!("PLC face: connection {id} of {peer} accepted");
    Some((close, id))
}

/// Ends a connection's part in the registry and the ownership, however it ends.
struct Closing {
    id: u64,
    peer: SocketAddr,
    shared: Shared,
    reg: SharedRegistry,
    why: String,
}

impl Drop for Closing {
    fn drop(&mut self) {
        lock(&self.shared).plc_disconnected(self.id);
        let mut r = registry(&self.reg);
        r.conns.remove(&self.id);
        r.log.count(Event::Closed, Instant::now());
        tracing::debug!(
            "PLC face: connection {} of {} closed ({})",
            self.id,
            self.peer,
            self.why
        );
    }
}

async fn connection(
    mut stream: TcpStream,
    peer: SocketAddr,
    id: u64,
    shared: Shared,
    reg: SharedRegistry,
    close: Arc<Notify>,
) {
    let mut closing = Closing {
        id,
        peer,
        shared,
        reg,
        why: String::new(),
    };
    let mut frame = vec![0u8; MBAP_LEN + MAX_LENGTH_FIELD];
    closing.why = loop {
        let read = async {
            stream.read_exact(&mut frame[..MBAP_LEN]).await?;
            let length = usize::from(u16::from_be_bytes([frame[4], frame[5]]));
            let protocol = u16::from_be_bytes([frame[2], frame[3]]);
            if protocol != 0 || !(2..=MAX_LENGTH_FIELD).contains(&length) {
                return Err(io::Error::new(
                    io::ErrorKind::InvalidData,
                    format!("not a Modbus TCP frame (protocol {protocol}, length {length})"),
                ));
            }
            stream
                .read_exact(&mut frame[MBAP_LEN..MBAP_LEN + length - 1])
                .await?;
            Ok::<usize, io::Error>(length - 1)
        };
        let pdu_len = tokio::select! {
            _ = close.notified() => break "closed for a new connection".to_string(),
            r = read => match r {
                Ok(n) => n,
                Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => break "closed by the peer".into(),
                Err(e) => break e.to_string(),
            },
        };
        let (answer, owner) = {
            let mut gateway = lock(&closing.shared);
            gateway.plc_heard(id);
            let a = answer(
                &mut gateway,
                id,
                peer.ip(),
                &frame[MBAP_LEN..MBAP_LEN + pdu_len],
            );
            (a, gateway.plc_owner_ip())
        };
        {
            let mut r = registry(&closing.reg);
            if let Some(e) = r.conns.get_mut(&id) {
                e.heard = Instant::now();
            }
            if owner.is_some() {
                r.last_owner = owner;
            }
        }
        let mut out = Vec::with_capacity(MBAP_LEN + answer.len());
        out.extend_from_slice(&frame[..4]);
        out.extend_from_slice(&(answer.len() as u16 + 1).to_be_bytes());
        out.push(frame[6]);
        out.extend_from_slice(&answer);
        match tokio::time::timeout(WRITE_TIMEOUT, stream.write_all(&out)).await {
            Ok(Ok(())) => {}
            Ok(Err(e)) => break e.to_string(),
            Err(_) => break "the peer takes no answers".into(),
        }
    };
}

fn exception(e: MapException) -> u8 {
    match e {
        MapException::IllegalDataAddress => EXC_ILLEGAL_DATA_ADDRESS,
        MapException::IllegalDataValue => EXC_ILLEGAL_DATA_VALUE,
    }
}

fn write_refusal(e: WriteRefusal) -> u8 {
    match e {
        WriteRefusal::Busy => EXC_SERVER_DEVICE_BUSY,
        WriteRefusal::Map(m) => exception(m),
    }
}

fn word(pdu: &[u8], at: usize) -> u16 {
    u16::from_be_bytes([pdu[at], pdu[at + 1]])
}

/// The answer PDU to a request PDU (at least the function code).
fn answer(gateway: &mut Gateway, conn: u64, ip: IpAddr, pdu: &[u8]) -> Vec<u8> {
    let fc = pdu[0];
    let result: Result<Vec<u8>, u8> = match fc {
        0x03 if pdu.len() == 5 => gateway
            .plc_read(word(pdu, 1), word(pdu, 3))
            .map(|regs| {
                let mut a = vec![fc, (regs.len() * 2) as u8];
                regs.iter()
                    .for_each(|r| a.extend_from_slice(&r.to_be_bytes()));
                a
            })
            .map_err(exception),
        0x06 if pdu.len() == 5 => gateway
            .plc_write(conn, ip, word(pdu, 1), &[word(pdu, 3)])
            .map(|()| pdu.to_vec())
            .map_err(write_refusal),
        0x10 if pdu.len() >= 6 => {
            let (addr, count, bytes) = (word(pdu, 1), word(pdu, 3), usize::from(pdu[5]));
            if pdu.len() != 6 + bytes || bytes != 2 * usize::from(count) {
                Err(EXC_ILLEGAL_DATA_VALUE)
            } else {
                let values: Vec<u16> = (0..usize::from(count))
                    .map(|i| word(pdu, 6 + 2 * i))
                    .collect();
                gateway
                    .plc_write(conn, ip, addr, &values)
                    .map(|()| pdu[..5].to_vec())
                    .map_err(write_refusal)
            }
        }
        // The right function with the wrong length.
        0x03 | 0x06 | 0x10 => Err(EXC_ILLEGAL_DATA_VALUE),
        _ => Err(EXC_ILLEGAL_FUNCTION),
    };
    result.unwrap_or_else(|code| vec![fc | 0x80, code])
}
