//! SDO server: the device side of the default SDO channel (requests on 0x600 + node,
//! answers on 0x580 + node), over any [`ObjectDictionary`].

use super::*;
use crate::canopen::cob_id;

/// The objects a server exposes. Errors are the abort codes sent to the client.
pub trait ObjectDictionary {
    /// Copies the value of `index:sub` into `buf` (at most [`MAX_TRANSFER`] bytes);
    /// returns its length.
    fn read(&mut self, index: u16, sub: u8, buf: &mut [u8]) -> Result<usize, SdoAbortCode>;

    /// Stores `data` as the value of `index:sub`.
    fn write(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), SdoAbortCode>;
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    Idle,
    /// Expecting the download segment with `toggle`.
    Downloading {
        toggle: bool,
        size: Option<usize>,
    },
    /// Expecting the upload segment request with `toggle`; `pos` bytes sent.
    Uploading {
        toggle: bool,
        pos: usize,
    },
}

#[derive(Clone, Debug)]
pub struct SdoServer {
    node: u8,
    phase: Phase,
    index: u16,
    sub: u8,
    buf: [u8; MAX_TRANSFER],
    len: usize,
}

impl SdoServer {
    pub fn new(node: u8) -> Self {
        Self {
            node,
            phase: Phase::Idle,
            index: 0,
            sub: 0,
            buf: [0; MAX_TRANSFER],
            len: 0,
        }
    }

    pub fn node(&self) -> u8 {
        self.node
    }

    pub fn is_busy(&self) -> bool {
        self.phase != Phase::Idle
    }

    /// Drops a running segmented transfer (the server's own timeout, an NMT reset).
    pub fn reset(&mut self) {
        self.phase = Phase::Idle;
    }

    fn response_cob(&self) -> u16 {
        cob_id::sdo_response_cob(self.node)
    }

    fn abort(&mut self, index: u16, sub: u8, code: SdoAbortCode) -> Option<CanFrame> {
        self.phase = Phase::Idle;
        Some(abort_frame(self.response_cob(), index, sub, code))
    }

    /// Handles a request; the response to send. Frames for other COB-IDs, frames
    /// that are not 8 bytes (CiA 301 fixes the SDO length) and aborts from the client
    /// get none.
    pub fn on_frame(&mut self, f: &CanFrame, od: &mut impl ObjectDictionary) -> Option<CanFrame> {
        if f.cob_id() != cob_id::sdo_request_cob(self.node) {
            return None;
        }
        let d = f.data();
        if d.len() != 8 {
            return None;
        }
        let ccs = cs(d[0]);
        match ccs {
            CS_ABORT => {
                self.phase = Phase::Idle;
                None
            }
            // A new initiate always starts over: the client gave up on the old one.
            CCS_INITIATE_DOWNLOAD => self.initiate_download(d, od),
            CCS_INITIATE_UPLOAD => self.initiate_upload(d, od),
            CCS_DOWNLOAD_SEGMENT => self.download_segment(d, od),
            CCS_UPLOAD_SEGMENT => self.upload_segment(d),
            // Block transfer (5, 6) and anything else.
            _ => {
                let (index, sub) = mux_of(d);
                self.abort(index, sub, SdoAbortCode::COMMAND_SPECIFIER_INVALID)
            }
        }
    }

    fn initiate_download(&mut self, d: &[u8], od: &mut impl ObjectDictionary) -> Option<CanFrame> {
        let (index, sub) = mux_of(d);
        self.index = index;
        self.sub = sub;
        self.phase = Phase::Idle;
        let sized = d[0] & BIT_S != 0;
        if d[0] & BIT_E != 0 {
            let len = if sized {
                4 - ((d[0] >> 2) & 0x03) as usize
            } else {
                4
            };
            return match od.write(index, sub, &d[4..4 + len]) {
                Ok(()) => Some(self.download_initiate_response()),
                Err(code) => self.abort(index, sub, code),
            };
        }
        let size = if sized {
            let s = u32::from_le_bytes([d[4], d[5], d[6], d[7]]) as usize;
            if s > MAX_TRANSFER {
                return self.abort(index, sub, SdoAbortCode::OUT_OF_MEMORY);
            }
            Some(s)
        } else {
            None
        };
        self.len = 0;
        self.phase = Phase::Downloading {
            toggle: false,
            size,
        };
        Some(self.download_initiate_response())
    }

    fn download_initiate_response(&self) -> CanFrame {
        initiate(
            self.response_cob(),
            SCS_INITIATE_DOWNLOAD << 5,
            self.index,
            self.sub,
            [0; 4],
        )
    }

    fn download_segment(&mut self, d: &[u8], od: &mut impl ObjectDictionary) -> Option<CanFrame> {
        let (index, sub) = (self.index, self.sub);
        let Phase::Downloading { toggle, size } = self.phase else {
            return self.abort(index, sub, SdoAbortCode::COMMAND_SPECIFIER_INVALID);
        };
        if (d[0] & BIT_TOGGLE != 0) != toggle {
            return self.abort(index, sub, SdoAbortCode::TOGGLE_BIT_NOT_ALTERNATED);
        }
        let unused = ((d[0] >> 1) & 0x07) as usize;
        let data = &d[1..1 + SEGMENT_DATA - unused];
        let limit = size.unwrap_or(MAX_TRANSFER);
        if self.len + data.len() > limit {
            let code = if size.is_some() {
                SdoAbortCode::LENGTH_TOO_HIGH
            } else {
                SdoAbortCode::OUT_OF_MEMORY
            };
            return self.abort(index, sub, code);
        }
        self.buf[self.len..self.len + data.len()].copy_from_slice(data);
        self.len += data.len();
        let response = segment(
            self.response_cob(),
            SCS_DOWNLOAD_SEGMENT << 5 | toggle_bit(toggle),
            &[],
        );
        if d[0] & BIT_C == 0 {
            self.phase = Phase::Downloading {
                toggle: !toggle,
                size,
            };
            return Some(response);
        }
        self.phase = Phase::Idle;
        if size.is_some_and(|s| s != self.len) {
            return self.abort(index, sub, SdoAbortCode::LENGTH_MISMATCH);
        }
        // The response to the last segment confirms the write, so it waits for it.
        match od.write(index, sub, &self.buf[..self.len]) {
            Ok(()) => Some(response),
            Err(code) => self.abort(index, sub, code),
        }
    }

    fn initiate_upload(&mut self, d: &[u8], od: &mut impl ObjectDictionary) -> Option<CanFrame> {
        let (index, sub) = mux_of(d);
        self.index = index;
        self.sub = sub;
        self.phase = Phase::Idle;
        let len = match od.read(index, sub, &mut self.buf) {
            Ok(n) if n <= MAX_TRANSFER => n,
            Ok(_) => return self.abort(index, sub, SdoAbortCode::GENERAL_ERROR),
            Err(code) => return self.abort(index, sub, code),
        };
        let cob = self.response_cob();
        if (1..=4).contains(&len) {
            let mut p = [0u8; 4];
            p[..len].copy_from_slice(&self.buf[..len]);
            let n = (4 - len) as u8;
            let byte0 = SCS_INITIATE_UPLOAD << 5 | n << 2 | BIT_E | BIT_S;
            return Some(initiate(cob, byte0, index, sub, p));
        }
        // Empty values go segmented too: expedited cannot say "0 bytes".
        self.len = len;
        self.phase = Phase::Uploading {
            toggle: false,
            pos: 0,
        };
        Some(initiate(
            cob,
            SCS_INITIATE_UPLOAD << 5 | BIT_S,
            index,
            sub,
            (len as u32).to_le_bytes(),
        ))
    }

    fn upload_segment(&mut self, d: &[u8]) -> Option<CanFrame> {
        let (index, sub) = (self.index, self.sub);
        let Phase::Uploading { toggle, pos } = self.phase else {
            return self.abort(index, sub, SdoAbortCode::COMMAND_SPECIFIER_INVALID);
        };
        if (d[0] & BIT_TOGGLE != 0) != toggle {
            return self.abort(index, sub, SdoAbortCode::TOGGLE_BIT_NOT_ALTERNATED);
        }
        let end = (pos + SEGMENT_DATA).min(self.len);
        let chunk = &self.buf[pos..end];
        let unused = (SEGMENT_DATA - chunk.len()) as u8;
        let last = end == self.len;
        let byte0 = SCS_UPLOAD_SEGMENT << 5
            | toggle_bit(toggle)
            | unused << 1
            | if last { BIT_C } else { 0 };
        let f = segment(self.response_cob(), byte0, chunk);
        self.phase = if last {
            Phase::Idle
        } else {
            Phase::Uploading {
                toggle: !toggle,
                pos: end,
            }
        };
        Some(f)
    }
}
