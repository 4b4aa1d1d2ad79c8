//! SocketCAN transport (`can0`, `vcan0`) through the `socketcan` crate.

use super::{CanFrame, CanTransport, TransportError, TransportErrorKind};
use ::socketcan::{CanSocket, EmbeddedFrame, Socket};
use core::time::Duration;

pub struct SocketCanTransport {
    socket: CanSocket,
    iface: String,
    /// Last read timeout set on the socket, to avoid a syscall per receive.
    timeout: Option<Duration>,
}

impl SocketCanTransport {
    /// Opens `iface` (for example `can0` or `vcan0`).
    pub fn open(iface: &str) -> Result<Self, TransportError> {
        let socket = CanSocket::open(iface).map_err(|e| {
            TransportError::new(
                TransportErrorKind::Open,
                format!("cannot open CAN interface {iface:?}: {e}"),
            )
        })?;
        Ok(Self {
            socket,
            iface: iface.to_string(),
            timeout: None,
        })
    }

    fn io_error(&self, what: &str, e: std::io::Error) -> TransportError {
        let kind = match e.raw_os_error() {
            Some(libc::ENOBUFS) => TransportErrorKind::Overrun,
            Some(libc::ENETDOWN) => TransportErrorKind::BusOff,
            _ => TransportErrorKind::Io,
        };
        TransportError::new(kind, format!("{what} on {}: {e}", self.iface))
    }
}

impl CanTransport for SocketCanTransport {
    fn transmit(&mut self, frame: &CanFrame) -> Result<(), TransportError> {
        let f = if frame.is_rtr() {
            ::socketcan::CanFrame::new_remote(frame.id(), frame.dlc())
        } else {
            ::socketcan::CanFrame::new(frame.id(), frame.data())
        }
        .ok_or_else(|| TransportError::new(TransportErrorKind::Io, "frame not representable"))?;
        self.socket
            .write_frame(&f)
            .map_err(|e| self.io_error("write", e))
    }

    fn receive(&mut self, timeout: Duration) -> Result<Option<CanFrame>, TransportError> {
        // A zero read timeout means "block forever" to the kernel; use the smallest.
        let t = timeout.max(Duration::from_micros(1));
        if self.timeout != Some(t) {
            self.socket
                .set_read_timeout(t)
                .map_err(|e| self.io_error("set timeout", e))?;
            self.timeout = Some(t);
        }
        loop {
            match self.socket.read_frame() {
                Ok(::socketcan::CanFrame::Data(d)) => {
                    if let Some(f) = CanFrame::new(raw_id(d.id()), d.data()) {
                        return Ok(Some(f));
                    }
                    // Extended-ID frames are not CANopen; skip them.
                }
                Ok(::socketcan::CanFrame::Remote(r)) => {
                    if let Some(f) = CanFrame::remote(raw_id(r.id()), r.dlc() as u8) {
                        return Ok(Some(f));
                    }
                }
                Ok(::socketcan::CanFrame::Error(e)) => {
                    return Err(TransportError::new(
                        TransportErrorKind::BusOff,
                        format!("error frame on {}: {e:?}", self.iface),
                    ))
                }
                Err(e)
                    if e.kind() == std::io::ErrorKind::WouldBlock
                        || e.kind() == std::io::ErrorKind::TimedOut =>
                {
                    return Ok(None)
                }
                Err(e) => return Err(self.io_error("read", e)),
            }
        }
    }
}

fn raw_id(id: embedded_can::Id) -> u16 {
    match id {
        embedded_can::Id::Standard(s) => s.as_raw(),
        // Out of CanFrame's range: rejected by CanFrame::new.
        embedded_can::Id::Extended(_) => 0xFFFF,
    }
}
