//! TCP keepalive and a user timeout for the faces' connections (the PLC's Modbus
//! connections, the OPC UA face's front): a peer that lost power is found dead in
//! about 10 s instead of holding its socket ESTABLISHED for hours.

use std::io;
use std::net::SocketAddr;
use std::os::fd::AsRawFd;
use tokio::net::TcpStream;

/// TCP keepalive: probes after 5 s of silence, every 1 s, 5 unanswered end it.
const KEEPALIVE_IDLE_S: libc::c_int = 5;
const KEEPALIVE_INTERVAL_S: libc::c_int = 1;
const KEEPALIVE_PROBES: libc::c_int = 5;
const USER_TIMEOUT_MS: libc::c_uint = 10_000;

/// Sets both on an accepted connection; a failure is logged at debug level (the
/// connection works without, a dead peer is then found later).
pub fn set(stream: &TcpStream, peer: SocketAddr) {
    let fd = stream.as_raw_fd();
    let set = |level, name, value: libc::c_int| {
        // SAFETY: setsockopt on a socket we own, with a c_int of the right size.
        let rc = unsafe {
            libc::setsockopt(
                fd,
                level,
                name,
                (&value as *const libc::c_int).cast(),
                std::mem::size_of::<libc::c_int>() as libc::socklen_t,
            )
        };
        if rc != 0 {
            tracing::debug!(%peer, "setsockopt {name}: {}", io::Error::last_os_error());
        }
    };
    set(libc::SOL_SOCKET, libc::SO_KEEPALIVE, 1);
    set(libc::IPPROTO_TCP, libc::TCP_KEEPIDLE, KEEPALIVE_IDLE_S);
    set(libc::IPPROTO_TCP, libc::TCP_KEEPINTVL, KEEPALIVE_INTERVAL_S);
    set(libc::IPPROTO_TCP, libc::TCP_KEEPCNT, KEEPALIVE_PROBES);
    set(
        libc::IPPROTO_TCP,
        libc::TCP_USER_TIMEOUT,
        USER_TIMEOUT_MS as libc::c_int,
    );
}
