//! Record and replay of CAN traffic in candump's log format.
//!
//! [`Recorder`] wraps a transport and logs every frame sent and received, in the order
//! the node saw them, without allocating (a stack buffer per line and a buffered
//! writer), so it can stay on in the field. [`Replay`] plays such a log back to a
//! master: every frame the master sends must equal the next master frame of the log,
//! byte for byte, and the devices' recorded answers are handed back in order. Under
//! lockstep pacing the master is deterministic, so a replay is an exact regression
//! test of its traffic.

use super::candump::{parse_log, write_line, CandumpError};
use super::{CanFrame, CanTransport, TransportError, TransportErrorKind};
use crate::canopen::cob_id::{classify, CobKind};
use crate::clock::monotonic_ns;
use core::time::Duration;
use std::collections::VecDeque;
use std::io::Write;
use std::sync::{Arc, OnceLock};

/// Whether a CANopen master (not a device) sends frames with this identifier: NMT,
/// SYNC, RPDOs and SDO requests, and its heartbeat when it has the node ID
/// `master_node` (a heartbeat's identifier alone does not say who sent it).
pub fn sent_by_master(cob_id: u16, master_node: Option<u8>) -> bool {
    match classify(cob_id) {
        CobKind::Nmt | CobKind::Sync | CobKind::Rpdo { .. } | CobKind::SdoRequest { .. } => true,
        CobKind::Heartbeat { node } => Some(node) == master_node,
        _ => false,
    }
}

/// Whether a recording is whole: the first write error, shared with whoever opened
/// the log (the recorder itself runs in the real-time thread).
#[derive(Clone, Debug, Default)]
pub struct RecordHealth(Arc<OnceLock<String>>);

impl RecordHealth {
    /// Why the log is incomplete, once a write failed.
    pub fn error(&self) -> Option<&str> {
        self.0.get().map(String::as_str)
    }

    fn fail(&self, e: &std::io::Error) {
        let _ = self.0.set(e.to_string());
    }
}

/// Logs all traffic of the wrapped transport (the buffered writer flushes when the
/// recorder is dropped). A failed write stops the logging, never the machine, and is
/// kept in [`Recorder::health`] for the command to report.
pub struct Recorder<T, W: Write + Send> {
    inner: T,
    out: std::io::BufWriter<W>,
    iface: heapless::String<16>,
    failed: bool,
    health: RecordHealth,
}

impl<T: CanTransport, W: Write + Send> Recorder<T, W> {
    /// `iface` names the interface in the log (cut to 16 characters).
    pub fn new(inner: T, out: W, iface: &str) -> Self {
        let mut name = heapless::String::new();
        for c in iface.chars().take(16) {
            let _ = name.push(c);
        }
        Self {
            inner,
            out: std::io::BufWriter::with_capacity(64 * 1024, out),
            iface: name,
            failed: false,
            health: RecordHealth::default(),
        }
    }

    /// Shared view of whether the log is whole (also after the recorder is gone).
    pub fn health(&self) -> RecordHealth {
        self.health.clone()
    }

    fn log(&mut self, frame: &CanFrame) {
        let mut line: heapless::String<64> = heapless::String::new();
        if write_line(&mut line, monotonic_ns(), &self.iface, frame).is_ok() && !self.failed {
            // A full disk must not stop the machine: stop logging, keep going, and
            // say so at the end.
            if let Err(e) = self
                .out
                .write_all(line.as_bytes())
                .and_then(|()| self.out.write_all(b"\n"))
            {
                self.failed = true;
                self.health.fail(&e);
            }
        }
    }
}

impl<T, W: Write + Send> Drop for Recorder<T, W> {
    fn drop(&mut self) {
        if !self.failed {
            if let Err(e) = self.out.flush() {
                self.health.fail(&e);
            }
        }
    }
}

impl<T: CanTransport, W: Write + Send> CanTransport for Recorder<T, W> {
    fn transmit(&mut self, frame: &CanFrame) -> Result<(), TransportError> {
        self.inner.transmit(frame)?;
        self.log(frame);
        Ok(())
    }

    fn receive(&mut self, timeout: Duration) -> Result<Option<CanFrame>, TransportError> {
        let f = self.inner.receive(timeout)?;
        if let Some(f) = &f {
            self.log(f);
        }
        Ok(f)
    }

    fn transmit_all(&mut self, frames: &[CanFrame]) -> Result<(), TransportError> {
        self.inner.transmit_all(frames)?;
        for f in frames {
            self.log(f);
        }
        Ok(())
    }

    fn arrival_ns(&self) -> Option<u64> {
        self.inner.arrival_ns()
    }

    fn virtual_now_ns(&self) -> Option<u64> {
        self.inner.virtual_now_ns()
    }

    fn advance_virtual_clock(&mut self, now_ns: u64) {
        self.inner.advance_virtual_clock(now_ns)
    }
}

/// Plays a recorded log back to a master.
pub struct Replay {
    frames: VecDeque<(usize, CanFrame)>,
    ready: VecDeque<CanFrame>,
    master_node: Option<u8>,
}

impl Replay {
    /// The log of a master that sends no heartbeat.
    pub fn from_log(text: &str) -> Result<Self, CandumpError> {
        Self::from_log_of(text, None)
    }

    /// The log of a master with node ID `master_node` (its heartbeat is its own frame,
    /// not an answer), or `None` when it sends no heartbeat.
    pub fn from_log_of(text: &str, master_node: Option<u8>) -> Result<Self, CandumpError> {
        let frames = parse_log(text)?
            .into_iter()
            .enumerate()
            .map(|(i, (_, _, f))| (i + 1, f))
            .collect();
        let mut r = Self {
            frames,
            ready: VecDeque::new(),
            master_node,
        };
        r.release_answers();
        Ok(r)
    }

    /// Device frames up to the next master frame become receivable.
    fn release_answers(&mut self) {
        while let Some((_, f)) = self.frames.front() {
            if sent_by_master(f.cob_id(), self.master_node) {
                break;
            }
            self.ready.push_back(*f);
            self.frames.pop_front();
        }
    }

    /// Log frames not yet replayed (0 when the master did everything it did then).
    pub fn remaining(&self) -> usize {
        self.frames.len() + self.ready.len()
    }
}

impl CanTransport for Replay {
    fn transmit(&mut self, frame: &CanFrame) -> Result<(), TransportError> {
        match self.frames.pop_front() {
            Some((_, want)) if want == *frame => {
                self.release_answers();
                Ok(())
            }
            Some((line, want)) => Err(TransportError::new(
                TransportErrorKind::Io,
                format!("replay: line {line} of the log has {want:?}, the master sent {frame:?}"),
            )),
            None => Err(TransportError::new(
                TransportErrorKind::Closed,
                format!("replay: the log has ended, the master sent {frame:?}"),
            )),
        }
    }

    fn receive(&mut self, _timeout: Duration) -> Result<Option<CanFrame>, TransportError> {
        Ok(self.ready.pop_front())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::inproc::InprocBus;

    #[test]
    fn recorded_traffic_replays_and_a_changed_frame_is_caught() {
        let bus = InprocBus::new();
        let mut device = bus.endpoint();
        let mut log = Vec::new();
        {
            let mut master = Recorder::new(bus.endpoint(), &mut log, "vcan0");
            master
                .transmit(&CanFrame::new(0x605, &[0x40, 0x41, 0x60, 0, 0, 0, 0, 0]).unwrap())
                .unwrap();
            device
                .transmit(&CanFrame::new(0x585, &[0x4B, 0x41, 0x60, 0, 0x37, 0x02, 0, 0]).unwrap())
                .unwrap();
            assert!(master.receive(Duration::from_secs(1)).unwrap().is_some());
            master.transmit(&crate::canopen::sync::encode()).unwrap();
        }
        let text = String::from_utf8(log).unwrap();
        assert_eq!(text.lines().count(), 3, "{text}");
        assert!(
            text.lines()
                .nth(1)
                .unwrap()
                .ends_with(" vcan0 585#4B41600037020000"),
            "{text}"
        );

        let mut r = Replay::from_log(&text).unwrap();
        r.transmit(&CanFrame::new(0x605, &[0x40, 0x41, 0x60, 0, 0, 0, 0, 0]).unwrap())
            .unwrap();
        assert_eq!(r.receive(Duration::ZERO).unwrap().unwrap().cob_id(), 0x585);
        let e = r
            .transmit(&CanFrame::new(0x080, &[1]).unwrap())
            .unwrap_err();
        assert!(
            e.message.contains("line 3") && e.message.contains("080#01"),
            "{}",
            e.message
        );
    }

    /// A writer that takes `room` bytes and then reports a full disk.
    struct Full {
        room: usize,
    }

    impl Write for Full {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            if self.room == 0 {
                return Err(std::io::Error::from_raw_os_error(libc::ENOSPC));
            }
            let n = buf.len().min(self.room);
            self.room -= n;
            Ok(n)
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn a_failed_write_is_kept_for_the_command_and_the_traffic_goes_on() {
        let bus = InprocBus::new();
        let health;
        {
            let mut master = Recorder::new(bus.endpoint(), Full { room: 100 }, "vcan0");
            health = master.health();
            for _ in 0..10 {
                master.transmit(&crate::canopen::sync::encode()).unwrap();
            }
            assert!(health.error().is_none(), "buffered so far");
        }
        let e = health.error().expect("the flush at the end failed");
        assert!(e.contains("No space left"), "{e}");
    }
}
