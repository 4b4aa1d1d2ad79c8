//! Service data objects (CiA 301): expedited and segmented upload and download, client
//! and server. Block transfer is not implemented; a server answers it with an abort.
//!
//! Every SDO frame has 8 data bytes; byte 0 is the command byte:
//!
//! | frame | byte 0 |
//! |---|---|
//! | initiate download request | `001 - nn e s` (ccs 1) |
//! | initiate download response | `011 - ----` (scs 3) |
//! | download segment request | `000 t nnn c` (ccs 0) |
//! | download segment response | `001 t ----` (scs 1) |
//! | initiate upload request | `010 - ----` (ccs 2) |
//! | initiate upload response | `010 - nn e s` (scs 2) |
//! | upload segment request | `011 t ----` (ccs 3) |
//! | upload segment response | `000 t nnn c` (scs 0) |
//! | abort | `100 - ----` (cs 4), bytes 4..8 the abort code |
//!
//! Initiate frames carry index (LE) and sub-index in bytes 1..4; n counts the bytes
//! of the data field that do NOT hold data.

mod abort;
mod client;
mod server;

pub use abort::SdoAbortCode;
pub use client::{SdoClient, SdoClientEvent, SdoError, SdoOutcome};
pub use server::{ObjectDictionary, SdoServer};

use super::frame;
use crate::can::CanFrame;

/// Largest value one transfer carries, both sides (fixed buffers, no allocation).
pub const MAX_TRANSFER: usize = 256;

/// Data bytes in one segment.
const SEGMENT_DATA: usize = 7;

// Command specifiers (bits 7-5 of byte 0).
const CCS_DOWNLOAD_SEGMENT: u8 = 0;
const CCS_INITIATE_DOWNLOAD: u8 = 1;
const CCS_INITIATE_UPLOAD: u8 = 2;
const CCS_UPLOAD_SEGMENT: u8 = 3;
const SCS_UPLOAD_SEGMENT: u8 = 0;
const SCS_DOWNLOAD_SEGMENT: u8 = 1;
const SCS_INITIATE_UPLOAD: u8 = 2;
const SCS_INITIATE_DOWNLOAD: u8 = 3;
const CS_ABORT: u8 = 4;

// Bits of byte 0.
const BIT_S: u8 = 0x01;
const BIT_E: u8 = 0x02;
const BIT_C: u8 = 0x01;
const BIT_TOGGLE: u8 = 0x10;

const fn cs(byte0: u8) -> u8 {
    byte0 >> 5
}

const fn toggle_bit(toggle: bool) -> u8 {
    if toggle {
        BIT_TOGGLE
    } else {
        0
    }
}

fn mux_of(d: &[u8]) -> (u16, u8) {
    (u16::from_le_bytes([d[1], d[2]]), d[3])
}

fn initiate(cob: u16, byte0: u8, index: u16, sub: u8, payload: [u8; 4]) -> CanFrame {
    let i = index.to_le_bytes();
    let p = payload;
    frame(cob, &[byte0, i[0], i[1], sub, p[0], p[1], p[2], p[3]])
}

/// A segment frame: `byte0` then up to 7 data bytes, zero-padded to 8.
fn segment(cob: u16, byte0: u8, data: &[u8]) -> CanFrame {
    let mut d = [0u8; 8];
    d[0] = byte0;
    d[1..1 + data.len()].copy_from_slice(data);
    frame(cob, &d)
}

/// The abort frame: `80 idx_lo idx_hi sub code(LE)`.
pub fn abort_frame(cob_id: u16, index: u16, sub: u8, code: SdoAbortCode) -> CanFrame {
    initiate(cob_id, CS_ABORT << 5, index, sub, code.0.to_le_bytes())
}

/// Index, sub-index and code of an abort frame's data; `None` if it is not one.
pub fn parse_abort(data: &[u8]) -> Option<(u16, u8, SdoAbortCode)> {
    if data.len() != 8 || cs(data[0]) != CS_ABORT {
        return None;
    }
    let (index, sub) = mux_of(data);
    let code = u32::from_le_bytes([data[4], data[5], data[6], data[7]]);
    Some((index, sub, SdoAbortCode(code)))
}
