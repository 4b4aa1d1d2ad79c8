//! Structure-aware inputs: bytes read as a sequence of operations and frames through
//! `arbitrary`, so most frames land on the identifiers and lengths the code under
//! test listens to, and the rest anywhere.

use arbitrary::{Result, Unstructured};
use hal::can::CanFrame;

/// A frame: 7 in 8 on one of `cobs`, else any 11-bit identifier; 7 in 8 of length
/// `usual_len`, else 0..=8 bytes; 1 in 32 a remote frame.
pub fn frame(u: &mut Unstructured<'_>, cobs: &[u16], usual_len: usize) -> Result<CanFrame> {
    let cob = if !cobs.is_empty() && u.ratio(7u8, 8u8)? {
        *u.choose(cobs)?
    } else {
        u.int_in_range(0..=0x7FF)?
    };
    if u.ratio(1u8, 32u8)? {
        let dlc = u.int_in_range(0..=8)?;
        return Ok(
            CanFrame::remote(cob, dlc).unwrap_or_else(|| unreachable!("id and DLC in range"))
        );
    }
    let len = if u.ratio(7u8, 8u8)? {
        usual_len.min(8)
    } else {
        u.int_in_range(0..=8)?
    };
    let mut data = [0u8; 8];
    u.fill_buffer(&mut data[..len])?;
    Ok(CanFrame::new(cob, &data[..len]).unwrap_or_else(|| unreachable!("id and length in range")))
}

/// Seed bytes from literal frames (identifier, length, data, one after another):
/// [`frame`] reads them as some frames, which is all a starting point needs.
pub fn literal(frames: &[(u16, &[u8])]) -> Vec<u8> {
    let mut out = Vec::new();
    for (cob, data) in frames {
        out.extend_from_slice(&cob.to_le_bytes());
        out.push(data.len() as u8);
        out.extend_from_slice(data);
    }
    out
}
