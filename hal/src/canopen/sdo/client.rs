//! SDO client: the master side of one SDO channel (requests to 0x600 + node, answers
//! from 0x580 + node). One transfer at a time; the caller owns the timeout and calls
//! [`SdoClient::abort`] with [`SdoAbortCode::TIMEOUT`] when it expires.

use heapless::Vec;

use super::*;
use crate::canopen::cob_id;
use crate::canopen::pdo::SdoWrite;

/// Misuse of the client; device answers (aborts) come as [`SdoOutcome::Aborted`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum SdoError {
    #[error("an SDO transfer to node {node} is still running")]
    Busy { node: u8 },
    #[error("SDO download of {len} bytes exceeds the {max}-byte transfer buffer")]
    TooLong { len: usize, max: usize },
}

/// How a transfer ended.
// The upload buffer lives inline: boxing it would allocate on every transfer.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SdoOutcome {
    Downloaded,
    Uploaded(Vec<u8, MAX_TRANSFER>),
    /// The server aborted, or the client did (see [`SdoClientEvent::Aborting`]).
    Aborted(SdoAbortCode),
}

/// What the client makes of a received frame.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SdoClientEvent {
    /// Not an answer to a running transfer.
    Ignored,
    /// Send this frame next (the next segment request).
    Transmit(CanFrame),
    /// The transfer is over.
    Done(SdoOutcome),
    /// The server broke the protocol (wrong toggle, unexpected command, wrong length):
    /// send `frame` (the client's abort); the transfer is over with `code`.
    Aborting { frame: CanFrame, code: SdoAbortCode },
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    Idle,
    /// Waiting for the initiate download response.
    DownloadInitiate {
        expedited: bool,
    },
    /// Sent the segment with `toggle` ending at `end`; waiting for its response.
    DownloadSegment {
        toggle: bool,
        end: usize,
    },
    UploadInitiate,
    /// Sent the upload segment request with `toggle`.
    UploadSegment {
        toggle: bool,
        size: Option<usize>,
    },
}

#[derive(Clone, Debug)]
pub struct SdoClient {
    node: u8,
    phase: Phase,
    index: u16,
    sub: u8,
    /// Download: the data to send; upload: the data received so far.
    buf: Vec<u8, MAX_TRANSFER>,
}

impl SdoClient {
    /// Client for the default SDO channel of `node` (1..=127).
    pub fn new(node: u8) -> Self {
        Self {
            node,
            phase: Phase::Idle,
            index: 0,
            sub: 0,
            buf: Vec::new(),
        }
    }

    pub fn node(&self) -> u8 {
        self.node
    }

    pub fn is_busy(&self) -> bool {
        self.phase != Phase::Idle
    }

    /// Index and sub-index of the running transfer.
    pub fn current(&self) -> Option<(u16, u8)> {
        self.is_busy().then_some((self.index, self.sub))
    }

    fn request_cob(&self) -> u16 {
        cob_id::sdo_request_cob(self.node)
    }

    fn start(&mut self, index: u16, sub: u8) -> Result<(), SdoError> {
        if self.is_busy() {
            return Err(SdoError::Busy { node: self.node });
        }
        self.index = index;
        self.sub = sub;
        self.buf.clear();
        Ok(())
    }

    /// Starts writing `data` to `index:sub`: expedited for 1..=4 bytes, segmented
    /// otherwise. Returns the initiate request to send.
    pub fn download(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<CanFrame, SdoError> {
        if data.len() > MAX_TRANSFER {
            return Err(SdoError::TooLong {
                len: data.len(),
                max: MAX_TRANSFER,
            });
        }
        self.start(index, sub)?;
        let cob = self.request_cob();
        if (1..=4).contains(&data.len()) {
            let mut p = [0u8; 4];
            p[..data.len()].copy_from_slice(data);
            let n = (4 - data.len()) as u8;
            let byte0 = CCS_INITIATE_DOWNLOAD << 5 | n << 2 | BIT_E | BIT_S;
            self.phase = Phase::DownloadInitiate { expedited: true };
            return Ok(initiate(cob, byte0, index, sub, p));
        }
        // Fits: length checked above against the buffer's capacity.
        let _ = self.buf.extend_from_slice(data);
        let byte0 = CCS_INITIATE_DOWNLOAD << 5 | BIT_S;
        self.phase = Phase::DownloadInitiate { expedited: false };
        Ok(initiate(
            cob,
            byte0,
            index,
            sub,
            (data.len() as u32).to_le_bytes(),
        ))
    }

    pub fn download_u8(&mut self, index: u16, sub: u8, v: u8) -> Result<CanFrame, SdoError> {
        self.download(index, sub, &[v])
    }

    pub fn download_u16(&mut self, index: u16, sub: u8, v: u16) -> Result<CanFrame, SdoError> {
        self.download(index, sub, &v.to_le_bytes())
    }

    pub fn download_u32(&mut self, index: u16, sub: u8, v: u32) -> Result<CanFrame, SdoError> {
        self.download(index, sub, &v.to_le_bytes())
    }

    pub fn download_i32(&mut self, index: u16, sub: u8, v: i32) -> Result<CanFrame, SdoError> {
        self.download(index, sub, &v.to_le_bytes())
    }

    /// One step of a PDO configuration sequence.
    pub fn download_write(&mut self, w: &SdoWrite) -> Result<CanFrame, SdoError> {
        self.download(w.index, w.sub, &w.payload())
    }

    /// Starts reading `index:sub`; returns the initiate request to send.
    pub fn upload(&mut self, index: u16, sub: u8) -> Result<CanFrame, SdoError> {
        self.start(index, sub)?;
        self.phase = Phase::UploadInitiate;
        Ok(initiate(
            self.request_cob(),
            CCS_INITIATE_UPLOAD << 5,
            index,
            sub,
            [0; 4],
        ))
    }

    /// Ends the running transfer with `code` (typically the caller's timeout,
    /// [`SdoAbortCode::TIMEOUT`]); the abort frame to send, `None` when idle.
    pub fn abort(&mut self, code: SdoAbortCode) -> Option<CanFrame> {
        if !self.is_busy() {
            return None;
        }
        self.phase = Phase::Idle;
        Some(abort_frame(self.request_cob(), self.index, self.sub, code))
    }

    fn fail(&mut self, code: SdoAbortCode) -> SdoClientEvent {
        match self.abort(code) {
            Some(frame) => SdoClientEvent::Aborting { frame, code },
            None => SdoClientEvent::Ignored,
        }
    }

    fn done(&mut self, outcome: SdoOutcome) -> SdoClientEvent {
        self.phase = Phase::Idle;
        SdoClientEvent::Done(outcome)
    }

    /// Feeds a received frame; frames of other COB-IDs are [`SdoClientEvent::Ignored`].
    pub fn on_frame(&mut self, f: &CanFrame) -> SdoClientEvent {
        if f.cob_id() != cob_id::sdo_response_cob(self.node) || !self.is_busy() {
            return SdoClientEvent::Ignored;
        }
        let d = f.data();
        if d.len() != 8 {
            // CiA 301 fixes SDO frames at 8 bytes.
            return self.fail(SdoAbortCode::GENERAL_ERROR);
        }
        let scs = cs(d[0]);
        if scs == CS_ABORT {
            // Accepted whatever multiplexer it names: some servers send 0 in
            // the segment phase.
            let code = u32::from_le_bytes([d[4], d[5], d[6], d[7]]);
            return self.done(SdoOutcome::Aborted(SdoAbortCode(code)));
        }
        let initiating = matches!(
            self.phase,
            Phase::DownloadInitiate { .. } | Phase::UploadInitiate
        );
        if initiating
            && matches!(scs, SCS_INITIATE_DOWNLOAD | SCS_INITIATE_UPLOAD)
            && mux_of(d) != (self.index, self.sub)
        {
            // The answer to an earlier transfer (duplicated on the bus, or late after
            // its timeout) names its own object: not ours, and ours may still come.
            return SdoClientEvent::Ignored;
        }
        match self.phase {
            Phase::Idle => SdoClientEvent::Ignored,
            Phase::DownloadInitiate { expedited } => {
                if scs != SCS_INITIATE_DOWNLOAD {
                    return self.fail(SdoAbortCode::COMMAND_SPECIFIER_INVALID);
                }
                if mux_of(d) != (self.index, self.sub) {
                    return self.fail(SdoAbortCode::GENERAL_ERROR);
                }
                if expedited {
                    return self.done(SdoOutcome::Downloaded);
                }
                self.next_download_segment(false, 0)
            }
            Phase::DownloadSegment { toggle, end } => {
                if scs != SCS_DOWNLOAD_SEGMENT {
                    return self.fail(SdoAbortCode::COMMAND_SPECIFIER_INVALID);
                }
                if (d[0] & BIT_TOGGLE != 0) != toggle {
                    return self.fail(SdoAbortCode::TOGGLE_BIT_NOT_ALTERNATED);
                }
                if end >= self.buf.len() {
                    return self.done(SdoOutcome::Downloaded);
                }
                self.next_download_segment(!toggle, end)
            }
            Phase::UploadInitiate => {
                if scs != SCS_INITIATE_UPLOAD {
                    return self.fail(SdoAbortCode::COMMAND_SPECIFIER_INVALID);
                }
                if mux_of(d) != (self.index, self.sub) {
                    return self.fail(SdoAbortCode::GENERAL_ERROR);
                }
                let sized = d[0] & BIT_S != 0;
                if d[0] & BIT_E != 0 {
                    let len = if sized {
                        4 - ((d[0] >> 2) & 0x03) as usize
                    } else {
                        4
                    };
                    let mut v = Vec::new();
                    let _ = v.extend_from_slice(&d[4..4 + len]);
                    return self.done(SdoOutcome::Uploaded(v));
                }
                let size = if sized {
                    let s = u32::from_le_bytes([d[4], d[5], d[6], d[7]]) as usize;
                    if s > MAX_TRANSFER {
                        return self.fail(SdoAbortCode::OUT_OF_MEMORY);
                    }
                    Some(s)
                } else {
                    None
                };
                self.phase = Phase::UploadSegment {
                    toggle: false,
                    size,
                };
                SdoClientEvent::Transmit(self.upload_segment_request(false))
            }
            Phase::UploadSegment { toggle, size } => {
                if scs != SCS_UPLOAD_SEGMENT {
                    return self.fail(SdoAbortCode::COMMAND_SPECIFIER_INVALID);
                }
                if (d[0] & BIT_TOGGLE != 0) != toggle {
                    return self.fail(SdoAbortCode::TOGGLE_BIT_NOT_ALTERNATED);
                }
                let unused = ((d[0] >> 1) & 0x07) as usize;
                let data = &d[1..1 + SEGMENT_DATA - unused];
                let limit = size.unwrap_or(MAX_TRANSFER);
                if self.buf.len() + data.len() > limit {
                    let code = if size.is_some() {
                        SdoAbortCode::LENGTH_TOO_HIGH
                    } else {
                        SdoAbortCode::OUT_OF_MEMORY
                    };
                    return self.fail(code);
                }
                let _ = self.buf.extend_from_slice(data);
                if d[0] & BIT_C == 0 {
                    self.phase = Phase::UploadSegment {
                        toggle: !toggle,
                        size,
                    };
                    return SdoClientEvent::Transmit(self.upload_segment_request(!toggle));
                }
                if size.is_some_and(|s| s != self.buf.len()) {
                    return self.fail(SdoAbortCode::LENGTH_TOO_LOW);
                }
                let v = core::mem::take(&mut self.buf);
                self.done(SdoOutcome::Uploaded(v))
            }
        }
    }

    fn next_download_segment(&mut self, toggle: bool, start: usize) -> SdoClientEvent {
        let end = (start + SEGMENT_DATA).min(self.buf.len());
        let chunk = &self.buf[start..end];
        let unused = (SEGMENT_DATA - chunk.len()) as u8;
        let last = end == self.buf.len();
        let byte0 = CCS_DOWNLOAD_SEGMENT << 5
            | toggle_bit(toggle)
            | unused << 1
            | if last { BIT_C } else { 0 };
        let f = segment(self.request_cob(), byte0, chunk);
        self.phase = Phase::DownloadSegment { toggle, end };
        SdoClientEvent::Transmit(f)
    }

    fn upload_segment_request(&self, toggle: bool) -> CanFrame {
        segment(
            self.request_cob(),
            CCS_UPLOAD_SEGMENT << 5 | toggle_bit(toggle),
            &[],
        )
    }
}
